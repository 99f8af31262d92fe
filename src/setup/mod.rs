//! `imubake setup`: bring up a suit in the browser. A live session without a mapping feeds every
//! sample to a [`board::Board`] (each sensor's readings, the one that moves lit, the bones
//! assigned, the calibrations taken from the stream); the viewer's server serves the setup page
//! and a `/setup` WebSocket over which the page gets the board ten times a second and sends its
//! commands ([`board::Command`]); **Save** writes the mapping, the subject and the sensor
//! calibration into one folder, each first read by the parser of the loader `convert` and `live`
//! use (nothing a later command would refuse is written).

pub mod board;

use crate::intrinsics::{SensorCalibration, SensorIntrinsics};
use crate::mapping::parse_mapping;
use crate::rig::Rig;
use crate::rig::subject::Subject;
use crate::take::StreamValue;
use crate::world::World;
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
    /// The rig the bones are of: a subject is checked against it before it is saved.
    rig: Rig,
    /// The rig as given (`--rig`): a built-in name goes into the mapping, any value into the
    /// printed command.
    rig_arg: String,
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
    /// `rig_arg`: the rig as given on the command line (`rig`'s name or file).
    pub fn new(
        board: Board,
        out: PathBuf,
        rig: Rig,
        rig_arg: String,
        sources: Vec<String>,
    ) -> Setup {
        Setup {
            board: Mutex::new(board),
            out,
            rig,
            rig_arg,
            sources,
        }
    }

    fn board(&self) -> std::sync::MutexGuard<'_, Board> {
        self.board.lock().unwrap_or_else(|e| e.into_inner())
    }

    /// One sample from the session; an orientation `q_world_sensor` in the source's `world` goes
    /// to the board as `q_enu_sensor` (raw readings are in the sensor's own frame).
    pub fn sample(&self, id: &str, t_s: f64, value: StreamValue, world: World) {
        let value = match value.orientation() {
            Some(q) if world != World::Enu => {
                let enu_from_world = World::Enu.to_rig().inverse() * world.to_rig();
                StreamValue::Quaternion(enu_from_world * q)
            }
            _ => value,
        };
        self.board().sample(id, t_s, value);
    }

    /// The board for the page, as JSON text.
    pub fn snapshot_json(&self) -> String {
        let board = self.board();
        serde_json::to_string(&board.snapshot()).expect("the board serialises")
    }

    /// A command from the page (JSON text); its outcome is the board's `message`.
    pub fn command_json(&self, text: &str) {
        match serde_json::from_str::<Command>(text) {
            Ok(command) => self.command(command),
            Err(e) => self.board().message = Some(format!("error: not a command: {e}")),
        }
    }

    /// A command; its outcome is the board's `message`.
    pub fn command(&self, command: Command) {
        let outcome = match command {
            Command::Save => self.save().map(|s| {
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
            c => self.board().command(c).map(|()| String::new()),
        };
        let mut board = self.board();
        board.message = match outcome {
            Ok(m) if m.is_empty() => None,
            Ok(m) => Some(m),
            Err(e) => Some(format!("error: {e}")),
        };
    }

    /// Writes the mapping, the subject (when a height or a segment was given) and the sensor
    /// calibration (when a bias or a magnetometer fit was found) into the folder, atomically.
    /// Each text is first read by the parser its loader uses (the subject also applied to the rig
    /// in the pose held), so a file a later command would refuse is not written at all.
    pub fn save(&self) -> Result<Saved, String> {
        let (mapping, subject, calibration, pose) = {
            let board = self.board();
            let builtin = crate::rig::file::BUILTIN
                .iter()
                .any(|(name, _)| *name == self.rig_arg);
            let files = files_of(&board, builtin.then_some(self.rig_arg.as_str()))?;
            (files.0, files.1, files.2, board.pose_name().to_string())
        };
        let path = |name: &str| self.out.join(name);
        parse_mapping(&mapping, &path(MAPPING_FILE)).map_err(|e| e.to_string())?;
        if let Some(subject) = &subject {
            let standing = self.rig.pose(&pose).map(|p| p.local);
            Subject::parse(subject, &path(SUBJECT_FILE))
                .and_then(|s| s.apply(&self.rig, standing.as_deref(), &path(SUBJECT_FILE)))
                .map_err(|e| e.to_string())?;
        }
        if let Some(calibration) = &calibration {
            SensorCalibration::parse(calibration)
                .map_err(|e| format!("{}: {e}", path(CALIBRATION_FILE).display()))?;
        }
        std::fs::create_dir_all(&self.out).map_err(|e| format!("{}: {e}", self.out.display()))?;
        let write = |name: &str, text: &str| -> Result<PathBuf, String> {
            let path = path(name);
            crate::write::write_atomic(&path, |w| w.write_all(text.as_bytes()))
                .map_err(|e| format!("{}: {e}", path.display()))?;
            Ok(path)
        };
        let word = |p: &Path| shell_word(&p.display().to_string());
        let mapping_path = write(MAPPING_FILE, &mapping)?;
        let mut command = format!(
            "imubake live {} --rig {} --mapping {}",
            self.sources
                .iter()
                .map(|s| format!("--source {}", shell_word(s)))
                .collect::<Vec<_>>()
                .join(" "),
            shell_word(&self.rig_arg),
            word(&mapping_path),
        );
        let mut files = vec![mapping_path];
        if let Some(subject) = subject {
            let path = write(SUBJECT_FILE, &subject)?;
            command += &format!(" --subject {}", word(&path));
            files.push(path);
        }
        if let Some(calibration) = calibration {
            let path = write(CALIBRATION_FILE, &calibration)?;
            command += &format!(" --sensor-calibration {}", word(&path));
            files.push(path);
        }
        command += &format!(" --record {}", word(&self.out.join("takes")));
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
    // The second pose as it was held after the first (a take repeats that timing).
    if let (Some(first), Some((name, second))) = (board.pose_held(), board.second_held()) {
        mapping["calibration"]["second"] = serde_json::json!({
            "pose": name,
            "start_s": second.start_s - first.start_s,
            "duration_s": second.seconds,
        });
        mapping["comment"] = "written by imubake setup: a take recorded with it starts with the calibration pose, then the second pose in the same timing".into();
    }
    if let Some(rig) = rig {
        mapping["rig"] = rig.into();
    }
    let mapping = serde_json::to_string_pretty(&mapping).expect("JSON") + "\n";
    let subject = Subject {
        height_m: board.height_m(),
        segments: board.segments().clone(),
    };
    let subject = (subject != Subject::default()).then(|| {
        format!(
            "# written by imubake setup: metres\n{}",
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
    for (sensor, fit) in board.mag_fits() {
        calibration.sources.insert(
            "mag".into(),
            "imubake setup: turned through every direction in the live stream".into(),
        );
        calibration
            .sensors
            .entry(sensor.to_string())
            .or_default()
            .magnetometer = Some(fit.clone());
    }
    let calibration = (!calibration.sensors.is_empty()).then(|| calibration.to_yaml());
    Ok((mapping, subject, calibration))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::take::ImuSample;

    /// A setup on the built-in mixamo rig (`--rig mixamo`), the page drawing `board`.
    fn on_mixamo(board: Board, out: PathBuf, sources: Vec<String>) -> Setup {
        let rig = crate::rig::builtin_rig("mixamo").unwrap().unwrap();
        Setup::new(board, out, rig, "mixamo".into(), sources)
    }
    use nalgebra::Vector3;

    #[test]
    fn save_writes_files_the_loaders_read_back() {
        let dir = tempfile::tempdir().unwrap();
        let setup = on_mixamo(
            Board::new(board::tests::joints(&["Hips", "Spine"]), vec![]),
            dir.path().join("suit"),
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
            setup.sample("s 1", i as f64 / 100.0, value, World::Enu);
            if i == 0 {
                setup.command_json(r#"{"cmd":"assign","sensor":"s 1","bone":"Spine"}"#);
                setup.command_json(r#"{"cmd":"capture","kind":"gyro_bias","seconds":2}"#);
                setup.command_json(r#"{"cmd":"height","m":1.72}"#);
            }
        }
        let saved = setup.save().unwrap();
        assert_eq!(saved.files.len(), 3);
        let mapping = crate::mapping::load_mapping(&saved.files[0]).unwrap();
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
    fn a_subject_the_rig_cannot_take_is_not_saved() {
        let dir = tempfile::tempdir().unwrap();
        let setup = on_mixamo(
            Board::of_rig(&crate::rig::builtin_rig("mixamo").unwrap().unwrap()),
            dir.path().join("suit"),
            vec!["stdin".into()],
        );
        setup.sample(
            "a",
            0.0,
            StreamValue::Raw {
                imu: ImuSample {
                    gyro_rad_s: Vector3::zeros(),
                    accel_m_s2: Vector3::new(0.0, 0.0, 9.81),
                },
                mag: None,
            },
            World::Enu,
        );
        setup.command_json(r#"{"cmd":"assign","sensor":"a","bone":"Hips"}"#);
        // Mixamo's thigh is about 0.4 m: 1.4 m is more than 3× it.
        setup.command_json(r#"{"cmd":"segment","part":"left_thigh","m":1.4}"#);
        let e = setup.save().unwrap_err();
        assert!(e.contains("left_thigh"), "{e}");
        // Nothing is written then, not even the mapping.
        assert!(!dir.path().join("suit").exists());
        setup.command_json(r#"{"cmd":"segment","part":"left_thigh","m":0.45}"#);
        let saved = setup.save().unwrap();
        let subject = Subject::load(&saved.files[1]).unwrap();
        assert_eq!(subject.segments["left_thigh"], 0.45);
        assert_eq!(subject.height_m, None);
    }

    #[test]
    fn a_second_pose_is_saved_in_the_timing_it_was_held() {
        let dir = tempfile::tempdir().unwrap();
        let setup = on_mixamo(
            Board::new(
                board::tests::joints(&["Hips", "Spine"]),
                vec!["rest".into(), "tpose".into()],
            ),
            dir.path().join("suit"),
            vec![],
        );
        let still = StreamValue::Raw {
            imu: ImuSample {
                gyro_rad_s: Vector3::zeros(),
                accel_m_s2: Vector3::new(0.0, 0.0, 9.81),
            },
            mag: None,
        };
        let message = |s: &Setup| -> String {
            let snapshot: serde_json::Value = serde_json::from_str(&s.snapshot_json()).unwrap();
            snapshot["message"].as_str().unwrap_or_default().to_string()
        };
        for i in 0..=1000 {
            let t = i as f64 / 100.0;
            setup.sample("a", t, still, World::Enu);
            match i {
                0 => {
                    setup.command_json(r#"{"cmd":"assign","sensor":"a","bone":"Hips"}"#);
                    setup.command_json(r#"{"cmd":"capture","kind":"second_pose","seconds":1.5}"#);
                    assert!(message(&setup).contains("first"));
                    setup.command_json(r#"{"cmd":"second_pose","name":"rest"}"#);
                    assert!(message(&setup).contains("already"));
                    setup.command_json(r#"{"cmd":"second_pose","name":"tpose"}"#);
                    // Held from 1 to 3 s.
                    setup.command_json(
                        r#"{"cmd":"capture","kind":"pose","seconds":2,"countdown_s":1}"#,
                    );
                }
                // Held from 4.5 to 6 s: 3.5 s after the first began.
                400 => setup.command_json(
                    r#"{"cmd":"capture","kind":"second_pose","seconds":1.5,"countdown_s":0.5}"#,
                ),
                _ => {}
            }
        }
        let saved = setup.save().unwrap();
        let crate::mapping::MappingFile::Quaternion(m) =
            crate::mapping::load_mapping(&saved.files[0]).unwrap()
        else {
            panic!("not a quaternion mapping");
        };
        let window = m.calibration.unwrap();
        assert_eq!((window.start_s, window.duration_s), (0.0, 2.0));
        let second = window.second.unwrap();
        assert_eq!(second.pose, crate::mapping::PoseRef::Named("tpose".into()));
        assert!((second.start_s - 3.5).abs() < 1e-9, "{}", second.start_s);
        assert_eq!(second.duration_s, 1.5);
    }

    proptest::proptest! {
        /// Any text from the page is a command or a message on the board: never a panic.
        #[test]
        fn any_text_from_the_page_is_answered(text in ".{0,200}") {
            let setup = on_mixamo(Board::new(board::tests::joints(&["Hips"]), vec![]), std::env::temp_dir().join("imubake-setup-never-written"), vec![]);
            setup.command_json(&text);
            let snapshot: serde_json::Value = serde_json::from_str(&setup.snapshot_json()).unwrap();
            proptest::prop_assert!(snapshot["message"].as_str().is_some_and(|m| m.starts_with("error")));
        }
    }

    #[test]
    fn a_suit_in_ned_bows_to_the_forward_it_has_in_enu() {
        // board.rs's quaternion bow (the pelvis sensor 180° about up, a 30° forward bow), sent
        // as `q_ned_sensor`: the board turns it to ENU, so the forward is the same −y.
        let setup = on_mixamo(
            Board::new(board::tests::joints(&["Hips"]), vec![]),
            std::env::temp_dir().join("imubake-setup-never-written"),
            vec![],
        );
        let ned_from_enu = World::Ned.to_rig().inverse() * World::Enu.to_rig();
        let q0 =
            nalgebra::UnitQuaternion::from_axis_angle(&Vector3::z_axis(), std::f64::consts::PI);
        for step in board::tests::pose_then_bow() {
            match step {
                board::tests::BowStep::Command(c) => setup.command(c),
                board::tests::BowStep::Sample { t, bow_rad } => {
                    let bow =
                        nalgebra::UnitQuaternion::from_axis_angle(&-Vector3::x_axis(), bow_rad);
                    let q = StreamValue::Quaternion(ned_from_enu * bow * q0);
                    setup.sample("p", t, q, World::Ned);
                }
            }
        }
        let snapshot: serde_json::Value = serde_json::from_str(&setup.snapshot_json()).unwrap();
        assert_eq!(snapshot["bow"]["forward"], "-y", "{}", snapshot["bow"]);
        // Shown as q_enu_sensor.
        let q = &snapshot["sensors"][0]["q"];
        assert!(
            (q[0].as_f64().unwrap().abs() - q0.w.abs()).abs() < 1e-9,
            "{q}"
        );
    }

    #[test]
    fn a_word_with_a_space_or_quote_is_quoted_for_the_shell() {
        assert_eq!(shell_word("udp:9000"), "udp:9000");
        assert_eq!(shell_word("a b"), "'a b'");
        assert_eq!(shell_word("it's"), r"'it'\''s'");
    }
}
