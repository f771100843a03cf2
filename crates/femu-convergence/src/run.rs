//! Running a study: the mesh sequence, the solves, the comparison at the common points, the
//! rates, the recommended mesh and the locking check (seed §2.1.2.1).

use crate::rate::{fit_rate_against_finest, RateFit};
use crate::study::{ConvergenceStudy, MeshSequence};
use crate::ConvergenceError;
use femu_geometry::{parametric_thigh_on_raster, ThighModel};
use femu_mech::loading::{apply_loading, Loading};
use femu_mech::model::{ModelSpec, NamedMaterial};
use femu_mech::output::peak_memory_mb;
use femu_mech::{Model, SolverOptions, StaticSolver};
use femu_mesh::{ElementKind, PointInterpolation};
use serde::Serialize;
use std::time::Instant;

/// One solve of the study: one element type on one mesh, with Table 1 (`d_scale` = 1) or the
/// nearly incompressible materials.
#[derive(Debug, Clone, Serialize)]
pub struct MeshRun {
    /// The loading test (`contention`, `compression-anterior`, ...).
    pub test: String,
    /// `CPE4`, `CPE4H` or `CPE3`.
    pub element: String,
    /// Factor on every D (1 for the main study).
    pub d_scale: f64,
    /// Position in the mesh sequence (0 = coarsest).
    pub mesh: usize,
    /// The target element count asked for (quads), if the sequence gives counts.
    pub target_elements: Option<usize>,
    /// The element size the mesher used (mm).
    pub element_size_mm: f64,
    pub elements: usize,
    pub nodes: usize,
    /// Node spacing `sqrt(meshed area / nodes)` (mm): the same for a quad mesh and the
    /// triangles split from it, so element types are compared at equal `h`.
    pub h_mm: f64,
    /// `converged`, or why the solve failed.
    pub status: String,
    /// Grid points inside this mesh.
    pub points_inside: usize,
    /// Largest and RMS difference of the displacement (vector norm) from the finest mesh of the
    /// same element type and materials, over the common points (mm).
    pub max_diff_mm: Option<f64>,
    pub rms_diff_mm: Option<f64>,
    /// RMS displacement magnitude over the common points (mm).
    pub rms_displacement_mm: Option<f64>,
    /// `rms_displacement_mm` over that of the reference (the finest mesh of the reference
    /// element type with the same materials): below 1 the mesh is too stiff.
    pub displacement_ratio: Option<f64>,
    /// Largest nodal displacement magnitude (mm).
    pub max_displacement_mm: f64,
    /// Total reaction force on the fixed femur (N per mm of thickness).
    pub reaction_n_per_mm: [f64; 2],
    /// Rigid body (compression, indentation): travel beyond first contact (mm) and contact
    /// force (N per mm).
    pub travel_mm: Option<f64>,
    pub contact_force_n_per_mm: Option<f64>,
    pub increments: usize,
    pub newton_iterations: usize,
    /// Meshing time of the quad mesh (shared by the element types of one size) (s).
    pub mesh_s: f64,
    /// Model setup and Newton solve (s).
    pub solve_s: f64,
    /// Peak resident memory of the process during this solve (MB; the peak is reset before each
    /// solve where Linux allows it, otherwise it is the process's peak so far).
    pub peak_memory_mb: Option<f64>,
    /// Displacement at every grid point (`None`: outside this mesh).
    #[serde(skip)]
    pub u_points: Vec<Option<[f64; 2]>>,
}

/// Per element type and materials: the fitted rate and the recommendation.
#[derive(Debug, Clone, Serialize)]
pub struct ElementSummary {
    pub test: String,
    pub element: String,
    pub d_scale: f64,
    /// Rate of the largest difference from the finest mesh against `h`.
    pub rate_max: Option<RateFit>,
    /// Rate of the RMS difference.
    pub rate_rms: Option<RateFit>,
    /// Index (in the sequence) of the coarsest mesh whose largest difference from the finest
    /// is below the tolerance, and every finer one too; `None` if no coarser mesh passes.
    pub recommended_mesh: Option<usize>,
    pub recommended_elements: Option<usize>,
    pub recommended_nodes: Option<usize>,
    pub recommended_max_diff_mm: Option<f64>,
}

