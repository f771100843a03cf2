//! Grey-level images in memory: luminance, the pixel size, and the 2x2 pyramid (reading them
//! from PNG/TIFF/DICOM files is [`crate::read`]).
//!
//! Grey levels are kept as `f64` on a 0–255 scale whatever the bit depth (16-bit values are
//! divided by 257, so no precision is lost). Colour is converted to luminance with the ITU-R
//! BT.601 weights `Y = 0.299 R + 0.587 G + 0.114 B` (the weights of ultrasound scanners' video
//! outputs and of DICOM's YBR conversion).

use crate::error::DicError;
use std::path::Path;

/// BT.601 luma weights.
pub const LUMA: [f64; 3] = [0.299, 0.587, 0.114];

/// The physical size of a pixel, when the file tells it.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize)]
pub struct PixelSize {
    /// Size along x (columns), mm.
    pub dx_mm: f64,
    /// Size along y (rows), mm.
    pub dy_mm: f64,
    /// Where it comes from (`"SequenceOfUltrasoundRegions"`, `"PixelSpacing"`, `"option"`).
    pub source: &'static str,
}

/// A grey-level image, row-major, pixel centres at integer coordinates `(x, y)`, `y` down.
#[derive(Debug, Clone)]
pub struct GreyImage {
    pub width: usize,
    pub height: usize,
    /// `data[y * width + x]`, grey levels on a 0–255 scale.
    pub data: Vec<f64>,
    /// Pixel size read from the file (DICOM), if any.
    pub pixel_size: Option<PixelSize>,
}

impl GreyImage {
    /// An image from row-major values; errors if the length does not match or a value is not
    /// finite.
    pub fn new(width: usize, height: usize, data: Vec<f64>) -> Result<Self, DicError> {
        if width == 0 || height == 0 || data.len() != width * height {
            return Err(DicError::option(
                "image",
                format!("{} values for a {width} x {height} image", data.len()),
            ));
        }
        if let Some(k) = data.iter().position(|v| !v.is_finite()) {
            return Err(DicError::option(
                "image",
                format!("pixel ({}, {}) is not finite", k % width, k / width),
            ));
        }
        Ok(GreyImage {
            width,
            height,
            data,
            pixel_size: None,
        })
    }

    /// The grey level of pixel `(x, y)`.
    #[inline]
    pub fn at(&self, x: usize, y: usize) -> f64 {
        self.data[y * self.width + x]
    }

    /// The 2x2 block average (one pyramid level down): pixel `(i, j)` of the result covers the
    /// pixels `2i..2i+2 x 2j..2j+2`, so its centre is at `(2i + 0.5, 2j + 0.5)` here.
    pub fn half(&self) -> GreyImage {
        let (w, h) = (self.width / 2, self.height / 2);
        let mut data = vec![0.0; w * h];
        for j in 0..h {
            for i in 0..w {
                let a = self.at(2 * i, 2 * j) + self.at(2 * i + 1, 2 * j);
                let b = self.at(2 * i, 2 * j + 1) + self.at(2 * i + 1, 2 * j + 1);
                data[j * w + i] = 0.25 * (a + b);
            }
        }
        GreyImage {
            width: w,
            height: h,
            data,
            pixel_size: self.pixel_size,
        }
    }

    /// The image convolved with a Gaussian of standard deviation `sigma` px (separable,
    /// truncated at 3.5 σ and renormalized, mirror-symmetric borders as the B-splines use);
    /// `sigma = 0` returns a copy. Coarse-to-fine correlation smooths the speckle this way to
    /// widen its capture range: a displacement error `δ` changes the grey levels of a blurred
    /// image by about `∇f δ`, with `|∇f|` falling as `1/√(σ_speckle² + σ²)`.
    pub fn gaussian_blur(&self, sigma: f64) -> GreyImage {
        if !(sigma > 0.0) {
            return self.clone();
        }
        let r = (3.5 * sigma).ceil() as isize;
        let mut k: Vec<f64> = (-r..=r)
            .map(|i| (-(i * i) as f64 / (2.0 * sigma * sigma)).exp())
            .collect();
        let sum: f64 = k.iter().sum();
        k.iter_mut().for_each(|v| *v /= sum);
        let (w, h) = (self.width, self.height);
        let mirror = |i: isize, n: usize| -> usize {
            let n = n as isize;
            if n == 1 {
                return 0;
            }
            let period = 2 * (n - 1);
            let mut i = i.rem_euclid(period);
            if i >= n {
                i = period - i;
            }
            i as usize
        };
        let mut rows = vec![0.0; w * h];
        for y in 0..h {
            for x in 0..w {
                rows[y * w + x] = k
                    .iter()
                    .enumerate()
                    .map(|(m, kv)| kv * self.data[y * w + mirror(x as isize + m as isize - r, w)])
                    .sum();
            }
        }
        let mut data = vec![0.0; w * h];
        for y in 0..h {
            for x in 0..w {
                data[y * w + x] = k
                    .iter()
                    .enumerate()
                    .map(|(m, kv)| kv * rows[mirror(y as isize + m as isize - r, h) * w + x])
                    .sum();
            }
        }
        GreyImage {
            width: w,
            height: h,
            data,
            pixel_size: self.pixel_size,
        }
    }

