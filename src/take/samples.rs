//! Sample types of sensor streams.

use nalgebra::{UnitQuaternion, Vector3};

/// Yaw, pitch, roll in degrees: intrinsic Z-Y-X, R = Rz(yaw) · Ry(pitch) · Rx(roll).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct YawPitchRollDeg {
    pub yaw: f64,
    pub pitch: f64,
    pub roll: f64,
}

impl YawPitchRollDeg {
    pub fn to_quaternion(self) -> UnitQuaternion<f64> {
        let z = UnitQuaternion::from_axis_angle(&Vector3::z_axis(), self.yaw.to_radians());
        let y = UnitQuaternion::from_axis_angle(&Vector3::y_axis(), self.pitch.to_radians());
        let x = UnitQuaternion::from_axis_angle(&Vector3::x_axis(), self.roll.to_radians());
        z * y * x
    }
}

/// One raw inertial reading in SI units, sensor frame.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ImuSample {
    pub gyro_rad_s: Vector3<f64>,
    pub accel_m_s2: Vector3<f64>,
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn yaw_pitch_roll_is_intrinsic_zyx() {
        // Hand calculation: yaw 90° about z maps sensor x to world y; a following pitch of 90°
        // about the new y tips sensor x down to world -z (x → -z under Ry(90°)), then Rz keeps it.
        let q = YawPitchRollDeg {
            yaw: 90.0,
            pitch: 90.0,
            roll: 0.0,
        }
        .to_quaternion();
        let x = q * Vector3::x();
        assert!((x - Vector3::new(0.0, 0.0, -1.0)).norm() < 1e-12, "{x}");
        // Roll 90° about x maps sensor y to world z when yaw = pitch = 0.
        let q = YawPitchRollDeg {
            yaw: 0.0,
            pitch: 0.0,
            roll: 90.0,
        }
        .to_quaternion();
        assert!((q * Vector3::y() - Vector3::z()).norm() < 1e-12);
        // Rz(90°)·Rx(90°)·z = Rz(90°)·(-y) = x.
        let q = YawPitchRollDeg {
            yaw: 90.0,
            pitch: 0.0,
            roll: 90.0,
        }
        .to_quaternion();
        assert!((q * Vector3::z() - Vector3::x()).norm() < 1e-12);
    }
}
