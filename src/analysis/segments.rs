//! The anatomical segments of a rig: which joint is the pelvis, the thorax, each side's upper arm,
//! forearm, hand, thigh, shank and foot, and where the neck, the hands' and the feet's ends are;
//! and each segment's anatomical frame at rest.
//!
//! # Landmarks
//! The segments are the rig's body parts ([`crate::rig::anatomy`]: a rig file's `segments:`,
//! else the joints' names in any of the common schemes, else the skeleton's shape): the pelvis,
//! the thorax (the spine's top, where the arms meet; the pelvis when there is no spine between),
//! each side's upper arm, forearm, hand, thigh, shank and foot; and points:
//!
//! | point | where |
//! |---|---|
//! | `neck` | the neck's first joint, else the head |
//! | `hand_end` | a rig file's `left_hand_end`/`right_hand_end`, else the first of `SHandMiddle1`, `SFingerBase`, `SHand_End`, `SHandEnd` (`S` is `Left` or `Right`) |
//! | `toe` | the toes joint |
//!
//! A joint a rig file declares must lie below the part before it (forearm below upper arm, ...),
//! else it is an error. A point is its joint's position, unless that coincides with the segment's own joint
//! at rest (CMU's `LeftFingerBase` sits on `LeftHand`): then the joint's first child, again, or at
//! the end of the chain its End Site. Without a `hand_end` or `toe` joint, the walk starts at the
//! hand or foot itself. Without a hand (sou12) the wrist point is the forearm's End Site, the
//! ankle the shank's.
//!
//! # Frames at rest
//! Rest rotations are identity (the rig convention), so a segment's anatomical frame at rest is a
//! rotation `F_rest` (columns X anterior, Y superior/along the segment towards its proximal end,
//! Z to the right; the ISB's axes) and at any frame `F = q_world_joint ⊗ F_rest`.
//! - Body: `up` = the rig's +Y; `right` = right thigh − left thigh (else upper arms) at rest,
//!   perpendicular to up; `forward = up × right`.
//! - Pelvis, thorax, foot: the body frame (the rest pose's foot is neutral, 0°).
//! - Thigh, shank, upper arm: `Y = (proximal − distal point) / |…|`, `X` = forward made
//!   perpendicular to `Y`, `Z = X × Y`.
//! - Forearm, hand: the same with the palm's direction for forward: forward if the rest upper arm
//!   hangs within 30° of straight down (anatomical position, palms forward), else down (a T- or
//!   A-pose, palms down). So a palms-down T-pose reads as a pronated forearm (elbow rotation
//!   ≈ 90°), which it anatomically is.

use super::AnalysisError;
use crate::rig::Rig;
use crate::rig::anatomy::{Anatomy, Limb, Part};
use nalgebra::{Matrix3, Rotation3, UnitQuaternion, Vector3};

pub use crate::rig::anatomy::Side;

/// A point of the body: a joint's position, or its End Site's.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Point {
    Joint(usize),
    EndSite(usize),
}

impl Point {
    /// Its position, from every joint's world position and rotation.
    pub fn position(
        self,
        rig: &Rig,
        positions: &[Vector3<f64>],
        rotations: &[UnitQuaternion<f64>],
    ) -> Vector3<f64> {
        match self {
            Point::Joint(j) => positions[j],
            Point::EndSite(j) => {
                positions[j] + rotations[j] * rig.joints()[j].end_site.unwrap_or_default()
            }
        }
    }
}

/// One side's limbs: joints (indices) and points.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Limbs {
    pub upper_arm: Option<usize>,
    pub forearm: Option<usize>,
    pub hand: Option<usize>,
    /// Where the forearm ends: the hand joint, or the forearm's End Site.
    pub wrist: Option<Point>,
    pub hand_end: Option<Point>,
    pub thigh: Option<usize>,
    pub shank: Option<usize>,
    pub foot: Option<usize>,
    /// Where the shank ends: the foot joint, or the shank's End Site.
    pub ankle: Option<Point>,
    pub toe: Option<Point>,
}

/// A rig's anatomical segments and their frames at rest.
#[derive(Debug, Clone, PartialEq)]
pub struct Segments {
    pub pelvis: Option<usize>,
    pub thorax: Option<usize>,
    pub neck: Option<Point>,
    /// `[left, right]`.
    pub sides: [Limbs; 2],
    /// The body frame at rest (columns forward, up, right).
    pub body: Matrix3<f64>,
    /// `[left, right]`: the palm's direction at rest (forward or down).
    pub palm: [Vector3<f64>; 2],
}