/// The nearly incompressible study in numbers, at one mesh.
#[derive(Debug, Clone, Serialize)]
pub struct LockingSummary {
    /// The loading test of the locking study.
    pub test: String,
    pub d_scale: f64,
    /// Bulk over shear modulus `K/μ = 1/(C10 D)` of the materials, smallest and largest, with
    /// Table 1 and with the scaled D.
    pub bulk_to_shear_table1: [f64; 2],
    pub bulk_to_shear_scaled: [f64; 2],
    /// The mesh compared (index, elements of the quad mesh).
    pub mesh: usize,
    pub quads: usize,
    /// Per element type: displacement ratio (RMS |u| over the reference's) with Table 1 and
    /// with the scaled D, on that mesh.
    pub ratios: Vec<(String, Option<f64>, Option<f64>)>,
    /// The sentence of the report.
    pub sentence: String,
}

/// Everything a study found.
#[derive(Debug, Clone, Serialize)]
pub struct StudyResult {
    pub loading: String,
    pub tolerance_mm: f64,
    /// Grid points, points inside every mesh (compared), points masked.
    pub grid_points: usize,
    pub common_points: usize,
    pub masked_points: usize,
    /// The element type whose finest mesh is the reference of the displacement ratios.
    pub reference_element: String,
    /// Raster of the parametric shapes shared by every mesh (mm).
    pub raster_mm: f64,
    pub runs: Vec<MeshRun>,
    pub elements: Vec<ElementSummary>,
    /// The cheapest recommendation over the element types (fewest nodes), as
    /// `(element, mesh index)`, and its sentence.
    pub recommended: Option<(String, usize)>,
    pub recommendation: String,
    pub locking: Option<LockingSummary>,
    /// Mask of the common points (inside every mesh), one per grid point.
    #[serde(skip)]
    pub common: Vec<bool>,
    pub total_s: f64,
}

/// Newton tolerances well below the differences measured (1e-4 mm on displacements of about
/// 1 mm): the solver's own error must not pollute the comparison.
fn solver_options() -> SolverOptions {
    SolverOptions {
        residual_tolerance: 1e-10,
        energy_tolerance: 1e-14,
        ..SolverOptions::default()
    }
}

/// Resets the process's peak resident memory (Linux: `5` to `/proc/self/clear_refs`).
fn reset_peak_memory() {
    // Not available (or not permitted): the peak then stays the process's peak so far.
    let _ = std::fs::write("/proc/self/clear_refs", "5");
}

/// The quad mesh of level `k` (CPE4 elements; the kind is set per run).
fn quad_mesh(study: &ConvergenceStudy, k: usize) -> Result<ThighModel, ConvergenceError> {
    let mut params = study.thigh.clone();
    let what = match &study.meshes {
        MeshSequence::TargetElements(v) => {
            params.target_elements = Some(v[k]);
            format!("{} target elements", v[k])
        }
        MeshSequence::ElementSizes(v) => {
            params.element_size_mm = Some(v[k]);
            format!("element size {} mm", v[k])
        }
    };
    parametric_thigh_on_raster(&params, ElementKind::Cpe4, Some(raster_mm(study)))
        .map_err(|source| ConvergenceError::Geometry { what, source })
}

/// The raster shared by every mesh of the study (mm).
pub fn raster_mm(study: &ConvergenceStudy) -> f64 {
    study.raster_mm.unwrap_or_else(|| {
        let [a, b] = study.thigh.skin_semi_axes_mm;
        let rf = 0.5 * study.thigh.femur_diameter_mm;
        study
            .meshes
            .raster_mm(std::f64::consts::PI * (a * b - rf * rf))
    })
}

