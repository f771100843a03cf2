//! Cubic B-spline interpolation of an image (Unser 1999, "Splines: a perfect fit for signal and
//! image processing"; Thévenaz, Blu & Unser 2000, "Interpolation revisited").
//!
//! The interpolant is `g(x, y) = Σ_k Σ_l c[l][k] β³(x − k) β³(y − l)` with the cubic B-spline
//!
//! ```text
//! β³(t) = 2/3 − |t|² + |t|³/2        for |t| < 1
//!       = (2 − |t|)³ / 6             for 1 ≤ |t| < 2
//! ```
//!
//! The coefficients `c` are obtained from the samples by the exact inverse filter (causal and
//! anti-causal first-order recursions with the pole `z = √3 − 2`, gain 6) with mirror-symmetric
//! boundaries, so the interpolant passes through every pixel value (pixel centres at integer
//! coordinates). It is C² and its gradient is exact (eq. [`BSpline::eval_grad`]); evaluation
//! outside the image uses the mirror extension.

use rayon::prelude::*;

/// The pole of the cubic B-spline prefilter.
const POLE: f64 = -0.267_949_192_431_122_7; // √3 − 2

/// The cubic B-spline coefficients of an image.
#[derive(Debug, Clone)]
pub struct BSpline {
    pub width: usize,
    pub height: usize,
    /// Row-major coefficients `c[y * width + x]`.
    pub coef: Vec<f64>,
}

/// The 4 weights `β³(t + 1), β³(t), β³(t − 1), β³(t − 2)` of the samples `i − 1 .. i + 2`
/// for a point `i + t`, `0 ≤ t < 1`.
#[inline(always)]
pub fn weights(t: f64) -> [f64; 4] {
    let t2 = t * t;
    let t3 = t2 * t;
    let s = 1.0 - t;
    [
        s * s * s / 6.0,
        0.5 * t3 - t2 + 2.0 / 3.0,
        -0.5 * t3 + 0.5 * t2 + 0.5 * t + 1.0 / 6.0,
        t3 / 6.0,
    ]
}

/// The derivatives `d/dt` of [`weights`].
#[inline(always)]
pub fn weights_derivative(t: f64) -> [f64; 4] {
    let t2 = t * t;
    let s = 1.0 - t;
    [
        -0.5 * s * s,
        1.5 * t2 - 2.0 * t,
        -1.5 * t2 + t + 0.5,
        0.5 * t2,
    ]
}

/// Mirror-symmetric index (whole-sample symmetry: `-1 → 1`, `n → n − 2`).
#[inline(always)]
fn mirror(k: isize, n: usize) -> usize {
    let n = n as isize;
    if n == 1 {
        return 0;
    }
    let period = 2 * (n - 1);
    let mut k = k.rem_euclid(period);
    if k >= n {
        k = period - k;
    }
    k as usize
}

/// In-place cubic B-spline prefilter of one line with mirror boundaries (Unser's recursive
/// algorithm: `c⁺(k) = s(k) + z c⁺(k−1)`, `c⁻(k) = z (c⁻(k+1) − c⁺(k))`, `c = 6 c⁻`).
fn prefilter_line(s: &mut [f64]) {
    let n = s.len();
    if n < 2 {
        return;
    }
    let z = POLE;
    // Causal initialization: Σ z^k s(k) over the mirrored line, truncated when z^k < 1e-16.
    let horizon = ((1e-16f64).ln() / z.abs().ln()).ceil() as usize;
    let mut c0 = 0.0;
    if horizon < n {
        let mut zk = 1.0;
        for v in s.iter().take(horizon) {
            c0 += zk * v;
            zk *= z;
        }
    } else {
        // Exact mirror sum for short lines.
        let zn = z.powi(n as i32 - 1);
        let iz = 1.0 / z;
        let mut z1 = z;
        let mut z2 = zn * zn * iz;
        c0 = s[0] + zn * s[n - 1];
        for v in s.iter().take(n - 1).skip(1) {
            c0 += (z1 + z2) * v;
            z1 *= z;
            z2 *= iz;
        }
        c0 /= 1.0 - zn * zn;
    }
    s[0] = c0;
    for k in 1..n {
        s[k] += z * s[k - 1];
    }
    // Anti-causal initialization for mirror boundaries.
    s[n - 1] = (z / (z * z - 1.0)) * (s[n - 1] + z * s[n - 2]);
    for k in (0..n - 1).rev() {
        s[k] = z * (s[k + 1] - s[k]);
    }
    for v in s.iter_mut() {
        *v *= 6.0; // (1 − z)(1 − 1/z)
    }
}

