//! Frictionless contact of the skin with rigid bodies: a flat plate and a cylindrical indenter
//! (seed §2.1.2.3, Fig. 3.B–C).
//!
//! Node-to-rigid-surface contact with an augmented-Lagrangian penalty. For a skin node at current
//! position `x` and a body translated by `t` along its direction of travel `d`, the gap `g(x, t)`
//! is negative when the node penetrates. Each node stores the energy
//!
//! ```text
//! ψ(g) = ⟨λ̂ - ε g⟩₊² / (2 ε),        λ = ⟨λ̂ - ε g⟩₊  (contact force, ≥ 0)
//! ∂ψ/∂q = -λ ∂g/∂q,                   ∂²ψ/∂q² = ε ∂g ∂gᵀ - λ ∂²g      (q = (x, t))
//! ```
//!
//! with the penalty ε and the multiplier estimate λ̂ (Uzawa updates `λ̂ ← λ` until the
//! penetration is below both `penetration_tolerance` of the element size and the gap at which
//! the penalty's force is the Newton residual tolerance; see `solver::contact_state`). Under
//! force control the travel `t` is an
//! unknown of the Newton system, with the equation `∂/∂t (Σ ψ) - F = 0`: the contact force on
//! the body along `d` equals the applied force `F`. The whole system derives from the potential
//! `Π_int + Σ ψ - F t` (plus the loads), so the bordered tangent stays symmetric.

use std::sync::Arc;

/// Gap of a point and its derivatives with respect to the point `x` and the travel `t`.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct Gap {
    pub g: f64,
    pub dg_dx: [f64; 2],
    pub dg_dt: f64,
    pub d2g_dxdx: [[f64; 2]; 2],
    pub d2g_dxdt: [f64; 2],
    pub d2g_dtdt: f64,
}

/// A rigid surface translated by `t` along its direction of travel.
pub trait RigidSurface: Send + Sync + std::fmt::Debug {
    /// Gap of the point `x` with the body at travel `t` (negative inside the body).
    fn gap(&self, x: [f64; 2], t: f64) -> Gap;
    /// The smallest travel at which the point touches the body, if it ever does.
    fn contact_travel(&self, x: [f64; 2]) -> Option<f64>;
    /// Direction of travel (unit).
    fn direction(&self) -> [f64; 2];
    /// Short description for reports.
    fn describe(&self) -> String;
    /// Points outlining the body at travel `t` (for pictures), in mm.
    fn outline(&self, t: f64, half_length: f64) -> Vec<[f64; 2]>;
}

fn unit(v: [f64; 2]) -> Option<[f64; 2]> {
    let n = v[0].hypot(v[1]);
    (n > 0.0 && n.is_finite()).then(|| [v[0] / n, v[1] / n])
}

fn dot(a: [f64; 2], b: [f64; 2]) -> f64 {
    a[0] * b[0] + a[1] * b[1]
}

/// A flat rigid plate: the line through `point` with unit `normal` pointing from the plate
/// towards the tissue, moving along `direction`. `g = (x - p - t d)·n`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RigidPlate {
    pub point: [f64; 2],
    pub normal: [f64; 2],
    pub direction: [f64; 2],
}

impl RigidPlate {
    /// A plate at `point` facing the tissue along `normal`, moving along `normal` (pressing).
    pub fn new(point: [f64; 2], normal: [f64; 2]) -> Result<Self, ContactError> {
        let n = unit(normal).ok_or(ContactError::BadDirection)?;
        Ok(RigidPlate {
            point,
            normal: n,
            direction: n,
        })
    }
}

impl RigidSurface for RigidPlate {
    fn gap(&self, x: [f64; 2], t: f64) -> Gap {
        let p = [
            self.point[0] + t * self.direction[0],
            self.point[1] + t * self.direction[1],
        ];
        Gap {
            g: dot([x[0] - p[0], x[1] - p[1]], self.normal),
            dg_dx: self.normal,
            dg_dt: -dot(self.direction, self.normal),
            ..Default::default()
        }
    }

    fn contact_travel(&self, x: [f64; 2]) -> Option<f64> {
        let dn = dot(self.direction, self.normal);
        (dn > 0.0).then(|| dot([x[0] - self.point[0], x[1] - self.point[1]], self.normal) / dn)
    }

    fn direction(&self) -> [f64; 2] {
        self.direction
    }