/// The thigh with elements of `kind`: quads relabelled, or each quad split into two CPE3
/// triangles (sets, surfaces and nodes kept).
pub fn with_element_kind(thigh: &ThighModel, kind: ElementKind) -> ThighModel {
    let mut t = thigh.clone();
    match kind {
        ElementKind::Cpe3 => {
            t.mesh = femu_mesh::generate::split_into_triangles(&thigh.mesh);
        }
        _ => {
            for el in &mut t.mesh.mesh.elements {
                el.kind = kind;
            }
        }
    }
    t
}

/// Meshed area (mm²).
fn meshed_area(thigh: &ThighModel) -> f64 {
    thigh.region_areas().values().sum()
}

/// Materials with every D (the volumetric compliance every registered law has) multiplied by
/// `d_scale`.
fn scaled_materials(materials: &[NamedMaterial], d_scale: f64) -> Vec<NamedMaterial> {
    materials
        .iter()
        .map(|m| {
            let mut law = m.law.clone();
            if let Some(k) = law.parameter_index("D") {
                let d = law.parameter(k);
                law.set_parameter(k, d * d_scale);
            }
            NamedMaterial {
                name: m.name.clone(),
                law,
            }
        })
        .collect()
}

/// Builds and solves one run; a failed solve is recorded in `status`, not returned as an error.
#[allow(clippy::too_many_arguments)]
fn solve_run(
    study: &ConvergenceStudy,
    loading: &Loading,
    quads: &ThighModel,
    k: usize,
    kind: ElementKind,
    d_scale: f64,
    mesh_s: f64,
    points: &[[f64; 2]],
) -> Result<MeshRun, ConvergenceError> {
    let t0 = Instant::now();
    reset_peak_memory();
    let thigh = with_element_kind(quads, kind);
    let what = format!(
        "{} mesh {} ({} elements)",
        kind.deck_name(),
        k + 1,
        thigh.mesh.mesh.elements.len()
    );
    // One material per region (named as the region), the femur fixed, no load; then the test
    // on the skin.
    let regions = thigh
        .regions
        .iter()
        .map(|r| {
            scaled_materials(&study.materials, d_scale)
                .into_iter()
                .find(|m| m.name.eq_ignore_ascii_case(r))
                .map(|m| NamedMaterial {
                    name: r.clone(),
                    law: m.law,
                })
                .ok_or_else(|| ConvergenceError::Model {
                    what: what.clone(),
                    message: format!("region {r} has no material"),
                })
        })
        .collect::<Result<Vec<_>, _>>()?;
    let spec = ModelSpec::with_regions(
        thigh.mesh.mesh.clone(),
        thigh.mesh.surfaces.clone(),
        regions,
        "FEMUR",
    );
    let mut model = spec
        .and_then(Model::new)
        .map_err(|e| ConvergenceError::Model {
            what: what.clone(),
            message: e.to_string(),
        })?;
    let skin = thigh.mesh.surfaces.get("SKIN").cloned().unwrap_or_default();
    apply_loading(&mut model, &skin, loading).map_err(|e| ConvergenceError::Model {
        what: what.clone(),
        message: e.to_string(),
    })?;
    let mut run = MeshRun {
        test: loading.name(),
        element: kind.deck_name().to_string(),
        d_scale,
        mesh: k,
        target_elements: match &study.meshes {
            MeshSequence::TargetElements(v) => Some(v[k]),
            MeshSequence::ElementSizes(_) => None,
        },
        element_size_mm: quads.element_size_mm,
        elements: model.mesh.elements.len(),
        nodes: model.node_count(),
        h_mm: (meshed_area(&thigh) / model.node_count() as f64).sqrt(),
        status: String::new(),
        points_inside: 0,
        max_diff_mm: None,
        rms_diff_mm: None,
        rms_displacement_mm: None,
        displacement_ratio: None,
        max_displacement_mm: f64::NAN,
        reaction_n_per_mm: [f64::NAN; 2],
        travel_mm: None,
        contact_force_n_per_mm: None,
        increments: 0,
        newton_iterations: 0,
        mesh_s,
        solve_s: 0.0,
        peak_memory_mb: None,
        u_points: vec![None; points.len()],
    };
    let outcome = StaticSolver::new(&model, solver_options()).and_then(|mut s| s.solve(&model));
    run.solve_s = t0.elapsed().as_secs_f64();
    run.peak_memory_mb = peak_memory_mb();
    match outcome {
        Ok(sol) => {
            run.status = "converged".into();
            run.increments = sol.report.converged_increments;
            run.newton_iterations = sol.report.newton_iterations;
            run.reaction_n_per_mm = sol.report.reaction_total;
            run.max_displacement_mm = sol
                .u
                .chunks_exact(2)
                .map(|c| c[0].hypot(c[1]))
                .fold(0.0, f64::max);
            if let Some(b) = sol.bodies.first() {
                run.travel_mm = Some(b.travel);
                run.contact_force_n_per_mm = Some(b.force);
            }
            let ip = PointInterpolation::new(&model.mesh, points);
            run.points_inside = ip.inside();
            run.u_points = ip.interpolate_vector(&sol.u);
        }
        Err(femu_mech::SolveError::Interrupted(source)) => {
            return Err(ConvergenceError::Interrupted {
                finished: Vec::new(),
                source,
            })
        }
        Err(e) => {
            run.status = format!("failed: {e}");
            run.newton_iterations = 0;
        }
    }
    Ok(run)
}

