//! `femu batch collect DIR`: every case's identified parameters, their intervals and the quality
//! of the fit gathered into one table, read from the typed summaries the cases wrote (each
//! case's `steps.json`, `identify/GROUPING/summary.json`), and the population report.
//!
//! ```text
//! DIR/collect/population.csv   one row per case, identification (grouping) and parameter
//! DIR/collect/population.json  the same as a typed document ([`Population`]), the states too
//! DIR/collect/cases.csv        one row per case: its variables, state, time, error
//! DIR/collect/report.html      the population report (figures embedded)
//! DIR/collect/figures/         its figures (PNG)
//! ```

mod report;

use crate::error::{Context, IoContext, Result};
use crate::folder::BatchDir;
use crate::status::{status, CaseState};
use femu_mech::material::{Unit, LAWS};
use femu_study::steps::identify::IdentificationSummary;
use femu_study::steps::record::RunRecord;
use serde::{Deserialize, Serialize};
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

/// The gathered results of a batch.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Population {
    /// The batch file.
    pub batch_file: PathBuf,
    /// The variables of the cases (`subject`, ...), in the table's order.
    pub variables: Vec<String>,
    pub cases: Vec<CaseResult>,
}

/// One case: its state and the identifications it finished.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct CaseResult {
    pub case: String,
    pub origin: String,
    pub vars: BTreeMap<String, String>,
    pub state: CaseState,
    pub seconds: Option<f64>,
    pub error: Option<String>,
    pub fits: Vec<Fit>,
}

/// One identification of a case (`identify/GROUPING`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Fit {
    /// `ungrouped`, `grouped`.
    pub grouping: String,
    pub test: String,
    pub optimizer: String,
    pub measured: String,
    pub elements: usize,
    pub points_in_tissue: usize,
    /// The cost ½|W(u_measured − u_model)|² at the optimum (Eq. 2; weighted by 1/σ² for a
    /// virtual experiment or a field with standard deviations, then dimensionless).
    pub best_cost: f64,
    /// Residual components (two per measured point, and the actuator's travel if any).
    pub residuals: usize,
    /// √(2 cost / residuals): the RMS weighted residual (≈ 1 when the model fits to the noise
    /// of a field given with its σ; mm for an unweighted field).
    pub rms_residual: f64,
    /// Whether the best start's optimizer met its convergence test.
    pub converged: bool,
    /// Forward solves of every start (and of the refinement, multilevel).
    pub forward_solves: usize,
    pub parameters: Vec<ParameterResult>,
}

/// One identified parameter (internal units: MPa, MPa⁻¹).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ParameterResult {
    /// `C10_FAT`, `D_ISCHIO+D_GRACILIS+D_SARTORIUS`.
    pub name: String,
    /// The law's parameter (`C10`, `D`).
    pub kind: String,
    /// The tissue(s): `FAT`, `ISCHIO+GRACILIS+SARTORIUS`.
    pub tissue: String,
    pub unit: String,
    pub identified: f64,
    pub ci95: [f64; 2],
    pub relative_sd: f64,
    pub reference: Option<f64>,
    pub relative_error: Option<f64>,
}

/// What `collect` wrote.
#[derive(Debug, Clone, PartialEq)]
pub struct Collected {
    pub population: Population,
    pub files: Vec<PathBuf>,
    /// What the status could not learn (no Slurm, no accounting).
    pub notes: Vec<String>,
}

/// Gathers the batch in `dir` into `dir/collect/`.
pub fn collect(dir: &BatchDir) -> Result<Collected> {
    let plan = dir.read_plan()?;
    let st = status(dir)?;
    let mut cases = Vec::new();
    for c in &st.cases {
        let fits = case_fits(&dir.case_dir(&c.name)).with_context(|| format!("case {}", c.name))?;
        cases.push(CaseResult {
            case: c.name.clone(),
            origin: c.origin.clone(),
            vars: c.vars.clone(),
            state: c.state,
            seconds: c.seconds,
            error: c.error.clone(),
            fits,
        });
    }
    let population = Population {
        batch_file: plan.batch_file.clone(),
        variables: plan.variables.clone(),
        cases,
    };
    let out = dir.collect_dir();
    let figures = out.join("figures");
    std::fs::create_dir_all(&figures)
        .at(&figures, || format!("cannot create {}", out.display()))?;
    let mut files = vec![
        out.join("population.csv"),
        out.join("cases.csv"),
        out.join("population.json"),
    ];
    write_population_csv(&files[0], &population)?;
    write_cases_csv(&files[1], &population)?;
    femu_study::output::write_json(&files[2], &population)?;
    files.push(report::write(&out, &population, &st.notes)?);
    Ok(Collected {
        population,
        files,
        notes: st.notes,
    })
}

/// The identifications a case finished: the done steps of its `steps.json` whose folder is an
/// identification's, each read from its `summary.json`.
fn case_fits(case_dir: &Path) -> Result<Vec<Fit>> {
    let steps = case_dir.join("steps.json");
    if !steps.is_file() {
        return Ok(Vec::new());
    }
    let record: RunRecord = femu_study::output::read_json(&steps)?;
    record
        .steps
        .iter()
        .filter(|s| s.status == "done")
        .filter_map(|s| s.folder.as_deref())
        .filter(|f| f.starts_with("identify/"))
        .map(|folder| {
            let s: IdentificationSummary =
                femu_study::output::read_json(&case_dir.join(folder).join("summary.json"))?;
            let grouping = folder.trim_start_matches("identify/").to_string();
            Ok(fit(grouping, &s))
        })
        .collect()
}

