//! The sensitivity step (`femu sensitivity [STUDY] --out DIR`): exact sensitivities of the
//! displacement field to every material parameter for each loading test (seed §2.3, Eq. 3,
//! Fig. 8), and the identifiability of the parameters from the measurement grid (Fisher
//! information).

use crate::bail;
use crate::error::{Context, Result};
use crate::output::{create_dir, write_json, ParameterEntry};
use crate::progress::Progress;
use crate::schema::{GridSpec, MeasurementSpec, QuadElement, Study, TestSpec};
use femu_identify::fisher::{self, Identifiability, Tied};
use femu_mech::loading::apply_loading;
use femu_mech::sensitivity::{all_parameters, sensitivity_map, DirectSensitivity, Parameter};
use femu_mech::{Model, Solution, SolverOptions, StaticSolver};
use femu_mesh::locate::PointLocator;
use femu_mesh::FieldWriter;
use femu_plot::{bar_chart_png, node_field_png, tile_png, BarChart, FieldPlot};
use rayon::prelude::*;
use serde::{Deserialize, Serialize};
use std::io::Write;
use std::path::{Path, PathBuf};
use std::time::Instant;

/// Options of the step.
#[derive(Debug, Clone)]
pub struct SensitivityOptions {
    pub out: PathBuf,
    /// Also compute central finite differences and report their difference from the direct
    /// differentiation.
    pub fd_check: bool,
    /// Relative parameter step of the finite differences (the seed's 5e-2 %).
    pub fd_step: f64,
    pub figures: bool,
}

/// Sensitivities of one test.
struct TestResult {
    name: String,
    model: Model,
    solution: Solution,
    /// `∂u/∂θ_k` (2 per node).
    du: Vec<Vec<f64>>,
    /// Eq. 3 per parameter and its nodal map.
    global: Vec<f64>,
    maps: Vec<Vec<f64>>,
    solve_s: f64,
    sensitivity_s: f64,
    report: femu_mech::sensitivity::SensitivityReport,
    fd_max_rel_diff: Option<Vec<f64>>,
}

/// The sensitivities of one test, as the summary gives them.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct TestSummary {
    pub test: String,
    pub solve_time_s: f64,
    pub sensitivity_time_s: f64,
    pub sensitivity_over_solve: f64,
    pub newton_iterations: usize,
    pub max_displacement_mm: f64,
    /// Eq. 3 per parameter.
    pub sensitivity_index: Vec<(String, f64)>,
    pub direct_differentiation: femu_mech::sensitivity::SensitivityReport,
    pub finite_difference_max_relative_difference: Option<Vec<(String, f64)>>,
}

/// The predicted identifiability of one measurement (a test, or all tests together).
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct Ranking {
    pub measurement: String,
    pub grouping: String,
    /// The worst of the C10 and of the D family (every registered law has both): also in
    /// [`Ranking::worst_relative_sd`].
    pub worst_c10_relative_sd: f64,
    pub worst_d_relative_sd: f64,
    /// The worst predicted relative sd of each family of law parameters (`C10`, `C20`, `C01`,
    /// `D`, ...) in the order the model's materials declare them.
    #[serde(default)]
    pub worst_relative_sd: Vec<(String, f64)>,
    pub condition: f64,
    pub identifiability: Identifiability,
}

impl Ranking {
    /// The worst predicted relative sd of any parameter (what the ranking sorts by).
    pub fn worst(&self) -> f64 {
        self.worst_relative_sd.iter().map(|w| w.1).fold(
            self.worst_c10_relative_sd.max(self.worst_d_relative_sd),
            f64::max,
        )
    }
}

