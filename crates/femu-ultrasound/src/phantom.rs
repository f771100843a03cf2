//! The digital phantom: random point scatterers in the reference configuration of a mesh,
//! and their positions once the tissue has moved.
//!
//! A B-mode image is the echo of sub-resolution scatterers (cell nuclei, fibres, collagen).
//! Each tissue gets scatterers at random positions (uniform, its own density) with zero-mean
//! Gaussian amplitudes (variance set by the tissue's backscatter level, see
//! [`crate::render`](mod@crate::render)); interfaces get line scatterers along the mesh faces between regions
//! (fascia), along the skin and along the bone surface. A deformed image moves the **same**
//! scatterers by the FE displacement interpolated at their reference position with the
//! mesh's isoparametric map (`femu_mesh::locate`), so a pair of images has a known
//! displacement and the speckle decorrelates the way it does in tissue (the interference
//! pattern changes as the scatterers move relative to each other and to the beam).

use crate::error::UsError;
use crate::probe::Probe;
use crate::tissue::Acoustics;
use femu_mesh::locate::PointLocator;
use femu_mesh::Mesh;
use rand::{Rng, SeedableRng};
use rand_distr::StandardNormal;
use rayon::prelude::*;
use std::collections::HashMap;

/// What a scatterer belongs to.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum ScattererKind {
    /// Diffuse scatterer of tissue `k` (index into [`Acoustics::tissues`]).
    Tissue(usize),
    /// Point of a specular interface with unit normal `normal` and level `echo_db`.
    Line { normal: [f64; 2], echo_db: f64 },
}

/// One scatterer.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Scatterer {
    /// Reference position (model frame, mm).
    pub x: [f64; 2],
    /// Standard normal amplitude (scaled at rendering by the tissue level).
    pub z: f64,
    pub kind: ScattererKind,
    /// Fixed with the bone (not moved by the displacement field).
    pub on_bone: bool,
}

/// A phantom: the reference mesh, its acoustics, the bone outline and the scatterers.
#[derive(Debug, Clone)]
pub struct Phantom {
    pub mesh: Mesh,
    pub acoustics: Acoustics,
    /// Tissue index of each element.
    pub tissue_of_element: Vec<usize>,
    /// Bone outline segments (model frame, mm): the bone is a rigid hole of the mesh.
    pub bone: Vec<[[f64; 2]; 2]>,
    pub scatterers: Vec<Scatterer>,
}

/// Where the phantom is at one instant: the mesh with moved nodes and the scatterer positions.
#[derive(Debug, Clone)]
pub struct PhantomState {
    /// The mesh in the current configuration.
    pub mesh: Mesh,
    /// Current scatterer positions (mm), one per [`Phantom::scatterers`].
    pub positions: Vec<[f64; 2]>,
}

