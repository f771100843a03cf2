//! `femu` — finite element model updating of thigh tissue: the command line.
//!
//! Thin glue: parse arguments, call the library crates, write the output folder, map errors to
//! messages and a non-zero exit code. Nothing numerical lives here.

mod bench;
mod run;
mod study;

use clap::{Parser, Subcommand, ValueEnum};
use std::path::PathBuf;
use std::process::ExitCode;

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

impl QuadElement {
    pub fn kind(self) -> femu_mesh::ElementKind {
        match self {
            QuadElement::Cpe4 => femu_mesh::ElementKind::Cpe4,
            QuadElement::Cpe4h => femu_mesh::ElementKind::Cpe4h,
        }
    }
}

#[derive(Subcommand, Debug)]
enum Command {
    /// The demo: the contention test (20 mmHg on the skin, femur fixed) on the built-in
    /// thigh-like cross-section with the seed's Table 1 parameters; writes the deck, the
    /// displacements, a ParaView file and a summary.
    Demo {
        /// Output folder.
        #[arg(long, default_value = "out/demo")]
        out: PathBuf,
        /// Element formulation.
        #[arg(long, value_enum, default_value = "cpe4h")]
        element: QuadElement,
        /// Angular divisions of the ring mesh (480 gives about 25 000 elements, the seed's size).
        #[arg(long, default_value_t = 240)]
        n_theta: usize,
    },
    /// Solve an Abaqus/CalculiX deck (.inp), or a Gmsh mesh (.msh) with a study file naming its
    /// materials and loads.
    Solve {
        /// The deck (.inp) or Gmsh mesh (.msh 4.1).
        input: PathBuf,
        /// Study file (TOML) for a .msh input: materials per physical surface, fixed curves,
        /// pressures (see README).
        #[arg(long)]
        study: Option<PathBuf>,
        /// Output folder (created if absent).
        #[arg(long, default_value = "out/solve")]
        out: PathBuf,
        /// Print the Newton table (residual and energy norms per iteration).
        #[arg(long)]
        newton_table: bool,
    },
    /// Benchmark: the paper-scale thigh-like contention problem (about 25 000 CPE4 quads) solved
    /// by femu and by CalculiX (`ccx`) on the same deck, side by side; reports the time ratio,
    /// the displacement agreement and femu's peak memory.
    Bench {
        /// Output folder.
        #[arg(long, default_value = "out/bench")]
        out: PathBuf,
        /// Angular divisions of the ring mesh (480: 24 960 elements).
        #[arg(long, default_value_t = 480)]
        n_theta: usize,
        /// Repetitions of each solver (the best and the median are reported).
        #[arg(long, default_value_t = 3)]
        repeat: usize,
        /// Skip CalculiX.
        #[arg(long)]
        no_ccx: bool,
    },
}

fn main() -> ExitCode {
    let cli = Cli::parse();
    let result = match cli.command {
        Command::Demo {
            out,
            element,
            n_theta,
        } => run::demo(&out, element, n_theta, cli.quiet),
        Command::Solve {
            input,
            study,
            out,
            newton_table,
        } => run::solve(&input, study.as_deref(), &out, newton_table, cli.quiet),
        Command::Bench {
            out,
            n_theta,
            repeat,
            no_ccx,
        } => bench::run(&out, n_theta, repeat, !no_ccx, cli.quiet),
    };
    match result {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("error: {e:#}");
            ExitCode::FAILURE
        }
    }
}