    fn describe(&self) -> String {
        format!(
            "rigid plate through ({:.3}, {:.3}) mm, normal ({:.3}, {:.3})",
            self.point[0], self.point[1], self.normal[0], self.normal[1]
        )
    }

    fn outline(&self, t: f64, half_length: f64) -> Vec<[f64; 2]> {
        let p = [
            self.point[0] + t * self.direction[0],
            self.point[1] + t * self.direction[1],
        ];
        let s = [-self.normal[1], self.normal[0]];
        vec![
            [p[0] - half_length * s[0], p[1] - half_length * s[1]],
            [p[0] + half_length * s[0], p[1] + half_length * s[1]],
        ]
    }
}

/// A rigid cylindrical indenter: circle of `radius` about `center`, moving along `direction`.
/// `g = |x - c - t d| - R`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RigidCylinder {
    pub center: [f64; 2],
    pub radius: f64,
    pub direction: [f64; 2],
}

impl RigidCylinder {
    /// An indenter of `radius` (mm) at `center`, moving along `direction`.
    pub fn new(center: [f64; 2], radius: f64, direction: [f64; 2]) -> Result<Self, ContactError> {
        if !(radius > 0.0 && radius.is_finite()) {
            return Err(ContactError::BadRadius(radius));
        }
        let d = unit(direction).ok_or(ContactError::BadDirection)?;
        Ok(RigidCylinder {
            center,
            radius,
            direction: d,
        })
    }
}

impl RigidSurface for RigidCylinder {
    fn gap(&self, x: [f64; 2], t: f64) -> Gap {
        let d = self.direction;
        let v = [
            x[0] - self.center[0] - t * d[0],
            x[1] - self.center[1] - t * d[1],
        ];
        let r = v[0].hypot(v[1]).max(1e-300);
        let m = [v[0] / r, v[1] / r];
        // P = (I - m mᵀ) / r
        let p = [
            [(1.0 - m[0] * m[0]) / r, -m[0] * m[1] / r],
            [-m[1] * m[0] / r, (1.0 - m[1] * m[1]) / r],
        ];
        let pd = [
            p[0][0] * d[0] + p[0][1] * d[1],
            p[1][0] * d[0] + p[1][1] * d[1],
        ];
        Gap {
            g: r - self.radius,
            dg_dx: m,
            dg_dt: -dot(m, d),
            d2g_dxdx: p,
            d2g_dxdt: [-pd[0], -pd[1]],
            d2g_dtdt: dot(d, pd),
        }
    }

    fn contact_travel(&self, x: [f64; 2]) -> Option<f64> {
        // |w - t d| = R with w = x - c: t² - 2 t (w·d) + |w|² - R² = 0, smallest root.
        let w = [x[0] - self.center[0], x[1] - self.center[1]];
        let b = dot(w, self.direction);
        let disc = b * b - (dot(w, w) - self.radius * self.radius);
        (disc >= 0.0).then(|| b - disc.sqrt())
    }

    fn direction(&self) -> [f64; 2] {
        self.direction
    }

    fn describe(&self) -> String {
        format!(
            "rigid cylinder of radius {:.3} mm at ({:.3}, {:.3}) mm, moving along ({:.3}, {:.3})",
            self.radius, self.center[0], self.center[1], self.direction[0], self.direction[1]
        )
    }

    fn outline(&self, t: f64, _half_length: f64) -> Vec<[f64; 2]> {
        let c = [
            self.center[0] + t * self.direction[0],
            self.center[1] + t * self.direction[1],
        ];
        (0..=72)
            .map(|k| {
                let a = std::f64::consts::TAU * k as f64 / 72.0;
                [c[0] + self.radius * a.cos(), c[1] + self.radius * a.sin()]
            })
            .collect()
    }
}

/// How the body's travel is driven.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum TravelControl {
    /// The body is pushed with this force along its direction of travel (N per mm of
    /// thickness); its travel is an unknown.
    Force(f64),
    /// The body travels this far beyond first contact (mm).
    Displacement(f64),
}

