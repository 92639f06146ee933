//! The recording kit (Rerun): the stream of a recording file with its blueprint (the 3D cell
//! next to time series), points and capsules in {W}, frame axes, the error colour scale. Each
//! device logs its own entities with it; a recorder is an observer, run after the numerical work.

use std::path::Path;

use nalgebra::{Isometry3, UnitQuaternion, Vector3};
use rerun::blueprint::{Blueprint, BlueprintActivation, Horizontal, Spatial3DView, Tabs, TimePanel, TimeSeriesView};
use rerun::{Arrows3D, Capsules3D, Color, RecordingStream};

/// Sphere (or station) colours: 1, 2, 3, 4, then repeating.
pub const SPHERE_COLOURS: [[u8; 3]; 4] = [[230, 80, 60], [60, 160, 80], [70, 110, 230], [200, 160, 40]];

/// What logging returns.
pub type Rr = Result<(), rerun::RecordingStreamError>;

/// Writes a recording to the path it is given (a device's recorder, called by its results writer).
pub type Recorder<'a> = &'a dyn Fn(&Path) -> Result<(), RecordError>;

/// A recording could not be written.
#[derive(Debug, thiserror::Error)]
#[error("recording: {0}")]
pub struct RecordError(pub String);

impl From<rerun::RecordingStreamError> for RecordError {
    fn from(e: rerun::RecordingStreamError) -> Self {
        Self(e.to_string())
    }
}

/// Saves a recording named `name` to `path`: `log` logs its entities, then the blueprint opens on
/// the 3D cell (`cell_contents`) beside the time series (`first_series`: title and origin, on the
/// `pool_configuration` timeline; the study's per-task series under `study_title`).
///
/// The recording is encoded in memory and written in one go: Rerun's own file writer runs on a
/// thread of its own, which on a full disk dies and leaves the flush waiting (or says only "File-
/// writer thread shut down prematurely"); written here, the error is the file system's, naming the
/// file (`study.rrd: No space left on device`).
pub fn save(
    path: &Path,
    name: &str,
    log: impl FnOnce(&RecordingStream) -> Rr,
    cell_contents: &[&str],
    first_series: (&str, &str),
    study_title: &str,
) -> Result<(), RecordError> {
    save_on(path, name, log, cell_contents, first_series, study_title, "pool_configuration")
}

/// [`save`], the file opening on the timeline `timeline` (the first series' own).
pub fn save_on(
    path: &Path,
    name: &str,
    log: impl FnOnce(&RecordingStream) -> Rr,
    cell_contents: &[&str],
    first_series: (&str, &str),
    study_title: &str,
    timeline: &str,
) -> Result<(), RecordError> {
    let (rec, storage) =
        rerun::RecordingStreamBuilder::new("calsim").recording_name(name).memory().map_err(|e| RecordError(e.to_string()))?;
    log(&rec)?;
    blueprint(cell_contents, first_series, study_title, timeline)
        .send(&rec, BlueprintActivation { make_active: true, make_default: true })
        .map_err(|e| RecordError(e.to_string()))?;
    rec.flush_blocking().map_err(|e| RecordError(e.to_string()))?;
    let bytes = storage.drain_as_bytes().map_err(|e| RecordError(e.to_string()))?;
    crate::io::out_dir::write_file(path, bytes).map_err(|e| RecordError(e.to_string()))
}

/// A point in f32, as Rerun takes it.
pub fn p3(v: &Vector3<f64>) -> [f32; 3] {
    [v.x as f32, v.y as f32, v.z as f32]
}

/// A rotation as Rerun takes it.
pub fn quat(q: &UnitQuaternion<f64>) -> rerun::Quaternion {
    rerun::Quaternion::from_xyzw([q.i as f32, q.j as f32, q.k as f32, q.w as f32])
}

/// The error colour scale of the figures ([`crate::io::plot::heat_rgb`]).
pub fn heat(t: f64) -> Color {
    let [r, g, b] = crate::io::plot::heat_rgb(t);
    Color::from_rgb(r, g, b)
}

/// Capsules between world points, as Rerun draws them (a length along +Z, moved and turned).
pub fn capsules(ends: &[(Vector3<f64>, Vector3<f64>, f64)]) -> Capsules3D {
    let lengths: Vec<f32> = ends.iter().map(|(a, b, _)| (b - a).norm() as f32).collect();
    let radii: Vec<f32> = ends.iter().map(|(_, _, r)| *r as f32).collect();
    let translations: Vec<[f32; 3]> = ends.iter().map(|(a, _, _)| p3(a)).collect();
    let rotations: Vec<rerun::Quaternion> = ends
        .iter()
        .map(|(a, b, _)| {
            quat(
                &UnitQuaternion::rotation_between(&Vector3::z(), &(b - a))
                    .unwrap_or_else(|| UnitQuaternion::from_axis_angle(&Vector3::x_axis(), std::f64::consts::PI)),
            )
        })
        .collect();
    Capsules3D::from_lengths_and_radii(lengths, radii).with_translations(translations).with_quaternions(rotations)
}

/// The layout every recording opens on: the 3D cell (`cell_contents`) next to two time series in
/// tabs, the first on the timeline the file opens on (`timeline`), the second the study's series
/// (under `/study`).
fn blueprint(cell_contents: &[&str], first_series: (&str, &str), study_title: &str, timeline: &str) -> Blueprint {
    Blueprint::new(
        Horizontal::new([
            Spatial3DView::new("cell").with_origin("/").with_contents(cell_contents.iter().copied()).into(),
            Tabs::new([
                TimeSeriesView::new(first_series.0).with_origin(first_series.1).into(),
                TimeSeriesView::new(study_title).with_origin("/study").into(),
            ])
            .into(),
        ])
        .with_column_shares([3.0, 2.0]),
    )
    .with_time_panel(TimePanel::new().with_timeline(timeline))
}

/// Static x, y, z arrows (red, green, blue) of `frame`, `len` mm long.
pub fn log_axes(rec: &RecordingStream, path: &str, frame: &Isometry3<f64>, len: f64) -> Rr {
    let o = frame.translation.vector;
    let v: Vec<[f32; 3]> = (0..3).map(|k| p3(&(frame.rotation * Vector3::ith(k, len)))).collect();
    rec.log_static(
        path,
        &Arrows3D::from_vectors(v).with_origins([p3(&o); 3]).with_colors([
            Color::from_rgb(230, 40, 40),
            Color::from_rgb(40, 200, 40),
            Color::from_rgb(40, 80, 230),
        ]),
    )
}

#[cfg(test)]
mod tests {
    #[test]
    fn a_recording_that_cannot_be_written_says_which_file_and_why() {
        let log = |rec: &rerun::RecordingStream| rec.log("cell/point", &rerun::Points3D::new([[0.0f32, 0.0, 0.0]]));
        let e = super::save(std::path::Path::new("/dev/full"), "test", log, &["cell"], ("series", "series"), "study").unwrap_err();
        assert!(e.to_string().contains("full: No space left on device"), "{e}");
    }
}