    /// The image locally normalized: each grey level minus its local mean, over its local
    /// spread, both Gaussian-weighted over `window` px (standard deviation),
    ///
    /// ```text
    ///   n = 50 (f − G∗f) / √(G∗(f − G∗f)² + 5²)
    /// ```
    ///
    /// (scaled so that a textured region keeps a spread of about 50 grey levels; the 5 grey
    /// levels keep flat regions, the black gel above the skin, from being amplified into noise).
    /// A brightness that changes slowly in space — a gain, an offset, the echo of an interface
    /// whose amplitude changes between frames — leaves `n` as it was while the positions of the
    /// pattern stay: what a correlation then matches is the pattern, not its local brightness
    /// (locally normalized correlation; cf. the zero-normalized criteria of subset DIC, Pan et
    /// al. 2009).
    pub fn locally_normalized(&self, window: f64) -> GreyImage {
        let mean = self.gaussian_blur(window);
        let mut centred = self.clone();
        centred
            .data
            .iter_mut()
            .zip(&mean.data)
            .for_each(|(v, m)| *v -= m);
        let mut square = centred.clone();
        square.data.iter_mut().for_each(|v| *v *= *v);
        let variance = square.gaussian_blur(window);
        centred
            .data
            .iter_mut()
            .zip(&variance.data)
            .for_each(|(v, s2)| *v = 50.0 * *v / (s2 + 25.0).sqrt());
        centred
    }

    /// Writes the image as an 8-bit grey PNG (values clamped to 0–255).
    pub fn save_png(&self, path: &Path) -> Result<(), DicError> {
        let buf: Vec<u8> = self
            .data
            .iter()
            .map(|v| v.round().clamp(0.0, 255.0) as u8)
            .collect();
        image::GrayImage::from_raw(self.width as u32, self.height as u32, buf)
            .ok_or_else(|| DicError::Write {
                path: path.to_path_buf(),
                message: "buffer size".into(),
            })
            .and_then(|img| {
                femu_plot::save_png(path, &img).map_err(|e| DicError::Write {
                    path: path.to_path_buf(),
                    message: e.to_string(),
                })
            })
    }
}

/// BT.601 luminance.
#[inline]
pub fn luma(r: f64, g: f64, b: f64) -> f64 {
    LUMA[0] * r + LUMA[1] * g + LUMA[2] * b
}

#[cfg(test)]
mod tests {
    use super::*;

