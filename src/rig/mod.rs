//! Rigs: a joint hierarchy with offsets, per-joint Euler channel order, end sites and named poses.
//!
//! Joint frames follow BVH: at the rest pose every joint frame is parallel to the rig world
//! (Y-up, facing +Z, +X on the character's left), so rest rotations are identity and a pose is
//! the local rotation of each joint. Rig files are YAML or JSON (schema in README, "Rigs"); any
//! BVH file's hierarchy serves as a rig too.

pub mod anatomy;
pub mod file;
pub mod names;
pub mod subject;

mod bvh;

pub use file::{RigFile, builtin_rig, load_rig, rig_from_bytes};

use crate::rotation::EulerOrder;
use nalgebra::{UnitQuaternion, Vector3};
use serde::{Deserialize, Serialize};
use std::collections::BTreeMap;

/// The length unit of a rig's offsets.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, Default)]
pub enum LengthUnit {
    #[default]
    #[serde(rename = "m")]
    Metres,
    #[serde(rename = "cm")]
    Centimetres,
}

impl LengthUnit {
    pub fn metres_per_unit(self) -> f64 {
        match self {
            LengthUnit::Metres => 1.0,
            LengthUnit::Centimetres => 0.01,
        }
    }

    pub fn name(self) -> &'static str {
        match self {
            LengthUnit::Metres => "m",
            LengthUnit::Centimetres => "cm",
        }
    }
}

/// One joint of a rig.
#[derive(Debug, Clone, PartialEq)]
pub struct Joint {
    pub name: String,
    /// Index of the parent joint; `None` only for the root (index 0).
    pub parent: Option<usize>,
    /// From the parent joint to this one, in the rig's unit, rig world axes (rest pose).
    pub offset: Vector3<f64>,
    /// Channel order of this joint's rotation in BVH output.
    pub order: EulerOrder,
    /// The end of a leaf bone, relative to this joint, when the rig defines one.
    pub end_site: Option<Vector3<f64>>,
}

/// A pose: the local rotation of every joint (identity = rest).
#[derive(Debug, Clone, PartialEq)]
pub struct Pose {
    pub local: Vec<UnitQuaternion<f64>>,
}

#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum RigError {
    #[error("a rig needs at least one joint")]
    NoJoints,
    #[error("joint `{0}` appears twice")]
    DuplicateJoint(String),
    #[error("joint `{joint}`: parent `{parent}` is not defined before it")]
    UnknownParent { joint: String, parent: String },
    #[error("joint `{0}` has no parent; only the first joint (the root) may have none")]
    SecondRoot(String),
    #[error("joint `{0}`: offset or end site is not finite")]
    NonFinite(String),
    #[error("pose `{pose}`: unknown joint `{joint}`")]
    PoseJoint { pose: String, joint: String },
    #[error("vmc_names: `{0}` is not a joint of the rig")]
    VmcJoint(String),
    #[error("segments: `{landmark}` names `{joint}`, which is not a joint of the rig")]
    SegmentJoint { landmark: String, joint: String },
    #[error("segments: `{landmark}` is no body part; the parts are {known}")]
    UnknownLandmark { landmark: String, known: String },
}

/// A validated joint hierarchy: joint 0 is the root, every parent comes before its children,
/// names are unique, offsets are finite.
#[derive(Debug, Clone, PartialEq)]
pub struct Rig {
    name: String,
    units: LengthUnit,
    joints: Vec<Joint>,
    poses: BTreeMap<String, Pose>,
    /// Local rotations per frame of a BVH rig's motion: the poses `frame:N`.
    frame_poses: Vec<Vec<UnitQuaternion<f64>>>,
    /// Anatomical landmarks named by the rig file (`segments:`, landmark → joint), for rigs the
    /// analysis's own table does not know.
    segments: BTreeMap<String, usize>,
    /// Unity humanoid bone names for VMC (`vmc_names:`, joint → name).
    vmc_names: BTreeMap<String, String>,
}

/// The prefix Mixamo puts before its bone names; names match with or without it.
pub const MIXAMO_PREFIX: &str = "mixamorig:";

fn strip_prefix(name: &str) -> &str {
    // Mixamo exports use `mixamorig:`, `mixamorig1:` ... and some tools `mixamorig_`.
    match name.find(':') {
        Some(i) if name[..i].starts_with("mixamorig") => &name[i + 1..],
        _ => name.strip_prefix("mixamorig_").unwrap_or(name),
    }
}

