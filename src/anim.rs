//! The animation a conversion produces: per-joint local rotations and the root position on a
//! frame grid, for one rig.

use crate::fps::Fps;
use crate::rig::Rig;
use nalgebra::{UnitQuaternion, Vector3};

/// Keyframes on the grid t = n / fps, n = 0 .. frames − 1.
///
/// Invariants (checked by [`Animation::new`]): at least one frame; one rotation track per rig
/// joint, each `frames` long; `frames` root positions; everything finite.
#[derive(Debug, Clone, PartialEq)]
pub struct Animation {
    rig: Rig,
    fps: Fps,
    frames: usize,
    /// `local[joint][frame]`: q_parent_joint (the root's is q_world_root), rig world axes.
    local: Vec<Vec<UnitQuaternion<f64>>>,
    /// Which joints move: those a sensor drives, and those between two of them that share
    /// their bend (the others keep their rest rotation).
    animated: Vec<bool>,
    /// Per frame: left and right foot planted (foot-rooted root motion), when known.
    contacts: Option<Vec<[bool; 2]>>,
    /// Joints (other than the root) whose translation from their parent is animated: per frame,
    /// replacing the rig's offset (rig units, the parent's axes).
    translations: Vec<(usize, Vec<Vector3<f64>>)>,
    /// Root joint position per frame, rig units, rig world (Y up).
    root_positions: Vec<Vector3<f64>>,
    /// The standing pose's lowest and highest points' heights (the floor and the top of the
    /// head), rig units, the root at its rest offset: the calibration pose's when the pipeline
    /// made the animation ([`Animation::standing_in`]), else the rest pose's.
    standing: (f64, f64),
}

/// One frame of an animation: what a stream emits. Every joint's local rotation (rig world
/// axes; the root's is its world rotation) and the root position (rig units), at frame `frame`
/// (time `time_s` = frame / fps).
#[derive(Debug, Clone, PartialEq)]
pub struct Pose {
    pub frame: u64,
    pub time_s: f64,
    pub local: Vec<UnitQuaternion<f64>>,
    pub root: Vector3<f64>,
    /// Left and right foot planted (foot-rooted root motion; false otherwise).
    pub contact: [bool; 2],
    /// Both feet off the floor (foot-rooted root motion).
    pub airborne: bool,
}

/// An [`Animation`] built by collecting [`Pose`]s (frame after frame).
pub struct AnimationBuilder {
    rig: Rig,
    fps: Fps,
    local: Vec<Vec<UnitQuaternion<f64>>>,
    roots: Vec<Vector3<f64>>,
}

impl AnimationBuilder {
    pub fn new(rig: Rig, fps: Fps) -> AnimationBuilder {
        let joints = rig.len();
        AnimationBuilder {
            rig,
            fps,
            local: vec![Vec::new(); joints],
            roots: Vec::new(),
        }
    }

    /// Adds the next frame (`pose.local` has one rotation per joint).
    pub fn push(&mut self, pose: &Pose) {
        for (track, q) in self.local.iter_mut().zip(&pose.local) {
            track.push(*q);
        }
        self.roots.push(pose.root);
    }

    /// Frames collected so far.
    pub fn frames(&self) -> usize {
        self.roots.len()
    }

    /// The animation of frames `first ..` (a `--trim` of the collected frames), with `animated`
    /// saying which joints carry motion.
    pub fn finish(
        mut self,
        first: usize,
        frames: usize,
        animated: Vec<bool>,
    ) -> Result<Animation, AnimationError> {
        fn keep<T>(v: &mut Vec<T>, first: usize, frames: usize) {
            v.truncate(first + frames);
            v.drain(..first.min(v.len()));
        }
        for track in &mut self.local {
            keep(track, first, frames);
        }
        keep(&mut self.roots, first, frames);
        Animation::new(self.rig, self.fps, self.local, animated, self.roots)
    }
}

#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum AnimationError {
    #[error("an animation needs at least one frame")]
    NoFrames,
    #[error("{what}: expected {expected} entries, found {found}")]
    Length {
        what: String,
        expected: usize,
        found: usize,
    },
    #[error("{0} holds a value that is not finite")]
    NonFinite(String),
    #[error("its skeleton is not a rig: {0}")]
    Rig(String),
}

