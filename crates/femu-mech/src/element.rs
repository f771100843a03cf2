//! Plane-strain finite-strain solid elements: CPE4 (Q4, 2x2 Gauss), CPE4H (Q4 with constant
//! pressure, mean dilatation), CPE3 (linear triangle).
//!
//! Total Lagrangian form. With `F = I + Σ_a u_a ⊗ ∇_X N_a` at each Gauss point, the element
//! residual and tangent are
//!
//! ```text
//! f_ai  = Σ_g w_g P_iJ ∂N_a/∂X_J
//! K_aibk = Σ_g w_g A_iJkL ∂N_a/∂X_J ∂N_b/∂X_L
//! ```
//!
//! Local dof `2a + i` is component `i` of local node `a`. Node order and faces are drawn in the
//! `femu-mesh` crate documentation.

use crate::material::hyperelastic::{
    cauchy_from_derivatives, cof2, det2, log_strain, EnergyPart, Hyperelastic,
    InvariantDerivatives, NonPositiveJacobian, Tensor2,
};
use femu_mesh::ElementKind;

/// Largest number of nodes of an element, and of local dofs.
pub const MAX_NODES: usize = 4;
pub const MAX_DOFS: usize = 8;

/// Reference-configuration data of one integration point.
#[derive(Debug, Clone, Copy, Default)]
pub struct GaussPoint {
    /// `∂N_a/∂X_J` for each node a.
    pub dn_dx: [[f64; 2]; MAX_NODES],
    /// Gauss weight times the reference Jacobian determinant (area weight, mm²).
    pub weight: f64,
}

/// Precomputed reference geometry of one element (computed once per mesh).
#[derive(Debug, Clone, Copy)]
pub struct ElementGeometry {
    pub kind: ElementKind,
    pub n_nodes: usize,
    pub n_gauss: usize,
    pub gauss: [GaussPoint; 4],
    /// Reference area (mm²).
    pub area: f64,
}

/// The element's reference map is singular or inverted at a Gauss point.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct BadReferenceGeometry {
    pub gauss_point: usize,
    pub det_j: f64,
}

const G: f64 = 0.577_350_269_189_625_8; // 1/sqrt(3)
const QUAD_GAUSS: [[f64; 2]; 4] = [[-G, -G], [G, -G], [G, G], [-G, G]];

/// Q4 shape-function derivatives with respect to (ξ, η) at a point.
fn quad_dn_dxi(xi: f64, eta: f64) -> [[f64; 2]; 4] {
    [
        [-0.25 * (1.0 - eta), -0.25 * (1.0 - xi)],
        [0.25 * (1.0 - eta), -0.25 * (1.0 + xi)],
        [0.25 * (1.0 + eta), 0.25 * (1.0 + xi)],
        [-0.25 * (1.0 + eta), 0.25 * (1.0 - xi)],
    ]
}

/// Q4 shape functions at (ξ, η).
pub fn quad_shape(xi: f64, eta: f64) -> [f64; 4] {
    [
        0.25 * (1.0 - xi) * (1.0 - eta),
        0.25 * (1.0 + xi) * (1.0 - eta),
        0.25 * (1.0 + xi) * (1.0 + eta),
        0.25 * (1.0 - xi) * (1.0 + eta),
    ]
}

fn gauss_point(
    x: &[[f64; 2]; MAX_NODES],
    dn: &[[f64; 2]],
    w: f64,
    g: usize,
) -> Result<GaussPoint, BadReferenceGeometry> {
    // Jacobian of the reference map J0 = ∂X/∂ξ.
    let mut j0 = [0.0; 4];
    for (a, d) in dn.iter().enumerate() {
        j0[0] += x[a][0] * d[0];
        j0[1] += x[a][0] * d[1];
        j0[2] += x[a][1] * d[0];
        j0[3] += x[a][1] * d[1];
    }
    let det = det2(&j0);
    if !(det > 0.0) {
        return Err(BadReferenceGeometry {
            gauss_point: g,
            det_j: det,
        });
    }
    // ∂N/∂X = ∂N/∂ξ J0^-1
    let inv = [j0[3] / det, -j0[1] / det, -j0[2] / det, j0[0] / det];
    let mut gp = GaussPoint {
        weight: w * det,
        ..Default::default()
    };
    for (a, d) in dn.iter().enumerate() {
        gp.dn_dx[a] = [d[0] * inv[0] + d[1] * inv[2], d[0] * inv[1] + d[1] * inv[3]];
    }
    Ok(gp)
}

