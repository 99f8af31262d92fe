//! A foot's own sensor says when it stands still: the zero-velocity detector of pedestrian dead
//! reckoning, SHOE (the stance hypothesis optimal detector, Skog, Händel, Nilsson and Rantakokko,
//! "Zero-velocity detection — an algorithm evaluation", IEEE TBME 2010).
//!
//! A foot-mounted IMU on a foot that stands still measures gravity alone and no rotation. Over
//! the `W` readings `i ∈ K` around reading `k` (gyro `ω_i`, rad/s; specific force `a_i`, m/s²;
//! sensor frame), the generalised likelihood ratio test of "still" against "moving" reduces to
//!
//! ```text
//! T_k = (1/W) Σ_{i∈K} [ ‖a_i − g · ā / ‖ā‖‖² / σ_a² + ‖ω_i‖² / σ_ω² ],   still when T_k ≤ γ
//! ```
//!
//! with `ā` the window's mean specific force and `g` = 9.80665 m/s² (its direction is the
//! window's own: the detector needs no orientation). We state it with `γ` folded in — `A = σ_a √γ`,
//! `Ω = σ_ω √γ` — so that still is `T_k ≤ 1` and the two scales read as what a still foot may
//! show: a specific force off gravity by about [`Shoe::accel_m_s2`] or a rate of about
//! [`Shoe::gyro_rad_s`] alone is at the bound. The defaults are OpenShoe's (σ_a = 0.01 m/s²,
//! σ_ω = 0.1 °/s, γ = 3·10⁴, W = 3 at its rate): `A` ≈ 1.73 m/s², `Ω` ≈ 17.3 °/s.
//!
//! A walking foot seldom stands still altogether: it turns about its heel, then its toes. The
//! root stage reads the force term about each of the foot's points instead
//! ([`Shoe::pivot_acceleration_m_s2`]): how fast the least-moving point accelerates.

use crate::take::{ImuSample, Track};

/// Standard gravity, m/s².
const G_M_S2: f64 = 9.80665;

/// SHOE's scales, with its threshold folded in (see the module).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Shoe {
    /// The window `K`, s: the readings within half of it on each side (at least the reading).
    pub window_s: f64,
    /// `A = σ_a √γ`, m/s².
    pub accel_m_s2: f64,
    /// `Ω = σ_ω √γ`, rad/s.
    pub gyro_rad_s: f64,
}

impl Default for Shoe {
    fn default() -> Shoe {
        let root_gamma = 3.0e4_f64.sqrt();
        Shoe {
            window_s: 0.03,
            accel_m_s2: 0.01 * root_gamma,
            gyro_rad_s: (0.1_f64 * root_gamma).to_radians(),
        }
    }
}

impl Shoe {
    /// `T_k` for every reading (`times_s` ascending, s, one per reading): the window is the
    /// readings within `window_s / 2` of reading `k` (always `k` itself).
    pub fn statistic(&self, times_s: &[f64], readings: &[ImuSample]) -> Vec<f64> {
        let n = readings.len().min(times_s.len());
        let half = self.window_s / 2.0;
        let (a2, w2) = (self.accel_m_s2.powi(2), self.gyro_rad_s.powi(2));
        let (mut lo, mut hi) = (0, 0);
        (0..n)
            .map(|k| {
                while times_s[lo] < times_s[k] - half {
                    lo += 1;
                }
                hi = hi.max(k);
                while hi + 1 < n && times_s[hi + 1] <= times_s[k] + half {
                    hi += 1;
                }
                let window = &readings[lo..=hi];
                let mean = window
                    .iter()
                    .map(|r| r.accel_m_s2)
                    .sum::<nalgebra::Vector3<f64>>()
                    / window.len() as f64;
                let up = mean.try_normalize(1e-12).unwrap_or_default() * G_M_S2;
                window
                    .iter()
                    .map(|r| {
                        (r.accel_m_s2 - up).norm_squared() / a2 + r.gyro_rad_s.norm_squared() / w2
                    })
                    .sum::<f64>()
                    / window.len() as f64
            })
            .collect()
    }