/// `summary.json` of the sensitivity step.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct SensitivitySummary {
    pub command: String,
    pub version: String,
    pub elements: usize,
    pub nodes: usize,
    pub element: String,
    /// Every parameter's name and value (internal units: MPa, MPa⁻¹).
    pub parameters: Vec<(String, f64)>,
    /// The same parameters as their laws declare them: law, unit, study-file key, value in
    /// the unit reports show, scale.
    #[serde(default)]
    pub law_parameters: Vec<ParameterEntry>,
    pub tests: Vec<TestSummary>,
    pub grid_points: usize,
    pub grid_points_in_tissue: usize,
    pub grid_spacing_mm: f64,
    pub noise_sigma_mm: f64,
    /// Best first, per grouping.
    pub ranking: Vec<Ranking>,
    pub finding: Vec<String>,
    pub wall_time_s: f64,
    /// Tests that could not be solved, with the reason: left out of the maps and the ranking.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub failed_tests: Vec<(String, String)>,
}

/// `femu sensitivity`: the study's model built, every test solved and differentiated.
pub fn run(
    study: &Study,
    options: &SensitivityOptions,
    progress: &dyn Progress,
) -> Result<SensitivitySummary> {
    femu_mesh::folder::refuse_inputs_in(&options.out, &study.input_files())?;
    let built = crate::model::build(&study.model)?;
    run_on(
        SensitivityInputs::of(study),
        &built.model,
        &built.skin,
        options,
        progress,
        &mut |_, _, _, _| Ok(()),
    )
}

/// What the sensitivity step reads of a study: its tests, its groups, its grid and noise.
#[derive(Debug, Clone, Copy)]
pub struct SensitivityInputs<'a> {
    pub tests: &'a [TestSpec],
    /// `[parameters] groups` (the grouped ranking ties them).
    pub groups: &'a [Vec<String>],
    /// The grid of the identifiability and the noise of the measured displacement.
    pub measurement: &'a MeasurementSpec,
    /// The model's element (the summary names it).
    pub element: QuadElement,
}