impl ElementGeometry {
    /// Computes the Gauss-point gradients and weights from the reference node coordinates.
    pub fn new(kind: ElementKind, x: &[[f64; 2]; MAX_NODES]) -> Result<Self, BadReferenceGeometry> {
        let mut geo = ElementGeometry {
            kind,
            n_nodes: kind.node_count(),
            n_gauss: 0,
            gauss: [GaussPoint::default(); 4],
            area: 0.0,
        };
        match kind {
            ElementKind::Cpe4 | ElementKind::Cpe4h => {
                geo.n_gauss = 4;
                for (g, p) in QUAD_GAUSS.iter().enumerate() {
                    geo.gauss[g] = gauss_point(x, &quad_dn_dxi(p[0], p[1]), 1.0, g)?;
                }
            }
            ElementKind::Cpe3 => {
                geo.n_gauss = 1;
                let dn = [[-1.0, -1.0], [1.0, 0.0], [0.0, 1.0]];
                geo.gauss[0] = gauss_point(x, &dn, 0.5, 0)?;
            }
        }
        geo.area = geo.gauss[..geo.n_gauss].iter().map(|g| g.weight).sum();
        Ok(geo)
    }

    /// Deformation gradient `[F11, F12, F21, F22]` at Gauss point g for local displacements u.
    #[inline(always)]
    pub fn deformation_gradient(&self, g: usize, u: &[[f64; 2]]) -> Tensor2 {
        let gp = &self.gauss[g];
        let mut f = [1.0, 0.0, 0.0, 1.0];
        for a in 0..self.n_nodes {
            let d = gp.dn_dx[a];
            f[0] += u[a][0] * d[0];
            f[1] += u[a][0] * d[1];
            f[2] += u[a][1] * d[0];
            f[3] += u[a][1] * d[1];
        }
        f
    }
}

/// What an element evaluation fills: energy, internal force and (optionally) tangent.
pub struct ElementResult<'a> {
    pub energy: f64,
    /// Internal force, length `2 n_nodes`.
    pub force: &'a mut [f64],
    /// Tangent, row-major `2n x 2n`, or `None` when only the residual is needed.
    pub stiffness: Option<&'a mut [f64]>,
}

/// An element formulation (one per deck element type).
pub trait SolidElement: Sync {
    /// Energy, internal force and tangent at local displacements `u`.
    fn evaluate(
        &self,
        geo: &ElementGeometry,
        mat: &dyn Hyperelastic,
        u: &[[f64; 2]],
        out: &mut ElementResult,
    ) -> Result<(), NonPositiveJacobian>;

    /// Element averages (area-weighted over the Gauss points) of the output fields at local
    /// displacements `u`, in one pass.
    fn averages(
        &self,
        geo: &ElementGeometry,
        mat: &dyn Hyperelastic,
        u: &[[f64; 2]],
    ) -> Result<ElementAverages, NonPositiveJacobian>;

    /// Element-average Cauchy stress `[σxx, σyy, σzz, σxy]` at local displacements `u`.
    fn cauchy_stress(
        &self,
        geo: &ElementGeometry,
        mat: &dyn Hyperelastic,
        u: &[[f64; 2]],
    ) -> Result<[f64; 4], NonPositiveJacobian> {
        Ok(self.averages(geo, mat, u)?.cauchy_stress)
    }
}

/// Element averages of the output fields (see [`SolidElement::averages`]).
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct ElementAverages {
    /// Logarithmic strain `[LExx, LEyy, LEzz, LExy]` (Abaqus' LE, the seed's Fig. 3).
    pub log_strain: [f64; 4],
    /// Cauchy stress `[σxx, σyy, σzz, σxy]` (MPa).
    pub cauchy_stress: [f64; 4],
    /// Volume ratio J = det F (for CPE4H, the mean dilatation θ).
    pub volume_ratio: f64,
}

/// The Gauss-point averages of LE, J and the Cauchy stress of the energy density whose
/// invariant derivatives `derivatives` gives at F (as in [`integrate`]).
fn average_fields(
    geo: &ElementGeometry,
    u: &[[f64; 2]],
    mat: &dyn Hyperelastic,
    derivatives: impl Fn(&Tensor2) -> Result<InvariantDerivatives, NonPositiveJacobian>,
) -> Result<ElementAverages, NonPositiveJacobian> {
    let mut avg = ElementAverages::default();
    for g in 0..geo.n_gauss {
        let f = geo.deformation_gradient(g, u);
        let s = cauchy_from_derivatives(mat, &f, &derivatives(&f)?);
        let le = log_strain(&f);
        let w = geo.gauss[g].weight / geo.area;
        for k in 0..4 {
            avg.log_strain[k] += w * le[k];
            avg.cauchy_stress[k] += w * s[k];
        }
        avg.volume_ratio += w * det2(&f);
    }
    Ok(avg)
}

/// CPE4 and CPE3: displacement-only, every Gauss point evaluates the full material.
#[derive(Debug, Clone, Copy)]
pub struct DisplacementElement;

