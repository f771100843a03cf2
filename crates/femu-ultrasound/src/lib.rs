//! Ultrasound for `femu`: a B-mode image simulator on FE meshes, the choice of the scanner
//! settings from grey-level histograms, and the DIC random error of repeated acquisitions —
//! the seed's §2.2 and §3.1 (Figs. 4–7) as code, and the virtual experiment that replaces
//! the seed's "FE field + white noise" by images.
//!
//! - [`probe`]: the linear probe on the skin (image ↔ model frame) and the PSF from the
//!   centre frequency.
//! - [`tissue`]: scatterer density, backscatter and attenuation per tissue.
//! - [`phantom`]: random scatterers in the reference mesh, moved by an FE displacement field.
//! - [`render`](mod@render): echoes, attenuation, TGC, envelope, log compression, gain and dynamic range.
//! - [`stats`]: histograms, saturation, spread, texture against depth, speckle size, paired
//!   t-tests.
//! - [`manifest`]: the image manifests of `us-settings` and `us-noise`.
//! - [`settings`]: optimal gain per dynamic range (seed Figs. 5–6), texture per frequency
//!   (Fig. 4).
//! - [`noise`]: DIC random error per setting and the t-tests between settings (Fig. 7).
//! - [`pose`]: the image's pose in the model refined from the unloaded frame (model outlines
//!   matched to the bright lines), with its covariance.
//! - [`experiment`]: the virtual experiment (images of the unloaded and loaded tissue, DIC,
//!   comparison with the FE field).

#![forbid(unsafe_code)]

pub mod error;
pub mod experiment;
pub mod manifest;
pub mod noise;
pub mod phantom;
pub mod pose;
pub mod probe;
pub mod render;
pub mod settings;
pub mod stats;
pub mod tissue;

pub use error::UsError;
pub use phantom::{Phantom, PhantomState};
pub use probe::{Probe, Psf, Transducer};
pub use render::{render, Frame, Scanner};
pub use tissue::{Acoustics, Tissue};