    /// How fast the foot's least-moving point accelerates, m/s², per reading: SHOE's force term
    /// about a pivot. A foot planted on its heel or its toes may turn (at a walk's heel strike
    /// and push-off it turns at 200–300 °/s, so SHOE's rate term calls most of a stance moving —
    /// `the_feet_sensors_stillness_is_shoes`); the point it turns about may not move. A point `r`
    /// of the foot (sensor frame, m, from the sensor) that stands still makes the sensor move as a
    /// rigid body turning about it, `a_s = −(ω̇ × r + ω × (ω × r))` in the sensor's frame (the
    /// world's angular acceleration is `R ω̇`), so that the specific force less it,
    ///
    /// ```text
    /// c_i(r) = a_i + ω̇_i × r + ω_i × (ω_i × r),
    /// ```
    ///
    /// is gravity alone, and what is left over is the point's own acceleration. Over SHOE's window
    /// `K` (its `W` readings around reading `k`), about the window's mean direction,
    ///
    /// ```text
    /// a_k(r) = √( (1/W) Σ_{i∈K} ‖c_i(r) − g · c̄ / ‖c̄‖‖² ),   a_k = min over the points r,
    /// ```
    ///
    /// with `ω̇` by central differences of the gyro (one-sided at the ends). Infinite with no
    /// points.
    pub fn pivot_acceleration_m_s2(
        &self,
        times_s: &[f64],
        readings: &[ImuSample],
        points_m: &[nalgebra::Vector3<f64>],
    ) -> Vec<f64> {
        let n = readings.len().min(times_s.len());
        let rate_change: Vec<nalgebra::Vector3<f64>> = (0..n)
            .map(|i| {
                let (a, b) = (i.saturating_sub(1), (i + 1).min(n - 1));
                let dt = times_s[b] - times_s[a];
                if dt > 0.0 {
                    (readings[b].gyro_rad_s - readings[a].gyro_rad_s) / dt
                } else {
                    nalgebra::Vector3::zeros()
                }
            })
            .collect();
        // SHOE's force term alone at unit scale is the mean square.
        let force_alone = Shoe {
            accel_m_s2: 1.0,
            gyro_rad_s: f64::INFINITY,
            ..*self
        };
        let mut least = vec![f64::INFINITY; n];
        for r in points_m {
            let about: Vec<ImuSample> = (0..n)
                .map(|i| {
                    let w = readings[i].gyro_rad_s;
                    ImuSample {
                        gyro_rad_s: w,
                        accel_m_s2: readings[i].accel_m_s2
                            + rate_change[i].cross(r)
                            + w.cross(&w.cross(r)),
                    }
                })
                .collect();
            for (l, m) in least
                .iter_mut()
                .zip(force_alone.statistic(&times_s[..n], &about))
            {
                *l = l.min(m.sqrt());
            }
        }
        least
    }

    /// [`Self::statistic`] of a track, on the frames at `frame_times_s` ([`on_frames`]).
    pub fn frame_statistic(&self, track: &Track<ImuSample>, frame_times_s: &[f64]) -> Vec<f64> {
        let times = track.times_s();
        on_frames(times, &self.statistic(times, track.values()), frame_times_s)
    }
}

