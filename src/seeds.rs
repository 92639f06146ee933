//! Every random stream of calsim and the key that seeds it: the common-random-numbers scheme at a
//! glance.
//!
//! A stream is a ChaCha8 generator seeded from the scenario seed and a key naming *what* it draws
//! (a sphere's pool targets, a validation pose's noise, a study task), never *where* it is drawn
//! from. Two scenarios that differ in one amplitude or one design choice therefore draw the same
//! targets, noise and poses for everything else, and a task's result does not depend on which
//! thread or shard ran it.
//!
//! Keys are composed in two levels: a part of the experiment is `stream(seed, part)` or, where the
//! part has its own sub-streams, `split_seed(seed, part)` becomes the seed of those (the campaign's
//! streams below are keyed under [`experiment::CAMPAIGN`]). The numeric values are part of the
//! results: changing one changes every table drawn from it.

use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;

/// A stream of its own for the part `part` of whatever `seed` seeds.
pub fn stream(seed: u64, part: u64) -> ChaCha8Rng {
    ChaCha8Rng::seed_from_u64(split_seed(seed, part))
}

/// Mixes a seed and an index into an independent seed (SplitMix64 finaliser).
pub fn split_seed(seed: u64, index: u64) -> u64 {
    let mut z = seed ^ index.wrapping_mul(0x9E37_79B9_7F4A_7C15).wrapping_add(0x632B_E59B_D9B4_E019);
    z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
    z ^ (z >> 31)
}

/// The parts of the virtual TriCal experiment, keyed under the scenario seed.
pub mod experiment {
    /// Cell: ball tolerances, ballbar noise, the measured sphere centres.
    pub const CELL: u64 = 1;
    /// Physical robot: harmonic orders and phases, joint noise.
    pub const ROBOT: u64 = 2;
    /// TriCal device: indicator errors and misalignments.
    pub const TRICAL: u64 = 3;
    /// Laser tracker: placement and registration.
    pub const TRACKER: u64 = 4;
    /// Campaign: the seed of the streams in [`super::campaign`].
    pub const CAMPAIGN: u64 = 5;
    /// The robot's parameters around the truth (`[robot.spread]`), when they spread.
    pub const SPREAD: u64 = 6;
}

/// The campaign's streams, keyed under `split_seed(seed, experiment::CAMPAIGN)`.
pub mod campaign {
    /// CMM measurement of the TCP.
    pub const CMM: u64 = 1;
    /// Semi-automatic steps (TCP check, locating the spheres): the seed of the streams of their
    /// targets, one per [`semi_automatic_step`].
    pub const SEMI_AUTOMATIC: u64 = 2;
    /// Semi-automatic steps: the seed of the streams of their centrings, one per
    /// [`semi_automatic_step`].
    pub const SEMI_AUTOMATIC_CENTRING: u64 = 5;
    /// Validation configurations.
    pub const VALIDATION_POSES: u64 = 3;
    /// Pool targets: the seed of the streams of every try's target, one per [`pool_step`].
    pub const POOL_TARGETS: u64 = 100;
    /// Pool centrings: the seed of the streams of every try's centring, one per [`pool_step`].
    pub const POOL_CENTRING: u64 = 1 << 40;
    /// Move and tracker noise of validation pose i: `VALIDATION_NOISE + i`.
    pub const VALIDATION_NOISE: u64 = 1 << 41;
    /// Configurations of an instrument's identification pool (Table 8).
    pub const INSTRUMENT_POSES: u64 = 4;
    /// Move and instrument noise of pool pose i: `INSTRUMENT_NOISE + i`.
    pub const INSTRUMENT_NOISE: u64 = 1 << 42;

    /// The key of a semi-automatic draw under [`SEMI_AUTOMATIC`] or [`SEMI_AUTOMATIC_CENTRING`]:
    /// sphere `k`, its configuration `j` (the TCP check takes several on sphere 1) and try `t`
    /// (`t = 0`: the configuration's approach axis; tries count from 1). The checker bounds `j` to
    /// 100 and `t` to 100,000 (below 2^20).
    pub fn semi_automatic_step(k: usize, j: u32, t: u32) -> u64 {
        ((k as u64) << 32) + (u64::from(j) << 20) + u64::from(t)
    }

    /// The key of a pool try under [`POOL_TARGETS`] or [`POOL_CENTRING`]: sphere `k`, the kept
    /// configuration it is for (`slot`, 0-based) and the try `t` of that slot (0-based). The
    /// checker bounds the spheres to 12, the slots to 10,000 (below 2^16) and a sphere's tries to
    /// 10^9 (below 2^32).
    pub fn pool_step(k: usize, slot: u32, t: u32) -> u64 {
        ((k as u64) << 48) + (u64::from(slot) << 32) + u64::from(t)
    }
}

