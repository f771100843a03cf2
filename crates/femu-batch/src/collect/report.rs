//! The population report (`collect/report.html`): the cases and their states, the failed ones
//! with their errors, and per identification (grouping) the population's parameters — a table
//! of medians and quartiles, the per-tissue distributions across the cases, a forest plot per
//! parameter (each case's estimate and 95 % interval) and one per subject (each parameter of
//! the subject against the population's median) — and the quality of every fit.

use super::{unit_of, CaseResult, Fit, ParameterResult, Population};
use crate::error::Result;
use crate::status::CaseState;
use femu_plot::{box_plot_png, forest_plot_png, quantile, BoxPlot, ForestPlot, ForestRow};
use femu_study::html::{esc, g, Page};
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

/// One identified parameter of one case.
struct Entry<'a> {
    case: &'a CaseResult,
    p: &'a ParameterResult,
}

/// The factor and unit reports show a parameter of `kind` in (C10 in kPa, as the seed's Table 1).
fn report_unit(kind: &str) -> (f64, &'static str) {
    unit_of(kind).map_or((1.0, ""), |u| {
        let (name, factor) = u.report();
        (factor, name)
    })
}

/// A file-name-safe form of `s`.
fn file_safe(s: &str) -> String {
    s.chars()
        .map(|c| {
            if c.is_ascii_alphanumeric() || c == '-' || c == '_' {
                c
            } else {
                '_'
            }
        })
        .collect()
}

/// The subject of a case: its `subject` variable, else the case itself.
fn subject(c: &CaseResult) -> &str {
    c.vars
        .get("subject")
        .map_or(c.case.as_str(), String::as_str)
}

/// Writes `out/report.html` (figures in `out/figures/`).
pub(super) fn write(out: &Path, pop: &Population, notes: &[String]) -> Result<PathBuf> {
    let figures = out.join("figures");
    let mut page = Page::default();
    head(&mut page, pop, notes);
    cases(&mut page, pop);
    failures(&mut page, pop);
    let mut groupings: Vec<&str> = Vec::new();
    for f in pop.cases.iter().flat_map(|c| &c.fits) {
        if !groupings.contains(&f.grouping.as_str()) {
            groupings.push(&f.grouping);
        }
    }
    for grouping in groupings {
        population(&mut page, pop, grouping, &figures)?;
    }
    fits(&mut page, pop);
    page.h2("Versions");
    page.table(
        &["", ""],
        &[vec![
            "report written by".into(),
            format!("femu {}", env!("CARGO_PKG_VERSION")),
        ]],
    );
    let path = out.join("report.html");
    femu_study::output::write_text(&path, &page.finish("femu batch collect"))?;
    Ok(path)
}

fn head(page: &mut Page, pop: &Population, notes: &[String]) {
    let n = pop.cases.len();
    let done = pop
        .cases
        .iter()
        .filter(|c| c.state == CaseState::Done)
        .count();
    let seconds: f64 = pop.cases.iter().filter_map(|c| c.seconds).sum();
    page.body.push_str(&format!(
        "<h1>femu batch — {n} cases of {}</h1>",
        esc(&pop.batch_file.display().to_string())
    ));
    page.p(&format!(
        "{done} of {n} cases done ({:.1} s of case time in all). Each case is one <code>femu run</code> \
         of its study (the template with the case's values); the table \
         <code>population.csv</code> next to this report holds every identified parameter with \
         its 95 % interval and the quality of its fit, <code>cases.csv</code> every case's state.",
        seconds
    ));
    for note in notes {
        page.p(&format!("Note: {}", esc(note)));
    }
}

fn cases(page: &mut Page, pop: &Population) {
    page.h2("Cases");
    let mut header = vec!["case"];
    header.extend(pop.variables.iter().map(String::as_str));
    header.extend(["state", "time (s)", "identifications", "from"]);
    let rows: Vec<Vec<String>> = pop
        .cases
        .iter()
        .map(|c| {
            let mut r = vec![c.case.clone()];
            r.extend(
                pop.variables
                    .iter()
                    .map(|v| c.vars.get(v).cloned().unwrap_or_default()),
            );
            r.extend([
                c.state.name().to_string(),
                c.seconds.map_or(String::new(), |s| format!("{s:.1}")),
                c.fits
                    .iter()
                    .map(|f| f.grouping.as_str())
                    .collect::<Vec<_>>()
                    .join(", "),
                c.origin.clone(),
            ]);
            r
        })
        .collect();
    page.table(&header, &rows);
}

fn failures(page: &mut Page, pop: &Population) {
    let bad: Vec<&CaseResult> = pop
        .cases
        .iter()
        .filter(|c| c.state != CaseState::Done)
        .collect();
    page.h2("Cases not done");
    if bad.is_empty() {
        page.p("Every case is done.");
        return;
    }
    page.p(&format!(
        "<span class=\"bad\">{} of {} cases are not done</span>; their errors as they recorded \
         them (the whole output of each is <code>cases/NAME/femu.log</code>). \
         <code>femu batch run BATCH --out DIR --resume</code> runs them again once fixed.",
        bad.len(),
        pop.cases.len()
    ));
    for c in bad {
        page.h3(&format!("{} — {} ({})", c.case, c.state.name(), c.origin));
        page.body.push_str(&format!(
            "<pre>{}</pre>",
            esc(c
                .error
                .as_deref()
                .unwrap_or("(no error recorded: the case has not run)"))
        ));
    }
}