/// CPE4H: Q4 displacements with a constant pressure per element (Q1P0, mean dilatation;
/// Simo, Taylor & Pister 1985). The element energy is
/// `Π_e = Σ_g w_g W_iso(F_g) + V_e U(θ)` with `θ = (1/V_e) Σ_g w_g J_g`;
/// the pressure `p = U'(θ)` is condensed out, so only displacements remain.
#[derive(Debug, Clone, Copy)]
pub struct MeanDilatationElement;

/// [`SolidElement::evaluate`] of `geo`'s element type for the material type `M`: the static
/// solver's hot loop, compiled once per registered law (through
/// [`crate::material::Material::evaluate_element`], one dynamic call per element). The
/// material is called directly, so its invariant derivatives inline into the Gauss-point loop,
/// and on x86-64 CPUs with AVX2 the loop runs a copy of itself compiled for AVX2
/// ([`crate::simd::with_avx2`]; detected at run time, the binary stays portable). The copy does
/// the same IEEE operations in the same order (the compiler neither reassociates nor fuses
/// them), so both give the same results to the bit (unit test); the AVX2 copy takes less than
/// half the time (`examples/assembly_cost`).
#[inline(always)]
pub fn evaluate_static<M: Hyperelastic>(
    geo: &ElementGeometry,
    law: &M,
    u: &[[f64; 2]],
    out: &mut ElementResult,
) -> Result<(), NonPositiveJacobian> {
    crate::simd::with_avx2(
        #[inline(always)]
        || match geo.kind {
            ElementKind::Cpe4 | ElementKind::Cpe3 => {
                DisplacementElement::evaluate_with(geo, law, u, out)
            }
            ElementKind::Cpe4h => MeanDilatationElement::evaluate_with(geo, law, u, out),
        },
    )
}

/// The formulation of a deck element type.
pub fn formulation(kind: ElementKind) -> &'static dyn SolidElement {
    match kind {
        ElementKind::Cpe4 | ElementKind::Cpe3 => &DisplacementElement,
        ElementKind::Cpe4h => &MeanDilatationElement,
    }
}

/// Adds `w P:∇N` to the force (`P` the first Piola–Kirchhoff stress).
#[inline]
fn add_stress_divergence(
    n: usize,
    dn: &[[f64; 2]; MAX_NODES],
    w: f64,
    pk1: &Tensor2,
    force: &mut [f64],
) {
    for a in 0..n {
        force[2 * a] += w * (pk1[0] * dn[a][0] + pk1[1] * dn[a][1]);
        force[2 * a + 1] += w * (pk1[2] * dn[a][0] + pk1[3] * dn[a][1]);
    }
}

/// One Gauss point's terms of the internal force and stiffness of an element of `N` nodes,
/// from the invariant derivatives `d` of the energy at F (weight `w`).
///
/// With `g_a = F ∇N_a` and `h_a = cof(F) ∇N_a` (2-vectors), `P = 2 W_I F + W_J cof F` gives
/// `f_ai = w (2 W_I g_ai + W_J h_ai)`, and contracting the tangent of the material module,
/// `A = 4 W_II F⊗F + 2 W_IJ (F⊗cof + cof⊗F) + W_JJ cof⊗cof + W_J dcof/dF + 2 W_I 𝕀`, with
/// `∇N_a` and `∇N_b` gives
///
/// ```text
/// K_(ai)(bk) = w [ g_ai (4 W_II g_bk + 2 W_IJ h_bk) + h_ai (2 W_IJ g_bk + W_JJ h_bk)
///                  + δ_ik 2 W_I ∇N_a·∇N_b + ε_ik W_J (∇N_a × ∇N_b) ]
/// ```
///
/// (`ε_12 = 1`, `ε_21 = -1`, `ε_ii = 0`; the last term is `dcof/dF`, constant in 2D): a third
/// of the arithmetic of forming A and contracting it.
#[derive(Clone, Copy)]
struct PointTerms<const N: usize> {
    w: f64,
    dn: [[f64; 2]; N],
    g: [[f64; 2]; N],
    h: [[f64; 2]; N],
    /// `4 w W_II g_b + 2 w W_IJ h_b` and `2 w W_IJ g_b + w W_JJ h_b` (for the stiffness).
    p: [[f64; 2]; N],
    q: [[f64; 2]; N],
    /// `2 w W_I` and `w W_J`.
    s_i: f64,
    s_j: f64,
}

