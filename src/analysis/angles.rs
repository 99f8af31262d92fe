//! Joint angles per frame: paper 000's angle between adjacent segments and the signed anatomical
//! angles of a joint coordinate decomposition.
//!
//! # The angle between segments (paper 000, eq. 2–3)
//! `γ = atan2(|A × B|, A · B)` between the segment vectors `A` and `B`: 0° when they are in line,
//! never negative. As in the paper, a segment's vector is its rest vector (rest positions, from
//! its joint to its end) turned by its own world rotation, `q_world_joint · v_rest`, so it
//! follows that segment alone (not, say, finger joints between the wrist and the hand's end).
//! Per joint:
//!
//! | joint | A | B | reads 0° when |
//! |---|---|---|---|
//! | shoulder | trunk down (neck → pelvis) turned by the thorax | upper arm: shoulder → elbow | the arm hangs |
//! | elbow | upper arm | forearm: elbow → wrist | the arm is straight |
//! | wrist | forearm | hand: wrist → hand end | the hand is in line |
//! | hip | trunk down turned by the pelvis | thigh: hip → knee | standing |
//! | knee | thigh | shank: knee → ankle | the leg is straight |
//! | ankle | shank | foot: ankle → toe | never: about 90–120° standing |
//!
//! # Anatomical angles
//! `R = F_proximalᵀ · F_distal` ([`super::segments`]' frames: X anterior, Y along the segment, Z
//! right), decomposed as intrinsic rotations in the ISB's joint coordinate manner: flexion `a`
//! about the proximal segment's Z, abduction `b` about the floating X, rotation `c` about the
//! distal segment's Y — `R = Rz(a)·Rx(b)·Ry(c)` for every joint but the shoulder, which uses
//! `R = Rx(b)·Rz(a)·Ry(c)` (abduction first, as Xsens's shoulder angles do) so that a T-pose (90°
//! of abduction) is not the gimbal lock of the sequence; it is at 90° of flexion instead.
//! Proximal → distal: thorax → upper arm, upper arm → forearm, forearm → hand, pelvis → thigh,
//! thigh → shank, shank → foot.
//!
//! Signs, the same on both sides:
//!
//! | column | positive | from the decomposition |
//! |---|---|---|
//! | `_flexion` | flexion; at the knee too; at the ankle dorsiflexion; at the wrist towards the palm | `a` (knee: `−a`) |
//! | `_abduction` | away from the midline: abduction; at the wrist radial deviation; at the ankle eversion; at the knee valgus | left `b`, right `−b` |
//! | `_rotation` | internal rotation; at the elbow pronation; at the ankle toe-in | left `−c`, right `c` |
//!
//! Angles are relative to the rig's rest pose as anatomical position for the arms hanging or
//! abducted in the frontal plane, the legs and the feet (so a rig whose rest pose bends a knee
//! reads that bend as 0°).

use super::segments::{Point, Segments, Side};
use super::{AnalysisError, AngleTable};
use crate::anim::Animation;
use crate::bvh::Bvh;
use crate::rig::{LengthUnit, Rig};
use nalgebra::{Rotation3, UnitQuaternion, Vector3};

/// The joints, in column order.
pub const JOINTS: [&str; 6] = ["shoulder", "elbow", "wrist", "hip", "knee", "ankle"];

/// The components of a joint's anatomical angle, in column order.
pub const COMPONENTS: [&str; 3] = ["flexion", "abduction", "rotation"];

/// A segment: the joint whose rotation it follows, and its frame at rest.
#[derive(Debug, Clone, Copy)]
struct Segment {
    joint: usize,
    rest: Rotation3<f64>,
}

impl Segment {
    fn at(&self, rotations: &[UnitQuaternion<f64>]) -> Rotation3<f64> {
        rotations[self.joint].to_rotation_matrix() * self.rest
    }
}

/// A segment vector: the joint whose rotation turns it, and the vector at rest.
#[derive(Debug, Clone, Copy)]
struct Vector {
    joint: usize,
    rest: Vector3<f64>,
}

impl Vector {
    fn at(&self, rotations: &[UnitQuaternion<f64>]) -> Vector3<f64> {
        rotations[self.joint] * self.rest
    }
}

#[derive(Debug, Clone, Copy)]
struct JointDef {
    side: Side,
    /// Index in [`JOINTS`].
    joint: usize,
    gamma: Option<(Vector, Vector)>,
    anatomical: Option<(Segment, Segment)>,
}

/// The joint angles of a rig, frame after frame.
#[derive(Debug, Clone)]
pub struct JointAngles {
    rig: Rig,
    joints: Vec<JointDef>,
    names: Vec<String>,
}

