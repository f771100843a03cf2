//! The design step (`femu design STUDY --out DIR`, and `[run] design = true`): which tests to
//! make and where to put the probe, decided before any acquisition (`femu_identify::design`).
//!
//! Every `[design]` test is solved once at the reference parameters and differentiated
//! exactly; each probe window (side × size) is a grid of points in the tissue it sees, whose
//! Fisher information with the study's noise is `J_wᵀ J_w / σ²`. Designs of one to
//! `max_measurements` windows (no test seen twice from one side) are ranked by the A- and
//! D-optimal criteria, with the parameters each can and cannot identify. Writes
//!
//! - `designs.csv` — every design: criteria, worst sd per family, identifiable parameters;
//! - `candidates.csv` — every single window: points, predicted sd of each parameter;
//! - `designs.png` (the best designs' criteria), `candidates.png` (each window alone, worst C10
//!   against worst D);
//! - `summary.json` — [`DesignSummary`].

use super::measure::window_points;
use super::parameters::free_parameters;
use crate::bail;
use crate::error::{Context, Error, Result};
use crate::model::StudyModel;
use crate::output::{create_dir, write_json};
use crate::progress::Progress;
use crate::schema::{DesignSpec, Study, TestSpec, WindowSpec};
use femu_identify::design::{self, Candidate, Design};
use femu_identify::fit::FreeParameter;
use femu_mech::sensitivity::{DirectSensitivity, Parameter};
use femu_mech::{Model, SolverOptions, StaticSolver};
use femu_mesh::locate::PointLocator;
use femu_plot::{line_plot_png, LinePlot, LineStyle, Series};
use serde::{Deserialize, Serialize};
use std::io::Write;
use std::path::Path;
use std::time::Instant;

/// How many of the best designs the summary (and the report) lists; `designs.csv` has all.
pub const LISTED: usize = 30;

/// A single window of one test, as the summary lists it.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct CandidateSummary {
    pub name: String,
    pub test: String,
    pub side: String,
    pub window_mm: [f64; 2],
    pub points: usize,
    /// Per free parameter: the relative sd this window alone predicts.
    pub relative_sd: Vec<f64>,
}

/// The best single-test design for one parameter family (the seed's question).
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct BestFor {
    pub family: String,
    pub test: String,
    pub design: Vec<String>,
    pub worst_relative_sd: f64,
}

/// `summary.json` of the design step.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct DesignSummary {
    pub command: String,
    pub version: String,
    pub elements: usize,
    pub noise_sigma_mm: f64,
    /// The free parameters (tied when `grouped`) and their families.
    pub parameters: Vec<(String, String)>,
    pub grouped: bool,
    pub candidates: Vec<CandidateSummary>,
    /// Designs ranked, and the best [`LISTED`] of them by the A-optimal criterion.
    pub designs_ranked: usize,
    pub designs: Vec<Design>,
    pub best_single_test: Vec<BestFor>,
    pub finding: Vec<String>,
    /// Tests that could not be solved, with the reason.
    pub failed_tests: Vec<(String, String)>,
    /// Seconds: solves and sensitivities, windows and ranking, the whole step.
    pub timings_s: (f64, f64, f64),
}

/// The exact sensitivities of one test at the reference: the loaded model and `∂u/∂θ` of
/// every member of `free`, in their order.
fn differentiate(
    built: &StudyModel,
    loading: &femu_mech::loading::Loading,
    free: &[FreeParameter],
) -> Result<(Model, Vec<Vec<f64>>)> {
    let model = built.loaded(loading)?;
    let mut solver = StaticSolver::new(&model, SolverOptions::default())?;
    let solution = solver.solve(&model)?;
    let members: Vec<Parameter> = free.iter().flat_map(|f| f.members.clone()).collect();
    let mut dstate = Vec::new();
    DirectSensitivity::new()
        .compute(&mut solver, &model, &solution.state, &members, &mut dstate)
        .context("sensitivities")?;
    Ok((model, dstate))
}