impl Animation {
    pub fn new(
        rig: Rig,
        fps: Fps,
        local: Vec<Vec<UnitQuaternion<f64>>>,
        animated: Vec<bool>,
        root_positions: Vec<Vector3<f64>>,
    ) -> Result<Animation, AnimationError> {
        let frames = root_positions.len();
        if frames == 0 {
            return Err(AnimationError::NoFrames);
        }
        let check = |what: &str, expected: usize, found: usize| {
            if expected == found {
                Ok(())
            } else {
                Err(AnimationError::Length {
                    what: what.to_string(),
                    expected,
                    found,
                })
            }
        };
        check("joint rotation tracks", rig.len(), local.len())?;
        check("animated flags", rig.len(), animated.len())?;
        for (j, track) in local.iter().enumerate() {
            check(
                &format!("rotations of `{}`", rig.joints()[j].name),
                frames,
                track.len(),
            )?;
            if track
                .iter()
                .any(|q| !q.coords.iter().all(|v| v.is_finite()))
            {
                return Err(AnimationError::NonFinite(format!(
                    "rotations of `{}`",
                    rig.joints()[j].name
                )));
            }
        }
        if root_positions
            .iter()
            .any(|p| !p.iter().all(|v| v.is_finite()))
        {
            return Err(AnimationError::NonFinite("root positions".into()));
        }
        Ok(Animation {
            standing: rig.rest_extent(),
            rig,
            fps,
            frames,
            local,
            animated,
            root_positions,
            contacts: None,
            translations: Vec::new(),
        })
    }

    /// The pose the subject stood in, by its lowest and highest points' heights (rig units,
    /// [`Rig::extent_in`]): the floor the root motion stood the body on, and the standing
    /// height; the rest pose's need not stand.
    pub fn standing_in(mut self, extent: (f64, f64)) -> Animation {
        self.standing = extent;
        self
    }

    /// The floor's height, rig units, rig world.
    pub fn floor_y(&self) -> f64 {
        self.standing.0
    }

    /// The standing height, rig units: the standing pose's extent from floor to top.
    pub fn standing_height(&self) -> f64 {
        self.standing.1 - self.standing.0
    }

    /// Joints (other than the root) with an animated translation, and per frame that translation
    /// (rig units, in the parent's axes, replacing the rig's offset).
    pub fn translations(&self) -> &[(usize, Vec<Vector3<f64>>)] {
        &self.translations
    }

    /// `--in-place`: a new `root` joint at floor level above the old root (the hips) carries the
    /// hips' horizontal motion — the root-motion convention Unreal and Unity import. The root
    /// joint sits below the hips' rest position on the rest pose's floor, turns not, and moves
    /// horizontally with the hips; the hips keep a constant horizontal place over it and carry
    /// only their height above the floor (an animated translation).
    pub fn in_place(self) -> Result<Animation, AnimationError> {
        let old = self.rig.joints();
        let rest_hips = old[0].offset;
        let (floor, standing) = (self.floor_y(), self.standing);
        let name = if old.iter().any(|j| j.name == "root") {
            "imubake_root"
        } else {
            "root"
        };
        let mut joints = Vec::with_capacity(old.len() + 1);
        joints.push(crate::rig::Joint {
            name: name.to_string(),
            parent: None,
            offset: Vector3::new(rest_hips.x, floor, rest_hips.z),
            order: old[0].order,
            end_site: None,
        });
        for (i, j) in old.iter().enumerate() {
            joints.push(crate::rig::Joint {
                parent: Some(j.parent.map_or(0, |p| p + 1)),
                offset: if i == 0 {
                    Vector3::new(0.0, rest_hips.y - floor, 0.0)
                } else {
                    j.offset
                },
                ..j.clone()
            });
        }
        let rig = Rig::new(self.rig.name(), self.rig.units(), joints)
            .map_err(|e| AnimationError::NonFinite(format!("the in-place rig: {e}")))?;
        let frames = self.frames;
        let roots: Vec<Vector3<f64>> = self
            .root_positions
            .iter()
            .map(|p| Vector3::new(p.x, floor, p.z))
            .collect();
        let hips: Vec<Vector3<f64>> = self
            .root_positions
            .iter()
            .map(|p| Vector3::new(0.0, p.y - floor, 0.0))
            .collect();
        let mut local = Vec::with_capacity(self.local.len() + 1);
        local.push(vec![UnitQuaternion::identity(); frames]);
        local.extend(self.local);
        let mut animated = vec![false];
        animated.extend(self.animated);
        let translations = std::iter::once((1, hips))
            .chain(self.translations.into_iter().map(|(j, t)| (j + 1, t)))
            .collect();
        let contacts = self.contacts;
        let mut out = Animation::new(rig, self.fps, local, animated, roots)?.standing_in(standing);
        out.contacts = contacts;
        out.translations = translations;
        Ok(out)
    }

