//! Reading a grey-level image from a file: PNG or TIFF (8 or 16 bit, grey or colour, by the
//! `image` crate) or DICOM ([`crate::dicom`]), chosen by the file's content.

use crate::error::DicError;
use crate::image::{luma, GreyImage};
use std::path::Path;

impl GreyImage {
    /// Reads a PNG or TIFF file (by its content), or a DICOM file (by the `.dcm` extension or
    /// the `DICM` magic at byte 128), taking `frame` of a multi-frame DICOM file.
    pub fn open(path: &Path, frame: usize) -> Result<Self, DicError> {
        if crate::dicom::is_dicom(path) {
            return crate::dicom::read_dicom(path, frame);
        }
        let err = |message: String| DicError::ImageRead {
            path: path.to_path_buf(),
            message,
        };
        if frame != 0 {
            return Err(err(format!(
                "frame {frame} requested, but PNG/TIFF files are read as a single frame"
            )));
        }
        let img = image::ImageReader::open(path)
            .map_err(|e| err(e.to_string()))?
            .with_guessed_format()
            .map_err(|e| err(e.to_string()))?
            .decode()
            .map_err(|e| err(e.to_string()))?;
        Ok(from_dynamic(&img))
    }
}

/// Luminance of a decoded PNG/TIFF image on a 0–255 scale.
fn from_dynamic(img: &image::DynamicImage) -> GreyImage {
    use image::DynamicImage as D;
    let (w, h) = (img.width() as usize, img.height() as usize);
    let data: Vec<f64> = match img {
        D::ImageLuma8(b) => b.as_raw().iter().map(|&v| v as f64).collect(),
        D::ImageLumaA8(b) => b.pixels().map(|p| p.0[0] as f64).collect(),
        D::ImageLuma16(b) => b.as_raw().iter().map(|&v| v as f64 / 257.0).collect(),
        D::ImageLumaA16(b) => b.pixels().map(|p| p.0[0] as f64 / 257.0).collect(),
        D::ImageRgb8(b) => b
            .pixels()
            .map(|p| luma(p.0[0] as f64, p.0[1] as f64, p.0[2] as f64))
            .collect(),
        D::ImageRgba8(b) => b
            .pixels()
            .map(|p| luma(p.0[0] as f64, p.0[1] as f64, p.0[2] as f64))
            .collect(),
        D::ImageRgb16(b) => b
            .pixels()
            .map(|p| luma(p.0[0] as f64, p.0[1] as f64, p.0[2] as f64) / 257.0)
            .collect(),
        D::ImageRgba16(b) => b
            .pixels()
            .map(|p| luma(p.0[0] as f64, p.0[1] as f64, p.0[2] as f64) / 257.0)
            .collect(),
        other => other
            .to_rgb32f()
            .pixels()
            .map(|p| 255.0 * luma(p.0[0] as f64, p.0[1] as f64, p.0[2] as f64))
            .collect(),
    };
    GreyImage {
        width: w,
        height: h,
        data,
        pixel_size: None,
    }
}
