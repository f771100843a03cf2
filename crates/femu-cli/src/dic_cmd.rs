//! `femu dic REF DEF` (global Q4 DIC between two images, `femu_dic::command::run_dic`),
//! `femu dic-check FRAMES...` (self-consistency on a sequence, `femu_dic::check::run_check`)
//! and `femu dic-noise IMAGES...` (random error from successive images of unloaded tissue).
//! The files they write are documented in those library modules.
//!
//! Thin glue: parsing and validation here, everything numerical and every file in `femu-dic`.

use anyhow::{bail, Context, Result};
use clap::{Args, ValueEnum};
use femu_dic::auto::Setting;
use femu_dic::check::{run_check, CheckJob};
use femu_dic::command::{run_dic, CorrelationSpec, DicJob, RoiSpec};
use femu_dic::quality::TrustCriteria;
use femu_dic::{Brightness, DicOptions, GreyImage, PixelSize, Rect, Roi};
use serde::Serialize;
use std::path::{Path, PathBuf};
use std::time::Instant;

/// Brightness and contrast correction (CLI names).
#[derive(Debug, Clone, Copy, ValueEnum)]
pub enum BrightnessArg {
    None,
    Global,
    PerElement,
}

/// Options shared by `dic` and `dic-noise`: where and how to correlate.
#[derive(Args, Debug, Clone)]
pub struct CorrelationArgs {
    /// Region of interest x,y,WxH (pixels of the reference image: the top-left corner, then the
    /// width and height, e.g. 16,16,160x128).
    #[arg(long, conflicts_with = "mask")]
    pub roi: Option<String>,
    /// Region of interest as a mask image (same size; pixels brighter than half its maximum
    /// are inside). Without --roi or --mask, the whole image.
    #[arg(long)]
    pub mask: Option<PathBuf>,
    /// Element size (pixels); default: chosen from the speckle size (at least 16; dic-noise: 16).
    #[arg(long)]
    pub element: Option<usize>,
    /// Convergence: RMS of the nodal displacement increments (pixels).
    #[arg(long, default_value_t = 1e-3)]
    pub tolerance: f64,
    /// Depth of the Anderson acceleration of the Gauss–Newton iterations (0: plain steps).
    #[arg(long, default_value_t = femu_dic::anderson::DEFAULT_DEPTH)]
    pub acceleration: usize,
    /// Maximum Gauss–Newton iterations.
    #[arg(long, default_value_t = 100)]
    pub max_iterations: usize,
    /// Brightness/contrast correction of the deformed image.
    #[arg(long, value_enum, default_value = "global")]
    pub brightness: BrightnessArg,
    /// Tikhonov (Laplacian) regularization length: pixels, `off`, or `auto` (the default for
    /// dic and dic-check: the first of off, 4, 8, 16 elements that converges with half of the
    /// elements trusted, from 4 elements without the unregularized rung when the texture is line-like; dic-noise: off).
    #[arg(long, default_value = "auto")]
    pub regularization: String,
    /// Pyramid levels above full resolution (default: automatic, up to 2).
    #[arg(long)]
    pub levels: Option<usize>,
    /// No FFT cross-correlation initial guess (start from zero).
    #[arg(long)]
    pub no_fft: bool,
    /// Flag elements whose residual exceeds this factor times the median.
    #[arg(long, default_value_t = 3.0)]
    pub flag_factor: f64,
    /// Elements whose correlation score (ZNCC of the reference and the corrected deformed
    /// image) is below this value are not trusted (weight 0).
    #[arg(long, default_value_t = 0.5)]
    pub min_zncc: f64,
    /// Pixel size in mm (one value, or x,y); overrides the DICOM header.
    #[arg(long)]
    pub pixel_size: Option<String>,
}