impl Rig {
    pub fn new(
        name: impl Into<String>,
        units: LengthUnit,
        joints: Vec<Joint>,
    ) -> Result<Rig, RigError> {
        if joints.is_empty() {
            return Err(RigError::NoJoints);
        }
        let mut seen = std::collections::HashSet::new();
        for (i, j) in joints.iter().enumerate() {
            if !seen.insert(j.name.as_str()) {
                return Err(RigError::DuplicateJoint(j.name.clone()));
            }
            match j.parent {
                None if i > 0 => return Err(RigError::SecondRoot(j.name.clone())),
                Some(p) if p >= i => {
                    return Err(RigError::UnknownParent {
                        joint: j.name.clone(),
                        parent: joints.get(p).map_or(p.to_string(), |pj| pj.name.clone()),
                    });
                }
                _ => {}
            }
            let finite = j.offset.iter().all(|v| v.is_finite())
                && j.end_site.is_none_or(|e| e.iter().all(|v| v.is_finite()));
            if !finite {
                return Err(RigError::NonFinite(j.name.clone()));
            }
        }
        if joints[0].parent.is_some() {
            return Err(RigError::UnknownParent {
                joint: joints[0].name.clone(),
                parent: "?".into(),
            });
        }
        Ok(Rig {
            name: name.into(),
            units,
            joints,
            poses: BTreeMap::new(),
            frame_poses: Vec::new(),
            segments: BTreeMap::new(),
            vmc_names: BTreeMap::new(),
        })
    }

    pub fn name(&self) -> &str {
        &self.name
    }

    pub fn units(&self) -> LengthUnit {
        self.units
    }

    pub fn joints(&self) -> &[Joint] {
        &self.joints
    }

    pub fn len(&self) -> usize {
        self.joints.len()
    }

    /// Always false: a rig has at least one joint.
    pub fn is_empty(&self) -> bool {
        false
    }

    /// Finds a joint by name; `mixamorig:` prefixes are ignored on either side.
    pub fn joint_index(&self, name: &str) -> Option<usize> {
        self.joints.iter().position(|j| j.name == name).or_else(|| {
            let bare = strip_prefix(name);
            self.joints
                .iter()
                .position(|j| strip_prefix(&j.name) == bare)
        })
    }

