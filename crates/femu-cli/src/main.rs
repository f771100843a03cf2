//! `femu` — finite element model updating of thigh tissue: the command line.
//!
//! Thin glue: parse arguments, call the library crates, write the output folder, map errors to
//! messages and a non-zero exit code. Nothing numerical lives here.

// The commands' and options' doc comments are their `--help` text, where `[probe]`, `[thigh]`
// and the like name tables of a study file, not items of this crate.
#![allow(rustdoc::broken_intra_doc_links)]

mod batch_cmd;
mod bench;
mod convergence_cmd;
mod dic_cmd;
mod dic_seq;
mod huge_pages;
mod mesh_cmd;
mod progress;
mod us_cmd;

use clap::{Parser, Subcommand, ValueEnum};
use femu_study::steps::{identify, run, sensitivity, solve};
use progress::Terminal;
use std::path::PathBuf;
use std::process::ExitCode;

#[global_allocator]
static ALLOCATOR: huge_pages::HugePageAlloc = huge_pages::HugePageAlloc;

#[derive(Parser, Debug)]
#[command(
    name = "femu",
    version,
    about = "Finite element model updating of thigh muscles and fat (plane-strain Neo-Hookean FE, DIC, identification)"
)]
struct Cli {
    #[command(subcommand)]
    command: Command,
    /// Print nothing but errors.
    #[arg(long, short, global = true)]
    quiet: bool,
}

/// Element formulation for quadrilaterals of generated or Gmsh meshes.
#[derive(Debug, Clone, Copy, ValueEnum)]
pub enum QuadElement {
    /// Fully integrated 4-node quad (2x2 Gauss).
    Cpe4,
    /// 4-node quad, hybrid with constant pressure (mean dilatation).
    Cpe4h,
}

impl From<QuadElement> for femu_study::schema::QuadElement {
    fn from(e: QuadElement) -> Self {
        match e {
            QuadElement::Cpe4 => femu_study::schema::QuadElement::Cpe4,
            QuadElement::Cpe4h => femu_study::schema::QuadElement::Cpe4h,
        }
    }
}

