//! The virtual lab: synthetic speckle images warped by a known displacement field, with noise,
//! to score the DIC against an exact answer (as muDIC and DICe do).
//!
//! The speckle is an analytic function, a sum of Gaussian spots
//! `f(X) = b + Σ_k A_k exp(−|X − c_k|² / (2σ²))` with seeded random centres and amplitudes,
//! so it can be sampled anywhere without interpolation. The deformed image of a displacement
//! field `u` satisfies `g(X + u(X)) = f(X)` (grey-level conservation): each deformed pixel `x`
//! is mapped back to `X` by solving `X + u(X) = x` with the fixed-point iteration
//! `X ← x − u(X)` (a contraction when `|∇u| < 1`) to 1e-12 px, then `g(x) = f(X)`. The warp
//! is therefore exact to rounding, whatever the sub-pixel displacement.

use crate::image::GreyImage;
use rand::rngs::StdRng;
use rand::{Rng, SeedableRng};
use rand_distr::{Distribution, Normal};
use rayon::prelude::*;

/// A displacement field `u(X)` in pixels (reference coordinates, y down).
pub trait DisplacementField: Sync {
    fn at(&self, x: f64, y: f64) -> [f64; 2];
}

impl<F: Fn(f64, f64) -> [f64; 2] + Sync> DisplacementField for F {
    fn at(&self, x: f64, y: f64) -> [f64; 2] {
        self(x, y)
    }
}

/// A rigid translation.
pub fn translation(ux: f64, uy: f64) -> impl Fn(f64, f64) -> [f64; 2] + Sync {
    move |_, _| [ux, uy]
}

/// An affine field `u = c + G (X − X0)`, `G = [[g00, g01], [g10, g11]]`.
pub fn affine(c: [f64; 2], g: [[f64; 2]; 2], x0: [f64; 2]) -> impl Fn(f64, f64) -> [f64; 2] + Sync {
    move |x, y| {
        let (dx, dy) = (x - x0[0], y - x0[1]);
        [
            c[0] + g[0][0] * dx + g[0][1] * dy,
            c[1] + g[1][0] * dx + g[1][1] * dy,
        ]
    }
}

/// `ux = A sin(2π x / period)`, `uy = A cos(2π y / period)` (a smooth field with strains
/// `±2πA/period`).
pub fn sinusoid(amplitude: f64, period: f64) -> impl Fn(f64, f64) -> [f64; 2] + Sync {
    let k = std::f64::consts::TAU / period;
    move |x, y| [amplitude * (k * x).sin(), amplitude * (k * y).cos()]
}

/// An analytic speckle pattern.
#[derive(Debug, Clone)]
pub struct Speckle {
    pub width: usize,
    pub height: usize,
    /// Spot standard deviation (pixels).
    pub sigma: f64,
    /// Background grey level.
    pub background: f64,
    /// Spots `(x, y, amplitude)`.
    spots: Vec<(f64, f64, f64)>,
    /// Spots binned in square cells of `cell` pixels for the evaluation.
    cell: f64,
    ncx: usize,
    ncy: usize,
    cell_start: Vec<usize>,
    cell_spots: Vec<usize>,
}

impl Speckle {
    /// A seeded speckle over `width x height` with spots of standard deviation `sigma` px
    /// (`sigma` = 1.2–2 px gives the 3–5 px speckles recommended for DIC), about one spot per
    /// `2πσ²` of area, amplitudes uniform in 60..140 grey levels on a background of 30.
    pub fn new(width: usize, height: usize, sigma: f64, seed: u64) -> Self {
        let mut rng = StdRng::seed_from_u64(seed);
        let margin = 4.0 * sigma;
        let area = (width as f64 + 2.0 * margin) * (height as f64 + 2.0 * margin);
        let n = (area / (std::f64::consts::TAU * sigma * sigma)).ceil() as usize;
        let spots: Vec<(f64, f64, f64)> = (0..n)
            .map(|_| {
                (
                    rng.gen_range(-margin..width as f64 + margin),
                    rng.gen_range(-margin..height as f64 + margin),
                    rng.gen_range(60.0..140.0),
                )
            })
            .collect();
        let cell = 4.5 * sigma;
        let ncx = ((width as f64 + 2.0 * margin) / cell).ceil() as usize + 1;
        let ncy = ((height as f64 + 2.0 * margin) / cell).ceil() as usize + 1;
        let cell_of = |x: f64, y: f64| {
            let cx = (((x + margin) / cell).floor().max(0.0) as usize).min(ncx - 1);
            let cy = (((y + margin) / cell).floor().max(0.0) as usize).min(ncy - 1);
            cy * ncx + cx
        };
        let mut count = vec![0usize; ncx * ncy + 1];
        for s in &spots {
            count[cell_of(s.0, s.1) + 1] += 1;
        }
        for i in 0..ncx * ncy {
            count[i + 1] += count[i];
        }
        let mut fill = count.clone();
        let mut cell_spots = vec![0usize; spots.len()];
        for (k, s) in spots.iter().enumerate() {
            let c = cell_of(s.0, s.1);
            cell_spots[fill[c]] = k;
            fill[c] += 1;
        }
        Speckle {
            width,
            height,
            sigma,
            background: 30.0,
            spots,
            cell,
            ncx,
            ncy,
            cell_start: count,
            cell_spots,
        }
    }

