//! `femu us-sim`, `us-scan`, `us-settings`, `us-noise`: the ultrasound commands (seed §2.2,
//! §3.1, Figs. 4–7, and the virtual experiment with images). Thin glue: the study's
//! `[probe]` and `[ultrasound]` tables are read here, everything numerical lives in
//! `femu-ultrasound`.
//!
//! Study file additions (every key optional, unknown keys are errors):
//!
//! ```toml
//! [probe]
//! side = "anterior"      # anterior, posterior, lateral, medial, or degrees
//! width_mm = 40
//! depth_mm = 40
//! px_per_mm = 10
//! [ultrasound]
//! frequency_mhz = 9      # also cycles, f_number
//! gain_db = 34           # also dynamic_db, black_level_db, tgc_db_per_cm_mhz, tgc_max_db, noise_db
//! dynamic_db = 42
//! seed = 1
//! ```

use crate::plan;
use anyhow::{bail, Context, Result};
use clap::Args;
use femu_dic::{Brightness, DicOptions};
use femu_mech::loading::{apply_loading, Side};
use femu_mech::{SolverOptions, StaticSolver};
use femu_ultrasound::manifest::{fmt_num, Manifest};
use femu_ultrasound::settings::{self, Region, SettingsOptions};
use femu_ultrasound::{experiment, noise, probe, Acoustics, Phantom, Probe, Scanner, Transducer};
use serde::{Deserialize, Serialize};
use std::path::{Path, PathBuf};
use std::time::Instant;

/// `[probe]`: the linear probe on the skin.
#[derive(Debug, Clone, PartialEq, Deserialize, Serialize)]
#[serde(deny_unknown_fields, default)]
pub struct ProbeSection {
    side: String,
    width_mm: f64,
    depth_mm: f64,
    px_per_mm: f64,
}

impl Default for ProbeSection {
    fn default() -> Self {
        ProbeSection {
            side: "anterior".into(),
            width_mm: 40.0,
            depth_mm: 40.0,
            px_per_mm: 10.0,
        }
    }
}

/// `[ultrasound]`: the transducer and the scanner's knobs.
#[derive(Debug, Clone, PartialEq, Deserialize, Serialize)]
#[serde(deny_unknown_fields, default)]
pub struct UltrasoundSection {
    frequency_mhz: f64,
    cycles: f64,
    f_number: f64,
    gain_db: f64,
    dynamic_db: f64,
    black_level_db: f64,
    tgc_db_per_cm_mhz: f64,
    tgc_max_db: f64,
    noise_db: Option<f64>,
    seed: u64,
}

impl Default for UltrasoundSection {
    fn default() -> Self {
        let (t, s) = (Transducer::default(), Scanner::default());
        UltrasoundSection {
            frequency_mhz: t.frequency_mhz,
            cycles: t.cycles,
            f_number: t.f_number,
            gain_db: s.gain_db,
            dynamic_db: s.dynamic_db,
            black_level_db: s.black_level_db,
            tgc_db_per_cm_mhz: s.tgc_db_per_cm_mhz,
            tgc_max_db: s.tgc_max_db,
            noise_db: s.noise_db,
            seed: 1,
        }
    }
}

impl UltrasoundSection {
    fn transducer(&self) -> Transducer {
        Transducer {
            frequency_mhz: self.frequency_mhz,
            cycles: self.cycles,
            f_number: self.f_number,
        }
    }
    fn scanner(&self) -> Scanner {
        Scanner {
            gain_db: self.gain_db,
            dynamic_db: self.dynamic_db,
            black_level_db: self.black_level_db,
            tgc_db_per_cm_mhz: self.tgc_db_per_cm_mhz,
            tgc_max_db: self.tgc_max_db,
            noise_db: self.noise_db,
        }
    }
}

/// The study and its ultrasound tables (`[probe]`, `[ultrasound]`, checked with the rest of the
/// study by `plan`).
fn read_study(
    study: Option<&Path>,
    elements: Option<usize>,
) -> Result<(plan::Plan, ProbeSection, UltrasoundSection)> {
    let p = plan::load(study, elements)?;
    let (probe, us) = (p.probe.clone(), p.ultrasound.clone());
    Ok((p, probe, us))
}

fn place_probe(
    mesh: &femu_mesh::Mesh,
    skin: &[(usize, usize)],
    section: &ProbeSection,
) -> Result<Probe> {
    let side = Side::parse(&section.side).map_err(|e| anyhow::anyhow!("[probe] side: {e}"))?;
    Ok(probe::probe_on_skin(
        mesh,
        skin,
        side.direction(),
        section.width_mm,
        section.depth_mm,
        section.px_per_mm,
    )?)
}

