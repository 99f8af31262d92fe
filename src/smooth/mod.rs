//! Smoothing filters and their settings (README, "Smoothing"): `butterworth`, `gaussian` and
//! `fft` filter uniform series, matching scipy and numpy; `method` parses
//! `--smooth METHOD[:key=value,...]`. The pipeline's smoothing stage
//! ([`crate::pipeline::smoothing`]) applies them to rotation tracks.

pub mod butterworth;
pub mod fft;
pub mod gaussian;
mod method;

pub use method::{DEFAULT, Method, NotCausal};

use serde::Serialize;
use std::collections::BTreeMap;

/// Smoothing for a conversion: one method, with per-bone overrides.
#[derive(Debug, Clone, PartialEq, Default, Serialize)]
pub struct Smoothing {
    #[serde(flatten)]
    pub method: Method,
    /// Bone name → its own method.
    #[serde(skip_serializing_if = "BTreeMap::is_empty")]
    pub bones: BTreeMap<String, Method>,
}

impl Smoothing {
    pub fn none() -> Smoothing {
        Smoothing {
            method: Method::None,
            bones: BTreeMap::new(),
        }
    }

    /// The method for a bone (names match with or without `mixamorig:`, as the rig's do).
    pub fn for_bone(&self, bone: &str) -> &Method {
        let bare = |n: &str| n.rsplit(':').next().unwrap_or(n).to_string();
        self.bones
            .iter()
            .find(|(name, _)| *name == bone || bare(name) == bare(bone))
            .map_or(&self.method, |(_, m)| m)
    }

    /// For people: `butterworth:order=4,cutoff=14 (LeftHand: none)`.
    pub fn describe(&self) -> String {
        let mut text = self.method.to_string();
        if !self.bones.is_empty() {
            let overrides: Vec<String> = self
                .bones
                .iter()
                .map(|(b, m)| format!("{b}: {m}"))
                .collect();
            text += &format!(" ({})", overrides.join(", "));
        }
        text
    }

    /// True when nothing is smoothed.
    pub fn is_none(&self) -> bool {
        self.method == Method::None && self.bones.values().all(|m| *m == Method::None)
    }
}