/// `femu dic REF DEF`.
#[derive(Args, Debug, Clone)]
pub struct DicArgs {
    /// Reference image (PNG, TIFF or DICOM).
    pub reference: PathBuf,
    /// Deformed image (PNG, TIFF or DICOM).
    pub deformed: PathBuf,
    /// Further frames of a sequence (a cine loop under an increasing load): each frame is
    /// correlated with the one before, warm-started by the previous increment, and the
    /// increments are composed to the reference on its material points (field.csv: reference
    /// to the last frame; frame_K/field.csv: to frame K).
    #[arg(num_args = 0..)]
    pub then: Vec<PathBuf>,
    #[command(flatten)]
    pub corr: CorrelationArgs,
    /// Frame of a multi-frame DICOM reference (from 0).
    #[arg(long, default_value_t = 0)]
    pub frame_ref: usize,
    /// Frame of a multi-frame DICOM deformed image (from 0).
    #[arg(long, default_value_t = 0)]
    pub frame_def: usize,
    /// Pixel position x,y of the model origin.
    #[arg(long, default_value = "0,0")]
    pub origin: String,
    /// Model y axis pointing up (image rows point down).
    #[arg(long)]
    pub y_up: bool,
    /// Model x axis pointing left.
    #[arg(long)]
    pub x_left: bool,
    /// Step of the regular grid of field.csv (pixels; default: the element size).
    #[arg(long)]
    pub grid: Option<f64>,
    /// Skip the PNG maps.
    #[arg(long)]
    pub no_figures: bool,
    /// Output folder (created if absent).
    #[arg(long, default_value = "out/dic")]
    pub out: PathBuf,
}

/// `femu dic-noise IMAGES...`.
#[derive(Args, Debug, Clone)]
pub struct DicNoiseArgs {
    /// Successive images of unloaded tissue (at least 2; n images give n − 1 pairs).
    #[arg(required = true, num_args = 2..)]
    pub images: Vec<PathBuf>,
    #[command(flatten)]
    pub corr: CorrelationArgs,
    /// Output folder (created if absent).
    #[arg(long, default_value = "out/dic-noise")]
    pub out: PathBuf,
}

pub(crate) fn parse_pair(name: &str, s: &str) -> Result<[f64; 2]> {
    let v: Vec<f64> = s
        .split(',')
        .map(|t| t.trim().parse::<f64>())
        .collect::<std::result::Result<_, _>>()
        .with_context(|| format!("--{name} '{s}': expected one or two numbers"))?;
    let p = match v.as_slice() {
        [a] => [*a, *a],
        [a, b] => [*a, *b],
        _ => bail!("--{name} '{s}': expected one or two numbers"),
    };
    if !p.iter().all(|x| x.is_finite()) {
        bail!("--{name} '{s}': values must be finite");
    }
    Ok(p)
}

impl CorrelationArgs {
    fn regularization_setting(&self) -> Result<Setting> {
        Ok(match self.regularization.trim() {
            "auto" => Setting::Auto,
            "off" | "none" => Setting::Off,
            v => Setting::Given(
                v.parse::<f64>()
                    .ok()
                    .filter(|l| *l > 0.0)
                    .with_context(|| {
                        format!(
                            "--regularization '{v}': expected a length in pixels, 'auto' or 'off'"
                        )
                    })?,
            ),
        })
    }

    /// Checks every correlation option's range once, before any image is read or correlated:
    /// the first one out of range is the error, naming the option as it is typed (`femu dic`,
    /// `femu dic-check` and `femu dic-noise` call it through [`Self::spec`] and
    /// [`Self::options`]).
    pub fn validate_options(&self) -> Result<()> {
        if !(self.tolerance > 0.0 && self.tolerance.is_finite()) {
            bail!(
                "--tolerance {}: must be a positive number of pixels (e.g. 1e-3)",
                self.tolerance
            );
        }
        if self.max_iterations == 0 {
            bail!("--max-iterations 0: must be at least 1");
        }
        if !(self.flag_factor > 1.0 && self.flag_factor.is_finite()) {
            bail!(
                "--flag-factor {}: must be a number above 1 (times the median residual)",
                self.flag_factor
            );
        }
        if !(self.min_zncc > -1.0 && self.min_zncc < 1.0) {
            bail!("--min-zncc {}: must lie in (-1, 1)", self.min_zncc);
        }
        if let Some(l) = self.levels.filter(|&l| l > 6) {
            bail!("--levels {l}: at most 6 pyramid levels");
        }
        if let Some(h) = self.element.filter(|&h| h < 4) {
            bail!(
                "--element {h}: element size {h} px is below 4 px (too few pixels per element to be measurable)"
            );
        }
        let regularization = self.regularization_setting()?;
        if let (Some(h), Setting::Given(l)) = (self.element, regularization) {
            if l < 2.0 * h as f64 {
                bail!(
                    "--regularization {l}: must be at least twice the element size (--element {h}: {} px)",
                    2 * h
                );
            }
        }
        if let Some(r) = &self.roi {
            Rect::parse(r)?;
        }
        self.pixel_size(None)?;
        Ok(())
    }

