//! `imubake view`: a take in the browser. A small HTTP server on loopback serves one page
//! (three.js, vendored, with its glTF loader and animation mixer), the take's description
//! (`/take.json`) and its motion as GLB chunks of a fixed length (`/chunk/<k>.glb`), loaded by
//! the page on demand so that an hour-long take opens at once. A live session (`imubake live
//! --preview`) serves the same page with the rig at rest and its poses over a WebSocket
//! (`/live`).
//!
//! Only those paths exist: nothing is served from the file system, so no path can reach a
//! file that is not the take's own.
//!
//! Units and frames: everything the page gets is glTF's — metres, rig world Y up, quaternions
//! `[w, x, y, z]` in `take.json` and the live messages (three.js's own order, x y z w, only
//! inside the page).

pub mod assets;
pub mod live;
pub mod motion;
pub mod server;

pub use live::Preview;
pub use motion::{Motion, ViewTake};
pub use server::{ServeOptions, Server};

use std::path::PathBuf;

/// Why a take cannot be shown, or the server cannot run.
#[derive(Debug, thiserror::Error)]
pub enum ViewError {
    #[error("{path}: {reason}")]
    Input { path: PathBuf, reason: String },
    #[error("cannot listen on {addr}: {reason}")]
    Bind { addr: String, reason: String },
    #[error("chunk {chunk}: {reason}")]
    Chunk { chunk: usize, reason: String },
    /// A rig of more joints than the page can be given ([`motion::MAX_JOINTS`]).
    #[error(
        "the rig has {joints} joints; imubake view shows at most {max} (the glTF writer's limit)",
        max = motion::MAX_JOINTS
    )]
    TooManyJoints { joints: usize },
}

impl ViewError {
    fn input(path: &std::path::Path, reason: impl std::fmt::Display) -> ViewError {
        ViewError::Input {
            path: path.to_path_buf(),
            reason: reason.to_string(),
        }
    }
}