    pub fn children(&self, joint: usize) -> impl Iterator<Item = usize> + '_ {
        self.joints
            .iter()
            .enumerate()
            .filter(move |(_, j)| j.parent == Some(joint))
            .map(|(i, _)| i)
    }

    /// Adds or replaces a named pose given as local rotations by joint name.
    pub fn set_pose(
        &mut self,
        name: &str,
        rotations: &[(String, UnitQuaternion<f64>)],
    ) -> Result<(), RigError> {
        let mut local = vec![UnitQuaternion::identity(); self.joints.len()];
        for (joint, q) in rotations {
            let i = self.joint_index(joint).ok_or_else(|| RigError::PoseJoint {
                pose: name.to_string(),
                joint: joint.clone(),
            })?;
            local[i] = *q;
        }
        self.poses.insert(name.to_string(), Pose { local });
        Ok(())
    }

    /// Makes the frames of a BVH rig's motion available as poses `frame:N`; each entry holds
    /// every joint's local rotation.
    /// Declares the joint of a body part (`left_upper_arm: LeftArm`, ...; the keys are
    /// [`anatomy::declarable_keys`]): the rig file's `segments:`.
    pub fn set_segment(&mut self, landmark: &str, joint: &str) -> Result<(), RigError> {
        let known = anatomy::declarable_keys();
        if !known.iter().any(|k| k == landmark) {
            return Err(RigError::UnknownLandmark {
                landmark: landmark.to_string(),
                known: known.join(", "),
            });
        }
        let j = self
            .joint_index(joint)
            .ok_or_else(|| RigError::SegmentJoint {
                landmark: landmark.to_string(),
                joint: joint.to_string(),
            })?;
        self.segments.insert(landmark.to_string(), j);
        Ok(())
    }

    /// Names a joint for VMC (a Unity humanoid bone name): the rig file's `vmc_names:`.
    pub fn set_vmc_name(&mut self, joint: &str, unity: &str) -> Result<(), RigError> {
        let j = self
            .joint_index(joint)
            .ok_or_else(|| RigError::VmcJoint(joint.to_string()))?;
        let name = self.joints[j].name.clone();
        self.vmc_names.insert(name, unity.to_string());
        Ok(())
    }

    /// Joint name → Unity humanoid bone name, as the rig file gives them.
    pub fn vmc_names(&self) -> &BTreeMap<String, String> {
        &self.vmc_names
    }

    /// The landmarks the rig file names, landmark → joint index.
    pub fn segments(&self) -> &BTreeMap<String, usize> {
        &self.segments
    }

    pub fn set_frame_poses(&mut self, frames: Vec<Vec<UnitQuaternion<f64>>>) {
        self.frame_poses = frames
            .into_iter()
            .filter(|f| f.len() == self.joints.len())
            .collect();
    }

    /// A named pose; `rest` is always defined (all identity), `frame:N` for a BVH rig's frames.
    pub fn pose(&self, name: &str) -> Option<Pose> {
        if let Some(n) = name.strip_prefix("frame:") {
            let n: usize = n.trim().parse().ok()?;
            return self.frame_poses.get(n).map(|local| Pose {
                local: local.clone(),
            });
        }
        if name == "rest" {
            return Some(Pose {
                local: vec![UnitQuaternion::identity(); self.joints.len()],
            });
        }
        self.poses.get(name).cloned()
    }

    /// Pose names for messages: `rest`, the named poses, and `frame:0..N` for a BVH rig.
    pub fn pose_names(&self) -> Vec<String> {
        let mut names: Vec<String> = std::iter::once("rest".to_string())
            .chain(self.poses.keys().cloned())
            .collect();
        if !self.frame_poses.is_empty() {
            names.push(format!("frame:0 … frame:{}", self.frame_poses.len() - 1));
        }
        names
    }

    /// World rotations from local ones: q_world_j = q_world_parent ⊗ q_local_j.
    pub fn world_rotations(&self, local: &[UnitQuaternion<f64>]) -> Vec<UnitQuaternion<f64>> {
        let mut world: Vec<UnitQuaternion<f64>> = Vec::with_capacity(self.joints.len());
        for (i, j) in self.joints.iter().enumerate() {
            let q = match j.parent {
                Some(p) => world[p] * local[i],
                None => local[i],
            };
            world.push(q);
        }
        world
    }

    /// Joint positions in the rig world for local rotations and a root position (rig units).
    pub fn world_positions(
        &self,
        local: &[UnitQuaternion<f64>],
        root: Vector3<f64>,
    ) -> Vec<Vector3<f64>> {
        self.world_pose(local, root).1
    }

    /// Joint world rotations and positions (rig units) for local rotations and a root position.
    pub fn world_pose(
        &self,
        local: &[UnitQuaternion<f64>],
        root: Vector3<f64>,
    ) -> (Vec<UnitQuaternion<f64>>, Vec<Vector3<f64>>) {
        let (mut world, mut positions) = (Vec::new(), Vec::new());
        self.world_pose_into(local, root, &mut world, &mut positions);
        (world, positions)
    }

    /// [`Rig::world_pose`] into buffers a caller keeps (a stream's frames allocate nothing).
    pub fn world_pose_into(
        &self,
        local: &[UnitQuaternion<f64>],
        root: Vector3<f64>,
        world: &mut Vec<UnitQuaternion<f64>>,
        positions: &mut Vec<Vector3<f64>>,
    ) {
        world.clear();
        positions.clear();
        for (i, j) in self.joints.iter().enumerate() {
            let (q, p) = match j.parent {
                Some(p) => (world[p] * local[i], positions[p] + world[p] * j.offset),
                None => (local[i], root),
            };
            world.push(q);
            positions.push(p);
        }
    }

    /// Rest-pose joint positions with the root at its offset.
    pub fn rest_positions(&self) -> Vec<Vector3<f64>> {
        let identity = vec![UnitQuaternion::identity(); self.joints.len()];
        self.world_positions(&identity, self.joints[0].offset)
    }

    /// The rest pose's lowest and highest points' heights (joints and End Sites), rig units, the
    /// root at its offset.
    pub fn rest_extent(&self) -> (f64, f64) {
        self.extent_in(&vec![UnitQuaternion::identity(); self.joints.len()])
    }

    /// A pose's lowest and highest points' heights (joints and End Sites), rig units, the root at
    /// its offset; `local`: the pose's local rotations. In the pose a subject calibrates in, this
    /// is the floor and the standing height, whether or not the rig's zero pose stands.
    pub fn extent_in(&self, local: &[UnitQuaternion<f64>]) -> (f64, f64) {
        let world = self.world_rotations(local);
        let pos = self.world_positions(local, self.joints[0].offset);
        let (mut low, mut high) = (f64::INFINITY, f64::NEG_INFINITY);
        for (i, j) in self.joints.iter().enumerate() {
            let end = j.end_site.map(|e| (pos[i] + world[i] * e).y);
            for y in std::iter::once(pos[i].y).chain(end) {
                low = low.min(y);
                high = high.max(y);
            }
        }
        (low, high)
    }

    /// The rest pose's extent from its lowest point to its highest, rig units: the standing
    /// height of the body the rig models.
    pub fn standing_height(&self) -> f64 {
        let (low, high) = self.rest_extent();
        high - low
    }

    /// The same rig (names, hierarchy, poses) with other offsets and End Sites.
    pub fn with_lengths(
        &self,
        offsets: Vec<Vector3<f64>>,
        end_sites: Vec<Option<Vector3<f64>>>,
    ) -> Result<Rig, RigError> {
        let mut rig = self.clone();
        for ((j, o), e) in rig.joints.iter_mut().zip(offsets).zip(end_sites) {
            if !o.iter().chain(e.iter().flatten()).all(|v| v.is_finite()) {
                return Err(RigError::NonFinite(j.name.clone()));
            }
            j.offset = o;
            j.end_site = e;
        }
        Ok(rig)
    }

    /// Height of the root above the lowest point of the rest pose (joints and end sites), in rig
    /// units: where the root stands when the feet are on the ground.
    pub fn root_height(&self) -> f64 {
        self.joints[0].offset.y - self.rest_extent().0
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn joint(name: &str, parent: Option<usize>, offset: [f64; 3]) -> Joint {
        Joint {
            name: name.into(),
            parent,
            offset: Vector3::from(offset),
            order: EulerOrder::ZYX,
            end_site: None,
        }
    }

    #[test]
    fn validates_hierarchy() {
        assert_eq!(
            Rig::new("x", LengthUnit::Metres, vec![]),
            Err(RigError::NoJoints)
        );
        let dup = vec![joint("a", None, [0.0; 3]), joint("a", Some(0), [0.0; 3])];
        assert_eq!(
            Rig::new("x", LengthUnit::Metres, dup),
            Err(RigError::DuplicateJoint("a".into()))
        );
        let forward = vec![
            joint("a", None, [0.0; 3]),
            joint("b", Some(2), [0.0; 3]),
            joint("c", Some(0), [0.0; 3]),
        ];
        assert!(matches!(
            Rig::new("x", LengthUnit::Metres, forward),
            Err(RigError::UnknownParent { .. })
        ));
        let two_roots = vec![joint("a", None, [0.0; 3]), joint("b", None, [0.0; 3])];
        assert_eq!(
            Rig::new("x", LengthUnit::Metres, two_roots),
            Err(RigError::SecondRoot("b".into()))
        );
        let nan = vec![joint("a", None, [f64::NAN, 0.0, 0.0])];
        assert!(matches!(
            Rig::new("x", LengthUnit::Metres, nan),
            Err(RigError::NonFinite(_))
        ));
    }

    #[test]
    fn forward_kinematics_by_hand() {
        // root at (0,1,0); arm 1 along +x; hand 0.5 further along +x.
        let rig = Rig::new(
            "t",
            LengthUnit::Metres,
            vec![
                joint("root", None, [0.0, 1.0, 0.0]),
                joint("arm", Some(0), [1.0, 0.0, 0.0]),
                joint("hand", Some(1), [0.5, 0.0, 0.0]),
            ],
        )
        .unwrap();
        // Rotate the root 90° about +Y: +x goes to -z.
        let mut local = vec![UnitQuaternion::identity(); 3];
        local[0] = UnitQuaternion::from_axis_angle(&Vector3::y_axis(), std::f64::consts::FRAC_PI_2);
        let p = rig.world_positions(&local, Vector3::new(0.0, 1.0, 0.0));
        assert!((p[1] - Vector3::new(0.0, 1.0, -1.0)).norm() < 1e-12);
        assert!((p[2] - Vector3::new(0.0, 1.0, -1.5)).norm() < 1e-12);
        assert_eq!(rig.joint_index("mixamorig:arm"), Some(1));
    }
}