    /// The options with a fixed element size and regularization (dic-noise: auto = 16 px, off).
    fn options(&self) -> Result<DicOptions> {
        self.validate_options()?;
        Ok(DicOptions {
            element_size: self.element.unwrap_or(16),
            regularization_length: match self.regularization_setting()? {
                Setting::Given(l) => Some(l),
                _ => None,
            },
            ..self.base_options()
        })
    }

    fn base_options(&self) -> DicOptions {
        DicOptions {
            tolerance: self.tolerance,
            max_iterations: self.max_iterations,
            brightness: match self.brightness {
                BrightnessArg::None => Brightness::None,
                BrightnessArg::Global => Brightness::Global,
                BrightnessArg::PerElement => Brightness::PerElement,
            },
            pyramid_levels: self.levels,
            fft_init: !self.no_fft,
            flag_factor: self.flag_factor,
            acceleration_depth: self.acceleration,
            ..Default::default()
        }
    }

    /// The correlation as `femu dic` and `femu dic-check` run it.
    pub(crate) fn spec(&self) -> Result<CorrelationSpec> {
        self.validate_options()?;
        Ok(CorrelationSpec {
            roi: match (&self.roi, &self.mask) {
                (Some(r), _) => RoiSpec::Rect(Rect::parse(r)?),
                (None, Some(m)) => RoiSpec::Mask(m.clone()),
                (None, None) => RoiSpec::Whole,
            },
            options: self.base_options(),
            element: self
                .element
                .map_or(Setting::Auto, |h| Setting::Given(h as f64)),
            regularization: self.regularization_setting()?,
            trust: TrustCriteria {
                min_zncc: self.min_zncc,
                ..Default::default()
            },
        })
    }

    fn roi(&self, width: usize, height: usize) -> Result<Roi> {
        Ok(match (&self.roi, &self.mask) {
            (Some(r), _) => Roi::Rect(Rect::parse(r)?),
            (None, Some(m)) => {
                let img = GreyImage::open(m, 0)?;
                if (img.width, img.height) != (width, height) {
                    bail!(
                        "{}: the mask is {} x {} px, the images {width} x {height} px",
                        m.display(),
                        img.width,
                        img.height
                    );
                }
                Roi::mask_from_image(&img)
            }
            (None, None) => Roi::Rect(Rect {
                x: 0,
                y: 0,
                w: width,
                h: height,
            }),
        })
    }

    /// The pixel size: the option, else the reference header, else none.
    pub(crate) fn pixel_size(&self, header: Option<PixelSize>) -> Result<Option<PixelSize>> {
        if let Some(s) = &self.pixel_size {
            let p = parse_pair("pixel-size", s)?;
            if !(p[0] > 0.0 && p[1] > 0.0) {
                bail!("--pixel-size '{s}': must be positive (mm)");
            }
            return Ok(Some(PixelSize {
                dx_mm: p[0],
                dy_mm: p[1],
                source: "option --pixel-size",
            }));
        }
        Ok(header)
    }
}

