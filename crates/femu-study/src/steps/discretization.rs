//! The discretization check of an identification (`[identification] discretization`): the
//! identified parameters evaluated on meshes of the same geometry refined by √2 and 2, the bias
//! the study's mesh implies (`femu_identify::discretization`), and — with `"refine"` — the
//! identification continued on the finest of them.

use super::joint::{JointFit, TestModels};
use super::measure::{Prepared, PreparedData};
use crate::model::{build_refined, StudyModel};
use crate::progress::Progress;
use crate::schema::{Geometry, Study};
use anyhow::{Context, Result};
use femu_identify::discretization::{self, DiscretizationCheck, Level};
use femu_identify::fit::{
    levenberg_marquardt, FitResult, FreeParameter, LeastSquares, LmOptions, Problem,
};
use femu_identify::joint::{block_free, Block, JointProblem};
use femu_identify::measured::MeasuredField;
use femu_mech::{Model, SolverOptions};
use femu_mesh::locate::PointLocator;

/// The refinement ratios `h / h_i` of the check's meshes (2 and 4 times the elements).
pub const RATIOS: [f64; 2] = [std::f64::consts::SQRT_2, 2.0];

/// The study's model refined by `ratio` (see [`build_refined`]); `None` for a deck.
pub fn refined(study: &Study, built: &StudyModel, ratio: f64) -> Result<Option<StudyModel>> {
    build_refined(&study.model, built, ratio)
}

/// Whether the data were made by the model's own mesh: virtual data without
/// `data_refinement`, or images simulated on it. Their intervals need no widening.
pub fn data_from_model(study: &Study, prepared: &[Prepared]) -> bool {
    prepared.iter().all(|p| match &p.data {
        PreparedData::Virtual { .. } => study.identification.data_refinement == 1.0,
        PreparedData::Measured(m) => m.reference_known,
    })
}

/// What the check found, and the problem of the finest mesh (for `"refine"`).
pub struct Checked {
    pub check: DiscretizationCheck,
    pub finest: Option<JointProblem>,
}

/// The check of `fit` (its first repeat, relative sds `sd`).
pub fn check(
    study: &Study,
    built: &StudyModel,
    models: &TestModels,
    prepared: &[Prepared],
    fit: &JointFit,
    sd: &[f64],
    progress: &dyn Progress,
) -> Result<Checked> {
    if matches!(study.model.geometry, Geometry::Deck(_)) {
        return Ok(Checked {
            check: DiscretizationCheck::unknown(
                models.elements(),
                "femu cannot refine a deck; mesh the same geometry with about four times the elements, identify again from the same data and compare the parameters (or describe the geometry with [thigh] or [labels], which femu refines itself)",
            ),
            finest: None,
        });
    }
    let task = progress.task("discretization check on refined meshes", None);
    let mut levels_models = vec![models.full.clone()];
    let mut elements = vec![models.elements()];
    for ratio in RATIOS {
        let fine = refined(study, built, ratio)?.context("the model cannot be refined")?;
        elements.push(fine.model.mesh.elements.len());
        levels_models.push(
            models
                .tests
                .iter()
                .map(|&t| fine.loaded(&study.tests[t].loading))
                .collect::<Result<Vec<_>>>()?,
        );
    }
    let fields: Vec<MeasuredField> = (0..models.tests.len())
        .map(|b| {
            let meshes: Vec<&Model> = levels_models.iter().map(|ms| &ms[b]).collect();
            common_points(&fit.campaign.blocks[b].first_field, &meshes)
        })
        .collect();
    let mut problems = levels_models
        .iter()
        .map(|ms| level_problem(ms, &fields, models, fit, prepared))
        .collect::<Result<Vec<_>>>()?;
    let ratios = [1.0, RATIOS[0], RATIOS[1]];
    let mut levels: Vec<Level> = problems
        .iter_mut()
        .zip(ratios)
        .zip(&elements)
        .map(|((p, ratio), &elements)| Level {
            ratio,
            elements,
            problem: p as &mut dyn LeastSquares,
        })
        .collect();
    let theta = &fit.campaign.best[0].theta;
    let check = discretization::check(theta, sd, &mut levels, data_from_model(study, prepared))
        .context("the discretization check")?;
    drop(task);
    progress.note(&format!("discretization: {}", check.message));
    Ok(Checked {
        check,
        finest: problems.pop(),
    })
}

/// The joint problem on one level's models with the first repeat's data at `fields` (per
/// block, the points inside every level's mesh, so that the levels see the same residual
/// rows).
fn level_problem(
    models_at_level: &[Model],
    fields: &[MeasuredField],
    models: &TestModels,
    fit: &JointFit,
    prepared: &[Prepared],
) -> Result<JointProblem> {
    let mut blocks = Vec::new();
    for (b, model) in models_at_level.iter().enumerate() {
        let record = &fit.campaign.blocks[b];
        let (free, map) = block_free(&fit.free, &models.full[0], model);
        let mut p = Problem::new(model.clone(), SolverOptions::default(), &fields[b], free)?;
        let test = models.tests[b];
        let travel = prepared
            .iter()
            .filter(|p| p.test == test)
            .find_map(|p| p.travel);
        if let (Some(term), Some(t)) = (travel, record.reference_travel) {
            // The measured value cancels in the levels' differences; the reference serves.
            p = p.with_travel(t, term.sigma_mm)?;
        }
        blocks.push(Block {
            name: record.name.clone(),
            problem: Box::new(p),
            map,
            segments: Vec::new(),
        });
    }
    JointProblem::new(fit.free.clone(), blocks).map_err(|e| anyhow::anyhow!("{e}"))
}

/// The points of `field` inside every mesh of `models` (a point near the skin can fall outside
/// one polygonal outline and inside another).
fn common_points(field: &MeasuredField, models: &[&Model]) -> MeasuredField {
    let locators: Vec<PointLocator> = models.iter().map(|m| PointLocator::new(&m.mesh)).collect();
    MeasuredField {
        points: field
            .points
            .iter()
            .filter(|p| locators.iter().all(|l| l.locate(p.x).is_some()))
            .copied()
            .collect(),
        comments: Vec::new(),
    }
}

/// `[identification] discretization = "refine"`: the first repeat identified again on the
/// finest mesh of the check, from the bias-corrected parameters (within the bounds).
pub fn refine(
    finest: &mut JointProblem,
    free: &[FreeParameter],
    theta: &[f64],
    bias: &[f64],
) -> Result<FitResult> {
    let start: Vec<f64> = theta
        .iter()
        .zip(bias)
        .zip(free)
        .map(|((t, b), f)| (t * (-b).exp()).clamp(f.lower, f.upper))
        .collect();
    levenberg_marquardt(finest, &start, &LmOptions::default())
        .context("identifying again on the refined mesh")
}