    /// The grey level at `(x, y)` (spots further than 4.5σ are neglected: < 4e-5 of their
    /// amplitude).
    pub fn value(&self, x: f64, y: f64) -> f64 {
        let margin = 4.0 * self.sigma;
        let cx = ((x + margin) / self.cell).floor() as isize;
        let cy = ((y + margin) / self.cell).floor() as isize;
        let inv = 0.5 / (self.sigma * self.sigma);
        let r2max = (self.cell) * (self.cell);
        let mut v = self.background;
        for j in cy - 1..=cy + 1 {
            if j < 0 || j >= self.ncy as isize {
                continue;
            }
            for i in cx - 1..=cx + 1 {
                if i < 0 || i >= self.ncx as isize {
                    continue;
                }
                let c = j as usize * self.ncx + i as usize;
                for &k in &self.cell_spots[self.cell_start[c]..self.cell_start[c + 1]] {
                    let (sx, sy, a) = self.spots[k];
                    let d2 = (x - sx).powi(2) + (y - sy).powi(2);
                    if d2 < r2max {
                        v += a * (-d2 * inv).exp();
                    }
                }
            }
        }
        v
    }

    /// The reference image (pixel centres at integer coordinates).
    pub fn reference(&self) -> GreyImage {
        self.deformed(&translation(0.0, 0.0))
    }

    /// The image of the speckle displaced by `u`: `g(x) = f(X)` with `X + u(X) = x`.
    pub fn deformed(&self, u: &dyn DisplacementField) -> GreyImage {
        let w = self.width;
        let mut data = vec![0.0; w * self.height];
        data.par_chunks_mut(w).enumerate().for_each(|(y, row)| {
            for (x, v) in row.iter_mut().enumerate() {
                let (px, py) = (x as f64, y as f64);
                let mut p = [px, py];
                for _ in 0..100 {
                    let d = u.at(p[0], p[1]);
                    let q = [px - d[0], py - d[1]];
                    let err = (q[0] - p[0]).abs().max((q[1] - p[1]).abs());
                    p = q;
                    if err < 1e-12 {
                        break;
                    }
                }
                *v = self.value(p[0], p[1]);
            }
        });
        GreyImage {
            width: w,
            height: self.height,
            data,
            pixel_size: None,
        }
    }
}

/// Adds seeded Gaussian noise of standard deviation `sigma` grey levels.
pub fn add_noise(img: &GreyImage, sigma: f64, seed: u64) -> GreyImage {
    let mut out = img.clone();
    if sigma > 0.0 {
        let mut rng = StdRng::seed_from_u64(seed);
        let normal = Normal::new(0.0, sigma).expect("finite positive sigma");
        for v in &mut out.data {
            *v += normal.sample(&mut rng);
        }
    }
    out
}

/// Rounds to 8-bit grey levels (clamped to 0–255), as a camera would.
pub fn quantize_8bit(img: &GreyImage) -> GreyImage {
    let mut out = img.clone();
    for v in &mut out.data {
        *v = v.round().clamp(0.0, 255.0);
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The warp is exact: a translated image equals the speckle sampled at shifted points.
    #[test]
    fn warp_is_exact_for_a_translation() {
        let s = Speckle::new(40, 30, 1.5, 7);
        let g = s.deformed(&translation(0.37, -1.25));
        for &(x, y) in &[(10usize, 10usize), (20, 5), (33, 22)] {
            let v = s.value(x as f64 - 0.37, y as f64 + 1.25);
            assert!((g.at(x, y) - v).abs() < 1e-9);
        }
        let f = s.reference();
        let mean = f.data.iter().sum::<f64>() / f.data.len() as f64;
        let std =
            (f.data.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / f.data.len() as f64).sqrt();
        assert!(std > 20.0, "speckle contrast {std}");
    }

    /// The inverse map is solved: for an affine field, X + u(X) reproduces the pixel.
    #[test]
    fn warp_inverts_an_affine_field() {
        let s = Speckle::new(32, 32, 1.5, 3);
        let u = affine([0.2, -0.1], [[0.02, 0.01], [-0.015, 0.03]], [16.0, 16.0]);
        let g = s.deformed(&u);
        // Solve X + u(X) = x by hand (2x2 linear system) at one pixel.
        let (x, y) = (21.0, 9.0);
        let a = [[1.02, 0.01], [-0.015, 1.03]];
        let r = [
            x - 0.2 + 0.02 * 16.0 + 0.01 * 16.0,
            y + 0.1 - 0.015 * 16.0 + 0.03 * 16.0,
        ];
        let det = a[0][0] * a[1][1] - a[0][1] * a[1][0];
        let big_x = (r[0] * a[1][1] - a[0][1] * r[1]) / det;
        let big_y = (a[0][0] * r[1] - a[1][0] * r[0]) / det;
        assert!((g.at(21, 9) - s.value(big_x, big_y)).abs() < 1e-8);
    }
}
