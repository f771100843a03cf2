//! `femu us-sim`, `us-scan`, `us-settings`, `us-noise`: the ultrasound commands (seed §2.2,
//! §3.1, Figs. 4–7, and the virtual experiment with images). Thin glue: the study's `[probe]`
//! and `[ultrasound]` tables are read by femu-study, the experiment runs in
//! `femu_study::steps::ultrasound`, everything numerical lives in `femu-ultrasound`.

use crate::progress::Terminal;
use anyhow::{bail, Context, Result};
use clap::Args;
use femu_dic::DicOptions;
use femu_mesh::folder::refuse_inputs_in;
use femu_study::steps::ultrasound::{self, ScanOptions, SimOptions};
use femu_ultrasound::manifest::{fmt_num, Manifest};
use femu_ultrasound::noise;
use femu_ultrasound::settings::{self, Region, SettingsOptions};
use serde::Serialize;
use std::path::{Path, PathBuf};
use std::time::Instant;

/// `femu us-sim`.
#[derive(Debug, Args)]
pub struct UsSimArgs {
    /// Study file (TOML; the identification test, [probe], [ultrasound]). Without it: the
    /// built-in thigh, Table 1, compression (0.1 N/mm, anterior), probe on the anterior skin.
    pub study: Option<PathBuf>,
    #[arg(long, default_value = "out/us-sim")]
    pub out: PathBuf,
    /// Target number of elements of the built-in thigh (overrides the study).
    #[arg(long)]
    pub elements: Option<usize>,
    /// DIC element size (px).
    #[arg(long, default_value_t = 16)]
    pub element: usize,
    /// DIC regularization length (px).
    #[arg(long)]
    pub regularization: Option<f64>,
    /// Spacing of the measured grid (px).
    #[arg(long, default_value_t = 16.0)]
    pub grid_step: f64,
    /// DIC pyramid levels above the full image (the compression test moves the skin by tens
    /// of pixels: 3 levels bring that within the capture range of the coarsest level).
    #[arg(long, default_value_t = 3)]
    pub levels: usize,
    /// Load steps imaged and correlated in succession (incremental DIC); 1: one DIC from the
    /// unloaded to the loaded image.
    #[arg(long, default_value_t = 4)]
    pub steps: usize,
}

/// `femu us-scan`.
#[derive(Debug, Args)]
pub struct UsScanArgs {
    /// Study file (TOML; [probe], [ultrasound] and the built-in thigh's [model]).
    pub study: Option<PathBuf>,
    #[arg(long, default_value = "out/us-scan")]
    pub out: PathBuf,
    /// Centre frequencies (MHz).
    #[arg(long, value_delimiter = ',', default_value = "9")]
    pub frequencies: Vec<f64>,
    /// Gains (dB).
    #[arg(long, value_delimiter = ',', default_value = "30,34,38")]
    pub gains: Vec<f64>,
    /// Dynamic ranges (dB).
    #[arg(long, value_delimiter = ',', default_value = "42")]
    pub dynamics: Vec<f64>,
    /// Acquisitions per setting (successive frames of the unloaded tissue).
    #[arg(long, default_value_t = 1)]
    pub repeats: usize,
    /// Speckle correlation between successive acquisitions (out-of-plane motion), in [0, 1].
    #[arg(long, default_value_t = 0.95)]
    pub correlation: f64,
    /// Subjects (thighs with different scatterer realizations).
    #[arg(long, default_value_t = 1)]
    pub subjects: usize,
    /// Target number of elements of the built-in thigh.
    #[arg(long, default_value_t = 3000)]
    pub elements: usize,
}

/// `femu us-sim`: the virtual experiment with images.
pub fn sim(args: &UsSimArgs, quiet: bool) -> Result<()> {
    let study = femu_study::load(args.study.as_deref(), args.elements)?;
    let options = SimOptions {
        element: args.element,
        regularization: args.regularization,
        grid_step: args.grid_step,
        levels: args.levels,
        steps: args.steps,
    };
    ultrasound::sim(
        ultrasound::SimInputs::of(&study),
        &options,
        &args.out,
        &Terminal { quiet },
    )?;
    Ok(())
}

