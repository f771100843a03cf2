//! Identification of the Neo-Hookean parameters from measured displacements (seed §2.1.3,
//! §2.4): what a measurement can tell about the parameters before it is made.
//!
//! - [`fisher`]: identifiability of (log-)parameters from the sensitivity Jacobian of the
//!   measured displacements and the measurement noise (Fisher information, Cramér–Rao bounds,
//!   correlations, singular values), with tied parameters.
//! - [`measured`]: the measured-field CSV of conventions.md.
//! - [`fit`]: the identification problem (projection, exact Jacobian), Levenberg–Marquardt in
//!   log-parameters with bounds, Latin-hypercube starts.
//! - [`idic`]: integrated DIC, the parameters from the grey levels of an image sequence.
//! - [`misfit_intervals`]: intervals on a measured field widened by the Birge ratio or the
//!   block jackknife, whichever is larger.
//! - [`variance_components`]: the error variance of groups of residuals (component, depth
//!   band, lateral edge) estimated from a fit (Helmert, iterated), weights and intervals from it.
//! - [`speckle`]: the lateral motion of B-mode speckle under shear, a term of the measurement
//!   model with a fitted scale.
//! - [`weighted`]: the misfit weighted by a measured field's full covariance, robust loss.
//! - [`joint`]: several measurements (tests, probe windows, any least-squares block) sharing
//!   the free parameters, stacked into one problem; each measurement's share of the information.
//! - [`discretization`]: the model's own error: the parameter bias its mesh implies, from
//!   refined meshes of the same geometry (one Gauss–Newton step, Richardson extrapolation).
//! - [`design`]: the experiment's design: candidate measurements ranked by the parameter
//!   uncertainty they predict (A- and D-optimal criteria), alone and combined.
//! - [`campaign`]: a whole identification: free parameters (groups, fixed, bounds), the
//!   virtual experiment, multi-start (multilevel), Monte Carlo repeats, estimates with intervals.

#![forbid(unsafe_code)]

pub mod campaign;
pub mod design;
pub mod discretization;
pub mod error_model;
pub mod fisher;
pub mod fit;
mod fit_error;
pub mod idic;
pub mod joint;
pub mod measured;
pub mod misfit_intervals;
pub mod speckle;
pub mod variance_components;
pub mod weighted;
