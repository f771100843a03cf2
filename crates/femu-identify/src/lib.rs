//! Identification of the Neo-Hookean parameters from measured displacements (seed §2.1.3,
//! §2.4): what a measurement can tell about the parameters before it is made.
//!
//! - [`fisher`]: identifiability of (log-)parameters from the sensitivity Jacobian of the
//!   measured displacements and the measurement noise (Fisher information, Cramér–Rao bounds,
//!   correlations, singular values), with tied parameters.

pub mod fisher;
