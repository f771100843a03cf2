//! An image sequence and where it lies in the model: what the simulated-ultrasound and the
//! recorded-frames routes hand to the image identification.

use femu_dic::GreyImage;
use femu_identify::idic::ImageFrame;
use femu_ultrasound::Probe;

/// An image sequence and where it lies in the model.
#[derive(Debug, Clone)]
pub struct ImageSequence {
    /// The unloaded frame first, then one frame per load step.
    pub frames: Vec<GreyImage>,
    /// Fraction of the test's load of each loaded frame.
    pub load_fractions: Vec<f64>,
    pub frame: ImageFrame,
    /// Where the frames come from (files, or the simulator).
    pub source: String,
}

/// The image frame of a linear probe: pixel `(i, j)` at `c + ((i + ½)/p − W/2) t + ((j + ½)/p) n`
/// (`femu_ultrasound::probe`), an affine map with axes `t` (along the array) and `n` (the beam).
pub fn image_frame(probe: &Probe) -> ImageFrame {
    ImageFrame {
        origin_mm: probe.pixel_to_model([0.0, 0.0]),
        mm_per_px: 1.0 / probe.px_per_mm,
        x_axis: probe.lateral(),
        y_axis: probe.direction,
    }
}
