//! The report of a `femu run` / `femu demo` folder: one self-contained HTML file (figures
//! embedded as data URIs, no script, no external resource) and `summary.json` with the numbers
//! of every finished step. Built from the files the steps wrote, so it can be rewritten at any
//! time (`femu report DIR`), also for a run that stopped midway.

mod frames;
mod images;

use crate::bail;
use crate::error::Result;
use crate::html::{esc, g, Page as Html};
use crate::output::{read_json, write_json, write_text, ParameterEntry};
use crate::steps::identify::{FreeParameterSummary, IdentificationSummary};
use crate::steps::model::{DeckModelSummary, MeshSummary};
use crate::steps::record::RunRecord;
use crate::steps::sensitivity::SensitivitySummary;
use crate::steps::solve::{MaterialSummary, RigidBodySummary, SolveSummary};
use crate::steps::ultrasound::SimSummary;
use femu_identify::campaign::Estimate;
use femu_plot::{bar_chart_png, BarChart};
use serde::{Deserialize, Serialize};
use std::collections::BTreeMap;
use std::fmt::Write as _;
use std::path::{Path, PathBuf};

/// The model folder's summary: a meshed thigh, or a deck.
#[derive(Debug, Clone, Serialize, Deserialize)]
#[serde(untagged)]
pub enum ModelSummary {
    Mesh(Box<MeshSummary>),
    Deck(Box<DeckModelSummary>),
}

/// One loading test in the run's summary.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct ForwardOverview {
    pub status: String,
    pub max_displacement_mm: f64,
    pub rigid_bodies: Vec<RigidBodySummary>,
    pub newton_iterations: usize,
    pub solve_s: f64,
}

/// One measurement's predicted identifiability in the run's summary.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct RankingOverview {
    pub measurement: String,
    pub grouping: String,
    pub worst_c10_relative_sd: f64,
    pub worst_d_relative_sd: f64,
    /// The worst predicted relative sd of every family of law parameters (`C10`, `C20`, `D`,
    /// ...).
    #[serde(default)]
    pub worst_relative_sd: Vec<(String, f64)>,
}

/// One test's sensitivity indices in the run's summary.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct TestOverview {
    pub test: String,
    pub sensitivity_index: Vec<(String, f64)>,
    pub sensitivity_over_solve: f64,
}

/// The sensitivity step in the run's summary.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct SensitivityOverview {
    pub finding: Vec<String>,
    pub ranking: Vec<RankingOverview>,
    pub tests: Vec<TestOverview>,
    /// Every parameter of the model as its law declares it (law, unit, key, value).
    #[serde(default)]
    pub parameters: Vec<ParameterEntry>,
}

/// A simulated ultrasound measurement in the run's summary.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct MeasurementOverview {
    pub dic_error: femu_ultrasound::experiment::FieldError,
    pub image_px: (usize, usize),
    pub dic_steps: usize,
}

/// One identification in the run's summary.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct IdentificationOverview {
    /// The estimates (internal units: MPa, MPa⁻¹).
    pub parameters: Vec<Estimate>,
    /// The free parameters in the same order: the law parameters each moves and the unit the
    /// report shows it in.
    #[serde(default)]
    pub free_parameters: Vec<FreeParameterSummary>,
    pub best_cost: f64,
    pub forward_solves_per_start: Vec<usize>,
    pub wall_time_s: f64,
    pub optimizer: String,
    /// The discretization check's finding.
    #[serde(default)]
    pub discretization: Option<String>,
}

/// `summary.json` of a run folder: the numbers a user quotes, per step.
#[derive(Debug, Clone, Default, Serialize, Deserialize)]
pub struct RunSummary {
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub run: Option<RunRecord>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub model: Option<ModelSummary>,
    /// The model's materials as the loading tests were solved with them: each one's law and
    /// every parameter by its study-file key.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub materials: Option<Vec<MaterialSummary>>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub forward: Option<BTreeMap<String, ForwardOverview>>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub sensitivity: Option<SensitivityOverview>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub measurement: Option<MeasurementOverview>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub identification: Option<BTreeMap<String, IdentificationOverview>>,
    /// The identification from images, per grouping: integrated DIC beside DIC → FEMU.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub images: Option<BTreeMap<String, images::ImageOverview>>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub design: Option<Vec<String>>,
}

