//! Choice of the scanner settings from the images (seed §2.2 criteria a–b, §3.1.1–3.1.2):
//! per image the grey-level histogram, the saturated fractions and the spread; per dynamic
//! range the optimal gain — the widest histogram (largest standard deviation of the grey
//! levels) among the gains whose saturated fraction (black + white) stays under a threshold
//! (default 1 %), Figs. 5–6; and the texture against depth per frequency, Fig. 4.

use crate::error::UsError;
use crate::manifest::{fmt_num, Entry, Manifest};
use crate::stats::{grey_stats, texture_by_depth, GreyStats};
use femu_plot::{LinePlot, LineStyle, Series};
use std::collections::BTreeMap;
use std::path::Path;

/// Where to measure in each image (pixels): everything, a rectangle `[x0, x1) x [y0, y1)`,
/// or a mask (true inside) — burned-in annotations, scales and logos must be left out.
#[derive(Debug, Clone, PartialEq)]
pub enum Region {
    All,
    Rect {
        x0: usize,
        y0: usize,
        x1: usize,
        y1: usize,
    },
    Mask {
        width: usize,
        height: usize,
        inside: Vec<bool>,
    },
}

impl Region {
    /// Parses the `--roi` of every command, `x,y,WxH` (pixels: the top-left corner and the
    /// size; `femu_dic::Rect::parse`, which refuses four plain numbers).
    pub fn parse_rect(s: &str) -> Result<Region, UsError> {
        let r = femu_dic::Rect::parse(s).map_err(|e| UsError::param("--roi", e.to_string()))?;
        Ok(Region::Rect {
            x0: r.x,
            y0: r.y,
            x1: r.x + r.w,
            y1: r.y + r.h,
        })
    }

    /// A mask from an image file: pixels brighter than half the maximum are inside.
    pub fn mask_image(path: &Path) -> Result<Region, UsError> {
        let img = femu_dic::GreyImage::open(path, 0)
            .map_err(|e| UsError::param("--mask", e.to_string()))?;
        let max = img.data.iter().cloned().fold(0.0, f64::max);
        Ok(Region::Mask {
            width: img.width,
            height: img.height,
            inside: img
                .data
                .iter()
                .map(|&v| max > 0.0 && v > 0.5 * max)
                .collect(),
        })
    }

    /// The mask over a `width x height` image (`None`: all pixels), checked against its size.
    pub fn mask(&self, width: usize, height: usize) -> Result<Option<Vec<bool>>, UsError> {
        match self {
            Region::All => Ok(None),
            Region::Rect { x0, y0, x1, y1 } => {
                if *x1 > width || *y1 > height {
                    return Err(UsError::param(
                        "--roi",
                        format!(
                            "{x0},{y0},{}x{} reaches column {x1} and row {y1}, outside the {width} x {height} px image",
                            x1 - x0,
                            y1 - y0
                        ),
                    ));
                }
                Ok(Some(
                    (0..width * height)
                        .map(|k| {
                            (*x0..*x1).contains(&(k % width)) && (*y0..*y1).contains(&(k / width))
                        })
                        .collect(),
                ))
            }
            Region::Mask {
                width: w,
                height: h,
                inside,
            } => {
                if (*w, *h) != (width, height) {
                    return Err(UsError::param(
                        "--mask",
                        format!("the mask is {w} x {h} px, the images {width} x {height} px"),
                    ));
                }
                if !inside.iter().any(|&b| b) {
                    return Err(UsError::param("--mask", "no pixel is inside the mask"));
                }
                Ok(Some(inside.clone()))
            }
        }
    }

