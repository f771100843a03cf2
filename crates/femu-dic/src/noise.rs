//! Random error of the DIC from images of an unloaded specimen (seed §2.2, Fig. 7): between
//! successive acquisitions of tissue that does not deform, any measured displacement is error,
//! and the standard deviation of the measured `ux`, `uy` over the ROI is the random error of
//! that pair.

use crate::error::DicError;
use crate::image::GreyImage;
use crate::mesh::Roi;
use crate::output::mean_std;
use crate::solver::{correlate, DicOptions};

/// The error measured on one pair of images.
#[derive(Debug, Clone, serde::Serialize)]
pub struct PairNoise {
    /// Indices of the two images (reference, deformed).
    pub reference: usize,
    pub deformed: usize,
    /// Mean and standard deviation of the nodal displacements (pixels).
    pub mean_ux_px: f64,
    pub mean_uy_px: f64,
    pub std_ux_px: f64,
    pub std_uy_px: f64,
    pub converged: bool,
    pub iterations: usize,
    pub residual_rms: f64,
    pub seconds: f64,
}

/// Correlates each image with the next one (`n` images give `n − 1` pairs) and reports the
/// displacement statistics per pair. Stops at the first pair that fails, naming it.
pub fn successive_pairs(
    images: &[GreyImage],
    roi: &Roi,
    opts: &DicOptions,
) -> Result<Vec<PairNoise>, DicError> {
    if images.len() < 2 {
        return Err(DicError::option(
            "images",
            format!(
                "{} image(s) given, at least 2 are needed for one pair",
                images.len()
            ),
        ));
    }
    let mut out = Vec::with_capacity(images.len() - 1);
    for k in 0..images.len() - 1 {
        let res = correlate(&images[k], &images[k + 1], roi, opts)
            .map_err(|e| DicError::option("images", format!("pair {} → {}: {e}", k + 1, k + 2)))?;
        let (m, s) = mean_std(&res.displacement);
        out.push(PairNoise {
            reference: k,
            deformed: k + 1,
            mean_ux_px: m[0],
            mean_uy_px: m[1],
            std_ux_px: s[0],
            std_uy_px: s[1],
            converged: res.converged,
            iterations: res.iterations,
            residual_rms: res.residual_rms,
            seconds: res.timings.total_s,
        });
    }
    Ok(out)
}