/// The whitened information `JᵀJ/σ²` of the log-parameters `free` at `points` of a test whose
/// member sensitivities are `du` (tied members add their columns).
fn information(
    model: &Model,
    free: &[FreeParameter],
    du: &[Vec<f64>],
    points: &[[f64; 2]],
    sigma: f64,
) -> Vec<Vec<f64>> {
    let locator = PointLocator::new(&model.mesh);
    let located: Vec<_> = points.iter().filter_map(|x| locator.locate(*x)).collect();
    let mut k = 0;
    let columns: Vec<Vec<f64>> = free
        .iter()
        .map(|f| {
            let mut col = vec![0.0; 2 * located.len()];
            for m in &f.members {
                let theta = m.value(model);
                for (i, loc) in located.iter().enumerate() {
                    col[2 * i] += theta * loc.interpolate(&du[k], 2, 0) / sigma;
                    col[2 * i + 1] += theta * loc.interpolate(&du[k], 2, 1) / sigma;
                }
                k += 1;
            }
            col
        })
        .collect();
    let n = free.len();
    (0..n)
        .map(|p| {
            (0..n)
                .map(|q| columns[p].iter().zip(&columns[q]).map(|(a, b)| a * b).sum())
                .collect()
        })
        .collect()
}

/// What the design step reads of a study: `[design]`, the tests, the noise, and the free
/// parameters on the built model, checked before anything is solved.
pub struct DesignInputs<'a> {
    pub spec: &'a DesignSpec,
    pub tests: &'a [TestSpec],
    /// The noise of the measured displacement (mm).
    pub sigma_mm: f64,
    /// The free parameters (tied when `[design] grouped`).
    pub free: Vec<FreeParameter>,
}

impl<'a> DesignInputs<'a> {
    /// The study's `[design]`, tests and noise, and its free parameters on `built`; refuses a
    /// window larger than the model seen from one of the sides.
    pub fn of(study: &'a Study, built: &StudyModel) -> Result<DesignInputs<'a>> {
        let (free, _) = free_parameters(study, &built.model, study.design.grouped)?;
        check_window_sizes(study, &built.model.mesh)?;
        Ok(DesignInputs {
            spec: &study.design,
            tests: &study.tests,
            sigma_mm: study.measurement.sigma_mm,
            free,
        })
    }
}

/// The design step on the built model `built` (see the module documentation).
pub fn run_on(
    inputs: &DesignInputs,
    built: &StudyModel,
    out: &Path,
    progress: &dyn Progress,
) -> Result<DesignSummary> {
    let t0 = Instant::now();
    create_dir(out)?;
    let spec = inputs.spec;
    let free = &inputs.free;
    let names: Vec<String> = free.iter().map(|f| f.name.clone()).collect();
    let families: Vec<String> = free
        .iter()
        .map(|f| f.members[0].spec().name.to_string())
        .collect();
    let stopping = Stopping {
        out,
        names: &names,
        t0,
    };
    let windows = place_windows(spec, built, &stopping, progress)?;
    progress.note(&format!(
        "design: {} tests x {} windows, up to {} measurements per design, noise {} mm, {} free parameters",
        spec.tests.len(),
        windows.len(),
        spec.max_measurements,
        inputs.sigma_mm,
        free.len()
    ));
    let evaluated = evaluate_windows(inputs, built, &windows, &stopping, progress)?;
    let solved_s = t0.elapsed().as_secs_f64();
    let t1 = Instant::now();
    let ranked = rank_designs(&evaluated, spec, &families, &stopping, progress)?;
    let ranking_s = t1.elapsed().as_secs_f64();
    let best_single_test = best_for_each_family(&ranked, &families);
    let finding = findings(&best_single_test, &ranked);
    write_designs_csv(&out.join("designs.csv"), &ranked, &names)?;
    write_candidates_csv(&out.join("candidates.csv"), &evaluated.summaries, &names)?;
    write_figures(out, &ranked, &evaluated.summaries, &families)?;
    let summary = DesignSummary {
        command: "design".into(),
        version: env!("CARGO_PKG_VERSION").into(),
        elements: built.model.mesh.elements.len(),
        noise_sigma_mm: inputs.sigma_mm,
        parameters: names.into_iter().zip(families).collect(),
        grouped: spec.grouped,
        candidates: evaluated.summaries,
        designs_ranked: ranked.len(),
        designs: ranked.iter().take(LISTED).cloned().collect(),
        best_single_test,
        finding,
        failed_tests: evaluated.failed_tests,
        timings_s: (solved_s, ranking_s, t0.elapsed().as_secs_f64()),
    };
    write_json(&out.join("summary.json"), &summary)?;
    for line in &summary.finding {
        progress.note(line);
    }
    progress.note(&format!(
        "{} designs ranked in {:.3} s (solves and sensitivities {:.1} s); wrote {}",
        summary.designs_ranked,
        ranking_s,
        solved_s,
        out.display()
    ));
    Ok(summary)
}

/// Where a stopped design keeps what it finished.
struct Stopping<'a> {
    out: &'a Path,
    names: &'a [String],
    t0: Instant,
}

