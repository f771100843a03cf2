//! The report of a `femu run` / `femu demo` folder: one self-contained HTML file (figures
//! embedded as data URIs, no script, no external resource) and `summary.json` with the numbers
//! of every finished step. Built from the files the steps wrote, so it can be rewritten at any
//! time (`femu report DIR`), also for a run that stopped midway.

use crate::steps::run::RunRecord;
use anyhow::{Context, Result};
use base64::Engine;
use femu_plot::{bar_chart_png, BarChart};
use serde_json::{json, Value};
use std::fmt::Write as _;
use std::path::{Path, PathBuf};

/// Writes `DIR/report.html` and `DIR/summary.json`; returns the report's path.
pub fn write(dir: &Path) -> Result<PathBuf> {
    if !dir.is_dir() {
        anyhow::bail!("{} is not an output folder of femu run", dir.display());
    }
    let record: Option<RunRecord> =
        read_json(&dir.join("steps.json")).and_then(|v| serde_json::from_value(v).ok());
    let mut html = Html::default();
    let mut summary = serde_json::Map::new();
    html.head(record.as_ref());
    if let Some(r) = &record {
        summary.insert("run".into(), serde_json::to_value(r)?);
        html.steps(r);
    }
    if let Some(v) = model_section(&mut html, &dir.join("model")) {
        summary.insert("model".into(), v);
    }
    if let Some(v) = forward_section(&mut html, &dir.join("forward")) {
        summary.insert("forward".into(), v);
    }
    if let Some(v) = sensitivity_section(&mut html, &dir.join("sensitivity")) {
        summary.insert("sensitivity".into(), v);
    }
    if let Some(v) = measurement_section(&mut html, &dir.join("measurement")) {
        summary.insert("measurement".into(), v);
    }
    if let Some(v) = identification_section(&mut html, dir)? {
        summary.insert("identification".into(), v);
    }
    html.convergence(dir);
    if let Ok(text) = std::fs::read_to_string(dir.join("study.toml")) {
        html.h2("Study file");
        html.p("The study as run (<code>study.toml</code> in the output folder).");
        let _ = write!(html.body, "<pre>{}</pre>", esc(&text));
    }
    html.versions(record.as_ref());
    let path = dir.join("report.html");
    std::fs::write(&path, html.finish())
        .with_context(|| format!("cannot write {}", path.display()))?;
    let spath = dir.join("summary.json");
    std::fs::write(
        &spath,
        serde_json::to_string_pretty(&Value::Object(summary))?,
    )
    .with_context(|| format!("cannot write {}", spath.display()))?;
    Ok(path)
}

fn read_json(path: &Path) -> Option<Value> {
    serde_json::from_str(&std::fs::read_to_string(path).ok()?).ok()
}

fn esc(s: &str) -> String {
    s.replace('&', "&amp;")
        .replace('<', "&lt;")
        .replace('>', "&gt;")
        .replace('"', "&quot;")
}

fn num(v: &Value) -> Option<f64> {
    v.as_f64()
}

/// `x` with 4 significant digits.
fn g(x: f64) -> String {
    if x == 0.0 || !x.is_finite() {
        return format!("{x}");
    }
    let a = x.abs();
    if (1e-3..1e5).contains(&a) {
        let d = (3 - a.log10().floor() as i32).max(0) as usize;
        format!("{x:.d$}")
    } else {
        format!("{x:.3e}")
    }
}

fn pct(x: f64) -> String {
    format!("{:.3} %", 100.0 * x)
}

#[derive(Default)]
struct Html {
    body: String,
    toc: Vec<(String, String)>,
    figures: usize,
}