impl<'a> SensitivityInputs<'a> {
    /// The study's tests, groups, grid and noise.
    pub fn of(study: &'a Study) -> SensitivityInputs<'a> {
        SensitivityInputs {
            tests: &study.tests,
            groups: &study.groups,
            measurement: &study.measurement,
            element: study.model.element,
        }
    }
}

/// Called after each test is solved: `(test name, loaded model, solution, solve time s)`.
pub type OnSolved<'a> = dyn FnMut(&str, &Model, &Solution, f64) -> Result<()> + 'a;

/// The sensitivities of the tests of `inputs` on `base` (the study's model, unloaded);
/// `on_solved` sees each test's solution (`femu run` writes the forward results from it).
pub fn run_on(
    inputs: SensitivityInputs,
    base: &Model,
    skin: &[(usize, usize)],
    args: &SensitivityOptions,
    progress: &dyn Progress,
    on_solved: &mut OnSolved,
) -> Result<SensitivitySummary> {
    let t0 = Instant::now();
    if !(args.fd_step > 0.0 && args.fd_step < 0.1) {
        bail!("--fd-step must be in (0, 0.1), got {}", args.fd_step);
    }
    create_dir(&args.out)?;
    let params = all_parameters(base);
    let names: Vec<String> = params.iter().map(|p| p.name(base)).collect();
    let families: Vec<&str> = params.iter().map(|p| p.spec().name).collect();
    progress.note(&format!(
        "sensitivity: {} elements, {} nodes; {} tests, {} parameters",
        base.mesh.elements.len(),
        base.node_count(),
        inputs.tests.len(),
        params.len()
    ));
    // Checked before any solve: the groups and the grid.
    let groupings = [
        ("ungrouped".to_string(), Tied::none(&names)),
        (
            "grouped".to_string(),
            Tied::new(&names, inputs.groups).context("[parameters] groups")?,
        ),
    ];
    let grid = GridPoints::of(&inputs.measurement.grid, base)?;
    let setup = TestSetup {
        base,
        skin,
        params: &params,
        names: &names,
        args,
    };
    let (results, failed_tests) = solve_tests(inputs.tests, &setup, progress, on_solved)?;
    let thetas: Vec<f64> = params.iter().map(|p| p.value(base)).collect();
    let sigma_mm = inputs.measurement.sigma_mm;
    let ranking = rank_measurements(&results, &groupings, &grid, &thetas, sigma_mm, &families)?;
    write_ranking_csv(&args.out.join("identifiability.csv"), &ranking)?;

    let finding = findings(&results, &families);
    if args.figures {
        write_figures(&args.out, &results, &names, progress)?;
    }
    let summary = SensitivitySummary {
        command: "sensitivity".into(),
        version: env!("CARGO_PKG_VERSION").into(),
        elements: base.mesh.elements.len(),
        nodes: base.node_count(),
        element: format!("{:?}", inputs.element).to_uppercase(),
        parameters: names.iter().cloned().zip(thetas.iter().cloned()).collect(),
        law_parameters: ParameterEntry::all(base),
        tests: results.iter().map(|r| r.summary(&names)).collect(),
        grid_points: grid.points,
        grid_points_in_tissue: grid.located.len(),
        grid_spacing_mm: grid.spacing_mm,
        noise_sigma_mm: sigma_mm,
        ranking,
        finding: finding.clone(),
        wall_time_s: t0.elapsed().as_secs_f64(),
        failed_tests,
    };
    write_json(&args.out.join("summary.json"), &summary)?;
    for line in &finding {
        progress.note(line);
    }
    note_best_measurements(&summary, progress);
    progress.note(&format!("wrote {}", args.out.display()));
    Ok(summary)
}

/// The measurement grid's points in the tissue of the unloaded model.
struct GridPoints {
    /// How many points the grid has (in the tissue or not).
    points: usize,
    located: Vec<femu_mesh::locate::PointLocation>,
    /// The spacing along x of the first two points (0 for a single point).
    spacing_mm: f64,
}

impl GridPoints {
    /// The points of `grid` over `base`'s bounding box that lie in its tissue (at least one).
    fn of(grid: &GridSpec, base: &Model) -> Result<GridPoints> {
        let (lo, hi) = base.mesh.bounding_box();
        let points = grid.points(lo, hi);
        let spacing_mm = if points.len() > 1 {
            points[1][0] - points[0][0]
        } else {
            0.0
        };
        let locator = PointLocator::new(&base.mesh);
        let located: Vec<_> = points.iter().filter_map(|p| locator.locate(*p)).collect();
        if located.is_empty() {
            bail!("no grid point lies in the tissue: check [grid] origin_mm and spacing_mm");
        }
        Ok(GridPoints {
            points: points.len(),
            located,
            spacing_mm,
        })
    }
}

/// What every test is solved and differentiated with.
struct TestSetup<'a> {
    base: &'a Model,
    skin: &'a [(usize, usize)],
    params: &'a [Parameter],
    names: &'a [String],
    args: &'a SensitivityOptions,
}

/// Every test solved and differentiated, its outputs written; a test that cannot be solved is
/// reported and left out (with the reason), the others go on. Fails when none can be solved.
#[allow(clippy::type_complexity)]
fn solve_tests(
    tests: &[TestSpec],
    setup: &TestSetup,
    progress: &dyn Progress,
    on_solved: &mut OnSolved,
) -> Result<(Vec<TestResult>, Vec<(String, String)>)> {
    let mut results = Vec::new();
    let mut failed_tests = Vec::new();
    let bar = progress.task("solving the tests", Some(tests.len()));
    for test in tests {
        progress.check()?;
        let loading = &test.loading;
        bar.message(&format!("{}: solve and sensitivities", loading.name()));
        let r = match run_test(
            setup.base,
            setup.skin,
            loading,
            setup.params,
            setup.args,
            progress,
        ) {
            Ok(r) => r,
            // A stop is not a failure of the test.
            Err(e) if crate::progress::is_interrupted(&e) => return Err(e),
            Err(e) => {
                let why = format!(
                    "{} (refine the mesh, [model] elements, or lower the test's load)",
                    e.chain()
                );
                progress.warn(&format!("test {} left out: {why}", loading.name()));
                failed_tests.push((loading.name(), why));
                bar.inc(1);
                continue;
            }
        };
        on_solved(&r.name, &r.model, &r.solution, r.solve_s)?;
        write_test_outputs(&setup.args.out.join(&r.name), &r, setup.names)?;
        results.push(r);
        bar.inc(1);
    }
    drop(bar);
    if results.is_empty() {
        bail!(
            "no test could be solved: {}",
            failed_tests
                .iter()
                .map(|(t, why)| format!("{t}: {why}"))
                .collect::<Vec<_>>()
                .join("; ")
        );
    }
    Ok((results, failed_tests))
}