/// Writes `DIR/report.html` and `DIR/summary.json`; returns the report's path.
pub fn write(dir: &Path) -> Result<PathBuf> {
    if !dir.is_dir() {
        bail!("{} is not an output folder of femu run", dir.display());
    }
    // Only a run's folder: elsewhere the report's summary.json would replace another
    // command's (femu dic, identify, convergence write their own).
    if !dir.join("steps.json").is_file() {
        bail!(
            "{} is not the folder of a femu run or demo (no steps.json): femu report rewrites the report of a run's output folder",
            dir.display()
        );
    }
    let record: Option<RunRecord> = read_json(&dir.join("steps.json")).ok();
    let mut html = Html::default();
    html.head(record.as_ref());
    if let Some(r) = &record {
        html.steps(r);
    }
    let model = model_section(&mut html, &dir.join("model"));
    let materials = materials_section(&mut html, &dir.join("forward"));
    let summary = RunSummary {
        run: record.clone(),
        model,
        materials,
        forward: forward_section(&mut html, &dir.join("forward")),
        sensitivity: sensitivity_section(&mut html, &dir.join("sensitivity")),
        measurement: measurement_section(&mut html, &dir.join("measurement")),
        identification: identification_section(&mut html, dir)?,
        images: image_sections(&mut html, dir),
        design: design_section(&mut html, &dir.join("design")),
    };
    html.convergence(dir);
    if let Ok(text) = std::fs::read_to_string(dir.join("study.toml")) {
        html.h2("Study file");
        html.p("The study as run (<code>study.toml</code> in the output folder).");
        let _ = write!(html.body, "<pre>{}</pre>", esc(&text));
    }
    html.versions(record.as_ref());
    let path = dir.join("report.html");
    write_text(&path, &html.finish("femu report"))?;
    // Keys sorted at every level (as a JSON object's keys have no order).
    write_json(&dir.join("summary.json"), &serde_json::to_value(&summary)?)?;
    Ok(path)
}

fn pct(x: f64) -> String {
    format!("{:.3} %", 100.0 * x)
}

impl Html {
    /// The summary at `path`: `None` when absent, and when it cannot be read (a note in the
    /// report says so, rather than leaving its section out without a word).
    fn read<T: serde::de::DeserializeOwned>(&mut self, path: &Path) -> Option<T> {
        if !path.exists() {
            return None;
        }
        match read_json(path) {
            Ok(v) => Some(v),
            Err(e) => {
                self.p(&format!(
                    "<span class=\"bad\">{} could not be read</span>: {}.",
                    esc(&path.display().to_string()),
                    esc(&e.chain())
                ));
                None
            }
        }
    }

    fn head(&mut self, r: Option<&RunRecord>) {
        let title = match r {
            Some(r) if r.command == "demo" => {
                "femu demo — the seed's numerical example".to_string()
            }
            Some(r) => format!("femu {}", r.command),
            None => "femu report".to_string(),
        };
        let _ = write!(self.body, "<h1>{}</h1>", esc(&title));
        self.p(
            "Finite element model updating of thigh tissues: a plane-strain hyperelastic model of \
             the thigh cross-section (each tissue's law and parameters as the study gives them), \
             loading tests, the displacement field measured on a grid, and the parameters of \
             every tissue identified from it (the seed study's method; equations and figures \
             cited as in the seed).",
        );
    }

    fn steps(&mut self, r: &RunRecord) {
        self.h2("Run");
        let done = r.steps.iter().filter(|s| s.status == "done").count();
        self.p(&format!(
            "<b>{}</b> — {} of {} steps done in {:.1} s on {} threads ({}).",
            esc(&r.command),
            done,
            r.steps.len(),
            r.total_seconds,
            r.threads,
            esc(&r.os)
        ));
        let rows: Vec<Vec<String>> = r
            .steps
            .iter()
            .map(|s| {
                vec![
                    s.name.clone(),
                    s.status.clone(),
                    format!("{:.2}", s.seconds),
                    s.folder.clone().unwrap_or_default(),
                    s.error.clone().unwrap_or_default(),
                ]
            })
            .collect();
        self.table(&["step", "status", "time (s)", "folder", "note"], &rows);
        if let Some(f) = r.steps.iter().find(|s| s.status == "failed") {
            self.p(&format!(
                "<span class=\"bad\">The step <b>{}</b> failed</span>: {}. The sections below show \
                 what the finished steps wrote.",
                esc(&f.name),
                esc(f.error.as_deref().unwrap_or(""))
            ));
        }
    }

    fn convergence(&mut self, dir: &Path) {
        let mut rows = Vec::new();
        for (test, s) in forward_summaries(self, &dir.join("forward")) {
            let max_its = s
                .report
                .increments
                .iter()
                .map(|i| i.iterations.len())
                .max()
                .unwrap_or(0);
            rows.push(vec![
                test,
                s.increments.to_string(),
                s.cutbacks.to_string(),
                s.newton_iterations.to_string(),
                max_its.to_string(),
                s.report.factorizations.to_string(),
            ]);
        }
        let histories: Vec<PathBuf> = ["ungrouped", "grouped"]
            .iter()
            .map(|g| dir.join("identify").join(g).join("cost_history.png"))
            .filter(|p| p.exists())
            .collect();
        if rows.is_empty() && histories.is_empty() {
            return;
        }
        self.h2("Convergence");
        if !rows.is_empty() {
            self.p(
                "Newton–Raphson of each loading test (force residual ≤ 1e-8 of the load, energy \
                 ≤ 1e-9 of the first correction; contact by augmented Lagrangian). The mesh \
                 convergence study is <code>femu convergence</code>.",
            );
            self.table(
                &[
                    "test",
                    "increments",
                    "cut-backs",
                    "Newton iterations",
                    "most per increment",
                    "factorizations",
                ],
                &rows,
            );
        }
        for p in histories {
            let g = p
                .parent()
                .and_then(|d| d.file_name())
                .map(|n| n.to_string_lossy().to_string())
                .unwrap_or_default();
            self.figure(
                &p,
                &format!("Cost of the identification ({g}) over the optimizer's iterations, every start."),
            );
        }
    }

