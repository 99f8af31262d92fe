//! Gyroscope integration only (paper 004): the attitude from the first accelerometer and
//! magnetometer reading, then `q ← q ⊗ exp(½ ω Δt)` — no correction, so it drifts with the gyro's
//! bias; paper 004 bounds that by calibrating the gyroscope (see `calibrate-sensors`).

use super::Ahrs;
use nalgebra::{UnitQuaternion, Vector3};

#[derive(Debug, Clone)]
pub struct GyroIntegration {
    q: UnitQuaternion<f64>,
}

impl GyroIntegration {
    pub fn new(q0_enu: UnitQuaternion<f64>) -> GyroIntegration {
        GyroIntegration { q: q0_enu }
    }
}

impl Ahrs for GyroIntegration {
    fn update(
        &mut self,
        gyr: &Vector3<f64>,
        _acc: &Vector3<f64>,
        _mag: Option<&Vector3<f64>>,
        dt: f64,
    ) {
        self.q *= UnitQuaternion::from_scaled_axis(gyr * dt);
        self.q.renormalize();
    }

    fn orientation(&self) -> UnitQuaternion<f64> {
        self.q
    }
}
