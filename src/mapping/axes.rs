//! Axis strings: `+x` (one signed axis) and `+y-x+z` (a mount: the sensor's x, y, z axes given
//! in the bone frame).

use nalgebra::{Matrix3, Rotation3, UnitQuaternion, Vector3};

/// Parses one signed axis: `+x`, `-y`, `z` (sign optional, `+` by default).
pub fn parse_axis(s: &str) -> Result<Vector3<f64>, String> {
    let axes = parse_signed_axes(s.trim())?;
    match axes.as_slice() {
        [v] => Ok(*v),
        _ => Err(format!("`{s}`: expected one axis such as +x, -y or +z")),
    }
}

fn parse_signed_axes(s: &str) -> Result<Vec<Vector3<f64>>, String> {
    let mut out = Vec::new();
    let mut sign = None;
    for c in s.chars() {
        match c {
            '+' | '-' if sign.is_none() => sign = Some(if c == '+' { 1.0 } else { -1.0 }),
            'x' | 'y' | 'z' | 'X' | 'Y' | 'Z' => {
                let mut v = Vector3::zeros();
                v[(c.to_ascii_lowercase() as u8 - b'x') as usize] = sign.take().unwrap_or(1.0);
                out.push(v);
            }
            ' ' => {}
            _ => {
                return Err(format!(
                    "`{s}`: unexpected `{c}`; expected axes such as +y-x+z"
                ));
            }
        }
    }
    if sign.is_some() {
        return Err(format!("`{s}`: a sign without an axis"));
    }
    Ok(out)
}

/// Parses a mount axis string into q_bone_sensor: `+y-x+z` says sensor x = bone +y, sensor y =
/// bone −x, sensor z = bone +z (the columns of the rotation matrix).
pub fn parse_mount_axes(s: &str) -> Result<UnitQuaternion<f64>, String> {
    let axes = parse_signed_axes(s)?;
    if axes.len() != 3 {
        return Err(format!(
            "`{s}`: expected three signed axes (the sensor's x, y, z in the bone frame), e.g. +y-x+z"
        ));
    }
    let m = Matrix3::from_columns(&[axes[0], axes[1], axes[2]]);
    let det = m.determinant();
    if det.abs() < 0.5 {
        return Err(format!(
            "`{s}`: an axis is repeated; each of x, y, z must appear once"
        ));
    }
    if det < 0.0 {
        return Err(format!(
            "`{s}`: the axes are left-handed (a mirror, not a rotation); flip the sign of one axis"
        ));
    }
    Ok(UnitQuaternion::from_rotation_matrix(
        &Rotation3::from_matrix_unchecked(m),
    ))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn axes() {
        assert_eq!(parse_axis("+x").unwrap(), Vector3::x());
        assert_eq!(parse_axis("-z").unwrap(), -Vector3::z());
        assert_eq!(parse_axis("y").unwrap(), Vector3::y());
        assert!(parse_axis("+x+y").is_err());
        assert!(parse_axis("+w").is_err());
        assert!(parse_axis("-").is_err());
        let q = parse_mount_axes("+x+y+z").unwrap();
        assert!(q.angle() < 1e-12);
        // "-x-y+z": 180° about z.
        let q = parse_mount_axes("-x-y+z").unwrap();
        assert!((q.angle() - std::f64::consts::PI).abs() < 1e-12);
        assert!(parse_mount_axes("+x+y").is_err());
    }
}
