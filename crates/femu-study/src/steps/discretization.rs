//! The discretization check of an identification (`[identification] discretization`): the
//! identified parameters evaluated on meshes of the same geometry refined by √2 and 2 (a deck:
//! its elements split once and twice, [`DECK_RATIOS`]), the bias
//! the study's mesh implies (`femu_identify::discretization`), and — with `"refine"` — the
//! identification continued on the finest of them. The meshes and their solutions are kept with
//! the study's model for its next identification ([`CheckMeshes`]); on the first check the
//! model's own mesh starts Newton from the fit's last solution on it, and a refined mesh from
//! the solution of the mesh evaluated before it, carried onto its nodes (on the 25 557-element
//! thigh of `femu demo --full` the finest mesh's solve took about a quarter of its time from
//! the load increments; bench/perf/profile_full.txt).

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

/// The refinement ratios of a deck's check: its elements split in four once and twice (4 and 16
/// times the elements; a split cannot refine by √2).
pub const DECK_RATIOS: [f64; 2] = [2.0, 4.0];

/// What the check of a deck covers, added to its message.
pub const DECK_NOTE: &str = "the deck refined by splitting its elements (outline and interfaces on smooth curves through its nodes): this measures the error of its mesh on that geometry, not the geometry between its nodes, which the deck does not record (under contention the C10 are sensitive to it: compare with a finer deck of the same segmentation)";

