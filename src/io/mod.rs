//! Files: scenarios in, result tables, summaries and manifests out.

pub mod budget_results;
pub mod out_dir;
pub mod plots;
pub mod recording;
pub mod report;
pub mod results;
pub mod scenario;
pub mod spms_results;
pub mod sweep_results;
