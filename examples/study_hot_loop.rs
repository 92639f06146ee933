//! The study's hot loop for instruction counts: the default campaign, then 10 tasks at n = 75
//! (DETMAX, identification, validation) on one thread. `scripts/bench/instructions.sh` runs it
//! under callgrind, whose counts repeat exactly from run to run on one machine.
use calsim::device::trical::experiment::ExperimentSpec;
use calsim::device::trical::study::run;
use calsim::study::StudySpec;
fn main() {
    let spec = ExperimentSpec::default();
    let e = spec.build(2018).expect("campaign");
    let before = spec.before_model(&e.campaign);
    let study = StudySpec { set_sizes: vec![75], repetitions: 10, ..StudySpec::default() };
    let r = run(&e, &before, &study, 2018, &|_, _| {}).expect("study");
    let median: f64 = r.tasks.iter().map(|t| t.validation.median).sum::<f64>() / r.tasks.len() as f64;
    println!("{} tasks, mean of the validation medians {median:.4} mm", r.tasks.len());
}
