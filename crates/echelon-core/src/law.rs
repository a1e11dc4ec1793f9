//! The laws: where a follower holds its leader ([`lycomp`]: `L_X`, `L_Y`
//! and the curvature compensation, eqs. 4–6), the paper's backstepping law
//! on the dynamic model ([`control`], eqs. 7–16) and its first step as a
//! velocity command for velocity-controlled bases ([`kinematic`]).

pub mod control;
pub mod kinematic;
pub mod lycomp;
