//! `femu solve` and `femu forward`: read or build a model, solve it, write the output folder.

use crate::study;
use crate::QuadElement;
use anyhow::{bail, Context, Result};
use femu_mech::loading::Loading;
use femu_mech::output::{peak_memory_mb, write_displacements_csv, write_result_vtu};
use femu_mech::solver::IncrementRecord;
use femu_mech::{Model, Solution, SolveError, SolveReport, SolverOptions, StaticSolver};
use femu_mesh::Deck;
use serde::Serialize;
use std::path::Path;
use std::time::Instant;

/// The built-in parametric thigh (femu-geometry) with about `elements` quads of `kind`, as a
/// contention deck: Table 1 materials, femur fixed, 20 mmHg on the skin; and its skin faces.
pub fn thigh_deck(
    elements: usize,
    kind: femu_mesh::ElementKind,
) -> Result<(Deck, Vec<(usize, usize)>)> {
    if !(100..=500_000).contains(&elements) {
        bail!("the number of elements must be in [100, 500000], got {elements}");
    }
    let params = femu_geometry::ThighParams {
        target_elements: Some(elements),
        ..Default::default()
    };
    let thigh = femu_geometry::parametric_thigh(&params, kind)?;
    let skin = thigh.mesh.surfaces.get("SKIN").cloned().unwrap_or_default();
    let deck = femu_geometry::contention_deck(
        &thigh,
        &femu_geometry::table1_materials(),
        femu_geometry::CONTENTION_MPA,
    )?;
    Ok((deck, skin))
}

/// The built-in thigh as a model without loads (femur fixed), and its skin faces.
pub fn thigh_model(
    elements: usize,
    kind: femu_mesh::ElementKind,
) -> Result<(Model, Vec<(usize, usize)>)> {
    let (mut deck, skin) = thigh_deck(elements, kind)?;
    deck.pressures.clear();
    Ok((Model::from_deck(deck)?, skin))
}

/// The value of the parameter `name` of `law`, if its law has one.
fn parameter_named(law: &dyn femu_mech::Material, name: &str) -> Option<f64> {
    law.parameter_index(name).map(|k| law.parameter(k))
}

#[derive(Serialize)]
struct MaterialSummary {
    name: String,
    c10_kpa: Option<f64>,
    d_per_mpa: Option<f64>,
    elements: usize,
}

#[derive(Serialize)]
struct RigidBodySummary {
    name: String,
    body: String,
    control: String,
    travel_mm: f64,
    force_n_per_mm: f64,
    active_nodes: usize,
    max_penetration_mm: f64,
    penetration_limit_mm: f64,
    penalty_n_per_mm: f64,
    augmentations: usize,
}

#[derive(Serialize)]
struct Timings {
    read_s: f64,
    setup_s: f64,
    solve_s: f64,
    assembly_s: f64,
    factorization_s: f64,
    triangular_solve_s: f64,
    output_s: f64,
    total_s: f64,
}

#[derive(Serialize)]
struct Summary<'a> {
    femu_version: &'static str,
    command: &'a str,
    input: String,
    status: &'static str,
    error: Option<String>,
    nodes: usize,
    elements: usize,
    element_types: std::collections::BTreeMap<&'static str, usize>,
    materials: Vec<MaterialSummary>,
    prescribed_dofs: usize,
    pressure_faces: usize,
    rigid_bodies: Vec<RigidBodySummary>,
    load_factor: f64,
    max_displacement_mm: f64,
    reaction_force_total_n_per_mm: [f64; 2],
    increments: usize,
    newton_iterations: usize,
    cutbacks: usize,
    solver_options: SolverOptions,
    report: &'a SolveReport,
    timings: Timings,
    peak_memory_mb: Option<f64>,
}