/// `femu us-scan`: images of the unloaded built-in thigh over a grid of settings, with the
/// manifest that `us-settings` and `us-noise` read.
pub fn scan(args: &UsScanArgs, quiet: bool) -> Result<()> {
    let study = femu_study::load(args.study.as_deref(), Some(args.elements))?;
    let options = ScanOptions {
        frequencies: args.frequencies.clone(),
        gains: args.gains.clone(),
        dynamics: args.dynamics.clone(),
        repeats: args.repeats,
        correlation: args.correlation,
        subjects: args.subjects,
    };
    Ok(ultrasound::scan(
        &study,
        &options,
        &args.out,
        &Terminal { quiet },
    )?)
}

/// Region options shared by us-settings and us-noise.
#[derive(Debug, Args)]
pub struct RegionArgs {
    /// Region of interest x,y,WxH (pixels: the top-left corner, then the width and height, e.g.
    /// 115,65,570x450) — leave burned-in text and scales out.
    #[arg(long, conflicts_with = "mask")]
    pub roi: Option<String>,
    /// Region of interest as a mask image (pixels brighter than half its maximum are inside).
    #[arg(long)]
    pub mask: Option<PathBuf>,
}

impl RegionArgs {
    /// `files` and the mask image, if any.
    fn with_mask<'a>(&'a self, mut files: Vec<&'a Path>) -> Vec<&'a Path> {
        files.extend(self.mask.as_deref());
        files
    }

    fn region(&self) -> Result<Region> {
        Ok(match (&self.roi, &self.mask) {
            (Some(r), _) => Region::parse_rect(r)?,
            (None, Some(m)) => Region::mask_image(m)?,
            (None, None) => Region::All,
        })
    }
}

/// `femu us-settings`.
#[derive(Debug, Args)]
pub struct UsSettingsArgs {
    /// Manifest CSV: file, frequency_mhz, gain_db, dynamic_db[, subject] (paths relative to it).
    pub manifest: PathBuf,
    #[command(flatten)]
    pub region: RegionArgs,
    /// Largest saturated fraction (black + white) of an acceptable gain.
    #[arg(long, default_value_t = 0.01)]
    pub saturation: f64,
    /// Rows per depth band of the texture profile.
    #[arg(long, default_value_t = 20)]
    pub band: usize,
    /// Pixel size (mm) for the depth axis.
    #[arg(long)]
    pub pixel_size: Option<f64>,
    #[arg(long, default_value = "out/us-settings")]
    pub out: PathBuf,
}

/// `femu us-settings`.
pub fn run_settings(args: &UsSettingsArgs, quiet: bool) -> Result<()> {
    let t0 = Instant::now();
    let manifest = Manifest::read(&args.manifest)?;
    refuse_inputs_in(&args.out, &args.region.with_mask(manifest.input_files()))?;
    if let Some(d) = args.pixel_size {
        if !(d > 0.0 && d.is_finite()) {
            bail!("--pixel-size {d} must be positive");
        }
    }
    let opts = SettingsOptions {
        region: args.region.region()?,
        saturation_threshold: args.saturation,
        depth_band_px: args.band,
        pixel_size_mm: args.pixel_size,
    };
    let report = settings::analyse(&manifest, &opts)?;
    femu_mesh::atomic::create_dir_all(&args.out)
        .with_context(|| format!("cannot create output folder {}", args.out.display()))?;
    let files = settings::write_outputs(&report, &opts, &args.out)?;
    #[derive(Serialize)]
    struct Summary<'a> {
        command: &'static str,
        version: &'static str,
        manifest: String,
        roi: Option<&'a str>,
        mask: Option<String>,
        images: usize,
        pixels_in_region: usize,
        saturation_threshold: f64,
        optimal: Vec<&'a settings::GainChoice>,
        files: Vec<String>,
        wall_time_s: f64,
    }
    settings::write_json(
        &args.out.join("summary.json"),
        &Summary {
            command: "us-settings",
            version: env!("CARGO_PKG_VERSION"),
            manifest: args.manifest.display().to_string(),
            roi: args.region.roi.as_deref(),
            mask: args.region.mask.as_ref().map(|p| p.display().to_string()),
            images: report.images.len(),
            pixels_in_region: report.pixels_in_region,
            saturation_threshold: report.saturation_threshold,
            optimal: report.choices.iter().collect(),
            files,
            wall_time_s: t0.elapsed().as_secs_f64(),
        },
    )?;
    if !quiet {
        for c in &report.choices {
            eprintln!(
                "{}{} MHz, dynamic {} dB: optimal gain {}",
                if c.subject.is_empty() {
                    String::new()
                } else {
                    format!("{} ", c.subject)
                },
                fmt_num(c.frequency_mhz),
                fmt_num(c.dynamic_db),
                c.optimal_gain_db
                    .map_or("none (every gain saturates)".into(), |g| format!(
                        "{} dB",
                        fmt_num(g)
                    ))
            );
        }
    }
    Ok(())
}