    fn versions(&mut self, r: Option<&RunRecord>) {
        self.h2("Versions");
        let mut rows = vec![
            vec!["femu".into(), env!("CARGO_PKG_VERSION").into()],
            vec![
                "report written by".into(),
                format!("femu {}", env!("CARGO_PKG_VERSION")),
            ],
        ];
        rows.push(vec!["compiler".into(), env!("FEMU_RUSTC_VERSION").into()]);
        rows.push(vec!["libraries".into(), env!("FEMU_CRATE_VERSIONS").into()]);
        if let Some(r) = r {
            rows[0][1] = r.femu_version.clone();
            rows.push(vec![
                "run started (unix time, s)".into(),
                r.started_unix_s.to_string(),
            ]);
            rows.push(vec!["platform".into(), r.os.clone()]);
        }
        self.table(&["", ""], &rows);
    }
}

/// The forward summaries `(test, summary.json)` in test order of the folder.
fn forward_summaries(html: &mut Html, dir: &Path) -> Vec<(String, SolveSummary)> {
    let Ok(entries) = std::fs::read_dir(dir) else {
        return Vec::new();
    };
    let mut v: Vec<(String, SolveSummary)> = entries
        .filter_map(|e| e.ok())
        .filter_map(|e| {
            let name = e.file_name().to_string_lossy().to_string();
            html.read(&e.path().join("summary.json")).map(|s| (name, s))
        })
        .collect();
    v.sort_by_key(|(n, _)| {
        (
            ["contention", "compression", "indentation"]
                .iter()
                .position(|k| n.starts_with(k))
                .unwrap_or(9),
            n.clone(),
        )
    });
    v
}

fn model_section(html: &mut Html, dir: &Path) -> Option<ModelSummary> {
    let path = dir.join("summary.json");
    let s: ModelSummary = match html.read::<MeshSummary>(&path) {
        Some(m) => ModelSummary::Mesh(Box::new(m)),
        None => ModelSummary::Deck(Box::new(html.read(&path)?)),
    };
    html.h2("Model");
    let (nodes, elements, element, size, q) = match &s {
        ModelSummary::Mesh(m) => (
            m.nodes,
            m.elements,
            m.element.as_str(),
            Some(m.element_size_mm),
            &m.quality.total,
        ),
        ModelSummary::Deck(d) => (d.nodes, d.elements, "", None, &d.quality.total),
    };
    html.p(&format!(
        "{} nodes, {} {} elements{}; scaled Jacobian {}–{}, corner angles {:.1}–{:.1}°, {} elements \
         below 0.3. Femur edge fixed. Files: <code>model/mesh.inp</code> (runs in \
         CalculiX/Abaqus), <code>model/mesh.vtu</code> (ParaView).",
        nodes,
        elements,
        esc(element),
        size.map(|h| format!(" of about {h:.2} mm"))
            .unwrap_or_default(),
        g(q.min_scaled_jacobian),
        g(q.max_scaled_jacobian),
        q.min_angle_deg,
        q.max_angle_deg,
        q.below_0_3,
    ));
    if let ModelSummary::Mesh(m) = &s {
        let rows: Vec<Vec<String>> = m
            .regions
            .iter()
            .map(|(name, r)| {
                vec![
                    name.clone(),
                    r.elements.to_string(),
                    format!("{:.1}", r.area_mm2),
                ]
            })
            .collect();
        html.table(&["region", "elements", "area (mm²)"], &rows);
    }
    html.figure(
        &dir.join("regions.png"),
        "The model's regions (tissues) and mesh.",
    );
    Some(s)
}

/// The materials the loading tests were solved with (the first test's summary: every test
/// solves the same model): one row per material, its law and each parameter of the law with
/// its unit, whatever the law.
fn materials_section(html: &mut Html, dir: &Path) -> Option<Vec<MaterialSummary>> {
    let (_, first) = forward_summaries(html, dir).into_iter().next()?;
    let materials = first.materials;
    if materials.iter().all(|m| m.parameters.is_empty()) {
        return Some(materials); // written before the summaries listed every parameter
    }
    html.h2("Materials");
    html.p(
        "Each tissue's law and its parameters as the loading tests were solved with them (the \
         reference values; study-file keys and their units).",
    );
    let rows: Vec<Vec<String>> = materials
        .iter()
        .map(|m| {
            // In the law's order (C10, C01, D), else the keys' (alphabetical).
            let mut keyed: Vec<(&String, &f64)> = m.parameters.iter().collect();
            if let Ok(law) = femu_mech::material::law(&m.law) {
                let order: Vec<String> = law
                    .spec
                    .parameters
                    .iter()
                    .map(crate::output::shown_key)
                    .collect();
                keyed.sort_by_key(|(key, _)| order.iter().position(|k| k == *key));
            }
            let values: Vec<String> = keyed
                .iter()
                .map(|(key, v)| format!("{} = {}", parameter_label(key), g(**v)))
                .collect();
            vec![
                m.name.clone(),
                m.law.clone(),
                values.join(", "),
                m.elements.to_string(),
            ]
        })
        .collect();
    html.table(&["tissue", "law", "parameters", "elements"], &rows);
    Some(materials)
}

