//! holefill: repairs scanned triangle meshes by closing every hole with a method
//! chosen by the hole's size under a TOML policy.
//!
//! The public API is three steps: [`read`] a file into a triangle soup, [`repair`] it
//! under a [`policy::Policy`], [`write`] the result. The library knows nothing of folders or
//! daemons.
//!
//! ```no_run
//! use holefill::{policy::Policy, read, repair, write};
//! let raw = read("scan.obj".as_ref(), None).unwrap();
//! let (out, report) = repair(&raw, &Policy::default()).unwrap();
//! write("repaired.obj".as_ref(), &out, None).unwrap();
//! println!("{} filled", report.summary.filled);
//! ```
#![forbid(unsafe_code)]

pub mod check;
pub mod fasthash;
pub mod fill;
pub mod geometry;
pub mod io;
pub mod mesh;
pub mod patch;
pub mod picture;
pub mod pipeline;
pub mod policy;
pub mod report;
pub mod smooth;
#[cfg(test)]
pub(crate) mod testutil;

pub use fill::dispatch::parallel::{start_workers, WARM_SPIN};
pub use io::{read, write};
pub use pipeline::{repair, RepairError};