impl Phantom {
    /// Scatterers over the probe's field of view plus `margin_mm` on every side (so that
    /// tissue entering the view when it moves, and echoes from just outside, are there).
    /// `bone_faces` are the `(element, face)` pairs of the bone outline (the `FEMUR` surface of
    /// the built-in thigh), possibly empty. Seeded: the same seed gives the same phantom.
    pub fn generate(
        mesh: &Mesh,
        bone_faces: &[(usize, usize)],
        acoustics: &Acoustics,
        probe: &Probe,
        margin_mm: f64,
        seed: u64,
    ) -> Result<Phantom, UsError> {
        acoustics.validate()?;
        if !(0.0..=100.0).contains(&margin_mm) {
            return Err(UsError::param(
                "margin_mm",
                format!("{margin_mm} is outside [0, 100]"),
            ));
        }
        if mesh.elements.is_empty() {
            return Err(UsError::Geometry("the mesh has no element".into()));
        }
        for &(e, f) in bone_faces {
            if e >= mesh.elements.len() || f >= mesh.elements[e].face_count() {
                return Err(UsError::Geometry(format!(
                    "bone face ({e}, {f}) is not a face of the mesh"
                )));
            }
        }
        let tissue_of_element = acoustics.tissue_of_elements(mesh);
        let locator = PointLocator::new(mesh);
        let mut rng = rand::rngs::StdRng::seed_from_u64(seed);
        // Diffuse scatterers: uniform at the largest density, thinned per tissue.
        let rho_max = acoustics
            .tissues
            .iter()
            .chain(std::iter::once(&acoustics.default_tissue))
            .map(|t| t.density_per_mm2)
            .fold(0.0, f64::max);
        let lo = [-0.5 * probe.width_mm - margin_mm, -margin_mm];
        let hi = [0.5 * probe.width_mm + margin_mm, probe.depth_mm + margin_mm];
        let area = (hi[0] - lo[0]) * (hi[1] - lo[1]);
        let n = (rho_max * area).round() as usize;
        if n > 50_000_000 {
            return Err(UsError::param(
                "scatterers",
                format!("{n} scatterers: the field of view is too large for the densities"),
            ));
        }
        let draws: Vec<([f64; 2], f64, f64)> = (0..n)
            .map(|_| {
                let q = [rng.gen_range(lo[0]..hi[0]), rng.gen_range(lo[1]..hi[1])];
                (
                    probe.probe_to_model(q),
                    rng.gen::<f64>(),
                    rng.sample(StandardNormal),
                )
            })
            .collect();
        let mut scatterers: Vec<Scatterer> = draws
            .par_iter()
            .filter_map(|&(x, accept, z)| {
                let loc = locator.locate(x)?;
                let k = tissue_of_element[loc.element];
                (accept * rho_max < acoustics.tissue(k).density_per_mm2).then_some(Scatterer {
                    x,
                    z,
                    kind: ScattererKind::Tissue(k),
                    on_bone: false,
                })
            })
            .collect();
        // Faces: interfaces between tissues, skin, bone.
        let bone_set: std::collections::HashSet<(usize, usize)> =
            bone_faces.iter().copied().collect();
        let mut faces: HashMap<(usize, usize), Vec<(usize, usize)>> = HashMap::new();
        for (e, el) in mesh.elements.iter().enumerate() {
            for f in 0..el.face_count() {
                let [a, b] = el.face_nodes(f);
                faces.entry((a.min(b), a.max(b))).or_default().push((e, f));
            }
        }
        let in_view = |p: [f64; 2]| {
            let q = probe.model_to_probe(p);
            q[0] >= lo[0] && q[0] <= hi[0] && q[1] >= lo[1] && q[1] <= hi[1]
        };
        let mut keys: Vec<_> = faces.keys().copied().collect();
        keys.sort_unstable();
        let mut bone = Vec::new();
        for key in keys {
            let owners = &faces[&key];
            let (e, f) = owners[0];
            let [a, b] = mesh.elements[e].face_nodes(f);
            let (pa, pb) = (mesh.nodes[a], mesh.nodes[b]);
            let is_bone = owners.len() == 1 && bone_set.contains(&(e, f));
            if is_bone {
                bone.push([pa, pb]);
            }
            let echo = if is_bone {
                Some(acoustics.bone_echo_db)
            } else if owners.len() == 1 {
                acoustics.skin_echo_db
            } else if owners
                .iter()
                .any(|&(o, _)| tissue_of_element[o] != tissue_of_element[e])
            {
                acoustics.fascia_echo_db
            } else {
                None
            };
            let Some(echo_db) = echo else { continue };
            if !(in_view(pa) || in_view(pb)) {
                continue;
            }
            let d = [pb[0] - pa[0], pb[1] - pa[1]];
            let len = d[0].hypot(d[1]);
            if !(len > 0.0) {
                continue;
            }
            let normal = [d[1] / len, -d[0] / len];
            let expected = acoustics.line_density_per_mm * len;
            let mut m = expected.floor() as usize;
            if rng.gen::<f64>() < expected - m as f64 {
                m += 1;
            }
            for _ in 0..m {
                let s: f64 = rng.gen();
                scatterers.push(Scatterer {
                    x: [pa[0] + s * d[0], pa[1] + s * d[1]],
                    z: rng.sample(StandardNormal),
                    kind: ScattererKind::Line { normal, echo_db },
                    on_bone: is_bone,
                });
            }
        }
        if scatterers.is_empty() {
            return Err(UsError::Geometry(format!(
                "the probe at {:?} mm looking along {:?} sees no tissue of the mesh",
                probe.centre_mm, probe.direction
            )));
        }
        Ok(Phantom {
            mesh: mesh.clone(),
            acoustics: acoustics.clone(),
            tissue_of_element,
            bone,
            scatterers,
        })
    }

    /// The reference configuration.
    pub fn reference(&self) -> PhantomState {
        PhantomState {
            mesh: self.mesh.clone(),
            positions: self.scatterers.iter().map(|s| s.x).collect(),
        }
    }