/// A study-file key as a label: `c20_kpa` → `C20 (kPa)`, `d_per_mpa` → `D (MPa⁻¹)`, from the
/// registered laws' declarations (the key itself when no law knows it).
fn parameter_label(key: &str) -> String {
    femu_mech::material::LAWS
        .iter()
        .flat_map(|l| l.spec.parameters.iter())
        .find(|p| crate::output::shown_key(p) == key)
        .map_or(key.to_string(), |p| {
            format!("{} ({})", p.name, p.unit.report().0)
        })
}

/// The internal unit (MPa, MPa⁻¹) of a model parameter named `KIND_MATERIAL` (or a tied group
/// of them), from the registered laws; empty when no law declares its kind.
pub(crate) fn internal_unit(name: &str) -> &'static str {
    let kind = name.split('_').next().unwrap_or("");
    femu_mech::material::LAWS
        .iter()
        .flat_map(|l| l.spec.parameters.iter())
        .find(|p| p.name == kind)
        .map_or("", |p| p.unit.symbol())
}

fn forward_section(html: &mut Html, dir: &Path) -> Option<BTreeMap<String, ForwardOverview>> {
    let summaries = forward_summaries(html, dir);
    if summaries.is_empty() {
        return None;
    }
    html.h2("Loading tests (seed Fig. 3)");
    html.p(
        "Each test solved with the reference (Table 1) parameters; the deformed shapes are \
         coloured by the logarithmic strain LE11 as in the seed's Fig. 3.",
    );
    let rows: Vec<Vec<String>> = summaries
        .iter()
        .map(|(test, s)| {
            let b = s.rigid_bodies.first();
            let or_dash =
                |f: fn(&RigidBodySummary) -> f64| b.map(|b| g(f(b))).unwrap_or("-".into());
            vec![
                test.clone(),
                s.status.clone(),
                g(s.max_displacement_mm),
                or_dash(|b| b.travel_mm),
                or_dash(|b| b.force_n_per_mm),
                or_dash(|b| b.max_penetration_mm),
                s.newton_iterations.to_string(),
                format!("{:.2}", s.timings.solve_s),
            ]
        })
        .collect();
    html.table(
        &[
            "test",
            "status",
            "max |u| (mm)",
            "rigid-body travel (mm)",
            "contact force (N/mm)",
            "penetration (mm)",
            "Newton iterations",
            "solve (s)",
        ],
        &rows,
    );
    let mut out = BTreeMap::new();
    for (test, s) in summaries {
        html.h3(&test);
        let d = dir.join(&test);
        html.figure(
            &d.join("deformed_le11.png"),
            &format!("{test}: deformed shape (true scale) coloured by LE11."),
        );
        html.figure(
            &d.join("contact_pressure.png"),
            &format!("{test}: contact pressure along the skin."),
        );
        html.figure(
            &d.join("force_displacement.png"),
            &format!("{test}: force–travel curve of the rigid body over the increments."),
        );
        out.insert(
            test,
            ForwardOverview {
                status: s.status,
                max_displacement_mm: s.max_displacement_mm,
                rigid_bodies: s.rigid_bodies,
                newton_iterations: s.newton_iterations,
                solve_s: s.timings.solve_s,
            },
        );
    }
    Some(out)
}

fn sensitivity_section(html: &mut Html, dir: &Path) -> Option<SensitivityOverview> {
    let s: SensitivitySummary = html.read(&dir.join("summary.json"))?;
    html.h2("Sensitivity and test ranking (seed Eq. 3, Fig. 8)");
    html.p(
        "Exact derivatives of the displacement field with respect to each parameter (direct \
         differentiation, one back-substitution per parameter); S = ‖θ ∂U/∂θ‖ / ‖U‖ per test.",
    );
    let items: String = s
        .finding
        .iter()
        .map(|l| format!("<li>{}</li>", esc(l)))
        .collect();
    let _ = write!(html.body, "<ul>{items}</ul>");
    test_sensitivity_table(html, &s.tests);
    html.figure(
        &dir.join("sensitivity_index.png"),
        "Global sensitivity index of each parameter in each test (Eq. 3).",
    );
    html.figure(
        &dir.join("sensitivity_quadriceps.png"),
        "Sensitivity maps of every parameter of the quadriceps per test (the seed's Fig. 8); \
         colour scale shared per row.",
    );
    html.figure(
        &dir.join("sensitivity_maps.png"),
        "Sensitivity maps of every parameter (rows) in every test (columns).",
    );
    law_parameters_table(html, &s.law_parameters);
    html.h3("Which test to measure: predicted parameter errors (Cramér–Rao)");
    ranking_table(html, &s);
    Some(SensitivityOverview {
        finding: s.finding,
        ranking: s
            .ranking
            .into_iter()
            .map(|x| RankingOverview {
                measurement: x.measurement,
                grouping: x.grouping,
                worst_c10_relative_sd: x.worst_c10_relative_sd,
                worst_d_relative_sd: x.worst_d_relative_sd,
                worst_relative_sd: x.worst_relative_sd,
            })
            .collect(),
        tests: s
            .tests
            .into_iter()
            .map(|x| TestOverview {
                test: x.test,
                sensitivity_index: x.sensitivity_index,
                sensitivity_over_solve: x.sensitivity_over_solve,
            })
            .collect(),
        parameters: s.law_parameters,
    })
}