/// Per frame (`frame_times_s`, the readings' clock, evenly spaced), the statistic `t` of the
/// readings (at `times_s`) within half a frame of it — the largest — or of the nearest reading
/// when none is that close; infinite outside the readings' span (nothing says the foot stood
/// still there). Still is `T ≤ 1`.
pub fn on_frames(times_s: &[f64], t: &[f64], frame_times_s: &[f64]) -> Vec<f64> {
    let n = times_s.len().min(t.len());
    let (times, t) = (&times_s[..n], &t[..n]);
    let (Some(&first), Some(&last)) = (times.first(), times.last()) else {
        return vec![f64::INFINITY; frame_times_s.len()];
    };
    let half = match frame_times_s {
        [a, b, ..] => (b - a) / 2.0,
        _ => 0.0,
    };
    frame_times_s
        .iter()
        .map(|&frame| {
            if frame < first - half || frame > last + half {
                return f64::INFINITY;
            }
            let lo = times.partition_point(|&s| s < frame - half);
            let hi = times.partition_point(|&s| s <= frame + half);
            if lo < hi {
                t[lo..hi].iter().copied().fold(0.0, f64::max)
            } else {
                // The nearest reading.
                let k = times.partition_point(|&s| s < frame).min(n - 1);
                let k = if k > 0 && (frame - times[k - 1]) < (times[k] - frame) {
                    k - 1
                } else {
                    k
                };
                t[k]
            }
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::Vector3;

    fn reading(gyro: [f64; 3], accel: [f64; 3]) -> ImuSample {
        ImuSample {
            gyro_rad_s: Vector3::from(gyro),
            accel_m_s2: Vector3::from(accel),
        }
    }

    #[test]
    fn the_statistic_by_hand() {
        let shoe = Shoe {
            window_s: 0.025,
            accel_m_s2: 2.0,
            gyro_rad_s: 0.5,
        };
        // 100 Hz: the window is the reading and its two neighbours.
        let times = [0.0, 0.01, 0.02];
        let readings = [
            reading([0.0; 3], [0.0, 0.0, 9.80665]),
            reading([0.5, 0.0, 0.0], [0.0, 0.0, 9.80665]),
            reading([0.0; 3], [0.0, 0.0, 9.80665 + 3.0]),
        ];
        let t = shoe.statistic(&times, &readings);
        // Reading 0's window: readings 0 and 1, mean specific force straight up: only the rate
        // counts, (0.5/0.5)² over 2 readings.
        assert!((t[0] - 0.5).abs() < 1e-12, "{}", t[0]);
        // Reading 1's window: all three; ā points up, so g·ā/‖ā‖ = (0, 0, g): the third reading
        // is 3 m/s² off, (3/2)² = 2.25; plus the rate's 1; over 3.
        assert!((t[1] - (2.25 + 1.0) / 3.0).abs() < 1e-12, "{}", t[1]);
        // Reading 2's window: readings 1 and 2, the rate's 1 and the force's 2.25, over 2.
        assert!((t[2] - (1.0 + 2.25) / 2.0).abs() < 1e-12, "{}", t[2]);
    }

    /// A foot turning at 10 rad/s about its vertical (sensor z, up) around a point 0.1 m
    /// ahead of the sensor (+x) that stands: the sensor swings on a circle about it, its specific
    /// force `(r ω², 0, g)` = (10, 0, g) m/s² and constant. By hand: about that point
    /// `c = f + ω × (ω × r) = (10 − 10, 0, g)`, gravity alone — 0; about the sensor itself `c = f`,
    /// whose length is √(100 + g²) = 14.006 m/s² against g along its own direction: 4.199 m/s²;
    /// the least of the two points is 0. Speeding the turn up by 50 rad/s² adds
    /// `ω̇ × r` = (0, 5, 0) m/s² about the sensor's point, and the point still stands.
    #[test]
    fn a_foot_turning_about_a_standing_point_has_it_still() {
        let shoe = Shoe::default();
        let times: Vec<f64> = (0..20).map(|i| i as f64 * 0.01).collect();
        let (w, r) = (10.0, 0.1);
        let turning: Vec<ImuSample> = times
            .iter()
            .map(|_| reading([0.0, 0.0, w], [r * w * w, 0.0, G_M_S2]))
            .collect();
        let pivot = Vector3::new(r, 0.0, 0.0);
        let about = |points: &[Vector3<f64>], readings: &[ImuSample]| {
            shoe.pivot_acceleration_m_s2(&times, readings, points)
        };
        let sensor_point = (100.0 + G_M_S2 * G_M_S2).sqrt() - G_M_S2;
        for (p, s) in about(&[pivot], &turning)
            .iter()
            .zip(about(&[Vector3::zeros()], &turning))
        {
            assert!(p.abs() < 1e-9, "{p}");
            assert!((s - sensor_point).abs() < 1e-9, "{s} vs {sensor_point}");
        }
        assert!(
            about(&[Vector3::zeros(), pivot], &turning)
                .iter()
                .all(|a| a.abs() < 1e-9)
        );
        // Speeding up: ω = 10 + 50 t about z; the sensor's tangential acceleration is
        // −(ω̇ × r) = (0, −5, 0) on top of the centripetal r ω².
        let speeding: Vec<ImuSample> = times
            .iter()
            .map(|t| {
                let w = w + 50.0 * t;
                reading([0.0, 0.0, w], [r * w * w, -50.0 * r, G_M_S2])
            })
            .collect();
        for a in about(&[pivot], &speeding) {
            assert!(a.abs() < 1e-9, "{a}");
        }
        assert!(about(&[], &turning).iter().all(|a| a.is_infinite()));
    }

    proptest::proptest! {
        /// Any readings at any increasing times, any frames: one value per frame (and one
        /// pivot acceleration per reading), never negative; and no panic.
        #[test]
        fn any_readings_give_one_value_per_frame(
            steps in proptest::collection::vec(1e-4f64..0.1, 1..40),
            values in proptest::collection::vec(-50.0f64..50.0, 240),
            frames in proptest::collection::vec(-0.5f64..5.0, 0..30),
            window_s in 0.0f64..0.2,
        ) {
            let times: Vec<f64> = steps.iter().scan(0.0, |t, d| { *t += d; Some(*t) }).collect();
            let readings: Vec<ImuSample> = (0..times.len())
                .map(|i| {
                    let v = &values[6 * i..6 * i + 6];
                    reading([v[0], v[1], v[2]], [v[3], v[4], v[5]])
                })
                .collect();
            let track = Track::new(times.clone(), readings.clone()).unwrap();
            let mut frames = frames;
            frames.sort_by(f64::total_cmp);
            let shoe = Shoe { window_s, ..Shoe::default() };
            let t = shoe.frame_statistic(&track, &frames);
            proptest::prop_assert_eq!(t.len(), frames.len());
            for v in t {
                proptest::prop_assert!(v >= 0.0, "{}", v);
            }
            let points = [Vector3::zeros(), Vector3::new(0.1, -0.05, 0.02)];
            let a = shoe.pivot_acceleration_m_s2(&times, &readings, &points);
            proptest::prop_assert_eq!(a.len(), times.len());
            for v in a {
                proptest::prop_assert!(v >= 0.0, "{}", v);
            }
        }
    }

    #[test]
    fn frames_take_the_readings_within_half_a_frame() {
        let shoe = Shoe {
            window_s: 0.0,
            ..Shoe::default()
        };
        let standing = reading([0.0; 3], [0.0, 9.80665, 0.0]);
        let turning = reading([0.0, 0.0, 2.0], [0.0, 9.80665, 0.0]);
        let times: Vec<f64> = (0..10).map(|i| i as f64 * 0.01).collect();
        let mut values = vec![standing; 10];
        values[4] = turning;
        let track = Track::new(times, values).unwrap();
        // Frames 0.02 s apart: the frame at 0.04 s has reading 4 (turning) within 0.01 s; the one
        // at 0.02 s has readings 1–3; the one at 0.5 s is past the readings.
        let frames = [0.0, 0.02, 0.04, 0.06, 0.08, 0.5];
        let still = |t: Vec<f64>| t.iter().map(|&t| t <= 1.0).collect::<Vec<_>>();
        assert_eq!(
            still(shoe.frame_statistic(&track, &frames)),
            [true, true, false, true, true, false]
        );
        // The readings 0.05 s apart, frames 0.02 s apart: a frame takes its nearest reading.
        let sparse = Track::new(vec![0.0, 0.05, 0.1], vec![standing, turning, standing]).unwrap();
        assert_eq!(
            still(shoe.frame_statistic(&sparse, &[0.0, 0.02, 0.045, 0.08])),
            [true, true, false, true]
        );
    }
}