/// Largest and RMS of `|a - b|` over the common points, and the RMS of `|a|`.
fn compare(a: &[Option<[f64; 2]>], b: &[Option<[f64; 2]>], common: &[bool]) -> (f64, f64) {
    let mut max = 0.0f64;
    let mut sum = 0.0;
    let mut n = 0usize;
    for ((a, b), &c) in a.iter().zip(b).zip(common) {
        if let (true, Some(a), Some(b)) = (c, a, b) {
            let d = (a[0] - b[0]).hypot(a[1] - b[1]);
            max = max.max(d);
            sum += d * d;
            n += 1;
        }
    }
    (max, (sum / n.max(1) as f64).sqrt())
}

fn rms_magnitude(a: &[Option<[f64; 2]>], common: &[bool]) -> f64 {
    let (mut s, mut n) = (0.0, 0usize);
    for (a, &c) in a.iter().zip(common) {
        if let (true, Some(a)) = (c, a) {
            s += a[0] * a[0] + a[1] * a[1];
            n += 1;
        }
    }
    (s / n.max(1) as f64).sqrt()
}

/// Runs the whole study; `progress` receives one line per solve.
pub fn run_study(
    study: &ConvergenceStudy,
    progress: &mut dyn FnMut(&str),
) -> Result<StudyResult, ConvergenceError> {
    study
        .validate()
        .map_err(|(key, message)| ConvergenceError::Study {
            file: "study".into(),
            key,
            message,
        })?;
    let t0 = Instant::now();
    let points = study.grid.points();
    let lock_loading = locking_loading(study);
    let lock_kinds: &[ElementKind] = if study.locking { &study.elements } else { &[] };
    // The locking study's D scales: Table 1 too unless the main study already ran that test.
    let lock_scales: Vec<f64> = if lock_loading == study.loading {
        vec![study.d_scale]
    } else {
        vec![1.0, study.d_scale]
    };
    let mut runs = Vec::new();
    // A stop between or inside the solves returns the runs finished so far.
    let stopped = |runs: Vec<MeshRun>, source| ConvergenceError::Interrupted {
        finished: runs,
        source,
    };
    for k in 0..study.meshes.len() {
        if let Err(source) = femu_mesh::stop::check() {
            return Err(stopped(runs, source));
        }
        let tm = Instant::now();
        let quads = quad_mesh(study, k)?;
        let mesh_s = tm.elapsed().as_secs_f64();
        let mut jobs: Vec<(Loading, ElementKind, f64)> = study
            .elements
            .iter()
            .map(|&e| (study.loading.clone(), e, 1.0))
            .collect();
        if k < study.locking_meshes {
            for &d in &lock_scales {
                jobs.extend(lock_kinds.iter().map(|&e| (lock_loading.clone(), e, d)));
            }
        }
        for (loading, kind, d_scale) in jobs {
            let run = match femu_mesh::stop::check() {
                Err(source) => return Err(stopped(runs, source)),
                Ok(()) => solve_run(study, &loading, &quads, k, kind, d_scale, mesh_s, &points),
            };
            let run = match run {
                Err(ConvergenceError::Interrupted { source, .. }) => {
                    return Err(stopped(runs, source))
                }
                r => r?,
            };
            progress(&format!(
                "{} {:<5} D x {:<6} mesh {}: {:>6} elements, {:>6} nodes, h {:.3} mm: {}, max |u| {:.5} mm, {} Newton iterations, {:.2} s",
                run.test,
                run.element,
                run.d_scale,
                k + 1,
                run.elements,
                run.nodes,
                run.h_mm,
                run.status,
                run.max_displacement_mm,
                run.newton_iterations,
                run.solve_s
            ));
            runs.push(run);
        }
    }
    // Common points: inside every mesh that was solved.
    let common: Vec<bool> = (0..points.len())
        .map(|p| {
            runs.iter()
                .filter(|r| r.status == "converged")
                .all(|r| r.u_points[p].is_some())
        })
        .collect();
    let common_points = common.iter().filter(|&&c| c).count();
    if common_points == 0 {
        return Err(ConvergenceError::NoCommonPoints {
            points: points.len(),
            origin: study.grid.origin_mm,
            spacing: study.grid.spacing_mm,
        });
    }
    let reference_kind = if study.elements.contains(&ElementKind::Cpe4h) {
        ElementKind::Cpe4h
    } else {
        study.elements[0]
    };
    let find = |runs: &[MeshRun], test: &str, kind: ElementKind, d: f64, k: usize| {
        runs.iter().position(|r| {
            r.test == test
                && r.element == kind.deck_name()
                && r.d_scale == d
                && r.mesh == k
                && r.status == "converged"
        })
    };
    // Groups of runs compared with their own finest mesh: (test, element, D scale, finest).
    let main_test = study.loading.name();
    let mut groups: Vec<(String, ElementKind, f64, usize)> = study
        .elements
        .iter()
        .map(|&k| (main_test.clone(), k, 1.0, study.meshes.len() - 1))
        .collect();
    for &d in &lock_scales {
        for &k in lock_kinds {
            groups.push((lock_loading.name(), k, d, study.locking_meshes - 1));
        }
    }
    let mut summaries = Vec::new();
    for (test, kind, d, finest) in &groups {
        let (kind, d, finest) = (*kind, *d, *finest);
        let fine = find(&runs, test, kind, d, finest);
        let reference = find(&runs, test, reference_kind, d, finest);
        let ref_rms = reference.map(|i| rms_magnitude(&runs[i].u_points, &common));
        let fine_u = fine.map(|i| runs[i].u_points.clone());
        let h_f = fine.map(|i| runs[i].h_mm).unwrap_or(f64::NAN);
        for r in runs.iter_mut() {
            if &r.test != test
                || r.element != kind.deck_name()
                || r.d_scale != d
                || r.status != "converged"
            {
                continue;
            }
            let rms = rms_magnitude(&r.u_points, &common);
            r.rms_displacement_mm = Some(rms);
            r.displacement_ratio = ref_rms.filter(|&v| v > 0.0).map(|v| rms / v);
            if let Some(fu) = &fine_u {
                let (max, rms) = compare(&r.u_points, fu, &common);
                r.max_diff_mm = Some(max);
                r.rms_diff_mm = Some(rms);
            }
        }
        let coarser: Vec<&MeshRun> = runs
            .iter()
            .filter(|r| {
                &r.test == test
                    && r.element == kind.deck_name()
                    && r.d_scale == d
                    && r.mesh < finest
                    && r.max_diff_mm.is_some()
            })
            .collect();
        let hs: Vec<f64> = coarser.iter().map(|r| r.h_mm).collect();
        let maxes: Vec<f64> = coarser.iter().filter_map(|r| r.max_diff_mm).collect();
        let rmses: Vec<f64> = coarser.iter().filter_map(|r| r.rms_diff_mm).collect();
        let rate_max = fit_rate_against_finest(&hs, &maxes, h_f);
        let rate_rms = fit_rate_against_finest(&hs, &rmses, h_f);
        // The coarsest mesh from which every finer mesh (short of the finest) passes too.
        let mut recommended: Option<&MeshRun> = None;
        for r in coarser.iter().rev() {
            if r.max_diff_mm.is_some_and(|v| v < study.tolerance_mm) {
                recommended = Some(r);
            } else {
                break;
            }
        }
        summaries.push(ElementSummary {
            test: test.clone(),
            element: kind.deck_name().to_string(),
            d_scale: d,
            rate_max,
            rate_rms,
            recommended_mesh: recommended.map(|r| r.mesh),
            recommended_elements: recommended.map(|r| r.elements),
            recommended_nodes: recommended.map(|r| r.nodes),
            recommended_max_diff_mm: recommended.and_then(|r| r.max_diff_mm),
        });
    }
    // The cheapest recommendation (fewest nodes) of the main study.
    let best = summaries
        .iter()
        .filter(|s| s.test == main_test && s.d_scale == 1.0 && s.recommended_mesh.is_some())
        .min_by_key(|s| {
            (
                s.recommended_nodes.unwrap_or(usize::MAX),
                s.element != reference_kind.deck_name(),
            )
        });
    let recommended = best.map(|s| (s.element.clone(), s.recommended_mesh.unwrap_or(0)));
    let recommendation = recommendation_sentence(study, &runs, &summaries, best, common_points);
    let locking = study
        .locking
        .then(|| locking_summary(study, &lock_loading, &runs, reference_kind));
    Ok(StudyResult {
        loading: main_test,
        tolerance_mm: study.tolerance_mm,
        grid_points: points.len(),
        common_points,
        masked_points: points.len() - common_points,
        reference_element: reference_kind.deck_name().to_string(),
        raster_mm: raster_mm(study),
        runs,
        elements: summaries,
        recommended,
        recommendation,
        locking,
        common,
        total_s: t0.elapsed().as_secs_f64(),
    })
}

