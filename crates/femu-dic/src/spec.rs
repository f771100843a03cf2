//! What `femu dic` is asked to correlate and how: the region of interest and the correlation's
//! options with the automatic choice of element size and regularization. Shared by the pair
//! command ([`crate::command`]), the sequence ([`crate::sequence`]) and the check
//! ([`crate::check`]).

use crate::auto::{self, Choice, Measured, Setting};
use crate::error::DicError;
use crate::image::GreyImage;
use crate::mesh::{Rect, Roi};
use crate::quality::TrustCriteria;
use crate::solver::DicOptions;
use std::path::{Path, PathBuf};

/// Where to correlate.
#[derive(Debug, Clone, serde::Serialize)]
#[serde(rename_all = "kebab-case")]
pub enum RoiSpec {
    /// The whole image.
    Whole,
    Rect(Rect),
    /// A mask image (pixels brighter than half its maximum are inside).
    Mask(PathBuf),
}

impl RoiSpec {
    /// The mask file, if the region of interest is one.
    pub fn mask_file(&self) -> Option<&Path> {
        match self {
            RoiSpec::Mask(p) => Some(p),
            _ => None,
        }
    }

    /// The ROI over an image of `width x height`.
    pub fn resolve(&self, width: usize, height: usize) -> Result<Roi, DicError> {
        match self {
            RoiSpec::Whole => Ok(Roi::Rect(Rect {
                x: 0,
                y: 0,
                w: width,
                h: height,
            })),
            RoiSpec::Rect(r) => Ok(Roi::Rect(*r)),
            RoiSpec::Mask(p) => {
                let img = GreyImage::open(p, 0)?;
                if (img.width, img.height) != (width, height) {
                    return Err(DicError::Roi(format!(
                        "{}: the mask is {} x {} px, the images {width} x {height} px",
                        p.display(),
                        img.width,
                        img.height
                    )));
                }
                Ok(Roi::mask_from_image(&img))
            }
        }
    }
}

/// How to correlate: the options of [`crate::correlate`] and the automatic choice.
#[derive(Debug, Clone, serde::Serialize)]
pub struct CorrelationSpec {
    pub roi: RoiSpec,
    /// Everything but the element size and the regularization length, which come from
    /// `element` and `regularization`.
    pub options: DicOptions,
    pub element: Setting,
    pub regularization: Setting,
    pub trust: TrustCriteria,
}

impl CorrelationSpec {
    /// Correlates `f → g` as specified.
    pub fn measure(&self, f: &GreyImage, g: &GreyImage) -> Result<(Measured, Choice), DicError> {
        let roi = self.roi.resolve(f.width, f.height)?;
        auto::correlate_auto(
            f,
            g,
            &roi,
            &self.options,
            self.element,
            self.regularization,
            &self.trust,
        )
    }
}
