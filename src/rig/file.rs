//! Rig files (YAML or JSON) and the built-in rigs.
//!
//! ```yaml
//! name: mixamo
//! units: m                 # m | cm
//! order: ZYX               # default channel order of every joint (BVH naming)
//! joints:                  # parents before children; the first joint is the root
//!   - {name: Hips, offset: [0, 1.0, 0]}
//!   - {name: Spine, parent: Hips, offset: [0, 0.1, 0]}
//!   - {name: Head, parent: Neck, offset: [0, 0.1, 0], end_site: [0, 0.15, 0], order: ZXY}
//! poses:                   # local rotations per joint; unnamed joints keep identity
//!   npose:
//!     LeftArm: {axis: [0, 0, 1], angle_deg: -90}
//!     RightArm: [0.7071068, 0, 0, 0.7071068]   # quaternion w, x, y, z
//! ```

use super::{Joint, LengthUnit, Rig, RigError};
use crate::rotation::EulerOrder;
use nalgebra::{Quaternion, Unit, UnitQuaternion, Vector3};
use serde::Deserialize;
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

/// The built-in rigs: name, rig file text.
pub const BUILTIN: [(&str, &str); 2] = [
    ("mixamo", include_str!("../../rigs/mixamo.yaml")),
    ("sou12", include_str!("../../rigs/sou12.yaml")),
];

#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RigFile {
    pub name: String,
    #[serde(default)]
    pub units: LengthUnit,
    #[serde(default = "default_order")]
    pub order: EulerOrder,
    pub joints: Vec<JointEntry>,
    #[serde(default)]
    pub poses: BTreeMap<String, BTreeMap<String, RotationEntry>>,
    /// Anatomical landmarks → joints, for `imubake angles` on rigs its table does not know.
    #[serde(default)]
    pub segments: BTreeMap<String, String>,
    /// Joints → Unity humanoid bone names, for `imubake live`'s VMC output.
    #[serde(default)]
    pub vmc_names: BTreeMap<String, String>,
}

fn default_order() -> EulerOrder {
    EulerOrder::ZYX
}

#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct JointEntry {
    pub name: String,
    #[serde(default)]
    pub parent: Option<String>,
    pub offset: [f64; 3],
    #[serde(default)]
    pub order: Option<EulerOrder>,
    #[serde(default)]
    pub end_site: Option<[f64; 3]>,
}

/// A rotation in a rig or mapping file: a quaternion `[w, x, y, z]` or an axis and an angle.
#[derive(Debug, Clone, Deserialize)]
#[serde(untagged)]
pub enum RotationEntry {
    Quaternion([f64; 4]),
    AxisAngle { axis: [f64; 3], angle_deg: f64 },
}

impl RotationEntry {
    pub fn to_quaternion(&self) -> Result<UnitQuaternion<f64>, String> {
        match self {
            RotationEntry::Quaternion([w, x, y, z]) => {
                let q = Quaternion::new(*w, *x, *y, *z);
                let n = q.norm();
                if !n.is_finite() || n < 1e-9 {
                    return Err(format!(
                        "[{w}, {x}, {y}, {z}] is not a rotation quaternion (w, x, y, z)"
                    ));
                }
                Ok(UnitQuaternion::from_quaternion(q))
            }
            RotationEntry::AxisAngle { axis, angle_deg } => {
                let axis = Vector3::from(*axis);
                let unit = Unit::try_new(axis, 1e-9)
                    .filter(|_| angle_deg.is_finite())
                    .ok_or_else(|| {
                        format!("axis {axis:?} with angle {angle_deg}° is not a rotation")
                    })?;
                Ok(UnitQuaternion::from_axis_angle(
                    &unit,
                    angle_deg.to_radians(),
                ))
            }
        }
    }
}

#[derive(Debug, thiserror::Error)]
pub enum RigLoadError {
    #[error("{}: cannot read: {source}", .path.display())]
    Io {
        path: PathBuf,
        #[source]
        source: std::io::Error,
    },
    #[error("{}: {message}", .path.display())]
    Parse { path: PathBuf, message: String },
    #[error("{}: {source}", .path.display())]
    Invalid {
        path: PathBuf,
        #[source]
        source: RigError,
    },
    #[error(
        "unknown rig `{0}`; expected a built-in rig (mixamo, sou12) or a rig file (.yaml, .json, .bvh)"
    )]
    Unknown(String),
}

