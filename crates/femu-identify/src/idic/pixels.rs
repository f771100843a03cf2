//! The pixels an integrated correlation uses, chosen by the model itself: the reference-image
//! pixels whose model point lies in the tissue of the mesh, that are not in the acoustic
//! shadow of a hole (the bone), and that keep clear of the image border. Each pixel carries its
//! location in the mesh (element and shape-function weights, found once), the brightness band
//! it belongs to and the block it is summed into by the covariance estimator.
//!
//! **Shadow.** The image rows are depth (the beam runs along `+y` of the image, as in a B-mode
//! image): going down a column, a pixel that lies below a tissue pixel followed by a pixel out
//! of the tissue sees the tissue through a hole of the mesh — the femur, which reflects and
//! absorbs nearly all the energy — and is masked with everything below it.

use super::frame::ImageFrame;
use femu_mesh::locate::{PointLocation, PointLocator};
use femu_mesh::Mesh;
use serde::{Deserialize, Serialize};

/// How the pixels are chosen and grouped.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct PixelOptions {
    /// Pixels closer than this to the image edge are left out (px): the B-spline of a frame
    /// needs its neighbours, and the tissue moves.
    pub border_px: usize,
    /// Every `stride`-th pixel along each axis (1: all).
    pub stride: usize,
    /// Height of a brightness band (rows, px): one contrast and one offset per band and frame
    /// pair (see [`super::brightness`]). `None`: one pair over the whole image.
    pub band_px: Option<usize>,
    /// Side of the square blocks of the covariance estimator (px): larger than the residual's
    /// correlation length (the speckle), small enough to give many blocks.
    pub block_px: usize,
    /// Side of the square groups of the jackknife (px): regions over which a model error may
    /// pull the estimate one way ([`super::uncertainty::group_jackknife`]).
    #[serde(default = "default_group_px")]
    pub group_px: usize,
}

fn default_group_px() -> usize {
    100
}

impl Default for PixelOptions {
    fn default() -> Self {
        PixelOptions {
            border_px: 4,
            stride: 1,
            band_px: Some(64),
            block_px: 32,
            group_px: default_group_px(),
        }
    }
}

/// The pixels of an integrated correlation.
#[derive(Debug, Clone)]
pub struct PixelSet {
    pub width: usize,
    pub height: usize,
    /// Pixel positions `(x, y)` (integers) in the reference image.
    pub px: Vec<[usize; 2]>,
    /// Where each pixel's model point lies in the reference mesh.
    pub loc: Vec<PointLocation>,
    /// Brightness band of each pixel (`0..bands`).
    pub band: Vec<usize>,
    pub bands: usize,
    /// Covariance block of each pixel (`0..blocks`).
    pub block: Vec<usize>,
    pub blocks: usize,
    /// Jackknife group of each pixel (`0..groups`).
    pub group: Vec<usize>,
    pub groups: usize,
    /// Pixels of the image that are in the tissue, in the shadow, out of the tissue.
    pub counts: MaskCounts,
}

/// What the model's mask made of the image's pixels.
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize, Deserialize)]
pub struct MaskCounts {
    pub tissue: usize,
    pub shadow: usize,
    pub outside: usize,
    pub border: usize,
}

/// What a pixel of the reference image is, by the model.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum PixelKind {
    Tissue,
    /// Below a hole of the mesh along its column.
    Shadow,
    /// Not in the mesh (gel above the skin, the bone itself).
    Outside,
}

/// The kind of every pixel of a `width x height` image in `frame` over `mesh`, row-major, and
/// the locations of the tissue pixels.
pub fn classify(
    mesh: &Mesh,
    frame: &ImageFrame,
    width: usize,
    height: usize,
) -> (Vec<PixelKind>, Vec<Option<PointLocation>>) {
    let locator = PointLocator::new(mesh);
    let mut kind = vec![PixelKind::Outside; width * height];
    let mut loc = vec![None; width * height];
    for x in 0..width {
        let mut entered = false;
        let mut shadowed = false;
        for y in 0..height {
            let k = y * width + x;
            if shadowed {
                kind[k] = PixelKind::Shadow;
                continue;
            }
            match locator.locate(frame.pixel_to_model([x as f64, y as f64])) {
                Some(l) => {
                    entered = true;
                    kind[k] = PixelKind::Tissue;
                    loc[k] = Some(l);
                }
                None if entered => {
                    shadowed = true;
                    kind[k] = PixelKind::Shadow;
                }
                None => {}
            }
        }
    }
    (kind, loc)
}

