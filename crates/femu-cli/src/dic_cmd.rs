//! `femu dic REF DEF` (global Q4 DIC between two images) and `femu dic-noise IMAGES...`
//! (random error from successive images of unloaded tissue).
//!
//! `femu dic` writes into `--out`:
//! - `field.csv` — the measured-field CSV of conventions.md (`x,y,ux,uy,w`, mm, model frame)
//!   on a regular grid; `w` = 0 in elements flagged for a high residual;
//! - `nodes.csv` — nodal displacements in pixels and mm; `elements.csv` — strain, residual,
//!   flag per element; `result.vtu` — the mesh for ParaView;
//! - `ux.png`, `uy.png`, `exx.png`, `eyy.png`, `exy.png`, `residual.png` — maps over the
//!   reference image with colour bars;
//! - `summary.json` — inputs, options, pixel size and its source, iterations, residual,
//!   timings.
//!
//! Thin glue: parsing and validation here, everything numerical in `femu-dic`.

use anyhow::{bail, Context, Result};
use clap::{Args, ValueEnum};
use femu_dic::output::{self, DicSummary, ModelFrame};
use femu_dic::{correlate, Brightness, DicOptions, DicResult, GreyImage, PixelSize, Rect, Roi};
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
    /// Region of interest x,y,w,h (pixels of the reference image).
    #[arg(long, conflicts_with = "mask")]
    pub roi: Option<String>,
    /// Region of interest as a mask image (same size; pixels brighter than half its maximum
    /// are inside). Without --roi or --mask, the whole image.
    #[arg(long)]
    pub mask: Option<PathBuf>,
    /// Element size (pixels).
    #[arg(long, default_value_t = 16)]
    pub element: usize,
    /// Convergence: RMS of the nodal displacement increments (pixels).
    #[arg(long, default_value_t = 1e-3)]
    pub tolerance: f64,
    /// Maximum Gauss–Newton iterations.
    #[arg(long, default_value_t = 100)]
    pub max_iterations: usize,
    /// Brightness/contrast correction of the deformed image.
    #[arg(long, value_enum, default_value = "global")]
    pub brightness: BrightnessArg,
    /// Tikhonov (Laplacian) regularization length (pixels); off by default.
    #[arg(long)]
    pub regularization: Option<f64>,
    /// Pyramid levels above full resolution (default: automatic, up to 2).
    #[arg(long)]
    pub levels: Option<usize>,
    /// No FFT cross-correlation initial guess (start from zero).
    #[arg(long)]
    pub no_fft: bool,
    /// Flag elements whose residual exceeds this factor times the median.
    #[arg(long, default_value_t = 3.0)]
    pub flag_factor: f64,
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