/// The global sensitivity index of each parameter in each test, and the cost of the
/// sensitivities against the solve's.
fn test_sensitivity_table(html: &mut Html, tests: &[crate::steps::sensitivity::TestSummary]) {
    if let Some(first) = tests.first() {
        let mut header = vec!["test".to_string()];
        header.extend(first.sensitivity_index.iter().map(|p| p.0.clone()));
        header.push("sensitivities / solve".into());
        let rows: Vec<Vec<String>> = tests
            .iter()
            .map(|t| {
                let mut r = vec![t.test.clone()];
                r.extend(t.sensitivity_index.iter().map(|p| g(p.1)));
                r.push(format!("{:.0} %", 100.0 * t.sensitivity_over_solve));
                r
            })
            .collect();
        let h: Vec<&str> = header.iter().map(String::as_str).collect();
        html.table(&h, &rows);
    }
}

/// The predicted parameter errors (Cramér–Rao) of each measurement, per grouping: the worst
/// relative sd of each family of law parameters.
fn ranking_table(html: &mut Html, s: &SensitivitySummary) {
    // The families of law parameters (C10, C20, C01, D, ...); a summary written before they
    // were listed has C10 and D.
    let mut families: Vec<String> = Vec::new();
    for r in &s.ranking {
        for (f, _) in &r.worst_relative_sd {
            if !families.contains(f) {
                families.push(f.clone());
            }
        }
    }
    let worst_of = |r: &crate::steps::sensitivity::Ranking, f: &str| {
        r.worst_relative_sd
            .iter()
            .find(|w| w.0 == f)
            .map(|w| w.1)
            .or(match f {
                "C10" => Some(r.worst_c10_relative_sd),
                "D" => Some(r.worst_d_relative_sd),
                _ => None,
            })
    };
    if families.is_empty() {
        families = vec!["C10".into(), "D".into()];
    }
    html.p(&format!(
        "Fisher information of the {} grid points in the tissue ({} mm apart) with noise \
         σ = {} mm; the worst predicted relative standard deviation of each family of \
         parameters ({}); best first within each grouping.",
        s.grid_points_in_tissue,
        g(s.grid_spacing_mm),
        g(s.noise_sigma_mm),
        families.join(", ")
    ));
    let rows: Vec<Vec<String>> = s
        .ranking
        .iter()
        .map(|r| {
            let mut row = vec![r.measurement.clone(), r.grouping.clone()];
            row.extend(
                families
                    .iter()
                    .map(|f| worst_of(r, f).map_or("-".into(), pct)),
            );
            row.push(g(r.condition));
            row
        })
        .collect();
    let worst_headers: Vec<String> = families.iter().map(|f| format!("worst {f} sd")).collect();
    let mut header = vec!["measured test(s)", "grouping"];
    header.extend(worst_headers.iter().map(String::as_str));
    header.push("condition number");
    html.table(&header, &rows);
}

/// Every parameter of the model with its law, value and unit (the units reports show: C10 in
/// kPa, D in MPa⁻¹, as the seed's Table 1).
fn law_parameters_table(html: &mut Html, parameters: &[ParameterEntry]) {
    if parameters.is_empty() {
        return;
    }
    let rows: Vec<Vec<String>> = parameters
        .iter()
        .map(|p| {
            vec![
                p.name.clone(),
                p.material.clone(),
                p.law.clone(),
                g(p.shown),
                p.shown_unit.clone(),
                if p.log_scale { "log" } else { "linear" }.to_string(),
            ]
        })
        .collect();
    html.table(
        &["parameter", "tissue", "law", "value", "unit", "scale"],
        &rows,
    );
}