#[derive(Subcommand, Debug)]
enum Command {
    /// The demo, no input needed: the seed's numerical example end to end on the built-in thigh
    /// (sensitivity of the three tests, the compression test measured on a 64 x 64 grid with the
    /// seed's noise, identification ungrouped and grouped from five starts, Fig. 9 errors) and
    /// its report (report.html) — about 5 s on two cores; --full for the paper scale.
    Demo {
        /// Output folder.
        #[arg(long, default_value = "out/demo")]
        out: PathBuf,
        /// The paper scale: 25 000 elements (several minutes).
        #[arg(long)]
        full: bool,
        /// Target number of elements of the built-in thigh (default 4 000; 25 000 with --full).
        #[arg(long)]
        elements: Option<usize>,
    },
    /// Run a study file end to end: model -> forward tests -> sensitivity and test ranking ->
    /// measurement (virtual or a measured field) -> identification -> report.html and
    /// summary.json. Each step writes its own sub-folder as soon as it finishes.
    Run {
        /// Study file (TOML; `femu init` writes a commented example).
        study: PathBuf,
        /// Output folder.
        #[arg(long, default_value = "out/run")]
        out: PathBuf,
    },
    /// Write a commented example study file (every key with its default).
    Init {
        /// The file to write.
        #[arg(default_value = "study.toml")]
        path: PathBuf,
        /// Overwrite an existing file.
        #[arg(long)]
        force: bool,
    },
    /// (Re)write the HTML report of a `femu run` or `femu demo` output folder.
    Report {
        /// The output folder of a run.
        dir: PathBuf,
    },
    /// The seed's loading tests on the built-in parametric thigh with the Table 1 parameters,
    /// femur fixed — contention (20 mmHg on the skin) and compression (rigid plate, 0.1 N/mm,
    /// anterior) by default; one output folder per test.
    Forward {
        /// Output folder.
        #[arg(long, default_value = "out/forward")]
        out: PathBuf,
        /// Element formulation.
        #[arg(long, value_enum, default_value = "cpe4h")]
        element: QuadElement,
        /// Target number of elements of the built-in thigh (the seed's paper scale is 25 000).
        #[arg(long, default_value_t = 6000)]
        elements: usize,
        /// Loading tests, comma-separated: contention, compression, indentation (the seed's
        /// values: 20 mmHg; plate 0.1 N/mm anterior; indenter R = 10 mm, 0.1 N/mm anterior).
        #[arg(long, value_delimiter = ',', default_value = "contention,compression")]
        tests: Vec<String>,
    },
    /// Solve an Abaqus/CalculiX deck (.inp; plane-strain CPE4/CPE4H/CPE3 or 3D
    /// C3D8/C3D8H/C3D4/C3D10 elements), or a Gmsh mesh (.msh) with a study file naming its
    /// materials and loads.
    Solve {
        /// The deck (.inp) or Gmsh mesh (.msh 4.1). A deck whose elements are C3D* is solved in
        /// 3D (displacements.csv gains z and uz).
        input: PathBuf,
        /// Study file (TOML) for a .msh input: materials per physical surface, fixed curves,
        /// pressures (the guide: docs/guide, "A deck from another mesher").
        #[arg(long)]
        study: Option<PathBuf>,
        /// Output folder (created if absent).
        #[arg(long, default_value = "out/solve")]
        out: PathBuf,
        /// Print the Newton table (residual and energy norms per iteration).
        #[arg(long)]
        newton_table: bool,
        /// Skip the pictures (deformed shape with LE11, contact pressure, force–travel).
        #[arg(long)]
        no_figures: bool,
    },
    /// Benchmark: the paper-scale contention problem on the built-in thigh (about 25 000 CPE4 quads) solved
    /// by femu and by CalculiX (`ccx`) on the same deck, side by side; reports the time ratio,
    /// the displacement agreement and femu's peak memory.
    Bench {
        /// Output folder.
        #[arg(long, default_value = "out/bench")]
        out: PathBuf,
        /// Target number of elements of the built-in thigh (25 000: the seed's scale).
        #[arg(long, default_value_t = 25_000)]
        elements: usize,
        /// Repetitions of each solver (the best and the median are reported).
        #[arg(long, default_value_t = 3)]
        repeat: usize,
        /// Skip CalculiX.
        #[arg(long)]
        no_ccx: bool,
    },
    /// Exact sensitivities of the displacement field to C10 and D of every tissue for each
    /// loading test (seed Eq. 3, Fig. 8), and the identifiability of the parameters from the
    /// measurement grid (Fisher information, predicted standard deviations, test ranking).
    Sensitivity {
        /// Study file (TOML; `femu init` writes one with every key). Without it: the built-in
        /// thigh, Table 1, the seed's three tests, a 64 x 64 grid over the thigh, sigma =
        /// 1.76e-2 mm.
        study: Option<PathBuf>,
        /// Output folder.
        #[arg(long, default_value = "out/sensitivity")]
        out: PathBuf,
        /// Target number of elements of the built-in thigh (overrides the study).
        #[arg(long)]
        elements: Option<usize>,
        /// Also compute central finite differences (two extra solves per parameter) and report
        /// their difference from the direct differentiation.
        #[arg(long)]
        fd_check: bool,
        /// Relative parameter step of the finite differences (the seed's 5e-2 %).
        #[arg(long, default_value_t = 5e-4)]
        fd_step: f64,
        /// Skip the pictures.
        #[arg(long)]
        no_figures: bool,
    },
    /// The virtual experiment (seed §2.4.1): solve the study's identification test with the
    /// reference parameters, project the field on the grid, add seeded Gaussian noise; writes
    /// measured.csv.
    Synth {
        /// Study file (TOML; `femu init` writes one with every key). Without it: built-in thigh,
        /// Table 1, compression.
        study: Option<PathBuf>,
        #[arg(long, default_value = "out/synth")]
        out: PathBuf,
        /// Target number of elements of the built-in thigh (overrides the study).
        #[arg(long)]
        elements: Option<usize>,
    },
    /// Identify C10 and D of the tissues from a measured field (FEMU): Levenberg–Marquardt with
    /// the exact Jacobian from Latin-hypercube starts; a virtual experiment when no --measured
    /// field is given (with --repeat noise realizations: the seed's Fig. 9 with error bars).
    Identify {
        /// Study file (TOML; `femu init` writes one with every key).
        study: Option<PathBuf>,
        #[arg(long, default_value = "out/identify")]
        out: PathBuf,
        /// Measured field (CSV x,y,ux,uy[,sx,sy][,w] in the model frame, mm).
        #[arg(long)]
        measured: Option<PathBuf>,
        /// Target number of elements of the built-in thigh (overrides the study).
        #[arg(long)]
        elements: Option<usize>,
        /// Noise realizations of the virtual experiment (overrides the study).
        #[arg(long)]
        repeat: Option<usize>,
        /// Latin-hypercube starts (overrides the study).
        #[arg(long)]
        starts: Option<usize>,
    },
    /// Design of the experiment: the study's tests seen through probe windows on each side of
    /// the thigh ([design]: tests x sides x window sizes, with the study's noise), alone and
    /// combined, ranked by the predicted parameter sd (A- and D-optimal); which parameters
    /// each design can and cannot identify; designs.csv, figures, report.html.
    Design {
        /// Study file (TOML; `femu init` writes one with every key). Without it: the built-in
        /// thigh, the seed's three tests, four sides, 40 x 40 and 60 x 40 mm windows, sigma =
        /// 1.76e-2 mm.
        study: Option<PathBuf>,
        #[arg(long, default_value = "out/design")]
        out: PathBuf,
        /// Target number of elements of the built-in thigh (overrides the study).
        #[arg(long)]
        elements: Option<usize>,
    },
    /// Build a thigh model: `mesh thigh` (the built-in parametric thigh) or `mesh labels IMAGE`
    /// (a segmented MRI slice); writes mesh.inp, mesh.vtu, regions.png, quality.csv/json and
    /// summary.json.
    Mesh {
        #[command(subcommand)]
        what: mesh_cmd::MeshCommand,
    },
    /// Mesh and element validation (seed §2.1.2.1): the study's loading test on a sequence of
    /// meshes of the built-in thigh per element type, compared with the finest at the DIC grid
    /// points; table, log-log plot with rates, the recommended mesh, the locking check.
    Convergence {
        /// Study file (TOML; see the femu-convergence docs). Without it: contention, Table 1,
        /// CPE4H/CPE4/CPE3, 1 500 to 50 000 elements, tolerance 1e-4 mm, D / 1000 for locking.
        study: Option<PathBuf>,
        /// Output folder.
        #[arg(long, default_value = "out/convergence")]
        out: PathBuf,
    },
    /// Global finite-element DIC (Q4) between a reference and a deformed image (PNG, TIFF,
    /// DICOM): field.csv (mm, model frame), nodes/elements CSV, VTU, PNG maps, summary.json.
    Dic(dic_cmd::DicArgs),
    /// DIC random error: correlates successive images of unloaded tissue and reports the
    /// standard deviation of ux and uy per pair (CSV, box plot).
    DicNoise(dic_cmd::DicNoiseArgs),
    /// DIC self-consistency on a sequence: forward-backward, composition (and repeated
    /// correlation of unloaded frames), per depth band, with the options femu dic chooses.
    DicCheck(dic_cmd::DicCheckArgs),
    /// Virtual experiment with images: simulated B-mode images of the unloaded and loaded
    /// thigh (same scatterers moved by the FE field), DIC, comparison with the FE field;
    /// writes ref.png, def.png, measured.csv (for identify --measured), maps, summary.json.
    UsSim(us_cmd::UsSimArgs),
    /// Simulated B-mode images of the unloaded built-in thigh over a grid of frequencies,
    /// gains, dynamic ranges and repeated acquisitions, with their manifest.csv.
    UsScan(us_cmd::UsScanArgs),
    /// Scanner settings from grey-level histograms (seed §2.2, Figs. 4–6): saturation and
    /// spread per image, the optimal gain per dynamic range, texture against depth.
    UsSettings(us_cmd::UsSettingsArgs),
    /// DIC random error of repeated acquisitions per setting, paired t-tests between settings,
    /// the recommended setting (seed §3.1.3, Fig. 7).
    UsNoise(us_cmd::UsNoiseArgs),
    /// Population studies: many cases (subjects, slices, sessions, seeds) of one template study
    /// run here or as a Slurm job array, their state, their results gathered (femu batch
    /// run|status|collect).
    Batch {
        #[command(subcommand)]
        what: batch_cmd::BatchCommand,
    },
}

