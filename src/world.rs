//! Sensor world frames (conventions.md, "World frames").

use nalgebra::{Matrix3, Rotation3, UnitQuaternion, Vector3};
use serde::{Deserialize, Serialize};
use std::fmt;
use std::str::FromStr;

/// The world frame a sensor's orientation `q_world_sensor` is expressed in.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum World {
    /// x east, y north, z up.
    Enu,
    /// x north, y east, z down (paper 002's Madgwick output).
    Ned,
    /// x north, y west, z up (x-io x-IMU3, textbook Madgwick).
    Nwu,
    /// OpenSim ground: y up (OpenSense `.sto` files).
    Opensim,
    /// The rig world itself: y up, facing +z, +x left (BVH motion).
    Rig,
}

impl World {
    pub const ALL: [World; 5] = [
        World::Enu,
        World::Ned,
        World::Nwu,
        World::Opensim,
        World::Rig,
    ];

    /// `q_rig_world`: takes vectors from this world into the rig world (Y up, facing +Z, +X
    /// left), keeping the sensors' heading: north → +Z, up → +Y, west → +X. OpenSim ground has no
    /// north: its x (forward) → +Z, y (up) → +Y, z (right) → −X.
    pub fn to_rig(self) -> UnitQuaternion<f64> {
        let (x, y, z) = match self {
            // x east → −X, y north → +Z, z up → +Y
            World::Enu => ([-1.0, 0.0, 0.0], [0.0, 0.0, 1.0], [0.0, 1.0, 0.0]),
            // x north → +Z, y east → −X, z down → −Y
            World::Ned => ([0.0, 0.0, 1.0], [-1.0, 0.0, 0.0], [0.0, -1.0, 0.0]),
            // x north → +Z, y west → +X, z up → +Y
            World::Nwu => ([0.0, 0.0, 1.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]),
            World::Opensim => ([0.0, 0.0, 1.0], [0.0, 1.0, 0.0], [-1.0, 0.0, 0.0]),
            World::Rig => ([1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]),
        };
        let m = Matrix3::from_columns(&[Vector3::from(x), Vector3::from(y), Vector3::from(z)]);
        UnitQuaternion::from_rotation_matrix(&Rotation3::from_matrix_unchecked(m))
    }

    pub fn name(self) -> &'static str {
        match self {
            World::Enu => "enu",
            World::Ned => "ned",
            World::Nwu => "nwu",
            World::Opensim => "opensim",
            World::Rig => "rig",
        }
    }
}

impl fmt::Display for World {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}

/// Where a take's world came from, in precedence order: `--world`, the config file's `world`,
/// the mapping's `world`, the format's own (its default, or what the file declares).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum WorldFrom {
    Flag,
    Config,
    Mapping,
    Format,
}

#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("unknown world frame `{0}`; expected one of enu, ned, nwu, opensim, rig")]
pub struct UnknownWorld(pub String);

impl FromStr for World {
    type Err = UnknownWorld;
    fn from_str(s: &str) -> Result<Self, Self::Err> {
        let lower = s.trim().to_ascii_lowercase();
        World::ALL
            .into_iter()
            .find(|w| w.name() == lower)
            .ok_or_else(|| UnknownWorld(s.to_string()))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn worlds_map_north_to_plus_z_and_up_to_plus_y() {
        let close = |a: Vector3<f64>, b: [f64; 3]| (a - Vector3::from(b)).norm() < 1e-12;
        // Unit vectors written in each world: north, up, west.
        let cases = [
            (
                World::Enu,
                [0.0, 1.0, 0.0],
                [0.0, 0.0, 1.0],
                [-1.0, 0.0, 0.0],
            ),
            (
                World::Ned,
                [1.0, 0.0, 0.0],
                [0.0, 0.0, -1.0],
                [0.0, -1.0, 0.0],
            ),
            (
                World::Nwu,
                [1.0, 0.0, 0.0],
                [0.0, 0.0, 1.0],
                [0.0, 1.0, 0.0],
            ),
        ];
        for (world, north, up, west) in cases {
            let c = world.to_rig();
            assert!(
                close(c * Vector3::from(north), [0.0, 0.0, 1.0]),
                "{world} north"
            );
            assert!(close(c * Vector3::from(up), [0.0, 1.0, 0.0]), "{world} up");
            assert!(
                close(c * Vector3::from(west), [1.0, 0.0, 0.0]),
                "{world} west"
            );
        }
        let c = World::Opensim.to_rig();
        assert!(close(c * Vector3::y(), [0.0, 1.0, 0.0]));
        assert!(close(c * Vector3::x(), [0.0, 0.0, 1.0]));
    }
}