    /// The same region for the DIC.
    pub fn dic_roi(&self, width: usize, height: usize) -> Result<femu_dic::Roi, UsError> {
        Ok(match self {
            Region::All => femu_dic::Roi::Rect(femu_dic::Rect {
                x: 0,
                y: 0,
                w: width,
                h: height,
            }),
            Region::Rect { x0, y0, x1, y1 } => {
                self.mask(width, height)?;
                femu_dic::Roi::Rect(femu_dic::Rect {
                    x: *x0,
                    y: *y0,
                    w: x1 - x0,
                    h: y1 - y0,
                })
            }
            Region::Mask { .. } => femu_dic::Roi::Mask {
                width,
                height,
                inside: self.mask(width, height)?.unwrap_or_default(),
            },
        })
    }
}

/// Options of [`analyse`].
#[derive(Debug, Clone)]
pub struct SettingsOptions {
    pub region: Region,
    /// Largest saturated fraction (black + white) of an acceptable image (0.01: 1 %).
    pub saturation_threshold: f64,
    /// Rows per depth band of the texture profile.
    pub depth_band_px: usize,
    /// Pixel size (mm) for the depth axis, if known.
    pub pixel_size_mm: Option<f64>,
}

impl Default for SettingsOptions {
    fn default() -> Self {
        SettingsOptions {
            region: Region::All,
            saturation_threshold: 0.01,
            depth_band_px: 20,
            pixel_size_mm: None,
        }
    }
}

/// One image's numbers.
#[derive(Debug, Clone, serde::Serialize)]
pub struct ImageReport {
    pub entry: Entry,
    pub stats: GreyStats,
    /// Mean gradient magnitude per depth band (grey levels/px).
    pub texture: Vec<f64>,
}

/// The gains tried at one (subject, frequency, dynamic) and the chosen one.
#[derive(Debug, Clone, serde::Serialize)]
pub struct GainChoice {
    pub subject: String,
    pub frequency_mhz: f64,
    pub dynamic_db: f64,
    /// `(gain, mean std of the grey levels, mean saturated fraction, images)` per gain.
    pub gains: Vec<(f64, f64, f64, usize)>,
    /// The widest histogram under the saturation threshold; `None` if every gain saturates.
    pub optimal_gain_db: Option<f64>,
}

/// The result of `us-settings`.
#[derive(Debug, Clone, serde::Serialize)]
pub struct SettingsReport {
    pub images: Vec<ImageReport>,
    pub choices: Vec<GainChoice>,
    /// Texture per depth band averaged per frequency: `(frequency, values)`.
    pub texture_by_frequency: Vec<(f64, Vec<f64>)>,
    pub depth_band_px: usize,
    pub saturation_threshold: f64,
    pub pixels_in_region: usize,
}

