//! Parameter sensitivities by direct differentiation of the discrete equilibrium (the exact
//! version of the seed's §2.3, Eq. 3, which used finite differences).
//!
//! At a converged state `R(u(θ), θ) = 0`, so `K_T ∂u/∂θ_k = -∂R/∂θ_k`. Only the internal force
//! depends on the material parameters, and every registered law is linear in a function of each
//! parameter (`W = Σ_k c_k(θ_k) E_k`, e.g. the Neo-Hookean
//! `W = C10 (I1bar - 3) + (1/D)(J - 1)²`, linear in C10 and in 1/D): `∂f_int/∂θ_k` is the
//! internal force of the energy `c_k'(θ_k) E_k` over the elements of the parameter's material
//! ([`crate::material::Material::rate_forces`]), exact for every element formulation (the CPE4H
//! mean-dilatation force is linear in the energy too). One back-substitution per parameter with
//! the tangent of the solve.
//!
//! **Contact.** The sensitivity is that of the exactly constrained problem (the limit the
//! augmented-Lagrangian iterations converge to): the nodes in contact at the converged state keep
//! their gap, `Gᵀ ∂u/∂θ = 0`, and their contact forces change freely (μ):
//!
//! ```text
//! K_T x - G μ = -∂R/∂θ,   Gᵀ x = 0
//! ⇒  x = x₀ + Z μ,  x₀ = K_T⁻¹ (-∂R/∂θ),  Z = K_T⁻¹ G,  (Gᵀ Z) μ = -Gᵀ x₀
//! ```
//!
//! with `G` the gap gradients of the active nodes (including the rigid body's travel under
//! force control, and the master segment's nodes for a frictionless sliding interface's slave
//! node). The penalty terms of `K_T` vanish on `Gᵀ x = 0`, so the result does not
//! depend on the penalty. The Schur complement `Gᵀ Z` costs one back-substitution per active
//! node, shared by all parameters; `Z` itself is not kept (one column of every equation per
//! active node: 220 MB for 140 nodes of a 200 000-equation mesh): it is formed [`MAX_RHS`]
//! columns at a time, and `Z μ` is solved as `K_T⁻¹ (G μ)`, one more back-substitution per
//! parameter.
//!
//! **Reusing the factorization.** The solver's last factorization is that of the last Newton
//! iterate, one (tiny) correction away from the converged state. The exact tangent at the
//! converged state is assembled (no factorization) and the systems are solved by iterative
//! refinement preconditioned with the stale factors, which converges in one or two steps; if it
//! does not, the exact tangent is factorized. The solver lends all of this as one
//! [`Linearization`]: the state, its tangent, the factors and the active contact constraints.

use crate::element::MAX_DOFS;
use crate::material::{LawSpec, ParameterSpec};
use crate::model::Model;
use crate::solver::{AssemblyError, Linearization, StaticSolver};
use femu_sparse::LinearSolveError;
use femu_sparse::MAX_RHS;
use rayon::prelude::*;
use serde::Serialize;
use std::time::Instant;

/// One material parameter of a model: parameter `index` of the law of material `material`, as
/// the law declares it (`spec`). Its name is the parameter's and the material's, `C10_FAT`,
/// `D_QUADRICEPS`, `C01_FAT`.
#[derive(Debug, Clone, Copy)]
pub struct Parameter {
    pub material: usize,
    pub index: usize,
    spec: &'static ParameterSpec,
}

impl Parameter {
    /// Parameter `index` of `law` on material `material` (`None` if the law has no such
    /// parameter).
    pub fn new(material: usize, law: &'static LawSpec, index: usize) -> Option<Parameter> {
        law.parameters.get(index).map(|spec| Parameter {
            material,
            index,
            spec,
        })
    }

    /// Parameter `index` of material `material` of `model`.
    pub fn of(model: &Model, material: usize, index: usize) -> Option<Parameter> {
        let law = model.materials.get(material)?.law.spec();
        Parameter::new(material, law, index)
    }

    /// The parameter of `model` named `name` (`C10_FAT`, case-insensitive).
    pub fn named(model: &Model, name: &str) -> Option<Parameter> {
        all_parameters(model)
            .into_iter()
            .find(|p| p.name(model).eq_ignore_ascii_case(name))
    }

