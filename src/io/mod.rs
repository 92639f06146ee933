//! Files: scenarios in, result tables, summaries and manifests out.

pub mod plots;
pub mod report;
pub mod results;
pub mod scenario;
