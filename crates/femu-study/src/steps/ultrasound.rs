//! The simulated ultrasound experiment (`femu us-sim`, `femu us-scan`, and `[measurement]
//! source = "ultrasound"` of `femu run`): B-mode images of the thigh under the study's
//! `[probe]` and `[ultrasound]`, everything numerical in `femu-ultrasound`.

use crate::bail;
use crate::error::{Context, Result};
use crate::output::create_dir;
use crate::progress::Progress;
use crate::schema::{
    Geometry, ModelSpec, ProbeSection, Resolution, Study, UltrasoundSection, DEFAULT_ELEMENTS,
    DEFAULT_LABEL_SIZE_MM,
};
use crate::steps::sequence::ImageSequence;
use femu_dic::{Brightness, DicOptions, GreyImage};
use femu_identify::measured::{MeasuredField, MeasuredPoint};
use femu_identify::weighted::FieldCovariance;
use femu_mech::loading::{apply_loading, Loading, Side};
use femu_mech::{SolverOptions, StaticSolver};
use femu_ultrasound::manifest::fmt_num;
use femu_ultrasound::settings;
use femu_ultrasound::{experiment, probe, Acoustics, Phantom, Probe, Scanner, Transducer};
use serde::{Deserialize, Serialize};
use std::path::Path;
use std::time::Instant;

/// The options of `femu us-sim` beyond the study.
#[derive(Debug, Clone)]
pub struct SimOptions {
    /// DIC element size (px).
    pub element: usize,
    /// DIC regularization length (px).
    pub regularization: Option<f64>,
    /// Spacing of the measured grid (px).
    pub grid_step: f64,
    /// DIC pyramid levels above the full image.
    pub levels: usize,
    /// Load steps imaged and correlated in succession (incremental DIC).
    pub steps: usize,
}

impl Default for SimOptions {
    fn default() -> Self {
        SimOptions {
            element: 16,
            regularization: None,
            grid_step: 16.0,
            levels: 3,
            steps: 4,
        }
    }
}

/// The options of `femu us-scan` beyond the study.
#[derive(Debug, Clone)]
pub struct ScanOptions {
    pub frequencies: Vec<f64>,
    pub gains: Vec<f64>,
    pub dynamics: Vec<f64>,
    pub repeats: usize,
    pub correlation: f64,
    pub subjects: usize,
}

/// The probe of `[probe]` on the skin.
pub fn place_probe(
    mesh: &femu_mesh::Mesh,
    skin: &[(usize, usize)],
    section: &ProbeSection,
) -> Result<Probe> {
    let side = Side::parse(&section.side).map_err(|e| crate::input!("[probe] side: {e}"))?;
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
pub fn bone_faces(mesh: &femu_mesh::Mesh, skin: &[(usize, usize)]) -> Vec<(usize, usize)> {
    let skin: std::collections::HashSet<_> = skin.iter().copied().collect();
    mesh.boundary_faces()
        .into_iter()
        .filter(|f| !skin.contains(f))
        .collect()
}

/// The model the images are rendered from: `spec` with its element size divided by `refine`
/// (`refine²` times the elements of the built-in thigh), so that the identification does not
/// fit the very mesh that made its data. A deck cannot be refined here: its own mesh is used,
/// with a note saying so.
pub fn render_model_spec(spec: &ModelSpec, refine: usize) -> (ModelSpec, Option<String>) {
    let r = refine.max(1);
    let resolution = match (&spec.geometry, spec.resolution) {
        (Geometry::Deck(_), _) => {
            let note = (r > 1).then(|| {
                format!(
                    "[ultrasound] render_refine = {r}: a deck's mesh cannot be refined here; the images are rendered from the deck's own mesh, the one identified (an inverse crime: errors will look smaller than on real images)"
                )
            });
            return (spec.clone(), note);
        }
        (_, Resolution::Elements(n)) => Resolution::Elements(n * r * r),
        (_, Resolution::SizeMm(h)) => Resolution::SizeMm(h / r as f64),
        (Geometry::Thigh(_), Resolution::Default) => Resolution::Elements(DEFAULT_ELEMENTS * r * r),
        (_, Resolution::Default) => Resolution::SizeMm(DEFAULT_LABEL_SIZE_MM / r as f64),
    };
    (
        ModelSpec {
            resolution,
            ..spec.clone()
        },
        None,
    )
}

/// `summary.json` of `femu us-sim`.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct SimSummary {
    pub command: String,
    pub version: String,
    pub test: String,
    pub elements: usize,
    pub probe: Probe,
    pub transducer: Transducer,
    pub psf: femu_ultrasound::Psf,
    pub scanner: Scanner,
    pub acoustics: Acoustics,
    pub scatterers: usize,
    pub image_px: (usize, usize),
    pub roi_pixels: usize,
    pub dic_steps: usize,
    pub dic_elements: usize,
    pub dic_converged: bool,
    pub dic_iterations: usize,
    pub dic_residual_rms: f64,
    pub error: experiment::FieldError,
    pub max_fe_displacement_mm: f64,
    pub timings_s: SimTimings,
    /// Elements of the mesh the images were rendered from (`[ultrasound] render_refine`
    /// times finer than `[model]`; absent in summaries written before it existed).
    #[serde(default)]
    pub render_elements: usize,
    #[serde(default = "one")]
    pub render_refine: usize,
    /// Fraction of the scatterers renewed per load step.
    #[serde(default)]
    pub decorrelation: f64,
    /// The image sequence: one file per state, the unloaded one first (`frame_00.png`, ...),
    /// and the load fraction of each loaded frame.
    #[serde(default)]
    pub frames: Vec<String>,
    #[serde(default)]
    pub load_fractions: Vec<f64>,
}