    /// What its law declares about it: name, unit, bounds, log scale.
    pub fn spec(&self) -> &'static ParameterSpec {
        self.spec
    }

    /// The parameter's value in `model` (internal units: MPa or MPa⁻¹).
    pub fn value(&self, model: &Model) -> f64 {
        model.materials[self.material].law.parameter(self.index)
    }

    /// Sets the parameter's value in `model` (the caller keeps it within its bounds).
    pub fn set(&self, model: &mut Model, value: f64) {
        model.materials[self.material]
            .law
            .set_parameter(self.index, value);
    }

    /// `C10_QUADRICEPS`, `D_FAT`, ... (material names as in the model).
    pub fn name(&self, model: &Model) -> String {
        format!("{}_{}", self.spec.name, model.materials[self.material].name)
    }

    /// Whether this parameter is one of `model`'s (its material exists and has this law's
    /// parameter at `index`).
    pub fn belongs_to(&self, model: &Model) -> bool {
        model
            .materials
            .get(self.material)
            .and_then(|m| m.law.spec().parameters.get(self.index))
            .is_some_and(|p| std::ptr::eq(p, self.spec) || p == self.spec)
    }
}

impl PartialEq for Parameter {
    fn eq(&self, other: &Self) -> bool {
        self.material == other.material
            && self.index == other.index
            && self.spec.name == other.spec.name
    }
}

impl Eq for Parameter {}

impl std::hash::Hash for Parameter {
    fn hash<H: std::hash::Hasher>(&self, state: &mut H) {
        (self.material, self.index, self.spec.name).hash(state);
    }
}

/// Serialized as `{"material": 0, "kind": "C10"}` (the form result files have always had).
impl Serialize for Parameter {
    fn serialize<S: serde::Serializer>(&self, serializer: S) -> Result<S::Ok, S::Error> {
        use serde::ser::SerializeStruct;
        let mut s = serializer.serialize_struct("Parameter", 2)?;
        s.serialize_field("material", &self.material)?;
        s.serialize_field("kind", self.spec.name)?;
        s.end()
    }
}

/// Every parameter of every material of `model`: material by material, each law's parameters
/// in the order it declares them (`[C10_0, D_0, C10_1, D_1, ...]` for Neo-Hookean materials).
pub fn all_parameters(model: &Model) -> Vec<Parameter> {
    model
        .materials
        .iter()
        .enumerate()
        .flat_map(|(m, nm)| {
            let law = nm.law.spec();
            (0..law.parameters.len()).filter_map(move |k| Parameter::new(m, law, k))
        })
        .collect()
}

