//! The capture formats a take can come from (what [`crate::read`] reads, and what the sidecar
//! records as `source.format`).

use serde::Serialize;
use std::fmt;
use std::str::FromStr;

/// The capture formats imubake reads.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize)]
#[serde(rename_all = "kebab-case")]
pub enum InputFormat {
    /// Paper 002's SOU log: `timestamp_ms,SOU_ID,yaw1,pitch1,roll1,yaw2,pitch2,roll2`.
    Sou,
    /// imubake's own CSV (README, "imubake CSV").
    ImubakeCsv,
    /// OpenSense orientation `.sto` (quaternions per `<body>_imu` column).
    OpensenseSto,
    /// Movella/Xsens DOT CSV export: a folder with one file per sensor (or one such file).
    XsensDot,
    /// Xsens MTw `.txt` export (MT Manager, as used by OpenSense): one file, or a folder of them.
    XsensMtw,
    /// x-io x-IMU3 session folder, one sub-folder per device.
    XioSession,
    /// x-io Fusion's raw-readings CSV (`Time (s),Gyroscope X (deg/s),…`): one sensor.
    XioFusionCsv,
    /// Xsens MVN's MVNX export (XML): each sensor's orientation, Xsens's foot contacts.
    XsensMvnx,
    /// A BVH file's motion: not a sensor capture; `convert` retargets it onto the rig.
    Bvh,
    /// WitMotion's binary serial stream (WT901 and relatives): one recording per sensor.
    #[serde(rename = "witmotion")]
    WitMotion,
    /// APDM Opal `.h5` (HDF5; the cargo feature `hdf5`).
    ApdmH5,
    /// A home-made device's frames, read through a declared layout (`--layout FILE`).
    Layout,
}

impl InputFormat {
    pub const ALL: [InputFormat; 12] = [
        InputFormat::Sou,
        InputFormat::ImubakeCsv,
        InputFormat::OpensenseSto,
        InputFormat::XsensDot,
        InputFormat::XsensMtw,
        InputFormat::XioSession,
        InputFormat::XioFusionCsv,
        InputFormat::XsensMvnx,
        InputFormat::Bvh,
        InputFormat::WitMotion,
        InputFormat::ApdmH5,
        InputFormat::Layout,
    ];

    pub fn name(self) -> &'static str {
        match self {
            InputFormat::Sou => "sou",
            InputFormat::ImubakeCsv => "imubake-csv",
            InputFormat::OpensenseSto => "opensense-sto",
            InputFormat::XsensDot => "xsens-dot",
            InputFormat::XsensMtw => "xsens-mtw",
            InputFormat::XioSession => "xio-session",
            InputFormat::XioFusionCsv => "xio-fusion-csv",
            InputFormat::XsensMvnx => "xsens-mvnx",
            InputFormat::Bvh => "bvh",
            InputFormat::WitMotion => "witmotion",
            InputFormat::ApdmH5 => "apdm-h5",
            InputFormat::Layout => "layout",
        }
    }

    /// What a person would call it.
    pub fn description(self) -> &'static str {
        match self {
            InputFormat::Sou => "paper-002 SOU log",
            InputFormat::ImubakeCsv => "imubake CSV",
            InputFormat::OpensenseSto => "OpenSense orientation .sto",
            InputFormat::XsensDot => "Movella/Xsens DOT CSV export",
            InputFormat::XsensMtw => "Xsens MTw .txt export",
            InputFormat::XioSession => "x-io x-IMU3 session",
            InputFormat::XioFusionCsv => "x-io Fusion raw-readings CSV",
            InputFormat::XsensMvnx => "Xsens MVN .mvnx export",
            InputFormat::Bvh => "BVH motion",
            InputFormat::WitMotion => "WitMotion binary stream",
            InputFormat::ApdmH5 => "APDM Opal .h5",
            InputFormat::Layout => "frames of a declared layout (--layout FILE)",
        }
    }
}

impl fmt::Display for InputFormat {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}

impl FromStr for InputFormat {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, Self::Err> {
        InputFormat::ALL
            .into_iter()
            .find(|f| f.name() == s)
            .ok_or_else(|| {
                let names: Vec<_> = InputFormat::ALL.iter().map(|f| f.name()).collect();
                format!(
                    "unknown input format `{s}`; expected one of {}",
                    names.join(", ")
                )
            })
    }
}