/// `femu dic` on one pair of frames (a sequence goes to `dic_seq::run`).
pub fn run(a: &DicArgs, quiet: bool) -> Result<()> {
    let origin = parse_pair("origin", &a.origin)?;
    let job = DicJob {
        reference: a.reference.clone(),
        deformed: a.deformed.clone(),
        frame_ref: a.frame_ref,
        frame_def: a.frame_def,
        correlation: a.corr.spec()?,
        pixel_size: a.corr.pixel_size(None)?,
        origin_px: origin,
        x_left: a.x_left,
        y_up: a.y_up,
        grid_step_px: a.grid,
        figures: !a.no_figures,
        out: a.out.clone(),
    };
    let t0 = Instant::now();
    let r = match run_dic(&job) {
        Err(femu_dic::DicError::Interrupted(stop)) => {
            let note = "stopped by the user during the correlation: nothing was measured";
            femu_study::output::write_stopped(
                &a.out,
                "dic",
                note,
                &[],
                t0.elapsed().as_secs_f64(),
            )?;
            return Err(anyhow::Error::new(stop).context(note));
        }
        r => r?,
    };
    if !quiet {
        let s = &r.result;
        println!(
            "DIC: {} elements of {} px, regularization {}, {} iterations ({}), residual {:.3} grey levels ({:.2} % of the dynamic), mean u = ({:.4}, {:.4}) px, {:.3} s",
            s.elements,
            s.element_size_px,
            r.choice
                .regularization_px
                .map_or("off".to_string(), |l| format!("{l} px")),
            s.iterations,
            if s.converged { "converged" } else { "NOT converged" },
            s.residual_rms,
            s.residual_percent_of_dynamic,
            s.mean_u_px[0],
            s.mean_u_px[1],
            s.timings.total_s
        );
        println!("options: {}", r.choice.reason);
        println!(
            "quality: {} of {} elements trusted; nodal sd median ({:.3}, {:.3}) px, 90th percentile ({:.3}, {:.3}) px",
            r.quality.trusted_elements,
            s.elements,
            r.quality.sd_median_px[0],
            r.quality.sd_median_px[1],
            r.quality.sd_p90_px[0],
            r.quality.sd_p90_px[1]
        );
        for w in &r.warnings {
            eprintln!("warning: {w}");
        }
        println!("results in {}", a.out.display());
    }
    if r.quality.trusted_elements == 0 {
        bail!(
            "no element of the {} is trusted (every one fails the trust criteria: {}): field.csv has weight 0 everywhere and measures nothing; the folder {} says why per element (elements.csv, trust.png)",
            r.result.elements,
            r.quality
                .untrusted
                .iter()
                .filter(|(_, n)| *n > 0)
                .map(|(why, n)| format!("{n} {why}"))
                .collect::<Vec<_>>()
                .join(", "),
            a.out.display()
        );
    }
    if !r.result.converged {
        bail!(
            "the correlation did not converge in {} iterations (last increment {:.2e} px > {:.1e}); the last field is in {}; {}",
            r.result.iterations,
            r.result.last_increment_px,
            a.corr.tolerance,
            a.out.display(),
            r.advice.unwrap_or_default()
        );
    }
    Ok(())
}

/// `femu dic-check FRAMES...`.
#[derive(Args, Debug, Clone)]
pub struct DicCheckArgs {
    /// Frames of a sequence (PNG, TIFF, DICOM; a multi-frame DICOM file gives all its frames;
    /// at least 2 frames in all).
    #[arg(required = true, num_args = 1..)]
    pub frames: Vec<PathBuf>,
    #[command(flatten)]
    pub corr: CorrelationArgs,
    /// The frames are repeated acquisitions of unloaded tissue (adds the random error).
    #[arg(long)]
    pub unloaded: bool,
    /// Skip the PNG maps.
    #[arg(long)]
    pub no_figures: bool,
    /// Output folder (created if absent).
    #[arg(long, default_value = "out/dic-check")]
    pub out: PathBuf,
}