/// The unit of a law parameter (`C10` → stress), from the registered laws.
fn unit_of(kind: &str) -> Option<Unit> {
    LAWS.iter()
        .flat_map(|l| l.spec.parameters.iter())
        .find(|p| p.name == kind)
        .map(|p| p.unit)
}

fn fit(grouping: String, s: &IdentificationSummary) -> Fit {
    let best = s
        .starts
        .iter()
        .filter(|st| st.repeat == 0)
        .filter_map(|st| st.result.as_ref())
        .min_by(|a, b| a.cost.total_cmp(&b.cost));
    let residuals = best.map_or(0, |b| b.data);
    let parameters = s
        .parameters
        .iter()
        .zip(&s.free_parameters)
        .map(|(e, f)| {
            let kind = f.members.first().map_or(String::new(), |m| m.kind.clone());
            // `C10_FAT+C10_ISCHIO` → `FAT+ISCHIO`: each member named KIND_MATERIAL.
            let prefix = format!("{kind}_");
            let tissue = e
                .name
                .split('+')
                .map(|m| m.strip_prefix(&prefix).unwrap_or(m))
                .collect::<Vec<_>>()
                .join("+");
            ParameterResult {
                name: e.name.clone(),
                unit: unit_of(&kind).map_or("", |u| u.symbol()).to_string(),
                kind,
                tissue,
                identified: e.identified,
                ci95: e.ci95,
                relative_sd: e.relative_sd,
                reference: e.reference,
                relative_error: e.relative_error,
            }
        })
        .collect();
    Fit {
        grouping,
        test: s.test.clone(),
        optimizer: s.optimizer.clone(),
        measured: s.measured.clone(),
        elements: s.elements,
        points_in_tissue: s.points_in_tissue,
        best_cost: s.best_cost,
        residuals,
        rms_residual: if residuals > 0 {
            (2.0 * s.best_cost / residuals as f64).sqrt()
        } else {
            f64::NAN
        },
        converged: best.is_some_and(|b| b.converged),
        forward_solves: s.forward_solves_per_start.iter().sum::<usize>()
            + s.refinement_forward_solves.iter().sum::<usize>(),
        parameters,
    }
}

/// A number as written in the tables: shortest round-trip decimal (exact), empty when absent.
fn num(v: Option<f64>) -> String {
    v.map_or(String::new(), |v| format!("{v}"))
}

fn writer(path: &Path) -> Result<csv::Writer<std::fs::File>> {
    csv::Writer::from_path(path).with_context(|| format!("cannot write {}", path.display()))
}

/// `population.csv`: one row per case, identification and parameter (done cases and any
/// identification a stopped case finished).
fn write_population_csv(path: &Path, p: &Population) -> Result<()> {
    let mut w = writer(path)?;
    let mut header: Vec<&str> = vec!["case"];
    header.extend(p.variables.iter().map(String::as_str));
    header.extend([
        "grouping",
        "parameter",
        "kind",
        "tissue",
        "unit",
        "identified",
        "ci95_low",
        "ci95_high",
        "relative_sd",
        "reference",
        "relative_error",
        "best_cost",
        "rms_residual",
        "residuals",
        "converged",
    ]);
    w.write_record(&header)?;
    for c in &p.cases {
        for f in &c.fits {
            for q in &f.parameters {
                let mut row = vec![c.case.clone()];
                row.extend(
                    p.variables
                        .iter()
                        .map(|v| c.vars.get(v).cloned().unwrap_or_default()),
                );
                row.extend([
                    f.grouping.clone(),
                    q.name.clone(),
                    q.kind.clone(),
                    q.tissue.clone(),
                    q.unit.clone(),
                    num(Some(q.identified)),
                    num(Some(q.ci95[0])),
                    num(Some(q.ci95[1])),
                    num(Some(q.relative_sd)),
                    num(q.reference),
                    num(q.relative_error),
                    num(Some(f.best_cost)),
                    num(Some(f.rms_residual)),
                    f.residuals.to_string(),
                    f.converged.to_string(),
                ]);
                w.write_record(&row)?;
            }
        }
    }
    w.flush()
        .at(path, || format!("cannot write {}", path.display()))
}

/// `cases.csv`: one row per case.
fn write_cases_csv(path: &Path, p: &Population) -> Result<()> {
    let mut w = writer(path)?;
    let mut header: Vec<&str> = vec!["case", "origin"];
    header.extend(p.variables.iter().map(String::as_str));
    header.extend(["state", "seconds", "identifications", "error"]);
    w.write_record(&header)?;
    for c in &p.cases {
        let mut row = vec![c.case.clone(), c.origin.clone()];
        row.extend(
            p.variables
                .iter()
                .map(|v| c.vars.get(v).cloned().unwrap_or_default()),
        );
        row.extend([
            c.state.name().to_string(),
            c.seconds.map_or(String::new(), |s| format!("{s:.3}")),
            c.fits.len().to_string(),
            c.error.clone().unwrap_or_default(),
        ]);
        w.write_record(&row)?;
    }
    w.flush()
        .at(path, || format!("cannot write {}", path.display()))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn units_come_from_the_registry() {
        assert_eq!(unit_of("C10"), Some(Unit::Stress));
        assert_eq!(unit_of("D"), Some(Unit::Compliance));
        assert_eq!(unit_of("nothing"), None);
    }
}
