//! imubake: body-worn inertial captures in, animation out.
//!
//! The library is a pipeline over one data model, [`take::Take`]: readers ([`read`]) turn
//! capture logs into takes, and analysis ([`inspect`]) summarises them. Conventions for frames,
//! time and units are those of `conventions.md`: quaternions are Hamilton, written w, x, y, z;
//! times are seconds on the take's clock (t = 0 at the earliest kept sample).

pub mod analysis;
pub mod anim;
pub mod batch;
pub mod bvh;
pub mod config;
pub mod convert;
pub mod diagnostic;
pub mod fps;
pub mod fusion;
pub mod inspect;
pub mod intrinsics;
pub mod ledger;
pub mod live;
pub mod mapping;
pub mod pipeline;
pub mod read;
pub mod retarget;
pub mod rig;
pub mod rotation;
pub mod setup;
pub mod simulate;
pub mod smooth;
pub mod take;
pub mod view;
pub mod watch;
pub mod world;
pub mod write;
