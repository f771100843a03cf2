//! One solve and its output folder: `displacements.csv`, `result.vtu`, contact results,
//! pictures and `summary.json` (conventions.md: `femu solve DECK.inp --out DIR`).

use crate::error::{Context, Result};
use crate::output::{create_dir, write_json};
use crate::progress::Progress;
use femu_mech::output::{peak_memory_mb, write_displacements_csv, write_result_vtu};
use femu_mech::solver::IncrementRecord;
use femu_mech::{Model, Solution, SolveError, SolveReport, SolverOptions, StaticSolver};
use serde::{Deserialize, Serialize};
use std::collections::BTreeMap;
use std::path::Path;
use std::time::Instant;

/// A material of a solved model, as its summary lists it.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct MaterialSummary {
    pub name: String,
    /// C10 (kPa) and D (MPa⁻¹), when the material's law has them.
    pub c10_kpa: Option<f64>,
    pub d_per_mpa: Option<f64>,
    pub elements: usize,
    /// The material's law (`neo-hookean`, `mooney-rivlin`, `yeoh`).
    #[serde(default)]
    pub law: String,
    /// Every parameter of its law by its study-file key, in the unit the key names
    /// (`c10_kpa`, `c20_kpa`, `c30_kpa`, `d_per_mpa`).
    #[serde(default)]
    pub parameters: BTreeMap<String, f64>,
}

/// A rigid body of a solved model.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct RigidBodySummary {
    pub name: String,
    pub body: String,
    pub control: String,
    pub travel_mm: f64,
    pub force_n_per_mm: f64,
    pub active_nodes: usize,
    pub max_penetration_mm: f64,
    pub penetration_limit_mm: f64,
    pub penalty_n_per_mm: f64,
    pub augmentations: usize,
}

/// Where the time of a solve went (s).
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct SolveTimings {
    pub read_s: f64,
    pub setup_s: f64,
    pub solve_s: f64,
    pub assembly_s: f64,
    pub factorization_s: f64,
    pub triangular_solve_s: f64,
    pub output_s: f64,
    pub total_s: f64,
}

/// `summary.json` of a solve.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct SolveSummary {
    pub femu_version: String,
    pub command: String,
    pub input: String,
    /// `converged` or `not converged`.
    pub status: String,
    pub error: Option<String>,
    pub nodes: usize,
    pub elements: usize,
    pub element_types: BTreeMap<String, usize>,
    pub materials: Vec<MaterialSummary>,
    pub prescribed_dofs: usize,
    /// Labels of the nodes no element uses (e.g. reference points): held at zero
    /// displacement, written as such, and named in a warning.
    #[serde(default)]
    pub unused_nodes: Vec<i64>,
    pub pressure_faces: usize,
    pub rigid_bodies: Vec<RigidBodySummary>,
    pub load_factor: f64,
    pub max_displacement_mm: f64,
    pub reaction_force_total_n_per_mm: [f64; 2],
    pub increments: usize,
    pub newton_iterations: usize,
    pub cutbacks: usize,
    pub solver_options: SolverOptions,
    pub report: SolveReport,
    pub timings: SolveTimings,
    pub peak_memory_mb: Option<f64>,
}

/// Prints one line per increment and, if asked, the Newton table.
fn increment_notes<'a>(
    progress: &'a dyn Progress,
    table: bool,
) -> impl FnMut(&IncrementRecord) + 'a {
    move |rec: &IncrementRecord| {
        if table {
            for it in &rec.iterations {
                progress.note(&format!(
                    "    iteration {:>2}: |R| = {:.3e} (ref {:.3e}), energy {:.3e}, step {:.2}, max|du| {:.3e} mm",
                    it.iteration, it.residual_norm, it.reference_force, it.energy_norm, it.step_length, it.max_correction
                ));
            }
        }
        match &rec.failure {
            None => progress.note(&format!(
                "increment {:>3}: load factor {:.4} (+{:.4}), {} Newton iterations",
                rec.increment,
                rec.lambda,
                rec.dlambda,
                rec.iterations.len()
            )),
            Some(why) => progress.note(&format!(
                "increment {:>3}: load factor {:.4} (+{:.4}) cut back: {why}",
                rec.increment, rec.lambda, rec.dlambda
            )),
        }
    }
}

/// How [`solve_model`] reports and what it draws.
#[derive(Debug, Clone, Copy)]
pub struct SolveOutput<'a> {
    /// What was solved, for the messages and the summary.
    pub input: &'a str,
    /// The command, for the summary.
    pub command: &'a str,
    pub out: &'a Path,
    /// Seconds spent reading or building the model.
    pub read_s: f64,
    /// Print the Newton table.
    pub newton_table: bool,
    pub figures: bool,
}

