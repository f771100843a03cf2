//! Finite element model updating (seed §2.1.3, Eq. 2): the parameters θ that minimize
//! `J(θ) = ½ Σ_i w_i (u_model,i(θ) - u_measured,i)²` over the measured points.
//!
//! The free parameters are optimized in log scale, `φ = ln θ`, within bounds; a free parameter
//! may move several model parameters together (tied, the seed's grouping of D). The model's
//! field at the measured points is the nodal solution interpolated by the shape functions of the
//! element that contains each point in the reference configuration (`femu_mesh::locate`); points
//! outside the tissue are masked and counted. The Jacobian is exact: the projection of the
//! direct-differentiation sensitivities (`femu_mech::sensitivity`), one back-substitution per
//! parameter with the tangent of the solve. Each forward solve starts from the last converged
//! field (warm start).
//!
//! [`levenberg_marquardt`] minimizes with Marquardt's diagonal scaling and bound projection;
//! failed forward solves (Newton diverging at extreme parameters) are rejected steps, not
//! failures. [`latin_hypercube`] draws the starts of the seed's multi-start.

use crate::measured::MeasuredField;
use crate::speckle::{ShiftScale, SpeckleShift};
use crate::weighted::{FieldCovariance, Loss, Whitening};
use femu_mech::sensitivity::{DirectSensitivity, Parameter};
use femu_mech::{Model, SolverOptions, StaticSolver};
use femu_mesh::locate::{PointLocation, PointLocator};
use rand::{Rng, SeedableRng};
use serde::{Deserialize, Serialize};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;
use std::time::Instant;

/// Jacobian columns, one per free parameter.
pub type Columns = Vec<Vec<f64>>;

/// A free parameter: the model parameters it moves together, and its bounds (model units).
#[derive(Debug, Clone, Serialize)]
pub struct FreeParameter {
    pub name: String,
    pub members: Vec<Parameter>,
    pub lower: f64,
    pub upper: f64,
}

pub use crate::fit_error::FitError;

/// A weighted least-squares problem in log-parameters `φ = ln θ`: what the optimizers
/// ([`levenberg_marquardt`], [`bfgs`]) minimize, `½|r(φ)|²`. FEMU on a measured field
/// ([`Problem`]) is one; any other residual (several measurements at once, grey levels) with an
/// exact Jacobian can be another.
pub trait LeastSquares {
    /// The free parameters: names and bounds (model units).
    fn free(&self) -> &[FreeParameter];
    /// The weighted residuals at `phi` and, if asked, the Jacobian columns `∂r/∂φ_k`. A forward
    /// model that fails at `phi` (Newton diverging at extreme parameters) is a
    /// [`FitError::Solve`], which the optimizers treat as a rejected step.
    fn evaluate(
        &mut self,
        phi: &[f64],
        jacobian: bool,
    ) -> Result<(Vec<f64>, Option<Columns>), FitError>;
    /// Forward solves and Jacobian evaluations so far.
    fn counts(&self) -> (usize, usize);
    /// Hands back Jacobian columns the caller no longer needs, for a later [`Self::evaluate`]
    /// to fill instead of allocating (a problem with large columns keeps them; the default
    /// drops them).
    fn recycle(&mut self, columns: Columns) {
        drop(columns);
    }
    /// The forward states of the last evaluation, one per forward model (`None` before its
    /// first solve), to start another problem on the same meshes from them
    /// ([`Problem::with_warm_start`]); empty for a problem without forward models.
    fn states(&self) -> Vec<Option<Vec<f64>>> {
        Vec::new()
    }
}

/// Some free parameters of a problem held at given values, the others free: a
/// [`LeastSquares`] over the subset `keep` (indices into `inner.free()`), the held ones at their
/// log-values in `phi`.
pub struct Subset<'a, P: LeastSquares + ?Sized> {
    inner: &'a mut P,
    keep: Vec<usize>,
    phi: Vec<f64>,
    free: Vec<FreeParameter>,
}

impl<'a, P: LeastSquares + ?Sized> Subset<'a, P> {
    /// `phi`: log-values of every free parameter of `inner` (those of `keep` are overwritten by
    /// each evaluation).
    pub fn new(inner: &'a mut P, keep: Vec<usize>, phi: Vec<f64>) -> Self {
        let free = keep.iter().map(|&k| inner.free()[k].clone()).collect();
        Subset {
            inner,
            keep,
            phi,
            free,
        }
    }

    /// The log-values of every free parameter for subset log-values `sub`.
    pub fn full(&self, sub: &[f64]) -> Vec<f64> {
        let mut phi = self.phi.clone();
        for (&k, &v) in self.keep.iter().zip(sub) {
            phi[k] = v;
        }
        phi
    }
}

impl<P: LeastSquares + ?Sized> LeastSquares for Subset<'_, P> {
    fn free(&self) -> &[FreeParameter] {
        &self.free
    }

    fn evaluate(
        &mut self,
        phi: &[f64],
        jacobian: bool,
    ) -> Result<(Vec<f64>, Option<Columns>), FitError> {
        let full = self.full(phi);
        let (r, j) = self.inner.evaluate(&full, jacobian)?;
        let j = j.map(|mut cols| {
            let kept = self
                .keep
                .iter()
                .map(|&k| std::mem::take(&mut cols[k]))
                .collect();
            self.inner.recycle(cols);
            kept
        });
        Ok((r, j))
    }

    fn counts(&self) -> (usize, usize) {
        self.inner.counts()
    }

    fn recycle(&mut self, columns: Columns) {
        self.inner.recycle(columns);
    }
}

/// The model, its solver and the measurement, ready for repeated evaluations.
pub struct Problem {
    model: Model,
    solver: StaticSolver,
    sensitivity: DirectSensitivity,
    free: Vec<FreeParameter>,
    /// Located measured points, their measured components and `√w`.
    locations: Vec<PointLocation>,
    measured: Vec<f64>,
    sqrt_w: Vec<f64>,
    /// Index in the measured field of each located point, and the field's point count.
    field_index: Vec<usize>,
    field_points: usize,
    /// The full covariance's whitening and the located points it covers.
    whitening: Option<(Whitening, Vec<usize>)>,
    loss: Loss,
    masked: usize,
    /// Whether each point of the field lies in the tissue (its residual rows follow).
    located: Vec<bool>,
    /// The actuator term: the measured travel of the force-controlled rigid body (mm) and its
    /// standard deviation, one more residual `(T_model - T_measured) / σ_T`.
    travel: Option<(f64, f64)>,
    /// The speckle's lateral shift under shear in the measurement model
    /// ([`Problem::with_speckle_shift`]).
    speckle: Option<SpeckleTerm>,
    warm: Option<Vec<f64>>,
    dstate: Vec<Vec<f64>>,
    /// Set by the user to stop: checked before every forward solve.
    stop: Option<Arc<AtomicBool>>,
    /// Forward solves and sensitivity evaluations so far.
    pub forward_solves: usize,
    pub jacobians: usize,
}

