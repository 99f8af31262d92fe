//! The motion: fusion, calibration, smoothing, the body model and anatomy, retargeting, root motion, the closed loop and the benchmarks with optical ground truth.
//!
//! One test crate per area (issue 46): each file a module, linked once.

#[path = "../common/mod.rs"]
mod common;

mod anatomy_schemes;
mod any_rig;
mod body_model;
mod broad;
mod bvh_retarget;
mod closed_loop;
mod filters_scipy;
mod functional_calibration;
mod fusion_real;
mod fusion_reference;
mod fusion_short_takes;
mod joint_angles;
mod property_fusion;
mod real_exports;
mod root_motion;
mod sensor_calibration;
mod smoothing_properties;
mod stream;