    /// 8-bit grey, 16-bit grey and RGB PNG files read back with the same grey levels.
    #[test]
    fn reads_grey_16bit_and_rgb() {
        let dir = std::env::temp_dir().join(format!("femu-dic-img-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let g8 = image::GrayImage::from_fn(5, 3, |x, y| image::Luma([(10 * x + 50 * y) as u8]));
        g8.save(dir.join("g8.png")).unwrap();
        let g16 = image::ImageBuffer::<image::Luma<u16>, _>::from_fn(5, 3, |x, y| {
            image::Luma([257 * (10 * x + 50 * y) as u16])
        });
        g16.save(dir.join("g16.tif")).unwrap();
        let rgb = image::RgbImage::from_fn(5, 3, |x, y| {
            let v = (10 * x + 50 * y) as u8;
            image::Rgb([v, v, v])
        });
        rgb.save(dir.join("rgb.png")).unwrap();
        for name in ["g8.png", "g16.tif", "rgb.png"] {
            let img = GreyImage::open(&dir.join(name), 0).unwrap();
            assert_eq!((img.width, img.height), (5, 3));
            assert!(
                (img.at(3, 2) - 130.0).abs() < 1e-9,
                "{name}: {}",
                img.at(3, 2)
            );
        }
        let e = GreyImage::open(&dir.join("missing.png"), 0).unwrap_err();
        assert!(e.to_string().contains("missing.png"));
        std::fs::remove_dir_all(&dir).ok();
    }

    /// The blur keeps a constant image, conserves the grey levels and spreads a point as a
    /// Gaussian of the asked width (second moment σ² to 1 %: the truncation at 3.5 σ removes
    /// 0.6 % of it at most; measured 0.2 %).
    #[test]
    fn gaussian_blur_spreads_a_point_by_sigma() {
        let (w, h) = (41, 41);
        let mut d = vec![0.0; w * h];
        d[20 * w + 20] = 1.0;
        let b = GreyImage::new(w, h, d).unwrap().gaussian_blur(2.5);
        let total: f64 = b.data.iter().sum();
        let m2: f64 = (0..w * h)
            .map(|k| b.data[k] * (((k % w) as f64 - 20.0).powi(2)))
            .sum();
        assert!((total - 1.0).abs() < 1e-12, "{total}");
        assert!((m2 / 2.5f64.powi(2) - 1.0).abs() < 1e-2, "{m2}");
        let flat = GreyImage::new(9, 7, vec![42.0; 63])
            .unwrap()
            .gaussian_blur(3.0);
        assert!(flat.data.iter().all(|v| (v - 42.0).abs() < 1e-12));
        assert_eq!(b.gaussian_blur(0.0).data, b.data);
    }

    /// Local normalization removes a gain and an offset that vary slowly across the image
    /// (here 0.5 → 1.5 and 20 → 80 grey levels over 64 px, against a 4-px window): the
    /// normalized textures agree to a few percent of their spread, where the raw ones differ by
    /// their whole spread; a flat image normalizes to zero.
    #[test]
    fn local_normalization_ignores_a_slow_gain_and_offset() {
        let (w, h) = (64, 64);
        let texture: Vec<f64> = (0..w * h)
            .map(|k| {
                let (x, y) = ((k % w) as f64, (k / w) as f64);
                100.0 + 40.0 * (0.9 * x).sin() * (0.7 * y + 0.3 * x).cos()
            })
            .collect();
        let shaded: Vec<f64> = texture
            .iter()
            .enumerate()
            .map(|(k, v)| {
                let t = (k % w) as f64 / (w - 1) as f64;
                (0.5 + t) * v + 20.0 + 60.0 * t
            })
            .collect();
        let a = GreyImage::new(w, h, texture.clone())
            .unwrap()
            .locally_normalized(4.0);
        let b = GreyImage::new(w, h, shaded.clone())
            .unwrap()
            .locally_normalized(4.0);
        let inner = |k: usize| (12..w - 12).contains(&(k % w)) && (12..h - 12).contains(&(k / w));
        let (mut diff, mut spread, mut n) = (0.0, 0.0, 0.0);
        for k in (0..w * h).filter(|&k| inner(k)) {
            diff += (a.data[k] - b.data[k]).powi(2);
            spread += a.data[k].powi(2);
            n += 1.0;
        }
        let (diff, spread) = ((diff / n).sqrt(), (spread / n).sqrt());
        assert!(spread > 30.0 && spread < 60.0, "spread {spread}");
        assert!(
            diff < 0.05 * spread,
            "rms difference {diff} against spread {spread}"
        );
        // Without the normalization the two differ by more than the texture's own spread.
        let raw = GreyImage::new(w, h, texture.clone()).unwrap();
        let shaded = GreyImage::new(w, h, shaded).unwrap();
        let raw_diff = (0..w * h)
            .filter(|&k| inner(k))
            .map(|k| (raw.data[k] - shaded.data[k]).powi(2))
            .sum::<f64>()
            / n;
        assert!(raw_diff.sqrt() > 28.0, "{}", raw_diff.sqrt());
        let flat = GreyImage::new(9, 7, vec![42.0; 63])
            .unwrap()
            .locally_normalized(3.0);
        assert!(flat.data.iter().all(|v| v.abs() < 1e-9));
    }

    #[test]
    fn half_averages_blocks() {
        let img = GreyImage::new(4, 2, vec![0., 2., 4., 6., 2., 4., 6., 8.]).unwrap();
        let h = img.half();
        assert_eq!((h.width, h.height), (2, 1));
        assert_eq!(h.data, vec![2.0, 6.0]);
    }
}
