//! The project itself: its layers, its docs, the files it ships.
//!
//! One test crate per area (issue 46): each file a module, linked once.

#[path = "../common/mod.rs"]
mod common;

mod architecture;
mod docs;
mod shipped_files;