/// Solves `model` and writes its output folder (see [`write_solved`]). A solve that stops
/// midway still writes the last converged state, then returns the error.
pub fn solve_model(
    model: &Model,
    o: &SolveOutput,
    progress: &dyn Progress,
) -> Result<SolveSummary> {
    let t0 = Instant::now();
    create_dir(o.out)?;
    // Nothing reads the tangent at the solution here (no sensitivities): not assembled.
    let options = SolverOptions {
        final_tangent: false,
        ..SolverOptions::default()
    };
    let mut solver = StaticSolver::new(model, options)?;
    let setup_s = t0.elapsed().as_secs_f64();
    let unused = model.unused_nodes();
    if !unused.is_empty() {
        let labels: Vec<String> = unused
            .iter()
            .take(10)
            .map(|&n| model.mesh.node_labels[n].to_string())
            .collect();
        progress.warn(&format!(
            "{}: {} node(s) belong to no element ({}{}): held at zero displacement (listed in summary.json, unused_nodes)",
            o.input,
            unused.len(),
            labels.join(", "),
            if unused.len() > 10 { ", ..." } else { "" }
        ));
    }
    progress.note(&format!(
        "{}: {} nodes, {} elements, {} equations; solving",
        o.input,
        model.node_count(),
        model.mesh.elements.len(),
        solver.equations()
    ));
    let t1 = Instant::now();
    let mut on_increment = increment_notes(progress, o.newton_table);
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
            input: o.input,
            command: o.command,
            out: o.out,
            figures: o.figures,
            options,
            read_s: o.read_s,
            setup_s,
            solve_s,
        },
        progress,
    )
}

/// What [`write_solved`] reports besides the solution.
pub struct SolveContext<'a> {
    pub input: &'a str,
    pub command: &'a str,
    pub out: &'a Path,
    pub figures: bool,
    pub options: SolverOptions,
    pub read_s: f64,
    pub setup_s: f64,
    pub solve_s: f64,
}

/// Writes the output folder of a solved model (`displacements.csv`, `result.vtu`, contact
/// results, figures, `summary.json`); returns its summary, or `error` (a solve that stopped
/// midway, whose last converged state `solution` is) with the folder named.
pub fn write_solved(
    model: &Model,
    solution: &Solution,
    error: Option<SolveError>,
    cx: &SolveContext,
    progress: &dyn Progress,
) -> Result<SolveSummary> {
    let t0 = Instant::now();
    let out = cx.out;
    create_dir(out)?;
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
        create_dir(&dir)?;
        femu_mech::output::write_contact_csv(&dir, model, solution, b)
            .with_context(|| format!("cannot write contact results into {}", dir.display()))?;
        body_dirs.push(dir);
    }
    if cx.figures {
        crate::figures::write_solve_figures(out, &body_dirs, cx.input, model, solution)?;
    }
    let output_s = t0.elapsed().as_secs_f64();
    let summary = summary(model, solution, error.as_ref(), cx, output_s);
    write_json(&out.join("summary.json"), &summary)?;
    let r = &solution.report;
    progress.note(&format!(
        "{}: max |u| = {:.4} mm, reaction {:.3e}, {:.3e} N/mm; {} increments, {} Newton iterations; solve {:.3} s; results in {}",
        summary.status,
        summary.max_displacement_mm,
        r.reaction_total[0],
        r.reaction_total[1],
        r.converged_increments,
        r.newton_iterations,
        cx.solve_s,
        out.display()
    ));
    for b in &summary.rigid_bodies {
        progress.note(&format!(
            "{}: travel {:.4} mm for {:.4e} N/mm, {} nodes in contact, penetration {:.2e} mm (limit {:.2e})",
            b.name, b.travel_mm, b.force_n_per_mm, b.active_nodes, b.max_penetration_mm, b.penetration_limit_mm
        ));
    }
    match error {
        None => Ok(summary),
        Some(e) => Err(crate::Error::from(e).context(format!(
            "the solve stopped at load factor {:.4}; the last converged state is in {}",
            r.lambda,
            out.display()
        ))),
    }
}

/// The value of the parameter `name` of `law`, if its law has one.
fn parameter_named(law: &dyn femu_mech::Material, name: &str) -> Option<f64> {
    law.parameter_index(name).map(|k| law.parameter(k))
}