/// The predicted identifiability of each test and of all tests together, in each grouping,
/// from the scaled sensitivities `θ ∂u/∂θ` at the grid's points with noise `sigma_mm`: best
/// first within each grouping.
fn rank_measurements(
    results: &[TestResult],
    groupings: &[(String, Tied)],
    grid: &GridPoints,
    thetas: &[f64],
    sigma_mm: f64,
    families: &[&str],
) -> Result<Vec<Ranking>> {
    let columns_of = |r: &TestResult| -> Vec<Vec<f64>> {
        r.du.iter()
            .zip(thetas)
            .map(|(du, th)| {
                grid.located
                    .iter()
                    .flat_map(|loc| {
                        [
                            th * loc.interpolate(du, 2, 0),
                            th * loc.interpolate(du, 2, 1),
                        ]
                    })
                    .collect()
            })
            .collect()
    };
    let mut ranking = Vec::new();
    for (gname, tied) in groupings {
        let mut total: Option<Vec<Vec<f64>>> = None;
        for r in results {
            let f = fisher::information(&columns_of(r), sigma_mm, tied)?;
            ranking.push(rank(&r.name, gname, &f, tied, families));
            match &mut total {
                None => total = Some(f),
                Some(t) => fisher::add_information(t, &f),
            }
        }
        if results.len() > 1 {
            let label = results
                .iter()
                .map(|r| r.name.as_str())
                .collect::<Vec<_>>()
                .join(" + ");
            ranking.push(rank(
                &label,
                gname,
                total.as_ref().expect("tests"),
                tied,
                families,
            ));
        }
    }
    ranking.sort_by(|a, b| {
        (a.grouping.as_str(), a.worst())
            .partial_cmp(&(b.grouping.as_str(), b.worst()))
            .unwrap_or(std::cmp::Ordering::Equal)
    });
    Ok(ranking)
}

impl TestResult {
    /// As the summary gives it (`names`: the parameters').
    fn summary(&self, names: &[String]) -> TestSummary {
        TestSummary {
            test: self.name.clone(),
            solve_time_s: self.solve_s,
            sensitivity_time_s: self.sensitivity_s,
            sensitivity_over_solve: self.sensitivity_s / self.solve_s,
            newton_iterations: self.solution.report.newton_iterations,
            max_displacement_mm: max_norm(&self.solution.u),
            sensitivity_index: names
                .iter()
                .cloned()
                .zip(self.global.iter().cloned())
                .collect(),
            direct_differentiation: self.report.clone(),
            finite_difference_max_relative_difference: self
                .fd_max_rel_diff
                .as_ref()
                .map(|d| names.iter().cloned().zip(d.iter().cloned()).collect()),
        }
    }
}

/// The six best measurements of the ranking, for the user.
fn note_best_measurements(summary: &SensitivitySummary, progress: &dyn Progress) {
    let family_names: Vec<&str> = summary
        .ranking
        .first()
        .map(|r| r.worst_relative_sd.iter().map(|w| w.0.as_str()).collect())
        .unwrap_or_default();
    progress.note(&format!(
        "best measurements (predicted relative sd, worst {}):",
        family_names.join(" / worst ")
    ));
    for r in summary.ranking.iter().take(6) {
        let worst: Vec<String> = r
            .worst_relative_sd
            .iter()
            .map(|w| format!("{:>9.2e}", w.1))
            .collect();
        progress.note(&format!(
            "  {:<40} {:<9} {}",
            r.measurement,
            r.grouping,
            worst.join(" / ")
        ));
    }
}

