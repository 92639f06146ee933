//! The SPMS study of Gao et al. (Sensors 2023), on the one study engine: the head built and its
//! beams identified (`head`), the ER20-C10 calibrated at SPMS stations and tested per ISO 9283
//! (`calibration`, `iso9283`), random and DETMAX sets compared (`study`). The device itself (beams,
//! readings, sphere fit, measurement frame, beam identification) is an instrument:
//! [`crate::instrument::spms`], re-exported here.

pub mod calibration;
pub mod head;
pub mod iso9283;
pub mod study;

pub use crate::instrument::spms::*;