/// Bone faces: the mesh outline minus the skin.
fn bone_faces(mesh: &femu_mesh::Mesh, skin: &[(usize, usize)]) -> Vec<(usize, usize)> {
    let skin: std::collections::HashSet<_> = skin.iter().copied().collect();
    mesh.boundary_faces()
        .into_iter()
        .filter(|f| !skin.contains(f))
        .collect()
}

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

/// The loading scaled by `s` (intermediate states of the incremental DIC).
fn scaled(test: femu_mech::loading::Loading, s: f64) -> femu_mech::loading::Loading {
    use femu_mech::loading::Loading;
    match test {
        Loading::Contention { pressure } => Loading::Contention {
            pressure: pressure * s,
        },
        Loading::Compression { side, force } => Loading::Compression {
            side,
            force: force * s,
        },
        Loading::Indentation {
            site,
            radius,
            force,
        } => Loading::Indentation {
            site,
            radius,
            force: force * s,
        },
    }
}

#[derive(Serialize)]
struct SimSummary {
    command: &'static str,
    version: &'static str,
    test: String,
    elements: usize,
    probe: Probe,
    transducer: Transducer,
    psf: femu_ultrasound::Psf,
    scanner: Scanner,
    acoustics: Acoustics,
    scatterers: usize,
    image_px: (usize, usize),
    roi_pixels: usize,
    dic_steps: usize,
    dic_elements: usize,
    dic_converged: bool,
    dic_iterations: usize,
    dic_residual_rms: f64,
    error: experiment::FieldError,
    max_fe_displacement_mm: f64,
    timings_s: Timings,
}

#[derive(Serialize, Default)]
struct Timings {
    mesh_and_solve: f64,
    phantom: f64,
    render_reference: f64,
    render_deformed: f64,
    dic: f64,
    total: f64,
}