/// The landmarks a rig file's `segments:` may name ([`crate::rig::anatomy::declarable_keys`]).
pub fn landmark_names() -> Vec<String> {
    crate::rig::anatomy::declarable_keys()
}

fn bare(name: &str) -> &str {
    name.rsplit(':').next().unwrap_or(name)
}

fn is_below(rig: &Rig, joint: usize, ancestor: usize) -> bool {
    let mut j = rig.joints()[joint].parent;
    while let Some(p) = j {
        if p == ancestor {
            return true;
        }
        j = rig.joints()[p].parent;
    }
    false
}

struct Finder<'a> {
    rig: &'a Rig,
    /// Every joint's position and world rotation in the reference pose.
    rest: Vec<Vector3<f64>>,
    rotations: Vec<UnitQuaternion<f64>>,
}

impl Finder<'_> {
    /// The first of `names` the rig has (any `namespace:` prefix ignored), unless the rig file
    /// declares `landmark`.
    fn joint(&self, landmark: &str, names: &[String]) -> Option<usize> {
        if let Some(&j) = self.rig.segments().get(landmark) {
            return Some(j);
        }
        names.iter().find_map(|n| {
            self.rig
                .joints()
                .iter()
                .position(|j| bare(&j.name) == n.as_str())
        })
    }

    /// A part's joint; one the rig file declares must lie below the part `above` (an error
    /// naming both when it does not).
    fn part(
        &self,
        anatomy: &Anatomy,
        side: Side,
        limb: Limb,
        above: Option<(usize, &str)>,
    ) -> Result<Option<usize>, AnalysisError> {
        let Some(j) = anatomy.limb(side, limb) else {
            return Ok(None);
        };
        let key = Part::Limb(side, limb).key();
        match above {
            Some((a, above_name))
                if self.rig.segments().contains_key(&key) && !is_below(self.rig, j, a) =>
            {
                Err(AnalysisError::NotBelow {
                    rig: self.rig.name().to_string(),
                    landmark: key,
                    joint: self.rig.joints()[j].name.clone(),
                    above: above_name.to_string(),
                    above_joint: self.rig.joints()[a].name.clone(),
                })
            }
            Some((a, _)) if !is_below(self.rig, j, a) => Ok(None),
            _ => Ok(Some(j)),
        }
    }

    /// The end point of the segment of joint `of`: `start` (a named joint below it, else `of`
    /// itself), walked down first children while it sits on `of`, ending at an End Site.
    fn end_point(&self, of: usize, start: Option<usize>) -> Option<Point> {
        let eps = 1e-9 * (1.0 + self.rest[of].norm());
        let mut j = start.filter(|&s| is_below(self.rig, s, of)).unwrap_or(of);
        loop {
            if j != of && (self.rest[j] - self.rest[of]).norm() > eps {
                return Some(Point::Joint(j));
            }
            match self.rig.children(j).next() {
                Some(c) => j = c,
                None => {
                    let e = self.rig.joints()[j].end_site?;
                    let p = self.rest[j] + self.rotations[j] * e;
                    return ((p - self.rest[of]).norm() > eps).then_some(Point::EndSite(j));
                }
            }
        }
    }
}

