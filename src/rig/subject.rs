//! A subject's body measurements (paper 000 scales its model to them): `height_m` and/or segment
//! lengths by bone name or by body part (`left_thigh`, `right_forearm`: the rig's
//! [`super::anatomy`], so one file fits every rig), in metres, from a YAML file.
//!
//! ```yaml
//! height_m: 1.68
//! segments:          # a bone's segment: from the joint to its one child (or its End Site)
//!   LeftUpLeg: 0.42
//!   right_thigh: 0.42  # a body part: whichever joint the rig's right thigh is
//! ```
//!
//! `height_m` scales every offset and End Site by `height_m / h_rig`, `h_rig` the rig's rest
//! pose from its lowest point to its highest; a segment given then sets that segment's length,
//! its direction kept. Zero, negative or non-finite values, unknown bones, bones with several
//! children, and segments more than 3× or less than ⅓ of the rig's own are errors naming the key.

use super::{Rig, RigError};
use nalgebra::Vector3;
use serde::{Deserialize, Serialize};
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

/// A subject's measurements.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Subject {
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub height_m: Option<f64>,
    #[serde(default, skip_serializing_if = "BTreeMap::is_empty")]
    pub segments: BTreeMap<String, f64>,
}

#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("{}: {message}", .path.display())]
pub struct SubjectError {
    pub path: PathBuf,
    pub message: String,
}

/// The joint of a body part named by its key (`left_thigh`; [`super::anatomy::Part::key`]): the
/// part's joint, the spine's top for `thorax`, the neck's first joint for `neck`.
fn part_joint(rig: &Rig, key: &str) -> Option<usize> {
    use super::anatomy::{Anatomy, Part};
    let part = Part::all().into_iter().find(|p| p.key() == key)?;
    let joints = Anatomy::of(rig).joints(part);
    match part {
        Part::Spine => joints.last().copied(),
        _ => joints.first().copied(),
    }
}

impl Subject {
    pub fn load(path: &Path) -> Result<Subject, SubjectError> {
        let err = |message: String| SubjectError {
            path: path.to_path_buf(),
            message,
        };
        let text = std::fs::read_to_string(path).map_err(|e| err(format!("cannot read: {e}")))?;
        Subject::parse(&text, path)
    }

    /// A subject file's text; `path` names the file in errors.
    pub fn parse(text: &str, path: &Path) -> Result<Subject, SubjectError> {
        let err = |message: String| SubjectError {
            path: path.to_path_buf(),
            message,
        };
        serde_yaml::from_str(text).map_err(|e| {
            err(format!(
                "{e}; expected `height_m: <metres>` and/or `segments: {{<bone>: <metres>}}`"
            ))
        })
    }