/// The SPMS head's streams, keyed under the scenario seed.
pub mod spms_head {
    /// Assembly errors of the beams and the sensors' error curves.
    pub const BUILD: u64 = 0x4845_4144_0001;
    /// Poses of the beam identification.
    pub const IDENT_POSES: u64 = 0x4845_4144_0002;
    /// Particle swarm.
    pub const PSO: u64 = 0x4845_4144_0003;
    /// Accuracy experiment against the tracker.
    pub const ACCURACY: u64 = 0x4845_4144_0004;
}

/// The SPMS calibration cell's streams, keyed under the scenario seed.
pub mod spms_cell {
    /// The physical robot: its unmodelled effects and joint noise.
    pub const ROBOT: u64 = 0x4552_3230_0004;
    /// The sphere's true place on the flange.
    pub const TOOL: u64 = 0x4552_3230_0005;
    /// Station k's placement error and the tracker's measurement of its frame: `STATION + k`.
    pub const STATION: u64 = 0x5354_4154_0000_0000;
    /// Pool candidate `index` at station k: `POOL + k * 2^32 + index` ([`pool`]).
    pub const POOL: u64 = 0x4552_3230_0100;

    /// The key of pool candidate `index` at station `k`.
    pub fn pool(k: usize, index: u64) -> u64 {
        POOL + ((k as u64) << 32) + index
    }
    /// ISO 9283 cycles.
    pub const ISO: u64 = 0x4552_3230_0002;
    /// The robot's parameters around the truth table (`[robot.spread]`), when they spread.
    pub const SPREAD: u64 = 0x4552_3230_0003;
}

/// Study tasks: task i of a study draws from `stream(split_seed(seed, salt), i)`.
pub mod study {
    /// TriCal study tasks.
    pub const TRICAL: u64 = 0x5354_5544_5900_0000;
    /// SPMS study tasks.
    pub const SPMS: u64 = 0x5350_4d53_5441_534b;
    /// The validation with compensated targets of TriCal task i (its own stream: the study's
    /// sets, fits and validation do not move when it is added or changed).
    pub const COMPENSATED: u64 = 0x434f_4d50_454e_5341;
}

/// The streams of `calsim calibrate`, keyed under its `--seed` (measured data carry no scenario
/// seed: the split, the folds and the prediction's draws are the only random quantities).
pub mod calibrate {
    /// Which poses are held out, and the fold of every other pose.
    pub const SPLIT: u64 = 0x4341_4c49_0001;
    /// The draws of the predicted held-out errors.
    pub const PREDICTION: u64 = 0x4341_4c49_0002;
    /// A simulated measurement file (`calibrate::simulate`): its poses.
    pub const SIMULATED_POSES: u64 = 0x4341_4c49_0003;
    /// A simulated measurement file: the robot's unmodelled effects, move and instrument noise.
    pub const SIMULATED_NOISE: u64 = 0x4341_4c49_0004;
    /// A simulated measurement file: the noise of the probes' orientation readings.
    pub const SIMULATED_ORIENTATION: u64 = 0x4341_4c49_0010;
    /// The noise of a plan's simulated worlds (`calibrate::plan::simulate`), per world.
    pub const PLAN_NOISE: u64 = 0x4341_4c49_0005;
    /// The folds of the k-fold cross-validation over every pose (`calibrate::validation::assign_every_pose`).
    pub const FOLDS_EVERY_POSE: u64 = 0x4341_4c49_0006;
    /// The learned effects at their fitted values (a twin plan's flagged points): every spread is
    /// zero, so the draw takes no number from its stream.
    pub const FITTED_EFFECTS: u64 = 0;
}

/// The streams of `calsim plan`, keyed under the plan file's `seed`.
pub mod plan {
    /// The pool's candidates: candidate i draws from `stream(split_seed(seed, POOL), i)`.
    pub const POOL: u64 = 0x504c_414e_0001;
    /// DETMAX's random start.
    pub const DETMAX: u64 = 0x504c_414e_0002;
    /// The random set DETMAX's set is compared with.
    pub const RANDOM: u64 = 0x504c_414e_0003;
    /// The pilot world's measurement noise.
    pub const PILOT: u64 = 0x504c_414e_0004;
    /// The seed of the simulated worlds (`calibrate::plan::simulate`).
    pub const WORLDS: u64 = 0x504c_414e_0005;
    /// The measurements written by `--simulate`.
    pub const SIMULATE: u64 = 0x504c_414e_0006;
    /// The twin's robot (its `[learned]` effects drawn once), and under `split_seed` of it the
    /// noise of its moves per measurement.
    pub const TWIN: u64 = 0x504c_414e_0007;
}

