//! The discretization check of an identification (`[identification] discretization`): the
//! identified parameters evaluated on meshes of the same geometry refined by √2 and 2, the bias
//! the study's mesh implies (`femu_identify::discretization`), and — with `"refine"` — the
//! identification continued on the finest of them. The meshes and their solutions are kept with
//! the study's model for its next identification ([`CheckMeshes`]).

use super::joint::{JointFit, TestModels};
use super::measure::{Prepared, PreparedData};
use super::parameters::IdentificationInputs;
use crate::error::{Context, Result};
use crate::model::{build_refined, CachedLevel, CheckMeshes, StudyModel};
use crate::progress::Progress;
use crate::schema::{Discretization, Geometry, ModelSpec};
use femu_identify::discretization::{self, DiscretizationCheck, Evaluated};
use femu_identify::fit::{
    levenberg_marquardt, FitResult, FreeParameter, LeastSquares, LmOptions, Problem,
};
use femu_identify::joint::{block_free, Block, JointProblem};
use femu_identify::measured::MeasuredField;
use femu_mech::{Model, SolverOptions};
use femu_mesh::locate::PointLocator;

/// The refinement ratios `h / h_i` of the check's meshes (2 and 4 times the elements). A coarser
/// mesh instead of the finest (ratios 1/√2 and √2, a quarter of the work) was tried: on the
/// demo's thigh the meshes then do not follow one rate (a coarser mesh of 1 941 elements is
/// nearer the model's 4 101 than the 7 602 one is), so the rate would be assumed and the bias
/// doubled.
pub const RATIOS: [f64; 2] = [std::f64::consts::SQRT_2, 2.0];

/// The model `built` of `spec` refined by `ratio` (see [`build_refined`]); `None` for a deck.
pub fn refined(spec: &ModelSpec, built: &StudyModel, ratio: f64) -> Result<Option<StudyModel>> {
    build_refined(spec, built, ratio)
}

/// Whether the data were made by the model's own mesh: virtual data without
/// `data_refinement`, or images simulated on it (`[ultrasound] render_refine = 1`; the default
/// 2 renders them from a finer mesh). Their intervals need no widening.
pub fn data_from_model(inputs: &IdentificationInputs, prepared: &[Prepared]) -> bool {
    prepared.iter().all(|p| match &p.data {
        PreparedData::Virtual { .. } => inputs.identification.data_refinement == 1.0,
        PreparedData::Measured(m) => m.reference_known && inputs.render_refine == 1,
    })
}

/// What the check found, and the problem of the finest mesh (for `"refine"`).
pub struct Checked {
    pub check: DiscretizationCheck,
    pub finest: Option<JointProblem>,
}

/// The meshes of the check: the model's own and the refined ones (`RATIOS`), each with the
/// measured tests' models; those of an earlier check on this model (the demo's ungrouped
/// identification before its grouped one) taken back with their last solutions.
fn check_levels(
    inputs: &IdentificationInputs,
    built: &StudyModel,
    models: &TestModels,
) -> Result<Vec<CachedLevel>> {
    let tests: Vec<String> = models
        .tests
        .iter()
        .map(|&t| format!("{:?}", inputs.tests[t].loading))
        .collect();
    let mut cached =
        std::mem::take(&mut *built.check_meshes.lock().unwrap_or_else(|e| e.into_inner()));
    cached.levels.retain(|l| l.tests == tests);
    let mut take = |ratio: f64| -> Option<CachedLevel> {
        let k = cached.levels.iter().position(|l| l.ratio == ratio)?;
        Some(cached.levels.swap_remove(k))
    };
    // Each level: the model's own mesh first, then the refined ones.
    let own = take(1.0);
    let mut levels = vec![CachedLevel {
        ratio: 1.0,
        tests: tests.clone(),
        elements: models.elements(),
        models: models.full.clone(),
        states: own.map(|l| l.states).unwrap_or_default(),
    }];
    for ratio in RATIOS {
        if let Some(level) = take(ratio) {
            levels.push(level);
            continue;
        }
        let fine = refined(inputs.model, built, ratio)?.context("the model cannot be refined")?;
        levels.push(CachedLevel {
            ratio,
            tests: tests.clone(),
            elements: fine.model.mesh.elements.len(),
            models: models
                .tests
                .iter()
                .map(|&t| fine.loaded(&inputs.tests[t].loading))
                .collect::<Result<Vec<_>>>()?,
            states: Vec::new(),
        });
    }
    Ok(levels)
}