fn one() -> usize {
    1
}

/// Where the time of `femu us-sim` went (s).
#[derive(Debug, Clone, Serialize, Deserialize, Default)]
pub struct SimTimings {
    pub mesh_and_solve: f64,
    pub phantom: f64,
    pub render_reference: f64,
    pub render_deformed: f64,
    /// Every DIC increment.
    pub dic: f64,
    /// The measured field's covariance (`measured_covariance.mtx`).
    #[serde(default)]
    pub covariance: f64,
    pub total: f64,
}

/// What the simulated experiment needs of a study: the model the images are rendered from
/// (refined by `[ultrasound] render_refine`), the test imaged, the probe and the acquisition.
#[derive(Debug, Clone, Copy)]
pub struct SimInputs<'a> {
    pub model: &'a ModelSpec,
    pub test: &'a Loading,
    pub probe: &'a ProbeSection,
    pub ultrasound: &'a UltrasoundSection,
}

impl<'a> SimInputs<'a> {
    /// The study's identification test under its `[probe]` (what `femu us-sim` images).
    pub fn of(study: &'a Study) -> SimInputs<'a> {
        SimInputs {
            model: &study.model,
            test: &study.identification_test().loading,
            probe: &study.probe,
            ultrasound: &study.ultrasound,
        }
    }
}

/// What the simulated experiment made, for the steps after it: its summary (`summary.json`),
/// the image sequence and the DIC's measured field with its covariance, each as its file holds
/// it (the frames 8-bit as `frame_KK.png`, the field and covariance at the ten significant
/// digits of `measured.csv` and `measured_covariance.mtx`), so that what is fitted from memory
/// is what a user fits from the files.
#[derive(Debug, Clone)]
pub struct SimulatedImages {
    pub summary: SimSummary,
    /// The unloaded frame first, then one per load step.
    pub frames: Vec<GreyImage>,
    /// `measured.csv`: the composed incremental DIC field (model frame, mm).
    pub measured: MeasuredField,
    /// `measured_covariance.mtx`: the covariance of its components (mm²).
    pub covariance: FieldCovariance,
}

impl SimulatedImages {
    /// The image sequence and where it lies in the model (the probe's image frame).
    pub fn sequence(&self) -> ImageSequence {
        self.summary.sequence(self.frames.clone())
    }
}

impl SimSummary {
    /// The experiment's image sequence of `frames` (its frames, as [`SimSummary::frames`] names
    /// them) and where it lies in the model (the probe's image frame).
    pub fn sequence(&self, frames: Vec<GreyImage>) -> ImageSequence {
        ImageSequence {
            frames,
            load_fractions: self.load_fractions.clone(),
            frame: super::sequence::image_frame(&self.probe),
            source: format!(
                "{} B-mode frames simulated at {} MHz from {} elements (render_refine {}, decorrelation {})",
                self.frames.len(),
                self.transducer.frequency_mhz,
                self.render_elements,
                self.render_refine,
                self.decorrelation
            ),
        }
    }
}

/// `v` as a file written with `{:.9e}` holds it (`measured.csv`, `measured_covariance.mtx`).
fn as_written(v: f64) -> f64 {
    format!("{v:.9e}").parse().unwrap_or(v)
}

/// `femu us-sim`: the virtual experiment with images of `inputs`' test, written into `out`
/// (`ref.png`, `def.png`, `frame_KK.png`, `measured.csv`, `measured_covariance.mtx`,
/// `true_field.csv`, maps, `summary.json`) and returned.
pub fn sim(
    inputs: SimInputs,
    args: &SimOptions,
    out: &Path,
    progress: &dyn Progress,
) -> Result<SimulatedImages> {
    let t0 = Instant::now();
    let us = inputs.ultrasound;
    create_dir(out)?;
    if args.steps == 0 || args.steps > 20 {
        bail!("--steps {} must be in [1, 20]", args.steps);
    }
    let (render_spec, render_note) = render_model_spec(inputs.model, us.render_refine);
    if let Some(note) = &render_note {
        progress.warn(note);
    }
    let built = crate::model::build(&render_spec)?;
    let solved = LoadSteps::solve(&built, inputs.test, args.steps)?;
    let u = solved.stages.last().context("no load step")?;
    let umax = u.chunks(2).map(|c| c[0].hypot(c[1])).fold(0.0, f64::max);
    let mut timings = SimTimings {
        mesh_and_solve: t0.elapsed().as_secs_f64(),
        ..Default::default()
    };
    progress.note(&format!(
        "{}: images rendered from {} elements (render_refine {}) solved in {:.2} s, largest displacement {:.3} mm",
        inputs.test.name(),
        solved.model.mesh.elements.len(),
        us.render_refine,
        timings.mesh_and_solve,
        umax
    ));
    let probe = place_probe(&solved.model.mesh, &solved.skin, inputs.probe)?;
    let t = Instant::now();
    let acoustics = Acoustics::default();
    let bone = bone_faces(&solved.model.mesh, &solved.skin);
    let phantom = Phantom::generate(
        &solved.model.mesh,
        &bone,
        &acoustics,
        &probe,
        3.0 + umax,
        us.seed,
    )?;
    timings.phantom = t.elapsed().as_secs_f64();
    let opts = experiment_options(us, args);
    let exp = experiment::run_incremental(&phantom, &solved.stages, &probe, &opts)?;
    timings.render_reference = exp.reference.seconds;
    timings.render_deformed = exp.deformed.seconds;
    // Every increment's correlation (the first alone was reported before: 1/4 of the time).
    timings.dic = exp.increments.iter().map(|d| d.timings.total_s).sum();
    let frames = write_images(&exp, out)?;
    let measured = write_measured(&exp, &probe, inputs, out)?;
    let t = Instant::now();
    let covariance = write_covariance(&exp, &probe, out)?;
    timings.covariance = t.elapsed().as_secs_f64();
    write_maps(&exp, &phantom, u, &probe, args.grid_step, out)?;
    timings.total = t0.elapsed().as_secs_f64();
    let summary = SimSummary {
        command: "us-sim".into(),
        version: env!("CARGO_PKG_VERSION").into(),
        test: inputs.test.name(),
        elements: solved.model.mesh.elements.len(),
        probe,
        transducer: opts.transducer,
        psf: opts.transducer.psf(),
        scanner: opts.scanner,
        acoustics,
        scatterers: exp.phantom_scatterers,
        image_px: (exp.reference.width, exp.reference.height),
        roi_pixels: exp.roi.iter().filter(|&&b| b).count(),
        dic_steps: exp.steps,
        dic_elements: exp.dic.mesh.n_elements(),
        dic_converged: exp.dic.converged,
        dic_iterations: exp.dic.iterations,
        dic_residual_rms: exp.dic.residual_rms,
        error: exp.error,
        max_fe_displacement_mm: umax,
        timings_s: timings,
        render_elements: solved.model.mesh.elements.len(),
        render_refine: us.render_refine,
        decorrelation: us.decorrelation,
        frames: frame_names(exp.frames.len()),
        load_fractions: solved.fractions,
    };
    settings::write_json(&out.join("summary.json"), &summary)?;
    note_experiment(&exp, &out.join("measured.csv"), progress);
    Ok(SimulatedImages {
        summary,
        frames,
        measured,
        covariance,
    })
}

/// The test solved at each of `steps` equal fractions of its load on the render model, each
/// from the one before (the loaded state last).
struct LoadSteps {
    /// The render model under the whole load, and its skin faces.
    model: femu_mech::Model,
    skin: Vec<(usize, usize)>,
    /// `k / steps` for `k = 1..=steps`.
    fractions: Vec<f64>,
    /// The nodal displacement of each fraction.
    stages: Vec<Vec<f64>>,
}

impl LoadSteps {
    fn solve(built: &crate::model::StudyModel, test: &Loading, steps: usize) -> Result<LoadSteps> {
        let fractions: Vec<f64> = (1..=steps).map(|k| k as f64 / steps as f64).collect();
        let mut stages: Vec<Vec<f64>> = Vec::new();
        let mut model = None;
        let mut skin = Vec::new();
        for (k, &fraction) in fractions.iter().enumerate() {
            let (mut m, sk) = (built.model.clone(), built.skin.clone());
            let load = test.scaled(fraction);
            apply_loading(&mut m, &sk, &load).with_context(|| format!("test {}", test.name()))?;
            let mut solver = StaticSolver::new(&m, SolverOptions::default())?;
            let sol = solver
                .solve_with(&m, stages.last().map(|v| v.as_slice()), &mut |_| {})
                .map_err(|e| {
                    crate::input!("test {} at {}/{steps} of the load: {e}", test.name(), k + 1)
                })?;
            stages.push(sol.u[..2 * m.node_count()].to_vec());
            skin = sk;
            model = Some(m);
        }
        Ok(LoadSteps {
            model: model.context("no load step")?,
            skin,
            fractions,
            stages,
        })
    }
}

/// The acquisition of `[ultrasound]` and the incremental DIC of `args`.
fn experiment_options(us: &UltrasoundSection, args: &SimOptions) -> experiment::ExperimentOptions {
    experiment::ExperimentOptions {
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
        decorrelation: us.decorrelation,
        ..Default::default()
    }
}

/// The file of each frame of a sequence of `n`: `frame_00.png` (unloaded), `frame_01.png`, ...
fn frame_names(n: usize) -> Vec<String> {
    (0..n).map(|k| format!("frame_{k:02}.png")).collect()
}

/// Writes `ref.png`, `def.png` and the sequence `frame_KK.png`; returns the sequence (8-bit
/// already: what the files hold).
fn write_images(exp: &experiment::Experiment, out: &Path) -> Result<Vec<GreyImage>> {
    let save = |img: &GreyImage, name: &str| -> Result<()> {
        img.save_png(&out.join(name))
            .with_context(|| format!("cannot write {}", out.join(name).display()))
    };
    save(&exp.reference.image, "ref.png")?;
    save(&exp.deformed.image, "def.png")?;
    for (img, name) in exp.frames.iter().zip(frame_names(exp.frames.len())) {
        save(img, &name)?;
    }
    Ok(exp.frames.clone())
}

/// Writes the DIC's field (`measured.csv`) and the FE field at its points (`true_field.csv`);
/// returns the DIC's field as `measured.csv` holds it.
fn write_measured(
    exp: &experiment::Experiment,
    probe: &Probe,
    inputs: SimInputs,
    out: &Path,
) -> Result<MeasuredField> {
    let us = inputs.ultrasound;
    let comments = vec![
        format!(
            "femu us-sim {}: DIC of simulated B-mode images, {} test, {} MHz, gain {} dB, dynamic {} dB",
            env!("CARGO_PKG_VERSION"),
            inputs.test.name(),
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
    Ok(MeasuredField {
        points: exp
            .points
            .iter()
            .map(|p| MeasuredPoint {
                x: p.x_mm.map(as_written),
                u: p.dic_mm.map(as_written),
                weight: [p.w, p.w],
            })
            .collect(),
        comments,
    })
}

/// Writes the composed field's covariance (`measured_covariance.mtx`, which weighted FEMU
/// reads beside `measured.csv`); returns it as the file holds it (its lower triangle, mirrored).
fn write_covariance(
    exp: &experiment::Experiment,
    probe: &Probe,
    out: &Path,
) -> Result<FieldCovariance> {
    let all: Vec<usize> = (0..exp.points.len()).collect();
    let cov = FieldCovariance::new(all.len(), experiment::grid_covariance(exp, &all, probe)?)?;
    let cov_path = out.join("measured_covariance.mtx");
    cov.write_mtx(
        &cov_path,
        &[
            format!(
                "femu us-sim {}: covariance of measured.csv's components (ux, uy per point, in its order), mm^2, model frame",
                env!("CARGO_PKG_VERSION")
            ),
            "sum over the DIC increments of N A^-1 M_sigma A^-1 N^T at each point's position in that increment (femu_dic::quality)".into(),
        ],
    )
    .with_context(|| format!("cannot write {}", cov_path.display()))?;
    let m = 2 * cov.points;
    let mut values = vec![0.0; m * m];
    for j in 0..m {
        for i in j..m {
            let v = as_written(cov.values[i * m + j]);
            values[i * m + j] = v;
            values[j * m + i] = v;
        }
    }
    Ok(FieldCovariance::new(cov.points, values)?)
}

/// The DIC's and the FE displacement and their difference over the reference image
/// (`ux_true.png`, `uy_true.png`, `ux_dic.png`, `uy_dic.png`, `error_ux.png`, `error_uy.png`).
fn write_maps(
    exp: &experiment::Experiment,
    phantom: &Phantom,
    u: &[f64],
    probe: &Probe,
    grid_step: f64,
    out: &Path,
) -> Result<()> {
    let maps = experiment::pixel_maps(exp, phantom, u, probe, grid_step);
    let (w, h) = (exp.reference.width, exp.reference.height);
    let grey = &exp.reference.image.data;
    let err: [Vec<f64>; 2] = [0, 1].map(|c| {
        maps[c]
            .iter()
            .zip(&maps[c + 2])
            .map(|(d, t)| d - t)
            .collect()
    });
    let plots: [(&str, &str, &Vec<f64>); 6] = [
        ("ux_true.png", "FE displacement ux (lateral)", &maps[2]),
        ("uy_true.png", "FE displacement uy (depth, down)", &maps[3]),
        ("ux_dic.png", "DIC displacement ux (lateral)", &maps[0]),
        ("uy_dic.png", "DIC displacement uy (depth, down)", &maps[1]),
        ("error_ux.png", "DIC - FE, ux", &err[0]),
        ("error_uy.png", "DIC - FE, uy", &err[1]),
    ];
    for (name, title, values) in plots {
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
                diverging: true,
                ..Default::default()
            },
        )
        .with_context(|| format!("cannot write {}", p.display()))?;
    }
    Ok(())
}

/// The experiment's images, DIC and error for the user.
fn note_experiment(exp: &experiment::Experiment, measured: &Path, progress: &dyn Progress) {
    let e = &exp.error;
    progress.note(&format!(
        "images {} x {} px ({} scatterers) rendered in {:.2} + {:.2} s; DIC {} elements in {:.2} s; \
         error over {} points in tissue: RMS ({:.3}, {:.3}) px = ({:.4}, {:.4}) mm, max ({:.2}, {:.2}) px \
         for displacements up to {:.1} px -> {}",
        exp.reference.width,
        exp.reference.height,
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
        measured.display()
    ));
}

/// `femu us-scan`: images of the unloaded built-in thigh over a grid of settings, with the
/// manifest that `us-settings` and `us-noise` read.
pub fn scan(study: &Study, args: &ScanOptions, out: &Path, progress: &dyn Progress) -> Result<()> {
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
    let (probe_s, us) = (&study.probe, &study.ultrasound);
    create_dir(out)?;
    let built = crate::model::build(&study.model)?;
    let (model, skin) = (&built.model, &built.skin);
    let probe = place_probe(&model.mesh, skin, probe_s)?;
    let bone = bone_faces(&model.mesh, skin);
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
                let setting = Setting {
                    subject: s,
                    frequency_mhz: f,
                    gain_db: g.0,
                    dynamic_db: g.1,
                };
                manifest += &setting.acquire(&base, &state, &probe, us, args, out)?;
            }
        }
    }
    let mp = out.join("manifest.csv");
    femu_mesh::atomic::write(&mp, manifest)
        .with_context(|| format!("cannot write {}", mp.display()))?;
    progress.note(&format!(
        "{n} images in {:.1} s -> {}",
        t0.elapsed().as_secs_f64(),
        mp.display()
    ));
    Ok(())
}

/// One setting of `femu us-scan` for one subject.
struct Setting {
    subject: usize,
    frequency_mhz: f64,
    gain_db: f64,
    dynamic_db: f64,
}

impl Setting {
    /// `args.repeats` acquisitions of `base` in `state` with this setting, each decorrelated
    /// from the one before by `args.correlation`, written into `out`; returns their lines of
    /// the manifest.
    fn acquire(
        &self,
        base: &Phantom,
        state: &femu_ultrasound::PhantomState,
        probe: &Probe,
        us: &UltrasoundSection,
        args: &ScanOptions,
        out: &Path,
    ) -> Result<String> {
        let (s, f, gain, dynamic) = (
            self.subject,
            self.frequency_mhz,
            self.gain_db,
            self.dynamic_db,
        );
        let mut lines = String::new();
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
                state,
                probe,
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
                .save_png(&out.join(&name))
                .with_context(|| format!("cannot write {}", out.join(&name).display()))?;
            lines += &format!(
                "{name},{},{},{},s{}\n",
                fmt_num(f),
                fmt_num(gain),
                fmt_num(dynamic),
                s + 1
            );
        }
        Ok(lines)
    }
}