impl RigFile {
    pub fn into_rig(self) -> Result<Rig, RigError> {
        let mut index = BTreeMap::new();
        let mut joints = Vec::with_capacity(self.joints.len());
        for (i, j) in self.joints.iter().enumerate() {
            let parent = match &j.parent {
                None => None,
                Some(p) => Some(
                    *index
                        .get(p.as_str())
                        .ok_or_else(|| RigError::UnknownParent {
                            joint: j.name.clone(),
                            parent: p.clone(),
                        })?,
                ),
            };
            joints.push(Joint {
                name: j.name.clone(),
                parent,
                offset: Vector3::from(j.offset),
                order: j.order.unwrap_or(self.order),
                end_site: j.end_site.map(Vector3::from),
            });
            index.insert(j.name.as_str(), i);
        }
        let mut rig = Rig::new(self.name, self.units, joints)?;
        for (pose, rotations) in &self.poses {
            let mut list = Vec::new();
            for (joint, rotation) in rotations {
                let q = rotation.to_quaternion().map_err(|_| RigError::PoseJoint {
                    pose: pose.clone(),
                    joint: joint.clone(),
                })?;
                list.push((joint.clone(), q));
            }
            rig.set_pose(pose, &list)?;
        }
        for (landmark, joint) in &self.segments {
            rig.set_segment(landmark, joint)?;
        }
        for (joint, unity) in &self.vmc_names {
            rig.set_vmc_name(joint, unity)?;
        }
        Ok(rig)
    }
}

impl crate::diagnostic::Diagnostic for RigLoadError {
    fn file(&self) -> Option<&Path> {
        match self {
            RigLoadError::Io { path, .. }
            | RigLoadError::Parse { path, .. }
            | RigLoadError::Invalid { path, .. } => Some(path),
            RigLoadError::Unknown(_) => None,
        }
    }

    fn hint(&self) -> Option<&'static str> {
        Some("check --rig (README, Rigs)")
    }
}

/// Parses rig text (YAML, of which JSON is a subset).
pub fn parse_rig(text: &str, path: &Path) -> Result<Rig, RigLoadError> {
    let file: RigFile = serde_yaml::from_str(text).map_err(|e| RigLoadError::Parse {
        path: path.to_path_buf(),
        message: format!("{e}; expected a rig file (README, \"Rigs\")"),
    })?;
    file.into_rig().map_err(|source| RigLoadError::Invalid {
        path: path.to_path_buf(),
        source,
    })
}

/// A BVH file's hierarchy as a rig, its frames as poses `frame:N`. BVH has no unit: a rig whose
/// zero pose spans more than 3 units along any axis is taken to be in centimetres, else metres
/// (any axis: a zero pose need not stand).
pub fn bvh_rig(bytes: &[u8], path: &Path) -> Result<Rig, RigLoadError> {
    let bvh = crate::bvh::parse(bytes).map_err(|e| RigLoadError::Parse {
        path: path.to_path_buf(),
        message: format!("{e}; expected a BVH file"),
    })?;
    let name = path
        .file_stem()
        .map_or("bvh".to_string(), |s| s.to_string_lossy().into_owned());
    let invalid = |source| RigLoadError::Invalid {
        path: path.to_path_buf(),
        source,
    };
    let probe = bvh.to_rig(&name, LengthUnit::Metres).map_err(invalid)?;
    let rest = probe.rest_positions();
    let span = (0..3)
        .map(|axis| {
            let along = rest.iter().map(|p| p[axis]);
            along.clone().fold(f64::NEG_INFINITY, f64::max) - along.fold(f64::INFINITY, f64::min)
        })
        .fold(0.0, f64::max);
    let units = if span > 3.0 {
        LengthUnit::Centimetres
    } else {
        LengthUnit::Metres
    };
    let mut rig = bvh.to_rig(&name, units).map_err(invalid)?;
    rig.set_frame_poses(
        (0..bvh.frame_count())
            .map(|f| bvh.local_rotations(f))
            .collect(),
    );
    Ok(rig)
}