/// Problems with a rigid body, found before any solve.
#[derive(Debug, Clone, thiserror::Error, PartialEq)]
pub enum ContactError {
    #[error("the direction of travel or the normal is zero or not finite")]
    BadDirection,
    #[error("the indenter radius must be positive, got {0} mm")]
    BadRadius(f64),
    #[error(
        "the rigid body ({0}) can never touch the contact surface along its direction of travel"
    )]
    NeverTouches(String),
    #[error("the applied force must push the body towards the tissue (positive), got {0} N/mm")]
    WrongForceSign(f64),
    #[error(
        "the rigid body ({body}) starts inside the tissue: node {node} is {depth:.3e} mm inside it"
    )]
    StartsInside { body: String, node: i64, depth: f64 },
    #[error("the rigid body ({0}) starts inside the tissue: its centre lies in the mesh")]
    CentreInside(String),
    #[error("the contact surface is empty")]
    EmptySurface,
    #[error("the contact surface includes face {face} of element {element}, which does not exist")]
    BadFace { element: usize, face: usize },
}

/// A rigid body in frictionless contact with a surface of the mesh.
#[derive(Debug, Clone)]
pub struct RigidContact {
    pub name: String,
    pub body: Arc<dyn RigidSurface>,
    /// Candidate nodes (the nodes of the contact surface).
    pub nodes: Vec<usize>,
    /// Tributary length of each candidate node on the surface (reference, mm), for pressures.
    pub tributary: Vec<f64>,
    /// Mean reference length of the surface's faces (mm).
    pub element_size: f64,
    /// Travel at first contact: the body starts there (load factor 0).
    pub first_contact: f64,
    pub control: TravelControl,
    /// Penalty ε as a multiple of the largest diagonal stiffness of the candidate dofs
    /// (default 10: stiff enough that few Uzawa updates are needed, soft enough that Newton's
    /// first iterations, when contact spreads from one node, stay well conditioned).
    pub penalty_factor: f64,
    /// Allowed penetration at convergence as a fraction of `element_size` (an upper bound: the
    /// solver also converges the multipliers until another Uzawa update would change the
    /// contact forces by less than its residual tolerance, which is far tighter by default).
    pub penetration_tolerance: f64,
}

impl RigidContact {
    /// A rigid body against the faces `surface` (`(element, face)`, 0-based) of `mesh`.
    /// Checks that the body can touch, does not start inside the tissue, and that a force
    /// pushes towards the tissue; places the body at first contact.
    pub fn new(
        name: &str,
        mesh: &femu_mesh::Mesh,
        surface: &[(usize, usize)],
        body: Arc<dyn RigidSurface>,
        control: TravelControl,
    ) -> Result<Self, ContactError> {
        if surface.is_empty() {
            return Err(ContactError::EmptySurface);
        }
        if let TravelControl::Force(f) = control {
            if !(f > 0.0 && f.is_finite()) {
                return Err(ContactError::WrongForceSign(f));
            }
        }
        let mut trib = std::collections::BTreeMap::<usize, f64>::new();
        let mut total = 0.0;
        for &(e, f) in surface {
            let el = mesh.elements.get(e).ok_or(ContactError::BadFace {
                element: e,
                face: f,
            })?;
            if f >= el.face_count() {
                return Err(ContactError::BadFace {
                    element: e,
                    face: f,
                });
            }
            let [a, b] = el.face_nodes(f);
            let (xa, xb) = (mesh.nodes[a], mesh.nodes[b]);
            let len = (xb[0] - xa[0]).hypot(xb[1] - xa[1]);
            total += len;
            *trib.entry(a).or_default() += 0.5 * len;
            *trib.entry(b).or_default() += 0.5 * len;
        }
        let nodes: Vec<usize> = trib.keys().copied().collect();
        let tributary: Vec<f64> = trib.values().copied().collect();
        for &n in trib.keys() {
            let g = body.gap(mesh.nodes[n], 0.0).g;
            if g < 0.0 {
                return Err(ContactError::StartsInside {
                    body: body.describe(),
                    node: mesh.node_labels[n],
                    depth: -g,
                });
            }
        }
        let first = nodes
            .iter()
            .filter_map(|&n| body.contact_travel(mesh.nodes[n]))
            .fold(f64::INFINITY, f64::min);
        if !first.is_finite() {
            return Err(ContactError::NeverTouches(body.describe()));
        }
        Ok(RigidContact {
            name: name.to_string(),
            body,
            nodes,
            tributary,
            element_size: total / surface.len() as f64,
            first_contact: first,
            control,
            penalty_factor: 1e1,
            penetration_tolerance: 1e-3,
        })
    }