/// Histogram statistics, optimal gains and texture profiles of the manifest's images.
pub fn analyse(manifest: &Manifest, opts: &SettingsOptions) -> Result<SettingsReport, UsError> {
    if !(opts.saturation_threshold >= 0.0 && opts.saturation_threshold < 1.0) {
        return Err(UsError::param(
            "saturation threshold",
            format!("{} is outside [0, 1)", opts.saturation_threshold),
        ));
    }
    let first = manifest.open(0, None)?;
    let (w, h) = (first.width, first.height);
    let mask = opts.region.mask(w, h)?;
    let mut images = Vec::new();
    for (k, e) in manifest.entries.iter().enumerate() {
        let img = if k == 0 {
            first.clone()
        } else {
            manifest.open(k, Some((w, h)))?
        };
        let stats = grey_stats(&img.data, mask.as_deref())?;
        let texture = texture_by_depth(&img.data, w, h, mask.as_deref(), opts.depth_band_px)?;
        images.push(ImageReport {
            entry: e.clone(),
            stats,
            texture,
        });
    }
    let pixels_in_region = images[0].stats.pixels;
    // Optimal gain per (subject, frequency, dynamic).
    let key = |e: &Entry| (e.subject.clone(), ord(e.frequency_mhz), ord(e.dynamic_db));
    let mut groups: BTreeMap<(String, i64, i64), BTreeMap<i64, Vec<&ImageReport>>> =
        BTreeMap::new();
    for r in &images {
        groups
            .entry(key(&r.entry))
            .or_default()
            .entry(ord(r.entry.gain_db))
            .or_default()
            .push(r);
    }
    let mut choices = Vec::new();
    for ((subject, _, _), by_gain) in &groups {
        let any = by_gain
            .values()
            .next()
            .and_then(|v| v.first())
            .map(|r| &r.entry);
        let Some(e0) = any else { continue };
        let gains: Vec<(f64, f64, f64, usize)> = by_gain
            .values()
            .map(|rs| {
                let n = rs.len() as f64;
                (
                    rs[0].entry.gain_db,
                    rs.iter().map(|r| r.stats.std).sum::<f64>() / n,
                    rs.iter().map(|r| r.stats.saturation()).sum::<f64>() / n,
                    rs.len(),
                )
            })
            .collect();
        let optimal_gain_db = gains
            .iter()
            .filter(|g| g.2 <= opts.saturation_threshold)
            .max_by(|a, b| a.1.total_cmp(&b.1))
            .map(|g| g.0);
        choices.push(GainChoice {
            subject: subject.clone(),
            frequency_mhz: e0.frequency_mhz,
            dynamic_db: e0.dynamic_db,
            gains,
            optimal_gain_db,
        });
    }
    // Texture per frequency (mean over its images, band by band).
    let mut by_f: BTreeMap<i64, (f64, Vec<f64>, Vec<usize>)> = BTreeMap::new();
    for r in &images {
        let slot = by_f.entry(ord(r.entry.frequency_mhz)).or_insert_with(|| {
            (
                r.entry.frequency_mhz,
                vec![0.0; r.texture.len()],
                vec![0; r.texture.len()],
            )
        });
        for (b, &v) in r.texture.iter().enumerate() {
            if v.is_finite() {
                slot.1[b] += v;
                slot.2[b] += 1;
            }
        }
    }
    let texture_by_frequency = by_f
        .into_values()
        .map(|(f, s, c)| {
            (
                f,
                s.iter()
                    .zip(&c)
                    .map(|(s, &c)| if c > 0 { s / c as f64 } else { f64::NAN })
                    .collect(),
            )
        })
        .collect();
    Ok(SettingsReport {
        images,
        choices,
        texture_by_frequency,
        depth_band_px: opts.depth_band_px,
        saturation_threshold: opts.saturation_threshold,
        pixels_in_region,
    })
}

/// `(gain, summed histogram in %, images)` of one gain.
type GainHistogram = (f64, [f64; 256], usize);

/// A setting value as an ordered key (1e-6 resolution).
fn ord(v: f64) -> i64 {
    (v * 1e6).round() as i64
}

