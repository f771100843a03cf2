//! Three-dimensional solids from the command line: a 3D deck solved (`femu solve DECK.inp` with
//! `C3D8`, `C3D8H`, `C3D4` or `C3D10` elements) and the built-in thigh swept into a 3D deck
//! (`femu mesh thigh3d`).
//!
//! A 3D solve writes the plane-strain solve's files with a third component:
//! `displacements.csv` (`node,x,y,z,ux,uy,uz`, the deck's node labels, every digit),
//! `result.vtu` (displacement, region, the element averages of the Cauchy stress and of the
//! volume ratio J) and `summary.json` ([`Solve3Summary`]). The solve is
//! [`femu_mech::solid3d::solve`]: the plane-strain solver's Newton driver on the 3D elements.
//! A solve that stops midway writes its last converged state, says so in the summary, and
//! returns the error.

use crate::error::{Context, Result};
use crate::output::{create_dir, create_file, write_json};
use crate::progress::Progress;
use femu_geometry::thigh3d::{sweep_thigh, Sweep, Thigh3};
use femu_geometry::{parametric_thigh, table1_materials, ThighParams};
use femu_mech::output::peak_memory_mb;
use femu_mech::solid3d::{self, Body3, Options3, Solution3, Solve3Error};
use femu_mech::SolveError;
use femu_mesh::decimal::push_f64;
use femu_mesh::vtu::{write_vtu3, VtuField, VtuIntField};
use femu_mesh::{Deck3, ElementKind, ElementKind3};
use serde::{Deserialize, Serialize};
use std::collections::BTreeMap;
use std::io::Write;
use std::path::Path;
use std::time::Instant;

/// `summary.json` of a 3D solve.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct Solve3Summary {
    pub femu_version: String,
    pub command: String,
    pub input: String,
    /// Always 3 (a plane-strain solve's summary has no such key).
    pub dimension: usize,
    /// `converged` or `not converged`.
    pub status: String,
    pub error: Option<String>,
    pub nodes: usize,
    pub elements: usize,
    pub element_types: BTreeMap<String, usize>,
    /// Deck material of each element set, with its element count.
    pub materials: Vec<Material3Summary>,
    pub prescribed_dofs: usize,
    pub pressure_faces: usize,
    pub point_loads: usize,
    pub equations: usize,
    pub matrix_nonzeros: usize,
    /// The last factorization: `ldlt` for a symmetric tangent, `lu` otherwise (a follower
    /// pressure's load stiffness is not symmetric).
    pub factorization: Option<String>,
    /// Load factor reached (1 when the step completed).
    pub load_factor: f64,
    pub increments: usize,
    pub newton_iterations: usize,
    pub cutbacks: usize,
    pub max_displacement_mm: f64,
    /// The sums of the reactions at the prescribed dofs along x, y and z (N).
    pub reaction_force_total_n: [f64; 3],
    /// The smallest element volume ratio J at the end (> 0 for a valid state).
    pub min_volume_ratio: f64,
    pub timings: Solve3Timings,
    pub peak_memory_mb: Option<f64>,
}

/// A material of a 3D deck and how many elements use it.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct Material3Summary {
    pub name: String,
    pub law: String,
    pub constants: Vec<f64>,
    pub elements: usize,
}

/// Where the time of a 3D solve went (s).
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct Solve3Timings {
    pub read_s: f64,
    pub solve_s: f64,
    pub setup_s: f64,
    pub assembly_s: f64,
    pub factorization_s: f64,
    pub triangular_solve_s: f64,
    pub output_s: f64,
    pub total_s: f64,
}

/// The Newton options of a deck's step: increments of the step's initial increment (at least
/// one, at most 1000), 25 iterations each, the plane-strain solver's tolerance.
fn options_of(deck: &Deck3) -> Options3 {
    let first = deck.step.initial_increment;
    let increments = if first > 0.0 && first.is_finite() {
        (1.0 / first).round().clamp(1.0, 1000.0) as usize
    } else {
        1
    };
    Options3 {
        increments,
        ..Options3::default()
    }
}