/// The loading of the locking study: the study's own if it presses a rigid body on the skin;
/// for contention the seed's compression (plate, 0.1 N/mm, anterior). A nearly incompressible
/// thigh held at its femur can hardly change volume, so a pressure all around it barely moves
/// it (max |u| about 1e-3 mm with D / 1000 against 1 mm with Table 1) and shows no locking;
/// a plate forces the shape change (the tissue flows sideways) that CPE4 cannot represent at
/// J = 1 on every Gauss point.
pub fn locking_loading(study: &ConvergenceStudy) -> Loading {
    if study.loading.has_rigid_body() {
        study.loading.clone()
    } else {
        Loading::seed_compression()
    }
}

fn recommendation_sentence(
    study: &ConvergenceStudy,
    runs: &[MeshRun],
    summaries: &[ElementSummary],
    best: Option<&ElementSummary>,
    common_points: usize,
) -> String {
    let tol = study.tolerance_mm;
    match best {
        Some(s) => format!(
            "Recommended mesh: {} elements of {} ({} nodes, mesh {} of {}); its displacement at the {} common grid points differs from the finest {} mesh by at most {:.2e} mm < {:.0e} mm.",
            s.recommended_elements.unwrap_or(0),
            s.element,
            s.recommended_nodes.unwrap_or(0),
            s.recommended_mesh.unwrap_or(0) + 1,
            study.meshes.len(),
            common_points,
            s.element,
            s.recommended_max_diff_mm.unwrap_or(f64::NAN),
            tol
        ),
        None => {
            let main = study.loading.name();
            let closest = summaries
                .iter()
                .filter(|s| s.test == main && s.d_scale == 1.0)
                .filter_map(|s| {
                    runs.iter()
                        .filter(|r| {
                            r.test == main
                                && r.element == s.element
                                && r.d_scale == 1.0
                                && r.mesh + 1 < study.meshes.len()
                        })
                        .filter_map(|r| r.max_diff_mm.map(|d| (d, r)))
                        .min_by(|a, b| a.0.total_cmp(&b.0))
                })
                .min_by(|a, b| a.0.total_cmp(&b.0));
            match closest {
                Some((d, r)) => format!(
                    "No mesh coarser than the finest meets the tolerance {tol:.0e} mm: the closest is {} elements of {} ({:.2e} mm from its finest mesh, RMS {:.2e} mm). Refine the sequence (add finer meshes) or relax tolerance_mm.",
                    r.elements, r.element, d, r.rms_diff_mm.unwrap_or(f64::NAN)
                ),
                None => format!("No mesh could be compared with the tolerance {tol:.0e} mm (see the failed solves)."),
            }
        }
    }
}