impl BSpline {
    /// The coefficients of the row-major image `data` (`width x height`).
    pub fn new(data: &[f64], width: usize, height: usize) -> Self {
        debug_assert_eq!(data.len(), width * height);
        let mut coef = data.to_vec();
        coef.par_chunks_mut(width).for_each(prefilter_line);
        // Columns: transpose, filter rows, transpose back.
        let mut t = vec![0.0; width * height];
        transpose(&coef, &mut t, width, height);
        t.par_chunks_mut(height).for_each(prefilter_line);
        transpose(&t, &mut coef, height, width);
        BSpline {
            width,
            height,
            coef,
        }
    }

    /// Value of the interpolant at `(x, y)` (pixel units, pixel centres at integers).
    #[inline]
    pub fn eval(&self, x: f64, y: f64) -> f64 {
        let (ix, tx) = split(x);
        let (iy, ty) = split(y);
        let wx = weights(tx);
        let wy = weights(ty);
        let w = self.width;
        if ix >= 1 && iy >= 1 && (ix as usize) + 2 < w && (iy as usize) + 2 < self.height {
            let base = (iy as usize - 1) * w + ix as usize - 1;
            let mut v = 0.0;
            for (j, wyj) in wy.iter().enumerate() {
                let r = &self.coef[base + j * w..base + j * w + 4];
                v += wyj * (wx[0] * r[0] + wx[1] * r[1] + wx[2] * r[2] + wx[3] * r[3]);
            }
            v
        } else {
            let mut v = 0.0;
            for (j, wyj) in wy.iter().enumerate() {
                let row = mirror(iy - 1 + j as isize, self.height) * w;
                let mut s = 0.0;
                for (i, wxi) in wx.iter().enumerate() {
                    s += wxi * self.coef[row + mirror(ix - 1 + i as isize, w)];
                }
                v += wyj * s;
            }
            v
        }
    }

    /// Value and gradient `(g, ∂g/∂x, ∂g/∂y)` of the interpolant at `(x, y)`.
    #[inline]
    pub fn eval_grad(&self, x: f64, y: f64) -> (f64, f64, f64) {
        let (ix, tx) = split(x);
        let (iy, ty) = split(y);
        let wx = weights(tx);
        let wy = weights(ty);
        let dx = weights_derivative(tx);
        let dy = weights_derivative(ty);
        let w = self.width;
        let (mut v, mut gx, mut gy) = (0.0, 0.0, 0.0);
        if ix >= 1 && iy >= 1 && (ix as usize) + 2 < w && (iy as usize) + 2 < self.height {
            // Inside: the 4 x 4 coefficients without the mirror's index arithmetic (the same
            // products summed in the same order as below, so the same bits).
            let base = (iy as usize - 1) * w + ix as usize - 1;
            for j in 0..4 {
                let r = &self.coef[base + j * w..base + j * w + 4];
                let (mut s, mut sd) = (0.0, 0.0);
                for i in 0..4 {
                    s += wx[i] * r[i];
                    sd += dx[i] * r[i];
                }
                v += wy[j] * s;
                gx += wy[j] * sd;
                gy += dy[j] * s;
            }
            return (v, gx, gy);
        }
        self.eval_grad_mirrored(x, y)
    }