fn limbs(f: &Finder, anatomy: &Anatomy, side: Side) -> Result<Limbs, AnalysisError> {
    let s = side.name();
    let prefix = side.prefix();
    let upper_arm = f.part(anatomy, side, Limb::UpperArm, None)?;
    let forearm = match upper_arm {
        Some(u) => f.part(anatomy, side, Limb::Forearm, Some((u, "upper_arm")))?,
        None => None,
    };
    let hand = match forearm {
        Some(fa) => f.part(anatomy, side, Limb::Hand, Some((fa, "forearm")))?,
        None => None,
    };
    let wrist = match (hand, forearm) {
        (Some(h), _) => Some(Point::Joint(h)),
        (None, Some(fa)) => f.rig.joints()[fa].end_site.map(|_| Point::EndSite(fa)),
        _ => None,
    };
    let hand_end = hand.and_then(|h| {
        let names: Vec<String> = ["HandMiddle1", "FingerBase", "Hand_End", "HandEnd"]
            .iter()
            .map(|n| format!("{prefix}{n}"))
            .collect();
        let start = f.joint(&format!("{s}_hand_end"), &names);
        f.end_point(h, start)
    });
    let thigh = f.part(anatomy, side, Limb::Thigh, None)?;
    let shank = match thigh {
        Some(t) => f.part(anatomy, side, Limb::Shank, Some((t, "thigh")))?,
        None => None,
    };
    let foot = match shank {
        Some(sh) => f.part(anatomy, side, Limb::Foot, Some((sh, "shank")))?,
        None => None,
    };
    let ankle = match (foot, shank) {
        (Some(ft), _) => Some(Point::Joint(ft)),
        (None, Some(sh)) => f.rig.joints()[sh].end_site.map(|_| Point::EndSite(sh)),
        _ => None,
    };
    let toe = foot.and_then(|ft| f.end_point(ft, anatomy.limb(side, Limb::Toes)));
    Ok(Limbs {
        upper_arm,
        forearm,
        hand,
        wrist,
        hand_end,
        thigh,
        shank,
        foot,
        ankle,
        toe,
    })
}

/// Left and right are not told apart: the joints whose names come closest to a thigh or an
/// upper arm.
fn no_sides(rig: &Rig, anatomy: &Anatomy) -> AnalysisError {
    let mut closest = Vec::new();
    for side in Side::BOTH {
        for limb in [Limb::Thigh, Limb::UpperArm] {
            let part = Part::Limb(side, limb);
            closest.push(format!(
                "{}: {}",
                part.label(),
                anatomy.closest(part, 2).join(", ")
            ));
        }
    }
    AnalysisError::NoSides {
        rig: rig.name().to_string(),
        closest: closest.join("; "),
    }
}

impl Segments {
    /// The rig's segments (see the module's docs), in its rest pose.
    pub fn of(rig: &Rig) -> Result<Segments, AnalysisError> {
        Segments::in_pose(rig, &vec![UnitQuaternion::identity(); rig.len()])
    }

    /// The rig's segments with their frames in a standing reference pose (`pose`: its local
    /// rotations, e.g. the calibration pose), not the zero pose, which need not stand: the body
    /// frame, the palms' direction and the segments' ends are read where the pose puts them.
    pub fn in_pose(rig: &Rig, pose: &[UnitQuaternion<f64>]) -> Result<Segments, AnalysisError> {
        let anatomy = Anatomy::of(rig);
        let f = Finder {
            rig,
            rest: rig.world_positions(pose, rig.joints()[0].offset),
            rotations: rig.world_rotations(pose),
        };
        let sides = [
            limbs(&f, &anatomy, Side::Left)?,
            limbs(&f, &anatomy, Side::Right)?,
        ];
        let [l, r] = &sides;
        let pair = |a: Option<usize>, b: Option<usize>| a.zip(b);
        let pelvis = anatomy.pelvis();
        let arms = pair(l.upper_arm, r.upper_arm).is_some();
        let thorax = anatomy
            .thorax()
            .or_else(|| pelvis.filter(|_| arms || rig.segments().contains_key("thorax")));
        if pelvis.is_none() && thorax.is_none() {
            return Err(AnalysisError::NoSegments {
                rig: rig.name().to_string(),
            });
        }
        let neck = anatomy
            .neck()
            .first()
            .copied()
            .or(anatomy.head())
            .map(Point::Joint);
        let (left, right) = pair(l.thigh, r.thigh)
            .or_else(|| pair(l.upper_arm, r.upper_arm))
            .ok_or_else(|| no_sides(rig, &anatomy))?;
        let up = Vector3::y();
        let across = f.rest[right] - f.rest[left];
        let right_dir = across - up * up.dot(&across);
        if right_dir.norm() < 1e-9 * (1.0 + across.norm()) {
            return Err(no_sides(rig, &anatomy));
        }
        let right_dir = right_dir.normalize();
        let forward = up.cross(&right_dir);
        let body = Matrix3::from_columns(&[forward, up, right_dir]);
        let palm = [0, 1].map(|i| {
            let hanging = match (sides[i].upper_arm, sides[i].forearm) {
                (Some(u), Some(fa)) => {
                    let d = (f.rest[fa] - f.rest[u]).normalize();
                    d.dot(&-up) >= 30f64.to_radians().cos()
                }
                _ => true,
            };
            if hanging { forward } else { -up }
        });
        Ok(Segments {
            pelvis,
            thorax,
            neck,
            sides,
            body,
            palm,
        })
    }