/// `R = Rz(a)·Rx(b)·Ry(c)` → `(a, b, c)`, radians: `b = asin(R₂₁)`, `a = atan2(−R₀₁, R₁₁)`,
/// `c = atan2(−R₂₀, R₂₂)`.
pub fn zxy(r: &Rotation3<f64>) -> (f64, f64, f64) {
    let m = r.matrix();
    let a = f64::atan2(-m[(0, 1)], m[(1, 1)]);
    let b = m[(2, 1)].clamp(-1.0, 1.0).asin();
    let c = f64::atan2(-m[(2, 0)], m[(2, 2)]);
    (a, b, c)
}

/// `R = Rx(b)·Rz(a)·Ry(c)` → `(a, b, c)`, radians: `a = asin(−R₀₁)`, `b = atan2(R₂₁, R₁₁)`,
/// `c = atan2(R₀₂, R₀₀)`.
pub fn xzy(r: &Rotation3<f64>) -> (f64, f64, f64) {
    let m = r.matrix();
    let a = (-m[(0, 1)]).clamp(-1.0, 1.0).asin();
    let b = f64::atan2(m[(2, 1)], m[(1, 1)]);
    let c = f64::atan2(m[(0, 2)], m[(0, 0)]);
    (a, b, c)
}

impl JointAngles {
    /// The joints of `rig` whose segments it has ([`Segments::of`]), measured from its rest pose.
    pub fn new(rig: &Rig) -> Result<JointAngles, AnalysisError> {
        JointAngles::in_pose(rig, &vec![UnitQuaternion::identity(); rig.len()])
    }

    /// The same, the anatomical frames read in a standing reference pose (`pose`: local
    /// rotations, e.g. the calibration pose) and carried by their bones ([`Segments::in_pose`]):
    /// a frame `F_P` built in the pose's world rides on its joint as `W_P⁻¹ ⊗ F_P`, so a rig
    /// whose joints' frames differ (a bone-along-X twin) measures the same angles.
    pub fn in_pose(rig: &Rig, pose: &[UnitQuaternion<f64>]) -> Result<JointAngles, AnalysisError> {
        let seg = Segments::in_pose(rig, pose)?;
        let rest = rig.world_positions(pose, rig.joints()[0].offset);
        let turned = rig.world_rotations(pose);
        let point = |p: Point| p.position(rig, &rest, &turned);
        // A frame or vector in the pose's world, as its joint carries it.
        let on = |joint: usize| turned[joint].inverse().to_rotation_matrix();
        let forward = seg.body.column(0).into_owned();
        let body = Rotation3::from_matrix_unchecked(seg.body);
        let fixed = |j: Option<usize>| {
            j.map(|joint| Segment {
                joint,
                rest: on(joint) * body,
            })
        };
        let limb = |joint: Option<usize>, distal: Option<Point>, reference: Vector3<f64>| {
            let (joint, distal) = (joint?, distal?);
            Segments::limb_frame(rest[joint], point(distal), reference).map(|frame| Segment {
                joint,
                rest: on(joint) * frame,
            })
        };
        // The segment of `joint`, from it to `to`, turned by `by` (the joint itself but for the
        // trunk).
        let vector = |joint: Option<usize>, to: Option<Point>, by: Option<usize>| {
            let (joint, to, by) = (joint?, to?, by?);
            Some(Vector {
                joint: by,
                rest: on(by) * (point(to) - rest[joint]),
            })
        };
        let joint_point = |j: Option<usize>| j.map(Point::Joint);
        let pelvis = fixed(seg.pelvis);
        let thorax = fixed(seg.thorax);
        let mut joints = Vec::new();
        for (i, name) in JOINTS.iter().enumerate() {
            for side in Side::BOTH {
                let l = &seg.sides[side as usize];
                let palm = seg.palm[side as usize];
                let upper_arm = limb(l.upper_arm, l.forearm.map(Point::Joint), forward);
                let forearm = limb(l.forearm, l.wrist, palm);
                let hand = limb(l.hand, l.hand_end, palm);
                let thigh = limb(l.thigh, l.shank.map(Point::Joint), forward);
                let shank = limb(l.shank, l.ankle, forward);
                let foot = fixed(l.foot);
                // Neck → pelvis: the neck is a point, so the vector runs from it by hand.
                let trunk = |by: Option<usize>| {
                    let (neck, pelvis, by) = (seg.neck?, seg.pelvis?, by?);
                    Some(Vector {
                        joint: by,
                        rest: on(by) * (rest[pelvis] - point(neck)),
                    })
                };
                let upper_arm_v = vector(l.upper_arm, joint_point(l.forearm), l.upper_arm);
                let forearm_v = vector(l.forearm, l.wrist, l.forearm);
                let hand_v = vector(l.hand, l.hand_end, l.hand);
                let thigh_v = vector(l.thigh, joint_point(l.shank), l.thigh);
                let shank_v = vector(l.shank, l.ankle, l.shank);
                let foot_v = vector(l.foot, l.toe, l.foot);
                let (gamma, anatomical) = match *name {
                    "shoulder" => ((trunk(seg.thorax), upper_arm_v), (thorax, upper_arm)),
                    "elbow" => ((upper_arm_v, forearm_v), (upper_arm, forearm)),
                    "wrist" => ((forearm_v, hand_v), (forearm, hand)),
                    "hip" => ((trunk(seg.pelvis), thigh_v), (pelvis, thigh)),
                    "knee" => ((thigh_v, shank_v), (thigh, shank)),
                    _ => ((shank_v, foot_v), (shank, foot)),
                };
                let def = JointDef {
                    side,
                    joint: i,
                    gamma: gamma.0.zip(gamma.1),
                    anatomical: anatomical.0.zip(anatomical.1),
                };
                if def.gamma.is_some() || def.anatomical.is_some() {
                    joints.push(def);
                }
            }
        }
        let mut names = Vec::new();
        for d in &joints {
            let stem = format!("{}_{}", d.side.name(), JOINTS[d.joint]);
            if d.gamma.is_some() {
                names.push(stem.clone());
            }
            if d.anatomical.is_some() {
                names.extend(COMPONENTS.iter().map(|c| format!("{stem}_{c}")));
            }
        }
        Ok(JointAngles {
            rig: rig.clone(),
            joints,
            names,
        })
    }