impl Stopping<'_> {
    /// The error of a design stopped `what` (`"while solving X"`), `finished` kept.
    fn stop(&self, finished: &[CandidateSummary], what: &str) -> Error {
        stopped(self.out, self.names, finished, self.t0, what)
    }
}

/// Every window (each side × size) and its points in the tissue of the unloaded model (the
/// measured points are reference positions).
#[allow(clippy::type_complexity)]
fn place_windows(
    spec: &DesignSpec,
    built: &StudyModel,
    stopping: &Stopping,
    progress: &dyn Progress,
) -> Result<Vec<(WindowSpec, Vec<[f64; 2]>)>> {
    let mut windows = Vec::new();
    for side in &spec.sides {
        for &[width_mm, depth_mm] in &spec.windows_mm {
            if progress.cancelled() {
                return Err(stopping.stop(&[], "while placing the windows"));
            }
            let w = WindowSpec {
                side: side.clone(),
                width_mm,
                depth_mm,
                spacing_mm: spec.spacing_mm,
            };
            let (points, _) = window_points(built, &w)?;
            windows.push((w, points));
        }
    }
    Ok(windows)
}

/// The candidates of every test that could be solved: each window's information, and the
/// tests left out with the reason.
struct Evaluated {
    candidates: Vec<Candidate>,
    summaries: Vec<CandidateSummary>,
    failed_tests: Vec<(String, String)>,
}

/// Each test of `[design]` solved and differentiated once, and the information of each of its
/// windows; a test that cannot be solved is left out (fails when none can).
fn evaluate_windows(
    inputs: &DesignInputs,
    built: &StudyModel,
    windows: &[(WindowSpec, Vec<[f64; 2]>)],
    stopping: &Stopping,
    progress: &dyn Progress,
) -> Result<Evaluated> {
    let spec = inputs.spec;
    let bar = progress.task(
        "solving and differentiating the tests",
        Some(spec.tests.len()),
    );
    let mut e = Evaluated {
        candidates: Vec::new(),
        summaries: Vec::new(),
        failed_tests: Vec::new(),
    };
    for &t in &spec.tests {
        let loading = &inputs.tests[t].loading;
        let test = loading.name();
        let stop_here =
            |e: &Evaluated| stopping.stop(&e.summaries, &format!("while solving {test}"));
        if progress.cancelled() {
            return Err(stop_here(&e));
        }
        let (model, du) = match differentiate(built, loading, &inputs.free) {
            Ok(r) => r,
            Err(err) if crate::progress::is_interrupted(&err) => return Err(stop_here(&e)),
            Err(err) => {
                let why = err.chain();
                progress.warn(&format!("test {test} left out: {why}"));
                e.failed_tests.push((test, why));
                bar.inc(1);
                continue;
            }
        };
        let mut infos = Vec::with_capacity(windows.len());
        for (_, points) in windows {
            if progress.cancelled() {
                return Err(stop_here(&e));
            }
            infos.push(information(
                &model,
                &inputs.free,
                &du,
                points,
                inputs.sigma_mm,
            ));
        }
        for ((w, points), info) in windows.iter().zip(infos) {
            e.push(&test, w, points.len(), info, stopping.names);
        }
        bar.inc(1);
    }
    drop(bar);
    if e.candidates.is_empty() {
        bail!(
            "no test could be solved: {}",
            e.failed_tests
                .iter()
                .map(|(t, why)| format!("{t}: {why}"))
                .collect::<Vec<_>>()
                .join("; ")
        );
    }
    Ok(e)
}