impl Problem {
    /// Sets up the problem: locates the measured points in the reference mesh and checks the
    /// free parameters. Contact is converged to 1e-8 of the element size (instead of 1e-3) so
    /// that the model field is a smooth function of the parameters.
    pub fn new(
        mut model: Model,
        options: SolverOptions,
        field: &MeasuredField,
        free: Vec<FreeParameter>,
    ) -> Result<Problem, FitError> {
        for f in &free {
            if !(f.lower > 0.0 && f.upper > f.lower && f.upper.is_finite()) {
                return Err(FitError::BadBounds {
                    name: f.name.clone(),
                    lower: f.lower,
                    upper: f.upper,
                });
            }
        }
        for c in &mut model.contacts {
            c.penetration_tolerance = c.penetration_tolerance.min(1e-8);
        }
        let locator = PointLocator::new(&model.mesh);
        let mut locations = Vec::new();
        let mut measured = Vec::new();
        let mut sqrt_w = Vec::new();
        let mut field_index = Vec::new();
        let mut masked = 0;
        let mut located = Vec::with_capacity(field.points.len());
        for (i, p) in field.points.iter().enumerate() {
            let loc = locator.locate(p.x);
            located.push(loc.is_some());
            match loc {
                Some(loc) => {
                    locations.push(loc);
                    field_index.push(i);
                    measured.extend_from_slice(&p.u);
                    sqrt_w.extend(p.weight.iter().map(|w| w.sqrt()));
                }
                None => masked += 1,
            }
        }
        if locations.is_empty() {
            return Err(FitError::NoData { masked });
        }
        let data = sqrt_w.iter().filter(|w| **w > 0.0).count();
        if data < free.len() {
            return Err(FitError::TooFewData {
                data,
                free: free.len(),
            });
        }
        let solver =
            StaticSolver::new(&model, options).map_err(|e| FitError::Solve(e.to_string()))?;
        Ok(Problem {
            model,
            solver,
            sensitivity: DirectSensitivity::new(),
            free,
            locations,
            measured,
            sqrt_w,
            field_index,
            field_points: field.points.len(),
            whitening: None,
            loss: Loss::Squared,
            masked,
            located,
            travel: None,
            speckle: None,
            warm: None,
            dstate: Vec::new(),
            stop: None,
            forward_solves: 0,
            jacobians: 0,
        })
    }

    /// Adds the actuator term of a force-controlled loading test: the rigid body's travel
    /// beyond first contact measured as `travel_mm ± sigma_mm` (the displacement sensor of the
    /// compression or indentation device; the seed's §2.1.2.3 force-controlled tests): one
    /// residual `(T(θ) - T_measured) / σ` whose derivative is the travel component of the
    /// direct-differentiation sensitivities.
    pub fn with_travel(mut self, travel_mm: f64, sigma_mm: f64) -> Result<Problem, FitError> {
        let force_controlled = self.model.contacts.len() == 1
            && matches!(
                self.model.contacts[0].control,
                femu_mech::contact::TravelControl::Force(_)
            );
        if !force_controlled {
            return Err(FitError::Travel(
                "the actuator term needs one force-controlled rigid body (compression or indentation)".into(),
            ));
        }
        if !(sigma_mm > 0.0 && sigma_mm.is_finite() && travel_mm.is_finite()) {
            return Err(FitError::Travel(format!(
                "travel {travel_mm} mm with sigma {sigma_mm} mm: need a finite travel and a positive sigma"
            )));
        }
        self.travel = Some((travel_mm, sigma_mm));
        Ok(self)
    }

    /// Starts the first forward solve from `state` (the solution of the same mesh at nearby
    /// parameters, [`LeastSquares::states`]) instead of the load increments; a state of another
    /// length is ignored.
    pub fn with_warm_start(mut self, state: Vec<f64>) -> Problem {
        if state.len() == self.model.state_len() {
            self.warm = Some(state);
        }
        self
    }

    /// Stops at the next forward solve with [`FitError::Interrupted`] once `flag` is set (the
    /// user's Ctrl-C), so that a long optimization can be interrupted between solves.
    pub fn with_stop(mut self, flag: Option<Arc<AtomicBool>>) -> Problem {
        self.stop = flag;
        self
    }

    /// Also stops once the process was asked to stop ([`femu_mesh::stop`]).
    fn check_stop(&self) -> Result<(), FitError> {
        let flagged = self
            .stop
            .as_ref()
            .is_some_and(|f| f.load(Ordering::Relaxed));
        if flagged || femu_mesh::stop::requested() {
            Err(FitError::Interrupted)
        } else {
            Ok(())
        }
    }

    /// The first rigid body's travel (mm) at the last solved state (None without a rigid body
    /// or before any solve).
    pub fn last_travel(&self) -> Option<f64> {
        let state = self.warm.as_ref()?;
        (!self.model.contacts.is_empty()).then(|| state[2 * self.model.node_count()])
    }

    /// Measured points inside the tissue, and masked ones.
    pub fn points(&self) -> (usize, usize) {
        (self.locations.len(), self.masked)
    }

    /// The residual rows of the field's points `points` (two per point in the tissue, in field
    /// order; masked points have none).
    pub fn rows_of(&self, points: std::ops::Range<usize>) -> std::ops::Range<usize> {
        let before = |k: usize| {
            2 * self.located[..k.min(self.located.len())]
                .iter()
                .filter(|l| **l)
                .count()
        };
        before(points.start)..before(points.end)
    }

    /// The row of the actuator term (the last), if there is one.
    pub fn travel_row(&self) -> Option<usize> {
        self.travel.map(|_| 2 * self.locations.len())
    }

    pub fn model(&self) -> &Model {
        &self.model
    }

    /// Sets the model parameters from the log-parameters `phi`.
    fn set(&mut self, phi: &[f64]) {
        for (f, &p) in self.free.iter().zip(phi) {
            for m in &f.members {
                m.set(&mut self.model, p.exp());
            }
        }
    }

    /// The model field at the measured points for the last solve, as the measurement sees it:
    /// the displacement, plus the speckle's shift under shear at its current scale.
    fn project(&self, u: &[f64], out: &mut Vec<f64>) {
        let kappa = self.speckle.as_ref().map_or(0.0, |s| s.kappa);
        self.project_with(u, kappa, out);
    }

    /// The displacement at the measured points plus `kappa` times the speckle's shift
    /// ([`SpeckleTerm::shift`]); linear in `u`, so it maps sensitivities too.
    fn project_with(&self, u: &[f64], kappa: f64, out: &mut Vec<f64>) {
        out.clear();
        for loc in &self.locations {
            out.push(loc.interpolate(u, 2, 0));
            out.push(loc.interpolate(u, 2, 1));
        }
        if let (Some(s), true) = (&self.speckle, kappa != 0.0) {
            s.add_shift(&self.locations, u, kappa, out);
        }
    }

