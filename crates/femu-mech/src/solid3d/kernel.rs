//! Reference geometry and element kernels of the 3D solid elements (see [`crate::solid3d`]).
//!
//! At each Gauss point the kernel takes the invariant derivatives of the energy at F, forms
//! `P` ([`pk1_3d`]) and, when the tangent is asked for, `A = dP/dF` ([`tangent_3d`]), and
//! contracts them with the shape-function gradients. C3D8H is the 3D counterpart of
//! [`crate::element::MeanDilatationElement`]: the element energy is
//! `Π_e = Σ_g w_g W_iso(F_g) + V_e U(θ)` with `θ = (1/V_e) Σ_g w_g J_g` (Simo, Taylor & Pister
//! 1985), the pressure `p = U'(θ)` condensed out, so that
//!
//! ```text
//! f = Σ_g w_g P_iso(F_g):∇N + p g,           g_ai = Σ_g w_g (H_g ∇N_a)_i = V_e ∂θ/∂u_ai
//! K = Σ_g w_g [A_iso(F_g) + p ∂H/∂F]:∇N∇N + (U''(θ)/V_e) g ⊗ g
//! ```
//!
//! (H = cof F): the pressure is carried by `W_J`, as in 2D, while `W_JJ` stays isochoric.

use super::shape::Kind3;
use crate::element::{BadReferenceGeometry, ElementResult};
use crate::material::hyperelastic::{
    cauchy_3d, cof3, det3, pk1_3d, tangent_3d, EnergyPart, Hyperelastic, InvariantDerivatives3,
    NonPositiveJacobian, Tensor3,
};
use crate::material::MaterialLaw;

/// Largest number of nodes of a 3D element (C3D10), of local dofs, and of Gauss points (C3D8).
pub const MAX_NODES_3D: usize = 10;
pub const MAX_DOFS_3D: usize = 3 * MAX_NODES_3D;
pub const MAX_GAUSS_3D: usize = 8;

/// Reference-configuration data of one integration point.
#[derive(Debug, Clone, Copy, Default)]
pub struct GaussPoint3 {
    /// `∂N_a/∂X_J` for each node a.
    pub dn_dx: [[f64; 3]; MAX_NODES_3D],
    /// Gauss weight times the reference Jacobian determinant (volume weight, mm³).
    pub weight: f64,
}

/// Precomputed reference geometry of one 3D element.
#[derive(Debug, Clone, Copy)]
pub struct Geometry3 {
    pub kind: Kind3,
    pub n_nodes: usize,
    pub n_gauss: usize,
    pub gauss: [GaussPoint3; MAX_GAUSS_3D],
    /// Reference volume (mm³).
    pub volume: f64,
}

impl Geometry3 {
    /// The Gauss-point gradients and weights from the reference node coordinates `x` (the
    /// element's nodes in its node order).
    pub fn new(kind: Kind3, x: &[[f64; 3]]) -> Result<Self, BadReferenceGeometry> {
        let n = kind.node_count();
        assert_eq!(x.len(), n, "{} has {n} nodes", kind.abaqus_name());
        let rule = kind.rule();
        let mut geo = Geometry3 {
            kind,
            n_nodes: n,
            n_gauss: rule.len(),
            gauss: [GaussPoint3::default(); MAX_GAUSS_3D],
            volume: 0.0,
        };
        for (g, (p, w)) in rule.iter().enumerate() {
            let dn = kind.shape_derivatives(*p);
            // J0_Jr = ∂X_J/∂ξ_r
            let mut j0 = [0.0; 9];
            for a in 0..n {
                for jj in 0..3 {
                    for r in 0..3 {
                        j0[3 * jj + r] += x[a][jj] * dn[a][r];
                    }
                }
            }
            let det = det3(&j0);
            if !(det > 0.0) {
                return Err(BadReferenceGeometry {
                    gauss_point: g,
                    det_j: det,
                });
            }
            // ∂N/∂X_J = Σ_r ∂N/∂ξ_r (J0⁻¹)_rJ, (J0⁻¹)_rJ = cof(J0)_Jr / det.
            let c = cof3(&j0);
            let gp = &mut geo.gauss[g];
            gp.weight = w * det;
            for a in 0..n {
                gp.dn_dx[a] = std::array::from_fn(|jj| {
                    (0..3).map(|r| dn[a][r] * c[3 * jj + r]).sum::<f64>() / det
                });
            }
        }
        geo.volume = geo.gauss[..geo.n_gauss].iter().map(|g| g.weight).sum();
        Ok(geo)
    }

    /// Deformation gradient (row-major 3x3) at Gauss point g for local displacements u.
    #[inline]
    pub fn deformation_gradient(&self, g: usize, u: &[[f64; 3]]) -> Tensor3 {
        let gp = &self.gauss[g];
        let mut f = [1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0];
        for a in 0..self.n_nodes {
            let d = gp.dn_dx[a];
            for i in 0..3 {
                for jj in 0..3 {
                    f[3 * i + jj] += u[a][i] * d[jj];
                }
            }
        }
        f
    }

