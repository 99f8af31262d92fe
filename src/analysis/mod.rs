//! Biomechanical analysis of an animation (paper 000, chapters IV and VI): joint angles per frame
//! and their comparison with a reference.
//!
//! - [`segments`]: which joints of a rig are the anatomical segments (a table for mixamo, sou12
//!   and common BVH skeletons; a rig file's `segments:` for others), and each segment's
//!   anatomical frame at rest.
//! - [`angles`]: per frame, paper 000's angle between adjacent segment vectors and the signed
//!   anatomical angles of a joint coordinate decomposition in the ISB manner.
//! - [`table`]: a table of angle series (CSV and JSON, in and out).
//! - [`compare`]: two tables synchronised (cross-correlation or a clap-like spike), then RMSE
//!   and Pearson's r per angle, as paper 000's Table 1.
//!
//! Angles are in degrees and times in seconds throughout.

pub mod angles;
pub mod compare;
pub mod segments;
pub mod table;

pub use angles::JointAngles;
pub use compare::{CompareOptions, Comparison, Sync, compare};
pub use segments::Segments;
pub use table::AngleTable;

use std::path::PathBuf;

#[derive(Debug, thiserror::Error)]
pub enum AnalysisError {
    #[error(
        "rig `{rig}`: no anatomical segments found (no pelvis, thighs or upper arms among its joints by name or shape; `imubake inspect <rig>` shows what was found; a rig file's `segments:` can name them)"
    )]
    NoSegments { rig: String },
    #[error(
        "rig `{rig}`: cannot tell left from right (no left and right thighs or upper arms; closest by name: {closest}; `imubake inspect <rig>` shows what was found)"
    )]
    NoSides { rig: String, closest: String },
    #[error(
        "rig `{rig}`: `segments:` `{landmark}` (`{joint}`) is not below `{above}` (`{above_joint}`)"
    )]
    NotBelow {
        rig: String,
        landmark: String,
        joint: String,
        above: String,
        above_joint: String,
    },
    #[error("`{rig}`: {reason}")]
    Rig { rig: String, reason: String },
    #[error("{path}: line {line}: {reason}")]
    Table {
        path: PathBuf,
        line: usize,
        reason: String,
    },
    #[error("{path}: {source}")]
    Io {
        path: PathBuf,
        source: std::io::Error,
    },
    #[error("no angle appears in both tables (the first has {a}; the second {b})")]
    NothingInCommon { a: String, b: String },
    #[error("`{0}`: no such angle in both tables")]
    UnknownAngle(String),
    #[error("{0}")]
    Sync(String),
}

impl crate::diagnostic::Diagnostic for AnalysisError {
    fn file(&self) -> Option<&std::path::Path> {
        match self {
            AnalysisError::Table { path, .. } | AnalysisError::Io { path, .. } => Some(path),
            _ => None,
        }
    }

    fn line(&self) -> Option<u64> {
        match self {
            AnalysisError::Table { line, .. } => Some(*line as u64),
            _ => None,
        }
    }

    fn hint(&self) -> Option<&'static str> {
        match self {
            AnalysisError::NoSegments { .. }
            | AnalysisError::NoSides { .. }
            | AnalysisError::NotBelow { .. } => {
                Some("name the landmarks in the rig file's `segments:` (docs: angles)")
            }
            AnalysisError::Sync(_) => Some("choose the angle with --sync-angle, or --sync none"),
            _ => None,
        }
    }
}