/// The named demo tests.
fn demo_tests(names: &[String]) -> anyhow::Result<Vec<femu_mech::loading::Loading>> {
    use femu_mech::loading::Loading;
    names
        .iter()
        .map(|n| match n.trim() {
            "contention" => Ok(Loading::seed_contention()),
            "compression" => Ok(Loading::seed_compression()),
            "indentation" => Ok(Loading::anterior_indentation(0.1)),
            other => anyhow::bail!(
                "--tests: unknown test '{other}' (contention, compression, indentation)"
            ),
        })
        .collect()
}

/// `femu init PATH`: the commented example study.
fn init(path: &std::path::Path, force: bool, quiet: bool) -> anyhow::Result<()> {
    use anyhow::Context;
    if path.exists() && !force {
        anyhow::bail!(
            "{} exists: choose another name or pass --force to overwrite it",
            path.display()
        );
    }
    if let Some(dir) = path.parent().filter(|d| !d.as_os_str().is_empty()) {
        std::fs::create_dir_all(dir).with_context(|| format!("cannot create {}", dir.display()))?;
    }
    femu_mesh::atomic::write(path, femu_study::schema::EXAMPLE_STUDY)
        .with_context(|| format!("cannot write {}", path.display()))?;
    if !quiet {
        eprintln!(
            "wrote {} (the seed's numerical example, every key with its default); run it with: femu run {} --out out/study",
            path.display(),
            path.display()
        );
    }
    Ok(())
}