    /// The mean dilatation `θ = (1/V_e) Σ_g w_g J_g`.
    pub fn mean_dilatation(&self, u: &[[f64; 3]]) -> Result<f64, NonPositiveJacobian> {
        let mut theta = 0.0;
        for g in 0..self.n_gauss {
            let j = det3(&self.deformation_gradient(g, u));
            if !(j > 0.0) {
                return Err(NonPositiveJacobian(j));
            }
            theta += self.gauss[g].weight * j;
        }
        Ok(theta / self.volume)
    }
}

/// `Σ_J T_iJ ∂N_a/∂X_J` for a 3x3 tensor T: the force of a stress T at node a.
#[inline]
fn contract(t: &Tensor3, d: &[f64; 3], i: usize) -> f64 {
    t[3 * i] * d[0] + t[3 * i + 1] * d[1] + t[3 * i + 2] * d[2]
}

/// The Gauss-point loop for the energy density whose invariant derivatives `derivatives`
/// gives at F (the whole W, or W_iso with the element's pressure for C3D8H): sets the energy,
/// the force and (if asked) the stiffness, and returns `Σ_g w_g H_g ∇N_a` per local dof (the
/// mean dilatation's gradient `V_e ∂θ/∂u`).
fn integrate(
    geo: &Geometry3,
    u: &[[f64; 3]],
    out: &mut ElementResult,
    derivatives: impl Fn(&Tensor3) -> Result<InvariantDerivatives3, NonPositiveJacobian>,
) -> Result<[f64; MAX_DOFS_3D], NonPositiveJacobian> {
    let n = geo.n_nodes;
    let nd = 3 * n;
    out.energy = 0.0;
    out.force[..nd].fill(0.0);
    if let Some(k) = out.stiffness.as_deref_mut() {
        k[..nd * nd].fill(0.0);
    }
    let mut volume_gradient = [0.0; MAX_DOFS_3D];
    for g in 0..geo.n_gauss {
        let gp = &geo.gauss[g];
        let w = gp.weight;
        let f = geo.deformation_gradient(g, u);
        let d = derivatives(&f)?;
        out.energy += w * d.w;
        let p = pk1_3d(&f, &d);
        let h = cof3(&f);
        for a in 0..n {
            for i in 0..3 {
                out.force[3 * a + i] += w * contract(&p, &gp.dn_dx[a], i);
                volume_gradient[3 * a + i] += w * contract(&h, &gp.dn_dx[a], i);
            }
        }
        if let Some(k) = out.stiffness.as_deref_mut() {
            let t = tangent_3d(&f, &d);
            for a in 0..n {
                let da = gp.dn_dx[a];
                // B_a[i][(kL)] = w Σ_J A_iJkL ∂N_a/∂X_J
                let ba: [[f64; 9]; 3] = std::array::from_fn(|i| {
                    std::array::from_fn(|c| {
                        w * (t[3 * i][c] * da[0]
                            + t[3 * i + 1][c] * da[1]
                            + t[3 * i + 2][c] * da[2])
                    })
                });
                for b in 0..n {
                    let db = gp.dn_dx[b];
                    for i in 0..3 {
                        for kk in 0..3 {
                            k[(3 * a + i) * nd + 3 * b + kk] += ba[i][3 * kk] * db[0]
                                + ba[i][3 * kk + 1] * db[1]
                                + ba[i][3 * kk + 2] * db[2];
                        }
                    }
                }
            }
        }
    }
    Ok(volume_gradient)
}

/// Energy, internal force (`3 n`) and, if asked, tangent (row-major `3n x 3n`) of a 3D
/// element at local displacements `u`, for any material (`dyn Hyperelastic` or a concrete
/// law).
pub fn evaluate<M: Hyperelastic + ?Sized>(
    geo: &Geometry3,
    mat: &M,
    u: &[[f64; 3]],
    out: &mut ElementResult,
) -> Result<(), NonPositiveJacobian> {
    if geo.kind != Kind3::C3d8h {
        integrate(geo, u, out, |f| mat.derivatives_3d(f))?;
        return Ok(());
    }
    let theta = geo.mean_dilatation(u)?;
    let [uvol, p, dp] = mat.volumetric(theta);
    let g = integrate(geo, u, out, |f| {
        let mut d = mat.derivatives_isochoric_3d(f)?;
        d.w_j += p;
        Ok(d)
    })?;
    out.energy += geo.volume * uvol;
    if let Some(k) = out.stiffness.as_deref_mut() {
        let nd = 3 * geo.n_nodes;
        let s = dp / geo.volume;
        for r in 0..nd {
            for c in 0..nd {
                k[r * nd + c] += s * g[r] * g[c];
            }
        }
    }
    Ok(())
}

/// Element averages (volume-weighted over the Gauss points) of the Cauchy stress and J.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct Averages3 {
    /// Cauchy stress `[σ11, σ22, σ33, σ12, σ13, σ23]` (MPa).
    pub cauchy_stress: [f64; 6],
    /// Volume ratio J = det F (for C3D8H the mean dilatation θ).
    pub volume_ratio: f64,
}

