//! Frame rates as rationals (conventions.md, "Time and frames").
//!
//! `29.97` means 30000/1001, `23.976` 24000/1001, `59.94` 60000/1001, `119.88` 120000/1001; any
//! other decimal is taken exactly (`12.5` = 25/2); `25`, `50` and fractions such as `2000/7` are
//! accepted too.

use serde::ser::SerializeStruct;
use serde::{Serialize, Serializer};
use std::fmt;
use std::str::FromStr;

/// A frame rate `num / den` frames per second, in lowest terms, both positive.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub struct Fps {
    num: u64,
    den: u64,
}

#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("`{0}` is not a frame rate; expected a positive number such as 24, 29.97, 60 or 2000/7")]
pub struct BadFps(pub String);

fn gcd(mut a: u64, mut b: u64) -> u64 {
    while b != 0 {
        (a, b) = (b, a % b);
    }
    a
}

/// Rates above this are refused (nothing samples or plays back faster).
const MAX_FPS: u64 = 100_000;

impl Fps {
    pub fn new(num: u64, den: u64) -> Option<Fps> {
        if num == 0 || den == 0 || num / den > MAX_FPS {
            return None;
        }
        let g = gcd(num, den);
        Some(Fps {
            num: num / g,
            den: den / g,
        })
    }

    pub fn num(self) -> u64 {
        self.num
    }

    pub fn den(self) -> u64 {
        self.den
    }

    pub fn as_f64(self) -> f64 {
        self.num as f64 / self.den as f64
    }

    /// Seconds per frame.
    pub fn frame_time_s(self) -> f64 {
        self.den as f64 / self.num as f64
    }

    /// Time of frame `n`: n / fps, computed from the rational so that it does not drift.
    pub fn frame_time_of(self, n: u64) -> f64 {
        (n as f64 * self.den as f64) / self.num as f64
    }

    /// The first frame at or after `t_s` (a tolerance of 1e-9 frame counts a time on a frame up to
    /// float noise as on it).
    pub fn first_frame_at_or_after(self, t_s: f64) -> u64 {
        (t_s * self.num as f64 / self.den as f64 - 1e-9)
            .ceil()
            .max(0.0) as u64
    }

    /// The last frame at or before `t_s` (the same tolerance), `None` before frame 0.
    pub fn last_frame_at_or_before(self, t_s: f64) -> Option<u64> {
        let f = (t_s * self.num as f64 / self.den as f64 + 1e-9).floor();
        (f >= 0.0).then_some(f as u64)
    }

    /// The rate a BVH file's `Frame Time:` (seconds per frame) stands for: a whole rate or an
    /// NTSC one (n·1000/1001) whose frame time agrees to 1 part in 10⁴ (files write 6 decimals,
    /// `0.033333` is 30 fps, `0.033367` 29.97), else the frame time's own decimal value.
    /// `None` when the frame time is not a positive number of a rate [`Fps::new`] accepts.
    pub fn from_frame_time_s(frame_time_s: f64) -> Option<Fps> {
        if !(frame_time_s.is_finite() && frame_time_s > 0.0) {
            return None;
        }
        let rate = 1.0 / frame_time_s;
        let close = |fps: Fps| (fps.frame_time_s() - frame_time_s).abs() <= 1e-4 * frame_time_s;
        let whole = Fps::new(rate.round().max(1.0) as u64, 1);
        let ntsc = Fps::new((rate * 1.001).round().max(1.0) as u64 * 1000, 1001);
        // The whole rate first: 1e-4 cannot mistake 30 for 29.97 (they differ by 1e-3).
        [whole, ntsc]
            .into_iter()
            .flatten()
            .find(|&f| close(f))
            .or_else(|| Fps::new((rate * 1e6).round() as u64, 1_000_000))
    }

    /// Frames on the grid from t = 0 to `last_s` inclusive: floor(last_s · fps) + 1.
    pub fn frame_count(self, last_s: f64) -> u64 {
        if !(last_s.is_finite() && last_s > 0.0) {
            return 1;
        }
        // A tiny tolerance so that a sample exactly on a frame (up to float noise) counts.
        let frames = (last_s * self.num as f64 / self.den as f64 + 1e-9).floor();
        frames as u64 + 1
    }
}

impl FromStr for Fps {
    type Err = BadFps;

    fn from_str(s: &str) -> Result<Self, Self::Err> {
        let bad = || BadFps(s.to_string());
        let t = s.trim();
        if let Some((n, d)) = t.split_once('/') {
            let n: u64 = n.trim().parse().map_err(|_| bad())?;
            let d: u64 = d.trim().parse().map_err(|_| bad())?;
            return Fps::new(n, d).ok_or_else(bad);
        }
        match t {
            "29.97" => {
                return Ok(Fps {
                    num: 30000,
                    den: 1001,
                });
            }
            "23.976" | "23.98" => {
                return Ok(Fps {
                    num: 24000,
                    den: 1001,
                });
            }
            "59.94" => {
                return Ok(Fps {
                    num: 60000,
                    den: 1001,
                });
            }
            "119.88" => {
                return Ok(Fps {
                    num: 120000,
                    den: 1001,
                });
            }
            _ => {}
        }
        // Any other decimal exactly: digits before and after the point.
        let (int, frac) = t.split_once('.').unwrap_or((t, ""));
        if int.is_empty() && frac.is_empty()
            || !int.bytes().all(|b| b.is_ascii_digit())
            || !frac.bytes().all(|b| b.is_ascii_digit())
            || frac.len() > 9
        {
            return Err(bad());
        }
        let den = 10u64.pow(frac.len() as u32);
        let int: u64 = if int.is_empty() {
            0
        } else {
            int.parse().map_err(|_| bad())?
        };
        let frac: u64 = if frac.is_empty() {
            0
        } else {
            frac.parse().map_err(|_| bad())?
        };
        let num = int
            .checked_mul(den)
            .and_then(|v| v.checked_add(frac))
            .ok_or_else(bad)?;
        Fps::new(num, den).ok_or_else(bad)
    }
}