    /// Weighted residuals `√w (u_model - u_measured)` at `phi` and, if asked, the Jacobian
    /// columns `∂r/∂φ_k`.
    fn residuals(
        &mut self,
        phi: &[f64],
        jacobian: bool,
    ) -> Result<(Vec<f64>, Option<Columns>), FitError> {
        self.check_stop()?;
        self.set(phi);
        self.forward_solves += 1;
        let sol = self
            .solver
            .solve_with(&self.model, self.warm.as_deref(), &mut |_| {})
            .map_err(FitError::from_solve)?;
        // The speckle's shift at a fixed scale is part of the projection; a fitted scale is
        // profiled out (variable projection): the residual's component along the weighted
        // shift v is removed, r = P⊥ (a), κ = -vᵀa / vᵀv, and the Jacobian columns are
        // P⊥ (∂a/∂φ + κ ∂v/∂φ) (Kaufman's form), so that the Gauss–Newton covariance of the
        // parameters is the marginal one with κ free.
        let (kappa, fitted) = match self.speckle.as_ref().map(|s| s.shift.scale) {
            None => (0.0, false),
            Some(ShiftScale::Fixed(k)) => (k, false),
            Some(ShiftScale::Fitted) => (0.0, true),
        };
        let mut diff = Vec::with_capacity(self.measured.len());
        self.project_with(&sol.u, kappa, &mut diff);
        for (d, m) in diff.iter_mut().zip(&self.measured) {
            *d -= m;
        }
        let mut r = self.weigh(&diff);
        let mut profile: Option<(Vec<f64>, f64)> = None;
        let mut kappa = kappa;
        if fitted {
            let mut shift = vec![0.0; diff.len()];
            if let Some(s) = &self.speckle {
                s.add_shift(&self.locations, &sol.u, 1.0, &mut shift);
            }
            let v = self.weigh(&shift);
            let vv: f64 = v.iter().map(|x| x * x).sum();
            let rr: f64 = r.iter().map(|x| x * x).sum();
            // A field without shear (or a shift of no size) says nothing about κ.
            if vv > 1e-24 * (1.0 + rr) && vv.is_finite() {
                let vr: f64 = v.iter().zip(&r).map(|(a, b)| a * b).sum();
                kappa = -vr / vv;
                for (x, a) in r.iter_mut().zip(&v) {
                    *x += kappa * a;
                }
                profile = Some((v, vv));
            }
        }
        if let Some(s) = self.speckle.as_mut() {
            s.kappa = kappa;
        }
        let travel_dof = 2 * self.model.node_count();
        if let Some((t, sigma)) = self.travel {
            r.push((sol.state[travel_dof] - t) / sigma);
        }
        let mut jac = if jacobian {
            self.jacobians += 1;
            let members: Vec<Parameter> = self
                .free
                .iter()
                .flat_map(|f| f.members.iter().copied())
                .collect();
            self.sensitivity
                .compute(
                    &mut self.solver,
                    &self.model,
                    &sol.state,
                    &members,
                    &mut self.dstate,
                )
                .map_err(|e| FitError::Sensitivity(e.to_string()))?;
            let mut cols = Vec::with_capacity(self.free.len());
            let mut k = 0;
            let mut col = Vec::new();
            for f in &self.free {
                let mut sum = vec![0.0; diff.len()];
                let mut travel = 0.0;
                for m in &f.members {
                    let theta = m.value(&self.model);
                    self.project_with(&self.dstate[k], kappa, &mut col);
                    for (s, c) in sum.iter_mut().zip(&col) {
                        *s += theta * c;
                    }
                    if let Some((_, sigma)) = self.travel {
                        travel += theta * self.dstate[k][travel_dof] / sigma;
                    }
                    k += 1;
                }
                let mut c = self.weigh(&sum);
                if let Some((v, vv)) = &profile {
                    let along = v.iter().zip(&c).map(|(a, b)| a * b).sum::<f64>() / vv;
                    for (x, a) in c.iter_mut().zip(v) {
                        *x -= along * a;
                    }
                }
                if self.travel.is_some() {
                    c.push(travel);
                }
                cols.push(c);
            }
            Some(cols)
        } else {
            None
        };
        self.loss.apply(&mut r, jac.as_mut());
        self.warm = Some(sol.state);
        Ok((r, jac))
    }

    /// The weighted residual of a difference over the located points' components: `√w d`, or
    /// with a covariance, `L⁻¹ d` over the components it covers.
    fn weigh(&self, d: &[f64]) -> Vec<f64> {
        match &self.whitening {
            None => d.iter().zip(&self.sqrt_w).map(|(v, w)| w * v).collect(),
            Some((w, kept)) => {
                let mut v: Vec<f64> = kept
                    .iter()
                    .flat_map(|&l| [d[2 * l], d[2 * l + 1]])
                    .collect();
                w.apply(&mut v);
                v
            }
        }
    }

    /// Weights the misfit by the measured field's full covariance (module
    /// [`crate::weighted`]): `cov` covers every point of the field given to [`Problem::new`];
    /// the points kept are those in the tissue with a non-zero weight (the others are
    /// marginalized: their rows and columns of `cov` dropped). Replaces the per-point weights.
    pub fn with_covariance(mut self, cov: &FieldCovariance) -> Result<Problem, FitError> {
        if cov.points != self.field_points {
            return Err(FitError::Covariance(format!(
                "a covariance of {} points for a field of {}",
                cov.points, self.field_points
            )));
        }
        let kept: Vec<usize> = (0..self.locations.len())
            .filter(|&l| self.sqrt_w[2 * l] > 0.0 || self.sqrt_w[2 * l + 1] > 0.0)
            .collect();
        if 2 * kept.len() < self.free.len() {
            return Err(FitError::TooFewData {
                data: 2 * kept.len(),
                free: self.free.len(),
            });
        }
        let field: Vec<usize> = kept.iter().map(|&l| self.field_index[l]).collect();
        self.whitening = Some((Whitening::new(&cov.sub(&field))?, kept));
        Ok(self)
    }

    /// Adds the speckle's lateral shift under shear to the measurement model (module
    /// [`crate::speckle`]): the field at each measured point is `u + κ c(z) g e_lateral`, with
    /// `g` the model's shear `e_axialᵀ ∇u e_lateral` there and `z` its depth below the face.
    /// With [`ShiftScale::Fitted`], `κ` is estimated at every evaluation (variable projection;
    /// [`Problem::speckle_scale`] gives the last).
    pub fn with_speckle_shift(mut self, shift: SpeckleShift) -> Result<Problem, FitError> {
        shift.check().map_err(FitError::Speckle)?;
        let mesh = &self.model.mesh;
        let coefficients = self
            .locations
            .iter()
            .map(|loc| {
                let mut x = [0.0; 2];
                for a in 0..loc.n_nodes {
                    let node = mesh.nodes[loc.nodes[a]];
                    x[0] += loc.weights[a] * node[0];
                    x[1] += loc.weights[a] * node[1];
                }
                let c = shift.per_shear(shift.depth(x));
                let grads = loc.shape_gradients(mesh);
                let mut q = [0.0; 4];
                for a in 0..loc.n_nodes {
                    q[a] = c * (grads[a][0] * shift.lateral[0] + grads[a][1] * shift.lateral[1]);
                }
                q
            })
            .collect();
        let kappa = match shift.scale {
            ShiftScale::Fixed(k) => k,
            ShiftScale::Fitted => 0.0,
        };
        self.speckle = Some(SpeckleTerm {
            shift,
            coefficients,
            kappa,
        });
        Ok(self)
    }

    /// The speckle shift's scale `κ` of the last evaluation (the fixed one before any), if the
    /// measurement model has the shift.
    pub fn speckle_scale(&self) -> Option<f64> {
        self.speckle.as_ref().map(|s| s.kappa)
    }