/// The element averages at local displacements `u`; for C3D8H the isochoric stress averaged
/// plus the element's pressure `U'(θ)` on the diagonal (as the 2D CPE4H).
pub fn averages<M: Hyperelastic + ?Sized>(
    geo: &Geometry3,
    mat: &M,
    u: &[[f64; 3]],
) -> Result<Averages3, NonPositiveJacobian> {
    let hybrid = geo.kind == Kind3::C3d8h;
    let mut avg = Averages3::default();
    for g in 0..geo.n_gauss {
        let f = geo.deformation_gradient(g, u);
        let d = if hybrid {
            mat.derivatives_isochoric_3d(&f)?
        } else {
            mat.derivatives_3d(&f)?
        };
        let s = cauchy_3d(&f, &d);
        let w = geo.gauss[g].weight / geo.volume;
        for (a, v) in avg.cauchy_stress.iter_mut().zip(s) {
            *a += w * v;
        }
        avg.volume_ratio += w * det3(&f);
    }
    if hybrid {
        let p = mat.volumetric(avg.volume_ratio)[1];
        for v in &mut avg.cauchy_stress[..3] {
            *v += p;
        }
    }
    Ok(avg)
}

/// The internal forces of the energies `E_k` (`k < count`, each with the part of the energy it
/// lives in, `term(k)`) at local displacements `u`: `forces[k * MAX_DOFS_3D..][..3 n]`. The 3D
/// counterpart of [`crate::element::unit_energy_forces`]: an isochoric term adds
/// `w P_k:∇N` at each point, a volumetric one `w E_k'(J) H:∇N`, or for C3D8H `E_k'(θ) g` with
/// the mean dilatation's gradient g. The forces are linear in the energy, so with
/// `W = Σ c_k E_k` these are exactly `∂f_int/∂c_k`.
pub fn unit_energy_forces<U: Hyperelastic>(
    geo: &Geometry3,
    u: &[[f64; 3]],
    count: usize,
    term: impl Fn(usize) -> (U, EnergyPart),
    forces: &mut [f64],
) -> Result<(), NonPositiveJacobian> {
    let n = geo.n_nodes;
    let nd = 3 * n;
    for k in 0..count {
        forces[k * MAX_DOFS_3D..k * MAX_DOFS_3D + nd].fill(0.0);
    }
    let mean_dilatation = geo.kind == Kind3::C3d8h;
    let mut volume_gradient = [0.0; MAX_DOFS_3D];
    let mut volume = 0.0;
    for g in 0..geo.n_gauss {
        let gp = &geo.gauss[g];
        let f = geo.deformation_gradient(g, u);
        let j = det3(&f);
        if !(j > 0.0) {
            return Err(NonPositiveJacobian(j));
        }
        let h = cof3(&f);
        for k in 0..count {
            let (energy, part) = term(k);
            let stress = match part {
                EnergyPart::Isochoric => pk1_3d(&f, &energy.derivatives_isochoric_3d(&f)?),
                EnergyPart::Volumetric if !mean_dilatation => {
                    let p = energy.volumetric(j)[1];
                    h.map(|c| p * c)
                }
                EnergyPart::Volumetric => continue,
            };
            let force = &mut forces[k * MAX_DOFS_3D..k * MAX_DOFS_3D + nd];
            for a in 0..n {
                for i in 0..3 {
                    force[3 * a + i] += gp.weight * contract(&stress, &gp.dn_dx[a], i);
                }
            }
        }
        if mean_dilatation {
            volume += gp.weight * j;
            for a in 0..n {
                for i in 0..3 {
                    volume_gradient[3 * a + i] += gp.weight * contract(&h, &gp.dn_dx[a], i);
                }
            }
        }
    }
    if mean_dilatation {
        let theta = volume / geo.volume;
        for k in 0..count {
            let (energy, part) = term(k);
            if part == EnergyPart::Volumetric {
                let p = energy.volumetric(theta)[1];
                let force = &mut forces[k * MAX_DOFS_3D..k * MAX_DOFS_3D + nd];
                for (v, g) in force.iter_mut().zip(&volume_gradient) {
                    *v = g * p;
                }
            }
        }
    }
    Ok(())
}

/// `∂f_e/∂θ_k` of a registered law's element force for each parameter k at local
/// displacements `u`: `forces[k * MAX_DOFS_3D..][..3 n]` (the 3D counterpart of
/// [`crate::material::Material::rate_forces`]): the force of `c_k'(θ_k) E_k`.
pub fn rate_forces<L: MaterialLaw>(
    law: &L,
    geo: &Geometry3,
    u: &[[f64; 3]],
    forces: &mut [f64],
) -> Result<(), NonPositiveJacobian> {
    let parameters = L::SPEC.parameters;
    unit_energy_forces(
        geo,
        u,
        parameters.len(),
        |k| (L::unit_energy(k), parameters[k].part),
        forces,
    )?;
    let nd = 3 * geo.n_nodes;
    for k in 0..parameters.len() {
        let rate = law.coefficient_rate(k);
        for v in &mut forces[k * MAX_DOFS_3D..k * MAX_DOFS_3D + nd] {
            *v *= rate;
        }
    }
    Ok(())
}
