//! A live layout stream as imubake CSV lines — `time_s,sensor,qw,qx,qy,qz` and, when the frames
//! carry them, the gyroscope and accelerometer columns in the layout's own units
//! (`gx_dps`/`gx_rad_s`, `ax_g`/`ax_m_s2`) — the text a live session's line stages read
//! (`imubake live --source udp:PORT:layout --layout FILE`). Every number is written with the
//! shortest text that reads back to the same `f64`, so a frame gives the values a file read
//! through the same layout gives. The magnetometer is not carried (yet).

use super::{AccelUnit, Decoded, Decoder, GyroUnit, Layout, Meaning};
use std::sync::Arc;

#[derive(Debug)]
pub struct CsvLines {
    layout: Arc<Layout>,
    /// The id of frames without a sensor field (the source's name).
    sensor: String,
    decoder: Decoder,
    decoded: Decoded,
    /// Whether the header written has the inertial columns (`None`: no header yet).
    inertial: Option<bool>,
    /// The first frame's time field, seconds: the stream's zero.
    t0: Option<f64>,
    /// Frames dropped (bad, repeated, without an orientation) so far.
    dropped: u64,
}

impl CsvLines {
    pub fn new(layout: Arc<Layout>, sensor: &str) -> CsvLines {
        CsvLines {
            layout,
            sensor: sensor.to_string(),
            decoder: Decoder::new(),
            decoded: Decoded::default(),
            inertial: None,
            t0: None,
            dropped: 0,
        }
    }

    /// A new connection of the same device: bytes half received are dropped; the header and
    /// the clock's origin stay.
    pub fn restart(&mut self) {
        self.decoder = Decoder::new();
    }

    /// Frames dropped so far: bad ones, repeats (`valid` 0), and frames without an orientation.
    pub fn dropped(&self) -> u64 {
        self.dropped
    }

    /// Feeds bytes received when the host's clock said `host_s`; complete frames' lines go to
    /// `out` (the header before the first).
    pub fn push(&mut self, bytes: &[u8], host_s: f64, out: &mut Vec<Vec<u8>>) {
        self.decoder.push(&self.layout, bytes, &mut self.decoded);
        self.lines(host_s, out);
    }

    /// The stream's end.
    pub fn finish(&mut self, host_s: f64, out: &mut Vec<Vec<u8>>) {
        self.decoder.finish(&self.layout, &mut self.decoded);
        self.lines(host_s, out);
    }

    fn lines(&mut self, host_s: f64, out: &mut Vec<Vec<u8>>) {
        self.dropped += self.decoded.bad.len() as u64;
        self.decoded.bad.clear();
        let layout = Arc::clone(&self.layout);
        for f in self.decoded.frames.drain(..) {
            let Some(Some(q)) = layout.orientation(&f).map(|q| q.map(|q| *q.quaternion())) else {
                self.dropped += 1;
                continue;
            };
            if f.get(Meaning::Valid) == Some(0.0) {
                self.dropped += 1;
                continue;
            }
            let quaternion = [
                f.get(Meaning::Qw),
                f.get(Meaning::Qx),
                f.get(Meaning::Qy),
                f.get(Meaning::Qz),
            ];
            // The frame's own components when it has them (the reader normalises them as the
            // file reader does); Euler angles as their unit quaternion.
            let q = match quaternion {
                [Some(w), Some(x), Some(y), Some(z)] => [w, x, y, z],
                _ => [q.w, q.i, q.j, q.k],
            };
            let inertial_values = super::INERTIAL.map(|m| f.get(m));
            let has_inertial = inertial_values.iter().all(Option::is_some);
            let inertial = *self.inertial.get_or_insert_with(|| {
                let mut header = b"time_s,sensor,qw,qx,qy,qz".to_vec();
                if has_inertial {
                    let g = match layout.gyro_unit {
                        Some(GyroUnit::Dps) => "dps",
                        _ => "rad_s",
                    };
                    let a = match layout.accel_unit {
                        Some(AccelUnit::G) => "g",
                        _ => "m_s2",
                    };
                    header.extend_from_slice(
                        format!(",gx_{g},gy_{g},gz_{g},ax_{a},ay_{a},az_{a}").as_bytes(),
                    );
                }
                out.push(header);
                has_inertial
            });
            let t = match (layout.time_unit, f.get(Meaning::Time)) {
                (Some(unit), Some(v)) => {
                    let s = v * unit.seconds();
                    s - *self.t0.get_or_insert(s)
                }
                _ => host_s,
            };
            let id = match f.get(Meaning::Sensor) {
                Some(s) => super::format_id(s),
                None => self.sensor.clone(),
            };
            let mut line = format!("{t:?},{id},{:?},{:?},{:?},{:?}", q[0], q[1], q[2], q[3]);
            if inertial {
                if !has_inertial {
                    self.dropped += 1;
                    continue;
                }
                for v in inertial_values.iter().flatten() {
                    line.push_str(&format!(",{v:?}"));
                }
            }
            out.push(line.into_bytes());
        }
    }
}
