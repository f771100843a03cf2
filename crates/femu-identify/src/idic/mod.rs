//! Integrated digital image correlation (I-DIC): the material parameters identified directly
//! from the grey levels of an image sequence (Leclerc, Périé, Roux & Hild 2009; Mathieu,
//! Leclerc, Hild & Roux 2015), without a measured displacement field in between.
//!
//! The unloaded image `f` and the images `g_i` of the loaded tissue at load steps `i` are
//! compared at the material points of the model: the reference pixel `x` is moved by the
//! finite-element displacement of step `i`, mapped into the image by the probe's pose and pixel
//! size, and the parameters `θ` minimize
//!
//! ```text
//!   Σ_pairs Σ_x w [ g_a(x + d_a(x; θ)) − s g_b(x + d_b(x; θ)) − o ]²
//! ```
//!
//! over the pixels the model puts in the tissue (not in the bone's shadow), with the exact
//! Jacobian from the direct-differentiation sensitivities chained with the image gradients
//! ([`problem`]). The problem is a [`crate::fit::LeastSquares`], so the optimizers, bounds,
//! tied and fixed parameters of `identify` apply unchanged.
//!
//! - [`frame`]: where the image lies in the model (pixels ↔ mm).
//! - [`pixels`]: the pixels chosen by the model (tissue, shadow, border), brightness bands,
//!   covariance blocks.
//! - [`brightness`]: contrast and offset per band by variable projection, exact derivative.
//! - [`problem`]: the residuals and the Jacobian.
//! - [`correction`]: the mesh's discretization error of the displacement, extrapolated, held
//!   fixed in a second identification.
//! - [`uncertainty`]: the sandwich covariance from the residual's own correlation, the
//!   discretization shift.
//! - [`pose_term`]: the probe pose's part of the uncertainty (the placement moved within its
//!   own covariance).
//! - [`identify`](mod@identify): coarse to fine, from several starts.

pub mod brightness;
pub mod correction;
pub mod frame;
pub mod identify;
pub mod pixels;
pub mod pose_term;
pub mod problem;
pub mod uncertainty;

pub use frame::ImageFrame;
pub use identify::{
    continue_on_scale, identify, noise_at, seen_parameters, IdicEvent, IdicOutcome, IdicRunError,
    IdicSettings, ScaleRecord, SEEN_SD,
};
pub use pixels::{PixelOptions, PixelSet};
pub use problem::{IdicError, IdicOptions, IdicProblem, Pairing};
pub use uncertainty::{block_sandwich, gauss_newton_shift, group_jackknife, SandwichCovariance};