/// Prints one line per increment (unless quiet) and, if asked, the Newton table.
fn progress(quiet: bool, table: bool) -> impl FnMut(&IncrementRecord) {
    move |rec: &IncrementRecord| {
        if quiet {
            return;
        }
        if table {
            for it in &rec.iterations {
                eprintln!(
                    "    iteration {:>2}: |R| = {:.3e} (ref {:.3e}), energy {:.3e}, step {:.2}, max|du| {:.3e} mm",
                    it.iteration, it.residual_norm, it.reference_force, it.energy_norm, it.step_length, it.max_correction
                );
            }
        }
        match &rec.failure {
            None => eprintln!(
                "increment {:>3}: load factor {:.4} (+{:.4}), {} Newton iterations",
                rec.increment,
                rec.lambda,
                rec.dlambda,
                rec.iterations.len()
            ),
            Some(why) => eprintln!(
                "increment {:>3}: load factor {:.4} (+{:.4}) cut back: {why}",
                rec.increment, rec.lambda, rec.dlambda
            ),
        }
    }
}

/// Solves `model` and writes `displacements.csv`, `result.vtu`, `summary.json` into `out`,
/// and for each rigid body `contact_pressure.csv` and `force_displacement.csv` (in a
/// sub-folder named after the body when there are several). A solve that stops midway still
/// writes the last converged state, then returns the error.
#[allow(clippy::too_many_arguments)]
pub fn solve_model(
    model: &Model,
    input: &str,
    command: &str,
    out: &Path,
    read_s: f64,
    table: bool,
    figures: bool,
    quiet: bool,
) -> Result<()> {
    let t0 = Instant::now();
    std::fs::create_dir_all(out)
        .with_context(|| format!("cannot create output folder {}", out.display()))?;
    // Nothing reads the tangent at the solution here (no sensitivities): not assembled.
    let options = SolverOptions {
        final_tangent: false,
        ..SolverOptions::default()
    };
    let mut solver = StaticSolver::new(model, options)?;
    let setup_s = t0.elapsed().as_secs_f64();
    if !quiet {
        eprintln!(
            "{input}: {} nodes, {} elements, {} equations; solving",
            model.node_count(),
            model.mesh.elements.len(),
            solver.equations()
        );
    }
    let t1 = Instant::now();
    let mut on_increment = progress(quiet, table);
    let outcome = solver.solve_with(model, None, &mut on_increment);
    let solve_s = t1.elapsed().as_secs_f64();
    let (solution, error): (Solution, Option<SolveError>) = match outcome {
        Ok(s) => (s, None),
        Err(SolveError::NotConverged { ref partial, .. })
        | Err(SolveError::TooManyIncrements { ref partial, .. }) => {
            let p = (**partial).clone();
            (p, Some(outcome.unwrap_err()))
        }
        Err(e) => return Err(e.into()),
    };
    // The factors, tangent and element buffers are not needed for the output: free them first
    // (the output's own buffers then never add to the solve's peak memory).
    drop(solver);
    write_solved(
        model,
        &solution,
        error,
        &SolveContext {
            input,
            command,
            out,
            figures,
            quiet,
            options,
            read_s,
            setup_s,
            solve_s,
        },
    )
}

/// What [`write_solved`] reports besides the solution.
pub struct SolveContext<'a> {
    pub input: &'a str,
    pub command: &'a str,
    pub out: &'a Path,
    pub figures: bool,
    pub quiet: bool,
    pub options: SolverOptions,
    pub read_s: f64,
    pub setup_s: f64,
    pub solve_s: f64,
}