impl Evaluated {
    /// The window `w` of `test`, of `points` points and information `info`.
    fn push(
        &mut self,
        test: &str,
        w: &WindowSpec,
        points: usize,
        info: Vec<Vec<f64>>,
        names: &[String],
    ) {
        let id = femu_identify::fisher::identifiability(&info, names);
        let name = format!("{test}, {}", w.label());
        self.summaries.push(CandidateSummary {
            name: name.clone(),
            test: test.to_string(),
            side: w.side.clone(),
            window_mm: [w.width_mm, w.depth_mm],
            points,
            relative_sd: id.relative_sd,
        });
        self.candidates.push(Candidate {
            name,
            group: test.to_string(),
            exclusive: format!("{test}@{}", w.side),
            information: info,
            points,
        });
    }
}

/// Every design of up to `[design] max_measurements` candidates scored and ranked (in chunks,
/// so that a stop is seen).
fn rank_designs(
    evaluated: &Evaluated,
    spec: &DesignSpec,
    families: &[String],
    stopping: &Stopping,
    progress: &dyn Progress,
) -> Result<Vec<Design>> {
    let candidates = &evaluated.candidates;
    let sets = design::designs(candidates, spec.max_measurements);
    let mut ranked: Vec<Design> = Vec::with_capacity(sets.len());
    for chunk in sets.chunks(2000) {
        if progress.cancelled() {
            return Err(stopping.stop(
                &evaluated.summaries,
                &format!(
                    "while ranking the designs ({} of {})",
                    ranked.len(),
                    sets.len()
                ),
            ));
        }
        ranked.extend(chunk.iter().map(|m| {
            design::score(
                candidates,
                m,
                stopping.names,
                families,
                spec.identifiable_sd,
            )
        }));
    }
    design::rank(&mut ranked);
    Ok(ranked)
}

/// Refuses a `[design] windows_mm` size larger than the model seen from one of the sides:
/// wider than the model across the side's direction, or deeper than it along it.
fn check_window_sizes(study: &Study, mesh: &femu_mesh::Mesh) -> Result<()> {
    for side in &study.design.sides {
        let d = femu_mech::loading::Side::parse(side)
            .map_err(|e| crate::input!("[design] sides: {e}"))?
            .direction();
        let extent = |axis: [f64; 2]| {
            let (lo, hi) = mesh.nodes.iter().fold((f64::MAX, f64::MIN), |(lo, hi), x| {
                let v = x[0] * axis[0] + x[1] * axis[1];
                (lo.min(v), hi.max(v))
            });
            hi - lo
        };
        let (across, along) = (extent([-d[1], d[0]]), extent(d));
        if let Some(w) = study
            .design
            .windows_mm
            .iter()
            .find(|w| w[0] > across || w[1] > along)
        {
            return Err(study
                .key_error(
                    "design",
                    "windows_mm",
                    format!(
                        "a {} x {} mm window (width x depth) is larger than the model seen from the {side} side: {across:.1} mm across, {along:.1} mm deep",
                        w[0], w[1]
                    ),
                )
                .into());
        }
    }
    Ok(())
}