    /// [`BSpline::eval_grad`] with every index through the mirror extension (any position).
    fn eval_grad_mirrored(&self, x: f64, y: f64) -> (f64, f64, f64) {
        let (ix, tx) = split(x);
        let (iy, ty) = split(y);
        let wx = weights(tx);
        let wy = weights(ty);
        let dx = weights_derivative(tx);
        let dy = weights_derivative(ty);
        let w = self.width;
        let (mut v, mut gx, mut gy) = (0.0, 0.0, 0.0);
        for j in 0..4 {
            let row = mirror(iy - 1 + j as isize, self.height) * w;
            let (mut s, mut sd) = (0.0, 0.0);
            for i in 0..4 {
                let c = self.coef[row + mirror(ix - 1 + i as isize, w)];
                s += wx[i] * c;
                sd += dx[i] * c;
            }
            v += wy[j] * s;
            gx += wy[j] * sd;
            gy += dy[j] * s;
        }
        (v, gx, gy)
    }

    /// Value and gradient at the pixel centre `(x, y)` (integers): weights `1/6, 2/3, 1/6`
    /// and derivative weights `−1/2, 0, 1/2`.
    pub fn grad_at_pixel(&self, x: usize, y: usize) -> (f64, f64, f64) {
        self.eval_grad(x as f64, y as f64)
    }
}

/// Integer part and fraction of `x`, with the integer part kept in a range that cannot
/// overflow the index arithmetic (positions far outside the image are mirrored anyway).
#[inline(always)]
fn split(x: f64) -> (isize, f64) {
    let x = x.clamp(-1.0e9, 1.0e9);
    // The floor by truncation (`f64::floor` is a call into the C library on a baseline x86-64
    // target, and this runs for every pixel of every iteration): truncation rounds towards
    // zero, one less below zero unless `x` is an integer.
    let t = x as i64 as f64;
    let f = if t > x { t - 1.0 } else { t };
    (f as isize, x - f)
}

/// `dst (h x w) = srcᵀ` for a row-major `src` of `w` columns and `h` rows, by blocks.
fn transpose(src: &[f64], dst: &mut [f64], w: usize, h: usize) {
    const B: usize = 32;
    dst.par_chunks_mut(B * h)
        .enumerate()
        .for_each(|(bx, chunk)| {
            let x0 = bx * B;
            let x1 = (x0 + B).min(w);
            for y in 0..h {
                for x in x0..x1 {
                    chunk[(x - x0) * h + y] = src[y * w + x];
                }
            }
        });
}

#[cfg(test)]
mod tests {
    use super::*;

    fn test_image(w: usize, h: usize) -> Vec<f64> {
        (0..w * h)
            .map(|k| {
                let (x, y) = ((k % w) as f64, (k / w) as f64);
                100.0
                    + 40.0 * (0.7 * x).sin() * (0.45 * y + 0.3).cos()
                    + 3.0 * ((k * 7919) % 13) as f64
            })
            .collect()
    }

    /// The interpolant passes through the samples (exact inverse filter), inside and at the
    /// borders, for long lines and for lines shorter than the filter horizon.
    #[test]
    fn interpolates_the_samples() {
        for (w, h) in [(37, 29), (9, 7)] {
            let img = test_image(w, h);
            let s = BSpline::new(&img, w, h);
            for y in 0..h {
                for x in 0..w {
                    let v = s.eval(x as f64, y as f64);
                    assert!(
                        (v - img[y * w + x]).abs() < 1e-9,
                        "({x},{y}) {v} vs {}",
                        img[y * w + x]
                    );
                }
            }
        }
    }