    /// The fitted speckle-shift scale at `phi` with what its standard deviation needs
    /// ([`crate::misfit_intervals::speckle_scale_sd`]): the weighted residuals and Jacobian
    /// columns at that scale held, and the scale's own column, the weighted shift `v` (zero on
    /// the actuator row). `None` unless the scale is fitted. Two forward solves and one
    /// sensitivity evaluation.
    pub fn speckle_columns(&mut self, phi: &[f64]) -> Result<Option<SpeckleColumns>, FitError> {
        if !matches!(
            self.speckle.as_ref().map(|s| s.shift.scale),
            Some(ShiftScale::Fitted)
        ) {
            return Ok(None);
        }
        self.residuals(phi, false)?;
        let kappa = self.speckle_scale().unwrap_or(0.0);
        let set = |p: &mut Problem, scale| {
            if let Some(s) = p.speckle.as_mut() {
                s.shift.scale = scale;
            }
        };
        set(self, ShiftScale::Fixed(kappa));
        let held = self.residuals(phi, true);
        set(self, ShiftScale::Fitted);
        let (r, j) = held?;
        let j = j.ok_or_else(|| FitError::Speckle("no Jacobian at the held scale".into()))?;
        let n = self.model.node_count();
        let u = &self.warm.as_ref().expect("solved just above")[..2 * n];
        let mut shift = vec![0.0; self.measured.len()];
        if let Some(s) = &self.speckle {
            s.add_shift(&self.locations, u, 1.0, &mut shift);
        }
        let mut v = self.weigh(&shift);
        v.resize(r.len(), 0.0); // the actuator term does not see the shift
        Ok(Some(SpeckleColumns {
            kappa,
            residual: r,
            jacobian: j,
            shift: v,
        }))
    }

    /// Minimizes the loss `loss` of the (whitened) residuals instead of their squares (module
    /// [`crate::weighted`]).
    pub fn with_loss(mut self, loss: Loss) -> Problem {
        self.loss = loss;
        self
    }

    /// The model field `[ux, uy, ...]` at the located measured points for `theta` (model
    /// units, one per free parameter), and the masked count: a virtual measurement.
    pub fn field_at(&mut self, theta: &[f64]) -> Result<Vec<f64>, FitError> {
        self.check_stop()?;
        let phi: Vec<f64> = theta.iter().map(|t| t.ln()).collect();
        self.set(&phi);
        let sol = self
            .solver
            .solve_with(&self.model, self.warm.as_deref(), &mut |_| {})
            .map_err(FitError::from_solve)?;
        let mut out = Vec::new();
        self.project(&sol.u, &mut out);
        self.warm = Some(sol.state);
        Ok(out)
    }
}

/// What the fitted speckle-shift scale's sd needs ([`Problem::speckle_columns`]).
pub struct SpeckleColumns {
    /// The fitted scale.
    pub kappa: f64,
    /// The weighted residuals and Jacobian columns at that scale held.
    pub residual: Vec<f64>,
    pub jacobian: Columns,
    /// The scale's own column: the weighted shift (zero on the actuator row).
    pub shift: Vec<f64>,
}

/// The speckle's shift of a [`Problem`]: per located point, `c(z) ∂N_a/∂x_lateral` of its
/// element's nodes, and the current scale.
struct SpeckleTerm {
    shift: SpeckleShift,
    coefficients: Vec<[f64; 4]>,
    kappa: f64,
}

impl SpeckleTerm {
    /// Adds `kappa c(z) g e_lateral` at every located point to `out` (`[ux, uy, ...]`), `g` the
    /// shear of the nodal field `u`.
    fn add_shift(&self, locations: &[PointLocation], u: &[f64], kappa: f64, out: &mut [f64]) {
        let [ax, ay] = self.shift.axial;
        let [lx, ly] = self.shift.lateral;
        for (i, (loc, q)) in locations.iter().zip(&self.coefficients).enumerate() {
            let mut cg = 0.0;
            for a in 0..loc.n_nodes {
                let n = loc.nodes[a];
                cg += q[a] * (ax * u[2 * n] + ay * u[2 * n + 1]);
            }
            out[2 * i] += kappa * cg * lx;
            out[2 * i + 1] += kappa * cg * ly;
        }
    }
}

impl FitError {
    /// A forward solve's failure; a solve stopped by the user is [`FitError::Interrupted`].
    fn from_solve(e: femu_mech::SolveError) -> FitError {
        match e {
            femu_mech::SolveError::Interrupted(_) => FitError::Interrupted,
            e => FitError::Solve(e.to_string()),
        }
    }

    /// [`FitError::from_solve`] with where the solve was (`load step 2`, ...).
    pub(crate) fn from_solve_at(e: femu_mech::SolveError, at: &str) -> FitError {
        match FitError::from_solve(e) {
            FitError::Solve(m) => FitError::Solve(format!("{at}: {m}")),
            other => other,
        }
    }
}

impl LeastSquares for Problem {
    fn free(&self) -> &[FreeParameter] {
        &self.free
    }

    fn evaluate(
        &mut self,
        phi: &[f64],
        jacobian: bool,
    ) -> Result<(Vec<f64>, Option<Columns>), FitError> {
        self.residuals(phi, jacobian)
    }

    fn counts(&self) -> (usize, usize) {
        (self.forward_solves, self.jacobians)
    }

    fn states(&self) -> Vec<Option<Vec<f64>>> {
        vec![self.warm.clone()]
    }
}

/// Options of [`levenberg_marquardt`].
#[derive(Debug, Clone, Copy, Serialize, Deserialize)]
pub struct LmOptions {
    pub max_iterations: usize,
    /// Stop when the largest log-parameter step is below this (relative parameter change).
    pub step_tolerance: f64,
    /// Stop when the cost decreases by less than this fraction in an accepted step, or the
    /// Gauss–Newton model predicts less for the next one.
    pub cost_tolerance: f64,
    /// Initial damping, relative to the diagonal of JᵀJ.
    pub initial_damping: f64,
    /// Stop when every parameter's Gauss–Newton step is below this fraction of its standard
    /// deviation `s √(JᵀJ)⁻¹_pp` (`s²` the residual variance): further steps would move the
    /// estimate by less than its uncertainty can tell. `None`: not used. Gauss–Newton converges
    /// linearly when the residual stays large (grey levels of decorrelated speckle), and the
    /// parameters the data hardly see keep drifting: this stops it on what matters.
    #[serde(default)]
    pub significance: Option<f64>,
    /// Extrapolate a linearly converging sequence of steps (Aitken's Δ² along the step): when
    /// two accepted steps point the same way (cosine above [`ACCELERATION_COSINE`]) and the
    /// second is a fraction `ρ` of the first, the remaining steps of that geometric sequence,
    /// `d ρ / (1 − ρ)`, are tried at once and kept if the cost decreases. Gauss–Newton
    /// converges linearly when the residual is large and curved (grey levels of decorrelated
    /// speckle: each step 8 % shorter than the one before, measured on the built-in thigh at
    /// 0 px): without this it crawls.
    #[serde(default)]
    pub accelerate: bool,
}

/// Two consecutive steps this parallel (cosine) form a geometric sequence that
/// [`LmOptions::accelerate`] extrapolates: 0.95, about 18°.
pub const ACCELERATION_COSINE: f64 = 0.95;