impl<const N: usize> PointTerms<N> {
    #[inline(always)]
    fn new(
        dn: &[[f64; 2]; MAX_NODES],
        w: f64,
        f: &Tensor2,
        d: &InvariantDerivatives,
        stiffness: bool,
    ) -> Self {
        let c = cof2(f);
        let mut t = PointTerms {
            w,
            dn: std::array::from_fn(|a| dn[a]),
            g: [[0.0; 2]; N],
            h: [[0.0; 2]; N],
            p: [[0.0; 2]; N],
            q: [[0.0; 2]; N],
            s_i: 2.0 * w * d.w_i,
            s_j: w * d.w_j,
        };
        for a in 0..N {
            let [d0, d1] = dn[a];
            t.g[a] = [f[0] * d0 + f[1] * d1, f[2] * d0 + f[3] * d1];
            t.h[a] = [c[0] * d0 + c[1] * d1, c[2] * d0 + c[3] * d1];
        }
        if stiffness {
            let (k_ii, k_ij, k_jj) = (4.0 * w * d.w_ii, 2.0 * w * d.w_ij, w * d.w_jj);
            for b in 0..N {
                for k in 0..2 {
                    t.p[b][k] = k_ii * t.g[b][k] + k_ij * t.h[b][k];
                    t.q[b][k] = k_ij * t.g[b][k] + k_jj * t.h[b][k];
                }
            }
        }
        t
    }

    #[inline(always)]
    fn add_force(&self, force: &mut [f64]) {
        for a in 0..N {
            for i in 0..2 {
                force[2 * a + i] += self.s_i * self.g[a][i] + self.s_j * self.h[a][i];
            }
        }
    }
}

/// Writes the element stiffness (row-major `2N x 2N`) as the sum of its points' terms (see
/// [`PointTerms`]): each 2x2 block summed over the points in registers and stored once; K is
/// symmetric, so the blocks `b ≥ a` are computed and mirrored.
#[inline(always)]
fn element_stiffness<const N: usize>(points: &[PointTerms<N>], k: &mut [f64]) {
    let nd = 2 * N;
    let k = &mut k[..nd * nd];
    for a in 0..N {
        for b in a..N {
            let mut block = [[0.0; 2]; 2];
            let (mut geometric, mut cross) = (0.0, 0.0);
            for t in points {
                let ([da0, da1], [db0, db1]) = (t.dn[a], t.dn[b]);
                geometric += t.s_i * (da0 * db0 + da1 * db1);
                cross += t.s_j * (da0 * db1 - da1 * db0);
                for i in 0..2 {
                    for kk in 0..2 {
                        block[i][kk] += t.g[a][i] * t.p[b][kk] + t.h[a][i] * t.q[b][kk];
                    }
                }
            }
            block[0][0] += geometric;
            block[1][1] += geometric;
            block[0][1] += cross;
            block[1][0] -= cross;
            for i in 0..2 {
                for kk in 0..2 {
                    k[(2 * a + i) * nd + 2 * b + kk] = block[i][kk];
                    k[(2 * b + kk) * nd + 2 * a + i] = block[i][kk];
                }
            }
        }
    }
}

/// The Gauss-point loop of an element of `N` nodes for the energy density whose invariant
/// derivatives `derivatives` gives at F (the whole W for CPE4 and CPE3; W_iso with the
/// element's pressure for CPE4H): sets the energy, the force and (if asked) the stiffness, and
/// returns `Σ_g w_g cof(F_g) ∇N_a` per node (`V_e ∂θ/∂u_a`, the mean dilatation's gradient).
#[inline(always)]
fn integrate<const N: usize>(
    geo: &ElementGeometry,
    u: &[[f64; 2]],
    out: &mut ElementResult,
    derivatives: impl Fn(&Tensor2) -> Result<InvariantDerivatives, NonPositiveJacobian>,
) -> Result<[[f64; 2]; MAX_NODES], NonPositiveJacobian> {
    let want_k = out.stiffness.is_some();
    let empty = PointTerms {
        w: 0.0,
        dn: [[0.0; 2]; N],
        g: [[0.0; 2]; N],
        h: [[0.0; 2]; N],
        p: [[0.0; 2]; N],
        q: [[0.0; 2]; N],
        s_i: 0.0,
        s_j: 0.0,
    };
    let mut points = [empty; 4];
    out.energy = 0.0;
    out.force[..2 * N].fill(0.0);
    let mut volume_gradient = [[0.0; 2]; MAX_NODES];
    for g in 0..geo.n_gauss {
        let f = geo.deformation_gradient(g, u);
        let d = derivatives(&f)?;
        let gp = &geo.gauss[g];
        out.energy += gp.weight * d.w;
        let t = PointTerms::<N>::new(&gp.dn_dx, gp.weight, &f, &d, want_k);
        t.add_force(out.force);
        for a in 0..N {
            for i in 0..2 {
                volume_gradient[a][i] += t.w * t.h[a][i];
            }
        }
        points[g] = t;
    }
    if let Some(k) = out.stiffness.as_deref_mut() {
        element_stiffness(&points[..geo.n_gauss], k);
    }
    Ok(volume_gradient)
}

