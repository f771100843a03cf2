//! `femu bench`: the paper-scale contention solve on the built-in parametric thigh (about 25 000
//! CPE4 quads, five regions, femur fixed, 20 mmHg on the skin), run by femu and by CalculiX on the same deck, interleaved so that
//! both see the same machine load; reports wall times, their ratio, the displacement agreement
//! and femu's peak memory.

use anyhow::{bail, Context, Result};
use serde::Serialize;
use std::path::{Path, PathBuf};
use std::process::Command;
use std::time::Instant;

#[derive(Serialize)]
struct BenchSummary {
    femu_version: &'static str,
    elements: usize,
    nodes: usize,
    repeat: usize,
    femu_wall_s: Vec<f64>,
    femu_solve_s: Vec<f64>,
    femu_peak_memory_mb: Option<f64>,
    ccx_wall_s: Vec<f64>,
    femu_best_wall_s: f64,
    femu_best_solve_s: f64,
    ccx_best_wall_s: Option<f64>,
    /// ccx best wall time over femu best wall time (whole commands, deck to result files).
    speedup_wall: Option<f64>,
    /// ccx median wall time over femu median wall time (the host's swings hit femu's short
    /// runs harder than ccx's long ones).
    speedup_median_wall: Option<f64>,
    /// max |u_femu - u_ccx| / max |u_ccx| over all nodes.
    max_displacement_difference_ratio: Option<f64>,
    threads: usize,
    /// The compression test (rigid plate, 0.1 N/mm, anterior) on the same mesh, in process:
    /// model setup + solve (s), increments and Newton iterations of the best run.
    compression_s: Vec<f64>,
    compression_best_s: f64,
    compression_increments: usize,
    compression_newton_iterations: usize,
}

/// Solves the compression test in process; returns (setup + solve time, increments, iterations).
fn run_compression(elements: usize) -> Result<(f64, usize, usize)> {
    let (mut model, skin) = femu_study::model::thigh_model(elements, femu_mesh::ElementKind::Cpe4)?;
    femu_mech::loading::apply_loading(
        &mut model,
        &skin,
        &femu_mech::loading::Loading::seed_compression(),
    )?;
    let t = Instant::now();
    let mut solver = femu_mech::StaticSolver::new(&model, femu_mech::SolverOptions::default())?;
    let sol = solver.solve(&model)?;
    Ok((
        t.elapsed().as_secs_f64(),
        sol.report.converged_increments,
        sol.report.newton_iterations,
    ))
}

fn median(v: &[f64]) -> f64 {
    let mut s = v.to_vec();
    s.sort_by(f64::total_cmp);
    s[s.len() / 2]
}

fn best(v: &[f64]) -> f64 {
    v.iter().copied().fold(f64::INFINITY, f64::min)
}

fn run_femu(deck: &Path, out: &Path) -> Result<(f64, f64, Option<f64>)> {
    let exe = std::env::current_exe().context("cannot locate the femu executable")?;
    let t = Instant::now();
    let status = Command::new(exe)
        .arg("solve")
        .arg(deck)
        .arg("--out")
        .arg(out)
        .arg("--quiet")
        .arg("--no-figures")
        .status()
        .context("cannot run femu solve")?;
    let wall = t.elapsed().as_secs_f64();
    if !status.success() {
        bail!("femu solve failed on {}", deck.display());
    }
    let summary: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("summary.json"))?)?;
    let solve = summary["timings"]["setup_s"].as_f64().unwrap_or(f64::NAN)
        + summary["timings"]["solve_s"].as_f64().unwrap_or(f64::NAN);
    Ok((wall, solve, summary["peak_memory_mb"].as_f64()))
}

fn run_ccx(dir: &Path, threads: usize) -> Result<f64> {
    let t = Instant::now();
    let output = Command::new("ccx")
        .arg("-i")
        .arg("model")
        .current_dir(dir)
        .env("OMP_NUM_THREADS", threads.to_string())
        .env("CCX_NPROC_EQUATION_SOLVER", threads.to_string())
        .env("CCX_NPROC_RESULTS", threads.to_string())
        .env("CCX_NPROC_STIFFNESS", threads.to_string())
        .output()
        .context("cannot run ccx (install it with: apt-get install calculix-ccx)")?;
    let wall = t.elapsed().as_secs_f64();
    let log = String::from_utf8_lossy(&output.stdout);
    if !output.status.success() || log.contains("*ERROR") {
        bail!(
            "ccx failed in {}:\n{}",
            dir.display(),
            log.lines().rev().take(20).collect::<Vec<_>>().join("\n")
        );
    }
    Ok(wall)
}

fn ccx_available() -> bool {
    Command::new("ccx").arg("-v").output().is_ok()
}