/// The images of a simulated ultrasound measurement (`femu us-sim`) and the DIC's error
/// against the FE field.
fn measurement_section(html: &mut Html, dir: &Path) -> Option<MeasurementOverview> {
    let s: SimSummary = html.read(&dir.join("summary.json"))?;
    html.h2("Measurement: simulated ultrasound and DIC");
    let e = &s.error;
    html.p(&format!(
        "B-mode images of the unloaded and loaded thigh ({} x {} px, {} scatterers moved by the FE \
         field of a mesh of {} elements (render_refine {}: finer than the one identified), {} of \
         the scatterers renewed per load step (decorrelation), {} MHz, gain {} dB, dynamic {} dB) \
         correlated by the global Q4 DIC in {} load steps. DIC against the FE field over {} points \
         in the tissue: RMS ({}, {}) px = ({}, {}) mm, largest ({}, {}) px, for displacements up \
         to {} px.",
        s.image_px.0,
        s.image_px.1,
        s.scatterers,
        s.render_elements,
        s.render_refine,
        pct(s.decorrelation),
        g(s.transducer.frequency_mhz),
        g(s.scanner.gain_db),
        g(s.scanner.dynamic_db),
        s.dic_steps,
        e.points,
        g(e.rms_px[0]),
        g(e.rms_px[1]),
        g(e.rms_mm[0]),
        g(e.rms_mm[1]),
        g(e.max_abs_px[0]),
        g(e.max_abs_px[1]),
        g(e.max_true_px),
    ));
    for (f, caption) in [
        ("ref.png", "Simulated B-mode image, unloaded."),
        (
            "def.png",
            "Simulated B-mode image, loaded (the same scatterers moved by the FE field).",
        ),
        (
            "uy_dic.png",
            "DIC displacement uy (depth) over the reference image.",
        ),
        ("error_ux.png", "DIC minus FE, ux."),
        ("error_uy.png", "DIC minus FE, uy."),
    ] {
        html.figure(&dir.join(f), caption);
    }
    Some(MeasurementOverview {
        dic_error: s.error,
        image_px: s.image_px,
        dic_steps: s.dic_steps,
    })
}

/// The identification from images of each grouping (`identify/GROUPING/` holding the routes).
fn image_sections(html: &mut Html, dir: &Path) -> Option<BTreeMap<String, images::ImageOverview>> {
    for g in ["ungrouped", "grouped"] {
        let at = dir.join("identify").join(g);
        if frames::is_frames_route(&at, &dir.join("measurement")) {
            frames::section(html, g, &at, &dir.join("measurement"));
        }
    }
    let groupings: Vec<&str> = ["ungrouped", "grouped"]
        .into_iter()
        .filter(|g| images::is_image_route(&dir.join("identify").join(g)))
        .filter(|g| {
            !frames::is_frames_route(&dir.join("identify").join(g), &dir.join("measurement"))
        })
        .collect();
    if groupings.is_empty() {
        return None;
    }
    html.h2("Identification from images");
    let mut out = BTreeMap::new();
    for g in groupings {
        if let Some(o) = images::section(
            html,
            g,
            &dir.join("identify").join(g),
            &dir.join("measurement"),
        ) {
            out.insert(g.to_string(), o);
        }
    }
    Some(out)
}

fn identification_section(
    html: &mut Html,
    dir: &Path,
) -> Result<Option<BTreeMap<String, IdentificationOverview>>> {
    let results: Vec<(String, IdentificationSummary)> = ["ungrouped", "grouped"]
        .iter()
        .filter(|g| !images::is_image_route(&dir.join("identify").join(g)))
        .filter(|g| {
            !frames::is_frames_route(&dir.join("identify").join(g), &dir.join("measurement"))
        })
        .filter_map(|g| {
            html.read(&dir.join("identify").join(g).join("summary.json"))
                .map(|s| (g.to_string(), s))
        })
        .collect();
    if results.is_empty() {
        return Ok(None);
    }
    html.h2("Identification (seed Fig. 9)");
    let first = &results[0].1;
    html.p(&format!(
        "Test <b>{}</b> measured at {} grid points in the tissue ({} outside it masked), from {}; noise \
         σ = {} mm. Optimizer {} from {} Latin-hypercube starts; relative error of Eq. 4 when the \
         reference is known; 95 % confidence intervals from the Jacobian at the optimum.",
        esc(&first.test),
        first.points_in_tissue,
        first.points_masked,
        esc(&first.measured),
        g(first.noise_sigma_mm),
        esc(&first.optimizer),
        first.starts_per_repeat,
    ));
    let mut out = BTreeMap::new();
    for (grouping, s) in &results {
        html.h3(&format!("{grouping} parameters"));
        measurements_table(html, s);
        let solves: Vec<String> = s
            .forward_solves_per_start
            .iter()
            .map(|v| v.to_string())
            .collect();
        html.p(&format!(
            "Best cost {}; forward solves per start: {}; {:.1} s.",
            g(s.best_cost),
            solves.join(", "),
            s.wall_time_s
        ));
        if !s.warnings.is_empty() {
            html.p(&format!(
                "<b>Warning</b>: {}",
                s.warnings
                    .iter()
                    .map(|w| esc(w))
                    .collect::<Vec<_>>()
                    .join("; ")
            ));
        }
        parameters_table(html, s);
        discretization_paragraph(html, s);
        let d = dir.join("identify").join(grouping);
        html.figure(
            &d.join("fields.png"),
            &format!("{grouping}: measured and identified-model displacements on the grid, and the residual."),
        );
        out.insert(
            grouping.clone(),
            IdentificationOverview {
                parameters: s.parameters.clone(),
                free_parameters: s.free_parameters.clone(),
                best_cost: s.best_cost,
                forward_solves_per_start: s.forward_solves_per_start.clone(),
                wall_time_s: s.wall_time_s,
                optimizer: s.optimizer.clone(),
                discretization: s.discretization.as_ref().map(|d| d.message.clone()),
            },
        );
    }
    if let Some(path) = fig9(dir, &results)? {
        html.figure(
            &path,
            "Relative identification errors (Eq. 4) per parameter, ungrouped and with D of ischio, \
             sartorius and gracilis grouped (the seed's Fig. 9); bars: the predicted (Cramér–Rao) \
             standard deviation.",
        );
    } else {
        for (grouping, _) in &results {
            html.figure(
                &dir.join("identify").join(grouping).join("errors.png"),
                &format!("{grouping}: relative identification errors (Eq. 4)."),
            );
        }
    }
    Ok(Some(out))
}