/// Solves the 3D deck `input` (already known to hold `C3D…` elements) and writes `out`.
pub fn solve_deck3(input: &Path, out: &Path, progress: &dyn Progress) -> Result<Solve3Summary> {
    let t0 = Instant::now();
    let name = input.display().to_string();
    let deck = femu_mesh::read_inp3(input)?;
    let body = Body3::from_deck3(&deck).with_context(|| format!("invalid model in {name}"))?;
    let read_s = t0.elapsed().as_secs_f64();
    create_dir(out)?;
    progress.note(&format!(
        "{name}: {} nodes, {} elements (3D); solving",
        body.nodes.len(),
        body.elements.len()
    ));
    let options = options_of(&deck);
    let t1 = Instant::now();
    let outcome = solid3d::solve(&body, &options);
    let solve_s = t1.elapsed().as_secs_f64();
    let (solution, error) = match outcome {
        Ok(s) => (s, None),
        Err(Solve3Error::Newton(e)) => match *e {
            SolveError::NotConverged { ref partial, .. }
            | SolveError::TooManyIncrements { ref partial, .. } => {
                let p: Solution3 = (**partial).clone();
                (p, Some(Solve3Error::Newton(e)))
            }
            other => return Err(Solve3Error::Newton(Box::new(other)).into()),
        },
        Err(e) => return Err(e.into()),
    };
    let t2 = Instant::now();
    let summary = write_solved3(
        &deck,
        &body,
        &solution,
        error.as_ref().map(|e| e.to_string()),
        &name,
        out,
        [read_s, solve_s],
    )?;
    let output_s = t2.elapsed().as_secs_f64();
    let mut summary = summary;
    summary.timings.output_s = output_s;
    summary.timings.total_s = t0.elapsed().as_secs_f64();
    write_json(&out.join("summary.json"), &summary)?;
    progress.note(&format!(
        "{}: max |u| {:.4} mm in {} increments, {} Newton iterations ({:.2} s)",
        summary.status,
        summary.max_displacement_mm,
        summary.increments,
        summary.newton_iterations,
        solve_s
    ));
    match error {
        None => Ok(summary),
        Some(e) => Err(e.into()),
    }
}

/// Writes `displacements.csv` and `result.vtu` of a 3D solution and returns its summary
/// (without the output and total times).
fn write_solved3(
    deck: &Deck3,
    body: &Body3,
    solution: &Solution3,
    error: Option<String>,
    input: &str,
    out: &Path,
    [read_s, solve_s]: [f64; 2],
) -> Result<Solve3Summary> {
    let mesh = &deck.mesh;
    let u = &solution.u;
    {
        let path = out.join("displacements.csv");
        let mut w = create_file(&path)?;
        let mut line = Vec::with_capacity(192);
        let mut ryu = ryu::Buffer::new();
        writeln!(w, "node,x,y,z,ux,uy,uz")?;
        for (n, x) in mesh.nodes.iter().enumerate() {
            line.clear();
            write!(line, "{}", mesh.node_labels[n])?;
            for &v in x.iter().chain(u[n].iter()) {
                line.push(b',');
                push_f64(&mut line, v, &mut ryu);
            }
            line.push(b'\n');
            w.write_all(&line)?;
        }
        w.commit()
            .with_context(|| format!("writing {}", path.display()))?;
    }
    let averages = body.element_averages(u);
    let mut stress = Vec::with_capacity(6 * averages.len());
    let mut volume_ratio = Vec::with_capacity(averages.len());
    let mut min_j = f64::INFINITY;
    for a in &averages {
        match a {
            Some(a) => {
                stress.extend_from_slice(&a.cauchy_stress);
                volume_ratio.push(a.volume_ratio);
                min_j = min_j.min(a.volume_ratio);
            }
            None => {
                stress.extend_from_slice(&[f64::NAN; 6]);
                volume_ratio.push(f64::NAN);
                min_j = f64::NAN;
            }
        }
    }
    let region: Vec<i32> = deck.element_region.iter().map(|&r| r as i32).collect();
    let path = out.join("result.vtu");
    write_vtu3(
        &path,
        mesh,
        Some(u),
        &[
            VtuField {
                name: "cauchy_stress",
                components: 6,
                data: &stress,
            },
            VtuField {
                name: "volume_ratio",
                components: 1,
                data: &volume_ratio,
            },
        ],
        &[VtuIntField {
            name: "region",
            data: &region,
        }],
    )
    .with_context(|| format!("writing {}", path.display()))?;

    let mut element_types = BTreeMap::new();
    for el in &mesh.elements {
        *element_types
            .entry(el.kind.deck_name().to_string())
            .or_insert(0) += 1;
    }
    let materials = deck
        .materials
        .iter()
        .enumerate()
        .map(|(m, def)| Material3Summary {
            name: def.name.clone(),
            law: def.keyword.clone(),
            constants: def.constants.clone(),
            elements: deck.element_material.iter().filter(|&&k| k == m).count(),
        })
        .collect();
    let mut reactions = [0.0; 3];
    for &(node, component, _) in &body.prescribed {
        reactions[component] += solution.internal_force[3 * node + component];
    }
    let max_u = u
        .iter()
        .map(|v| (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt())
        .fold(0.0, f64::max);
    let r = &solution.report;
    Ok(Solve3Summary {
        femu_version: env!("CARGO_PKG_VERSION").to_string(),
        command: "solve".into(),
        input: input.to_string(),
        dimension: 3,
        status: if error.is_none() {
            "converged".into()
        } else {
            "not converged".into()
        },
        error,
        nodes: mesh.nodes.len(),
        elements: mesh.elements.len(),
        element_types,
        materials,
        prescribed_dofs: body.prescribed.len(),
        pressure_faces: body.pressures.len(),
        point_loads: body.loads.len(),
        equations: r.equations,
        matrix_nonzeros: r.matrix_nonzeros,
        factorization: r
            .factorization
            .map(|f| format!("{f:?}").to_ascii_lowercase()),
        load_factor: r.lambda,
        increments: r.converged_increments,
        newton_iterations: r.newton_iterations,
        cutbacks: r.cutbacks,
        max_displacement_mm: max_u,
        reaction_force_total_n: reactions,
        min_volume_ratio: min_j,
        timings: Solve3Timings {
            read_s,
            solve_s,
            setup_s: r.setup_time_s,
            assembly_s: r.assembly_time_s,
            factorization_s: r.factorization_time_s,
            triangular_solve_s: r.triangular_solve_time_s,
            output_s: 0.0,
            total_s: 0.0,
        },
        peak_memory_mb: peak_memory_mb(),
    })
}

/// What `femu mesh thigh3d` builds: the built-in thigh's section swept along the femur axis.
#[derive(Debug, Clone)]
pub struct Thigh3Request {
    /// Element size of the section (mm).
    pub size_mm: f64,
    /// Length along the femur axis (mm).
    pub length_mm: f64,
    /// Layer thickness under the probe (mm); the layers grow by `growth` towards the ends.
    pub layer_mm: f64,
    pub growth: f64,
    /// Scale of the section at the far end (1: a prism).
    pub end_scale: f64,
    /// C3D8H or C3D8.
    pub kind: ElementKind3,
    /// The probe's footprint on the skin: its direction seen from the section's centre
    /// (degrees, 90 = anterior), its width across the thigh and its length along it (mm),
    /// centred at half the length.
    pub probe_angle_deg: f64,
    pub probe_width_mm: f64,
    pub probe_length_mm: f64,
    /// The pressure on the footprint (kPa, a follower pressure).
    pub pressure_kpa: f64,
    /// Hold both end faces along the axis (a plane-strain slab) instead of leaving them free.
    pub plane_strain_ends: bool,
}

/// What `femu mesh thigh3d` wrote.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct Thigh3Summary {
    pub deck: String,
    pub nodes: usize,
    pub elements: usize,
    pub element_type: String,
    pub section_quads: usize,
    pub layers: usize,
    pub length_mm: f64,
    pub end_scale: f64,
    pub probe_faces: usize,
    pub pressure_kpa: f64,
    /// Meshed area of each region of the section at z = 0 (mm²).
    pub section_areas_mm2: BTreeMap<String, f64>,
}