/// Writes the output folder of a solved model (`displacements.csv`, `result.vtu`, contact
/// results, figures, `summary.json`); returns `error` (a solve that stopped midway, whose last
/// converged state `solution` is) with the folder named.
pub fn write_solved(
    model: &Model,
    solution: &Solution,
    error: Option<SolveError>,
    cx: &SolveContext,
) -> Result<()> {
    let SolveContext {
        input,
        command,
        out,
        figures,
        quiet,
        options,
        read_s,
        setup_s,
        solve_s,
    } = *cx;
    let t0 = Instant::now();
    std::fs::create_dir_all(out)
        .with_context(|| format!("cannot create output folder {}", out.display()))?;
    // The two result files are independent: written at once, one per core.
    let (csv, vtu) = rayon::join(
        || write_displacements_csv(&out.join("displacements.csv"), model, &solution.u),
        || write_result_vtu(&out.join("result.vtu"), model, solution),
    );
    csv.with_context(|| format!("cannot write {}", out.join("displacements.csv").display()))?;
    vtu.with_context(|| format!("cannot write {}", out.join("result.vtu").display()))?;
    let mut body_dirs = Vec::new();
    for b in 0..model.contacts.len() {
        let dir = if model.contacts.len() == 1 {
            out.to_path_buf()
        } else {
            out.join(&model.contacts[b].name)
        };
        std::fs::create_dir_all(&dir)?;
        femu_mech::output::write_contact_csv(&dir, model, solution, b)
            .with_context(|| format!("cannot write contact results into {}", dir.display()))?;
        body_dirs.push(dir);
    }
    if figures {
        crate::figures::write_solve_figures(out, &body_dirs, input, model, solution)?;
    }
    let output_s = t0.elapsed().as_secs_f64();
    let mut element_types = std::collections::BTreeMap::new();
    for el in &model.mesh.elements {
        *element_types.entry(el.kind.deck_name()).or_insert(0) += 1;
    }
    let materials = model
        .materials
        .iter()
        .enumerate()
        .map(|(m, nm)| MaterialSummary {
            name: nm.name.clone(),
            c10_kpa: parameter_named(&*nm.law, "C10").map(|c| c * 1e3),
            d_per_mpa: parameter_named(&*nm.law, "D"),
            elements: model.element_material.iter().filter(|&&x| x == m).count(),
        })
        .collect();
    let r = &solution.report;
    let max_u = solution
        .u
        .chunks_exact(2)
        .map(|c| c[0].hypot(c[1]))
        .fold(0.0f64, f64::max);
    let summary = Summary {
        femu_version: env!("CARGO_PKG_VERSION"),
        command,
        input: input.to_string(),
        status: if error.is_none() {
            "converged"
        } else {
            "not converged"
        },
        error: error.as_ref().map(|e| e.to_string()),
        nodes: model.node_count(),
        elements: model.mesh.elements.len(),
        element_types,
        materials,
        prescribed_dofs: model.constraints.len(),
        pressure_faces: model.pressures.len(),
        rigid_bodies: model
            .contacts
            .iter()
            .zip(&solution.bodies)
            .map(|(c, b)| RigidBodySummary {
                name: c.name.clone(),
                body: c.body.describe(),
                control: format!("{:?}", c.control),
                travel_mm: b.travel,
                force_n_per_mm: b.force,
                active_nodes: b.active_nodes,
                max_penetration_mm: b.max_penetration,
                penetration_limit_mm: b.penetration_limit,
                penalty_n_per_mm: b.penalty,
                augmentations: b.augmentations,
            })
            .collect(),
        load_factor: r.lambda,
        max_displacement_mm: max_u,
        reaction_force_total_n_per_mm: r.reaction_total,
        increments: r.converged_increments,
        newton_iterations: r.newton_iterations,
        cutbacks: r.cutbacks,
        solver_options: options,
        report: r,
        timings: Timings {
            read_s,
            setup_s,
            solve_s,
            assembly_s: r.assembly_time_s,
            factorization_s: r.factorization_time_s,
            triangular_solve_s: r.triangular_solve_time_s,
            output_s,
            total_s: read_s + setup_s + solve_s + output_s,
        },
        peak_memory_mb: peak_memory_mb(),
    };
    let json = serde_json::to_string_pretty(&summary)?;
    std::fs::write(out.join("summary.json"), json)
        .with_context(|| format!("cannot write {}", out.join("summary.json").display()))?;
    if !quiet {
        eprintln!(
            "{}: max |u| = {max_u:.4} mm, reaction {:.3e}, {:.3e} N/mm; {} increments, {} Newton iterations; solve {:.3} s; results in {}",
            summary.status,
            r.reaction_total[0],
            r.reaction_total[1],
            r.converged_increments,
            r.newton_iterations,
            solve_s,
            out.display()
        );
    }
    if !quiet {
        for b in &summary.rigid_bodies {
            eprintln!(
                "{}: travel {:.4} mm for {:.4e} N/mm, {} nodes in contact, penetration {:.2e} mm (limit {:.2e})",
                b.name, b.travel_mm, b.force_n_per_mm, b.active_nodes, b.max_penetration_mm, b.penetration_limit_mm
            );
        }
    }
    match error {
        None => Ok(()),
        Some(e) => Err(anyhow::Error::new(e).context(format!(
            "the solve stopped at load factor {:.4}; the last converged state is in {}",
            r.lambda,
            out.display()
        ))),
    }
}

