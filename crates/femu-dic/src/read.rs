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
        Ok(from_dynamic(&decode_raster(path).map_err(err)?))
    }
}

/// Decodes a PNG or TIFF file after checking its header's size against
/// [`femu_mesh::limits::MAX_IMAGE_PIXELS`] (a header claiming 10⁹ pixels is refused before any
/// allocation); the errors say what is wrong with the file in the user's terms (issue 32.12: a
/// floating-point TIFF gave "color type Unknown(32)").
pub fn decode_raster(path: &Path) -> Result<image::DynamicImage, String> {
    let open = || {
        image::ImageReader::open(path)
            .and_then(|r| r.with_guessed_format())
            .map_err(|e| format!("cannot open the file: {e}"))
    };
    let (w, h) = open()?.into_dimensions().map_err(explain)?;
    femu_mesh::limits::check_image_size(w as u64, h as u64)?;
    open()?.decode().map_err(explain)
}

/// An image decoder's error in the user's terms.
fn explain(e: image::ImageError) -> String {
    use image::error::{ImageError as E, UnsupportedErrorKind as U};
    use image::ExtendedColorType as C;
    match &e {
        E::Unsupported(u) => match u.kind() {
            U::Color(C::Unknown(bits)) | U::ColorLayout(C::Unknown(bits)) => format!(
                "its pixels are {bits}-bit samples (a floating-point or 32-bit TIFF), which femu does not read: save it as 8- or 16-bit integer grey or RGB"
            ),
            U::Color(c) | U::ColorLayout(c) => format!(
                "its pixel type {c:?} is not supported: save it as 8- or 16-bit integer grey or RGB"
            ),
            U::Format(_) => "not an image femu reads (PNG, TIFF or DICOM)".into(),
            _ => format!("a feature of this file is not supported: {e}"),
        },
        E::Decoding(_) => format!("the file is damaged or cut short: {e}"),
        E::Limits(_) => format!("the image is too large to decode: {e}"),
        _ => e.to_string(),
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