/// The error of a design the user stopped: `candidates.csv` of the windows of the tests that
/// finished (when any did) and a `summary.json` that says what was stopped, then
/// [`crate::progress::Interrupted`].
fn stopped(
    out: &Path,
    names: &[String],
    finished: &[CandidateSummary],
    t0: Instant,
    what: &str,
) -> Error {
    let kept = femu_mesh::stop::shielded(|| -> Result<Vec<&str>> {
        let mut kept = Vec::new();
        if !finished.is_empty() {
            write_candidates_csv(&out.join("candidates.csv"), finished, names)?;
            kept.push("candidates.csv");
        }
        Ok(kept)
    });
    let message = match &kept {
        Ok(k) if !k.is_empty() => format!(
            "design interrupted {what}: the {} windows of the tests solved are kept in candidates.csv",
            finished.len()
        ),
        _ => format!("design interrupted {what}: no window was finished"),
    };
    let written = crate::output::write_stopped(
        out,
        "design",
        &message,
        kept.as_deref().unwrap_or(&[]),
        t0.elapsed().as_secs_f64(),
    );
    let mut e = Error::from(crate::progress::Interrupted).context(message);
    if let Err(w) = kept.and(written) {
        e = e.context(format!("keeping what was finished failed: {}", w.chain()));
    }
    e
}

/// For each parameter family, the single-test design (any of its windows) with the smallest
/// worst sd of that family.
fn best_for_each_family(ranked: &[Design], families: &[String]) -> Vec<BestFor> {
    let mut seen: Vec<&String> = Vec::new();
    for f in families {
        if !seen.contains(&f) {
            seen.push(f);
        }
    }
    seen.into_iter()
        .filter_map(|family| {
            let worst = |d: &Design| {
                d.worst_by_family
                    .iter()
                    .find(|(f, _)| f == family)
                    .map_or(f64::INFINITY, |w| w.1)
            };
            ranked
                .iter()
                .filter(|d| d.tests.len() == 1)
                .min_by(|a, b| worst(a).total_cmp(&worst(b)))
                .map(|d| BestFor {
                    family: family.clone(),
                    test: d.tests[0].clone(),
                    design: d.measurements.clone(),
                    worst_relative_sd: worst(d),
                })
        })
        .collect()
}

/// The sentences of the report: which test measures each family best (the seed's finding:
/// compression for C10, contention for D), and the best design.
fn findings(best: &[BestFor], ranked: &[Design]) -> Vec<String> {
    let mut out: Vec<String> = best
        .iter()
        .map(|b| {
            format!(
                "{}: best measured by {} alone (worst {} sd {:.2} % with {})",
                b.family,
                b.test,
                b.family,
                100.0 * b.worst_relative_sd,
                b.design.join(" + ")
            )
        })
        .collect();
    if let Some(d) = ranked.first() {
        out.push(format!(
            "best design (A-optimal): {} — RMS sd {:.2} %, worst {}; identifies {} of {} parameters",
            d.measurements.join(" + "),
            100.0 * d.a_criterion,
            d.worst_by_family
                .iter()
                .map(|(f, s)| format!("{f} {:.2} %", 100.0 * s))
                .collect::<Vec<_>>()
                .join(", "),
            d.identifiable.len(),
            d.identifiable.len() + d.not_identifiable.len()
        ));
    }
    out
}

fn write_designs_csv(path: &Path, ranked: &[Design], names: &[String]) -> Result<()> {
    let mut w = crate::output::create_file(path)?;
    write!(
        w,
        "rank_a,rank_d,measurements,points,a_rms_sd,d_geometric_sd,worst_sd_by_family,not_identifiable"
    )?;
    for n in names {
        write!(w, ",sd_{n}")?;
    }
    writeln!(w)?;
    for d in ranked {
        write!(
            w,
            "{},{},\"{}\",{},{:.6e},{:.6e},\"{}\",\"{}\"",
            d.rank_a,
            d.rank_d,
            d.measurements.join(" + "),
            d.points,
            d.a_criterion,
            d.d_criterion,
            d.worst_by_family
                .iter()
                .map(|(f, s)| format!("{f}={s:.4e}"))
                .collect::<Vec<_>>()
                .join(" "),
            d.not_identifiable.join(" ")
        )?;
        for s in &d.relative_sd {
            write!(w, ",{s:.6e}")?;
        }
        writeln!(w)?;
    }
    crate::output::commit(w)
}