impl Thigh3Request {
    /// Checks the request's numbers (each named as its command-line option).
    fn check(&self) -> Result<()> {
        let positive = [
            ("--size", self.size_mm),
            ("--length", self.length_mm),
            ("--layer", self.layer_mm),
            ("--probe-width", self.probe_width_mm),
            ("--probe-length", self.probe_length_mm),
        ];
        for (key, v) in positive {
            if !(v.is_finite() && v > 0.0) {
                crate::bail!("{key} must be a positive number of mm (got {v})");
            }
        }
        if !(self.growth.is_finite() && (1.0..=3.0).contains(&self.growth)) {
            crate::bail!("--growth must lie in [1, 3] (got {})", self.growth);
        }
        if !(self.end_scale.is_finite() && self.end_scale > 0.0 && self.end_scale <= 2.0) {
            crate::bail!("--end-scale must lie in (0, 2] (got {})", self.end_scale);
        }
        if self.probe_length_mm > self.length_mm {
            crate::bail!(
                "--probe-length ({} mm) is longer than the thigh (--length {} mm)",
                self.probe_length_mm,
                self.length_mm
            );
        }
        if self.layer_mm > 0.5 * self.probe_length_mm {
            crate::bail!(
                "--layer ({} mm) must be at most half the probe's length ({} mm): the footprint needs two layers",
                self.layer_mm,
                self.probe_length_mm
            );
        }
        if !self.pressure_kpa.is_finite() || self.pressure_kpa < 0.0 {
            crate::bail!(
                "--pressure must be a non-negative number of kPa (got {})",
                self.pressure_kpa
            );
        }
        Ok(())
    }