/// The check of `fit` (its first repeat, relative sds `sd`).
pub fn check(
    inputs: &IdentificationInputs,
    built: &StudyModel,
    models: &TestModels,
    prepared: &[Prepared],
    fit: &JointFit,
    sd: &[f64],
    progress: &dyn Progress,
) -> Result<Checked> {
    if matches!(inputs.model.geometry, Geometry::Deck(_)) {
        return Ok(Checked {
            check: DiscretizationCheck::unknown(
                models.elements(),
                "femu cannot refine a deck; mesh the same geometry with about four times the elements, identify again from the same data and compare the parameters (or describe the geometry with [thigh] or [labels], which femu refines itself)",
            ),
            finest: None,
        });
    }
    let task = progress.task("discretization check on refined meshes", None);
    let mut levels = check_levels(inputs, built, models)?;
    let fields: Vec<MeasuredField> = (0..models.tests.len())
        .map(|b| {
            let meshes: Vec<&Model> = levels.iter().map(|l| &l.models[b]).collect();
            common_points(&fit.campaign.blocks[b].first_field, &meshes)
        })
        .collect();
    let finest = discretization::finest_level(levels.iter().map(|l| l.ratio))?;
    let keep_finest = inputs.identification.discretization == Discretization::Refine;
    let phi: Vec<f64> = fit.campaign.best[0].theta.iter().map(|t| t.ln()).collect();
    // One level's problem at a time (the finest's solver alone holds more memory than the
    // model's), the finest last.
    let mut order: Vec<usize> = (0..levels.len()).filter(|&i| i != finest).collect();
    order.push(finest);
    let mut evaluated = Vec::with_capacity(order.len());
    let mut jacobian = None;
    let mut finest_problem = None;
    for i in order {
        let level = &mut levels[i];
        let mut problem = level_problem(level, &fields, models, fit, prepared)?;
        let (residual, j) = problem
            .evaluate(&phi, i == finest)
            .map_err(discretization::CheckError::from)
            .context("the discretization check")?;
        level.states = problem.states();
        evaluated.push(Evaluated {
            ratio: level.ratio,
            elements: level.elements,
            residual,
        });
        if i == finest {
            jacobian = j;
            finest_problem = keep_finest.then_some(problem);
        }
    }
    let jacobian =
        jacobian.context("the finest mesh of the discretization check gave no Jacobian")?;
    let check =
        discretization::assess(sd, &evaluated, &jacobian, data_from_model(inputs, prepared))
            .context("the discretization check")?;
    // Kept for the next check on this model; the model's own mesh by its state alone.
    levels[0].models.clear();
    *built.check_meshes.lock().unwrap_or_else(|e| e.into_inner()) = CheckMeshes { levels };
    drop(task);
    progress.note(&format!("discretization: {}", check.message));
    Ok(Checked {
        check,
        finest: finest_problem,
    })
}

/// The joint problem on one level's models with the first repeat's data at `fields` (per
/// block, the points inside every level's mesh, so that the levels see the same residual
/// rows).
fn level_problem(
    level: &CachedLevel,
    fields: &[MeasuredField],
    models: &TestModels,
    fit: &JointFit,
    prepared: &[Prepared],
) -> Result<JointProblem> {
    let mut blocks = Vec::new();
    for (b, model) in level.models.iter().enumerate() {
        let record = &fit.campaign.blocks[b];
        let (free, map) = block_free(&fit.free, &models.full[0], model);
        let mut p = Problem::new(model.clone(), SolverOptions::default(), &fields[b], free)?;
        if let Some(Some(state)) = level.states.get(b) {
            // The solution at the earlier check's parameters: Newton from there.
            p = p.with_warm_start(state.clone());
        }
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
    JointProblem::new(fit.free.clone(), blocks).map_err(|e| crate::input!("{e}"))
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