fn write_candidates_csv(path: &Path, c: &[CandidateSummary], names: &[String]) -> Result<()> {
    let mut w = crate::output::create_file(path)?;
    write!(w, "test,side,width_mm,depth_mm,points")?;
    for n in names {
        write!(w, ",sd_{n}")?;
    }
    writeln!(w)?;
    for c in c {
        write!(
            w,
            "{},{},{},{},{}",
            c.test, c.side, c.window_mm[0], c.window_mm[1], c.points
        )?;
        for s in &c.relative_sd {
            write!(w, ",{s:.6e}")?;
        }
        writeln!(w)?;
    }
    crate::output::commit(w)
}

/// The worst sd of `family` among `sd` (infinite when unseen).
fn worst_of(sd: &[f64], families: &[String], family: &str) -> f64 {
    sd.iter()
        .zip(families)
        .filter(|(_, f)| *f == family)
        .map(|(s, _)| *s)
        .fold(0.0, f64::max)
}

/// `designs.png`: the criteria and worst sds of the best designs against their rank (log);
/// `candidates.png`: each window alone, worst C10 sd against worst D sd, one series per test.
fn write_figures(
    out: &Path,
    ranked: &[Design],
    candidates: &[CandidateSummary],
    families: &[String],
) -> Result<()> {
    let top: Vec<&Design> = ranked
        .iter()
        .take(LISTED)
        .filter(|d| d.a_criterion.is_finite())
        .collect();
    let mut fams: Vec<&String> = Vec::new();
    for f in families {
        if !fams.contains(&f) {
            fams.push(f);
        }
    }
    if top.len() >= 2 {
        let mut series = vec![Series::new(
            "A criterion (RMS sd)",
            top.iter()
                .map(|d| (d.rank_a as f64, 100.0 * d.a_criterion))
                .collect(),
            LineStyle::LineAndMarkers,
        )];
        for f in &fams {
            series.push(Series::new(
                &format!("worst {f} sd"),
                top.iter()
                    .map(|d| {
                        (
                            d.rank_a as f64,
                            100.0 * worst_of(&d.relative_sd, families, f),
                        )
                    })
                    .filter(|p| p.1.is_finite() && p.1 > 0.0)
                    .collect(),
                LineStyle::Markers,
            ));
        }
        line_plot_png(
            &out.join("designs.png"),
            &series,
            &LinePlot {
                title: format!("The {} best designs (A-optimal ranking)", top.len()),
                x_label: "rank".into(),
                y_label: "predicted relative sd (%)".into(),
                log_y: true,
                ..Default::default()
            },
        )?;
    }
    let (Some(fx), Some(fy)) = (fams.first(), fams.get(1)) else {
        return Ok(());
    };
    let mut tests: Vec<&String> = Vec::new();
    for c in candidates {
        if !tests.contains(&&c.test) {
            tests.push(&c.test);
        }
    }
    let series: Vec<Series> = tests
        .iter()
        .map(|t| {
            Series::new(
                t,
                candidates
                    .iter()
                    .filter(|c| &&c.test == t)
                    .map(|c| {
                        (
                            100.0 * worst_of(&c.relative_sd, families, fx),
                            100.0 * worst_of(&c.relative_sd, families, fy),
                        )
                    })
                    .filter(|p| p.0.is_finite() && p.1.is_finite() && p.0 > 0.0 && p.1 > 0.0)
                    .collect(),
                LineStyle::Markers,
            )
        })
        .filter(|s| !s.points.is_empty())
        .collect();
    if !series.is_empty() {
        line_plot_png(
            &out.join("candidates.png"),
            &series,
            &LinePlot {
                title: "Each probe window alone: predicted worst sd per family".into(),
                x_label: format!("worst {fx} relative sd (%)"),
                y_label: format!("worst {fy} relative sd (%)"),
                log_x: true,
                log_y: true,
                ..Default::default()
            },
        )?;
    }
    Ok(())
}