fn max_norm(u: &[f64]) -> f64 {
    u.chunks_exact(2)
        .map(|c| c[0].hypot(c[1]))
        .fold(0.0, f64::max)
}

/// The distinct families of `families`, in order of first appearance.
fn distinct<'a>(families: &[&'a str]) -> Vec<&'a str> {
    let mut out: Vec<&str> = Vec::new();
    for f in families {
        if !out.contains(f) {
            out.push(f);
        }
    }
    out
}

/// The predicted identifiability of a measurement with information `f`; `families` names
/// each model parameter's law parameter (`"C10"`, `"D"`, ...), a tied one its first member's.
fn rank(
    measurement: &str,
    grouping: &str,
    f: &[Vec<f64>],
    tied: &Tied,
    families: &[&str],
) -> Ranking {
    let id = fisher::identifiability(f, &tied.names);
    let worst = |family: &str| {
        tied.members
            .iter()
            .zip(&id.relative_sd)
            .filter(|(members, _)| families[members[0]] == family)
            .map(|(_, s)| *s)
            .fold(0.0f64, f64::max)
    };
    Ranking {
        measurement: measurement.to_string(),
        grouping: grouping.to_string(),
        worst_c10_relative_sd: worst("C10"),
        worst_d_relative_sd: worst("D"),
        worst_relative_sd: distinct(families)
            .into_iter()
            .map(|family| (family.to_string(), worst(family)))
            .collect(),
        condition: id.condition,
        identifiability: id,
    }
}

fn run_test(
    base: &Model,
    skin: &[(usize, usize)],
    loading: &femu_mech::loading::Loading,
    params: &[Parameter],
    args: &SensitivityOptions,
    progress: &dyn Progress,
) -> Result<TestResult> {
    let name = loading.name();
    let mut model = base.clone();
    apply_loading(&mut model, skin, loading).with_context(|| format!("test {name}"))?;
    // With --fd-check the states are converged far beyond the default so that finite
    // differences of re-solves are meaningful at the 1e-5 level.
    let options = if args.fd_check {
        for c in &mut model.contacts {
            c.penetration_tolerance = 1e-13;
        }
        SolverOptions {
            residual_tolerance: 1e-12,
            energy_tolerance: 1e-24,
            ..Default::default()
        }
    } else {
        SolverOptions::default()
    };
    let mut solver = StaticSolver::new(&model, options)?;
    let t = Instant::now();
    let solution = solver
        .solve(&model)
        .with_context(|| format!("test {name}"))?;
    let solve_s = t.elapsed().as_secs_f64();
    let t = Instant::now();
    let mut dd = DirectSensitivity::new();
    let mut dstate = Vec::new();
    let report = dd
        .compute(&mut solver, &model, &solution.state, params, &mut dstate)
        .with_context(|| format!("test {name}"))?;
    let sensitivity_s = t.elapsed().as_secs_f64();
    let n2 = 2 * model.node_count();
    let du: Vec<Vec<f64>> = dstate.iter().map(|d| d[..n2].to_vec()).collect();
    let mut global = Vec::new();
    let mut maps = Vec::new();
    for (p, d) in params.iter().zip(&du) {
        let (s, map) = sensitivity_map(&solution.u, d, p.value(&model));
        global.push(s);
        maps.push(map);
    }
    progress.note(&format!(
        "{name}: solved in {solve_s:.2} s ({} Newton iterations), {} sensitivities in {sensitivity_s:.3} s ({:.0} % of the solve)",
        solution.report.newton_iterations,
        params.len(),
        100.0 * sensitivity_s / solve_s
    ));
    let fd_max_rel_diff = if args.fd_check {
        let mut diffs = Vec::new();
        for (k, p) in params.iter().enumerate() {
            let theta = p.value(&model);
            let h = args.fd_step;
            p.set(&mut model, theta * (1.0 + h));
            let plus = solver
                .solve_with(&model, Some(&solution.state), &mut |_| {})
                .with_context(|| format!("test {name}, finite difference"))?;
            p.set(&mut model, theta * (1.0 - h));
            let minus = solver
                .solve_with(&model, Some(&solution.state), &mut |_| {})
                .with_context(|| format!("test {name}, finite difference"))?;
            p.set(&mut model, theta);
            let mut dmax = 0.0f64;
            let mut smax = 0.0f64;
            for i in 0..n2 {
                let fd = (plus.u[i] - minus.u[i]) / (2.0 * h * theta);
                dmax = dmax.max((fd - du[k][i]).abs());
                smax = smax.max(fd.abs());
            }
            diffs.push(if smax > 0.0 { dmax / smax } else { dmax });
        }
        progress.note(&format!(
            "{name}: direct differentiation vs central finite differences (step {:.0e}): worst relative difference {:.2e}",
            args.fd_step,
            diffs.iter().cloned().fold(0.0, f64::max)
        ));
        Some(diffs)
    } else {
        None
    };
    Ok(TestResult {
        name,
        model,
        solution,
        du,
        global,
        maps,
        solve_s,
        sensitivity_s,
        report,
        fd_max_rel_diff,
    })
}