/// The entries of identification `grouping` by parameter, in the order the cases list them.
fn by_parameter<'a>(pop: &'a Population, grouping: &str) -> Vec<(String, Vec<Entry<'a>>)> {
    let mut out: Vec<(String, Vec<Entry<'a>>)> = Vec::new();
    for case in &pop.cases {
        for f in case.fits.iter().filter(|f| f.grouping == grouping) {
            for p in &f.parameters {
                let k = match out.iter().position(|(n, _)| *n == p.name) {
                    Some(k) => k,
                    None => {
                        out.push((p.name.clone(), Vec::new()));
                        out.len() - 1
                    }
                };
                out[k].1.push(Entry { case, p });
            }
        }
    }
    out
}

/// Median, quartiles, extremes of the identified values of `entries`.
fn spread(entries: &[Entry]) -> [f64; 5] {
    let mut v: Vec<f64> = entries.iter().map(|e| e.p.identified).collect();
    v.sort_by(f64::total_cmp);
    [
        v[0],
        quantile(&v, 0.25),
        quantile(&v, 0.5),
        quantile(&v, 0.75),
        v[v.len() - 1],
    ]
}

fn population(page: &mut Page, pop: &Population, grouping: &str, figures: &Path) -> Result<()> {
    let params = by_parameter(pop, grouping);
    if params.is_empty() {
        return Ok(());
    }
    page.h2(&format!("Population: identification {grouping}"));
    let medians: BTreeMap<String, f64> = params
        .iter()
        .map(|(n, e)| (n.clone(), spread(e)[2]))
        .collect();
    let rows: Vec<Vec<String>> = params
        .iter()
        .map(|(name, e)| {
            let (factor, unit) = report_unit(&e[0].p.kind);
            let s = spread(e);
            let mut sd: Vec<f64> = e.iter().map(|x| x.p.relative_sd).collect();
            sd.sort_by(f64::total_cmp);
            vec![
                name.clone(),
                unit.to_string(),
                e.len().to_string(),
                g(factor * s[2]),
                format!("{} – {}", g(factor * s[1]), g(factor * s[3])),
                format!("{} – {}", g(factor * s[0]), g(factor * s[4])),
                format!("{:.2} %", 100.0 * quantile(&sd, 0.5)),
            ]
        })
        .collect();
    page.table(
        &[
            "parameter",
            "unit",
            "cases",
            "median",
            "quartiles",
            "range",
            "median relative sd (one case)",
        ],
        &rows,
    );
    page.p(
        "The spread across the cases (between subjects, slices, sessions) next to the uncertainty \
         of one case's estimate (its relative standard deviation from the Jacobian at the \
         optimum): a spread well above it is a difference between the cases, not noise.",
    );
    distributions(page, &params, grouping, figures)?;
    page.h3("Each parameter across the cases");
    for (name, entries) in &params {
        let (factor, unit) = report_unit(&entries[0].p.kind);
        let rows: Vec<ForestRow> = entries
            .iter()
            .map(|e| ForestRow {
                label: e.case.case.clone(),
                estimate: factor * e.p.identified,
                low: factor * e.p.ci95[0],
                high: factor * e.p.ci95[1],
                group: 0,
            })
            .collect();
        let path = figures.join(format!(
            "{}_forest_{}.png",
            file_safe(grouping),
            file_safe(name)
        ));
        forest_plot_png(
            &path,
            &rows,
            &ForestPlot {
                title: format!("{name} of every case, with its 95 % interval ({grouping})"),
                x_label: format!("{name} ({unit})"),
                reference: Some((factor * medians[name], "median of the cases".into())),
                ..Default::default()
            },
        )?;
        page.figure(
            &path,
            &format!("{name} ({unit}) identified in each case (dot) with its 95 % interval (bar); the line is the median of the cases."),
        );
    }
    subjects(page, pop, grouping, &medians, figures)
}

/// Box plots of the identified values per tissue, one figure per law parameter (C10, D, ...).
fn distributions(
    page: &mut Page,
    params: &[(String, Vec<Entry>)],
    grouping: &str,
    figures: &Path,
) -> Result<()> {
    let mut kinds: Vec<&str> = Vec::new();
    for (_, e) in params {
        if !kinds.contains(&e[0].p.kind.as_str()) {
            kinds.push(&e[0].p.kind);
        }
    }
    page.h3("Distributions per tissue");
    for kind in kinds {
        let (factor, unit) = report_unit(kind);
        let groups: Vec<(String, Vec<f64>)> = params
            .iter()
            .filter(|(_, e)| e[0].p.kind == kind)
            .map(|(_, e)| {
                let values = e.iter().map(|x| factor * x.p.identified).collect();
                (e[0].p.tissue.to_lowercase(), values)
            })
            .collect();
        let path = figures.join(format!(
            "{}_distribution_{}.png",
            file_safe(grouping),
            file_safe(kind)
        ));
        box_plot_png(
            &path,
            &groups,
            &BoxPlot {
                title: format!("{kind} per tissue across the cases ({grouping})"),
                y_label: format!("{kind} ({unit})"),
                points: true,
                ..Default::default()
            },
        )?;
        page.figure(
            &path,
            &format!("{kind} ({unit}) of each tissue across the cases: box from the lower to the upper quartile, the median, whiskers to the extremes within 1.5 interquartile ranges; every case a dot."),
        );
    }
    Ok(())
}

/// One forest plot per subject: each parameter of each of its cases against the population's
/// median (a ratio on a logarithmic axis: C10 and D side by side).
fn subjects(
    page: &mut Page,
    pop: &Population,
    grouping: &str,
    medians: &BTreeMap<String, f64>,
    figures: &Path,
) -> Result<()> {
    let mut order: Vec<&str> = Vec::new();
    for c in &pop.cases {
        if c.fits.iter().any(|f| f.grouping == grouping) && !order.contains(&subject(c)) {
            order.push(subject(c));
        }
    }
    page.h3("Each subject against the population");
    for s in order {
        let cases: Vec<(&CaseResult, &Fit)> = pop
            .cases
            .iter()
            .filter(|c| subject(c) == s)
            .filter_map(|c| {
                c.fits
                    .iter()
                    .find(|f| f.grouping == grouping)
                    .map(|f| (c, f))
            })
            .collect();
        let several = cases.len() > 1;
        let mut rows = Vec::new();
        let first = cases[0].1;
        for p in &first.parameters {
            for (k, (c, f)) in cases.iter().enumerate() {
                let Some(q) = f.parameters.iter().find(|q| q.name == p.name) else {
                    continue;
                };
                let m = medians[&q.name];
                rows.push(ForestRow {
                    label: if several {
                        format!("{} · {}", q.name, c.case)
                    } else {
                        q.name.clone()
                    },
                    estimate: q.identified / m,
                    low: q.ci95[0] / m,
                    high: q.ci95[1] / m,
                    group: k,
                });
            }
        }
        // A logarithmic axis when the ratios span a factor 3 or more (C10 and D of very
        // different spreads side by side), else a linear one (which labels a narrow range);
        // linear also when an interval reaches 0 (a parameter the data cannot see has the
        // interval [0, ∞)), which no logarithmic axis shows.
        let values = || {
            rows.iter()
                .flat_map(|r| [r.low, r.high, r.estimate])
                .filter(|v| v.is_finite())
        };
        let (lo, hi) = values()
            .filter(|v| *v > 0.0)
            .fold((f64::INFINITY, 0.0f64), |(a, b), v| (a.min(v), b.max(v)));
        let log_x = hi / lo >= 3.0 && values().all(|v| v > 0.0);
        let path = figures.join(format!(
            "{}_subject_{}.png",
            file_safe(grouping),
            file_safe(s)
        ));
        forest_plot_png(
            &path,
            &rows,
            &ForestPlot {
                title: format!(
                    "subject {s}: parameters against the population's median ({grouping})"
                ),
                x_label: "identified / median of the cases".into(),
                log_x,
                reference: Some((1.0, "median of the cases".into())),
                groups: if several {
                    cases.iter().map(|(c, _)| c.case.clone()).collect()
                } else {
                    Vec::new()
                },
                ..Default::default()
            },
        )?;
        page.figure(
            &path,
            &format!("Subject {s}: each identified parameter divided by the median of the cases, with its 95 % interval; 1 is the population's median."),
        );
    }
    Ok(())
}

fn fits(page: &mut Page, pop: &Population) {
    page.h2("Quality of the fits");
    page.p(
        "Per case and identification: the cost at the optimum (Eq. 2, weighted), the residual \
         components, the RMS weighted residual √(2 cost / residuals) — about 1 when the model \
         fits a field to its noise σ —, whether the best start converged, and the forward solves \
         of all starts.",
    );
    let rows: Vec<Vec<String>> = pop
        .cases
        .iter()
        .flat_map(|c| {
            c.fits.iter().map(move |f| {
                vec![
                    c.case.clone(),
                    f.grouping.clone(),
                    f.test.clone(),
                    f.elements.to_string(),
                    f.points_in_tissue.to_string(),
                    g(f.best_cost),
                    f.residuals.to_string(),
                    g(f.rms_residual),
                    if f.converged { "yes" } else { "no" }.to_string(),
                    f.forward_solves.to_string(),
                ]
            })
        })
        .collect();
    page.table(
        &[
            "case",
            "identification",
            "test",
            "elements",
            "points",
            "cost",
            "residuals",
            "RMS residual",
            "converged",
            "forward solves",
        ],
        &rows,
    );
}
