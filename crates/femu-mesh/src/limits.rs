//! The sizes femu refuses before allocating (issue 28, item 4): an input that would need
//! absurd memory is an error naming its size, the estimate and the limit, not an abort on an
//! allocation minutes later. The mesh limit lives with the meshers
//! (`femu_geometry::MAX_ELEMENTS`, 500 000 quads); the grid limits with the study schema.

/// The largest image (pixels per frame) the readers decode: 50 million, e.g. 7 000 x 7 000.
/// The correlation keeps some 50 bytes per pixel (the reference and deformed grey levels,
/// the B-spline coefficients, the gradients, the pyramid): about 2.5 GB at the limit. The
/// largest images of the shared data are 800 x 600 (ultrasound) and 2 048 x 2 048 (DIC
/// Challenge).
pub const MAX_IMAGE_PIXELS: u64 = 50_000_000;

/// The largest NIfTI volume (voxels) read: the reader loads the whole volume to take one
/// slice; 500 million voxels are 1 GB of 16-bit labels (an MRI volume is some 512 x 512 x 200
/// = 5e7).
pub const MAX_VOLUME_VOXELS: u64 = 500_000_000;

/// Bytes per pixel of the correlation, for the estimate in [`check_image_size`]'s message.
const BYTES_PER_PIXEL: u64 = 50;

/// Refuses an image of `width` x `height` pixels above [`MAX_IMAGE_PIXELS`], from its header,
/// before its pixels are decoded: the message gives the size, the memory estimate and the
/// limit.
pub fn check_image_size(width: u64, height: u64) -> Result<(), String> {
    let pixels = width.saturating_mul(height);
    if pixels > MAX_IMAGE_PIXELS {
        return Err(format!(
            "{width} x {height} pixels ({:.1e}, some {:.0} GB to correlate) is above the limit of {MAX_IMAGE_PIXELS} pixels: crop or downsample it",
            pixels as f64,
            pixels.saturating_mul(BYTES_PER_PIXEL) as f64 / 1e9
        ));
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_header_claiming_a_billion_pixels_is_refused() {
        assert!(check_image_size(800, 600).is_ok());
        assert!(check_image_size(7000, 7000).is_ok());
        let e = check_image_size(40_000, 25_000).unwrap_err();
        assert!(
            e.contains("40000 x 25000 pixels (1.0e9")
                && e.contains("50 GB")
                && e.contains("50000000"),
            "{e}"
        );
        assert!(check_image_size(u64::MAX, u64::MAX).is_err());
    }
}