fn locking_summary(
    study: &ConvergenceStudy,
    loading: &Loading,
    runs: &[MeshRun],
    reference_kind: ElementKind,
) -> LockingSummary {
    let ks = |scale: f64| {
        let v: Vec<f64> = study
            .materials
            .iter()
            .map(|m| m.law.bulk_modulus() / (m.law.shear_modulus() * scale))
            .collect();
        [
            v.iter().copied().fold(f64::INFINITY, f64::min),
            v.iter().copied().fold(0.0, f64::max),
        ]
    };
    let test = loading.name();
    let ratio = |kind: &str, d: f64, mesh: usize| {
        runs.iter()
            .find(|r| r.test == test && r.element == kind && r.d_scale == d && r.mesh == mesh)
            .and_then(|r| r.displacement_ratio)
    };
    // The coarsest mesh: where locking shows most (the finest locking mesh is the reference).
    let mesh = 0;
    let ratios: Vec<(String, Option<f64>, Option<f64>)> = study
        .elements
        .iter()
        .map(|k| {
            let n = k.deck_name();
            (
                n.to_string(),
                ratio(n, 1.0, mesh),
                ratio(n, study.d_scale, mesh),
            )
        })
        .collect();
    let quads = runs
        .iter()
        .find(|r| r.test == test && r.mesh == mesh && r.element != "CPE3")
        .map_or(0, |r| r.elements);
    let pct = |v: Option<f64>| v.map_or("n/a".to_string(), |v| format!("{:.1} %", 100.0 * v));
    let parts: Vec<String> = ratios
        .iter()
        .map(|(n, t1, sc)| format!("{n} {} (Table 1 D: {})", pct(*sc), pct(*t1)))
        .collect();
    let kt = ks(1.0);
    let kd = ks(study.d_scale);
    let scaled = |n: &str| ratios.iter().find(|r| r.0 == n).and_then(|r| r.2);
    let verdict = match (scaled("CPE4"), scaled("CPE4H")) {
        (Some(a), Some(b)) if a < 0.95 * b => format!(
            "CPE4 locks: {:.0} % stiffer than the reference, where CPE4H is within {:.1} % of it; CPE4H (the seed's choice) is the element for nearly incompressible tissue.",
            100.0 * (1.0 - a),
            100.0 * (1.0 - b).abs()
        ),
        (Some(a), Some(b)) => format!(
            "CPE4 and CPE4H differ by {:.1} % only: no marked locking at this D.",
            100.0 * (b - a)
        ),
        _ => "CPE4 and CPE4H were not both in the study.".to_string(),
    };
    let finest_quads = runs
        .iter()
        .find(|r| r.test == test && r.mesh + 1 == study.locking_meshes && r.element != "CPE3")
        .map_or(0, |r| r.elements);
    let sentence = format!(
        "Locking check ({test}, every D x {}, K/mu {:.0}-{:.0} instead of {:.0}-{:.0}): on the coarsest mesh ({} quads) the RMS displacement at the common points, relative to the {} mesh of {} quads with the same materials, is {}. {}",
        study.d_scale,
        kd[0],
        kd[1],
        kt[0],
        kt[1],
        quads,
        reference_kind.deck_name(),
        finest_quads,
        parts.join(", "),
        verdict
    );
    LockingSummary {
        test,
        d_scale: study.d_scale,
        bulk_to_shear_table1: kt,
        bulk_to_shear_scaled: kd,
        mesh,
        quads,
        ratios,
        sentence,
    }
}