/// `femu us-noise`.
#[derive(Debug, Args)]
pub struct UsNoiseArgs {
    /// Manifest CSV: file, frequency_mhz, gain_db, dynamic_db[, subject]; the rows of one
    /// setting and subject, in order, are successive acquisitions of unloaded tissue.
    pub manifest: PathBuf,
    #[command(flatten)]
    pub region: RegionArgs,
    /// DIC element size (px) (the seed: 8).
    #[arg(long, default_value_t = 16)]
    pub element: usize,
    /// DIC regularization length (px).
    #[arg(long)]
    pub regularization: Option<f64>,
    /// Significance level of the paired t-tests.
    #[arg(long, default_value_t = 0.05)]
    pub alpha: f64,
    #[arg(long, default_value = "out/us-noise")]
    pub out: PathBuf,
}

/// `femu us-noise`.
pub fn run_noise(args: &UsNoiseArgs, quiet: bool) -> Result<()> {
    let t0 = Instant::now();
    let manifest = Manifest::read(&args.manifest)?;
    refuse_inputs_in(&args.out, &args.region.with_mask(manifest.input_files()))?;
    let dic = DicOptions {
        element_size: args.element,
        regularization_length: args.regularization,
        ..Default::default()
    };
    let report = noise::analyse(
        &manifest,
        &args.region.region()?,
        &dic,
        args.alpha,
        &mut |m| {
            if !quiet {
                eprintln!("{m}");
            }
        },
    )?;
    femu_mesh::atomic::create_dir_all(&args.out)
        .with_context(|| format!("cannot create output folder {}", args.out.display()))?;
    let files = noise::write_outputs(&report, &args.out)?;
    #[derive(Serialize)]
    struct Summary<'a> {
        command: &'static str,
        version: &'static str,
        manifest: String,
        dic_element_px: usize,
        report: &'a noise::NoiseReport,
        files: Vec<String>,
        wall_time_s: f64,
    }
    settings::write_json(
        &args.out.join("summary.json"),
        &Summary {
            command: "us-noise",
            version: env!("CARGO_PKG_VERSION"),
            manifest: args.manifest.display().to_string(),
            dic_element_px: args.element,
            report: &report,
            files,
            wall_time_s: t0.elapsed().as_secs_f64(),
        },
    )?;
    if !quiet {
        for s in &report.settings {
            eprintln!(
                "{}: {} pairs, std ux {:.3} ± {:.3} px, std uy {:.3} ± {:.3} px",
                s.label,
                s.pairs.len(),
                s.mean_std_ux_px,
                s.sd_std_ux_px,
                s.mean_std_uy_px,
                s.sd_std_uy_px
            );
        }
        eprintln!(
            "recommended: {}{}",
            report.recommended,
            if report.recommended_significantly_lower {
                " (significantly lower than every other setting)"
            } else {
                " (lowest mean; not significantly lower than every other setting)"
            }
        );
    }
    Ok(())
}
