//! A live session's poses for the page: the newest frame and the sensors' status as JSON text,
//! which each WebSocket client sends on when it changes. A slow page skips frames rather than
//! holding the session back.
//!
//! A pose message: `{"type": "pose", "frame": n, "time_s": t, "root": [x, y, z] (metres, rig
//! world Y up), "rotations": [[w, x, y, z], …] (each joint's local rotation, rig order = the
//! GLB's node order), "contact": [left, right]}`. A status message: `{"type": "status", "phase":
//! "waiting" | "calibrating" | "running", "calibrating_left_s", "frames", "sensors": [{"id",
//! "rate_hz", "silent_s"}]}` (`silent_s` null before a sensor's first sample).

use crate::anim::Pose;
use std::fmt::Write;
use std::sync::{Arc, Condvar, Mutex};
use std::time::Duration;

/// The newest messages of a session.
#[derive(Debug)]
pub struct Preview {
    metres_per_unit: f64,
    latest: Mutex<Latest>,
    changed: Condvar,
}

#[derive(Debug, Default)]
struct Latest {
    /// Bumped at each new message.
    seq: u64,
    pose: Option<Arc<str>>,
    status: Option<Arc<str>>,
}

/// What a client has already sent.
#[derive(Debug, Clone, Copy, Default)]
pub struct Seen(u64);

/// A sensor's line of the status.
#[derive(Debug, Clone)]
pub struct SensorLine<'a> {
    pub id: &'a str,
    pub rate_hz: f64,
    /// Seconds since its last sample; infinite before its first.
    pub silent_s: f64,
}

fn number(out: &mut String, v: f64) {
    if v.is_finite() {
        // Shortest text that reads back to the same f64.
        let _ = write!(out, "{v}");
    } else {
        out.push_str("null");
    }
}

impl Preview {
    /// `metres_per_unit`: the rig's length unit in metres (the root is sent in metres).
    pub fn new(metres_per_unit: f64) -> Arc<Preview> {
        Arc::new(Preview {
            metres_per_unit,
            latest: Mutex::new(Latest::default()),
            changed: Condvar::new(),
        })
    }

    fn publish(&self, set: impl FnOnce(&mut Latest)) {
        let mut latest = self.latest.lock().unwrap_or_else(|e| e.into_inner());
        set(&mut latest);
        latest.seq += 1;
        self.changed.notify_all();
    }

    /// A frame of the session.
    pub fn pose(&self, pose: &Pose) {
        let mut s = String::with_capacity(64 + pose.local.len() * 80);
        let _ = write!(
            s,
            "{{\"type\":\"pose\",\"frame\":{},\"time_s\":",
            pose.frame
        );
        number(&mut s, pose.time_s);
        s.push_str(",\"root\":[");
        for (i, v) in pose.root.iter().enumerate() {
            if i > 0 {
                s.push(',');
            }
            number(&mut s, v * self.metres_per_unit);
        }
        s.push_str("],\"rotations\":[");
        for (i, q) in pose.local.iter().enumerate() {
            if i > 0 {
                s.push(',');
            }
            s.push('[');
            for (k, v) in [q.w, q.i, q.j, q.k].into_iter().enumerate() {
                if k > 0 {
                    s.push(',');
                }
                number(&mut s, v);
            }
            s.push(']');
        }
        let _ = write!(
            s,
            "],\"contact\":[{},{}]}}",
            pose.contact[0], pose.contact[1]
        );
        let message: Arc<str> = s.into();
        self.publish(|l| l.pose = Some(message));
    }

    /// The session's status: `phase` (`waiting`, `calibrating` with the seconds left, `running`).
    pub fn status(
        &self,
        phase: &str,
        calibrating_left_s: Option<f64>,
        frames: u64,
        sensors: &[SensorLine<'_>],
    ) {
        let mut s = String::with_capacity(96 + sensors.len() * 64);
        let _ = write!(
            s,
            "{{\"type\":\"status\",\"phase\":{},\"calibrating_left_s\":",
            serde_json::Value::from(phase)
        );
        number(&mut s, calibrating_left_s.unwrap_or(f64::NAN));
        let _ = write!(s, ",\"frames\":{frames},\"sensors\":[");
        for (i, line) in sensors.iter().enumerate() {
            if i > 0 {
                s.push(',');
            }
            let _ = write!(
                s,
                "{{\"id\":{},\"rate_hz\":",
                serde_json::Value::from(line.id)
            );
            number(&mut s, line.rate_hz);
            s.push_str(",\"silent_s\":");
            number(&mut s, line.silent_s);
            s.push('}');
        }
        s.push_str("]}");
        let message: Arc<str> = s.into();
        self.publish(|l| l.status = Some(message));
    }

    /// The messages newer than `seen` (status first), waiting up to `timeout` for one; empty
    /// when none came.
    pub fn wait(&self, seen: &mut Seen, timeout: Duration) -> Vec<Arc<str>> {
        let latest = self.latest.lock().unwrap_or_else(|e| e.into_inner());
        let (latest, _) = self
            .changed
            .wait_timeout_while(latest, timeout, |l| l.seq == seen.0)
            .unwrap_or_else(|e| e.into_inner());
        if latest.seq == seen.0 {
            return Vec::new();
        }
        seen.0 = latest.seq;
        latest
            .status
            .iter()
            .chain(latest.pose.iter())
            .cloned()
            .collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::{UnitQuaternion, Vector3};

    #[test]
    fn a_pose_is_json_in_metres_with_w_first() {
        let preview = Preview::new(0.01);
        let pose = Pose {
            frame: 7,
            time_s: 0.125,
            local: vec![
                UnitQuaternion::identity(),
                UnitQuaternion::from_axis_angle(&Vector3::y_axis(), std::f64::consts::PI),
            ],
            root: Vector3::new(100.0, 50.0, -25.0),
            contact: [true, false],
            airborne: false,
        };
        preview.pose(&pose);
        preview.status(
            "running",
            None,
            8,
            &[SensorLine {
                id: "pelvis\"",
                rate_hz: 100.0,
                silent_s: f64::INFINITY,
            }],
        );
        let mut seen = Seen::default();
        let got = preview.wait(&mut seen, Duration::ZERO);
        assert_eq!(got.len(), 2);
        let status: serde_json::Value = serde_json::from_str(&got[0]).unwrap();
        assert_eq!(status["sensors"][0]["id"], "pelvis\"");
        assert!(status["sensors"][0]["silent_s"].is_null());
        assert!(status["calibrating_left_s"].is_null());
        let pose: serde_json::Value = serde_json::from_str(&got[1]).unwrap();
        assert_eq!(pose["frame"], 7);
        let numbers = |v: &serde_json::Value| -> Vec<f64> {
            v.as_array()
                .unwrap()
                .iter()
                .map(|x| x.as_f64().unwrap())
                .collect()
        };
        assert_eq!(numbers(&pose["root"]), [1.0, 0.5, -0.25]);
        assert_eq!(numbers(&pose["rotations"][0]), [1.0, 0.0, 0.0, 0.0]);
        let half_turn = numbers(&pose["rotations"][1]);
        assert!(half_turn[0].abs() < 1e-15);
        assert_eq!(half_turn[2], 1.0);
        assert_eq!(pose["contact"], serde_json::json!([true, false]));
        // Nothing newer: an empty wait.
        assert!(preview.wait(&mut seen, Duration::from_millis(1)).is_empty());
    }
}