/// The largest extrapolation factor `ρ / (1 − ρ)` (ρ = 0.95): further, the geometric model of
/// the remaining steps is not trusted.
pub const MAX_EXTRAPOLATION: f64 = 19.0;

/// The extrapolated point of a geometric sequence of steps `prev`, `d` (see
/// [`LmOptions::accelerate`]) from `phi` (the point after `d`), clamped to the log-bounds;
/// `None` when the steps do not form one.
fn extrapolated(prev: &[f64], d: &[f64], phi: &[f64], lo: &[f64], hi: &[f64]) -> Option<Vec<f64>> {
    let (nd, np) = (dot(d, d).sqrt(), dot(prev, prev).sqrt());
    if !(nd > 0.0 && np > 0.0) {
        return None;
    }
    let cos = dot(d, prev) / (nd * np);
    let rho = nd / np;
    if cos < ACCELERATION_COSINE || rho >= 1.0 {
        return None;
    }
    let factor = (rho / (1.0 - rho)).min(MAX_EXTRAPOLATION);
    Some(
        (0..phi.len())
            .map(|p| (phi[p] + factor * d[p]).clamp(lo[p], hi[p]))
            .collect(),
    )
}

impl Default for LmOptions {
    fn default() -> Self {
        LmOptions {
            max_iterations: 60,
            step_tolerance: 1e-8,
            cost_tolerance: 1e-10,
            initial_damping: 1e-3,
            significance: None,
            accelerate: false,
        }
    }
}

/// One accepted or rejected step.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct LmStep {
    pub iteration: usize,
    pub cost: f64,
    pub damping: f64,
    pub accepted: bool,
    pub max_step: f64,
    /// Why a step was rejected when its forward solve failed.
    pub failure: Option<String>,
}

/// The result of one minimization.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct FitResult {
    /// Identified free parameters (model units).
    pub theta: Vec<f64>,
    pub start: Vec<f64>,
    /// `½ Σ r²` at the optimum.
    pub cost: f64,
    pub iterations: usize,
    pub forward_solves: usize,
    pub jacobians: usize,
    pub converged: bool,
    pub reason: String,
    pub history: Vec<LmStep>,
    pub wall_time_s: f64,
    /// Jacobian columns at the optimum (for confidence intervals).
    #[serde(skip)]
    pub jacobian: Vec<Vec<f64>>,
    /// Number of residual components.
    pub data: usize,
    /// The residual at the optimum (for the jackknife over blocks of data; empty when the
    /// optimizer does not keep it).
    #[serde(skip)]
    pub residual: Vec<f64>,
}

impl FitResult {
    /// The fields every optimizer fills the same way: parameters from the log-parameters
    /// `phi`, the start, the forward solves and Jacobians since (`solves0`, `jac0`), the wall
    /// time since `t0`; the rest empty, for the optimizer to set.
    fn started<P: LeastSquares + ?Sized>(
        problem: &P,
        start: &[f64],
        phi: &[f64],
        solves0: usize,
        jac0: usize,
        t0: Instant,
    ) -> FitResult {
        FitResult {
            theta: phi.iter().map(|p| p.exp()).collect(),
            start: start.to_vec(),
            cost: f64::NAN,
            iterations: 0,
            forward_solves: problem.counts().0 - solves0,
            jacobians: problem.counts().1 - jac0,
            converged: false,
            reason: String::new(),
            history: Vec::new(),
            wall_time_s: t0.elapsed().as_secs_f64(),
            data: 0,
            jacobian: Vec::new(),
            residual: Vec::new(),
        }
    }
}

fn dot(a: &[f64], b: &[f64]) -> f64 {
    a.iter().zip(b).map(|(x, y)| x * y).sum()
}

/// Rows per block of [`normal_equations`].
pub const NORMAL_BLOCK_ROWS: usize = 4096;

/// The normal equations `A = JᵀJ` and `g = Jᵀr` of the Jacobian columns `j` and the residual
/// `r`, in one pass over the rows: blocks of [`NORMAL_BLOCK_ROWS`] rows are summed in parallel
/// (each row's outer product added to the block's upper triangle) and the blocks' sums added in
/// block order, so the result does not depend on the number of threads. An image
/// identification's Jacobian has millions of rows: one dot product per entry of `A` would read
/// every column `n + 1` times, on one thread.
pub fn normal_equations(j: &[Vec<f64>], r: &[f64]) -> (Vec<Vec<f64>>, Vec<f64>) {
    use rayon::prelude::*;
    let n = j.len();
    let m = r.len();
    debug_assert!(j.iter().all(|c| c.len() == m));
    // Per block: the upper triangle of A row by row (n (n + 1) / 2 values), then g.
    let tri = n * (n + 1) / 2;
    let blocks = m.div_ceil(NORMAL_BLOCK_ROWS);
    let sums: Vec<Vec<f64>> = (0..blocks)
        .into_par_iter()
        .map(|b| {
            let rows = b * NORMAL_BLOCK_ROWS..((b + 1) * NORMAL_BLOCK_ROWS).min(m);
            let mut acc = vec![0.0; tri + n];
            let mut v = vec![0.0; n];
            for i in rows {
                for (vp, c) in v.iter_mut().zip(j) {
                    *vp = c[i];
                }
                let ri = r[i];
                let mut k = 0;
                for p in 0..n {
                    let vp = v[p];
                    for &vq in &v[p..] {
                        acc[k] += vp * vq;
                        k += 1;
                    }
                    acc[tri + p] += vp * ri;
                }
            }
            acc
        })
        .collect();
    let mut total = vec![0.0; tri + n];
    for s in &sums {
        for (t, v) in total.iter_mut().zip(s) {
            *t += v;
        }
    }
    let mut a = vec![vec![0.0; n]; n];
    let mut k = 0;
    for p in 0..n {
        for q in p..n {
            a[p][q] = total[k];
            a[q][p] = total[k];
            k += 1;
        }
    }
    (a, total[tri..].to_vec())
}

/// The trial point of a damped Gauss–Newton step `(A + λ diag A) δ = −g` within the bounds
/// `lo..hi` (log-parameters): a parameter at a bound whose step would leave it is held there
/// (its row and column dropped) and the others solved for again, until no held parameter is
/// added (at most one pass per parameter); the result is clamped. Projecting the full step
/// instead would let one parameter pressing on its bound shrink every other step to nothing.
fn bounded_step(
    a: &[Vec<f64>],
    g: &[f64],
    lambda: f64,
    phi: &[f64],
    lo: &[f64],
    hi: &[f64],
) -> Vec<f64> {
    use faer::linalg::solvers::Solve;
    let n = phi.len();
    let mut held = vec![false; n];
    let mut delta = vec![0.0; n];
    for _ in 0..=n {
        let free: Vec<usize> = (0..n).filter(|&p| !held[p]).collect();
        delta.fill(0.0);
        if free.is_empty() {
            break;
        }
        let m = faer::Mat::<f64>::from_fn(free.len(), free.len(), |i, j| {
            let (p, q) = (free[i], free[j]);
            a[p][q] + if p == q { lambda * a[p][p] } else { 0.0 }
        });
        let rhs = faer::Mat::<f64>::from_fn(free.len(), 1, |i, _| -g[free[i]]);
        let x = m.partial_piv_lu().solve(&rhs);
        for (i, &p) in free.iter().enumerate() {
            delta[p] = x[(i, 0)];
        }
        let mut added = false;
        for &p in &free {
            let leaves = (phi[p] <= lo[p] && delta[p] < 0.0) || (phi[p] >= hi[p] && delta[p] > 0.0);
            if leaves {
                held[p] = true;
                added = true;
            }
        }
        if !added {
            break;
        }
    }
    (0..n)
        .map(|p| (phi[p] + delta[p]).clamp(lo[p], hi[p]))
        .collect()
}

