//! VQF (Laidig & Seel 2023), through the `vqf-rs` crate, a port of the authors' C++ that
//! `tests/motion/fusion_reference.rs` checks sample by sample against PyPI's `vqf` (the authors' own
//! package): the accelerometer low-passed in an almost-inertial frame (time constant `tau_acc`),
//! gyro bias estimated at rest and in motion, the heading corrected slowly from the magnetometer
//! (`tau_mag`) with magnetic disturbances detected and rejected. Its quaternions are
//! `q_enu_sensor`.

use super::{Ahrs, Rejected};
use nalgebra::{Quaternion, UnitQuaternion, Vector3};
use vqf_rs::{Params, VQF};

/// The VQF parameters imubake exposes (the others keep the authors' defaults).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct VqfParams {
    pub tau_acc: f64,
    pub tau_mag: f64,
    pub rest_bias_estimation: bool,
    pub motion_bias_estimation: bool,
    pub mag_disturbance_rejection: bool,
}

impl Default for VqfParams {
    fn default() -> Self {
        let p = Params::default();
        VqfParams {
            tau_acc: p.tau_acc,
            tau_mag: p.tau_mag,
            rest_bias_estimation: p.rest_bias_est_enabled,
            motion_bias_estimation: p.motion_bias_est_enabled,
            mag_disturbance_rejection: p.mag_dist_rejection_enabled,
        }
    }
}

pub struct Vqf {
    filter: VQF,
    /// Whether the magnetometer is used (9D) or not (6D).
    nine_d: bool,
}

impl Vqf {
    /// A filter for samples every `sample_time_s` (the nominal period; each step may give its own).
    pub fn new(params: &VqfParams, sample_time_s: f64, nine_d: bool) -> Vqf {
        let p = Params {
            tau_acc: params.tau_acc,
            tau_mag: params.tau_mag,
            rest_bias_est_enabled: params.rest_bias_estimation,
            motion_bias_est_enabled: params.motion_bias_estimation,
            mag_dist_rejection_enabled: params.mag_disturbance_rejection,
            ..Params::default()
        };
        Vqf {
            filter: VQF::new(sample_time_s, None, None, Some(p)),
            nine_d,
        }
    }
}

impl Ahrs for Vqf {
    fn update(
        &mut self,
        gyr: &Vector3<f64>,
        acc: &Vector3<f64>,
        mag: Option<&Vector3<f64>>,
        dt: f64,
    ) {
        self.filter.update_gyr_with_ts([gyr.x, gyr.y, gyr.z], dt);
        self.filter.update_acc([acc.x, acc.y, acc.z]);
        if let (true, Some(m)) = (self.nine_d, mag) {
            self.filter.update_mag([m.x, m.y, m.z]);
        }
    }

    fn orientation(&self) -> UnitQuaternion<f64> {
        let q = if self.nine_d {
            self.filter.quat_9d()
        } else {
            self.filter.quat_6d()
        };
        UnitQuaternion::new_normalize(Quaternion::new(q.0, q.1, q.2, q.3))
    }

    fn gyro_bias(&self) -> Option<Vector3<f64>> {
        let (b, _) = self.filter.bias_estimate();
        Some(Vector3::new(b[0], b[1], b[2]))
    }

    fn rejected(&self) -> Rejected {
        Rejected {
            magnetic: self.nine_d && self.filter.mag_dist_detected(),
            acceleration: false,
        }
    }
}