/// The identified parameters: reference, value, error, interval (widened by the
/// discretization bias when it is not negligible), sd; over repeats the worst error and the
/// interval coverage.
fn parameters_table(html: &mut Html, s: &IdentificationSummary) {
    let repeats = s.parameters.iter().any(|p| p.coverage95.is_some());
    // On a measured field: which term set each interval's width (Fisher, Birge ratio or the
    // jackknife over depth blocks, `femu_identify::misfit_intervals`).
    let widths = s.parameters.iter().any(|p| p.width_from.is_some());
    // In the units of the seed's Table 1 (C10 kPa, D MPa⁻¹).
    let rows: Vec<Vec<String>> = s
        .parameters
        .iter()
        .zip(&s.free_parameters)
        .map(|(p, f)| {
            let mut row = vec![
                p.name.clone(),
                f.unit.clone(),
                p.reference.map(|v| g(f.shown(v))).unwrap_or("-".into()),
                g(f.shown(p.identified)),
                p.relative_error.map(pct).unwrap_or("-".into()),
                format!("[{}, {}]", g(f.shown(p.ci95[0])), g(f.shown(p.ci95[1]))),
                pct(p.relative_sd),
                p.discretization_bias.map(pct).unwrap_or("-".into()),
            ];
            if widths {
                row.push(p.width_from.as_deref().unwrap_or("-").to_string());
            }
            if repeats {
                row.push(p.max_relative_error.map(pct).unwrap_or("-".into()));
                row.push(
                    p.coverage95
                        .map(|c| format!("{:.0} %", 100.0 * c))
                        .unwrap_or("-".into()),
                );
            }
            row
        })
        .collect();
    let mut header = vec![
        "parameter",
        "unit",
        "reference",
        "identified",
        "error (Eq. 4)",
        "95 % interval",
        "relative sd",
        "mesh bias",
    ];
    if widths {
        header.push("width set by");
    }
    if repeats {
        header.push("worst error over repeats");
        header.push("interval coverage");
    }
    html.table(&header, &rows);
}

/// Each measurement's points and share of the information (a joint identification).
fn measurements_table(html: &mut Html, s: &IdentificationSummary) {
    if s.measurements.len() < 2 {
        return;
    }
    html.p(
        "Measurements fitted together (one cost, the exact Jacobian): each one's points and its \
         share of the Fisher information of each parameter (the diagonal of JᵀJ; shares add to \
         100 %), then the relative sd it would give alone.",
    );
    let mut header = vec!["measurement".to_string(), "points".to_string()];
    header.extend(s.free_parameters.iter().map(|f| f.name.clone()));
    let rows: Vec<Vec<String>> = s
        .measurements
        .iter()
        .flat_map(|m| {
            let mut share = vec![m.label.clone(), m.points_in_tissue.to_string()];
            share.extend(
                m.information
                    .share
                    .iter()
                    .map(|v| format!("{:.1} %", 100.0 * v)),
            );
            let mut alone = vec![format!("{} alone: sd", m.name), String::new()];
            alone.extend(m.information.alone_relative_sd.iter().map(|v| pct(*v)));
            [share, alone]
        })
        .collect();
    let h: Vec<&str> = header.iter().map(String::as_str).collect();
    html.table(&h, &rows);
}

/// The discretization check: what refined meshes say about the bias of the mesh.
fn discretization_paragraph(html: &mut Html, s: &IdentificationSummary) {
    let Some(d) = &s.discretization else {
        return;
    };
    let class = if d.status == "negligible" {
        ""
    } else {
        " class=\"bad\""
    };
    let meshes: Vec<String> = d
        .levels
        .iter()
        .map(|l| format!("{} elements", l.elements))
        .collect();
    html.p(&format!(
        "<b>Discretization</b> (mesh of {} elements{}): <span{class}>{}</span>.",
        d.elements,
        if meshes.is_empty() {
            String::new()
        } else {
            format!(", refined: {}", meshes.join(", "))
        },
        esc(&d.message)
    ));
}