/// `femu us-sim`: the virtual experiment with images.
pub fn sim(args: &UsSimArgs, quiet: bool) -> Result<()> {
    let t0 = Instant::now();
    let (plan, probe_s, us) = read_study(args.study.as_deref(), args.elements)?;
    std::fs::create_dir_all(&args.out)
        .with_context(|| format!("cannot create output folder {}", args.out.display()))?;
    if args.steps == 0 || args.steps > 20 {
        bail!("--steps {} must be in [1, 20]", args.steps);
    }
    let test = plan.tests[plan.identification.test];
    // The loaded state and `steps - 1` intermediate loads (incremental DIC).
    let mut stages: Vec<Vec<f64>> = Vec::new();
    let mut model = None;
    let mut skin = Vec::new();
    for k in 1..=args.steps {
        let (mut m, sk) = crate::sensitivity_cmd::thigh_model(&plan)?;
        let load = scaled(test, k as f64 / args.steps as f64);
        apply_loading(&mut m, &sk, &load).with_context(|| format!("test {}", test.name()))?;
        let mut solver = StaticSolver::new(&m, SolverOptions::default())?;
        let sol = solver
            .solve_with(&m, stages.last().map(|v| v.as_slice()), &mut |_| {})
            .map_err(|e| {
                anyhow::anyhow!(
                    "test {} at {k}/{} of the load: {e}",
                    test.name(),
                    args.steps
                )
            })?;
        stages.push(sol.u[..2 * m.node_count()].to_vec());
        skin = sk;
        model = Some(m);
    }
    let model = model.context("no load step")?;
    let u = stages.last().context("no load step")?;
    let umax = u.chunks(2).map(|c| c[0].hypot(c[1])).fold(0.0, f64::max);
    let mut timings = Timings {
        mesh_and_solve: t0.elapsed().as_secs_f64(),
        ..Default::default()
    };
    if !quiet {
        eprintln!(
            "{}: {} elements solved in {:.2} s, largest displacement {:.3} mm",
            test.name(),
            model.mesh.elements.len(),
            timings.mesh_and_solve,
            umax
        );
    }
    let probe = place_probe(&model.mesh, &skin, &probe_s)?;
    let t = Instant::now();
    let acoustics = Acoustics::default();
    let bone = bone_faces(&model.mesh, &skin);
    let phantom = Phantom::generate(&model.mesh, &bone, &acoustics, &probe, 3.0 + umax, us.seed)?;
    timings.phantom = t.elapsed().as_secs_f64();
    let opts = experiment::ExperimentOptions {
        transducer: us.transducer(),
        scanner: us.scanner(),
        dic: DicOptions {
            element_size: args.element,
            regularization_length: args.regularization,
            brightness: Brightness::Global,
            pyramid_levels: Some(args.levels),
            ..Default::default()
        },
        grid_step_px: args.grid_step,
        noise_seed: us.seed,
        ..Default::default()
    };
    let exp = experiment::run_incremental(&phantom, &stages, &probe, &opts)?;
    timings.render_reference = exp.reference.seconds;
    timings.render_deformed = exp.deformed.seconds;
    timings.dic = exp.dic.timings.total_s;
    let out = &args.out;
    let save = |img: &femu_dic::GreyImage, name: &str| -> Result<()> {
        img.save_png(&out.join(name))
            .with_context(|| format!("cannot write {}", out.join(name).display()))
    };
    save(&exp.reference.image, "ref.png")?;
    save(&exp.deformed.image, "def.png")?;
    let comments = vec![
        format!(
            "femu us-sim {}: DIC of simulated B-mode images, {} test, {} MHz, gain {} dB, dynamic {} dB",
            env!("CARGO_PKG_VERSION"),
            test.name(),
            fmt_num(us.frequency_mhz),
            fmt_num(us.gain_db),
            fmt_num(us.dynamic_db)
        ),
        format!(
            "model frame (mm); probe centre {:?} mm, beam {:?}, {} px/mm",
            probe.centre_mm, probe.direction, probe.px_per_mm
        ),
    ];
    experiment::write_field_csv(&out.join("measured.csv"), &exp.points, false, &comments)?;
    experiment::write_field_csv(
        &out.join("true_field.csv"),
        &exp.points,
        true,
        &["FE displacement at the DIC grid points (mm, model frame)".into()],
    )?;
    // Maps over the reference image.
    let maps = experiment::pixel_maps(&exp, &phantom, u, &probe, args.grid_step);
    let (w, h) = (exp.reference.width, exp.reference.height);
    let grey = &exp.reference.image.data;
    let err: [Vec<f64>; 2] = [0, 1].map(|c| {
        maps[c]
            .iter()
            .zip(&maps[c + 2])
            .map(|(d, t)| d - t)
            .collect()
    });
    let plots: [(&str, &str, &Vec<f64>, bool); 6] = [
        (
            "ux_true.png",
            "FE displacement ux (lateral)",
            &maps[2],
            true,
        ),
        (
            "uy_true.png",
            "FE displacement uy (depth, down)",
            &maps[3],
            true,
        ),
        (
            "ux_dic.png",
            "DIC displacement ux (lateral)",
            &maps[0],
            true,
        ),
        (
            "uy_dic.png",
            "DIC displacement uy (depth, down)",
            &maps[1],
            true,
        ),
        ("error_ux.png", "DIC - FE, ux", &err[0], true),
        ("error_uy.png", "DIC - FE, uy", &err[1], true),
    ];
    for (name, title, values, diverging) in plots {
        let p = out.join(name);
        femu_plot::image_field_png(
            &p,
            grey,
            w,
            h,
            values,
            &femu_plot::ImageField {
                title: format!("{title} over the reference image"),
                value_label: if name.starts_with("error") {
                    "DIC - FE (px)".into()
                } else {
                    "displacement (px)".into()
                },
                diverging,
                ..Default::default()
            },
        )
        .with_context(|| format!("cannot write {}", p.display()))?;
    }
    timings.total = t0.elapsed().as_secs_f64();
    let e = exp.error;
    let summary = SimSummary {
        command: "us-sim",
        version: env!("CARGO_PKG_VERSION"),
        test: test.name(),
        elements: model.mesh.elements.len(),
        probe,
        transducer: opts.transducer,
        psf: opts.transducer.psf(),
        scanner: opts.scanner,
        acoustics,
        scatterers: exp.phantom_scatterers,
        image_px: (w, h),
        roi_pixels: exp.roi.iter().filter(|&&b| b).count(),
        dic_steps: exp.steps,
        dic_elements: exp.dic.mesh.n_elements(),
        dic_converged: exp.dic.converged,
        dic_iterations: exp.dic.iterations,
        dic_residual_rms: exp.dic.residual_rms,
        error: e,
        max_fe_displacement_mm: umax,
        timings_s: timings,
    };
    settings::write_json(&out.join("summary.json"), &summary)?;
    if !quiet {
        eprintln!(
            "images {w} x {h} px ({} scatterers) rendered in {:.2} + {:.2} s; DIC {} elements in {:.2} s; \
             error over {} points in tissue: RMS ({:.3}, {:.3}) px = ({:.4}, {:.4}) mm, max ({:.2}, {:.2}) px \
             for displacements up to {:.1} px -> {}",
            exp.phantom_scatterers,
            exp.reference.seconds,
            exp.deformed.seconds,
            exp.dic.mesh.n_elements(),
            exp.dic.timings.total_s,
            e.points,
            e.rms_px[0],
            e.rms_px[1],
            e.rms_mm[0],
            e.rms_mm[1],
            e.max_abs_px[0],
            e.max_abs_px[1],
            e.max_true_px,
            out.join("measured.csv").display()
        );
    }
    Ok(())
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

/// `femu us-scan`: images of the unloaded built-in thigh over a grid of settings, with the
/// manifest that `us-settings` and `us-noise` read.
pub fn scan(args: &UsScanArgs, quiet: bool) -> Result<()> {
    let t0 = Instant::now();
    if args.repeats == 0 || args.subjects == 0 {
        bail!("--repeats and --subjects must be at least 1");
    }
    let n = args.frequencies.len()
        * args.gains.len()
        * args.dynamics.len()
        * args.repeats
        * args.subjects;
    if n > 2000 {
        bail!("{n} images requested: at most 2000");
    }
    let (plan, probe_s, us) = read_study(args.study.as_deref(), Some(args.elements))?;
    std::fs::create_dir_all(&args.out)
        .with_context(|| format!("cannot create output folder {}", args.out.display()))?;
    let (model, skin) = crate::sensitivity_cmd::thigh_model(&plan)?;
    let probe = place_probe(&model.mesh, &skin, &probe_s)?;
    let bone = bone_faces(&model.mesh, &skin);
    let mut manifest = String::from("file,frequency_mhz,gain_db,dynamic_db,subject\n");
    for s in 0..args.subjects {
        let base = Phantom::generate(
            &model.mesh,
            &bone,
            &Acoustics::default(),
            &probe,
            3.0,
            us.seed.wrapping_add(1000 * s as u64),
        )?;
        let state = base.reference();
        // One phantom per acquisition, shared by every setting (the same frames re-displayed
        // with each setting would hide the setting's effect on the decorrelation; the seed
        // acquired each setting separately, so each setting gets its own frames).
        for &f in &args.frequencies {
            for &g in &args
                .dynamics
                .iter()
                .flat_map(|&d| args.gains.iter().map(move |&g| (g, d)))
                .collect::<Vec<_>>()
            {
                let (gain, dynamic) = g;
                let mut ph = base.clone();
                for r in 0..args.repeats {
                    if r > 0 {
                        ph = ph.decorrelated(
                            args.correlation,
                            us.seed
                                ^ (((s * 7919 + r) as u64) << 20)
                                ^ ((gain * 1e3) as u64)
                                ^ ((dynamic * 1e6) as u64),
                        )?;
                    }
                    let scanner = Scanner {
                        gain_db: gain,
                        dynamic_db: dynamic,
                        ..us.scanner()
                    };
                    let transducer = Transducer {
                        frequency_mhz: f,
                        ..us.transducer()
                    };
                    let frame = femu_ultrasound::render(
                        &ph,
                        &state,
                        &probe,
                        &transducer,
                        &scanner,
                        us.seed + (r as u64) * 31 + s as u64 * 7,
                    )?;
                    let name = format!(
                        "s{}_f{}_g{}_d{}_{:02}.png",
                        s + 1,
                        fmt_num(f),
                        fmt_num(gain),
                        fmt_num(dynamic),
                        r + 1
                    );
                    frame
                        .image
                        .save_png(&args.out.join(&name))
                        .with_context(|| {
                            format!("cannot write {}", args.out.join(&name).display())
                        })?;
                    manifest += &format!(
                        "{name},{},{},{},s{}\n",
                        fmt_num(f),
                        fmt_num(gain),
                        fmt_num(dynamic),
                        s + 1
                    );
                }
            }
        }
    }
    let mp = args.out.join("manifest.csv");
    std::fs::write(&mp, manifest).with_context(|| format!("cannot write {}", mp.display()))?;
    if !quiet {
        eprintln!(
            "{n} images in {:.1} s -> {}",
            t0.elapsed().as_secs_f64(),
            mp.display()
        );
    }
    Ok(())
}

/// Region options shared by us-settings and us-noise.
#[derive(Debug, Args)]
pub struct RegionArgs {
    /// Region of interest: a rectangle x0,y0,x1,y1 (pixels, corners) — leave burned-in text
    /// and scales out.
    #[arg(long, conflicts_with = "mask")]
    pub roi: Option<String>,
    /// Region of interest as a mask image (pixels brighter than half its maximum are inside).
    #[arg(long)]
    pub mask: Option<PathBuf>,
}

impl RegionArgs {
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
    std::fs::create_dir_all(&args.out)
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
    std::fs::create_dir_all(&args.out)
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
