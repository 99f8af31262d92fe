//! Readers of every input format against files made by other implementations, real vendor files, damaged and hostile input.
//!
//! One test crate per area (issue 46): each file a module, linked once.

#[path = "../common/mod.rs"]
mod common;

mod apdm;
mod bvh_prop;
mod bvh_read;
mod damaged_logs;
mod imubake_csv;
mod layouts;
mod property_readers;
mod sou_reader;
mod vendor_readers;
mod witmotion;
mod xsens_mtw_2019;
mod xsens_mvnx;
