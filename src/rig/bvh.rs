//! A BVH hierarchy as a rig (the `bvh` module knows nothing of rigs: rigs build on it).

use super::{Joint, LengthUnit, Rig, RigError};
use crate::bvh::Bvh;

impl Bvh {
    /// The hierarchy as a [`Rig`] named `name` whose offsets are in `units` (the unit the file's
    /// numbers are in; nothing is scaled).
    ///
    /// Joint order and names are the file's; each joint's Euler order is that of its rotation
    /// channels ([`crate::bvh::BvhJoint::rotation_order`]: a joint without rotation channels gets ZXY);
    /// End Sites are kept as [`Joint::end_site`]; the root's offset is its OFFSET line. Fails if
    /// the file repeats a joint name (BVH allows it, a rig does not).
    pub fn to_rig(&self, name: &str, units: LengthUnit) -> Result<Rig, RigError> {
        let joints = self
            .joints()
            .iter()
            .map(|j| Joint {
                name: j.name.clone(),
                parent: j.parent,
                offset: j.offset,
                order: j.rotation_order(),
                end_site: j.end_site,
            })
            .collect();
        Rig::new(name, units, joints)
    }
}
