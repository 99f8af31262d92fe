//! Rotation helpers: Euler orders and conversions, the Euler discontinuity filter, quaternion
//! hemisphere continuity and resampling.

pub mod euler;
pub mod quat;

pub use quat::{angle_between, make_hemisphere_continuous, slerp_shortest};

use serde::{Deserialize, Serialize};
use std::fmt;
use std::str::FromStr;

/// An angle difference in degrees brought into (−180°, 180°].
pub fn wrap_deg(d: f64) -> f64 {
    let r = d.rem_euclid(360.0);
    if r > 180.0 { r - 360.0 } else { r }
}

/// An intrinsic Euler order, named by the order its rotations are applied as BVH channel lists
/// are: `ZXY` (BVH `Zrotation Xrotation Yrotation`) means R = Rz · Rx · Ry. Blender names the same
/// rotation mode with the string reversed (`'YXZ'`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[allow(clippy::upper_case_acronyms)]
pub enum EulerOrder {
    XYZ,
    XZY,
    YXZ,
    YZX,
    ZXY,
    ZYX,
}

impl EulerOrder {
    pub const ALL: [EulerOrder; 6] = [
        EulerOrder::XYZ,
        EulerOrder::XZY,
        EulerOrder::YXZ,
        EulerOrder::YZX,
        EulerOrder::ZXY,
        EulerOrder::ZYX,
    ];

    /// The axes in application order (0 = x, 1 = y, 2 = z): ZXY → [2, 0, 1].
    #[inline]
    pub fn axes(self) -> [usize; 3] {
        match self {
            EulerOrder::XYZ => [0, 1, 2],
            EulerOrder::XZY => [0, 2, 1],
            EulerOrder::YXZ => [1, 0, 2],
            EulerOrder::YZX => [1, 2, 0],
            EulerOrder::ZXY => [2, 0, 1],
            EulerOrder::ZYX => [2, 1, 0],
        }
    }

    pub fn name(self) -> &'static str {
        match self {
            EulerOrder::XYZ => "XYZ",
            EulerOrder::XZY => "XZY",
            EulerOrder::YXZ => "YXZ",
            EulerOrder::YZX => "YZX",
            EulerOrder::ZXY => "ZXY",
            EulerOrder::ZYX => "ZYX",
        }
    }

    /// Blender's name for the same rotation mode (the string reversed).
    pub fn blender_name(self) -> &'static str {
        match self {
            EulerOrder::XYZ => "ZYX",
            EulerOrder::XZY => "YZX",
            EulerOrder::YXZ => "ZXY",
            EulerOrder::YZX => "XZY",
            EulerOrder::ZXY => "YXZ",
            EulerOrder::ZYX => "XYZ",
        }
    }

    /// The BVH channel names in order: ZXY → ["Zrotation", "Xrotation", "Yrotation"].
    pub fn bvh_channels(self) -> [&'static str; 3] {
        self.axes()
            .map(|a| ["Xrotation", "Yrotation", "Zrotation"][a])
    }
}

impl fmt::Display for EulerOrder {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}

impl FromStr for EulerOrder {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, Self::Err> {
        let upper = s.trim().to_ascii_uppercase();
        EulerOrder::ALL
            .into_iter()
            .find(|o| o.name() == upper)
            .ok_or_else(|| {
                format!("unknown Euler order `{s}`; expected one of XYZ, XZY, YXZ, YZX, ZXY, ZYX")
            })
    }
}
