//! The commands as a user runs them: batch, watch, live (and its hostile inputs), the viewer and its server, setup, inspect, mapping errors, the tools, fuse.
//!
//! One test crate per area (issue 46): each file a module, linked once.

#[path = "../common/mod.rs"]
mod common;

mod batch;
mod fuse_cli;
mod inspect_cli;
mod live;
mod live_hostile;
mod mapping_errors;
mod setup;
mod slurm;
mod tools;
mod viewer;
mod viewer_properties;
mod viewer_server;
mod watch;