/// The study of a command (the file, or the defaults) with the command-line overrides.
fn study_with(
    study: Option<&std::path::Path>,
    elements: Option<usize>,
    repeat: Option<usize>,
    starts: Option<usize>,
) -> anyhow::Result<femu_study::Study> {
    let mut s = femu_study::load(study, elements)?;
    if let Some(r) = repeat {
        if !(1..=1000).contains(&r) {
            anyhow::bail!("--repeat must be in [1, 1000], got {r}");
        }
        s.identification.repeat = r;
    }
    if let Some(n) = starts {
        if !(1..=64).contains(&n) {
            anyhow::bail!("--starts must be in [1, 64], got {n}");
        }
        s.identification.starts = n;
    }
    Ok(s)
}

fn main() -> ExitCode {
    let cli = Cli::parse();
    progress::install_stop_handler();
    let quiet = cli.quiet;
    let progress = Terminal { quiet };
    let result = match cli.command {
        Command::Demo {
            out,
            full,
            elements,
        } => run::demo(&out, full, elements, &progress)
            .map(|_| ())
            .map_err(Into::into),
        Command::Run { study, out } => run::run(&study, &out, &progress)
            .map(|_| ())
            .map_err(Into::into),
        Command::Init { path, force } => init(&path, force, quiet),
        Command::Report { dir } => femu_study::report::write(&dir)
            .map(|p| {
                if !quiet {
                    eprintln!("wrote {}", p.display());
                }
            })
            .map_err(Into::into),
        Command::Forward {
            out,
            element,
            elements,
            tests,
        } => demo_tests(&tests).and_then(|t| {
            let kind = femu_study::schema::QuadElement::from(element).kind();
            Ok(solve::forward(&out, kind, elements, &t, &progress)?)
        }),
        Command::Solve {
            input,
            study,
            out,
            newton_table,
            no_figures,
        } => solve::solve_file(
            &input,
            study.as_deref(),
            &out,
            newton_table,
            !no_figures,
            &progress,
        )
        .map_err(Into::into),
        Command::Bench {
            out,
            elements,
            repeat,
            no_ccx,
        } => bench::run(&out, elements, repeat, !no_ccx, quiet),
        Command::Mesh { what } => mesh_cmd::run(what, quiet),
        Command::Synth {
            study,
            out,
            elements,
        } => study_with(study.as_deref(), elements, None, None)
            .and_then(|s| Ok(identify::synth(&s, &out, &progress)?)),
        Command::Identify {
            study,
            out,
            measured,
            elements,
            repeat,
            starts,
        } => study_with(study.as_deref(), elements, repeat, starts).and_then(|s| {
            identify::identify(&s, measured.as_deref(), &out, &progress)?;
            Ok(())
        }),
        Command::Sensitivity {
            study,
            out,
            elements,
            fd_check,
            fd_step,
            no_figures,
        } => study_with(study.as_deref(), elements, None, None).and_then(|s| {
            let options = sensitivity::SensitivityOptions {
                out,
                fd_check,
                fd_step,
                figures: !no_figures,
            };
            let summary = sensitivity::run(&s, &options, &progress)?;
            match summary.failed_tests.first() {
                None => Ok(()),
                Some((test, why)) => anyhow::bail!(
                    "{} of {} tests could not be solved (the others are written): {test}: {why}",
                    summary.failed_tests.len(),
                    summary.failed_tests.len() + summary.tests.len()
                ),
            }
        }),
        Command::Design {
            study,
            out,
            elements,
        } => study_with(study.as_deref(), elements, None, None).and_then(|s| {
            femu_study::commands::design(&s, &out, &progress)?;
            Ok(())
        }),
        Command::Convergence { study, out } => convergence_cmd::run(study.as_deref(), &out, quiet),
        Command::Dic(args) if args.then.is_empty() => dic_cmd::run(&args, quiet),
        Command::Dic(args) => dic_seq::run(&args, quiet),
        Command::DicNoise(args) => dic_cmd::run_noise(&args, quiet),
        Command::DicCheck(args) => dic_cmd::run_dic_check(&args, quiet),
        Command::UsSim(args) => us_cmd::sim(&args, quiet),
        Command::UsScan(args) => us_cmd::scan(&args, quiet),
        Command::UsSettings(args) => us_cmd::run_settings(&args, quiet),
        Command::UsNoise(args) => us_cmd::run_noise(&args, quiet),
        Command::Batch { what } => batch_cmd::run(what, &progress, quiet),
    };
    match result {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) if femu_study::progress::chain_is_interrupted(e.as_ref()) => {
            eprintln!("interrupted ({e:#}); what was finished is kept");
            ExitCode::from(130)
        }
        Err(e) => {
            eprintln!("error: {e:#}");
            ExitCode::FAILURE
        }
    }
}
