//! The output transforms, applied in order to every mode's [`Conversion`] as it is written:
//! `--in-place`, then `--bind-frame`. The plan lists them (`Plan::transforms`).

use super::take::Conversion;
use crate::anim::AnimationError;
use nalgebra::UnitQuaternion;

/// One transform of a converted take.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum OutputTransform {
    /// `--in-place` ([`crate::anim::Animation::in_place`]): a `root` joint at floor level carries
    /// the hips' horizontal motion.
    InPlace,
    /// `--bind-frame`: the rest pose as frame 0, the take from frame 1.
    BindFrame,
}

impl OutputTransform {
    fn apply(self, conversion: Conversion) -> Result<Conversion, AnimationError> {
        match self {
            OutputTransform::InPlace => in_place(conversion),
            OutputTransform::BindFrame => Ok(with_bind_frame(conversion)),
        }
    }
}

/// `conversion` through each of `transforms`, in order.
pub fn apply_all(
    conversion: Conversion,
    transforms: &[OutputTransform],
) -> Result<Conversion, AnimationError> {
    transforms.iter().try_fold(conversion, |c, t| t.apply(c))
}

/// `--in-place`: the animation gets a `root` joint; the BVH channels (a zero row for the new
/// joint in paper 002's mode) and the report's unsmoothed rotations get it too.
fn in_place(mut c: Conversion) -> Result<Conversion, AnimationError> {
    c.animation = c.animation.in_place()?;
    let frames = c.animation.frames();
    if let Some(euler_deg) = &mut c.euler_deg {
        euler_deg.insert(0, vec![[0.0; 3]; frames]);
    }
    if let Some(unsmoothed) = &mut c.unsmoothed {
        unsmoothed.insert(0, vec![UnitQuaternion::identity(); frames]);
    }
    c.pipeline.in_place = true;
    Ok(c)
}

/// The rest pose as frame 0, the take from frame 1: the animation, its BVH channels (the
/// quaternion mode's again from the rotations, so the Euler filter runs on from the rest pose;
/// paper 002's channels start from zeros), the report's unsmoothed rotations and the contacts
/// move one frame on.
fn with_bind_frame(mut c: Conversion) -> Conversion {
    c.animation = c.animation.with_bind_frame();
    for track in c.euler_deg.iter_mut().flatten() {
        track.insert(0, [0.0; 3]);
    }
    if let Some(unsmoothed) = &mut c.unsmoothed {
        for track in unsmoothed {
            track.insert(0, UnitQuaternion::identity());
        }
    }
    if let Some(contacts) = &mut c.contacts {
        for r in contacts
            .left
            .iter_mut()
            .chain(&mut contacts.right)
            .chain(&mut contacts.airborne)
        {
            *r = [r[0] + 1, r[1] + 1];
        }
        contacts.per_frame.insert(0, [false; 2]);
    }
    c.pipeline.bind_frame = true;
    c
}