/// `sensitivity.csv` (node, x, y, ux, uy, one map column per parameter) and `sensitivity.vtu`
/// (the maps and the raw derivatives as point fields).
fn write_test_outputs(dir: &Path, r: &TestResult, names: &[String]) -> Result<()> {
    femu_mesh::atomic::create_dir_all(dir)
        .with_context(|| format!("cannot create {}", dir.display()))?;
    let path = dir.join("sensitivity.csv");
    let mut w = crate::output::create_file(&path)?;
    write!(w, "node,x,y,ux,uy")?;
    for n in names {
        write!(w, ",S_{n}")?;
    }
    writeln!(w)?;
    for (i, x) in r.model.mesh.nodes.iter().enumerate() {
        write!(
            w,
            "{},{:.9e},{:.9e},{:.9e},{:.9e}",
            r.model.mesh.node_labels[i],
            x[0],
            x[1],
            r.solution.u[2 * i],
            r.solution.u[2 * i + 1]
        )?;
        for m in &r.maps {
            write!(w, ",{:.6e}", m[i])?;
        }
        writeln!(w)?;
    }
    crate::output::commit(w)?;
    let disp: Vec<[f64; 2]> = r.solution.u.chunks_exact(2).map(|c| [c[0], c[1]]).collect();
    let field_names: Vec<(String, String)> = names
        .iter()
        .map(|n| (format!("S_{n}"), format!("dU_d{n}")))
        .collect();
    let du3: Vec<Vec<f64>> =
        r.du.iter()
            .map(|d| d.chunks_exact(2).flat_map(|c| [c[0], c[1], 0.0]).collect())
            .collect();
    let mut fields = Vec::new();
    for (k, (s_name, d_name)) in field_names.iter().enumerate() {
        fields.push(femu_mesh::vtu::VtuField {
            name: s_name,
            components: 1,
            data: &r.maps[k],
        });
        fields.push(femu_mesh::vtu::VtuField {
            name: d_name,
            components: 3,
            data: &du3[k],
        });
    }
    let path = dir.join("sensitivity.vtu");
    let set = femu_mesh::FieldSet {
        displacement: Some(&disp),
        point_fields: &fields,
        ..femu_mesh::FieldSet::mesh(&r.model.mesh)
    };
    femu_mesh::VtuWriter
        .write(&path, &set)
        .with_context(|| format!("cannot write {}", path.display()))?;
    Ok(())
}