/// A built-in rig (`mixamo`, `sou12`) by name, `None` for any other name.
pub fn builtin_rig(name: &str) -> Option<Result<Rig, RigLoadError>> {
    BUILTIN
        .iter()
        .find(|(n, _)| *n == name)
        .map(|(name, text)| parse_rig(text, Path::new(&format!("rigs/{name}.yaml"))))
}

/// A rig file's bytes as a rig: a `.bvh` file's hierarchy, else a YAML or JSON rig file. Reading
/// the file is the caller's (`convert::Plan` reads and hashes it once).
pub fn rig_from_bytes(path: &Path, bytes: Vec<u8>) -> Result<Rig, RigLoadError> {
    if path
        .extension()
        .is_some_and(|e| e.eq_ignore_ascii_case("bvh"))
    {
        return bvh_rig(&bytes, path);
    }
    let text = String::from_utf8(bytes).map_err(|_| RigLoadError::Parse {
        path: path.to_path_buf(),
        message: "not UTF-8 text; expected a YAML or JSON rig file".into(),
    })?;
    parse_rig(&text, path)
}

/// Loads a rig by built-in name (`mixamo`, `sou12`), from a `.yaml`/`.json` rig file, or from
/// a `.bvh` file's hierarchy.
pub fn load_rig(name_or_path: &str) -> Result<Rig, RigLoadError> {
    if let Some(rig) = builtin_rig(name_or_path) {
        return rig;
    }
    let path = Path::new(name_or_path);
    if !path.exists() {
        return Err(RigLoadError::Unknown(name_or_path.to_string()));
    }
    let bytes = std::fs::read(path).map_err(|source| RigLoadError::Io {
        path: path.to_path_buf(),
        source,
    })?;
    rig_from_bytes(path, bytes)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn builtin_rigs_load() {
        let m = load_rig("mixamo").unwrap();
        assert_eq!(m.name(), "mixamo");
        assert_eq!(m.units(), LengthUnit::Metres);
        let s = load_rig("sou12").unwrap();
        assert_eq!(s.name(), "sou12");
        assert!(matches!(load_rig("nope"), Err(RigLoadError::Unknown(_))));
    }

    #[test]
    fn a_bvh_hierarchy_is_a_rig_with_frame_poses() {
        // Root 1 unit tall → metres; one frame with the child turned 90° about Z.
        let text = "HIERARCHY\nROOT A\n{\n OFFSET 0 1 0\n CHANNELS 6 Xposition Yposition Zposition Zrotation Xrotation Yrotation\n JOINT B\n {\n  OFFSET 0 0.5 0\n  CHANNELS 3 Zrotation Xrotation Yrotation\n  End Site\n  {\n   OFFSET 0 0.5 0\n  }\n }\n}\nMOTION\nFrames: 1\nFrame Time: 0.1\n0 1 0 0 0 0 90 0 0\n";
        let rig = bvh_rig(text.as_bytes(), Path::new("two.bvh")).unwrap();
        assert_eq!(rig.name(), "two");
        assert_eq!(rig.units(), LengthUnit::Metres);
        assert_eq!(rig.joints()[1].order, EulerOrder::ZXY);
        let pose = rig.pose("frame:0").unwrap();
        assert!((pose.local[1].angle().to_degrees() - 90.0).abs() < 1e-9);
        assert!(rig.pose("frame:1").is_none());
        assert!(rig.pose_names().iter().any(|n| n.contains("frame:0")));
    }

    #[test]
    fn schema_errors_name_the_problem() {
        let bad = "name: x\njoints:\n  - {name: a, offset: [0,0,0]}\n  - {name: b, parent: c, offset: [0,1,0]}\n";
        let e = parse_rig(bad, Path::new("bad.yaml"))
            .unwrap_err()
            .to_string();
        assert!(e.contains("bad.yaml") && e.contains("`c`"), "{e}");
        let typo = "name: x\njoints:\n  - {name: a, ofset: [0,0,0]}\n";
        let e = parse_rig(typo, Path::new("t.yaml"))
            .unwrap_err()
            .to_string();
        assert!(e.contains("ofset"), "{e}");
    }
}
