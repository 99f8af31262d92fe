//! Mahony's explicit complementary filter (Mahony et al. 2008): the measured directions of
//! gravity `a` and of the magnetic field `m` against their predictions `v_a = R(q)ᵀ ẑ` and
//! `v_m = R(q)ᵀ (0, ‖h_xy‖, h_z)` (`h = R(q) m`, the field in the world), the error
//! `ω_mes = a × v_a + m × v_m`, a gyro bias `ḃ = −k_I ω_mes`, the corrected rate
//! `Ω = ω − b + k_P ω_mes`, integrated `q ← normalise(q + ½ q ⊗ (0, Ω) Δt)`. The reference field
//! has north along y and up along z: the filter estimates `q_enu_sensor` directly (PyPI `ahrs`'
//! `Mahony`, term for term).

use super::Ahrs;
use nalgebra::{Quaternion, UnitQuaternion, Vector3};

/// Mahony's filter (see the module documentation).
#[derive(Debug, Clone)]
pub struct Mahony {
    pub kp: f64,
    pub ki: f64,
    q: Quaternion<f64>,
    /// The gyro bias estimate, rad/s.
    bias: Vector3<f64>,
}

impl Mahony {
    pub fn new(kp: f64, ki: f64, q0_enu: UnitQuaternion<f64>) -> Mahony {
        Mahony {
            kp,
            ki,
            q: q0_enu.into_inner(),
            bias: Vector3::zeros(),
        }
    }
}

impl Ahrs for Mahony {
    fn update(
        &mut self,
        gyr: &Vector3<f64>,
        acc: &Vector3<f64>,
        mag: Option<&Vector3<f64>>,
        dt: f64,
    ) {
        if gyr.norm() == 0.0 {
            return;
        }
        let q = self.q / self.q.norm();
        let mut omega = *gyr;
        let a_norm = acc.norm();
        if a_norm > 0.0 {
            let a = acc / a_norm;
            let r = UnitQuaternion::new_unchecked(q)
                .to_rotation_matrix()
                .into_inner();
            let v_a = r.transpose() * Vector3::z();
            let mut omega_mes = a.cross(&v_a);
            if let Some(m) = mag.filter(|m| m.norm() > 0.0) {
                let m = m / m.norm();
                let h = r * m;
                let v_m = r.transpose() * Vector3::new(0.0, (h.x * h.x + h.y * h.y).sqrt(), h.z);
                let v_m = v_m / v_m.norm();
                omega_mes += m.cross(&v_m);
            }
            self.bias += -self.ki * omega_mes * dt;
            omega = omega - self.bias + self.kp * omega_mes;
        }
        let q_new = q + q * Quaternion::from_parts(0.0, omega) * (0.5 * dt);
        self.q = q_new / q_new.norm();
    }

    fn orientation(&self) -> UnitQuaternion<f64> {
        UnitQuaternion::new_normalize(self.q)
    }

    fn gyro_bias(&self) -> Option<Vector3<f64>> {
        Some(self.bias)
    }
}