/// `femu dic-check`.
pub fn run_dic_check(a: &DicCheckArgs, quiet: bool) -> Result<()> {
    let job = CheckJob {
        frames: a.frames.clone(),
        correlation: a.corr.spec()?,
        unloaded: a.unloaded,
        figures: !a.no_figures,
        out: a.out.clone(),
    };
    let r = run_check(&job)?;
    if !quiet {
        for p in &r.pairs {
            println!(
                "{} -> {}: {} ({} px, regularization {}, {} iterations, {:.0} % trusted)",
                p.reference,
                p.deformed,
                if p.converged {
                    "converged"
                } else {
                    "NOT converged"
                },
                p.element_size_px,
                p.regularization_px
                    .map_or("off".to_string(), |l| format!("{l} px")),
                p.iterations,
                100.0 * p.trusted_fraction
            );
        }
        for c in &r.pooled {
            let (all, tr) = (&c.regions[0], &c.regions[4]);
            println!(
                "{} ({}): RMS (x, y) ({:.3}, {:.3}) px over {} points, trusted ({:.3}, {:.3}) px over {}, predicted sd ({:.3}, {:.3}) px",
                c.check,
                c.frames[0],
                all.rms_px[0],
                all.rms_px[1],
                all.points,
                tr.rms_px[0],
                tr.rms_px[1],
                tr.points,
                tr.predicted_sd_px[0],
                tr.predicted_sd_px[1]
            );
        }
        println!("results in {}", a.out.display());
    }
    if !r.all_converged {
        let failed: Vec<String> = r
            .pairs
            .iter()
            .filter(|p| !p.converged)
            .map(|p| {
                let why = p.error.clone().unwrap_or_else(|| {
                    format!(
                        "not converged in {} iterations (element {} px)",
                        p.iterations, p.element_size_px
                    )
                });
                format!("  {} -> {}: {why}", p.reference, p.deformed)
            })
            .collect();
        bail!(
            "{} of {} correlations did not converge (pairs.csv in {}):\n{}",
            failed.len(),
            r.pairs.len(),
            a.out.display(),
            failed.join("\n")
        );
    }
    Ok(())
}

#[derive(Serialize)]
struct NoiseSummary<'a> {
    femu_version: &'static str,
    command: &'static str,
    images: &'a [PathBuf],
    options: &'a DicOptions,
    roi: Option<&'a str>,
    mask: Option<&'a Path>,
    pixel_size: Option<PixelSize>,
    pairs: &'a [femu_dic::noise::PairNoise],
    /// Mean over the pairs of the standard deviations (pixels).
    mean_std_ux_px: f64,
    mean_std_uy_px: f64,
    wall_time_s: f64,
}