    /// Errors if the point `centre` (e.g. an indenter's centre) lies inside an element.
    pub fn check_centre_outside(
        &self,
        mesh: &femu_mesh::Mesh,
        centre: [f64; 2],
    ) -> Result<(), ContactError> {
        let inside = mesh.elements.iter().any(|el| {
            let n = el.kind.node_count();
            (0..n).all(|k| {
                let p = mesh.nodes[el.conn[k]];
                let q = mesh.nodes[el.conn[(k + 1) % n]];
                (q[0] - p[0]) * (centre[1] - p[1]) - (q[1] - p[1]) * (centre[0] - p[0]) >= 0.0
            })
        });
        if inside {
            return Err(ContactError::CentreInside(self.body.describe()));
        }
        Ok(())
    }
}

/// Contact results of one body at a converged state.
#[derive(Debug, Clone, Default, serde::Serialize, serde::Deserialize)]
pub struct BodyState {
    pub name: String,
    /// Travel beyond first contact (mm).
    pub travel: f64,
    /// Contact force on the body along its direction of travel (N per mm).
    pub force: f64,
    /// Largest penetration of a node into the body (mm, ≥ 0).
    pub max_penetration: f64,
    /// The allowed penetration (mm): the smaller of the penetration tolerance and the gap at
    /// which the penalty's force is the residual tolerance.
    pub penetration_limit: f64,
    pub active_nodes: usize,
    /// Penalty ε used (N/mm per node).
    pub penalty: f64,
    /// Augmented-Lagrangian (Uzawa) updates made.
    pub augmentations: usize,
    /// Contact force of each candidate node (N per mm), same order as `RigidContact::nodes`.
    pub node_forces: Vec<f64>,
    /// Gap of each candidate node (mm).
    pub node_gaps: Vec<f64>,
}

#[cfg(test)]
mod tests {
    use super::*;

    fn check_gap_derivatives(body: &dyn RigidSurface, x: [f64; 2], t: f64) {
        let g0 = body.gap(x, t);
        let h = 1e-6;
        for k in 0..2 {
            let mut xp = x;
            let mut xm = x;
            xp[k] += h;
            xm[k] -= h;
            let (gp, gm) = (body.gap(xp, t), body.gap(xm, t));
            assert!(((gp.g - gm.g) / (2.0 * h) - g0.dg_dx[k]).abs() < 1e-8);
            for j in 0..2 {
                assert!(((gp.dg_dx[j] - gm.dg_dx[j]) / (2.0 * h) - g0.d2g_dxdx[j][k]).abs() < 1e-7);
            }
            assert!(((gp.dg_dt - gm.dg_dt) / (2.0 * h) - g0.d2g_dxdt[k]).abs() < 1e-7);
        }
        let (gp, gm) = (body.gap(x, t + h), body.gap(x, t - h));
        assert!(((gp.g - gm.g) / (2.0 * h) - g0.dg_dt).abs() < 1e-8);
        assert!(((gp.dg_dt - gm.dg_dt) / (2.0 * h) - g0.d2g_dtdt).abs() < 1e-7);
        for j in 0..2 {
            assert!(((gp.dg_dx[j] - gm.dg_dx[j]) / (2.0 * h) - g0.d2g_dxdt[j]).abs() < 1e-7);
        }
    }

    #[test]
    fn gap_derivatives_match_finite_differences() {
        let plate = RigidPlate::new([0.0, 10.0], [0.3, -1.0]).unwrap();
        check_gap_derivatives(&plate, [1.0, 2.0], 0.4);
        let cyl = RigidCylinder::new([0.0, 10.0], 4.0, [0.2, -1.0]).unwrap();
        check_gap_derivatives(&cyl, [1.0, 5.5], 0.7);
        check_gap_derivatives(&cyl, [-2.0, 3.0], -0.3);
    }

    #[test]
    fn first_contact_travel() {
        let plate = RigidPlate::new([0.0, 10.0], [0.0, -1.0]).unwrap();
        assert_eq!(plate.contact_travel([3.0, 7.0]), Some(3.0));
        let cyl = RigidCylinder::new([0.0, 10.0], 2.0, [0.0, -1.0]).unwrap();
        assert!((cyl.contact_travel([0.0, 5.0]).unwrap() - 3.0).abs() < 1e-12);
        assert_eq!(cyl.contact_travel([5.0, 5.0]), None);
    }
}
