//! Madgwick's gradient-descent filter (Madgwick 2010; paper 002 §6.1.1): the gyroscope's
//! quaternion rate `q̇_ω = ½ q ⊗ (0, ω)`, corrected against the normalised gradient of the
//! error between the measured and predicted directions of gravity (and of the magnetic field),
//! `q̇ = q̇_ω − β ∇f/‖∇f‖`, integrated `q ← normalise(q + q̇ Δt)`.
//!
//! The textbook filter estimates `q_nwu_sensor`: its reference field is `(b_x, 0, b_z)`, north
//! along x (NWU). This core runs the textbook equations (as PyPI `ahrs`' `Madgwick` does, term for
//! term) and hands out `q_enu_sensor = R_z(90°) ⊗ q_nwu_sensor`, so a forgotten frame cannot turn
//! every heading by 90°.

use super::{Ahrs, nwu_to_enu};
use nalgebra::{Matrix4x3, Matrix6x4, Quaternion, UnitQuaternion, Vector3, Vector4, Vector6};

/// Madgwick's filter (see the module documentation).
#[derive(Debug, Clone)]
pub struct Madgwick {
    /// The gain β, rad/s.
    pub beta: f64,
    /// `q_nwu_sensor` (w, x, y, z as nalgebra's Quaternion: w first in `new`).
    q: Quaternion<f64>,
}

impl Madgwick {
    /// A filter starting at `q_enu_sensor`.
    pub fn new(beta: f64, q0_enu: UnitQuaternion<f64>) -> Madgwick {
        Madgwick {
            beta,
            q: (nwu_to_enu().inverse() * q0_enu).into_inner(),
        }
    }

    /// The textbook state, `q_nwu_sensor`.
    pub fn q_nwu(&self) -> UnitQuaternion<f64> {
        UnitQuaternion::new_normalize(self.q)
    }
}

impl Ahrs for Madgwick {
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
        let mut q_dot = q * Quaternion::from_parts(0.0, *gyr) * 0.5;
        let a_norm = acc.norm();
        if a_norm > 0.0 {
            let a = acc / a_norm;
            let (qw, qx, qy, qz) = (q.w, q.i, q.j, q.k);
            let gradient = match mag.filter(|m| m.norm() > 0.0) {
                Some(m) => {
                    let m = m / m.norm();
                    // The field in the world frame: h = q ⊗ m ⊗ q*.
                    let h = q * Quaternion::from_parts(0.0, m) * q.conjugate();
                    let bx = (h.i * h.i + h.j * h.j).sqrt();
                    let bz = h.k;
                    let f = Vector6::new(
                        2.0 * (qx * qz - qw * qy) - a.x,
                        2.0 * (qw * qx + qy * qz) - a.y,
                        2.0 * (0.5 - qx * qx - qy * qy) - a.z,
                        2.0 * bx * (0.5 - qy * qy - qz * qz) + 2.0 * bz * (qx * qz - qw * qy) - m.x,
                        2.0 * bx * (qx * qy - qw * qz) + 2.0 * bz * (qw * qx + qy * qz) - m.y,
                        2.0 * bx * (qw * qy + qx * qz) + 2.0 * bz * (0.5 - qx * qx - qy * qy) - m.z,
                    );
                    if f.norm() == 0.0 {
                        None
                    } else {
                        #[rustfmt::skip]
                        let j = Matrix6x4::new(
                            -2.0 * qy, 2.0 * qz, -2.0 * qw, 2.0 * qx,
                            2.0 * qx, 2.0 * qw, 2.0 * qz, 2.0 * qy,
                            0.0, -4.0 * qx, -4.0 * qy, 0.0,
                            -2.0 * bz * qy, 2.0 * bz * qz, -4.0 * bx * qy - 2.0 * bz * qw, -4.0 * bx * qz + 2.0 * bz * qx,
                            -2.0 * bx * qz + 2.0 * bz * qx, 2.0 * bx * qy + 2.0 * bz * qw, 2.0 * bx * qx + 2.0 * bz * qz, -2.0 * bx * qw + 2.0 * bz * qy,
                            2.0 * bx * qy, 2.0 * bx * qz - 4.0 * bz * qx, 2.0 * bx * qw - 4.0 * bz * qy, 2.0 * bx * qx,
                        );
                        Some(j.transpose() * f)
                    }
                }
                None => {
                    let f = Vector3::new(
                        2.0 * (qx * qz - qw * qy) - a.x,
                        2.0 * (qw * qx + qy * qz) - a.y,
                        2.0 * (0.5 - qx * qx - qy * qy) - a.z,
                    );
                    if f.norm() == 0.0 {
                        None
                    } else {
                        #[rustfmt::skip]
                        let j = Matrix4x3::new(
                            -2.0 * qy, 2.0 * qx, 0.0,
                            2.0 * qz, 2.0 * qw, -4.0 * qx,
                            -2.0 * qw, 2.0 * qz, -4.0 * qy,
                            2.0 * qx, 2.0 * qy, 0.0,
                        );
                        Some(j * f)
                    }
                }
            };
            if let Some(g) = gradient.map(|g: Vector4<f64>| g / g.norm()) {
                // The gradient's components are (w, x, y, z).
                q_dot -= Quaternion::new(g[0], g[1], g[2], g[3]) * self.beta;
            }
        }
        let q_new = q + q_dot * dt;
        self.q = q_new / q_new.norm();
    }

    fn orientation(&self) -> UnitQuaternion<f64> {
        nwu_to_enu() * self.q_nwu()
    }
}