    /// The column names, in order: per joint ([`JOINTS`]) and side (left, right), `{side}_{joint}`
    /// (γ) and `{side}_{joint}_{flexion|abduction|rotation}`, each when the rig has its segments.
    pub fn names(&self) -> &[String] {
        &self.names
    }

    /// One frame's angles (degrees, in [`JointAngles::names`] order) into `out`, from every
    /// joint's world rotation. A segment of no length gives NaN.
    pub fn frame(&self, rotations: &[UnitQuaternion<f64>], out: &mut Vec<f64>) {
        out.clear();
        for d in &self.joints {
            if let Some((a, b)) = d.gamma {
                let (a, b) = (a.at(rotations), b.at(rotations));
                let gamma = if a.norm() > 0.0 && b.norm() > 0.0 {
                    a.cross(&b).norm().atan2(a.dot(&b)).to_degrees()
                } else {
                    f64::NAN
                };
                out.push(gamma);
            }
            if let Some((proximal, distal)) = d.anatomical {
                let r = proximal.at(rotations).inverse() * distal.at(rotations);
                let (a, b, c) = if JOINTS[d.joint] == "shoulder" {
                    xzy(&r)
                } else {
                    zxy(&r)
                };
                let flexion = if JOINTS[d.joint] == "knee" { -a } else { a };
                let (abduction, rotation) = match d.side {
                    Side::Left => (b, -c),
                    Side::Right => (-b, c),
                };
                out.extend([flexion, abduction, rotation].map(f64::to_degrees));
            }
        }
    }
}

/// The angles of every frame of a BVH file's motion (its own skeleton; time `n ×` Frame Time),
/// the segments' frames read in frame `reference`'s pose (`None`: the zero pose, every channel
/// zero), as [`JointAngles::in_pose`]: a skeleton and its twin with other joint axes measure the
/// same angles in a frame's pose, not in their zero poses, which differ.
pub fn of_bvh(
    bvh: &Bvh,
    name: &str,
    reference: Option<usize>,
) -> Result<AngleTable, AnalysisError> {
    let rig = bvh
        .to_rig(name, LengthUnit::Metres)
        .map_err(|e| AnalysisError::Rig {
            rig: name.to_string(),
            reason: e.to_string(),
        })?;
    let frames = bvh.frame_count();
    let angles = match reference {
        None => JointAngles::new(&rig)?,
        Some(n) if n < frames => JointAngles::in_pose(&rig, &bvh.local_rotations(n))?,
        Some(n) => {
            return Err(AnalysisError::Rig {
                rig: name.to_string(),
                reason: format!("the reference frame {n} is past the last frame {frames}"),
            });
        }
    };
    let time_s = (0..frames).map(|n| n as f64 * bvh.frame_time_s()).collect();
    let rows = (0..frames).map(|n| rig.world_rotations(&bvh.local_rotations(n)));
    angles.table(time_s, rows)
}

/// The angles of every frame of an animation (time `n / fps`), measured from the standing pose
/// `reference` (local rotations: the pose the subject calibrated in; `None`: the rig's rest).
pub fn of_animation(
    animation: &Animation,
    reference: Option<&[UnitQuaternion<f64>]>,
) -> Result<AngleTable, AnalysisError> {
    let rig = animation.rig();
    let angles = match reference {
        Some(pose) => JointAngles::in_pose(rig, pose)?,
        None => JointAngles::new(rig)?,
    };
    let fps = animation.fps();
    let time_s = (0..animation.frames())
        .map(|n| fps.frame_time_of(n as u64))
        .collect();
    let rows = (0..animation.frames()).map(|n| rig.world_rotations(&animation.pose_at(n)));
    angles.table(time_s, rows)
}