    /// The feet's contacts, one `[left, right]` per frame.
    pub fn with_contacts(mut self, per_frame: Vec<[bool; 2]>) -> Result<Animation, AnimationError> {
        if per_frame.len() != self.frames {
            return Err(AnimationError::Length {
                what: "foot contacts".into(),
                expected: self.frames,
                found: per_frame.len(),
            });
        }
        self.contacts = Some(per_frame);
        Ok(self)
    }

    /// Per frame, left and right foot planted (foot-rooted root motion only).
    pub fn contacts(&self) -> Option<&[[bool; 2]]> {
        self.contacts.as_deref()
    }

    /// The rest pose as a new frame 0 (every rotation the rig's rest, the root at its rest
    /// position, no contact), the take from frame 1: the bind frame engines retarget from.
    pub fn with_bind_frame(mut self) -> Animation {
        for track in &mut self.local {
            track.insert(0, UnitQuaternion::identity());
        }
        self.root_positions.insert(0, self.rig.joints()[0].offset);
        if let Some(c) = &mut self.contacts {
            c.insert(0, [false; 2]);
        }
        for (j, t) in &mut self.translations {
            t.insert(0, self.rig.joints()[*j].offset);
        }
        self.frames += 1;
        self
    }

    /// A BVH file's motion as an animation on its own skeleton (`Bvh::to_rig`, rest = every
    /// channel zero): each joint's rotation channels as its local rotation, the root's position
    /// channels as the root position, other joints' position channels as animated translations.
    /// `units` is the unit the file's numbers are in, `fps` its rate (the sidecar's exact one, or
    /// [`Fps::from_frame_time_s`]).
    pub fn from_bvh(
        bvh: &crate::bvh::Bvh,
        name: &str,
        units: crate::rig::LengthUnit,
        fps: Fps,
    ) -> Result<Animation, AnimationError> {
        let last = bvh
            .frame_count()
            .checked_sub(1)
            .ok_or(AnimationError::NoFrames)?;
        Animation::from_bvh_window(bvh, name, units, fps, 0..=last)
    }

    /// [`from_bvh`](Animation::from_bvh) of the file's frames `window` only (its first frame
    /// becomes frame 0): a time window of a long take without the whole take in memory twice.
    /// Fails with `NoFrames` when the window is empty or runs past the file's frames.
    pub fn from_bvh_window(
        bvh: &crate::bvh::Bvh,
        name: &str,
        units: crate::rig::LengthUnit,
        fps: Fps,
        window: std::ops::RangeInclusive<usize>,
    ) -> Result<Animation, AnimationError> {
        let rig = bvh
            .to_rig(name, units)
            .map_err(|e| AnimationError::Rig(e.to_string()))?;
        if window.is_empty() || *window.end() >= bvh.frame_count() {
            return Err(AnimationError::NoFrames);
        }
        let joints = bvh.joints();
        let frames = window.clone().count();
        let mut local = vec![Vec::with_capacity(frames); joints.len()];
        let mut roots = Vec::with_capacity(frames);
        let moved: Vec<usize> = (1..joints.len())
            .filter(|&j| joints[j].has_position_channels())
            .collect();
        let mut translations: Vec<(usize, Vec<Vector3<f64>>)> = moved
            .iter()
            .map(|&j| (j, Vec::with_capacity(frames)))
            .collect();
        for n in window {
            for (track, q) in local.iter_mut().zip(bvh.local_rotations(n)) {
                track.push(q);
            }
            let t = bvh.joint_translations(n);
            roots.push(t[0]);
            for (j, track) in &mut translations {
                track.push(t[*j]);
            }
        }
        let animated = joints.iter().map(|j| j.has_rotation_channels()).collect();
        let mut out = Animation::new(rig, fps, local, animated, roots)?;
        if let Some((j, _)) = translations
            .iter()
            .find(|(_, t)| !t.iter().all(|p| p.iter().all(|v| v.is_finite())))
        {
            return Err(AnimationError::NonFinite(format!(
                "translations of `{}`",
                joints[*j].name
            )));
        }
        out.translations = translations;
        Ok(out)
    }

    /// Frames `start ..= end` as an animation of their own (frame `start` becomes frame 0), with
    /// their contacts and translations: a time window of a long take. `None` when the window is
    /// empty or outside the take.
    pub fn window(&self, start: usize, end: usize) -> Option<Animation> {
        if start > end || end >= self.frames {
            return None;
        }
        let range = start..end + 1;
        Some(Animation {
            rig: self.rig.clone(),
            fps: self.fps,
            frames: range.len(),
            local: self
                .local
                .iter()
                .map(|t| t[range.clone()].to_vec())
                .collect(),
            animated: self.animated.clone(),
            contacts: self.contacts.as_ref().map(|c| c[range.clone()].to_vec()),
            translations: self
                .translations
                .iter()
                .map(|(j, t)| (*j, t[range.clone()].to_vec()))
                .collect(),
            root_positions: self.root_positions[range].to_vec(),
            standing: self.standing,
        })
    }