/// The model `built` of `spec` refined by `ratio` (see [`build_refined`]); `None` when it
/// cannot be (a deck and a ratio that is not a power of two).
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
/// identification before its grouped one) taken back with their last solutions. The model's
/// own mesh starts from the fit's last solutions on it when there is no earlier check (the
/// multilevel refinement's: `fitted_states`, one per test).
fn check_levels(
    inputs: &IdentificationInputs,
    built: &StudyModel,
    models: &TestModels,
    fitted_states: &[Option<Vec<f64>>],
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
    let fitted = || {
        let fits = fitted_states.len() == models.full.len()
            && fitted_states
                .iter()
                .zip(&models.full)
                .all(|(s, m)| s.as_ref().is_some_and(|s| s.len() == m.state_len()));
        if fits {
            fitted_states.to_vec()
        } else {
            Vec::new()
        }
    };
    let mut levels = vec![CachedLevel {
        ratio: 1.0,
        tests: tests.clone(),
        elements: models.elements(),
        models: models.full.clone(),
        states: own.map(|l| l.states).unwrap_or_else(fitted),
    }];
    let ratios = match inputs.model.geometry {
        Geometry::Deck(_) => DECK_RATIOS,
        _ => RATIOS,
    };
    for ratio in ratios {
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
    let task = progress.task("discretization check on refined meshes", None);
    let mut levels = check_levels(inputs, built, models, &fit.campaign.refined_states)?;
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
    let mut previous: Option<usize> = None;
    for i in order {
        // A mesh without a solution of its own (the first check on this model) starts Newton
        // from the solution of the mesh evaluated before it, interpolated onto its nodes.
        if levels[i].states.is_empty() {
            if let Some(p) = previous {
                let states = transferred_states(&levels[p], &levels[i].models);
                levels[i].states = states;
            }
        }
        previous = Some(i);
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
    let mut check =
        discretization::assess(sd, &evaluated, &jacobian, data_from_model(inputs, prepared))
            .context("the discretization check")?;
    if matches!(inputs.model.geometry, Geometry::Deck(_)) {
        check.message = format!("{} ({DECK_NOTE})", check.message);
    }
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
        // The measured field's speckle shift, as the fit had it (its single block).
        if let (0, Some((_, s))) = (b, super::measure::measured_speckle(prepared)) {
            p = p.with_speckle_shift(s)?;
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

/// The solutions of `from` (one per test) carried onto `to`, the same tests on another mesh of
/// the same geometry: a start for Newton on `to` near its solution, so that it converges at the
/// full load in a few iterations instead of following the load increments from zero. Each node
/// of `to` takes the displacement interpolated at its reference position in `from`'s mesh (the
/// element's shape functions), or a node outside `from`'s outline (its polygon differs near the
/// skin) that of the nearest node of `from`; the rigid bodies' travels are copied. `None` for a
/// test `from` has no solution of.
fn transferred_states(from: &CachedLevel, to: &[Model]) -> Vec<Option<Vec<f64>>> {
    to.iter()
        .enumerate()
        .map(|(b, target)| {
            let source = from.models.get(b)?;
            let state = from.states.get(b)?.as_ref()?;
            transferred_state(source, state, target)
        })
        .collect()
}

/// One test's solution `state` of `from` carried onto `to` (see [`transferred_states`]).
fn transferred_state(from: &Model, state: &[f64], to: &Model) -> Option<Vec<f64>> {
    if state.len() != from.state_len() || from.contacts.len() != to.contacts.len() {
        return None;
    }
    let mesh = &from.mesh;
    let locator = PointLocator::new(mesh);
    // The elements around each node of `from`, for the nodes outside its outline.
    let mut around = vec![Vec::new(); mesh.nodes.len()];
    for (e, el) in mesh.elements.iter().enumerate() {
        for &n in el.nodes() {
            around[n].push(e);
        }
    }
    let mut out = Vec::with_capacity(to.state_len());
    for &x in &to.mesh.nodes {
        let value = match locator.locate(x) {
            Some(loc) => [loc.interpolate(state, 2, 0), loc.interpolate(state, 2, 1)],
            None => outside_value(mesh, &around, state, x)?,
        };
        out.extend_from_slice(&value);
    }
    // Each body at the same place: its travel counts from its first contact, which depends on
    // the mesh's outline.
    let travels = &state[2 * mesh.nodes.len()..];
    for ((t, a), b) in travels.iter().zip(&from.contacts).zip(&to.contacts) {
        out.push(t + a.first_contact - b.first_contact);
    }
    Some(out)
}

/// The displacement at `x`, a point just outside `mesh` (a finer polygon of the same curved
/// outline lies outside the coarser one's chords): the bilinear field of the element of the
/// nearest node whose natural coordinates at `x` are least outside the element, extended there
/// (the nearest node's own value for an element that is not a quad).
fn outside_value(
    mesh: &femu_mesh::Mesh,
    around: &[Vec<usize>],
    state: &[f64],
    x: [f64; 2],
) -> Option<[f64; 2]> {
    let distance = |n: &[f64; 2]| (n[0] - x[0]).powi(2) + (n[1] - x[1]).powi(2);
    let nearest = (0..mesh.nodes.len())
        .min_by(|&a, &b| distance(&mesh.nodes[a]).total_cmp(&distance(&mesh.nodes[b])))?;
    let best = around[nearest]
        .iter()
        .filter(|&&e| mesh.elements[e].nodes().len() == 4)
        .filter_map(|&e| {
            let nodes = mesh.elements[e].nodes();
            let corners: Vec<[f64; 2]> = nodes.iter().map(|&n| mesh.nodes[n]).collect();
            let xi = natural_coordinates(&corners, x)?;
            Some((xi[0].abs().max(xi[1].abs()), e, xi))
        })
        .min_by(|a, b| a.0.total_cmp(&b.0));
    Some(match best {
        // Within twice the element: an extension of its field, not a guess far away.
        Some((reach, e, xi)) if reach < 2.0 => {
            let w = bilinear(xi);
            let nodes = mesh.elements[e].nodes();
            let mut v = [0.0; 2];
            for (a, &n) in nodes.iter().enumerate() {
                v[0] += w[a] * state[2 * n];
                v[1] += w[a] * state[2 * n + 1];
            }
            v
        }
        _ => [state[2 * nearest], state[2 * nearest + 1]],
    })
}

/// The bilinear shape functions of a quad (corners at ξ, η = ∓1 counter-clockwise from
/// (-1, -1)) at `xi`.
fn bilinear(xi: [f64; 2]) -> [f64; 4] {
    let [s, t] = xi;
    [
        0.25 * (1.0 - s) * (1.0 - t),
        0.25 * (1.0 + s) * (1.0 - t),
        0.25 * (1.0 + s) * (1.0 + t),
        0.25 * (1.0 - s) * (1.0 + t),
    ]
}

/// The natural coordinates of `x` in the bilinear map of the quad `corners`, also outside it
/// (Newton from the centre; `None` if it does not converge).
fn natural_coordinates(corners: &[[f64; 2]], x: [f64; 2]) -> Option<[f64; 2]> {
    let mut xi = [0.0f64; 2];
    let size = corners
        .iter()
        .map(|c| (c[0] - corners[0][0]).hypot(c[1] - corners[0][1]))
        .fold(0.0, f64::max);
    for _ in 0..20 {
        let w = bilinear(xi);
        let [s, t] = xi;
        // d N_a / d(s, t) for the corners in order.
        let ds = [-(1.0 - t), 1.0 - t, 1.0 + t, -(1.0 + t)].map(|v| 0.25 * v);
        let dt = [-(1.0 - s), -(1.0 + s), 1.0 + s, 1.0 - s].map(|v| 0.25 * v);
        let (mut f, mut j) = ([-x[0], -x[1]], [[0.0; 2]; 2]);
        for a in 0..4 {
            for c in 0..2 {
                f[c] += w[a] * corners[a][c];
                j[c][0] += ds[a] * corners[a][c];
                j[c][1] += dt[a] * corners[a][c];
            }
        }
        if f[0].hypot(f[1]) <= 1e-12 * size {
            return Some(xi);
        }
        let det = j[0][0] * j[1][1] - j[0][1] * j[1][0];
        if !(det.abs() > 0.0) {
            return None;
        }
        xi[0] -= (j[1][1] * f[0] - j[0][1] * f[1]) / det;
        xi[1] -= (-j[1][0] * f[0] + j[0][0] * f[1]) / det;
        if !(xi[0].is_finite() && xi[1].is_finite()) || xi[0].abs().max(xi[1].abs()) > 10.0 {
            return None;
        }
    }
    None
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

#[cfg(test)]
mod tests {
    use super::*;
    use femu_mesh::ElementKind;

    /// A linear displacement field on one mesh of the thigh is carried exactly onto another
    /// mesh of it (the bilinear shape functions reproduce linear fields), at the nodes inside
    /// the first mesh's outline and at those just outside it alike.
    #[test]
    fn a_linear_field_is_carried_onto_another_mesh() {
        let (coarse, _) = crate::model::thigh_model(2500, ElementKind::Cpe4h).unwrap();
        let (fine, _) = crate::model::thigh_model(6000, ElementKind::Cpe4h).unwrap();
        let field = |x: [f64; 2]| [0.01 * x[0] - 0.02 * x[1] + 0.3, 0.005 * x[0] + 0.1];
        let state: Vec<f64> = coarse.mesh.nodes.iter().flat_map(|&x| field(x)).collect();
        let carried = transferred_state(&coarse, &state, &fine).unwrap();
        assert_eq!(carried.len(), fine.state_len());
        let locator = PointLocator::new(&coarse.mesh);
        let (mut inside, mut outside) = (0, 0);
        for (n, &x) in fine.mesh.nodes.iter().enumerate() {
            let expected = field(x);
            let got = [carried[2 * n], carried[2 * n + 1]];
            // A bilinear map reproduces a linear field inside its element and beyond it: exact
            // but for rounding and the inverse map's Newton tolerance (1e-12 of the element).
            let tolerance = 1e-8;
            if locator.locate(x).is_some() {
                inside += 1;
            } else {
                outside += 1;
            }
            for c in 0..2 {
                assert!(
                    (got[c] - expected[c]).abs() < tolerance,
                    "node {n} at {x:?}: {got:?} against {expected:?}"
                );
            }
        }
        assert!(
            inside > 10 * outside && outside > 0,
            "{inside} nodes inside, {outside} outside"
        );
        // A state of another length is not carried.
        assert!(transferred_state(&coarse, &state[1..], &fine).is_none());
    }
}