/// Runs the benchmark and writes `summary.json` into `out`.
pub fn run(
    out: &Path,
    target_elements: usize,
    repeat: usize,
    with_ccx: bool,
    quiet: bool,
) -> Result<()> {
    if repeat == 0 {
        bail!("--repeat must be at least 1");
    }

    std::fs::create_dir_all(out).with_context(|| format!("cannot create {}", out.display()))?;
    let (model, skin) =
        femu_study::model::thigh_model(target_elements, femu_mesh::ElementKind::Cpe4)?;
    let deck = femu_study::model::contention_deck(&model, &skin, femu_geometry::CONTENTION_MPA);
    let (elements, nodes) = (deck.mesh.elements.len(), deck.mesh.nodes.len());
    let deck_path = out.join("model.inp");
    femu_mesh::write_inp_file(&deck, &deck_path)?;
    let ccx_dir: PathBuf = out.join("ccx");
    let use_ccx = with_ccx && ccx_available();
    if with_ccx && !use_ccx && !quiet {
        eprintln!("ccx not found: CalculiX is skipped (apt-get install calculix-ccx)");
    }
    if use_ccx {
        std::fs::create_dir_all(&ccx_dir)?;
        std::fs::copy(&deck_path, ccx_dir.join("model.inp"))?;
    }
    let threads = std::thread::available_parallelism().map_or(1, |n| n.get());
    if !quiet {
        eprintln!("bench: built-in thigh, contention, {elements} CPE4 elements, {nodes} nodes, {repeat} runs each, {threads} threads");
    }
    let femu_out = out.join("femu");
    let (mut femu_wall, mut femu_solve, mut ccx_wall) = (Vec::new(), Vec::new(), Vec::new());
    let mut peak = None;
    for k in 0..repeat {
        let (w, s, p) = run_femu(&deck_path, &femu_out)?;
        femu_wall.push(w);
        femu_solve.push(s);
        peak = match (peak, p) {
            (Some(a), Some(b)) => Some(f64::max(a, b)),
            (a, b) => a.or(b),
        };
        if use_ccx {
            ccx_wall.push(run_ccx(&ccx_dir, threads)?);
        }
        if !quiet {
            eprintln!(
                "run {}: femu {:.3} s (setup + solve {:.3} s){}",
                k + 1,
                w,
                s,
                ccx_wall
                    .last()
                    .map_or(String::new(), |c| format!(", ccx {c:.3} s"))
            );
        }
    }
    let mut compression = Vec::new();
    let (mut comp_inc, mut comp_it) = (0, 0);
    for k in 0..repeat {
        let (t, inc, it) = run_compression(target_elements)?;
        compression.push(t);
        (comp_inc, comp_it) = (inc, it);
        if !quiet {
            eprintln!("run {}: compression test (femu, in process) {t:.3} s, {inc} increments, {it} Newton iterations", k + 1);
        }
    }
    let diff = if use_ccx {
        let ccx_u = femu_mesh::inp::read_ccx_dat_displacements(&ccx_dir.join("model.dat"))?;
        let text = std::fs::read_to_string(femu_out.join("displacements.csv"))?;
        let mut femu_u = std::collections::HashMap::new();
        for line in text.lines().skip(1) {
            let v: Vec<&str> = line.split(',').collect();
            let label: i64 = v[0].parse()?;
            femu_u.insert(label, [v[3].parse::<f64>()?, v[4].parse::<f64>()?]);
        }
        let umax = ccx_u
            .iter()
            .map(|(_, u)| u[0].hypot(u[1]))
            .fold(0.0f64, f64::max);
        let mut dmax = 0.0f64;
        for (label, u) in &ccx_u {
            let f = femu_u
                .get(label)
                .with_context(|| format!("node {label} missing from femu's output"))?;
            dmax = dmax.max((f[0] - u[0]).hypot(f[1] - u[1]));
        }
        Some(dmax / umax)
    } else {
        None
    };
    let summary = BenchSummary {
        femu_version: env!("CARGO_PKG_VERSION"),
        elements,
        nodes,
        repeat,
        femu_best_wall_s: best(&femu_wall),
        femu_best_solve_s: best(&femu_solve),
        ccx_best_wall_s: use_ccx.then(|| best(&ccx_wall)),
        speedup_wall: use_ccx.then(|| best(&ccx_wall) / best(&femu_wall)),
        speedup_median_wall: use_ccx.then(|| median(&ccx_wall) / median(&femu_wall)),
        max_displacement_difference_ratio: diff,
        femu_wall_s: femu_wall.clone(),
        femu_solve_s: femu_solve.clone(),
        femu_peak_memory_mb: peak,
        ccx_wall_s: ccx_wall.clone(),
        threads,
        compression_best_s: best(&compression),
        compression_s: compression,
        compression_increments: comp_inc,
        compression_newton_iterations: comp_it,
    };
    femu_mesh::atomic::write(
        out.join("summary.json"),
        serde_json::to_string_pretty(&summary)?,
    )?;
    if !quiet {
        println!("femu  wall: best {:.3} s, median {:.3} s (setup + solve: best {:.3} s); peak memory {} MB", best(&femu_wall), median(&femu_wall), best(&femu_solve), peak.map_or("?".into(), |p| format!("{p:.0}")));
        if use_ccx {
            println!(
                "ccx   wall: best {:.3} s, median {:.3} s",
                best(&ccx_wall),
                median(&ccx_wall)
            );
            println!(
                "speed-up (ccx / femu, best wall): {:.1}x (median wall: {:.1}x)",
                summary.speedup_wall.unwrap_or(f64::NAN),
                summary.speedup_median_wall.unwrap_or(f64::NAN)
            );
            println!(
                "max |u_femu - u_ccx| / max |u_ccx| = {:.2e}",
                diff.unwrap_or(f64::NAN)
            );
        }
        println!(
            "compression test (rigid plate, 0.1 N/mm): best {:.3} s, {} increments, {} Newton iterations",
            summary.compression_best_s, summary.compression_increments, summary.compression_newton_iterations
        );
        println!("details in {}", out.join("summary.json").display());
    }
    Ok(())
}