fn write_ranking_csv(path: &Path, ranking: &[Ranking]) -> Result<()> {
    let mut w = crate::output::create_file(path)?;
    writeln!(
        w,
        "measurement,grouping,worst_c10_relative_sd,worst_d_relative_sd,condition,parameter_relative_sd,worst_relative_sd"
    )?;
    for r in ranking {
        let per: Vec<String> = r
            .identifiability
            .names
            .iter()
            .zip(&r.identifiability.relative_sd)
            .map(|(n, s)| format!("{n}={s:.3e}"))
            .collect();
        let worst: Vec<String> = r
            .worst_relative_sd
            .iter()
            .map(|(f, s)| format!("{f}={s:.3e}"))
            .collect();
        writeln!(
            w,
            "{},{},{:.4e},{:.4e},{:.4e},{},{}",
            r.measurement,
            r.grouping,
            r.worst_c10_relative_sd,
            r.worst_d_relative_sd,
            r.condition,
            per.join(" "),
            worst.join(" ")
        )?;
    }
    crate::output::commit(w)
}

/// The seed's qualitative finding, restated from the numbers: per test, which family of law
/// parameters (C10, D, and C20, C01, ... of the other laws) is the most sensitive (mean of Eq. 3
/// over the tissues), and by which factor over the next.
fn findings(results: &[TestResult], families: &[&str]) -> Vec<String> {
    let kinds = distinct(families);
    results
        .iter()
        .map(|r| {
            let mean = |family: &str| {
                let v: Vec<f64> = families
                    .iter()
                    .zip(&r.global)
                    .filter(|(f, _)| **f == family)
                    .map(|(_, s)| *s)
                    .collect();
                v.iter().sum::<f64>() / v.len().max(1) as f64
            };
            let means: Vec<(&str, f64)> = kinds.iter().map(|&k| (k, mean(k))).collect();
            // Largest first; a tie keeps the declared order (C10 before D).
            let mut order: Vec<usize> = (0..means.len()).collect();
            order.sort_by(|&a, &b| means[b].1.total_cmp(&means[a].1));
            let listed: Vec<String> = means.iter().map(|(k, m)| format!("{k} {m:.3e}")).collect();
            let (Some(&first), Some(&next)) = (order.first(), order.get(1)) else {
                return format!("{}: mean Eq. 3 index {}", r.name, listed.join(", "));
            };
            let best = means[first];
            format!(
                "{}: the {} family is the {} sensitive (mean Eq. 3 index {}; ratio {:.1})",
                r.name,
                best.0,
                if means.len() == 2 { "more" } else { "most" },
                listed.join(", "),
                best.1 / means[next].1
            )
        })
        .collect()
}