/// The summary of a solve.
fn summary(
    model: &Model,
    solution: &Solution,
    error: Option<&SolveError>,
    cx: &SolveContext,
    output_s: f64,
) -> SolveSummary {
    let mut element_types = BTreeMap::new();
    for el in &model.mesh.elements {
        *element_types
            .entry(el.kind.deck_name().to_string())
            .or_insert(0) += 1;
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
            law: nm.law.spec().name.to_string(),
            parameters: crate::output::keyed_parameters(&*nm.law),
        })
        .collect();
    let r = &solution.report;
    let max_u = solution
        .u
        .chunks_exact(2)
        .map(|c| c[0].hypot(c[1]))
        .fold(0.0f64, f64::max);
    SolveSummary {
        femu_version: env!("CARGO_PKG_VERSION").into(),
        command: cx.command.into(),
        input: cx.input.to_string(),
        status: if error.is_none() {
            "converged"
        } else {
            "not converged"
        }
        .into(),
        error: error.map(|e| e.to_string()),
        nodes: model.node_count(),
        elements: model.mesh.elements.len(),
        element_types,
        materials,
        prescribed_dofs: model.constraints.len(),
        unused_nodes: model
            .unused_nodes()
            .into_iter()
            .map(|n| model.mesh.node_labels[n])
            .collect(),
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
        solver_options: cx.options,
        report: r.clone(),
        timings: SolveTimings {
            read_s: cx.read_s,
            setup_s: cx.setup_s,
            solve_s: cx.solve_s,
            assembly_s: r.assembly_time_s,
            factorization_s: r.factorization_time_s,
            triangular_solve_s: r.triangular_solve_time_s,
            output_s,
            total_s: cx.read_s + cx.setup_s + cx.solve_s + output_s,
        },
        peak_memory_mb: peak_memory_mb(),
    }
}

/// `femu solve INPUT [--study S]`: an Abaqus/CalculiX deck, or a Gmsh mesh set up by the
/// study's Gmsh view, solved into `out`.
pub fn solve_file(
    input: &Path,
    study_file: Option<&Path>,
    out: &Path,
    newton_table: bool,
    figures: bool,
    progress: &dyn Progress,
) -> Result<()> {
    let t0 = Instant::now();
    femu_mesh::folder::refuse_inputs_in(out, &[input])?;
    let ext = input
        .extension()
        .and_then(|e| e.to_str())
        .unwrap_or("")
        .to_ascii_lowercase();
    let name = input.display().to_string();
    let model = match ext.as_str() {
        "inp" => {
            if study_file.is_some() {
                crate::bail!(
                    "--study is for .msh inputs; a deck carries its own materials and loads"
                );
            }
            // A deck of 3D elements goes to the 3D solve; anything else (text that is not
            // UTF-8 included) to the plane-strain reader, whose errors name what is wrong.
            let bytes = std::fs::read(input).with_context(|| format!("cannot read {name}"))?;
            if femu_mesh::inp::deck_dimension(&String::from_utf8_lossy(&bytes)) == 3 {
                super::solve3::solve_deck3(input, out, progress)?;
                return Ok(());
            }
            drop(bytes);
            let deck = femu_mesh::read_inp(input)?;
            Model::from_deck(deck).with_context(|| format!("invalid model in {name}"))?
        }
        "msh" => {
            let Some(sf) = study_file else {
                crate::bail!(
                    "{name}: a Gmsh mesh needs --study STUDY.toml naming materials and loads"
                );
            };
            let study = crate::schema::read(sf)?;
            crate::model::gmsh_model(&study, input)
                .with_context(|| format!("setting up {name} with {}", sf.display()))?
        }
        _ => crate::bail!("{name}: unknown input type (expected .inp or .msh)"),
    };
    let read_s = t0.elapsed().as_secs_f64();
    solve_model(
        &model,
        &SolveOutput {
            input: &name,
            command: "solve",
            out,
            read_s,
            newton_table,
            figures,
        },
        progress,
    )?;
    Ok(())
}

/// `femu forward`: loading tests on the built-in parametric thigh with the Table 1
/// parameters, femur fixed, one sub-folder per test; the contention test also writes its deck
/// (`model.inp`: runs unchanged in Abaqus, and in CalculiX with CPE4 elements).
pub fn forward(
    out: &Path,
    kind: femu_mesh::ElementKind,
    elements: usize,
    tests: &[femu_mech::loading::Loading],
    progress: &dyn Progress,
) -> Result<()> {
    create_dir(out)?;
    let t0 = Instant::now();
    let (base, skin) = crate::model::thigh_model(elements, kind)?;
    let mesh_s = t0.elapsed().as_secs_f64();
    for loading in tests {
        let t1 = Instant::now();
        let dir = out.join(loading.name());
        create_dir(&dir)?;
        if let Some(pressure) = loading.skin_pressure() {
            let deck_path = dir.join("model.inp");
            let deck = crate::model::contention_deck(&base, &skin, pressure);
            femu_mesh::write_inp_file(&deck, &deck_path)
                .with_context(|| format!("cannot write {}", deck_path.display()))?;
        }
        let mut model = base.clone();
        femu_mech::loading::apply_loading(&mut model, &skin, loading)?;
        progress.note(&format!(
            "forward: {} on the built-in thigh ({} elements, Table 1 materials, femur fixed) -> {}",
            loading.name(),
            model.mesh.elements.len(),
            dir.display()
        ));
        let read_s = mesh_s + t1.elapsed().as_secs_f64();
        solve_model(
            &model,
            &SolveOutput {
                input: &format!("built-in thigh, {}", loading.name()),
                command: "forward",
                out: &dir,
                read_s,
                newton_table: false,
                figures: true,
            },
            progress,
        )?;
    }
    Ok(())
}
