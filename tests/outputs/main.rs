//! Outputs read by their real consumers: BVH and glTF round trips, Blender, the glTF validator, the report, number formatting.
//!
//! One test crate per area (issue 46): each file a module, linked once.

#[path = "../common/mod.rs"]
mod common;

mod addon_anatomy;
mod blender_addon;
mod bvh_blender;
mod bvh_interop;
mod bvh_roundtrip;
mod convert_outputs;
mod decimal_format;
mod euler_mathutils;
mod gltf_writer;
mod godot_import;
mod legacy_mode;
mod report_html;
