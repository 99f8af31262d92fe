//! The initial attitude of a filter from one accelerometer (and magnetometer) reading, in ENU:
//! at rest the accelerometer reads the specific force, which points up; the magnetic field's
//! horizontal part points north.

use nalgebra::{Matrix3, Rotation3, UnitQuaternion, Vector3};

/// `q_world_sensor` (ENU) whose up is `acc`'s direction and, with `mag`, whose north is the
/// field's horizontal direction (TRIAD); without `mag` (or with a field along the vertical),
/// the heading puts the sensor's x axis, projected on the horizontal, to the east. `None` for a
/// zero accelerometer reading.
pub fn attitude(acc: &Vector3<f64>, mag: Option<&Vector3<f64>>) -> Option<UnitQuaternion<f64>> {
    let up = acc.try_normalize(1e-9)?;
    let east = mag
        .and_then(|m| m.cross(&up).try_normalize(1e-6))
        .or_else(|| {
            // Any horizontal direction: the sensor's x (or y when x is vertical).
            let x = Vector3::x() - up * up.x;
            let y = Vector3::y() - up * up.y;
            x.try_normalize(1e-6).or_else(|| y.try_normalize(1e-6))
        })?;
    let north = up.cross(&east);
    // Rows are the world axes in sensor coordinates: R maps sensor vectors to world ones.
    let r = Matrix3::from_rows(&[east.transpose(), north.transpose(), up.transpose()]);
    Some(UnitQuaternion::from_rotation_matrix(
        &Rotation3::from_matrix_unchecked(r),
    ))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_sensor_turned_in_the_world_is_found_again() {
        // A sensor turned 30° about x, then 50° about the vertical (ENU).
        let truth = UnitQuaternion::from_axis_angle(&Vector3::z_axis(), 50f64.to_radians())
            * UnitQuaternion::from_axis_angle(&Vector3::x_axis(), 30f64.to_radians());
        let field = Vector3::new(0.0, 20.0, -40.0); // north and down (a northern dip)
        let acc = truth.inverse() * Vector3::new(0.0, 0.0, 9.81);
        let mag = truth.inverse() * field;
        let q = attitude(&acc, Some(&mag)).unwrap();
        assert!(q.angle_to(&truth) < 1e-12, "{}", q.angle_to(&truth));
        // Without the field the inclination is still right.
        let q6 = attitude(&acc, None).unwrap();
        assert!(((q6 * acc.normalize()) - Vector3::z()).norm() < 1e-12);
        assert!(attitude(&Vector3::zeros(), None).is_none());
    }
}