/// `femu solve INPUT [--study S] --out DIR`.
pub fn solve(
    input: &Path,
    study_file: Option<&Path>,
    out: &Path,
    table: bool,
    figures: bool,
    quiet: bool,
) -> Result<()> {
    let t0 = Instant::now();
    let ext = input
        .extension()
        .and_then(|e| e.to_str())
        .unwrap_or("")
        .to_ascii_lowercase();
    let name = input.display().to_string();
    let model = match ext.as_str() {
        "inp" => {
            if study_file.is_some() {
                bail!("--study is for .msh inputs; a deck carries its own materials and loads");
            }
            let deck = femu_mesh::read_inp(input)?;
            Model::from_deck(deck).with_context(|| format!("invalid model in {name}"))?
        }
        "msh" => {
            let Some(sf) = study_file else {
                bail!("{name}: a Gmsh mesh needs --study STUDY.toml naming materials and loads");
            };
            let study = study::read(sf)?;
            let msh = femu_mesh::read_msh(input)?;
            let context = || format!("setting up {name} with {}", sf.display());
            let rigid_faces = match &study.rigid {
                Some((curve, _)) => {
                    Some(femu_mech::build::curve_faces(&msh, curve).with_context(context)?)
                }
                None => None,
            };
            let deck = femu_mech::build::deck_from_msh(msh, &study.setup).with_context(context)?;
            let mut model =
                Model::from_deck(deck).with_context(|| format!("invalid model in {name}"))?;
            if let (Some((_, loading)), Some(faces)) = (&study.rigid, rigid_faces) {
                femu_mech::loading::apply_loading(&mut model, &faces, loading)
                    .with_context(context)?;
            }
            model
        }
        _ => bail!("{name}: unknown input type (expected .inp or .msh)"),
    };
    let read_s = t0.elapsed().as_secs_f64();
    solve_model(&model, &name, "solve", out, read_s, table, figures, quiet)
}

/// `femu forward`: the seed's loading tests on the built-in parametric thigh, one sub-folder
/// per test.
pub fn forward(
    out: &Path,
    element: QuadElement,
    elements: usize,
    tests: &[Loading],
    quiet: bool,
) -> Result<()> {
    std::fs::create_dir_all(out)
        .with_context(|| format!("cannot create output folder {}", out.display()))?;
    let t0 = Instant::now();
    let (base_deck, skin) = thigh_deck(elements, element.kind())?;
    let mesh_s = t0.elapsed().as_secs_f64();
    for loading in tests {
        let t1 = Instant::now();
        let dir = out.join(loading.name());
        std::fs::create_dir_all(&dir)
            .with_context(|| format!("cannot create output folder {}", dir.display()))?;
        let mut deck = base_deck.clone();
        deck.pressures.clear();
        if let Loading::Contention { pressure } = loading {
            // Contention is expressible as a deck: write it; it runs unchanged in Abaqus, and in
            // CalculiX with CPE4 elements (`--element cpe4`; ccx has no hybrid element).
            let mut with_pressure = base_deck.clone();
            with_pressure
                .pressures
                .iter_mut()
                .for_each(|p| p.magnitude = *pressure);
            let deck_path = dir.join("model.inp");
            femu_mesh::write_inp_file(&with_pressure, &deck_path)
                .with_context(|| format!("cannot write {}", deck_path.display()))?;
        }
        let mut model = Model::from_deck(deck)?;
        femu_mech::loading::apply_loading(&mut model, &skin, loading)?;
        if !quiet {
            eprintln!(
                "forward: {} on the built-in thigh ({} elements, Table 1 materials, femur fixed) -> {}",
                loading.name(),
                model.mesh.elements.len(),
                dir.display()
            );
        }
        let read_s = mesh_s + t1.elapsed().as_secs_f64();
        solve_model(
            &model,
            &format!("built-in thigh, {}", loading.name()),
            "forward",
            &dir,
            read_s,
            false,
            true,
            quiet,
        )?;
    }
    Ok(())
}
