//! Sensor world frames (conventions.md, "World frames").

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
}

impl World {
    pub const ALL: [World; 4] = [World::Enu, World::Ned, World::Nwu, World::Opensim];

    pub fn name(self) -> &'static str {
        match self {
            World::Enu => "enu",
            World::Ned => "ned",
            World::Nwu => "nwu",
            World::Opensim => "opensim",
        }
    }
}

impl fmt::Display for World {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}

#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("unknown world frame `{0}`; expected one of enu, ned, nwu, opensim")]
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
