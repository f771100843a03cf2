//! `femu convergence [STUDY.toml] --out DIR`: the mesh and element validation study of the seed
//! (§2.1.2.1) on the built-in thigh. Reads the study's convergence view, calls
//! `femu_convergence`, prints the table and the recommendation.

use anyhow::{Context, Result};
use femu_convergence::{report, run_study, ConvergenceStudy};
use std::path::Path;

/// Runs the study in `study_file` (the defaults without one) and writes `out`.
pub fn run(study_file: Option<&Path>, out: &Path, quiet: bool) -> Result<()> {
    let study = match study_file {
        Some(p) => femu_study::read(p)?
            .convergence_study()
            .map_err(|e| e.in_file(p))?,
        None => ConvergenceStudy::default(),
    };
    if !quiet {
        eprintln!(
            "convergence: {} on the built-in thigh, {} meshes x {} element types{}, tolerance {:.0e} mm, {} x {} grid points",
            study.loading.name(),
            study.meshes.len(),
            study.elements.len(),
            if study.locking {
                format!(" (and D x {} for locking)", study.d_scale)
            } else {
                String::new()
            },
            study.tolerance_mm,
            study.grid.counts[0],
            study.grid.counts[1]
        );
    }
    let mut progress = |line: &str| {
        if !quiet {
            eprintln!("{line}");
        }
    };
    let t0 = std::time::Instant::now();
    let result = match run_study(&study, &mut progress) {
        Err(femu_convergence::ConvergenceError::Interrupted { finished, source }) => {
            // The finished solves are kept, and the summary says what was stopped.
            report::write_finished_runs(out, &finished)?;
            let note = format!(
                "stopped by the user after {} solves (their rows in convergence.csv; no differences, rates or recommendation: the finest meshes were not solved)",
                finished.len()
            );
            femu_study::output::write_stopped(
                out,
                "convergence",
                &note,
                &["convergence.csv"],
                t0.elapsed().as_secs_f64(),
            )?;
            return Err(anyhow::Error::new(source).context(note));
        }
        r => r?,
    };
    report::write_outputs(out, &study, &result)
        .with_context(|| format!("writing the results into {}", out.display()))?;
    if !quiet {
        println!(
            "{:<22} {:<6} {:>8} {:>6} {:>7} {:>7} {:>12} {:>12} {:>8} {:>8}",
            "test",
            "element",
            "D scale",
            "mesh",
            "elems",
            "nodes",
            "max diff mm",
            "RMS diff mm",
            "solve s",
            "mem MB"
        );
        for r in &result.runs {
            println!(
                "{:<22} {:<6} {:>8} {:>6} {:>7} {:>7} {:>12} {:>12} {:>8.2} {:>8}",
                r.test,
                r.element,
                r.d_scale,
                r.mesh + 1,
                r.elements,
                r.nodes,
                r.max_diff_mm.map_or("-".into(), |v| format!("{v:.3e}")),
                r.rms_diff_mm.map_or("-".into(), |v| format!("{v:.3e}")),
                r.solve_s,
                r.peak_memory_mb.map_or("-".into(), |v| format!("{v:.0}"))
            );
        }
        for s in &result.elements {
            if let Some(f) = s.rate_max {
                println!(
                    "{} {} (D x {}): rate {:.2} (max), {} (RMS)",
                    s.test,
                    s.element,
                    s.d_scale,
                    f.rate,
                    s.rate_rms.map_or("-".into(), |f| format!("{:.2}", f.rate))
                );
            }
        }
        println!("{}", result.recommendation);
        if let Some(l) = &result.locking {
            println!("{}", l.sentence);
        }
        println!(
            "{} of {} grid points compared; {:.1} s; results in {}",
            result.common_points,
            result.grid_points,
            result.total_s,
            out.display()
        );
    }
    Ok(())
}