impl DisplacementElement {
    /// [`SolidElement::evaluate`] for any material type (`dyn Hyperelastic` through the trait,
    /// a concrete law in [`evaluate_static`]).
    #[inline(always)]
    fn evaluate_with<M: Hyperelastic + ?Sized>(
        geo: &ElementGeometry,
        mat: &M,
        u: &[[f64; 2]],
        out: &mut ElementResult,
    ) -> Result<(), NonPositiveJacobian> {
        let derivatives = |f: &Tensor2| mat.derivatives(f);
        match geo.n_nodes {
            4 => integrate::<4>(geo, u, out, derivatives)?,
            3 => integrate::<3>(geo, u, out, derivatives)?,
            n => unreachable!("elements have 3 or 4 nodes, not {n}"),
        };
        Ok(())
    }
}

impl SolidElement for DisplacementElement {
    fn evaluate(
        &self,
        geo: &ElementGeometry,
        mat: &dyn Hyperelastic,
        u: &[[f64; 2]],
        out: &mut ElementResult,
    ) -> Result<(), NonPositiveJacobian> {
        Self::evaluate_with(geo, mat, u, out)
    }

    fn averages(
        &self,
        geo: &ElementGeometry,
        mat: &dyn Hyperelastic,
        u: &[[f64; 2]],
    ) -> Result<ElementAverages, NonPositiveJacobian> {
        average_fields(geo, u, mat, |f| mat.derivatives(f))
    }
}

impl MeanDilatationElement {
    /// Mean dilatation θ of the element.
    fn mean_dilatation(geo: &ElementGeometry, u: &[[f64; 2]]) -> Result<f64, NonPositiveJacobian> {
        let mut theta = 0.0;
        for g in 0..geo.n_gauss {
            let j = det2(&geo.deformation_gradient(g, u));
            if !(j > 0.0) {
                return Err(NonPositiveJacobian(j));
            }
            theta += geo.gauss[g].weight * j;
        }
        Ok(theta / geo.area)
    }
}

impl MeanDilatationElement {
    /// [`SolidElement::evaluate`] for any material type (as
    /// [`DisplacementElement::evaluate_with`]).
    #[inline(always)]
    fn evaluate_with<M: Hyperelastic + ?Sized>(
        geo: &ElementGeometry,
        mat: &M,
        u: &[[f64; 2]],
        out: &mut ElementResult,
    ) -> Result<(), NonPositiveJacobian> {
        let nd = 2 * geo.n_nodes;
        let theta = Self::mean_dilatation(geo, u)?;
        let [uvol, p, dp] = mat.volumetric(theta);
        // The pressure adds P_vol = p cof(F) and the tangent p dcof/dF: both are carried by
        // W_J, while W_JJ stays isochoric (the volumetric stiffness is U''(θ) g ⊗ g below).
        let derivatives = |f: &Tensor2| {
            let mut d = mat.derivatives_isochoric(f)?;
            d.w_j += p;
            Ok(d)
        };
        // g_ai = Σ_g w_g ∂J_g/∂u_ai = V_e ∂θ/∂u_ai
        let g = match geo.n_nodes {
            4 => integrate::<4>(geo, u, out, derivatives)?,
            3 => integrate::<3>(geo, u, out, derivatives)?,
            n => unreachable!("elements have 3 or 4 nodes, not {n}"),
        };
        out.energy += geo.area * uvol;
        if let Some(k) = out.stiffness.as_deref_mut() {
            let s = dp / geo.area;
            let gvec: [f64; MAX_DOFS] = std::array::from_fn(|r| g[r / 2][r % 2]);
            for r in 0..nd {
                for c in 0..nd {
                    k[r * nd + c] += s * gvec[r] * gvec[c];
                }
            }
        }
        Ok(())
    }
}

impl SolidElement for MeanDilatationElement {
    fn evaluate(
        &self,
        geo: &ElementGeometry,
        mat: &dyn Hyperelastic,
        u: &[[f64; 2]],
        out: &mut ElementResult,
    ) -> Result<(), NonPositiveJacobian> {
        Self::evaluate_with(geo, mat, u, out)
    }

    /// The isochoric stress averaged over the Gauss points plus the element's pressure
    /// `p = U'(θ)` (θ = the averaged J) on the diagonal.
    fn averages(
        &self,
        geo: &ElementGeometry,
        mat: &dyn Hyperelastic,
        u: &[[f64; 2]],
    ) -> Result<ElementAverages, NonPositiveJacobian> {
        let mut avg = average_fields(geo, u, mat, |f| mat.derivatives_isochoric(f))?;
        let p = mat.volumetric(avg.volume_ratio)[1];
        for k in 0..3 {
            avg.cauchy_stress[k] += p;
        }
        Ok(avg)
    }
}