/// Why sensitivities could not be computed.
#[derive(Debug, thiserror::Error)]
pub enum SensitivityError {
    #[error("the state cannot be assembled for sensitivities: {0}")]
    Assembly(String),
    #[error("the tangent at the state cannot be assembled for sensitivities: {0}")]
    State(#[source] AssemblyError),
    #[error("the tangent cannot be factorized for sensitivities: {0}")]
    Factorization(#[source] LinearSolveError),
    #[error("the contact constraints are singular (pivot {pivot:.3e} of {size} active nodes)")]
    SingularContact { pivot: f64, size: usize },
    #[error("parameter {index} ({name}) of material {material} is not a parameter of the model ({count} materials)")]
    BadParameter {
        index: usize,
        name: &'static str,
        material: usize,
        count: usize,
    },
}

/// How the sensitivities were obtained.
#[derive(Debug, Clone, Default, Serialize, serde::Deserialize)]
pub struct SensitivityReport {
    pub parameters: usize,
    /// Active contact nodes held on their rigid body.
    pub active_constraints: usize,
    /// Back-substitutions with the factorized tangent.
    pub back_substitutions: usize,
    /// Whether the exact tangent had to be factorized (refinement with the solve's factors did
    /// not converge, or there were none).
    pub refactorized: bool,
    /// Largest relative residual `‖K_T x - b‖ / ‖b‖` of the solves.
    pub max_relative_residual: f64,
    /// Refinement corrections (passes over the factors after the first, per block of
    /// [`MAX_RHS`] columns).
    pub refinement_steps: usize,
    pub wall_time_s: f64,
    /// Of which: element rate forces and the right-hand sides.
    pub assembly_time_s: f64,
    /// Numeric factorization of the tangent at the converged state.
    pub factorization_time_s: f64,
    /// Passes over the factors (triangular solves).
    pub triangular_solve_time_s: f64,
    /// Residuals `B - K_T X` of the refinement.
    pub residual_time_s: f64,
}

/// Direct-differentiation sensitivities with buffers kept between calls (the identification
/// calls it once per iteration).
#[derive(Debug, Default)]
pub struct DirectSensitivity {
    /// Element rate forces `∂f_e/∂θ_k` of each parameter k of the element's material,
    /// `MAX_DOFS` per parameter, `rate_stride` per element.
    rates: Vec<f64>,
    rate_stride: usize,
    /// The right-hand sides / solutions, one column per parameter.
    block: Vec<f64>,
    /// Three blocks of [`MAX_RHS`] columns at most: the right-hand sides of the refinement,
    /// their residuals (which first hold the solutions interleaved, `[i * cols + j]`), and the
    /// product of `K_T` with the interleaved solutions. Usually the solver's element-matrix
    /// buffer, idle between assemblies and already in memory (see
    /// [`DirectSensitivity::compute`]).
    work: Vec<f64>,
    /// Equation of each state dof.
    eqs: Vec<Option<usize>>,
    /// Norms of the right-hand sides of a block.
    bnorms: Vec<f64>,
    /// [`MAX_RHS`] columns of `Z = K⁻¹ G` at a time while the Schur complement is formed, then
    /// the contact corrections `K⁻¹ G μ_k`, one column per parameter.
    contact: Vec<f64>,
}

/// Largest relative residual `‖K_T x - b‖ / ‖b‖` at which the refinement stops. The linear
/// systems are solved as accurately as the state they differentiate: the refinement stops at
/// the Newton solve's own relative force-residual tolerance ([`SolverOptions::residual_tolerance`],
/// 1e-8 by default), and never looser than this. Solving further would add digits the
/// converged state does not have (its force residual moves `∂u/∂θ` by the same relative amount).
///
/// [`SolverOptions::residual_tolerance`]: crate::SolverOptions::residual_tolerance
const LOOSEST_REFINEMENT_TOLERANCE: f64 = 1e-8;
/// Relative residual accepted when the refinement stalls (round-off of the tangent's
/// conditioning; a direct solve with exact factors reaches the same level).
const ACCEPTABLE_RESIDUAL: f64 = 1e-10;

impl DirectSensitivity {
    pub fn new() -> Self {
        Self::default()
    }

    /// `∂state/∂θ_k` for each parameter at the converged `state` (length [`Model::state_len`])
    /// of `solver`'s last solve of `model` (its contact multipliers define the active set).
    /// `out[k]` has the state's layout; prescribed dofs have zero sensitivity.
    pub fn compute(
        &mut self,
        solver: &mut StaticSolver,
        model: &Model,
        state: &[f64],
        parameters: &[Parameter],
        out: &mut Vec<Vec<f64>>,
    ) -> Result<SensitivityReport, SensitivityError> {
        let t0 = Instant::now();
        for (index, p) in parameters.iter().enumerate() {
            if !p.belongs_to(model) {
                return Err(SensitivityError::BadParameter {
                    index,
                    name: p.spec.name,
                    material: p.material,
                    count: model.materials.len(),
                });
            }
        }
        let mut report = SensitivityReport {
            parameters: parameters.len(),
            ..Default::default()
        };
        // A successful solve ends with the tangent assembled at its solution (then it is not
        // assembled again).
        let mut lin = solver
            .linearize(model, state)
            .map_err(SensitivityError::State)?;
        if !lin.has_factors() {
            let t = Instant::now();
            lin.factorize().map_err(SensitivityError::Factorization)?;
            report.refactorized = true;
            report.factorization_time_s += t.elapsed().as_secs_f64();
        }
        let t = Instant::now();
        self.element_rate_forces(model, state)?;
        report.assembly_time_s += t.elapsed().as_secs_f64();

        let n_state = model.state_len();
        let mut eqs = std::mem::take(&mut self.eqs);
        eqs.clear();
        eqs.extend((0..n_state).map(|d| lin.equation_of(d)));
        // Work blocks: while this has none large enough (a first call), it borrows the
        // solver's element-matrix buffer (13 MB at paper scale, idle until the next assembly,
        // and already in memory: a fresh 12 MB would cost thousands of page faults) and gives
        // it back below, whatever the outcome.
        let active = lin.active_constraints().len() + lin.interface_constraints().len();
        let columns = parameters.len().max(active).clamp(1, MAX_RHS);
        let need = 3 * columns * lin.equations();
        let borrowed = self.work.len() < need && lin.scratch().len() >= need;
        if borrowed {
            std::mem::swap(&mut self.work, lin.scratch());
        }
        let result = self.compute_with(&mut lin, model, parameters, out, &eqs, report);
        if borrowed {
            std::mem::swap(&mut self.work, lin.scratch());
        }
        self.eqs = eqs;
        let mut report = result?;
        report.wall_time_s = t0.elapsed().as_secs_f64();
        Ok(report)
    }

    /// [`Self::compute`] once the rate forces are assembled, at the linearized state `lin`,
    /// with `eqs` the equation of each state dof.
    fn compute_with(
        &mut self,
        lin: &mut Linearization<'_>,
        model: &Model,
        parameters: &[Parameter],
        out: &mut Vec<Vec<f64>>,
        eqs: &[Option<usize>],
        mut report: SensitivityReport,
    ) -> Result<SensitivityReport, SensitivityError> {
        let n_eq = lin.equations();
        let n_state = model.state_len();
        let tolerance = lin.residual_tolerance().min(LOOSEST_REFINEMENT_TOLERANCE);

        // Contact: Z = K⁻¹ G and the Schur complement S = Gᵀ Z (dense, LU-factorized).
        let active = lin.active_constraints();
        let base = 2 * model.node_count();
        let g_entries: Vec<Vec<(usize, f64)>> = active
            .iter()
            .map(|c| {
                let dofs = [
                    (2 * c.node, c.dg_dx[0]),
                    (2 * c.node + 1, c.dg_dx[1]),
                    (base + c.body, c.dg_dt),
                ];
                dofs.iter()
                    .filter_map(|&(d, v)| eqs[d].map(|q| (q, v)))
                    .collect()
            })
            // The frictionless sliding interfaces' slave nodes in contact keep their gap too.
            .chain(lin.interface_constraints().iter().map(|c| {
                c.iter()
                    .filter_map(|&(d, v)| eqs[d].map(|q| (q, v)))
                    .collect()
            }))
            .collect();
        report.active_constraints = g_entries.len();
        let m = g_entries.len();
        // S = Gᵀ Z with Z = K⁻¹ G, formed MAX_RHS columns of Z at a time (column-major,
        // column j of the chunk at j·n_eq), then LU-factorized.
        let mut zc = std::mem::take(&mut self.contact);
        let mut s = faer::Mat::<f64>::zeros(m, m);
        for first in (0..m).step_by(MAX_RHS) {
            let cols = (m - first).min(MAX_RHS);
            zc.clear();
            zc.resize(cols * n_eq, 0.0);
            for (j, entries) in g_entries[first..first + cols].iter().enumerate() {
                for &(q, v) in entries {
                    zc[j * n_eq + q] = v;
                }
            }
            if let Err(e) = self.solve_block(lin, &mut zc, n_eq, tolerance, &mut report) {
                self.contact = zc;
                return Err(e);
            }
            for (i, entries) in g_entries.iter().enumerate() {
                for j in 0..cols {
                    s[(i, first + j)] = entries.iter().map(|&(q, v)| v * zc[j * n_eq + q]).sum();
                }
            }
        }
        let schur = (m > 0).then(|| {
            let pivot = (0..m)
                .map(|i| s[(i, i)].abs())
                .fold(f64::INFINITY, f64::min);
            (s.partial_piv_lu(), pivot)
        });

        // B = -∂R/∂θ_k on the free dofs, one column per parameter.
        let t = Instant::now();
        let np = parameters.len();
        let mut x = std::mem::take(&mut self.block);
        x.clear();
        x.resize(np * n_eq, 0.0);
        // The columns are independent: one task each, over the elements of its material.
        let (rates, stride) = (&self.rates, self.rate_stride);
        x.par_chunks_mut(n_eq).enumerate().for_each(|(k, col)| {
            let p = &parameters[k];
            for (e, el) in model.mesh.elements.iter().enumerate() {
                if model.element_material[e] != p.material {
                    continue;
                }
                let fe = &rates[e * stride + p.index * MAX_DOFS..][..MAX_DOFS];
                for (a, &n) in el.nodes().iter().enumerate() {
                    for i in 0..2 {
                        if let Some(q) = eqs[2 * n + i] {
                            col[q] -= fe[2 * a + i];
                        }
                    }
                }
            }
        });
        report.assembly_time_s += t.elapsed().as_secs_f64();
        let solved = self.solve_block(lin, &mut x, n_eq, tolerance, &mut report);
        if let Err(e) = solved {
            self.block = x;
            self.contact = zc;
            return Err(e);
        }
        // The contact forces' change of each parameter, μ_k = -S⁻¹ Gᵀ x_k, and the correction
        // K⁻¹ G μ_k (= Z μ_k), all parameters in one block.
        if let Some((lu, pivot)) = &schur {
            use faer::linalg::solvers::Solve;
            let y = faer::Mat::<f64>::from_fn(m, np, |i, k| {
                let xk = &x[k * n_eq..(k + 1) * n_eq];
                -g_entries[i].iter().map(|&(q, v)| v * xk[q]).sum::<f64>()
            });
            let mu = lu.solve(&y);
            if (0..np).any(|k| (0..m).any(|i| !mu[(i, k)].is_finite())) {
                self.block = x;
                self.contact = zc;
                return Err(SensitivityError::SingularContact {
                    pivot: *pivot,
                    size: m,
                });
            }
            zc.clear();
            zc.resize(np * n_eq, 0.0);
            for (k, col) in zc.chunks_mut(n_eq).enumerate() {
                for (i, entries) in g_entries.iter().enumerate() {
                    let mi = mu[(i, k)];
                    for &(q, v) in entries {
                        col[q] += mi * v;
                    }
                }
            }
            if let Err(e) = self.solve_block(lin, &mut zc, n_eq, tolerance, &mut report) {
                self.block = x;
                self.contact = zc;
                return Err(e);
            }
            for (xq, wq) in x.iter_mut().zip(&zc) {
                *xq += wq;
            }
        }
        self.contact = zc;
        out.resize_with(np, Vec::new);
        for (k, du) in out.iter_mut().enumerate() {
            let xk = &x[k * n_eq..(k + 1) * n_eq];
            // Scatter to the state layout.
            du.clear();
            du.resize(n_state, 0.0);
            for (d, q) in eqs.iter().enumerate() {
                if let Some(q) = q {
                    du[d] = xk[*q];
                }
            }
        }
        self.block = x;
        Ok(report)
    }

    /// `∂f_e/∂θ_k` of every parameter of each element's material, element by element.
    fn element_rate_forces(
        &mut self,
        model: &Model,
        state: &[f64],
    ) -> Result<(), SensitivityError> {
        let n_el = model.mesh.elements.len();
        let most = model
            .materials
            .iter()
            .map(|m| m.law.spec().parameters.len())
            .max()
            .unwrap_or(0);
        self.rate_stride = most.max(1) * MAX_DOFS;
        self.rates.resize(n_el * self.rate_stride, 0.0);
        let failed = self
            .rates
            .par_chunks_mut(self.rate_stride)
            .enumerate()
            .map(|(e, forces)| {
                let geo = &model.geometry[e];
                let ue = model.gather(e, state);
                let law = &model.materials[model.element_material[e]].law;
                if law.rate_forces(geo, &ue[..geo.n_nodes], forces).is_err() {
                    return Some(e);
                }
                None
            })
            .find_any(|r| r.is_some())
            .flatten();
        match failed {
            Some(e) => Err(SensitivityError::Assembly(format!(
                "element {} is inverted",
                model.mesh.element_labels[e]
            ))),
            None => Ok(()),
        }
    }

    /// Solves `K_T X = B` in place (`block` holds the columns of B, `n` rows each, and returns
    /// X) with the tangent at the state, by iterative refinement with the current factors
    /// down to the relative residual `tolerance`, [`MAX_RHS`] columns per pass over
    /// the factors; factorizes `K_T` itself if the refinement does not converge.
    fn solve_block(
        &mut self,
        lin: &mut Linearization<'_>,
        block: &mut [f64],
        n: usize,
        tolerance: f64,
        report: &mut SensitivityReport,
    ) -> Result<(), SensitivityError> {
        for chunk in block.chunks_mut(MAX_RHS * n) {
            let cols = chunk.len() / n;
            let len = chunk.len();
            if self.work.len() < 3 * len {
                self.work.resize(3 * len, 0.0);
            }
            let (rhs, rest) = self.work.split_at_mut(len);
            let (residual, rest) = rest.split_at_mut(len);
            let product = &mut rest[..len];
            rhs.copy_from_slice(chunk);
            self.bnorms.clear();
            self.bnorms.extend(rhs.chunks(n).map(norm));
            let t = Instant::now();
            lin.solve_many(chunk, cols);
            report.triangular_solve_time_s += t.elapsed().as_secs_f64();
            report.back_substitutions += cols;
            let mut last = f64::INFINITY;
            loop {
                let t = Instant::now();
                // R = B - K X (one pass over K for all the columns, interleaved), and the
                // worst relative residual of the columns.
                let rel = residual_of(lin, chunk, cols, n, rhs, &self.bnorms, product, residual);
                report.residual_time_s += t.elapsed().as_secs_f64();
                let converged = rel <= tolerance;
                let stalled = !(rel < 0.5 * last);
                if converged || (stalled && rel <= ACCEPTABLE_RESIDUAL.max(tolerance)) {
                    report.max_relative_residual = report.max_relative_residual.max(rel);
                    break;
                }
                if stalled {
                    if report.refactorized {
                        report.max_relative_residual = report.max_relative_residual.max(rel);
                        break;
                    }
                    // The stale factors are too far from K_T: factorize K_T and start again.
                    let t = Instant::now();
                    lin.factorize().map_err(SensitivityError::Factorization)?;
                    report.refactorized = true;
                    report.factorization_time_s += t.elapsed().as_secs_f64();
                    chunk.copy_from_slice(rhs);
                    let t = Instant::now();
                    lin.solve_many(chunk, cols);
                    report.triangular_solve_time_s += t.elapsed().as_secs_f64();
                    report.back_substitutions += cols;
                    last = f64::INFINITY;
                    continue;
                }
                last = rel;
                let t = Instant::now();
                lin.solve_many(residual, cols);
                report.triangular_solve_time_s += t.elapsed().as_secs_f64();
                report.back_substitutions += cols;
                report.refinement_steps += 1;
                for (xi, ci) in chunk.iter_mut().zip(residual.iter()) {
                    *xi += ci;
                }
            }
        }
        Ok(())
    }
}

/// `residual = rhs - K_T X` for the `cols` columns of `x` (`n` rows each, column-major like
/// the right-hand sides) and the largest relative residual `‖r_j‖ / ‖b_j‖` of the columns
/// (`bnorms`: the norms of the right-hand sides; `product`: a work block). `residual` first
/// holds the interleaved solutions.
#[allow(clippy::too_many_arguments)]
fn residual_of(
    lin: &Linearization<'_>,
    x: &[f64],
    cols: usize,
    n: usize,
    rhs: &[f64],
    bnorms: &[f64],
    product: &mut [f64],
    residual: &mut [f64],
) -> f64 {
    // Interleave X (into the residual block, free until the product is known) so that K_T is
    // read once for all the columns.
    residual
        .par_chunks_mut(cols)
        .enumerate()
        .for_each(|(i, row)| {
            for (j, v) in row.iter_mut().enumerate() {
                *v = x[j * n + i];
            }
        });
    lin.tangent_mul_many_interleaved(residual, product, cols);
    let product = &*product;
    residual
        .par_chunks_mut(n)
        .enumerate()
        .map(|(j, r)| {
            let mut sum = 0.0;
            for (i, (ri, bi)) in r.iter_mut().zip(&rhs[j * n..(j + 1) * n]).enumerate() {
                *ri = bi - product[i * cols + j];
                sum += *ri * *ri;
            }
            if bnorms[j] > 0.0 {
                sum.sqrt() / bnorms[j]
            } else {
                0.0
            }
        })
        .reduce(|| 0.0, f64::max)
}

fn norm(v: &[f64]) -> f64 {
    v.iter().map(|a| a * a).sum::<f64>().sqrt()
}

/// The seed's Eq. 3 for one parameter: `S_k = ‖θ_k ∂U/∂θ_k‖ / ‖U‖` over the nodal displacements
/// (2 per node), and the map behind it, per node:
/// `s_k(n) = θ_k |∂u_n/∂θ_k| / rms_n |u_n|` — normalized by the root-mean-square nodal
/// displacement so that `S_k = rms_n s_k(n)` and nodes with no displacement (the femur) do not
/// divide by zero.
pub fn sensitivity_map(u: &[f64], du_dtheta: &[f64], theta: f64) -> (f64, Vec<f64>) {
    let n = u.len() / 2;
    let unorm = norm(&u[..2 * n]);
    let rms = unorm / (n.max(1) as f64).sqrt();
    let map: Vec<f64> = (0..n)
        .map(|i| {
            let s = theta * du_dtheta[2 * i].hypot(du_dtheta[2 * i + 1]);
            if rms > 0.0 {
                s / rms
            } else {
                0.0
            }
        })
        .collect();
    let global = if unorm > 0.0 {
        theta.abs() * norm(&du_dtheta[..2 * n]) / unorm
    } else {
        0.0
    };
    (global, map)
}
