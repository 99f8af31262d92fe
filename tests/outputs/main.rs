//! Outputs read by their real consumers: BVH and glTF round trips, Blender, the glTF validator, the report, number formatting.
//!
//! One test crate per area (issue 46): each file a module, linked once.

#[path = "../common/mod.rs"]
mod common;

mod bvh_roundtrip;
mod bvh_interop;
mod bvh_blender;
mod blender_addon;
mod addon_anatomy;
mod convert_outputs;
mod decimal_format;
mod euler_mathutils;
mod gltf_writer;
mod report_html;
mod legacy_mode;