impl JointAngles {
    /// A table of these angles from each frame's world rotations.
    fn table(
        &self,
        time_s: Vec<f64>,
        frames: impl Iterator<Item = Vec<UnitQuaternion<f64>>>,
    ) -> Result<AngleTable, AnalysisError> {
        let mut columns = vec![Vec::with_capacity(time_s.len()); self.names.len()];
        let mut row = Vec::with_capacity(self.names.len());
        for rotations in frames {
            self.frame(&rotations, &mut row);
            for (c, v) in columns.iter_mut().zip(&row) {
                c.push(*v);
            }
        }
        AngleTable::new(self.names.clone(), time_s, columns).map_err(|reason| AnalysisError::Rig {
            rig: self.rig.name().to_string(),
            reason,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::rig::load_rig;

    fn rot(axis: Vector3<f64>, deg: f64) -> Rotation3<f64> {
        Rotation3::from_axis_angle(&nalgebra::Unit::new_normalize(axis), deg.to_radians())
    }

    #[test]
    fn decompositions_invert_their_compositions() {
        let (a, b, c): (f64, f64, f64) = (0.3, -0.5, 1.1);
        let r = rot(Vector3::z(), a.to_degrees())
            * rot(Vector3::x(), b.to_degrees())
            * rot(Vector3::y(), c.to_degrees());
        let (x, y, z) = zxy(&r);
        assert!((x - a).abs() < 1e-12 && (y - b).abs() < 1e-12 && (z - c).abs() < 1e-12);
        let r = rot(Vector3::x(), b.to_degrees())
            * rot(Vector3::z(), a.to_degrees())
            * rot(Vector3::y(), c.to_degrees());
        let (x, y, z) = xzy(&r);
        assert!((x - a).abs() < 1e-12 && (y - b).abs() < 1e-12 && (z - c).abs() < 1e-12);
    }

    /// Mixamo's T-pose by hand: the arms are abducted 90°, everything else 0; bending the left
    /// knee 30° (the shank turning back about the character's left–right axis) and the right
    /// elbow 45° (the forearm swinging forward) reads as those flexions, with the signs of the
    /// docs.
    #[test]
    fn the_rest_pose_and_hand_made_bends_read_as_expected() {
        let rig = load_rig("mixamo").unwrap();
        let angles = JointAngles::new(&rig).unwrap();
        let col = |name: &str| angles.names().iter().position(|n| n == name).unwrap();
        let mut local = vec![UnitQuaternion::identity(); rig.len()];
        let read = |local: &[UnitQuaternion<f64>]| {
            let mut out = Vec::new();
            angles.frame(&rig.world_rotations(local), &mut out);
            out
        };
        let rest = read(&local);
        assert!((rest[col("left_shoulder")] - 90.0).abs() < 1e-9);
        assert!((rest[col("left_shoulder_abduction")] - 90.0).abs() < 1e-9);
        assert!((rest[col("right_shoulder_abduction")] - 90.0).abs() < 1e-9);
        // Palms down: a pronated forearm.
        assert!((rest[col("right_elbow_rotation")] - 90.0).abs() < 1e-9);
        for n in [
            "left_knee",
            "left_knee_flexion",
            "right_hip_flexion",
            "left_elbow",
        ] {
            assert!(rest[col(n)].abs() < 1e-9, "{n}: {}", rest[col(n)]);
        }
        // Mixamo faces +Z with +X on its left: 30° about +X swings the left shank back (−Z).
        let knee = rig.joint_index("LeftLeg").unwrap();
        local[knee] = UnitQuaternion::from_axis_angle(&Vector3::x_axis(), 30f64.to_radians());
        let pos = rig.world_positions(&local, Vector3::new(0.0, 1.0, 0.0));
        let foot = rig.joint_index("LeftFoot").unwrap();
        assert!(pos[foot].z < pos[knee].z, "the shank turned back");
        let bent = read(&local);
        assert!((bent[col("left_knee_flexion")] - 30.0).abs() < 1e-9);
        assert!((bent[col("left_knee")] - 30.0).abs() < 1e-9);
        let elbow = rig.joint_index("RightForeArm").unwrap();
        // The right forearm runs along −X; 45° about +Y turns it to (−cos θ, 0, sin θ): forward.
        local[elbow] = UnitQuaternion::from_axis_angle(&Vector3::y_axis(), 45f64.to_radians());
        let bent = read(&local);
        assert!((bent[col("right_elbow_flexion")] - 45.0).abs() < 1e-9);
        assert!((bent[col("right_elbow")] - 45.0).abs() < 1e-9);
    }
}