/// The design step: the best designs, the best single test per family, the figures.
fn design_section(html: &mut Html, dir: &Path) -> Option<Vec<String>> {
    let s: crate::steps::design::DesignSummary = html.read(&dir.join("summary.json"))?;
    html.h2("Design of the experiment: tests and probe windows");
    html.p(&format!(
        "Each test solved once at the reference and differentiated exactly; each probe window a \
         grid of points in the tissue it sees, with noise σ = {} mm. {} designs of up to {} \
         measurements ranked by the predicted parameter uncertainty (Cramér–Rao): the \
         A-optimal criterion (RMS relative sd) and the D-optimal one (geometric mean of the \
         sds along the ellipsoid's axes); {} free parameters{}.",
        g(s.noise_sigma_mm),
        s.designs_ranked,
        s.designs
            .iter()
            .map(|d| d.measurements.len())
            .max()
            .unwrap_or(1),
        s.parameters.len(),
        if s.grouped { ", groups tied" } else { "" }
    ));
    let items: String = s
        .finding
        .iter()
        .map(|l| format!("<li>{}</li>", esc(l)))
        .collect();
    let _ = write!(html.body, "<ul>{items}</ul>");
    let families: Vec<String> = {
        let mut f: Vec<String> = Vec::new();
        for (_, fam) in &s.parameters {
            if !f.contains(fam) {
                f.push(fam.clone());
            }
        }
        f
    };
    let mut header = vec![
        "rank (A)",
        "rank (D)",
        "design",
        "A: RMS sd",
        "D: geometric sd",
    ];
    let worst: Vec<String> = families.iter().map(|f| format!("worst {f} sd")).collect();
    header.extend(worst.iter().map(String::as_str));
    header.push("not identifiable");
    let rows: Vec<Vec<String>> = s
        .designs
        .iter()
        .take(20)
        .map(|d| {
            let mut r = vec![
                d.rank_a.to_string(),
                d.rank_d.to_string(),
                d.measurements.join(" + "),
                pct(d.a_criterion),
                pct(d.d_criterion),
            ];
            r.extend(families.iter().map(|f| {
                d.worst_by_family
                    .iter()
                    .find(|(x, _)| x == f)
                    .map_or("-".into(), |w| pct(w.1))
            }));
            r.push(if d.not_identifiable.is_empty() {
                "—".into()
            } else {
                d.not_identifiable.join(", ")
            });
            r
        })
        .collect();
    html.table(&header, &rows);
    html.figure(
        &dir.join("designs.png"),
        "The best designs: A-optimal criterion and worst predicted sd of each family against the rank.",
    );
    html.figure(
        &dir.join("candidates.png"),
        "Each probe window of each test alone: worst predicted C10 sd against worst D sd (log–log).",
    );
    Some(s.finding)
}

/// Writes `DIR/report.html` of a `femu design` folder (the design section alone).
pub fn write_design(dir: &Path) -> Result<PathBuf> {
    let mut html = Html::default();
    let _ = write!(html.body, "<h1>femu design</h1>");
    if design_section(&mut html, dir).is_none() {
        bail!("{} holds no design summary", dir.display());
    }
    let path = dir.join("report.html");
    write_text(&path, &html.finish("femu design"))?;
    Ok(path)
}

/// The Fig. 9 chart of both groupings side by side (`identify/fig9_errors.png`), when the
/// reference is known.
fn fig9(dir: &Path, results: &[(String, IdentificationSummary)]) -> Result<Option<PathBuf>> {
    // The model parameters (from the ungrouped run, else the members of the grouped names).
    let mut names: Vec<String> = Vec::new();
    for (_, s) in results {
        for p in &s.parameters {
            for n in p.name.split('+') {
                if !names.iter().any(|m| m == n) {
                    names.push(n.to_string());
                }
            }
        }
    }
    let mut series = Vec::new();
    let mut bars = Vec::new();
    for (grouping, s) in results {
        let mut values = Vec::new();
        let mut sds = Vec::new();
        for n in &names {
            let p = s
                .parameters
                .iter()
                .find(|p| p.name.split('+').any(|k| k == n));
            values.push(
                p.and_then(|p| p.relative_error)
                    .map_or(f64::NAN, |e| 100.0 * e),
            );
            sds.push(p.map_or(0.0, |p| 100.0 * p.relative_sd));
        }
        if values.iter().all(|v| v.is_nan()) {
            return Ok(None);
        }
        series.push((grouping.clone(), values));
        bars.push(sds);
    }
    let path = dir.join("identify").join("fig9_errors.png");
    bar_chart_png(
        &path,
        &names,
        &series,
        Some(&bars),
        &BarChart {
            title: "Identification errors (seed Eq. 4, Fig. 9)".into(),
            x_label: "parameter".into(),
            y_label: "relative error (%)".into(),
            width: 1100,
            height: 520,
            ..Default::default()
        },
    )?;
    Ok(Some(path))
}
