//! Integer-pixel initial guess by FFT cross-correlation (phase correlation).
//!
//! With `F` and `G` the 2D Fourier transforms of the reference and deformed windows (zero mean,
//! Hann-tapered to damp the wrap-around), the normalized cross-power spectrum
//! `R = conj(F) G / |conj(F) G|` has the inverse transform `r(s)` peaked at the shift `s` for
//! which `g(x + s) ≈ f(x)` (Kuglin & Hines 1975), i.e. at the displacement. Only the integer
//! peak is used; the Gauss–Newton iterations take it from there.

use rustfft::num_complex::Complex;
use rustfft::FftPlanner;

/// The integer displacement `(sx, sy)` of `g` relative to `f` over a `w x h` window (row-major
/// slices of the same size), in `(-w/2, w/2] x (-h/2, h/2]`.
pub fn integer_shift(f: &[f64], g: &[f64], w: usize, h: usize) -> (i64, i64) {
    debug_assert!(f.len() == w * h && g.len() == w * h);
    if w < 2 || h < 2 {
        return (0, 0);
    }
    let hann = |k: usize, n: usize| {
        0.5 - 0.5 * (std::f64::consts::TAU * (k as f64 + 0.5) / n as f64).cos()
    };
    let prep = |v: &[f64]| -> Vec<Complex<f64>> {
        let mean = v.iter().sum::<f64>() / v.len() as f64;
        (0..w * h)
            .map(|k| Complex::new((v[k] - mean) * hann(k % w, w) * hann(k / w, h), 0.0))
            .collect()
    };
    let mut a = prep(f);
    let mut b = prep(g);
    let mut planner = FftPlanner::<f64>::new();
    fft2(&mut planner, &mut a, w, h, false);
    fft2(&mut planner, &mut b, w, h, false);
    for (x, y) in a.iter_mut().zip(&b) {
        let c = x.conj() * y;
        let m = c.norm();
        *x = if m > 1e-300 {
            c / m
        } else {
            Complex::new(0.0, 0.0)
        };
    }
    fft2(&mut planner, &mut a, w, h, true);
    let (mut best, mut k_best) = (f64::NEG_INFINITY, 0);
    for (k, v) in a.iter().enumerate() {
        if v.re > best {
            best = v.re;
            k_best = k;
        }
    }
    let wrap = |s: usize, n: usize| {
        if s > n / 2 {
            s as i64 - n as i64
        } else {
            s as i64
        }
    };
    (wrap(k_best % w, w), wrap(k_best / w, h))
}

/// In-place 2D FFT (rows, then columns) of a row-major `w x h` array.
fn fft2(
    planner: &mut FftPlanner<f64>,
    data: &mut [Complex<f64>],
    w: usize,
    h: usize,
    inverse: bool,
) {
    let (row, col) = if inverse {
        (planner.plan_fft_inverse(w), planner.plan_fft_inverse(h))
    } else {
        (planner.plan_fft_forward(w), planner.plan_fft_forward(h))
    };
    row.process(data);
    let mut t = vec![Complex::new(0.0, 0.0); w * h];
    for y in 0..h {
        for x in 0..w {
            t[x * h + y] = data[y * w + x];
        }
    }
    col.process(&mut t);
    for y in 0..h {
        for x in 0..w {
            data[y * w + x] = t[x * h + y];
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn finds_integer_shifts() {
        let (w, h) = (64, 48);
        let pattern = |x: i64, y: i64| {
            let k = (x.wrapping_mul(73856093) ^ y.wrapping_mul(19349663)).rem_euclid(1000);
            k as f64
        };
        let f: Vec<f64> = (0..w * h)
            .map(|k| pattern((k % w) as i64, (k / w) as i64))
            .collect();
        for &(sx, sy) in &[(0i64, 0i64), (5, -3), (-11, 7)] {
            // g(x + s) = f(x)  ⇔  g(x) = f(x − s)
            let g: Vec<f64> = (0..w * h)
                .map(|k| pattern((k % w) as i64 - sx, (k / w) as i64 - sy))
                .collect();
            assert_eq!(integer_shift(&f, &g, w, h), (sx, sy));
        }
    }
}
