//! `imubake setup`: bring up a suit in the browser. A live session without a mapping feeds every
//! sample to a [`board::Board`] (each sensor's readings, the one that moves lit, the bones
//! assigned, the calibrations taken from the stream); the viewer's server serves the setup page
//! and a `/setup` WebSocket over which the page gets the board ten times a second and sends its
//! commands ([`board::Command`]); **Save** writes the mapping, the subject and the sensor
//! calibration into one folder, each read back by the loader `convert` and `live` use.

pub mod board;

use crate::intrinsics::{SensorCalibration, SensorIntrinsics};
use crate::mapping::load_mapping;
use crate::rig::subject::Subject;
use crate::take::StreamValue;
use board::{Board, Command};
use std::path::{Path, PathBuf};
use std::sync::Mutex;

/// The files Save writes, in the folder given.
pub const MAPPING_FILE: &str = "mapping.json";
pub const SUBJECT_FILE: &str = "subject.yaml";
pub const CALIBRATION_FILE: &str = "sensor_calibration.yaml";

/// A setup session's shared state: the board (fed by the session's thread, read and commanded by
/// the page's), and where Save writes.
#[derive(Debug)]
pub struct Setup {
    board: Mutex<Board>,
    out: PathBuf,
    /// The rig as given (`--rig`): a built-in name goes into the mapping, any value into the
    /// printed command.
    rig: String,
    rig_is_builtin: bool,
    /// The sources as given (`--source`), for the printed command.
    sources: Vec<String>,
}

/// What Save wrote.
#[derive(Debug, Clone, PartialEq)]
pub struct Saved {
    pub files: Vec<PathBuf>,
    /// The command that records takes with these files (each starting with the pose).
    pub command: String,
}

impl Setup {
    pub fn new(
        board: Board,
        out: PathBuf,
        rig: String,
        rig_is_builtin: bool,
        sources: Vec<String>,
    ) -> Setup {
        Setup {
            board: Mutex::new(board),
            out,
            rig,
            rig_is_builtin,
            sources,
        }
    }

    fn board(&self) -> std::sync::MutexGuard<'_, Board> {
        self.board.lock().unwrap_or_else(|e| e.into_inner())
    }

    /// One sample from the session.
    pub fn sample(&self, id: &str, t_s: f64, value: StreamValue) {
        self.board().sample(id, t_s, value);
    }

    /// The board for the page, as JSON text.
    pub fn snapshot_json(&self) -> String {
        let board = self.board();
        serde_json::to_string(&board.snapshot()).expect("the board serialises")
    }

    /// A command from the page (JSON text); its outcome is the board's `message`.
    pub fn command_json(&self, text: &str) {
        let outcome = match serde_json::from_str::<Command>(text) {
            Err(e) => Err(format!("not a command: {e}")),
            Ok(Command::Save) => self.save().map(|s| {
                format!(
                    "saved {}; record takes with:\n{}",
                    s.files
                        .iter()
                        .map(|f| f.display().to_string())
                        .collect::<Vec<_>>()
                        .join(", "),
                    s.command
                )
            }),
            Ok(c) => self.board().command(c).map(|()| String::new()),
        };
        let mut board = self.board();
        board.message = match outcome {
            Ok(m) if m.is_empty() => None,
            Ok(m) => Some(m),
            Err(e) => Some(format!("error: {e}")),
        };
    }

    /// Writes the mapping, the subject (when a height was given) and the sensor calibration
    /// (when a bias was found) into the folder, atomically, and reads each back with its loader.
    pub fn save(&self) -> Result<Saved, String> {
        let (mapping, subject, calibration) = {
            let board = self.board();
            files_of(&board, self.rig_is_builtin.then_some(self.rig.as_str()))?
        };
        std::fs::create_dir_all(&self.out).map_err(|e| format!("{}: {e}", self.out.display()))?;
        let mut files = Vec::new();
        let write = |name: &str, text: &str| -> Result<PathBuf, String> {
            let path = self.out.join(name);
            crate::write::write_atomic(&path, |w| w.write_all(text.as_bytes()))
                .map_err(|e| format!("{}: {e}", path.display()))?;
            Ok(path)
        };
        let mapping_path = write(MAPPING_FILE, &mapping)?;
        load_mapping(&mapping_path).map_err(|e| e.to_string())?;
        files.push(mapping_path.clone());
        let mut command = format!(
            "imubake live {} --rig {} --mapping {}",
            self.sources
                .iter()
                .map(|s| format!("--source {}", shell_word(s)))
                .collect::<Vec<_>>()
                .join(" "),
            shell_word(&self.rig),
            shell_word(&mapping_path.display().to_string()),
        );
        if let Some(subject) = subject {
            let path = write(SUBJECT_FILE, &subject)?;
            Subject::load(&path).map_err(|e| e.to_string())?;
            command += &format!(" --subject {}", shell_word(&path.display().to_string()));
            files.push(path);
        }
        if let Some(calibration) = calibration {
            let path = write(CALIBRATION_FILE, &calibration)?;
            SensorCalibration::load(&path).map_err(|e| e.to_string())?;
            command += &format!(
                " --sensor-calibration {}",
                shell_word(&path.display().to_string())
            );
            files.push(path);
        }
        command += &format!(
            " --record {}",
            shell_word(&self.out.join("takes").display().to_string())
        );
        Ok(Saved { files, command })
    }

    /// The folder Save writes into.
    pub fn out(&self) -> &Path {
        &self.out
    }
}