/// The internal forces of the energies `E_k` (`k < count`, each given with the part of the
/// energy it lives in by `term(k)`) at local displacements `u`, in one pass over the Gauss
/// points: `forces[k * MAX_DOFS..][..2 n]`. With `W = Σ c_k E_k` these are `∂f_int/∂c_k`
/// (parameter sensitivities, seed §2.3; see [`law`](mod@crate::material::law)).
///
/// CPE4 and CPE3: an isochoric term adds `w P_k:∇N` at each point (P_k of `E_k`'s isochoric
/// part), a volumetric one `w E_k'(J) cof F:∇N`. CPE4H: the isochoric terms as for CPE4, a
/// volumetric one `E_k'(θ) g` with `g = Σ_g w_g cof(F_g) ∇N` (`V_e ∂θ/∂u`, as in
/// [`MeanDilatationElement`]'s evaluation): the mean-dilatation force is linear in the energy
/// too, so these are exact for every formulation.
pub fn unit_energy_forces<U: Hyperelastic>(
    geo: &ElementGeometry,
    u: &[[f64; 2]],
    count: usize,
    term: impl Fn(usize) -> (U, EnergyPart),
    forces: &mut [f64],
) -> Result<(), NonPositiveJacobian> {
    let n = geo.n_nodes;
    let nd = 2 * n;
    for k in 0..count {
        forces[k * MAX_DOFS..k * MAX_DOFS + nd].fill(0.0);
    }
    let mean_dilatation = geo.kind == ElementKind::Cpe4h;
    // CPE4H: Σ_g w_g cof(F_g) ∇N_a and Σ_g w_g J_g.
    let mut volume_gradient = [0.0; MAX_DOFS];
    let mut volume = 0.0;
    for g in 0..geo.n_gauss {
        let gp = &geo.gauss[g];
        let f = geo.deformation_gradient(g, u);
        let j = det2(&f);
        if !(j > 0.0) {
            return Err(NonPositiveJacobian(j));
        }
        for k in 0..count {
            let (energy, part) = term(k);
            let force = &mut forces[k * MAX_DOFS..(k + 1) * MAX_DOFS];
            match part {
                EnergyPart::Isochoric => {
                    let r = energy.response_isochoric(&f, false)?;
                    add_stress_divergence(n, &gp.dn_dx, gp.weight, &r.pk1, force);
                }
                EnergyPart::Volumetric if !mean_dilatation => {
                    let p = energy.volumetric(j)[1];
                    let pk1 = cof2(&f).map(|c| p * c);
                    add_stress_divergence(n, &gp.dn_dx, gp.weight, &pk1, force);
                }
                EnergyPart::Volumetric => {}
            }
        }
        if mean_dilatation {
            volume += gp.weight * j;
            let c = cof2(&f);
            for a in 0..n {
                let d = gp.dn_dx[a];
                volume_gradient[2 * a] += gp.weight * (c[0] * d[0] + c[1] * d[1]);
                volume_gradient[2 * a + 1] += gp.weight * (c[2] * d[0] + c[3] * d[1]);
            }
        }
    }
    if mean_dilatation {
        let theta = volume / geo.area;
        for k in 0..count {
            let (energy, part) = term(k);
            if part == EnergyPart::Volumetric {
                let p = energy.volumetric(theta)[1];
                let force = &mut forces[k * MAX_DOFS..k * MAX_DOFS + nd];
                for (v, g) in force.iter_mut().zip(&volume_gradient) {
                    *v = g * p;
                }
            }
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn unit_square_geometry() {
        let x = [[0.0, 0.0], [2.0, 0.0], [2.0, 1.0], [0.0, 1.0]];
        let geo = ElementGeometry::new(ElementKind::Cpe4, &x).unwrap();
        assert!((geo.area - 2.0).abs() < 1e-14);
        // Σ_a ∂N_a/∂X = 0 and Σ_a X_a ⊗ ∂N_a/∂X = I at every Gauss point.
        for g in 0..4 {
            let gp = &geo.gauss[g];
            let mut m = [0.0; 4];
            for a in 0..4 {
                m[0] += x[a][0] * gp.dn_dx[a][0];
                m[1] += x[a][0] * gp.dn_dx[a][1];
                m[2] += x[a][1] * gp.dn_dx[a][0];
                m[3] += x[a][1] * gp.dn_dx[a][1];
            }
            for (k, e) in [1.0, 0.0, 0.0, 1.0].iter().enumerate() {
                assert!((m[k] - e).abs() < 1e-14);
            }
        }
    }

    /// The one-pass unit-energy forces equal one evaluation per unit energy `E_k` (to round-off:
    /// the same sums in another order), for every element type and each law.
    #[test]
    fn one_pass_unit_forces_match_one_evaluation_per_term() {
        use crate::material::{MaterialLaw, MooneyRivlin, NeoHookean, Yeoh};
        fn check<L: MaterialLaw>() {
            let x = [[0.0, 0.0], [2.0, 0.1], [2.2, 1.3], [-0.1, 1.0]];
            // Large enough for the cubic term of the Yeoh law (I1bar - 3 ≈ 0.1).
            let u = [[0.04, -0.08], [0.2, 0.12], [-0.16, 0.32], [0.08, -0.04]];
            let tri = [[0.0, 0.0], [2.0, 0.1], [0.3, 1.4], [0.0, 0.0]];
            for (kind, x, n) in [
                (ElementKind::Cpe4h, x, 4),
                (ElementKind::Cpe4, x, 4),
                (ElementKind::Cpe3, tri, 3),
            ] {
                let geo = ElementGeometry::new(kind, &x).unwrap();
                let count = L::SPEC.parameters.len();
                let mut forces = vec![0.0; count * MAX_DOFS];
                let term = |k| (L::unit_energy(k), L::SPEC.parameters[k].part);
                unit_energy_forces(&geo, &u[..n], count, term, &mut forces).unwrap();
                for k in 0..count {
                    let mut want = [0.0; MAX_DOFS];
                    let mut out = ElementResult {
                        energy: 0.0,
                        force: &mut want,
                        stiffness: None,
                    };
                    let energy = L::unit_energy(k);
                    formulation(kind)
                        .evaluate(&geo, &energy, &u[..n], &mut out)
                        .unwrap();
                    let got = &forces[k * MAX_DOFS..(k + 1) * MAX_DOFS];
                    let scale = want.iter().fold(0.0f64, |m, v| m.max(v.abs()));
                    assert!(scale > 1e-5, "{}: a non-trivial force", L::SPEC.name);
                    for (g, w) in got.iter().zip(want.iter()) {
                        assert!(
                            (g - w).abs() <= 1e-14 * scale,
                            "{} {kind:?} term {k}: {g} vs {w}",
                            L::SPEC.name
                        );
                    }
                }
            }
        }
        check::<NeoHookean>();
        check::<MooneyRivlin>();
        check::<Yeoh>();
    }

    /// The Neo-Hookean unit forces are, to the bit, those of the one-pass code they replaced
    /// (kept here as the reference: `NeoHookeanRate`'s isochoric stress, then `U'(J) cof F`, or
    /// for CPE4H `U'(θ)` times the summed `w cof(F) ∇N`), so the sensitivities did not change.
    #[test]
    fn neo_hookean_unit_forces_are_those_of_the_former_one_pass_code() {
        use crate::material::neo_hookean::NeoHookeanRate;
        use crate::material::{MaterialLaw, NeoHookean};
        use rand::{Rng, SeedableRng};
        fn former(geo: &ElementGeometry, u: &[[f64; 2]]) -> Result<[f64; 16], NonPositiveJacobian> {
            let (n, mut out) = (geo.n_nodes, [0.0; 16]);
            let (f_c10, f_inv_d) = out.split_at_mut(MAX_DOFS);
            let (iso, vol) = (NeoHookeanRate::UNIT_C10, NeoHookeanRate::UNIT_INV_D);
            let mut volume = 0.0;
            for g in 0..geo.n_gauss {
                let gp = &geo.gauss[g];
                let f = geo.deformation_gradient(g, u);
                let r = iso.response_isochoric(&f, false)?;
                add_stress_divergence(n, &gp.dn_dx, gp.weight, &r.pk1, f_c10);
                if geo.kind == ElementKind::Cpe4h {
                    volume += gp.weight * det2(&f);
                    let c = cof2(&f);
                    for a in 0..n {
                        let d = gp.dn_dx[a];
                        f_inv_d[2 * a] += gp.weight * (c[0] * d[0] + c[1] * d[1]);
                        f_inv_d[2 * a + 1] += gp.weight * (c[2] * d[0] + c[3] * d[1]);
                    }
                } else {
                    let p = vol.volumetric(det2(&f))[1];
                    let pk1 = cof2(&f).map(|c| p * c);
                    add_stress_divergence(n, &gp.dn_dx, gp.weight, &pk1, f_inv_d);
                }
            }
            if geo.kind == ElementKind::Cpe4h {
                let p = vol.volumetric(volume / geo.area)[1];
                for v in &mut f_inv_d[..2 * n] {
                    *v *= p;
                }
            }
            Ok(out)
        }
        let mut rng = rand::rngs::StdRng::seed_from_u64(9);
        let quad = [[0.0, 0.0], [2.0, 0.1], [2.2, 1.3], [-0.1, 1.0]];
        let tri = [[0.0, 0.0], [2.0, 0.1], [0.3, 1.4], [0.0, 0.0]];
        for (kind, x) in [
            (ElementKind::Cpe4, quad),
            (ElementKind::Cpe4h, quad),
            (ElementKind::Cpe3, tri),
        ] {
            let geo = ElementGeometry::new(kind, &x).unwrap();
            for trial in 0..200 {
                let scale = 1.5 * f64::from(trial) / 200.0;
                let u: Vec<[f64; 2]> = (0..geo.n_nodes)
                    .map(|_| {
                        [
                            scale * rng.gen_range(-1.0..1.0),
                            scale * rng.gen_range(-1.0..1.0),
                        ]
                    })
                    .collect();
                let mut now = [0.0; 16];
                let term = |k| {
                    (
                        NeoHookean::unit_energy(k),
                        NeoHookean::SPEC.parameters[k].part,
                    )
                };
                let status = unit_energy_forces(&geo, &u, 2, term, &mut now);
                match former(&geo, &u) {
                    Ok(want) => {
                        assert!(status.is_ok());
                        let bits = |v: &[f64]| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
                        assert_eq!(bits(&now), bits(&want), "{kind:?}, trial {trial}");
                    }
                    Err(e) => assert_eq!(status, Err(e), "{kind:?}, trial {trial}"),
                }
            }
        }
    }

    /// The solver's path (static material, AVX2 copy where the CPU has it, reached through one
    /// dynamic call: [`crate::material::Material::evaluate_element`]) gives the trait's results
    /// (dynamic material, baseline instructions) to the bit: energy, force, stiffness, and the
    /// same error for an inverted element, for every element type and every registered law (at
    /// its typical parameters); for the Neo-Hookean law also the generic kernel called with the
    /// concrete type.
    #[test]
    fn static_path_matches_the_trait_to_the_bit() {
        use crate::material::{Material, NeoHookean, LAWS};
        use rand::{Rng, SeedableRng};
        let mut rng = rand::rngs::StdRng::seed_from_u64(5);
        let neo_hookean = NeoHookean::new(0.0123, 0.456).unwrap();
        let quad = [[0.0, 0.0], [2.0, 0.1], [2.2, 1.3], [-0.1, 1.0]];
        let tri = [[0.0, 0.0], [2.0, 0.1], [0.3, 1.4], [0.0, 0.0]];
        let evaluate = |path: u8, law: &dyn Material, geo: &ElementGeometry, u: &[[f64; 2]]| {
            let (mut force, mut stiffness) = ([0.0; MAX_DOFS], [0.0; MAX_DOFS * MAX_DOFS]);
            let mut out = ElementResult {
                energy: 0.0,
                force: &mut force,
                stiffness: Some(&mut stiffness),
            };
            let status = match path {
                0 => formulation(geo.kind).evaluate(geo, law as &dyn Hyperelastic, u, &mut out),
                1 => match geo.kind {
                    ElementKind::Cpe4h => {
                        MeanDilatationElement::evaluate_with(geo, &neo_hookean, u, &mut out)
                    }
                    _ => DisplacementElement::evaluate_with(geo, &neo_hookean, u, &mut out),
                },
                _ => law.evaluate_element(geo, u, &mut out),
            };
            let bits = |v: &[f64]| v.iter().map(|x| x.to_bits()).collect::<Vec<u64>>();
            let energy = out.energy.to_bits();
            (
                status.map_err(|e| e.0.to_bits()),
                energy,
                bits(&force),
                bits(&stiffness),
            )
        };
        let mut laws: Vec<Box<dyn Material>> = vec![Box::new(neo_hookean)];
        for entry in LAWS {
            let typical: Vec<f64> = entry.spec.parameters.iter().map(|p| p.typical).collect();
            laws.push(entry.build(&typical).unwrap());
        }
        for (l, law) in laws.iter().enumerate() {
            for (kind, x) in [
                (ElementKind::Cpe4, quad),
                (ElementKind::Cpe4h, quad),
                (ElementKind::Cpe3, tri),
            ] {
                let geo = ElementGeometry::new(kind, &x).unwrap();
                let n = geo.n_nodes;
                let mut inverted = 0;
                for trial in 0..200 {
                    // Up to 1.5 times the element size: the larger ones invert it.
                    let scale = 1.5 * f64::from(trial) / 200.0;
                    let u: Vec<[f64; 2]> = (0..n)
                        .map(|_| {
                            [
                                scale * rng.gen_range(-1.0..1.0),
                                scale * rng.gen_range(-1.0..1.0),
                            ]
                        })
                        .collect();
                    let name = law.spec().name;
                    let reference = evaluate(0, &**law, &geo, &u);
                    inverted += usize::from(reference.0.is_err());
                    if l == 0 {
                        let generic = evaluate(1, &**law, &geo, &u);
                        assert_eq!(generic, reference, "{name} {kind:?}, trial {trial}");
                    }
                    let fast = evaluate(2, &**law, &geo, &u);
                    assert_eq!(fast, reference, "{name} {kind:?}, trial {trial}");
                }
                assert!(
                    (1..100).contains(&inverted),
                    "{kind:?}: {inverted} inverted"
                );
            }
        }
    }

    #[test]
    fn inverted_reference_element_is_reported() {
        let x = [[0.0, 0.0], [0.0, 1.0], [1.0, 1.0], [1.0, 0.0]];
        assert!(ElementGeometry::new(ElementKind::Cpe4, &x).is_err());
    }
}
