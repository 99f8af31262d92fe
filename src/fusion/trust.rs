//! Paper 000's trust blend (chapter III): two estimates of the sensor's attitude each step —
//! **A**, the previous estimate propagated by the gyroscope, and **B**, the attitude the
//! accelerometer and magnetometer give alone — and a "trust" τ in [0, 1] that moves the estimate
//! from B towards A: `q = slerp(q_B, q_A, τ)`.
//!
//! - Gyro trust, per axis from the rate's magnitude on that axis: a quadratic that is 0 at rest
//!   (gyro noise), 1 at its peak and 0.5 at the gyro's range `ω_max` (a saturated reading is half
//!   believed): `f(ω) = 1 − (ω − ω_v)² / ω_v²` with `ω_v = ω_max / (1 + 1/√2)`, clamped to [0, 1];
//!   the three axes averaged.
//! - Accelerometer trust, paper 000's eq. 1 with `g` in units of standard gravity:
//!   `1 − 1 / (1 + |1 − ‖g‖|)²⁰` — 0 when the accelerometer reads exactly 1 g (B is reliable),
//!   near 1 as soon as it departs from it (the body accelerates: trust the gyro).
//! - τ is the mean of the two.
//!
//! The paper states its blend on spherical angles of one direction vector; this reading applies
//! the same weights to the whole attitude (a slerp), which keeps the heading as well. Without a
//! magnetometer, B keeps A's heading (its inclination alone comes from the accelerometer).

use super::{Ahrs, init::attitude};
use crate::rotation::slerp_shortest;
use nalgebra::{UnitQuaternion, Vector3};

/// Standard gravity, m/s².
const G: f64 = 9.80665;

#[derive(Debug, Clone)]
pub struct Trust {
    /// The gyro's range, rad/s (where its trust is back to 0.5).
    pub max_rate: f64,
    q: UnitQuaternion<f64>,
    /// Steps where the accelerometer's trust was below one half (B leaned on), and all steps.
    acc_distrusted: bool,
}

impl Trust {
    pub fn new(max_rate: f64, q0_enu: UnitQuaternion<f64>) -> Trust {
        Trust {
            max_rate,
            q: q0_enu,
            acc_distrusted: false,
        }
    }

    /// The gyro trust for one axis' rate (rad/s).
    pub fn gyro_trust(&self, rate: f64) -> f64 {
        let peak = self.max_rate / (1.0 + std::f64::consts::FRAC_1_SQRT_2);
        (1.0 - (rate.abs() - peak).powi(2) / (peak * peak)).clamp(0.0, 1.0)
    }

    /// Paper 000's eq. 1, `acc` in m/s².
    pub fn acc_trust(acc: &Vector3<f64>) -> f64 {
        let g = acc.norm() / G;
        1.0 - 1.0 / (1.0 + (1.0 - g).abs()).powi(20)
    }
}

impl Ahrs for Trust {
    fn update(
        &mut self,
        gyr: &Vector3<f64>,
        acc: &Vector3<f64>,
        mag: Option<&Vector3<f64>>,
        dt: f64,
    ) {
        let a = self.q * UnitQuaternion::from_scaled_axis(gyr * dt);
        let b = match mag {
            Some(m) => attitude(acc, Some(m)),
            None => attitude(acc, None).map(|b| {
                // Keep A's heading: turn B about the vertical onto it.
                let fwd = |q: &UnitQuaternion<f64>| {
                    let v = q * Vector3::y();
                    v.y.atan2(v.x)
                };
                UnitQuaternion::from_axis_angle(&Vector3::z_axis(), fwd(&a) - fwd(&b)) * b
            }),
        };
        let Some(b) = b else {
            self.q = a;
            return;
        };
        let gyro = (gyr.iter().map(|w| self.gyro_trust(*w)).sum::<f64>()) / 3.0;
        let acc_trust = Self::acc_trust(acc);
        self.acc_distrusted = acc_trust > 0.5;
        let tau = 0.5 * (gyro + acc_trust);
        self.q = slerp_shortest(&b, &a, tau);
    }

    fn orientation(&self) -> UnitQuaternion<f64> {
        self.q
    }

    fn rejected(&self) -> super::Rejected {
        super::Rejected {
            magnetic: false,
            acceleration: self.acc_distrusted,
        }
    }
}