    /// The analytic gradient matches central finite differences of the interpolant (step
    /// 1e-5 px: truncation ~1e-10 of the grey-level scale, rounding ~1e-10).
    #[test]
    fn gradient_matches_finite_differences() {
        let (w, h) = (40, 33);
        let s = BSpline::new(&test_image(w, h), w, h);
        let e = 1e-5;
        for &(x, y) in &[
            (5.3, 7.71),
            (0.2, 3.4),
            (38.6, 31.9),
            (20.0, 16.5),
            (12.999, 1.001),
        ] {
            let (v, gx, gy) = s.eval_grad(x, y);
            assert!((v - s.eval(x, y)).abs() < 1e-10);
            let fx = (s.eval(x + e, y) - s.eval(x - e, y)) / (2.0 * e);
            let fy = (s.eval(x, y + e) - s.eval(x, y - e)) / (2.0 * e);
            assert!((gx - fx).abs() < 1e-5 * (1.0 + fx.abs()), "{gx} vs {fx}");
            assert!((gy - fy).abs() < 1e-5 * (1.0 + fy.abs()), "{gy} vs {fy}");
        }
    }

    /// Cubic B-splines reproduce polynomials up to degree 3; the mirror boundary breaks this
    /// for a ramp only near the borders (the error decays as |z|^d ≈ 0.27^d with the distance
    /// d in pixels: below 1e-12 at 30 px), so a ramp is exact in the middle.
    #[test]
    fn reproduces_a_linear_ramp() {
        let (w, h) = (64, 64);
        let img: Vec<f64> = (0..w * h)
            .map(|k| 2.5 * (k % w) as f64 - 1.5 * (k / w) as f64)
            .collect();
        let s = BSpline::new(&img, w, h);
        for &(x, y) in &[(30.25, 28.5), (31.7, 33.1), (34.5, 30.9)] {
            let (v, gx, gy) = s.eval_grad(x, y);
            assert!((v - (2.5 * x - 1.5 * y)).abs() < 1e-9, "{v}");
            assert!((gx - 2.5).abs() < 1e-9 && (gy + 1.5).abs() < 1e-9);
        }
    }

    /// Inside the image the direct indexing gives the same bits as the mirrored one (the same
    /// products in the same order), up to the last positions that have all 4 x 4 neighbours;
    /// near and beyond the borders both paths are the mirrored one.
    #[test]
    fn inside_path_equals_the_mirrored_one() {
        let (w, h) = (23, 17);
        let s = BSpline::new(&test_image(w, h), w, h);
        for k in 0..400 {
            let x = -2.0 + 26.0 * ((k * 37 % 400) as f64 + 0.123) / 400.0;
            let y = -2.0 + 20.0 * ((k * 91 % 400) as f64 + 0.377) / 400.0;
            assert_eq!(s.eval_grad(x, y), s.eval_grad_mirrored(x, y), "({x}, {y})");
        }
        for &(x, y) in &[(1.0, 1.0), (19.999, 13.999), (20.0, 14.0), (0.999, 5.0)] {
            assert_eq!(s.eval_grad(x, y), s.eval_grad_mirrored(x, y), "({x}, {y})");
        }
    }

    #[test]
    fn mirror_indices() {
        assert_eq!(mirror(-1, 5), 1);
        assert_eq!(mirror(5, 5), 3);
        assert_eq!(mirror(-6, 5), 2);
        assert_eq!(mirror(3, 1), 0);
    }

    /// `split` by truncation equals the floor's split on integers, halves, their neighbours
    /// one ulp away, negative values and the clamp's ends (fractions compared with `==`, so
    /// the sign of a zero fraction does not count: it multiplies weights that are then added).
    #[test]
    fn split_matches_the_floor() {
        let mut xs = vec![0.0, -0.0, 1e9, -1e9, 3e12, -3e12, 1e-300, -1e-300];
        for k in -300..300 {
            for base in [k as f64, k as f64 + 0.5, k as f64 * 0.37] {
                xs.extend([base, base.next_up(), base.next_down()]);
            }
        }
        for x in xs {
            let c = x.clamp(-1.0e9, 1.0e9);
            let f = c.floor();
            let (i, t) = split(x);
            assert_eq!((i, t), (f as isize, c - f), "{x:e}");
        }
    }
}
