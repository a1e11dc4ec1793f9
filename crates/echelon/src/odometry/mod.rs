//! Odometry (paper section 6): the kernel's encoders, dead reckoning, error
//! models, fixes and estimate (`echelon_core::odometry`, re-exported here),
//! and the studies above them: [`bound`] is Theorem 2, [`umbmark`]
//! Borenstein's calibration test.

pub mod bound;
pub mod umbmark;

pub use echelon_core::odometry::*;