impl fmt::Display for Fps {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        if self.den == 1 {
            write!(f, "{}", self.num)
        } else {
            write!(f, "{}/{}", self.num, self.den)
        }
    }
}

impl Serialize for Fps {
    /// `{"num": 30000, "den": 1001, "float": 29.97002997}` (sidecar `fps`).
    fn serialize<S: Serializer>(&self, serializer: S) -> Result<S::Ok, S::Error> {
        let mut s = serializer.serialize_struct("Fps", 3)?;
        s.serialize_field("num", &self.num)?;
        s.serialize_field("den", &self.den)?;
        s.serialize_field("float", &self.as_f64())?;
        s.end()
    }
}

impl<'de> serde::Deserialize<'de> for Fps {
    /// Accepts a number (`24`, `29.97`), a string (`"30000/1001"`) or `{num, den}`.
    fn deserialize<D: serde::Deserializer<'de>>(deserializer: D) -> Result<Self, D::Error> {
        #[derive(serde::Deserialize)]
        #[serde(untagged)]
        enum Raw {
            Int(u64),
            Float(f64),
            Text(String),
            Ratio { num: u64, den: u64 },
        }
        let parsed = match Raw::deserialize(deserializer)? {
            Raw::Int(n) => Fps::new(n, 1).ok_or_else(|| BadFps(n.to_string())),
            // Through its shortest decimal text, so 29.97 keeps its NTSC meaning.
            Raw::Float(v) => v.to_string().parse(),
            Raw::Text(t) => t.parse(),
            Raw::Ratio { num, den } => {
                Fps::new(num, den).ok_or_else(|| BadFps(format!("{num}/{den}")))
            }
        };
        parsed.map_err(serde::de::Error::custom)
    }
}

#[cfg(test)]
mod tests {
    #[test]
    fn frame_times_of_bvh_files_give_their_rates() {
        use super::Fps;
        let rate = |ft: f64| Fps::from_frame_time_s(ft).map(|f| (f.num(), f.den()));
        assert_eq!(rate(0.033333), Some((30, 1)));
        assert_eq!(rate(1.0 / 30.0), Some((30, 1)));
        assert_eq!(rate(0.033367), Some((30000, 1001)));
        assert_eq!(rate(0.03336666666666667), Some((30000, 1001)));
        assert_eq!(rate(0.008333), Some((120, 1)));
        assert_eq!(rate(0.0083333), Some((120, 1)));
        assert_eq!(rate(0.016683), Some((60000, 1001)));
        // 1 / 0.0123 = 81.30…: neither whole nor NTSC, kept as its decimal.
        assert_eq!(rate(0.0123), Some((81_300_813, 1_000_000)));
        assert_eq!(rate(0.0), None);
        assert_eq!(rate(f64::NAN), None);
        assert_eq!(rate(-1.0), None);
    }

    use super::*;

    fn fps(s: &str) -> (u64, u64) {
        let f: Fps = s.parse().unwrap();
        (f.num(), f.den())
    }

    #[test]
    fn ntsc_rates_and_exact_decimals() {
        assert_eq!(fps("24"), (24, 1));
        assert_eq!(fps("29.97"), (30000, 1001));
        assert_eq!(fps("23.976"), (24000, 1001));
        assert_eq!(fps("59.94"), (60000, 1001));
        assert_eq!(fps("119.88"), (120000, 1001));
        assert_eq!(fps("12.5"), (25, 2));
        assert_eq!(fps("25.0"), (25, 1));
        assert_eq!(fps("2000/7"), (2000, 7));
        assert_eq!(fps("60000/1001"), (60000, 1001));
        for bad in ["", "0", "-24", "abc", "1/0", "24fps", ".", "1e3", "nan"] {
            assert!(bad.parse::<Fps>().is_err(), "{bad}");
        }
    }

    #[test]
    fn frame_grid() {
        let f: Fps = "29.97".parse().unwrap();
        // 1 s at 29.97: frames 0..=29 (frame 29 at 0.9676 s, frame 30 at 1.001 s).
        assert_eq!(f.frame_count(1.0), 30);
        assert!((f.frame_time_of(30) - 1.001).abs() < 1e-12);
        let f: Fps = "60".parse().unwrap();
        assert_eq!(f.frame_count(1.0), 61);
        assert_eq!(f.frame_count(0.0), 1);
        assert!((f.frame_time_s() - 1.0 / 60.0).abs() < 1e-15);
    }

    #[test]
    fn serde_forms() {
        let f: Fps = serde_json::from_str("29.97").unwrap();
        assert_eq!((f.num(), f.den()), (30000, 1001));
        let f: Fps = serde_json::from_str("\"24000/1001\"").unwrap();
        assert_eq!((f.num(), f.den()), (24000, 1001));
        let f: Fps = serde_json::from_str("{\"num\": 120, \"den\": 1}").unwrap();
        assert_eq!((f.num(), f.den()), (120, 1));
        let v = serde_json::to_value("30000/1001".parse::<Fps>().unwrap()).unwrap();
        assert_eq!(v["num"], 30000);
        assert!((v["float"].as_f64().unwrap() - 29.97002997).abs() < 1e-8);
    }
}