/// Minimizes the cost of `problem` from `start` (model units, one per free parameter).
pub fn levenberg_marquardt<P: LeastSquares + ?Sized>(
    problem: &mut P,
    start: &[f64],
    opts: &LmOptions,
) -> Result<FitResult, FitError> {
    let t0 = Instant::now();
    let n = problem.free().len();
    for (f, &s) in problem.free().iter().zip(start) {
        if !(s >= f.lower && s <= f.upper) {
            return Err(FitError::StartOutside {
                name: f.name.clone(),
                start: s,
                lower: f.lower,
                upper: f.upper,
            });
        }
    }
    let lo: Vec<f64> = problem.free().iter().map(|f| f.lower.ln()).collect();
    let hi: Vec<f64> = problem.free().iter().map(|f| f.upper.ln()).collect();
    let (solves0, jac0) = problem.counts();
    let mut phi: Vec<f64> = start.iter().map(|s| s.ln()).collect();
    let (mut r, j) = problem.evaluate(&phi, true)?;
    let mut j = j.expect("asked");
    let mut cost = 0.5 * dot(&r, &r);
    let mut lambda = opts.initial_damping;
    let mut history = Vec::new();
    let mut converged = false;
    let mut reason = format!("{} iterations", opts.max_iterations);
    let mut iterations = 0;
    // The last accepted step (for `opts.accelerate`; one buffer for the whole run).
    let mut previous_step = vec![0.0; n];
    let mut have_previous = false;
    for it in 1..=opts.max_iterations {
        iterations = it;
        // Normal equations A = JᵀJ, g = Jᵀr.
        let (a, g) = normal_equations(&j, &r);
        if let Some(p) = (0..n).find(|&p| !(a[p][p] > 0.0)) {
            return Err(FitError::Unidentifiable {
                name: problem.free()[p].name.clone(),
                norm: a[p][p].max(0.0).sqrt(),
            });
        }
        let trial = bounded_step(&a, &g, lambda, &phi, &lo, &hi);
        let max_step = (0..n)
            .map(|p| (trial[p] - phi[p]).abs())
            .fold(0.0f64, f64::max);
        if !max_step.is_finite() {
            return Err(FitError::Unidentifiable {
                name: problem.free()[0].name.clone(),
                norm: f64::NAN,
            });
        }
        // The decrease the Gauss–Newton model predicts for this step, `-(g·d + ½ dᵀAd)`: when
        // it is below the cost tolerance no step can show a decrease the forward solves resolve
        // (their displacements carry the solver's relative tolerance), so stop rather than
        // spend forward solves on rejected steps.
        let d: Vec<f64> = (0..n).map(|p| trial[p] - phi[p]).collect();
        let predicted = -(dot(&g, &d)
            + 0.5
                * (0..n)
                    .map(|p| d[p] * (0..n).map(|q| a[p][q] * d[q]).sum::<f64>())
                    .sum::<f64>());
        let negligible = predicted <= opts.cost_tolerance * cost;
        let insignificant = opts.significance.is_some_and(|f| {
            let (inv, _, _) = crate::fisher::pseudo_inverse(&a);
            let s2 = 2.0 * cost / (r.len().saturating_sub(n)).max(1) as f64;
            (0..n).all(|p| d[p].abs() <= f * (s2 * inv[p][p]).sqrt())
        });
        if max_step < opts.step_tolerance || negligible || insignificant {
            converged = true;
            reason = if negligible {
                format!(
                    "predicted decrease below {:.0e} of the cost",
                    opts.cost_tolerance
                )
            } else if insignificant {
                format!(
                    "every step below {} of its parameter's standard deviation",
                    opts.significance.unwrap_or(0.0)
                )
            } else {
                format!("step below {:.0e}", opts.step_tolerance)
            };
            history.push(LmStep {
                iteration: it,
                cost,
                damping: lambda,
                accepted: false,
                max_step,
                failure: None,
            });
            break;
        }
        match problem.evaluate(&trial, true) {
            Ok((rt, jt)) => {
                let ct = 0.5 * dot(&rt, &rt);
                let accepted = ct < cost;
                history.push(LmStep {
                    iteration: it,
                    cost: ct,
                    damping: lambda,
                    accepted,
                    max_step,
                    failure: None,
                });
                if accepted {
                    let decrease = (cost - ct) / cost.max(f64::MIN_POSITIVE);
                    phi = trial;
                    r = rt;
                    problem.recycle(std::mem::replace(&mut j, jt.expect("asked")));
                    cost = ct;
                    lambda = (lambda / 3.0).max(1e-12);
                    if decrease < opts.cost_tolerance || cost == 0.0 {
                        converged = true;
                        reason = "cost stationary".into();
                        break;
                    }
                    let ext = if opts.accelerate && have_previous {
                        extrapolated(&previous_step, &d, &phi, &lo, &hi)
                    } else {
                        None
                    };
                    if opts.accelerate {
                        previous_step.copy_from_slice(&d);
                        have_previous = true;
                    }
                    if let Some(ext) = ext {
                        let max_step = (0..n)
                            .map(|p| (ext[p] - phi[p]).abs())
                            .fold(0.0f64, f64::max);
                        match problem.evaluate(&ext, true) {
                            Ok((re, je)) => {
                                let ce = 0.5 * dot(&re, &re);
                                let better = ce < cost;
                                history.push(LmStep {
                                    iteration: it,
                                    cost: ce,
                                    damping: 0.0,
                                    accepted: better,
                                    max_step,
                                    failure: None,
                                });
                                if better {
                                    phi = ext;
                                    r = re;
                                    problem.recycle(std::mem::replace(&mut j, je.expect("asked")));
                                    cost = ce;
                                    // The next extrapolation needs two fresh steps.
                                    have_previous = false;
                                } else if let Some(je) = je {
                                    problem.recycle(je);
                                }
                            }
                            Err(FitError::Solve(why)) => history.push(LmStep {
                                iteration: it,
                                cost: f64::NAN,
                                damping: 0.0,
                                accepted: false,
                                max_step,
                                failure: Some(why),
                            }),
                            Err(e) => return Err(e),
                        }
                    }
                } else {
                    if let Some(jt) = jt {
                        problem.recycle(jt);
                    }
                    lambda *= 4.0;
                }
            }
            Err(FitError::Solve(why)) => {
                history.push(LmStep {
                    iteration: it,
                    cost: f64::NAN,
                    damping: lambda,
                    accepted: false,
                    max_step,
                    failure: Some(why),
                });
                lambda *= 10.0;
            }
            Err(e) => return Err(e),
        }
        if lambda > 1e12 {
            reason = "damping too large (no descent)".into();
            break;
        }
    }
    // The problem's state is that of the last evaluation, which may be a rejected trial:
    // the Jacobian returned is the one at `phi`.
    Ok(FitResult {
        cost,
        iterations,
        converged,
        reason,
        history,
        data: r.len(),
        jacobian: j,
        residual: r,
        ..FitResult::started(problem, start, &phi, solves0, jac0, t0)
    })
}