    /// `rig` scaled to this subject; `path` names the file in errors. `standing`: the local
    /// rotations of the pose the subject stands in (the calibration pose; `None`: the rest
    /// pose), whose height [`Rig::extent_in`] `height_m` is — a zero pose need not stand.
    pub fn apply(
        &self,
        rig: &Rig,
        standing: Option<&[nalgebra::UnitQuaternion<f64>]>,
        path: &Path,
    ) -> Result<Rig, SubjectError> {
        let err = |message: String| SubjectError {
            path: path.to_path_buf(),
            message,
        };
        let metres = rig.units().metres_per_unit();
        let mut offsets: Vec<Vector3<f64>> = rig.joints().iter().map(|j| j.offset).collect();
        let mut ends: Vec<Option<Vector3<f64>>> = rig.joints().iter().map(|j| j.end_site).collect();
        if let Some(h) = self.height_m {
            if !(h.is_finite() && h > 0.0) {
                return Err(err(format!("`height_m`: {h} is not a height above 0 m")));
            }
            let (low, high) = standing.map_or_else(|| rig.rest_extent(), |p| rig.extent_in(p));
            let rig_h = (high - low) * metres;
            let ratio = h / rig_h;
            if !(1.0 / 3.0..=3.0).contains(&ratio) {
                return Err(err(format!(
                    "`height_m`: {h} m is {ratio:.2}× the rig's own {rig_h:.3} m; expected within ⅓–3×"
                )));
            }
            offsets.iter_mut().for_each(|o| *o *= ratio);
            ends.iter_mut().flatten().for_each(|e| *e *= ratio);
        }
        for (bone, &length) in &self.segments {
            let key = format!("`segments.{bone}`");
            if !(length.is_finite() && length > 0.0) {
                return Err(err(format!("{key}: {length} is not a length above 0 m")));
            }
            let j = rig
                .joint_index(bone)
                .or_else(|| part_joint(rig, bone))
                .ok_or_else(|| {
                    err(format!(
                        "{key}: the rig `{}` has no bone `{bone}`, and it is no body part found in \
                     it (`imubake inspect {}` lists them)",
                        rig.name(),
                        rig.name()
                    ))
                })?;
            let children: Vec<usize> = rig.children(j).collect();
            let own = match children.as_slice() {
                [c] => offsets[*c].norm() * metres,
                [] => ends[j].map_or(0.0, |e| e.norm() * metres),
                _ => {
                    return Err(err(format!(
                        "{key}: `{bone}` has {} children, so its segment is not one length; give its \
                         children's segments instead",
                        children.len()
                    )));
                }
            };
            if own <= 0.0 {
                return Err(err(format!(
                    "{key}: `{bone}` has no segment of its own to scale"
                )));
            }
            let ratio = length / own;
            if !(1.0 / 3.0..=3.0).contains(&ratio) {
                return Err(err(format!(
                    "{key}: {length} m is {ratio:.2}× the rig's own {own:.3} m; expected within ⅓–3×"
                )));
            }
            match children.as_slice() {
                [c] => offsets[*c] *= ratio,
                _ => ends[j] = ends[j].map(|e| e * ratio),
            }
        }
        rig.with_lengths(offsets, ends)
            .map_err(|e: RigError| err(e.to_string()))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::rig::load_rig;

    #[test]
    fn a_body_part_key_fits_rigs_of_any_naming() {
        // The same file on Mixamo's names and on Poser's: the left thigh is 0.5 m on both.
        let s = Subject {
            height_m: None,
            segments: [("left_thigh".to_string(), 0.5)].into(),
        };
        let mixamo = load_rig("mixamo").unwrap();
        let scaled = s.apply(&mixamo, None, Path::new("s.yaml")).unwrap();
        let knee = scaled.joint_index("LeftLeg").unwrap();
        assert!((scaled.joints()[knee].offset.norm() - 0.5).abs() < 1e-12);
        let poser = "name: poser\njoints:\n  - {name: hip, offset: [0, 1, 0]}\n  - {name: lThigh, parent: hip, offset: [0.1, 0, 0]}\n  - {name: lShin, parent: lThigh, offset: [0, -0.4, 0]}\n  - {name: lFoot, parent: lShin, offset: [0, -0.4, 0], end_site: [0, 0, 0.1]}\n  - {name: rThigh, parent: hip, offset: [-0.1, 0, 0]}\n  - {name: rShin, parent: rThigh, offset: [0, -0.4, 0]}\n  - {name: rFoot, parent: rShin, offset: [0, -0.4, 0], end_site: [0, 0, 0.1]}\n";
        let rig = crate::rig::file::parse_rig(poser, Path::new("poser.yaml")).unwrap();
        let scaled = s.apply(&rig, None, Path::new("s.yaml")).unwrap();
        let knee = scaled.joint_index("lShin").unwrap();
        assert!((scaled.joints()[knee].offset.norm() - 0.5).abs() < 1e-12);
        let other = scaled.joint_index("rShin").unwrap();
        assert!((scaled.joints()[other].offset.norm() - 0.4).abs() < 1e-12);
    }

    #[test]
    fn height_scales_everything_and_segments_set_their_length() {
        let rig = load_rig("mixamo").unwrap();
        let h = rig.standing_height();
        let s = Subject {
            height_m: Some(h * 0.9),
            segments: [("LeftUpLeg".to_string(), 0.5)].into(),
        };
        let scaled = s.apply(&rig, None, Path::new("s.yaml")).unwrap();
        let leg = scaled.joint_index("LeftLeg").unwrap();
        assert!((scaled.joints()[leg].offset.norm() - 0.5).abs() < 1e-12);
        let spine = scaled.joint_index("Spine").unwrap();
        assert!((scaled.joints()[spine].offset - rig.joints()[spine].offset * 0.9).norm() < 1e-12);
        // Height alone: the standing height is the subject's.
        let tall = Subject {
            height_m: Some(1.9),
            ..Default::default()
        }
        .apply(&rig, None, Path::new("s.yaml"))
        .unwrap();
        assert!((tall.standing_height() - 1.9).abs() < 1e-9);
        assert_eq!(tall.pose_names(), rig.pose_names());
    }

    #[test]
    fn bad_values_name_their_key() {
        let rig = load_rig("mixamo").unwrap();
        let bad = |yaml: &str| {
            let s: Subject = serde_yaml::from_str(yaml).unwrap();
            s.apply(&rig, None, Path::new("s.yaml"))
                .unwrap_err()
                .to_string()
        };
        assert!(bad("height_m: -1").contains("`height_m`"));
        assert!(bad("height_m: 9").contains("within ⅓–3×"));
        assert!(bad("segments: {LeftUpLeg: 0}").contains("`segments.LeftUpLeg`"));
        assert!(bad("segments: {LeftUpLeg: 3.0}").contains("`segments.LeftUpLeg`: 3 m"));
        assert!(bad("segments: {Tail: 0.3}").contains("no bone `Tail`"));
        assert!(bad("segments: {Hips: 0.3}").contains("children"));
        assert!(serde_yaml::from_str::<Subject>("heigth_m: 1.7").is_err());
    }
}