/// `femu dic-noise`.
pub fn run_noise(a: &DicNoiseArgs, quiet: bool) -> Result<()> {
    let t0 = Instant::now();
    let mut inputs: Vec<&Path> = a.images.iter().map(PathBuf::as_path).collect();
    inputs.extend(a.corr.mask.as_deref());
    femu_mesh::folder::refuse_inputs_in(&a.out, &inputs)?;
    let images: Vec<GreyImage> = a
        .images
        .iter()
        .map(|p| GreyImage::open(p, 0))
        .collect::<std::result::Result<_, _>>()?;
    let opts = a.corr.options()?;
    let roi = a.corr.roi(images[0].width, images[0].height)?;
    let pixel_size = a.corr.pixel_size(images[0].pixel_size)?;
    let pairs = femu_dic::noise::successive_pairs(&images, &roi, &opts)?;
    femu_mesh::atomic::create_dir_all(&a.out)
        .with_context(|| format!("cannot create the output folder {}", a.out.display()))?;
    let mut csv = String::from(
        "pair,reference,deformed,mean_ux_px,mean_uy_px,std_ux_px,std_uy_px,std_ux_mm,std_uy_mm,converged,iterations,residual_rms\n",
    );
    let (dx, dy) = pixel_size
        .map(|p| (p.dx_mm, p.dy_mm))
        .unwrap_or((f64::NAN, f64::NAN));
    for (k, p) in pairs.iter().enumerate() {
        csv.push_str(&format!(
            "{},{},{},{:.6e},{:.6e},{:.6e},{:.6e},{:.6e},{:.6e},{},{},{:.4}\n",
            k + 1,
            a.images[p.reference].display(),
            a.images[p.deformed].display(),
            p.mean_ux_px,
            p.mean_uy_px,
            p.std_ux_px,
            p.std_uy_px,
            p.std_ux_px * dx,
            p.std_uy_px * dy,
            p.converged,
            p.iterations,
            p.residual_rms
        ));
    }
    let path = a.out.join("noise.csv");
    femu_mesh::atomic::write(&path, csv)
        .with_context(|| format!("cannot write {}", path.display()))?;
    let groups = vec![
        (
            "std ux".to_string(),
            pairs.iter().map(|p| p.std_ux_px).collect(),
        ),
        (
            "std uy".to_string(),
            pairs.iter().map(|p| p.std_uy_px).collect(),
        ),
    ];
    femu_plot::box_plot_png(
        &a.out.join("noise_box.png"),
        &groups,
        &femu_plot::BoxPlot {
            title: format!(
                "DIC random error over {} pairs of unloaded images",
                pairs.len()
            ),
            y_label: "standard deviation of the displacement (px)".into(),
            ..Default::default()
        },
    )?;
    let n = pairs.len() as f64;
    let summary = NoiseSummary {
        femu_version: env!("CARGO_PKG_VERSION"),
        command: "dic-noise",
        images: &a.images,
        options: &opts,
        roi: a.corr.roi.as_deref(),
        mask: a.corr.mask.as_deref(),
        pixel_size,
        pairs: &pairs,
        mean_std_ux_px: pairs.iter().map(|p| p.std_ux_px).sum::<f64>() / n,
        mean_std_uy_px: pairs.iter().map(|p| p.std_uy_px).sum::<f64>() / n,
        wall_time_s: t0.elapsed().as_secs_f64(),
    };
    let path = a.out.join("summary.json");
    femu_mesh::atomic::write(&path, serde_json::to_string_pretty(&summary)?)
        .with_context(|| format!("cannot write {}", path.display()))?;
    if !quiet {
        for (k, p) in pairs.iter().enumerate() {
            println!(
                "pair {}: std ux {:.4} px, std uy {:.4} px ({})",
                k + 1,
                p.std_ux_px,
                p.std_uy_px,
                if p.converged {
                    "converged"
                } else {
                    "NOT converged"
                }
            );
        }
        println!("results in {}", a.out.display());
    }
    if let Some((k, _)) = pairs.iter().enumerate().find(|(_, p)| !p.converged) {
        bail!("pair {} did not converge; see {}", k + 1, a.out.display());
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use clap::Parser;
    use femu_dic::auto::{advice_text, suggestions, FAILURES};
    use femu_dic::Rect;

    /// `femu dic ref.png def.png ARGS` through the command line's own parser, then the option
    /// check every DIC command runs first.
    fn parse(args: &[String]) {
        let argv = ["femu", "dic", "ref.png", "def.png"]
            .into_iter()
            .map(String::from)
            .chain(args.iter().cloned());
        let cli = crate::Cli::try_parse_from(argv)
            .unwrap_or_else(|e| panic!("femu dic refuses the advice {args:?}: {e}"));
        let crate::Command::Dic(a) = cli.command else {
            panic!("{args:?} is not femu dic")
        };
        a.corr
            .validate_options()
            .unwrap_or_else(|e| panic!("femu dic refuses the advice {args:?}: {e:#}"));
    }

    /// Every piece of advice femu can print after a failed correlation (each failure kind, with
    /// and without a ROI hint, small and large elements) is accepted by `femu dic` as printed,
    /// alone and all together.
    #[test]
    fn every_piece_of_advice_parses_as_femu_dic_options() {
        let hint = Rect {
            x: 16,
            y: 84,
            w: 448,
            h: 197,
        };
        let mut checked = 0;
        for failure in FAILURES {
            for h in [4, 16, 64] {
                for tissue in [None, Some(hint)] {
                    let all = suggestions(failure, h, tissue);
                    let text = advice_text(&all);
                    let mut together = Vec::new();
                    for s in &all {
                        if !s.args.is_empty() {
                            assert!(text.contains(&s.args.join(" ")), "{text}");
                        }
                        parse(&s.args);
                        together.extend(s.args.iter().cloned());
                        checked += 1;
                    }
                    parse(&together);
                }
            }
        }
        assert!(checked >= 20, "{checked} suggestions");
    }
}