    /// The anatomical frame at rest of a limb segment running from `proximal` to `distal`
    /// (rest positions), with `reference` for anterior: `Y` along the segment towards its
    /// proximal end, `X` the reference made perpendicular to it, `Z = X × Y`. `None` for a
    /// segment of no length or one along the reference.
    pub fn limb_frame(
        proximal: Vector3<f64>,
        distal: Vector3<f64>,
        reference: Vector3<f64>,
    ) -> Option<Rotation3<f64>> {
        let y = (proximal - distal).try_normalize(1e-12)?;
        let x = (reference - y * y.dot(&reference)).try_normalize(1e-6)?;
        let z = x.cross(&y);
        Some(Rotation3::from_matrix_unchecked(Matrix3::from_columns(&[
            x, y, z,
        ])))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::rig::load_rig;

    #[test]
    fn mixamo_and_sou12_name_their_segments() {
        let rig = load_rig("mixamo").unwrap();
        let s = Segments::of(&rig).unwrap();
        let name = |j: Option<usize>| rig.joints()[j.unwrap()].name.as_str();
        assert_eq!(name(s.pelvis), "Hips");
        assert_eq!(name(s.thorax), "Spine2");
        assert_eq!(name(s.sides[0].upper_arm), "LeftArm");
        assert_eq!(name(s.sides[1].shank), "RightLeg");
        assert_eq!(
            s.sides[0].hand_end,
            Some(Point::EndSite(rig.joint_index("LeftHand").unwrap()))
        );
        // Mixamo faces +Z with +X on the character's left: right is −X, forward +Z.
        assert!((s.body.column(0) - Vector3::z()).norm() < 1e-12);
        assert!((s.body.column(2) + Vector3::x()).norm() < 1e-12);
        // A T-pose: palms down.
        assert_eq!(s.palm[0], -Vector3::y());

        let rig = load_rig("sou12").unwrap();
        let s = Segments::of(&rig).unwrap();
        let name = |j: Option<usize>| rig.joints()[j.unwrap()].name.as_str();
        assert_eq!(name(s.pelvis), "N0_0");
        assert_eq!(name(s.thorax), "N0_1");
        assert_eq!(name(s.sides[0].upper_arm), "N2_0");
        assert_eq!(name(s.sides[1].thigh), "N3_0");
        assert_eq!(s.sides[0].hand, None);
        assert_eq!(
            s.sides[0].wrist,
            Some(Point::EndSite(rig.joint_index("N2_1").unwrap()))
        );
        assert_eq!(
            s.sides[1].ankle,
            Some(Point::EndSite(rig.joint_index("N3_1").unwrap()))
        );
    }

    #[test]
    fn a_rig_file_names_landmarks_and_bad_ones_are_errors() {
        let text = "name: odd\njoints:\n  - {name: root, offset: [0, 1, 0]}\n  - {name: a, parent: root, offset: [0.1, 0, 0]}\n  - {name: b, parent: a, offset: [0, -0.4, 0]}\n  - {name: c, parent: root, offset: [-0.1, 0, 0]}\n  - {name: d, parent: c, offset: [0, -0.4, 0], end_site: [0, -0.4, 0]}\nsegments: {left_thigh: a, left_shank: b, right_thigh: c, right_shank: d}\n";
        let rig = crate::rig::file::parse_rig(text, std::path::Path::new("odd.yaml")).unwrap();
        let s = Segments::of(&rig).unwrap();
        assert_eq!(s.pelvis, Some(0));
        assert_eq!(s.sides[1].ankle, Some(Point::EndSite(4)));
        assert_eq!(s.sides[0].ankle, None, "b has no End Site and no foot");
        let bad = text.replace("right_shank: d", "right_shank: a");
        let rig = crate::rig::file::parse_rig(&bad, std::path::Path::new("odd.yaml")).unwrap();
        let e = Segments::of(&rig).unwrap_err().to_string();
        assert!(
            e.contains("`right_shank` (`a`) is not below `thigh` (`c`)"),
            "{e}"
        );
        let bad = text.replace("left_thigh", "left_thighs");
        let e = crate::rig::file::parse_rig(&bad, std::path::Path::new("odd.yaml"))
            .unwrap_err()
            .to_string();
        assert!(e.contains("`left_thighs` is no body part"), "{e}");
    }
}