/// `n` Latin-hypercube starts in the log-bounds of `free` (each parameter's range cut into `n`
/// strata, one start per stratum, strata shuffled independently per parameter), seeded.
pub fn latin_hypercube(free: &[FreeParameter], n: usize, seed: u64) -> Vec<Vec<f64>> {
    let mut rng = rand::rngs::StdRng::seed_from_u64(seed);
    let mut starts = vec![vec![0.0; free.len()]; n];
    for (k, f) in free.iter().enumerate() {
        let (lo, hi) = (f.lower.ln(), f.upper.ln());
        let mut strata: Vec<usize> = (0..n).collect();
        for i in (1..n).rev() {
            let j = rng.gen_range(0..=i);
            strata.swap(i, j);
        }
        for (s, start) in strata.iter().zip(starts.iter_mut()) {
            let u = (*s as f64 + rng.gen_range(0.0..1.0)) / n as f64;
            start[k] = (lo + u * (hi - lo)).exp();
        }
    }
    starts
}

#[cfg(test)]
mod tests {
    use super::*;
    use femu_mech::material::{MaterialLaw, NeoHookean};

    /// The blocked normal equations against one dot product per entry, over rows that are
    /// not a multiple of the block (the last block partial) and one block alone.
    #[test]
    fn normal_equations_match_the_dot_products() {
        let mut rng = rand::rngs::StdRng::seed_from_u64(7);
        for m in [37, 3 * NORMAL_BLOCK_ROWS + 129] {
            let n = 5;
            let j: Columns = (0..n)
                .map(|_| (0..m).map(|_| rng.gen_range(-1.0..1.0)).collect())
                .collect();
            let r: Vec<f64> = (0..m).map(|_| rng.gen_range(-1.0..1.0)).collect();
            let (a, g) = normal_equations(&j, &r);
            for p in 0..n {
                // Sums of m products of magnitude below 1, reordered: round-off of order
                // m ε relative to the sum of magnitudes.
                let tol = 1e-13 * m as f64;
                assert!((g[p] - dot(&j[p], &r)).abs() < tol, "g[{p}]");
                for q in 0..n {
                    assert!((a[p][q] - dot(&j[p], &j[q])).abs() < tol, "a[{p}][{q}]");
                    assert_eq!(a[p][q], a[q][p]);
                }
            }
        }
    }

    #[test]
    fn latin_hypercube_fills_every_stratum() {
        let free: Vec<FreeParameter> = (0..3)
            .map(|k| FreeParameter {
                name: format!("P{k}"),
                members: vec![Parameter::new(k, &NeoHookean::SPEC, 0).unwrap()],
                lower: 1e-4,
                upper: 1e-2,
            })
            .collect();
        let s = latin_hypercube(&free, 5, 3);
        assert_eq!(s.len(), 5);
        for k in 0..3 {
            let mut strata: Vec<usize> = s
                .iter()
                .map(|x| {
                    ((x[k].ln() - 1e-4f64.ln()) / (1e-2f64.ln() - 1e-4f64.ln()) * 5.0) as usize
                })
                .collect();
            strata.sort_unstable();
            assert_eq!(strata, vec![0, 1, 2, 3, 4]);
        }
        assert_eq!(s, latin_hypercube(&free, 5, 3));
    }

    /// Dennis & Schnabel's large-residual example (1996, ex. 10.2.4) in `φ = ln θ`:
    /// `r = (φ + 1, λφ² + φ − 1)`, minimum at `φ = 0`, where Gauss–Newton converges linearly
    /// with ratio `λ` (the neglected `Σ r ∇²r = −2λ` against `JᵀJ = 2`).
    struct LargeResidual {
        free: Vec<FreeParameter>,
        lambda: f64,
        evaluations: usize,
    }

    impl LeastSquares for LargeResidual {
        fn free(&self) -> &[FreeParameter] {
            &self.free
        }
        fn evaluate(
            &mut self,
            phi: &[f64],
            jacobian: bool,
        ) -> Result<(Vec<f64>, Option<Columns>), FitError> {
            self.evaluations += 1;
            let x = phi[0];
            let r = vec![x + 1.0, self.lambda * x * x + x - 1.0];
            let j = jacobian.then(|| vec![vec![1.0, 2.0 * self.lambda * x + 1.0]]);
            Ok((r, j))
        }
        fn counts(&self) -> (usize, usize) {
            (self.evaluations, self.evaluations)
        }
    }

    /// BFGS keeps the Jacobian at its optimum, with either gradient, for the intervals that
    /// follow the fit (a finite-difference search evaluates none on its way).
    #[test]
    fn bfgs_returns_the_jacobian_at_its_optimum() {
        for gradient in [Gradient::Exact, Gradient::FiniteDifference(5e-4)] {
            let mut p = LargeResidual {
                free: vec![FreeParameter {
                    name: "P".into(),
                    members: vec![Parameter::new(0, &NeoHookean::SPEC, 0).unwrap()],
                    lower: 0.1,
                    upper: 10.0,
                }],
                lambda: 0.5,
                evaluations: 0,
            };
            let fit = bfgs(
                &mut p,
                &[0.5f64.exp()],
                gradient,
                &LmOptions::default(),
                200,
            )
            .unwrap();
            let x = fit.theta[0].ln();
            assert_eq!(fit.jacobian.len(), 1, "{gradient:?}");
            assert_eq!(fit.jacobian[0].len(), fit.residual.len(), "{gradient:?}");
            // The model's Jacobian and residual at the returned point (θ = exp φ read back as
            // ln θ: round-off only).
            let want = [[1.0, 2.0 * 0.5 * x + 1.0], [x + 1.0, 0.5 * x * x + x - 1.0]];
            for (got, want) in [&fit.jacobian[0], &fit.residual].iter().zip(want) {
                for (g, w) in got.iter().zip(want) {
                    assert!(
                        (g - w).abs() < 1e-12,
                        "{gradient:?}: {got:?} against {want:?}"
                    );
                }
            }
        }
    }