/// `s` quoted for a POSIX shell when it needs it.
fn shell_word(s: &str) -> String {
    if !s.is_empty()
        && s.bytes()
            .all(|b| b.is_ascii_alphanumeric() || b"-_./:@,=+".contains(&b))
    {
        s.to_string()
    } else {
        format!("'{}'", s.replace('\'', r"'\''"))
    }
}

/// The three files' texts: the mapping (JSON), the subject (YAML, with a height) and the sensor
/// calibration (YAML, with a bias).
fn files_of(
    board: &Board,
    rig: Option<&str>,
) -> Result<(String, Option<String>, Option<String>), String> {
    if board.assigned().is_empty() {
        return Err("no sensor is on a bone yet: click a sensor, then a bone".into());
    }
    let forward = board.forward();
    let sensors: serde_json::Map<String, serde_json::Value> = board
        .assigned()
        .iter()
        .map(|(sensor, bone)| {
            let mut entry = serde_json::json!({"bone": bone, "mount": "calibrate"});
            if let Some((s, axis)) = forward
                && s == sensor
            {
                entry["forward"] = axis.into();
            }
            (sensor.clone(), entry)
        })
        .collect();
    let duration_s = board.pose_held().map_or(2.0, |p| p.seconds);
    let mut mapping = serde_json::json!({
        "comment": "written by imubake setup: a take recorded with it starts with the calibration pose",
        "calibration": {"pose": board.pose_name(), "start_s": 0.0, "duration_s": duration_s},
        "sensors": sensors,
    });
    if let Some(rig) = rig {
        mapping["rig"] = rig.into();
    }
    let mapping = serde_json::to_string_pretty(&mapping).expect("JSON") + "\n";
    let subject = board.height_m().map(|h| {
        let subject = Subject {
            height_m: Some(h),
            ..Default::default()
        };
        format!(
            "# written by imubake setup\n{}",
            serde_yaml::to_string(&subject).expect("plain data")
        )
    });
    let mut calibration = SensorCalibration::new();
    for (sensor, bias) in board.biases() {
        calibration.sources.insert(
            "gyro-bias".into(),
            "imubake setup: held still in the live stream".into(),
        );
        calibration.sensors.insert(
            sensor.to_string(),
            SensorIntrinsics {
                gyro_bias: Some(bias.clone()),
                ..Default::default()
            },
        );
    }
    let calibration = (!calibration.sensors.is_empty()).then(|| calibration.to_yaml());
    Ok((mapping, subject, calibration))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::take::ImuSample;
    use nalgebra::Vector3;

    #[test]
    fn save_writes_files_the_loaders_read_back() {
        let dir = tempfile::tempdir().unwrap();
        let setup = Setup::new(
            Board::new(board::tests::joints(&["Hips", "Spine"]), vec![]),
            dir.path().join("suit"),
            "mixamo".into(),
            true,
            vec!["udp:9000".into()],
        );
        setup.command_json(r#"{"cmd":"save"}"#);
        assert!(setup.snapshot_json().contains("no sensor is on a bone"));
        let bias = Vector3::new(0.3f64, 0.0, -0.1).map(f64::to_radians);
        for i in 0..=300 {
            let value = StreamValue::Raw {
                imu: ImuSample {
                    gyro_rad_s: bias,
                    accel_m_s2: Vector3::new(0.0, 0.0, 9.81),
                },
                mag: None,
            };
            setup.sample("s 1", i as f64 / 100.0, value);
            if i == 0 {
                setup.command_json(r#"{"cmd":"assign","sensor":"s 1","bone":"Spine"}"#);
                setup.command_json(r#"{"cmd":"capture","kind":"gyro_bias","seconds":2}"#);
                setup.command_json(r#"{"cmd":"height","m":1.72}"#);
            }
        }
        let saved = setup.save().unwrap();
        assert_eq!(saved.files.len(), 3);
        let mapping = load_mapping(&saved.files[0]).unwrap();
        let crate::mapping::MappingFile::Quaternion(m) = mapping else {
            panic!("not a quaternion mapping");
        };
        assert_eq!(m.sensors[0].sensor, "s 1");
        assert_eq!(m.sensors[0].bone, "Spine");
        assert_eq!(m.rig.as_deref(), Some("mixamo"));
        assert_eq!(Subject::load(&saved.files[1]).unwrap().height_m, Some(1.72));
        let cal = SensorCalibration::load(&saved.files[2]).unwrap();
        let b = cal.sensors["s 1"].gyro_bias.as_ref().unwrap().bias_rad_s;
        assert!((b[0] - bias[0]).abs() < 1e-12 && (b[2] - bias[2]).abs() < 1e-12);
        assert!(
            saved.command.contains("--source udp:9000"),
            "{}",
            saved.command
        );
        assert!(saved.command.contains("--sensor-calibration"));
        // Nothing left beside the files (atomic writes leave no temporaries).
        let mut names: Vec<_> = std::fs::read_dir(dir.path().join("suit"))
            .unwrap()
            .map(|e| e.unwrap().file_name().into_string().unwrap())
            .collect();
        names.sort();
        assert_eq!(names, [MAPPING_FILE, CALIBRATION_FILE, SUBJECT_FILE]);
    }

    #[test]
    fn a_word_with_a_space_or_quote_is_quoted_for_the_shell() {
        assert_eq!(shell_word("udp:9000"), "udp:9000");
        assert_eq!(shell_word("a b"), "'a b'");
        assert_eq!(shell_word("it's"), r"'it'\''s'");
    }
}