/// The streams of `calsim optimise`, keyed under the design file's `search.seed`.
pub mod optimise {
    /// The swarm's draws of restart r: `split_seed(seed, SWARM + r)`.
    pub const SWARM: u64 = 1000;
    /// The spread starts of the later repetitions of a count of points: `stream(seed, SPREAD + count)`.
    pub const SPREAD: u64 = 2000;
    /// CMA-ES's draws of restart r: `split_seed(seed, CMAES + r)`.
    pub const CMAES: u64 = 3000;

    /// The seed of restart `r`'s swarm.
    pub fn swarm(seed: u64, r: usize) -> u64 {
        super::split_seed(seed, SWARM + r as u64)
    }

    /// The stream of the spread starts of the searches of `count` points.
    pub fn spread(seed: u64, count: usize) -> rand_chacha::ChaCha8Rng {
        super::stream(seed, SPREAD + count as u64)
    }

    /// The seed of restart `r`'s CMA-ES.
    pub fn cmaes(seed: u64, r: usize) -> u64 {
        super::split_seed(seed, CMAES + r as u64)
    }
}

/// Fixed streams of quantities that are functions of their inputs alone (no scenario seed).
pub mod fixed {
    /// The draws that estimate a robot's ISO 9283 repeatability per radian of joint noise
    /// (`robot::virtual_robot`).
    pub const REPEATABILITY: u64 = 9283;
    /// The bootstrap of a budget's share of source `s`: `BUDGET_SHARE + s`.
    pub const BUDGET_SHARE: u64 = 0x00B0_D6E7;
    /// The joint configurations an optimiser samples for the tool points an arm reaches
    /// (`design::optimise::reach`; "REACH" in ASCII).
    pub const REACH: u64 = 0x5245_4143_4800_0000;
    /// The candidate poses of a TriCal campaign's feasibility, pool cones and validation
    /// configurations (`device::trical::campaign::feasibility`; "FEASIB" in ASCII).
    pub const FEASIBILITY: u64 = 0x4645_4153_4942_0000;
    /// The random Fourier features of the unit field a twin's length fit predicts the bins with
    /// (`calibrate::twin::shape::length_scale`).
    pub const SMOOTH_FIELD: u64 = 0x5eed_1e47;
    /// The replicates of the twin's length fit's parametric bootstrap: replicate `i` draws from
    /// `stream(LENGTH_BOOTSTRAP, i)` (`calibrate::twin::shape::length_scale`).
    pub const LENGTH_BOOTSTRAP: u64 = 0x5eed_1e48;
}

/// A generator seeded with `seed` itself (for the [`fixed`] streams).
pub fn fixed_stream(seed: u64) -> ChaCha8Rng {
    ChaCha8Rng::seed_from_u64(seed)
}

/// The stream of task `index` of a study whose tasks are salted with `salt` (see [`study`]).
pub fn task_stream(seed: u64, salt: u64, index: usize) -> ChaCha8Rng {
    stream(split_seed(seed, salt), index as u64)
}

/// The configurations of the load-time identifiability check (keyed under seed 0: the same for
/// every scenario).
pub const STRUCTURAL_CHECK: u64 = 0x4f42_5345_5256;

/// The stream of the load-time identifiability check's configurations ([`STRUCTURAL_CHECK`]
/// under seed 0).
pub fn structural_check() -> ChaCha8Rng {
    stream(0, STRUCTURAL_CHECK)
}

/// Realisation r > 0 of a scenario seeded s is the world seeded `split_seed(s, REALISATION + r)`
/// (realisation 0 is the scenario's own seed): the same world whatever a sweep varies.
pub const REALISATION: u64 = 0x5245_414c_0000_0000;

/// The seed of realisation `r` of a scenario seeded `seed`: the seed itself for realisation 0 (the
/// plain run), an independent one for every other ([`REALISATION`]).
pub fn realisation_seed(seed: u64, r: u32) -> u64 {
    if r == 0 { seed } else { split_seed(seed, REALISATION + u64::from(r)) }
}

/// The draws of the linear prediction's validation errors, keyed per task (under the study's seed).
pub const PREDICTION: u64 = 0x5052_4544_4943_5400;