    /// The extrapolation of a geometric sequence of steps reaches the same minimum in far fewer
    /// evaluations; without it Gauss–Newton crawls at ratio λ = 0.9.
    #[test]
    fn acceleration_shortens_a_linear_crawl() {
        let problem = || LargeResidual {
            free: vec![FreeParameter {
                name: "P".into(),
                members: vec![Parameter::new(0, &NeoHookean::SPEC, 0).unwrap()],
                lower: 0.1,
                upper: 10.0,
            }],
            lambda: 0.9,
            evaluations: 0,
        };
        let opts = |accelerate| LmOptions {
            max_iterations: 400,
            step_tolerance: 1e-7,
            cost_tolerance: 1e-15,
            accelerate,
            ..LmOptions::default()
        };
        let start = [0.5f64.exp()];
        let mut plain = problem();
        let a = levenberg_marquardt(&mut plain, &start, &opts(false)).unwrap();
        let mut fast = problem();
        let b = levenberg_marquardt(&mut fast, &start, &opts(true)).unwrap();
        assert!(a.converged && b.converged, "{} / {}", a.reason, b.reason);
        // Both stop once a step is below 1e-7; the remaining error of a sequence of ratio 0.9
        // is 9 steps: 1e-6 in ln θ.
        assert!(a.theta[0].ln().abs() < 1e-5, "{}", a.theta[0]);
        assert!(b.theta[0].ln().abs() < 1e-5, "{}", b.theta[0]);
        // 0.5 · 0.9^k < 1e-7 takes ~146 iterations; the extrapolated sequence a handful
        // (measured: see the assertion message).
        assert!(
            3 * fast.evaluations < plain.evaluations,
            "{} evaluations with the extrapolation, {} without",
            fast.evaluations,
            plain.evaluations
        );
    }
}

/// How [`bfgs`] gets its gradient.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub enum Gradient {
    /// `Jᵀ r` with the exact Jacobian (one solve + sensitivities per evaluation).
    Exact,
    /// Central finite differences with this relative step (the seed's method: forward solves
    /// only, two extra per free parameter and gradient).
    FiniteDifference(f64),
}

/// BFGS on `½|r|²` in log-parameters with a projected backtracking (Armijo) line search — the
/// seed's optimizer (§2.1.3), kept to compare with [`levenberg_marquardt`]. Stops when the
/// largest step is below `opts.step_tolerance` or the cost stalls.
pub fn bfgs<P: LeastSquares + ?Sized>(
    problem: &mut P,
    start: &[f64],
    gradient: Gradient,
    opts: &LmOptions,
    max_iterations: usize,
) -> Result<FitResult, FitError> {
    let t0 = Instant::now();
    let n = problem.free().len();
    let lo: Vec<f64> = problem.free().iter().map(|f| f.lower.ln()).collect();
    let hi: Vec<f64> = problem.free().iter().map(|f| f.upper.ln()).collect();
    let (solves0, jac0) = problem.counts();
    let mut phi: Vec<f64> = start.iter().map(|s| s.ln()).collect();
    // Cost and gradient at phi.
    let eval = |p: &mut P, phi: &[f64]| -> Result<(f64, Vec<f64>), FitError> {
        match gradient {
            Gradient::Exact => {
                let (r, j) = p.evaluate(phi, true)?;
                let j = j.expect("asked");
                let g = j.iter().map(|c| dot(c, &r)).collect();
                Ok((0.5 * dot(&r, &r), g))
            }
            Gradient::FiniteDifference(h) => {
                let (r, _) = p.evaluate(phi, false)?;
                let c0 = 0.5 * dot(&r, &r);
                let mut g = vec![0.0; phi.len()];
                for k in 0..phi.len() {
                    // A relative step h of θ is a step of ln(1 + h) in φ; central differences.
                    let dq = (1.0 + h).ln();
                    let mut q = phi.to_vec();
                    q[k] += dq;
                    let (rp, _) = p.evaluate(&q, false)?;
                    q[k] = phi[k] - dq;
                    let (rm, _) = p.evaluate(&q, false)?;
                    g[k] = 0.5 * (dot(&rp, &rp) - dot(&rm, &rm)) / (2.0 * dq);
                }
                Ok((c0, g))
            }
        }
    };
    let (mut cost, mut g) = eval(problem, &phi)?;
    let mut hinv = vec![vec![0.0; n]; n];
    for (i, row) in hinv.iter_mut().enumerate() {
        row[i] = 1.0;
    }
    let mut history = Vec::new();
    let mut converged = false;
    let mut reason = format!("{max_iterations} iterations");
    let mut iterations = 0;
    let mut first = true;
    for it in 1..=max_iterations {
        iterations = it;
        let mut d: Vec<f64> = (0..n).map(|i| -dot(&hinv[i], &g)).collect();
        if first {
            // Scale the first step so that it moves the largest parameter by at most 0.5.
            let m = d.iter().fold(0.0f64, |a, v| a.max(v.abs()));
            if m > 0.5 {
                d.iter_mut().for_each(|v| *v *= 0.5 / m);
            }
        }
        let mut alpha = 1.0;
        let mut accepted = None;
        for _ in 0..30 {
            let trial: Vec<f64> = (0..n)
                .map(|i| (phi[i] + alpha * d[i]).clamp(lo[i], hi[i]))
                .collect();
            let step: Vec<f64> = (0..n).map(|i| trial[i] - phi[i]).collect();
            if step.iter().all(|s| s.abs() < opts.step_tolerance) {
                break;
            }
            match eval(problem, &trial) {
                Ok((ct, gt)) if ct <= cost + 1e-4 * dot(&g, &step) => {
                    accepted = Some((trial, step, ct, gt));
                    break;
                }
                Ok(_) | Err(FitError::Solve(_)) => alpha *= 0.5,
                Err(e) => return Err(e),
            }
        }
        let Some((trial, s, ct, gt)) = accepted else {
            converged = true;
            reason = "no further descent along the search direction".into();
            break;
        };
        let max_step = s.iter().fold(0.0f64, |a, v| a.max(v.abs()));
        history.push(LmStep {
            iteration: it,
            cost: ct,
            damping: alpha,
            accepted: true,
            max_step,
            failure: None,
        });
        let y: Vec<f64> = (0..n).map(|i| gt[i] - g[i]).collect();
        let sy = dot(&s, &y);
        if sy > 1e-12 * dot(&s, &s).sqrt() * dot(&y, &y).sqrt() {
            if first {
                // Shanno's scaling of the initial inverse Hessian.
                let scale = sy / dot(&y, &y);
                for (i, row) in hinv.iter_mut().enumerate() {
                    row.iter_mut().for_each(|v| *v = 0.0);
                    row[i] = scale;
                }
            }
            let hy: Vec<f64> = (0..n).map(|i| dot(&hinv[i], &y)).collect();
            let yhy = dot(&y, &hy);
            let rho = 1.0 / sy;
            for i in 0..n {
                for j in 0..n {
                    hinv[i][j] +=
                        (1.0 + rho * yhy) * rho * s[i] * s[j] - rho * (hy[i] * s[j] + s[i] * hy[j]);
                }
            }
        }
        first = false;
        let decrease = (cost - ct) / cost.max(f64::MIN_POSITIVE);
        phi = trial;
        cost = ct;
        g = gt;
        if max_step < opts.step_tolerance || decrease < opts.cost_tolerance {
            converged = true;
            reason = "step or cost decrease below tolerance".into();
            break;
        }
    }
    // The Jacobian at the optimum, for the intervals and the identifiability analysis (the
    // search used only the gradient; a finite-difference search keeps no Jacobian at all).
    let (r, jacobian) = problem.evaluate(&phi, true)?;
    let jacobian = jacobian.ok_or_else(|| {
        FitError::Covariance("the problem gave no Jacobian at the optimum".into())
    })?;
    Ok(FitResult {
        cost,
        iterations,
        converged,
        reason,
        history,
        data: r.len(),
        residual: r,
        jacobian,
        ..FitResult::started(problem, start, &phi, solves0, jac0, t0)
    })
}
