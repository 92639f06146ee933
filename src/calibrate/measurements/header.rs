//! The header keys of a measurement file: `# key = value` comment lines before the column names.

use super::FORMAT;

/// What the joint columns hold.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum JointValues {
    /// The controller's joint values: the robot file's `[[coupling]]` turns them into the model's
    /// joint angles (the default).
    Controller,
    /// The model's joint angles already (no coupling applied).
    Model,
}

/// The header keys of a measurement file.
#[derive(Clone, Debug, PartialEq)]
pub struct Header {
    /// What the joint columns hold.
    pub joints: JointValues,
    /// The targets to calibrate with (`None`: all); rows of other targets are left out and counted.
    pub targets: Option<Vec<String>>,
    /// The measuring frame's name, as the file gives it.
    pub frame: Option<String>,
    /// The data are simulated (`# simulated = true`): every report says so.
    pub simulated: bool,
    /// The robot measured, as the file names it.
    pub robot: Option<String>,
}

impl Default for Header {
    fn default() -> Self {
        Self { joints: JointValues::Controller, targets: None, frame: None, simulated: false, robot: None }
    }
}

/// A header error: line, key, what is wrong.
pub(super) type HeaderError = (Option<u64>, Option<String>, String);

/// Lines of the header keys that later checks name.
#[derive(Default)]
pub(super) struct DirectiveLines {
    /// The line of `# targets`.
    pub(super) targets: u64,
}

/// The header keys from the comment lines before the column names, the line of the column names,
/// and where the keys were. A comment line `# word = value` is a key (an unknown word is an error,
/// so that a misspelt key does not pass silently); any other comment is free text.
pub(super) fn read(text: &str) -> Result<(Header, u64, DirectiveLines), HeaderError> {
    let mut h = Header::default();
    let mut lines = DirectiveLines::default();
    for (i, raw) in text.lines().enumerate() {
        let line = i as u64 + 1;
        let t = raw.trim();
        if t.is_empty() {
            continue;
        }
        let Some(comment) = t.strip_prefix('#') else {
            return Ok((h, line, lines));
        };
        let Some((key, value)) = comment.split_once('=') else { continue };
        let (key, value) = (key.trim(), value.trim());
        if key.is_empty() || !key.chars().all(|c| c.is_ascii_lowercase() || c == '_') {
            continue;
        }
        let bad = |msg: String| (Some(line), Some(key.to_string()), msg);
        match key {
            "format" if value != FORMAT => return Err(bad(format!("{value:?}: this calsim reads {FORMAT}"))),
            "format" => {}
            "joints" => {
                h.joints = match value {
                    "controller" => JointValues::Controller,
                    "model" => JointValues::Model,
                    _ => return Err(bad(format!("{value:?}: `controller` (the robot file's coupling applies) or `model`"))),
                }
            }
            "targets" => {
                let list: Vec<String> = value.split(',').map(|s| s.trim().to_string()).collect();
                if list.iter().any(String::is_empty) {
                    return Err(bad("a comma-separated list of target labels".into()));
                }
                h.targets = Some(list);
                lines.targets = line;
            }
            "frame" => h.frame = Some(value.to_string()),
            "robot" => h.robot = Some(value.to_string()),
            "simulated" => {
                h.simulated = match value {
                    "true" => true,
                    "false" => false,
                    _ => return Err(bad(format!("{value:?}: true or false"))),
                }
            }
            _ => {
                return Err(bad(
                    "unknown header key (the keys: format, joints, targets, frame, robot, simulated; write free comments without `word =`)"
                        .into(),
                ));
            }
        }
    }
    Err((None, None, "no column names (the first line that is neither blank nor a comment)".into()))
}