impl PixelSet {
    /// The tissue pixels of an image of `width x height` in `frame` over the reference `mesh`.
    pub fn new(
        mesh: &Mesh,
        frame: &ImageFrame,
        width: usize,
        height: usize,
        options: &PixelOptions,
    ) -> Result<PixelSet, String> {
        if options.stride == 0
            || options.block_px == 0
            || options.group_px == 0
            || options.band_px == Some(0)
        {
            return Err("stride, block and band sizes must be at least 1 px".into());
        }
        let (kind, loc) = classify(mesh, frame, width, height);
        let b = options.border_px;
        let mut set = PixelSet {
            width,
            height,
            px: Vec::new(),
            loc: Vec::new(),
            band: Vec::new(),
            bands: 0,
            block: Vec::new(),
            blocks: 0,
            group: Vec::new(),
            groups: 0,
            counts: MaskCounts::default(),
        };
        let band_px = options.band_px.unwrap_or(height.max(1));
        let blocks_x = width.div_ceil(options.block_px);
        let groups_x = width.div_ceil(options.group_px);
        for y in 0..height {
            for x in 0..width {
                let k = y * width + x;
                match kind[k] {
                    PixelKind::Shadow => set.counts.shadow += 1,
                    PixelKind::Outside => set.counts.outside += 1,
                    PixelKind::Tissue => {
                        if x < b || y < b || x + b >= width || y + b >= height {
                            set.counts.border += 1;
                            continue;
                        }
                        set.counts.tissue += 1;
                        if x % options.stride != 0 || y % options.stride != 0 {
                            continue;
                        }
                        set.px.push([x, y]);
                        set.loc.push(loc[k].expect("tissue pixels are located"));
                        set.band.push(y / band_px);
                        set.block
                            .push((y / options.block_px) * blocks_x + x / options.block_px);
                        set.group
                            .push((y / options.group_px) * groups_x + x / options.group_px);
                    }
                }
            }
        }
        if set.px.is_empty() {
            return Err(format!(
                "no pixel of the {width} x {height} image lies in the tissue of the model ({} outside, {} in the shadow): check the image's position in the model",
                set.counts.outside, set.counts.shadow
            ));
        }
        set.bands = renumber(&mut set.band);
        set.blocks = renumber(&mut set.block);
        set.groups = renumber(&mut set.group);
        Ok(set)
    }

    pub fn len(&self) -> usize {
        self.px.len()
    }

    pub fn is_empty(&self) -> bool {
        self.px.is_empty()
    }
}

/// Renumbers the labels in `v` as `0..n` in order of first appearance; returns `n`.
fn renumber(v: &mut [usize]) -> usize {
    let mut map = std::collections::HashMap::new();
    for x in v.iter_mut() {
        let n = map.len();
        *x = *map.entry(*x).or_insert(n);
    }
    map.len()
}

#[cfg(test)]
mod tests {
    use super::*;

    /// An annulus (a ring of tissue, radii 10 and 20 mm, around a hole) seen from above
    /// through a 40 x 40 px window at 1 px/mm, rows going down from y = 19.5 mm: pixels beyond
    /// the ring are outside, the ring above the hole is tissue, the hole and the ring below it
    /// are in the shadow, the ring beside the hole is tissue.
    #[test]
    fn hole_casts_a_shadow() {
        let g =
            femu_mesh::generate::annulus(10.0, 15.0, 20.0, 64, 4, 4, femu_mesh::ElementKind::Cpe4);
        let frame = ImageFrame::new([-19.5, 19.5], 1.0, [1.0, 0.0], [0.0, -1.0]).unwrap();
        let (kind, loc) = classify(&g.mesh, &frame, 40, 40);
        let at = |x: usize, y: usize| kind[y * 40 + x];
        assert_eq!(at(0, 0), PixelKind::Outside); // (-19.5, 19.5): r = 27.6
        assert_eq!(at(20, 5), PixelKind::Tissue); // (0.5, 14.5)
        assert!(loc[5 * 40 + 20].is_some());
        assert_eq!(at(20, 15), PixelKind::Shadow); // (0.5, 4.5): in the hole
        assert_eq!(at(20, 35), PixelKind::Shadow); // (0.5, -15.5): ring below the hole
        assert_eq!(at(1, 20), PixelKind::Tissue); // (-18.5, -0.5): beside the hole
        let set = PixelSet::new(&g.mesh, &frame, 40, 40, &PixelOptions::default()).unwrap();
        assert_eq!(set.len(), set.counts.tissue);
        assert!(set
            .px
            .iter()
            .all(|p| p[0] >= 4 && p[1] >= 4 && p[0] < 36 && p[1] < 36));
        assert!(
            set.bands == 1 && set.blocks == 4,
            "{} {}",
            set.bands,
            set.blocks
        );
    }
}