impl Html {
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
            "Finite element model updating of thigh tissues: a plane-strain Neo-Hookean model of \
             the thigh cross-section, loading tests, the displacement field measured on a grid, \
             and C10 and D of every tissue identified from it (the seed study's method; \
             equations and figures cited as in the seed).",
        );
    }

    fn h2(&mut self, title: &str) {
        let id = format!("s{}", self.toc.len() + 1);
        let _ = write!(self.body, "<h2 id=\"{id}\">{}</h2>", esc(title));
        self.toc.push((id, title.to_string()));
    }

    fn h3(&mut self, title: &str) {
        let _ = write!(self.body, "<h3>{}</h3>", esc(title));
    }

    /// A paragraph of trusted HTML.
    fn p(&mut self, html: &str) {
        let _ = write!(self.body, "<p>{html}</p>");
    }

    fn table(&mut self, header: &[&str], rows: &[Vec<String>]) {
        self.body.push_str("<table><thead><tr>");
        for h in header {
            let _ = write!(self.body, "<th>{}</th>", esc(h));
        }
        self.body.push_str("</tr></thead><tbody>");
        for r in rows {
            self.body.push_str("<tr>");
            for c in r {
                let _ = write!(self.body, "<td>{}</td>", esc(c));
            }
            self.body.push_str("</tr>");
        }
        self.body.push_str("</tbody></table>");
    }

    /// Embeds a PNG with a numbered caption; nothing if the file is missing.
    fn figure(&mut self, path: &Path, caption: &str) -> bool {
        let Ok(bytes) = std::fs::read(path) else {
            return false;
        };
        self.figures += 1;
        let data = base64::engine::general_purpose::STANDARD.encode(bytes);
        let _ = write!(
            self.body,
            "<figure><img alt=\"{}\" src=\"data:image/png;base64,{data}\"><figcaption>Figure {}. {}</figcaption></figure>",
            esc(caption),
            self.figures,
            esc(caption)
        );
        true
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
        for (test, s) in forward_summaries(&dir.join("forward")) {
            let inc = &s["report"]["increments"];
            let max_its = inc
                .as_array()
                .map(|a| {
                    a.iter()
                        .filter_map(|i| i["iterations"].as_array().map(Vec::len))
                        .max()
                        .unwrap_or(0)
                })
                .unwrap_or(0);
            rows.push(vec![
                test,
                s["increments"].to_string(),
                s["cutbacks"].to_string(),
                s["newton_iterations"].to_string(),
                max_its.to_string(),
                s["report"]["factorizations"].to_string(),
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

    fn finish(self) -> String {
        let mut toc = String::from("<nav><b>Contents</b><ol>");
        for (id, t) in &self.toc {
            let _ = write!(toc, "<li><a href=\"#{id}\">{}</a></li>", esc(t));
        }
        toc.push_str("</ol></nav>");
        format!(
            "<!DOCTYPE html>\n<html lang=\"en\"><head><meta charset=\"utf-8\">\
             <meta name=\"viewport\" content=\"width=device-width, initial-scale=1\">\
             <title>femu report</title><style>{CSS}</style></head><body>{toc}<main>{}</main></body></html>\n",
            self.body
        )
    }
}

const CSS: &str = "body{font-family:system-ui,sans-serif;margin:0;display:flex;color:#222}\
nav{position:sticky;top:0;align-self:flex-start;width:220px;padding:1em;font-size:90%}\
main{max-width:1100px;min-width:0;flex:1;padding:1em 2em}h1{font-size:1.6em}h2{border-bottom:1px solid #ccc;margin-top:2em}\
table{border-collapse:collapse;margin:0.5em 0;font-size:85%;max-width:100%}td,th{border:1px solid #ccc;padding:3px 8px;text-align:right}\
th{background:#f2f2f2}td:first-child{text-align:left}figure{margin:1em 0}img{max-width:100%;border:1px solid #eee}\
figcaption{font-size:90%;color:#555}pre{background:#f7f7f7;padding:1em;overflow:auto;font-size:85%}\
.bad{color:#b00}";

/// The forward summaries `(test, summary.json)` in test order of the folder.
fn forward_summaries(dir: &Path) -> Vec<(String, Value)> {
    let Ok(entries) = std::fs::read_dir(dir) else {
        return Vec::new();
    };
    let mut v: Vec<(String, Value)> = entries
        .filter_map(|e| e.ok())
        .filter_map(|e| {
            let name = e.file_name().to_string_lossy().to_string();
            read_json(&e.path().join("summary.json")).map(|s| (name, s))
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

fn model_section(html: &mut Html, dir: &Path) -> Option<Value> {
    let s = read_json(&dir.join("summary.json"))?;
    html.h2("Model");
    let q = &s["quality"]["total"];
    html.p(&format!(
        "{} nodes, {} {} elements{}; scaled Jacobian {}–{}, corner angles {}–{}°, {} elements \
         below 0.3. Femur edge fixed. Files: <code>model/mesh.inp</code> (runs in \
         CalculiX/Abaqus), <code>model/mesh.vtu</code> (ParaView).",
        s["nodes"],
        s["elements"],
        esc(s["element"].as_str().unwrap_or("")),
        num(&s["element_size_mm"])
            .map(|h| format!(" of about {h:.2} mm"))
            .unwrap_or_default(),
        num(&q["min_scaled_jacobian"]).map(g).unwrap_or_default(),
        num(&q["max_scaled_jacobian"]).map(g).unwrap_or_default(),
        num(&q["min_angle_deg"])
            .map(|a| format!("{a:.1}"))
            .unwrap_or_default(),
        num(&q["max_angle_deg"])
            .map(|a| format!("{a:.1}"))
            .unwrap_or_default(),
        q["below_0_3"],
    ));
    if let Some(regions) = s["regions"].as_object() {
        let rows: Vec<Vec<String>> = regions
            .iter()
            .map(|(name, r)| {
                vec![
                    name.clone(),
                    r["elements"].to_string(),
                    num(&r["area_mm2"])
                        .map(|a| format!("{a:.1}"))
                        .unwrap_or_default(),
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

fn forward_section(html: &mut Html, dir: &Path) -> Option<Value> {
    let summaries = forward_summaries(dir);
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
            let b = &s["rigid_bodies"][0];
            vec![
                test.clone(),
                s["status"].as_str().unwrap_or("").to_string(),
                num(&s["max_displacement_mm"]).map(g).unwrap_or_default(),
                num(&b["travel_mm"]).map(g).unwrap_or("-".into()),
                num(&b["force_n_per_mm"]).map(g).unwrap_or("-".into()),
                num(&b["max_penetration_mm"]).map(g).unwrap_or("-".into()),
                s["newton_iterations"].to_string(),
                num(&s["timings"]["solve_s"])
                    .map(|t| format!("{t:.2}"))
                    .unwrap_or_default(),
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
    let mut out = serde_json::Map::new();
    for (test, s) in &summaries {
        html.h3(test);
        let d = dir.join(test);
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
            test.clone(),
            json!({
                "status": s["status"],
                "max_displacement_mm": s["max_displacement_mm"],
                "rigid_bodies": s["rigid_bodies"],
                "newton_iterations": s["newton_iterations"],
                "solve_s": s["timings"]["solve_s"],
            }),
        );
    }
    Some(Value::Object(out))
}

fn sensitivity_section(html: &mut Html, dir: &Path) -> Option<Value> {
    let s = read_json(&dir.join("summary.json"))?;
    html.h2("Sensitivity and test ranking (seed Eq. 3, Fig. 8)");
    html.p(
        "Exact derivatives of the displacement field with respect to each parameter (direct \
         differentiation, one back-substitution per parameter); S = ‖θ ∂U/∂θ‖ / ‖U‖ per test.",
    );
    if let Some(f) = s["finding"].as_array() {
        let items: String = f
            .iter()
            .filter_map(|l| l.as_str())
            .map(|l| format!("<li>{}</li>", esc(l)))
            .collect();
        let _ = write!(html.body, "<ul>{items}</ul>");
    }
    if let Some(tests) = s["tests"].as_array() {
        let names: Vec<String> = tests[0]["sensitivity_index"]
            .as_array()
            .map(|a| {
                a.iter()
                    .filter_map(|p| p[0].as_str().map(String::from))
                    .collect()
            })
            .unwrap_or_default();
        let mut header = vec!["test".to_string()];
        header.extend(names.iter().cloned());
        header.push("sensitivities / solve".into());
        let rows: Vec<Vec<String>> = tests
            .iter()
            .map(|t| {
                let mut r = vec![t["test"].as_str().unwrap_or("").to_string()];
                if let Some(a) = t["sensitivity_index"].as_array() {
                    r.extend(a.iter().map(|p| num(&p[1]).map(g).unwrap_or_default()));
                }
                r.push(
                    num(&t["sensitivity_over_solve"])
                        .map(|x| format!("{:.0} %", 100.0 * x))
                        .unwrap_or_default(),
                );
                r
            })
            .collect();
        let h: Vec<&str> = header.iter().map(String::as_str).collect();
        html.table(&h, &rows);
    }
    html.figure(
        &dir.join("sensitivity_index.png"),
        "Global sensitivity index of each parameter in each test (Eq. 3).",
    );
    html.figure(
        &dir.join("sensitivity_quadriceps.png"),
        "Sensitivity maps of C10 and D of the quadriceps per test (the seed's Fig. 8); colour \
         scale shared per row.",
    );
    html.figure(
        &dir.join("sensitivity_maps.png"),
        "Sensitivity maps of every parameter (rows) in every test (columns).",
    );
    if let Some(ranking) = s["ranking"].as_array() {
        html.h3("Which test to measure: predicted parameter errors (Cramér–Rao)");
        html.p(&format!(
            "Fisher information of the {} grid points in the tissue ({} mm apart) with noise \
             σ = {} mm; the worst predicted relative standard deviation of C10 and of D; best \
             first within each grouping.",
            s["grid_points_in_tissue"],
            num(&s["grid_spacing_mm"]).map(g).unwrap_or_default(),
            num(&s["noise_sigma_mm"]).map(g).unwrap_or_default()
        ));
        let rows: Vec<Vec<String>> = ranking
            .iter()
            .map(|r| {
                vec![
                    r["measurement"].as_str().unwrap_or("").to_string(),
                    r["grouping"].as_str().unwrap_or("").to_string(),
                    num(&r["worst_c10_relative_sd"])
                        .map(pct)
                        .unwrap_or_default(),
                    num(&r["worst_d_relative_sd"]).map(pct).unwrap_or_default(),
                    num(&r["condition"]).map(g).unwrap_or_default(),
                ]
            })
            .collect();
        html.table(
            &[
                "measured test(s)",
                "grouping",
                "worst C10 sd",
                "worst D sd",
                "condition number",
            ],
            &rows,
        );
    }
    Some(json!({
        "finding": s["finding"],
        "ranking": s["ranking"].as_array().map(|r| r.iter().map(|x| json!({
            "measurement": x["measurement"], "grouping": x["grouping"],
            "worst_c10_relative_sd": x["worst_c10_relative_sd"],
            "worst_d_relative_sd": x["worst_d_relative_sd"]})).collect::<Vec<_>>()),
        "tests": s["tests"].as_array().map(|t| t.iter().map(|x| json!({
            "test": x["test"], "sensitivity_index": x["sensitivity_index"],
            "sensitivity_over_solve": x["sensitivity_over_solve"]})).collect::<Vec<_>>()),
    }))
}

/// The images of a simulated ultrasound measurement (`femu us-sim`) and the DIC's error
/// against the FE field.
fn measurement_section(html: &mut Html, dir: &Path) -> Option<Value> {
    let s = read_json(&dir.join("summary.json"))?;
    html.h2("Measurement: simulated ultrasound and DIC");
    let e = &s["error"];
    html.p(&format!(
        "B-mode images of the unloaded and loaded thigh ({} x {} px, {} scatterers moved by the FE \
         field, {} MHz, gain {} dB, dynamic {} dB) correlated by the global Q4 DIC in {} load \
         steps. DIC against the FE field over {} points in the tissue: RMS ({}, {}) px = ({}, {}) \
         mm, largest ({}, {}) px, for displacements up to {} px.",
        s["image_px"][0],
        s["image_px"][1],
        s["scatterers"],
        num(&s["transducer"]["frequency_mhz"]).map(g).unwrap_or_default(),
        num(&s["scanner"]["gain_db"]).map(g).unwrap_or_default(),
        num(&s["scanner"]["dynamic_db"]).map(g).unwrap_or_default(),
        s["dic_steps"],
        e["points"],
        num(&e["rms_px"][0]).map(g).unwrap_or_default(),
        num(&e["rms_px"][1]).map(g).unwrap_or_default(),
        num(&e["rms_mm"][0]).map(g).unwrap_or_default(),
        num(&e["rms_mm"][1]).map(g).unwrap_or_default(),
        num(&e["max_abs_px"][0]).map(g).unwrap_or_default(),
        num(&e["max_abs_px"][1]).map(g).unwrap_or_default(),
        num(&s["error"]["max_true_px"]).map(g).unwrap_or_default(),
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
    Some(json!({"dic_error": s["error"], "image_px": s["image_px"], "dic_steps": s["dic_steps"]}))
}

fn identification_section(html: &mut Html, dir: &Path) -> Result<Option<Value>> {
    let results: Vec<(String, Value)> = ["ungrouped", "grouped"]
        .iter()
        .filter_map(|g| {
            read_json(&dir.join("identify").join(g).join("summary.json"))
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
        esc(first["test"].as_str().unwrap_or("")),
        first["points_in_tissue"],
        first["points_masked"],
        esc(first["measured"].as_str().unwrap_or("")),
        num(&first["noise_sigma_mm"]).map(g).unwrap_or_default(),
        esc(first["optimizer"].as_str().unwrap_or("lm")),
        first["starts_per_repeat"],
    ));
    let mut out = serde_json::Map::new();
    for (grouping, s) in &results {
        html.h3(&format!("{grouping} parameters"));
        let solves: Vec<String> = s["forward_solves_per_start"]
            .as_array()
            .map(|a| a.iter().map(|v| v.to_string()).collect())
            .unwrap_or_default();
        html.p(&format!(
            "Best cost {}; forward solves per start: {}; {:.1} s.",
            num(&s["best_cost"]).map(g).unwrap_or_default(),
            solves.join(", "),
            num(&s["wall_time_s"]).unwrap_or(0.0)
        ));
        let rows: Vec<Vec<String>> = s["parameters"]
            .as_array()
            .map(|ps| {
                ps.iter()
                    .map(|p| {
                        vec![
                            p["name"].as_str().unwrap_or("").to_string(),
                            num(&p["reference"]).map(g).unwrap_or("-".into()),
                            num(&p["identified"]).map(g).unwrap_or_default(),
                            num(&p["relative_error"]).map(pct).unwrap_or("-".into()),
                            format!(
                                "[{}, {}]",
                                num(&p["ci95"][0]).map(g).unwrap_or_default(),
                                num(&p["ci95"][1]).map(g).unwrap_or_default()
                            ),
                            num(&p["relative_sd"]).map(pct).unwrap_or_default(),
                        ]
                    })
                    .collect()
            })
            .unwrap_or_default();
        html.table(
            &[
                "parameter (C10 MPa, D 1/MPa)",
                "reference",
                "identified",
                "error (Eq. 4)",
                "95 % interval",
                "relative sd",
            ],
            &rows,
        );
        let d = dir.join("identify").join(grouping);
        html.figure(
            &d.join("fields.png"),
            &format!("{grouping}: measured and identified-model displacements on the grid, and the residual."),
        );
        out.insert(
            grouping.clone(),
            json!({
                "parameters": s["parameters"],
                "best_cost": s["best_cost"],
                "forward_solves_per_start": s["forward_solves_per_start"],
                "wall_time_s": s["wall_time_s"],
                "optimizer": s["optimizer"],
            }),
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
    Ok(Some(Value::Object(out)))
}

/// The Fig. 9 chart of both groupings side by side (`identify/fig9_errors.png`), when the
/// reference is known.
fn fig9(dir: &Path, results: &[(String, Value)]) -> Result<Option<PathBuf>> {
    // The model parameters (from the ungrouped run, else the members of the grouped names).
    let mut names: Vec<String> = Vec::new();
    for (_, s) in results {
        for p in s["parameters"].as_array().into_iter().flatten() {
            for n in p["name"].as_str().unwrap_or("").split('+') {
                if !names.iter().any(|m| m == n) {
                    names.push(n.to_string());
                }
            }
        }
    }
    let mut series = Vec::new();
    let mut bars = Vec::new();
    for (grouping, s) in results {
        let ps = s["parameters"].as_array().cloned().unwrap_or_default();
        let mut values = Vec::new();
        let mut sds = Vec::new();
        for n in &names {
            let p = ps.iter().find(|p| {
                p["name"]
                    .as_str()
                    .is_some_and(|m| m.split('+').any(|k| k == n))
            });
            values.push(
                p.and_then(|p| num(&p["relative_error"]))
                    .map_or(f64::NAN, |e| 100.0 * e),
            );
            sds.push(
                p.and_then(|p| num(&p["relative_sd"]))
                    .map_or(0.0, |e| 100.0 * e),
            );
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