fn parse_pair(name: &str, s: &str) -> Result<[f64; 2]> {
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
    fn options(&self) -> DicOptions {
        DicOptions {
            element_size: self.element,
            tolerance: self.tolerance,
            max_iterations: self.max_iterations,
            brightness: match self.brightness {
                BrightnessArg::None => Brightness::None,
                BrightnessArg::Global => Brightness::Global,
                BrightnessArg::PerElement => Brightness::PerElement,
            },
            regularization_length: self.regularization,
            pyramid_levels: self.levels,
            fft_init: !self.no_fft,
            flag_factor: self.flag_factor,
        }
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
    fn pixel_size(&self, header: Option<PixelSize>) -> Result<Option<PixelSize>> {
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

#[derive(Serialize)]
struct Inputs<'a> {
    reference: &'a Path,
    deformed: &'a Path,
    frame_ref: usize,
    frame_def: usize,
    image_size_px: (usize, usize),
    roi: Option<&'a str>,
    mask: Option<&'a Path>,
    options: &'a DicOptions,
}

#[derive(Serialize)]
struct Summary<'a> {
    femu_version: &'static str,
    command: &'static str,
    inputs: Inputs<'a>,
    /// Pixel size (mm/px) and where it comes from; null if unknown (mm = px then).
    pixel_size: Option<PixelSize>,
    model_frame: ModelFrame,
    result: DicSummary,
    grid_points: usize,
    outputs: Vec<&'static str>,
    warnings: Vec<String>,
    wall_time_s: f64,
}

/// `femu dic`.
pub fn run(a: &DicArgs, quiet: bool) -> Result<()> {
    let t0 = Instant::now();
    let f = GreyImage::open(&a.reference, a.frame_ref)?;
    let g = GreyImage::open(&a.deformed, a.frame_def)?;
    let opts = a.corr.options();
    let roi = a.corr.roi(f.width, f.height)?;
    let mut warnings = Vec::new();
    let pixel_size = a.corr.pixel_size(f.pixel_size)?;
    let origin = parse_pair("origin", &a.origin)?;
    let frame = ModelFrame {
        origin_px: origin,
        pixel_size_mm: pixel_size.map(|p| [p.dx_mm, p.dy_mm]).unwrap_or([1.0, 1.0]),
        x_left: a.x_left,
        y_up: a.y_up,
    };
    if pixel_size.is_none() {
        warnings.push(
            "pixel size unknown (no DICOM header, no --pixel-size): the mm columns are in pixels"
                .to_string(),
        );
    }
    let res = correlate(&f, &g, &roi, &opts)?;
    std::fs::create_dir_all(&a.out)
        .with_context(|| format!("cannot create the output folder {}", a.out.display()))?;
    let step = a.grid.unwrap_or(opts.element_size as f64);
    let points = output::grid(&res, &frame, step)?;
    let size_note = match pixel_size {
        Some(p) => format!("pixel size {} x {} mm ({})", p.dx_mm, p.dy_mm, p.source),
        None => "pixel size unknown: 1 mm = 1 px".to_string(),
    };
    let comments = vec![
        format!(
            "femu dic {}: reference {} (frame {}), deformed {} (frame {})",
            env!("CARGO_PKG_VERSION"),
            a.reference.display(),
            a.frame_ref,
            a.deformed.display(),
            a.frame_def
        ),
        format!(
            "units mm; {size_note}; origin at pixel ({}, {}); x {}, y {}",
            origin[0],
            origin[1],
            if a.x_left { "left" } else { "right" },
            if a.y_up { "up" } else { "down" }
        ),
        format!(
            "global Q4 DIC, element {} px, grid step {step} px; w = 0 in elements flagged for a high residual",
            opts.element_size
        ),
    ];
    output::write_field_csv(&a.out.join("field.csv"), &points, &comments)?;
    output::write_nodes_csv(&a.out.join("nodes.csv"), &res, &frame)?;
    output::write_elements_csv(&a.out.join("elements.csv"), &res, &frame)?;
    output::write_vtu(&a.out.join("result.vtu"), &res, &frame)?;
    let mut outputs = vec![
        "field.csv",
        "nodes.csv",
        "elements.csv",
        "result.vtu",
        "summary.json",
    ];
    if !a.no_figures {
        write_maps(&a.out, &f, &res, &frame, pixel_size.is_some())?;
        outputs.extend([
            "ux.png",
            "uy.png",
            "exx.png",
            "eyy.png",
            "exy.png",
            "residual.png",
        ]);
    }
    let flagged = res.flagged.iter().filter(|&&b| b).count();
    if flagged > 0 {
        warnings.push(format!(
            "{flagged} element(s) flagged for a residual above {} x the median (w = 0 in field.csv)",
            opts.flag_factor
        ));
    }
    if res.residual_percent > 5.0 {
        warnings.push(format!(
            "high grey-level residual ({:.1} % of the dynamic range): the images may not show the same texture (try --brightness per-element, a mask or a regularization length)",
            res.residual_percent
        ));
    }
    if !res.converged {
        warnings.push(format!(
            "not converged in {} iterations (last increment {:.2e} px)",
            res.iterations, res.last_increment_px
        ));
    }
    let summary = Summary {
        femu_version: env!("CARGO_PKG_VERSION"),
        command: "dic",
        inputs: Inputs {
            reference: &a.reference,
            deformed: &a.deformed,
            frame_ref: a.frame_ref,
            frame_def: a.frame_def,
            image_size_px: (f.width, f.height),
            roi: a.corr.roi.as_deref(),
            mask: a.corr.mask.as_deref(),
            options: &opts,
        },
        pixel_size,
        model_frame: frame,
        result: DicSummary::of(&res),
        grid_points: points.len(),
        outputs,
        warnings: warnings.clone(),
        wall_time_s: t0.elapsed().as_secs_f64(),
    };
    let path = a.out.join("summary.json");
    std::fs::write(&path, serde_json::to_string_pretty(&summary)?)
        .with_context(|| format!("cannot write {}", path.display()))?;
    if !quiet {
        let s = &summary.result;
        println!(
            "DIC: {} elements of {} px, {} iterations ({}), residual {:.3} grey levels ({:.2} % of the dynamic), mean u = ({:.4}, {:.4}) px, {:.3} s",
            s.elements,
            s.element_size_px,
            s.iterations,
            if s.converged { "converged" } else { "NOT converged" },
            s.residual_rms,
            s.residual_percent_of_dynamic,
            s.mean_u_px[0],
            s.mean_u_px[1],
            s.timings.total_s
        );
        for w in &warnings {
            eprintln!("warning: {w}");
        }
        println!("results in {}", a.out.display());
    }
    if !res.converged {
        bail!(
            "the correlation did not converge in {} iterations (last increment {:.2e} px > {:.1e}); the last field is in {}",
            res.iterations,
            res.last_increment_px,
            opts.tolerance,
            a.out.display()
        );
    }
    Ok(())
}

/// The PNG maps over the reference image, cropped to the mesh with a margin.
fn write_maps(
    out: &Path,
    f: &GreyImage,
    res: &DicResult,
    frame: &ModelFrame,
    mm: bool,
) -> Result<()> {
    let (w, h) = (f.width, f.height);
    let m = &res.mesh;
    let mut ux = vec![f64::NAN; w * h];
    let mut uy = vec![f64::NAN; w * h];
    let mut strain = [
        vec![f64::NAN; w * h],
        vec![f64::NAN; w * h],
        vec![f64::NAN; w * h],
    ];
    let es = output::element_strains(res, frame);
    for e in 0..m.n_elements() {
        let (px, py) = m.element_origin(e);
        for j in 0..m.h {
            for i in 0..m.h {
                let (x, y) = (px + i, py + j);
                let k = y * w + x;
                if let Some(u) = m.interpolate(&res.displacement, x as f64, y as f64) {
                    let um = frame.displacement(u);
                    ux[k] = if mm { um[0] } else { u[0] };
                    uy[k] = if mm { um[1] } else { u[1] };
                }
                for c in 0..3 {
                    strain[c][k] = es[e][c];
                }
            }
        }
    }
    let residual: Vec<f64> = res.residual_image.iter().map(|&v| v as f64).collect();
    let margin = m.h;
    let x0 = m.x0.saturating_sub(margin);
    let y0 = m.y0.saturating_sub(margin);
    let x1 = (m.x0 + m.nx * m.h + margin).min(w);
    let y1 = (m.y0 + m.ny * m.h + margin).min(h);
    let unit = if mm { "mm" } else { "px" };
    let maps: [(&str, &[f64], String, String, bool); 6] = [
        (
            "ux.png",
            &ux,
            "Horizontal displacement ux".into(),
            format!("ux ({unit})"),
            false,
        ),
        (
            "uy.png",
            &uy,
            "Vertical displacement uy".into(),
            format!("uy ({unit})"),
            false,
        ),
        (
            "exx.png",
            &strain[0],
            "Strain exx (element centres)".into(),
            "exx (-)".into(),
            true,
        ),
        (
            "eyy.png",
            &strain[1],
            "Strain eyy (element centres)".into(),
            "eyy (-)".into(),
            true,
        ),
        (
            "exy.png",
            &strain[2],
            "Shear strain exy (element centres)".into(),
            "exy (-)".into(),
            true,
        ),
        (
            "residual.png",
            &residual,
            format!("Grey-level residual (RMS {:.2})", res.residual_rms),
            "f - g(x+u) (grey levels)".into(),
            true,
        ),
    ];
    for (name, values, title, label, diverging) in maps {
        // Colour range from the 1st to the 99th percentile, so that a few wild values (a
        // flagged element) do not wash out the map.
        let mut v: Vec<f64> = values.iter().copied().filter(|x| x.is_finite()).collect();
        v.sort_by(|a, b| a.total_cmp(b));
        let range = (v.len() > 1).then(|| (v[v.len() / 100], v[v.len() - 1 - v.len() / 100]));
        let range = range.filter(|r| r.1 > r.0);
        let opts = femu_plot::ImageField {
            title,
            value_label: label,
            diverging,
            range,
            crop: Some((x0, y0, x1 - x0, y1 - y0)),
            ..Default::default()
        };
        femu_plot::image_field_png(&out.join(name), &f.data, w, h, values, &opts)
            .with_context(|| format!("cannot draw {}", out.join(name).display()))?;
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
    let images: Vec<GreyImage> = a
        .images
        .iter()
        .map(|p| GreyImage::open(p, 0))
        .collect::<std::result::Result<_, _>>()?;
    let opts = a.corr.options();
    let roi = a.corr.roi(images[0].width, images[0].height)?;
    let pixel_size = a.corr.pixel_size(images[0].pixel_size)?;
    let pairs = femu_dic::noise::successive_pairs(&images, &roi, &opts)?;
    std::fs::create_dir_all(&a.out)
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
    std::fs::write(&path, csv).with_context(|| format!("cannot write {}", path.display()))?;
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
    std::fs::write(&path, serde_json::to_string_pretty(&summary)?)
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