/// `sensitivity_maps.png` (one panel per parameter and test, rows sharing a colour scale, the
/// seed's Fig. 8 for every tissue), `sensitivity_quadriceps.png` (the seed's Fig. 8 itself) and
/// `sensitivity_index.png` (Eq. 3 per parameter and test).
fn write_figures(
    out: &Path,
    results: &[TestResult],
    names: &[String],
    progress: &dyn Progress,
) -> Result<()> {
    let panel_dir = out.join("panels");
    femu_mesh::atomic::create_dir_all(&panel_dir)?;
    // One panel per parameter and test, drawn in parallel (each its own file).
    let ranges: Vec<(f64, f64)> = (0..names.len())
        .map(|k| {
            let hi = results
                .iter()
                .flat_map(|r| r.maps[k].iter().cloned())
                .filter(|v| v.is_finite())
                .fold(0.0f64, f64::max);
            (0.0, if hi > 0.0 { hi } else { 1.0 })
        })
        .collect();
    let panels: Vec<Vec<PathBuf>> = names
        .iter()
        .map(|name| {
            results
                .iter()
                .map(|r| panel_dir.join(format!("{}_{name}.png", r.name)))
                .collect()
        })
        .collect();
    let jobs: Vec<(usize, usize)> = (0..names.len())
        .flat_map(|k| (0..results.len()).map(move |t| (k, t)))
        .collect();
    jobs.par_iter().try_for_each(|&(k, t)| -> Result<()> {
        let (r, name, path) = (&results[t], &names[k], &panels[k][t]);
        node_field_png(
            path,
            &r.model.mesh,
            None,
            &r.maps[k],
            &FieldPlot {
                title: format!("{}: S({name}) (Eq. 3, per node)", r.name),
                value_label: format!("θ|∂u/∂θ| / rms|u|, θ = {name}"),
                range: Some(ranges[k]),
                region_of_element: Some(&r.model.element_region),
                width: 700,
                height: 540,
                ..Default::default()
            },
        )
        .with_context(|| format!("cannot draw {}", path.display()))
    })?;
    let cols = results.len();
    let all: Vec<&Path> = panels.iter().flatten().map(|p| p.as_path()).collect();
    tile_png(&out.join("sensitivity_maps.png"), &all, cols)?;
    let quad: Vec<&Path> = names
        .iter()
        .enumerate()
        .filter(|(_, n)| n.ends_with("_QUADRICEPS"))
        .flat_map(|(k, _)| panels[k].iter().map(|p| p.as_path()))
        .collect();
    if !quad.is_empty() {
        tile_png(&out.join("sensitivity_quadriceps.png"), &quad, cols)?;
    }
    let groups: Vec<(String, Vec<f64>)> = results
        .iter()
        .map(|r| (r.name.clone(), r.global.clone()))
        .collect();
    bar_chart_png(
        &out.join("sensitivity_index.png"),
        names,
        &groups,
        None,
        &BarChart {
            title: "Sensitivity index S = ‖θ ∂U/∂θ‖ / ‖U‖ (seed Eq. 3)".into(),
            x_label: "parameter".into(),
            y_label: "S (-)".into(),
            ..Default::default()
        },
    )?;
    progress
        .note("figures: sensitivity_maps.png, sensitivity_quadriceps.png, sensitivity_index.png");
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The worst relative sd of every family of law parameters: with a diagonal information
    /// `F = diag(1/s_k²)` the predicted relative sds are the `s_k` themselves, so each family's
    /// worst is known; the C10 and D keys equal their families', and C20 and C01 (a Yeoh and a
    /// Mooney–Rivlin tissue) have theirs, the worst of all of them setting the ranking's order.
    #[test]
    fn every_family_has_its_worst_sd() {
        let names: Vec<String> = [
            "C10_FAT",
            "C20_FAT",
            "C30_FAT",
            "D_FAT",
            "C10_QUADRICEPS",
            "C01_QUADRICEPS",
            "D_QUADRICEPS",
        ]
        .map(String::from)
        .to_vec();
        let families: Vec<&str> = names.iter().map(|n| n.split('_').next().unwrap()).collect();
        let sd = [0.01, 0.3, 2.0, 0.02, 0.05, 0.4, 0.005];
        let f: Vec<Vec<f64>> = (0..sd.len())
            .map(|i| {
                (0..sd.len())
                    .map(|j| if i == j { 1.0 / (sd[i] * sd[i]) } else { 0.0 })
                    .collect()
            })
            .collect();
        let r = rank(
            "compression",
            "ungrouped",
            &f,
            &Tied::none(&names),
            &families,
        );
        let got: Vec<(&str, f64)> = r
            .worst_relative_sd
            .iter()
            .map(|(k, s)| (k.as_str(), *s))
            .collect();
        let expected = [
            ("C10", 0.05),
            ("C20", 0.3),
            ("C30", 2.0),
            ("D", 0.02),
            ("C01", 0.4),
        ];
        assert_eq!(got.len(), expected.len(), "{got:?}");
        for ((k, s), (ek, es)) in got.iter().zip(expected) {
            assert_eq!(*k, ek);
            // The inverse of a diagonal matrix: exact up to the rounding of 1/s² and its
            // square root.
            assert!((s / es - 1.0).abs() < 1e-12, "{k}: {s} against {es}");
        }
        assert_eq!(r.worst_c10_relative_sd, got[0].1);
        assert_eq!(r.worst_d_relative_sd, got[3].1);
        assert_eq!(r.worst(), got[2].1);
    }
}