    /// The configuration displaced by a nodal field `u = [ux0, uy0, ux1, ...]` (mm): each
    /// scatterer moves by `u` interpolated at its reference position (shape functions of the
    /// element holding it); bone scatterers stay (the bone is rigid and fixed).
    pub fn displaced(&self, u: &[f64]) -> Result<PhantomState, UsError> {
        if u.len() != 2 * self.mesh.nodes.len() {
            return Err(UsError::param(
                "displacement",
                format!(
                    "{} values for a mesh of {} nodes (2 per node expected)",
                    u.len(),
                    self.mesh.nodes.len()
                ),
            ));
        }
        if let Some(k) = u.iter().position(|v| !v.is_finite()) {
            return Err(UsError::param(
                "displacement",
                format!("node {} has a non-finite displacement", k / 2),
            ));
        }
        let locator = PointLocator::new(&self.mesh);
        let positions = self
            .scatterers
            .par_iter()
            .map(|s| {
                if s.on_bone {
                    return s.x;
                }
                match locator.locate(s.x) {
                    Some(loc) => [
                        s.x[0] + loc.interpolate(u, 2, 0),
                        s.x[1] + loc.interpolate(u, 2, 1),
                    ],
                    // A line scatterer a rounding error outside the outline: nearest node.
                    None => {
                        let n = nearest_node(&self.mesh, s.x);
                        [s.x[0] + u[2 * n], s.x[1] + u[2 * n + 1]]
                    }
                }
            })
            .collect();
        let mut mesh = self.mesh.clone();
        for (k, p) in mesh.nodes.iter_mut().enumerate() {
            p[0] += u[2 * k];
            p[1] += u[2 * k + 1];
        }
        Ok(PhantomState { mesh, positions })
    }

    /// The configuration moved by an analytic field `x ↦ u(x)` (mm), applied to the
    /// scatterers and to the mesh nodes alike (verification with known fields).
    pub fn moved_by(&self, f: &(dyn Fn([f64; 2]) -> [f64; 2] + Sync)) -> PhantomState {
        let mv = |x: [f64; 2]| {
            let u = f(x);
            [x[0] + u[0], x[1] + u[1]]
        };
        let mut mesh = self.mesh.clone();
        for p in mesh.nodes.iter_mut() {
            *p = mv(*p);
        }
        PhantomState {
            mesh,
            positions: self
                .scatterers
                .par_iter()
                .map(|s| if s.on_bone { s.x } else { mv(s.x) })
                .collect(),
        }
    }

    /// The same tissue with a fraction of its scatterers renewed: each scatterer, with
    /// probability `fraction`, gets a new amplitude (standard normal), the others keep theirs.
    /// Out-of-plane motion under load (the slice is thin: the tissue bulges out of it as it is
    /// compressed) carries scatterers out of the imaged plane and others in; between two load
    /// steps that renew a fraction `q`, the complex echo of a resolution cell keeps a
    /// correlation `1 − q`. Seeded.
    pub fn renewed(&self, fraction: f64, seed: u64) -> Result<Phantom, UsError> {
        if !(0.0..=1.0).contains(&fraction) {
            return Err(UsError::param(
                "decorrelation",
                format!("{fraction} is outside [0, 1]"),
            ));
        }
        let mut out = self.clone();
        if fraction == 0.0 {
            return Ok(out);
        }
        let mut rng = rand::rngs::StdRng::seed_from_u64(seed);
        for s in out.scatterers.iter_mut() {
            let renew = rng.gen::<f64>() < fraction;
            let z: f64 = rng.sample(StandardNormal);
            if renew {
                s.z = z;
            }
        }
        Ok(out)
    }

    /// A new acquisition of the same tissue with partially renewed amplitudes:
    /// `z' = ρ z + √(1 − ρ²) ζ`, `ζ` standard normal. Out-of-plane motion between repeated
    /// acquisitions (breathing, the probe's hold on the skin) replaces part of the scatterers
    /// in the thin imaged slice, so successive frames of unloaded tissue are not identical:
    /// the speckle correlation between them is `ρ`.
    pub fn decorrelated(&self, rho: f64, seed: u64) -> Result<Phantom, UsError> {
        if !(0.0..=1.0).contains(&rho) {
            return Err(UsError::param(
                "correlation",
                format!("{rho} is outside [0, 1]"),
            ));
        }
        let mut rng = rand::rngs::StdRng::seed_from_u64(seed);
        let c = (1.0 - rho * rho).sqrt();
        let mut out = self.clone();
        for s in out.scatterers.iter_mut() {
            let zeta: f64 = rng.sample(StandardNormal);
            s.z = rho * s.z + c * zeta;
        }
        Ok(out)
    }
}

fn nearest_node(mesh: &Mesh, x: [f64; 2]) -> usize {
    let mut best = (f64::INFINITY, 0);
    for (k, p) in mesh.nodes.iter().enumerate() {
        let d = (p[0] - x[0]).powi(2) + (p[1] - x[1]).powi(2);
        if d < best.0 {
            best = (d, k);
        }
    }
    best.1
}