    /// The swept thigh and its deck.
    pub fn build(&self) -> Result<(Thigh3, Deck3)> {
        self.check()?;
        let params = ThighParams {
            element_size_mm: Some(self.size_mm),
            ..ThighParams::default()
        };
        let section = parametric_thigh(&params, ElementKind::Cpe4h)?;
        let z0 = 0.5 * self.length_mm;
        let half = 0.5 * self.probe_length_mm;
        let fine = half / (half / self.layer_mm).ceil();
        let mut sweep = Sweep::graded(self.length_mm, z0, half, fine, self.growth);
        sweep.end_scale = self.end_scale;
        sweep.kind = self.kind;
        let thigh = sweep_thigh(&section, &sweep)?;
        let faces = thigh.skin_patch(
            &section,
            self.probe_angle_deg,
            self.probe_width_mm,
            z0,
            self.probe_length_mm,
        );
        let deck = thigh.deck(
            &table1_materials(),
            &faces,
            self.pressure_kpa * 1e-3,
            self.plane_strain_ends,
        )?;
        Ok((thigh, deck))
    }
}

/// Builds the swept thigh of `request` and writes `out/thigh3d.inp` (a deck CalculiX 2.20 and
/// `femu solve` read), `out/mesh.vtu` (regions) and `out/summary.json`.
pub fn mesh_thigh3d(request: &Thigh3Request, out: &Path) -> Result<Thigh3Summary> {
    let (thigh, deck) = request.build()?;
    create_dir(out)?;
    let path = out.join("thigh3d.inp");
    femu_mesh::inp::write_inp3_file(&deck, &path)
        .with_context(|| format!("writing {}", path.display()))?;
    let region: Vec<i32> = deck.element_region.iter().map(|&r| r as i32).collect();
    let vtu = out.join("mesh.vtu");
    write_vtu3(
        &vtu,
        &deck.mesh,
        None,
        &[],
        &[VtuIntField {
            name: "region",
            data: &region,
        }],
    )
    .with_context(|| format!("writing {}", vtu.display()))?;
    let summary = Thigh3Summary {
        deck: path.display().to_string(),
        nodes: deck.mesh.nodes.len(),
        elements: deck.mesh.elements.len(),
        element_type: request.kind.deck_name().to_string(),
        section_quads: thigh.quads,
        layers: thigh.sweep.levels.len() - 1,
        length_mm: request.length_mm,
        end_scale: request.end_scale,
        probe_faces: deck.pressures.len(),
        pressure_kpa: request.pressure_kpa,
        section_areas_mm2: thigh.section_areas_mm2.clone(),
    };
    write_json(&out.join("summary.json"), &summary)?;
    Ok(summary)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn request() -> Thigh3Request {
        Thigh3Request {
            size_mm: 4.5,
            length_mm: 40.0,
            layer_mm: 5.0,
            growth: 1.6,
            end_scale: 0.9,
            kind: ElementKind3::C3d8h,
            probe_angle_deg: 90.0,
            probe_width_mm: 20.0,
            probe_length_mm: 10.0,
            pressure_kpa: 2.0,
            plane_strain_ends: false,
        }
    }

    /// A change to a good request, and the option its error must name.
    type BadCase = (fn(&mut Thigh3Request), &'static str);

    #[test]
    fn bad_requests_name_their_option() {
        let cases: [BadCase; 5] = [
            (|r| r.size_mm = 0.0, "--size"),
            (|r| r.probe_length_mm = 80.0, "--probe-length"),
            (|r| r.layer_mm = 8.0, "--layer"),
            (|r| r.end_scale = 3.0, "--end-scale"),
            (|r| r.pressure_kpa = f64::NAN, "--pressure"),
        ];
        for (change, key) in cases {
            let mut r = request();
            change(&mut r);
            let e = r.build().unwrap_err().to_string();
            assert!(e.contains(key), "{key}: {e}");
        }
    }

    #[test]
    fn the_deck_holds_the_probe_pressure_and_the_fixed_femur() {
        let (thigh, deck) = request().build().unwrap();
        assert_eq!(deck.mesh.elements.len(), thigh.mesh.elements.len());
        assert!(!deck.pressures.is_empty());
        assert!(deck
            .pressures
            .iter()
            .all(|p| (p.magnitude - 2e-3).abs() < 1e-15));
        assert!(!deck.boundaries.is_empty());
        // Two layers of 5 mm under the 10 mm probe, growing to the ends.
        let levels = &thigh.sweep.levels;
        assert!(levels.windows(2).any(|w| (w[1] - w[0] - 5.0).abs() < 1e-9));
        assert!((levels.last().unwrap() - 40.0).abs() < 1e-12);
        // The step's first increment gives the Newton options.
        assert!(options_of(&deck).increments >= 1);
    }
}