/// Writes `images.csv`, `optimal_gain.csv`, `texture_depth.csv` and the figures
/// `histograms_<f>MHz_D<dyn>.png` (Fig. 5), `optimal_gain.png` and `saturation.png` (Fig. 6),
/// `texture_depth.png` (Fig. 4) into `out`; returns the files written.
pub fn write_outputs(
    report: &SettingsReport,
    opts: &SettingsOptions,
    out: &Path,
) -> Result<Vec<String>, UsError> {
    let mut files = Vec::new();
    let csv = |name: &str, body: String, files: &mut Vec<String>| -> Result<(), UsError> {
        let p = out.join(name);
        femu_mesh::atomic::write(&p, body).map_err(|e| UsError::write(&p, e))?;
        files.push(name.to_string());
        Ok(())
    };
    let mut s = String::from("line,file,subject,frequency_mhz,gain_db,dynamic_db,pixels,mean,std,fraction_black,fraction_white,p01,p99,range_1_99,entropy_bits\n");
    for r in &report.images {
        let (e, g) = (&r.entry, &r.stats);
        s += &format!(
            "{},{},{},{},{},{},{},{:.4},{:.4},{:.6},{:.6},{},{},{},{:.4}\n",
            e.line,
            e.file,
            e.subject,
            e.frequency_mhz,
            e.gain_db,
            e.dynamic_db,
            g.pixels,
            g.mean,
            g.std,
            g.fraction_black,
            g.fraction_white,
            g.p01,
            g.p99,
            g.range_1_99,
            g.entropy_bits
        );
    }
    csv("images.csv", s, &mut files)?;
    let mut s = String::from(
        "subject,frequency_mhz,dynamic_db,gain_db,images,mean_std,mean_saturation,optimal\n",
    );
    for c in &report.choices {
        for g in &c.gains {
            s += &format!(
                "{},{},{},{},{},{:.4},{:.6},{}\n",
                c.subject,
                c.frequency_mhz,
                c.dynamic_db,
                g.0,
                g.3,
                g.1,
                g.2,
                c.optimal_gain_db == Some(g.0)
            );
        }
    }
    csv("optimal_gain.csv", s, &mut files)?;
    let band = report.depth_band_px as f64;
    let depth = |b: usize| -> f64 {
        let px = (b as f64 + 0.5) * band;
        opts.pixel_size_mm.map_or(px, |d| px * d)
    };
    let mut s = format!(
        "depth_{},{}\n",
        if opts.pixel_size_mm.is_some() {
            "mm"
        } else {
            "px"
        },
        report
            .texture_by_frequency
            .iter()
            .map(|(f, _)| format!("gradient_{}mhz", fmt_num(*f)))
            .collect::<Vec<_>>()
            .join(",")
    );
    let nb = report.texture_by_frequency.first().map_or(0, |t| t.1.len());
    for b in 0..nb {
        s += &format!("{:.4}", depth(b));
        for (_, t) in &report.texture_by_frequency {
            s += &format!(",{:.4}", t[b]);
        }
        s += "\n";
    }
    csv("texture_depth.csv", s, &mut files)?;

    // Fig. 5: histograms per (frequency, dynamic), one curve per gain (mean over subjects).
    let mut hist: BTreeMap<(i64, i64), BTreeMap<i64, GainHistogram>> = BTreeMap::new();
    for r in &report.images {
        let e = &r.entry;
        let slot = hist
            .entry((ord(e.frequency_mhz), ord(e.dynamic_db)))
            .or_default()
            .entry(ord(e.gain_db))
            .or_insert((e.gain_db, [0.0; 256], 0));
        let n = r.stats.pixels as f64;
        for (v, &c) in r.stats.histogram.iter().enumerate() {
            slot.1[v] += 100.0 * c as f64 / n;
        }
        slot.2 += 1;
    }
    for ((f, d), by_gain) in &hist {
        let series: Vec<Series> = by_gain
            .values()
            .map(|(g, h, n)| {
                Series::new(
                    &format!("gain {} dB", fmt_num(*g)),
                    h.iter()
                        .enumerate()
                        .map(|(v, c)| (v as f64, c / *n as f64))
                        .collect(),
                    LineStyle::Line,
                )
            })
            .collect();
        let (f, d) = (*f as f64 * 1e-6, *d as f64 * 1e-6);
        let name = format!("histograms_{}MHz_D{}.png", fmt_num(f), fmt_num(d));
        let p = out.join(&name);
        femu_plot::line_plot_png(
            &p,
            &series,
            &LinePlot {
                title: format!(
                    "Grey-level histograms, {} MHz, dynamic {} dB (seed Fig. 5)",
                    fmt_num(f),
                    fmt_num(d)
                ),
                x_label: "grey level (0-255)".into(),
                y_label: "pixels (%)".into(),
                x_range: Some((0.0, 255.0)),
                ..Default::default()
            },
        )
        .map_err(|e| UsError::plot(&p, e))?;
        files.push(name);
    }
    // Fig. 6: spread and saturation against gain per (subject, frequency, dynamic).
    let label = |c: &GainChoice| {
        let mut l = format!("D{} dB", fmt_num(c.dynamic_db));
        if report.texture_by_frequency.len() > 1 {
            l = format!("{} MHz {l}", fmt_num(c.frequency_mhz));
        }
        if !c.subject.is_empty() {
            l = format!("{} {l}", c.subject);
        }
        l
    };
    let mut spread: Vec<Series> = report
        .choices
        .iter()
        .map(|c| {
            Series::new(
                &label(c),
                c.gains.iter().map(|g| (g.0, g.1)).collect(),
                LineStyle::LineAndMarkers,
            )
        })
        .collect();
    let chosen: Vec<(f64, f64)> = report
        .choices
        .iter()
        .filter_map(|c| {
            c.optimal_gain_db
                .and_then(|g| c.gains.iter().find(|x| x.0 == g).map(|x| (x.0, x.1)))
        })
        .collect();
    if !chosen.is_empty() {
        spread.push(Series::new(
            "optimal (saturation within threshold)",
            chosen,
            LineStyle::Markers,
        ));
    }
    let p = out.join("optimal_gain.png");
    femu_plot::line_plot_png(
        &p,
        &spread,
        &LinePlot {
            title: "Histogram spread against gain per dynamic range (seed Fig. 6)".into(),
            x_label: "gain (dB)".into(),
            y_label: "standard deviation of the grey levels".into(),
            ..Default::default()
        },
    )
    .map_err(|e| UsError::plot(&p, e))?;
    files.push("optimal_gain.png".into());
    let mut sat: Vec<Series> = report
        .choices
        .iter()
        .map(|c| {
            Series::new(
                &label(c),
                c.gains.iter().map(|g| (g.0, 100.0 * g.2)).collect(),
                LineStyle::LineAndMarkers,
            )
        })
        .collect();
    let (gmin, gmax) = report
        .images
        .iter()
        .fold((f64::INFINITY, f64::NEG_INFINITY), |a, r| {
            (a.0.min(r.entry.gain_db), a.1.max(r.entry.gain_db))
        });
    sat.push(Series::new(
        &format!("threshold {} %", 100.0 * report.saturation_threshold),
        vec![
            (gmin, 100.0 * report.saturation_threshold),
            (gmax, 100.0 * report.saturation_threshold),
        ],
        LineStyle::Line,
    ));
    let p = out.join("saturation.png");
    femu_plot::line_plot_png(
        &p,
        &sat,
        &LinePlot {
            title: "Saturated pixels (grey 0 or 255) against gain".into(),
            x_label: "gain (dB)".into(),
            y_label: "saturated pixels (%)".into(),
            ..Default::default()
        },
    )
    .map_err(|e| UsError::plot(&p, e))?;
    files.push("saturation.png".into());
    // Fig. 4: texture against depth per frequency.
    let tex: Vec<Series> = report
        .texture_by_frequency
        .iter()
        .map(|(f, t)| {
            Series::new(
                &format!("{} MHz", fmt_num(*f)),
                t.iter().enumerate().map(|(b, &v)| (depth(b), v)).collect(),
                LineStyle::LineAndMarkers,
            )
        })
        .collect();
    if tex.iter().any(|s| s.points.iter().any(|p| p.1.is_finite())) {
        let p = out.join("texture_depth.png");
        femu_plot::line_plot_png(
            &p,
            &tex,
            &LinePlot {
                title: "Texture against depth per frequency (seed Fig. 4)".into(),
                x_label: format!(
                    "depth ({})",
                    if opts.pixel_size_mm.is_some() {
                        "mm"
                    } else {
                        "px from the image top"
                    }
                ),
                y_label: "mean grey-level gradient (grey levels/px)".into(),
                ..Default::default()
            },
        )
        .map_err(|e| UsError::plot(&p, e))?;
        files.push("texture_depth.png".into());
    }
    Ok(files)
}

/// Writes a JSON value to `path`.
pub fn write_json(path: &Path, v: &impl serde::Serialize) -> Result<(), UsError> {
    let mut text = serde_json::to_string_pretty(v).map_err(|e| UsError::write(path, e))?;
    text.push('\n');
    femu_mesh::atomic::write(path, text).map_err(|e| UsError::write(path, e))
}