    pub fn rig(&self) -> &Rig {
        &self.rig
    }
    pub fn fps(&self) -> Fps {
        self.fps
    }
    pub fn frames(&self) -> usize {
        self.frames
    }
    /// Seconds from the first to the last frame: (frames − 1) / fps.
    pub fn duration_s(&self) -> f64 {
        self.fps.frame_time_of(self.frames as u64 - 1)
    }
    /// `local(joint)[frame]`.
    pub fn local(&self, joint: usize) -> &[UnitQuaternion<f64>] {
        &self.local[joint]
    }
    /// `locals()[joint][frame]`: every joint's [`Self::local`].
    pub fn locals(&self) -> &[Vec<UnitQuaternion<f64>>] {
        &self.local
    }
    pub fn is_animated(&self, joint: usize) -> bool {
        self.animated[joint]
    }
    pub fn root_positions(&self) -> &[Vector3<f64>] {
        &self.root_positions
    }

    /// Local rotations of every joint at one frame.
    pub fn pose_at(&self, frame: usize) -> Vec<UnitQuaternion<f64>> {
        self.local.iter().map(|t| t[frame]).collect()
    }

    /// World rotations of every joint at one frame.
    pub fn world_at(&self, frame: usize) -> Vec<UnitQuaternion<f64>> {
        self.rig.world_rotations(&self.pose_at(frame))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::rig::LengthUnit;

    /// Two joints; the hips move and turn, the child has position channels too.
    const BVH: &str = "HIERARCHY\nROOT Hips\n{\n OFFSET 0 90 0\n CHANNELS 6 Xposition Yposition \
        Zposition Zrotation Xrotation Yrotation\n JOINT Spine\n {\n  OFFSET 0 10 0\n  CHANNELS 6 \
        Xposition Yposition Zposition Zrotation Xrotation Yrotation\n  End Site\n  {\n   OFFSET 0 \
        5 0\n  }\n }\n}\nMOTION\nFrames: 3\nFrame Time: 0.0333333\n\
        0 90 0 0 0 0 0 10 0 0 0 0\n\
        1 91 2 0 0 90 0 12 0 0 0 0\n\
        2 92 4 30 0 0 0 14 0 0 0 0\n";

    #[test]
    fn a_bvh_motion_is_its_channels_and_a_window_keeps_its_frames() {
        let bvh = crate::bvh::parse(BVH.as_bytes()).unwrap();
        let fps = Fps::from_frame_time_s(bvh.frame_time_s()).unwrap();
        assert_eq!((fps.num(), fps.den()), (30, 1));
        let anim = Animation::from_bvh(&bvh, "t", LengthUnit::Centimetres, fps).unwrap();
        assert_eq!(anim.frames(), 3);
        assert_eq!(anim.root_positions()[1], Vector3::new(1.0, 91.0, 2.0));
        // Frame 1: Yrotation 90° (by hand: the hips' +Z turns to +X).
        let z = anim.local(0)[1] * Vector3::z();
        assert!((z - Vector3::x()).norm() < 1e-12, "{z}");
        // Frame 2: Zrotation 30°.
        assert!((anim.local(0)[2].angle() - 30f64.to_radians()).abs() < 1e-12);
        assert_eq!(anim.translations().len(), 1);
        assert_eq!(anim.translations()[0].1[2], Vector3::new(0.0, 14.0, 0.0));

        let w = anim.window(1, 2).unwrap();
        assert_eq!(w.frames(), 2);
        assert_eq!(w.root_positions()[0], anim.root_positions()[1]);
        assert_eq!(w.local(0)[1], anim.local(0)[2]);
        assert_eq!(w.translations()[0].1[1], Vector3::new(0.0, 14.0, 0.0));
        assert!(anim.window(2, 3).is_none());
        assert!(anim.window(2, 1).is_none());
        assert_eq!(anim.window(2, 2).unwrap().frames(), 1);
        let tail = Animation::from_bvh_window(&bvh, "t", LengthUnit::Centimetres, fps, 1..=2);
        assert_eq!(tail.unwrap(), w);
        assert!(
            Animation::from_bvh_window(&bvh, "t", LengthUnit::Centimetres, fps, 2..=3).is_err()
        );
    }
}
