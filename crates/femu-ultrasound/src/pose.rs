//! The pose of a B-mode image in the model, refined from the unloaded frame: the model's skin
//! and tissue interfaces matched to the bright lines of the image by a rigid 2D transform.
//!
//! **Pose.** An image is placed in the model by the model point of pixel `(0, 0)` (`o`), the
//! unit vectors of its columns and rows in the model (`a`, `b`, orthonormal, either
//! handedness) and its pixel size `s` (mm): pixel `(u, v)` (centres at integer coordinates)
//! images `X = o + s (u a + v b)` ([`ImagePose`]). A correction `p = (t_x, t_y, θ)` moves the
//! image rigidly about a pivot pixel `P` (by default the centre of the probe face, the middle
//! of the top edge, about which the probe tilts): `t_x` along `a` (along the skin), `t_y`
//! along `b` (depth), both in mm, and the axes turn by `θ` in the image's own sense (from `a`
//! towards `b`):
//!
//! ```text
//!   a' = cos θ a + sin θ b,   b' = −sin θ a + cos θ b,   X'(P) = X(P) + t_x a + t_y b     (1)
//! ```
//!
//! A model point `X` is then at the pixel `u = P_u + ξ/s`, `v = P_v + η/s` with
//! `ξ = (X − X'(P))·a'`, `η = (X − X'(P))·b'`; with `ξ₀ = (X − X(P))·a`, `η₀ = (X − X(P))·b`,
//!
//! ```text
//!   ξ = (ξ₀ − t_x) cos θ + (η₀ − t_y) sin θ,   η = −(ξ₀ − t_x) sin θ + (η₀ − t_y) cos θ     (2)
//! ```
//!
//! whose first and second derivatives in `p` are closed-form (`∂ξ/∂θ = η`, `∂η/∂θ = −ξ`).
//!
//! **Response.** Interfaces are thin bright lines (specular echoes: skin, fascia, bone
//! surface) over speckle. The response image is the scale-normalized negative Laplacian of
//! the frame smoothed by a Gaussian of standard deviation `σ` (a ridge detector: positive on
//! a bright line of width below `σ`, zero mean over a uniform texture; Lindeberg, "Edge and
//! ridge detection with automatic scale selection", IJCV 30, 1998),
//!
//! ```text
//!   R_σ = −σ² ∇²(G_σ ∗ I) / ŝ                                                            (3)
//! ```
//!
//! with `ŝ` the robust spread of `−σ² ∇²(G_σ ∗ I)` over the image (1.4826 × median absolute
//! deviation), so that `R` is in units of its own spread over the frame. Unlike the smoothed
//! intensity itself, whose maximum near a line is pulled towards the brighter side of a step
//! (fat is darker than muscle) by about `Bσ/A` (step height `B`, line area `A`), the ridge
//! response's peak moves by `Bσ²/(3A)` only, which vanishes as `σ` shrinks. `R` is
//! interpolated by the cubic B-spline of `femu_dic::bspline` (C², exact derivatives).
//!
//! **Objective.** The outlines are sampled at points `X_k` (spacing 0.5 px) with weights
//! `w_k` (length × the outline kind's weight × the specular reflection's fall-off with
//! incidence, `0.1 + 0.9 cos⁴ φ`, `φ` the angle between the outline's normal and the beam:
//! a fascia along the beam reflects little back to the probe); only points inside the image
//! count. The pose maximizes the weighted mean response
//!
//! ```text
//!   f(p) = Σ_k w_k R_σ(u_k(p), v_k(p)) / Σ_k w_k                                           (4)
//! ```
//!
//! by Newton's method with a Levenberg–Marquardt damping (exact gradient and Hessian of (4)
//! through (2) and the spline; a step is kept only if `f` grows), coarse to fine over `σ`
//! (default 1.0, 0.5, 0.25, 0.15, 0.1 mm), after a grid search of (4) at the coarsest scale
//! about the initial pose (±3 mm, ±2 mm, ±6° in half-scale steps) that captures a start
//! 1.5 mm and 3° away. The finest scales matter: on the default anterior window the skin and
//! fascia are nearly concentric arcs about the thigh's centre, so a turn about that centre is
//! seen only through the bone's cap at the bottom of the window and the shape of the arcs;
//! the ridge bias `Bσ²/(3A)` of the fat/muscle step then moves the pose along that turn, by
//! about 0.3 mm along the skin with 0.25 mm as the finest scale and 0.06–0.1 mm with 0.1 mm.
//!
//! **Uncertainty.** `p̂` is an M-estimator (it maximizes a sum of per-point terms); its
//! covariance is the sandwich `H⁻¹ V H⁻¹` (Huber 1967; White 1982) with `H` the Hessian of
//! `S = Σ w_k R_σ` at `p̂` and `V` the spread of the score over blocks of outline points
//! (squares of `block_mm` of the image, one outline each), within which the speckle
//! correlates and between which it does not:
//!
//! ```text
//!   V = G/(G − 3) Σ_g s_g s_gᵀ,   s_g = Σ_{k ∈ g} w_k ∇_p R_σ(u_k, v_k)                     (5)
//! ```
//!
//! (as `femu_identify::idic::uncertainty::block_sandwich` does for the identification).
//!
//! **Support.** An outline is found in the image if its mean response at `p̂` is at least
//! `min_response` and `min_z` standard errors above zero (the standard error from its blocks'
//! means). A pose needs `min_outlines` outlines found, each with `min_length_mm` in view;
//! otherwise the refinement is an error naming the outlines in view, their response, and
//! those not in view.

use crate::error::UsError;
use crate::probe::Probe;
use femu_dic::bspline::{weights, weights_derivative, BSpline};
use femu_dic::GreyImage;
use femu_mesh::Mesh;
use std::collections::{BTreeMap, HashMap, HashSet};

/// What an outline is.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize)]
pub enum OutlineKind {
    /// The mesh outline other than the bone.
    Skin,
    /// Faces between elements of two different regions (fascia, septa between muscles).
    Fascia,
    /// The bone surface (a hole of the mesh).
    Bone,
}

/// A named outline of the model: segments in the model frame (mm).
#[derive(Debug, Clone)]
pub struct Outline {
    /// `"skin"`, `"bone surface"` or `"fascia FAT/QUADRICEPS"`.
    pub name: String,
    pub kind: OutlineKind,
    pub segments: Vec<[[f64; 2]; 2]>,
}

/// The outlines of a mesh: the skin (boundary faces not in `bone_faces`), the bone surface
/// (`bone_faces`) and one outline per pair of regions that share faces (`regions` are element
/// set names; an element in none of them belongs to a region `OTHER`).
pub fn model_outlines(
    mesh: &Mesh,
    regions: &[String],
    bone_faces: &[(usize, usize)],
) -> Vec<Outline> {
    let mut region_of = vec![usize::MAX; mesh.elements.len()];
    for (r, name) in regions.iter().enumerate() {
        for &e in mesh.element_set(name).unwrap_or(&[]) {
            if e < region_of.len() && region_of[e] == usize::MAX {
                region_of[e] = r;
            }
        }
    }
    let region_name = |r: usize| -> &str {
        if r == usize::MAX {
            "OTHER"
        } else {
            &regions[r]
        }
    };
    let bone: HashSet<(usize, usize)> = bone_faces.iter().copied().collect();
    let mut owners: BTreeMap<(usize, usize), Vec<(usize, usize)>> = BTreeMap::new();
    for (e, el) in mesh.elements.iter().enumerate() {
        for f in 0..el.face_count() {
            let [a, b] = el.face_nodes(f);
            owners.entry((a.min(b), a.max(b))).or_default().push((e, f));
        }
    }
    let mut skin = Vec::new();
    let mut bone_segments = Vec::new();
    let mut fascia: BTreeMap<(usize, usize), Vec<[[f64; 2]; 2]>> = BTreeMap::new();
    for ((a, b), own) in owners {
        let seg = [mesh.nodes[a], mesh.nodes[b]];
        if own.len() == 1 {
            if bone.contains(&own[0]) {
                bone_segments.push(seg);
            } else {
                skin.push(seg);
            }
        } else {
            let (r0, r1) = (region_of[own[0].0], region_of[own[1].0]);
            if r0 != r1 {
                fascia
                    .entry((r0.min(r1), r0.max(r1)))
                    .or_default()
                    .push(seg);
            }
        }
    }
    let mut out = Vec::new();
    if !skin.is_empty() {
        out.push(Outline {
            name: "skin".into(),
            kind: OutlineKind::Skin,
            segments: skin,
        });
    }
    for ((r0, r1), segments) in fascia {
        out.push(Outline {
            name: format!("fascia {}/{}", region_name(r0), region_name(r1)),
            kind: OutlineKind::Fascia,
            segments,
        });
    }
    if !bone_segments.is_empty() {
        out.push(Outline {
            name: "bone surface".into(),
            kind: OutlineKind::Bone,
            segments: bone_segments,
        });
    }
    out
}

/// The placement of an image in the model (module documentation): pixel `(u, v)` images
/// `origin_mm + pixel_size_mm (u x_axis + v y_axis)`.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct ImagePose {
    /// Model point of the centre of pixel `(0, 0)` (mm).
    pub origin_mm: [f64; 2],
    /// Unit vectors of the image's columns (x) and rows (y) in the model.
    pub x_axis: [f64; 2],
    pub y_axis: [f64; 2],
    pub pixel_size_mm: f64,
}

impl ImagePose {
    /// A pose with its axes normalized; errors if they are not orthogonal (within 1e-6) or
    /// the pixel size is not positive.
    pub fn new(
        origin_mm: [f64; 2],
        x_axis: [f64; 2],
        y_axis: [f64; 2],
        pixel_size_mm: f64,
    ) -> Result<Self, UsError> {
        let (nx, ny) = (x_axis[0].hypot(x_axis[1]), y_axis[0].hypot(y_axis[1]));
        if !(nx > 1e-12 && ny > 1e-12 && nx.is_finite() && ny.is_finite()) {
            return Err(UsError::param("image axes", "zero or non-finite vector"));
        }
        let (a, b) = (
            [x_axis[0] / nx, x_axis[1] / nx],
            [y_axis[0] / ny, y_axis[1] / ny],
        );
        if (a[0] * b[0] + a[1] * b[1]).abs() > 1e-6 {
            return Err(UsError::param(
                "image axes",
                format!("x_axis {x_axis:?} and y_axis {y_axis:?} are not orthogonal"),
            ));
        }
        if !(pixel_size_mm > 0.0 && pixel_size_mm.is_finite()) {
            return Err(UsError::param(
                "pixel_size_mm",
                format!("{pixel_size_mm} must be positive"),
            ));
        }
        if !(origin_mm[0].is_finite() && origin_mm[1].is_finite()) {
            return Err(UsError::param("origin_mm", "must be finite"));
        }
        Ok(ImagePose {
            origin_mm,
            x_axis: a,
            y_axis: b,
            pixel_size_mm,
        })
    }

    /// The pose of a probe's image ([`Probe`]'s pixel convention).
    pub fn from_probe(probe: &Probe) -> Self {
        ImagePose {
            origin_mm: probe.pixel_to_model([0.0, 0.0]),
            x_axis: probe.lateral(),
            y_axis: probe.direction,
            pixel_size_mm: 1.0 / probe.px_per_mm,
        }
    }

    /// The model point of a pixel position.
    pub fn pixel_to_model(&self, p: [f64; 2]) -> [f64; 2] {
        let s = self.pixel_size_mm;
        [
            self.origin_mm[0] + s * (p[0] * self.x_axis[0] + p[1] * self.y_axis[0]),
            self.origin_mm[1] + s * (p[0] * self.x_axis[1] + p[1] * self.y_axis[1]),
        ]
    }

    /// The pixel position of a model point.
    pub fn model_to_pixel(&self, x: [f64; 2]) -> [f64; 2] {
        let d = [x[0] - self.origin_mm[0], x[1] - self.origin_mm[1]];
        [
            dot(d, self.x_axis) / self.pixel_size_mm,
            dot(d, self.y_axis) / self.pixel_size_mm,
        ]
    }

    /// The pose moved by `p = (t_x mm, t_y mm, θ rad)` about the pivot pixel (eq. (1)).
    pub fn moved(&self, pivot_px: [f64; 2], p: [f64; 3]) -> ImagePose {
        let (a, b) = (self.x_axis, self.y_axis);
        let (c, sn) = (p[2].cos(), p[2].sin());
        let a2 = [c * a[0] + sn * b[0], c * a[1] + sn * b[1]];
        let b2 = [-sn * a[0] + c * b[0], -sn * a[1] + c * b[1]];
        let x = self.pixel_to_model(pivot_px);
        let xp = [
            x[0] + p[0] * a[0] + p[1] * b[0],
            x[1] + p[0] * a[1] + p[1] * b[1],
        ];
        let s = self.pixel_size_mm;
        ImagePose {
            origin_mm: [
                xp[0] - s * (pivot_px[0] * a2[0] + pivot_px[1] * b2[0]),
                xp[1] - s * (pivot_px[0] * a2[1] + pivot_px[1] * b2[1]),
            ],
            x_axis: a2,
            y_axis: b2,
            pixel_size_mm: s,
        }
    }

    /// The correction `p` with `reference.moved(pivot_px, p) == self` (same pixel size and
    /// handedness): the pivot's offset along `reference`'s axes (mm) and the turn (rad).
    pub fn offset_from(&self, reference: &ImagePose, pivot_px: [f64; 2]) -> [f64; 3] {
        let x = self.pixel_to_model(pivot_px);
        let x0 = reference.pixel_to_model(pivot_px);
        let d = [x[0] - x0[0], x[1] - x0[1]];
        [
            dot(d, reference.x_axis),
            dot(d, reference.y_axis),
            dot(self.x_axis, reference.y_axis).atan2(dot(self.x_axis, reference.x_axis)),
        ]
    }
}

/// The pivot of a `width`-column image: the middle of its top edge (the probe face's centre
/// in [`Probe`]'s convention), pixel `((width − 1)/2, −1/2)`.
pub fn probe_face_pivot(width: usize) -> [f64; 2] {
    [0.5 * (width as f64 - 1.0), -0.5]
}

/// Outline points this far outside the image at the start of a scale are kept: they count
/// if the pose brings them in (mm).
const POOL_MM: f64 = 8.0;

/// Options of [`refine_pose`].
#[derive(Debug, Clone)]
pub struct PoseOptions {
    /// Half-widths of the grid searched at the coarsest scale about the initial pose:
    /// `t_x` (mm), `t_y` (mm), `θ` (degrees); a zero skips that parameter.
    pub search: [f64; 3],
    /// Smoothing scales `σ` (mm), coarse to fine (eq. (3)).
    pub scales_mm: Vec<f64>,
    /// Weight of the bone surface relative to the skin and fascia (per unit length). Default
    /// 4: the bone surface is included, weighted up, because on an anterior window it is the
    /// one outline not concentric with the skin and fascia and so pins the turn about the
    /// thigh's centre (without it the predicted sd along the skin is about 4 mm on the default
    /// window, with weight 1 about 0.4 mm, with 4 about 0.1–0.2 mm); it is also the brightest
    /// line, and the grey scale's ceiling (log compression) keeps it from swamping the others.
    pub bone_weight: f64,
    /// Weight of the skin relative to the fascia.
    pub skin_weight: f64,
    /// Side of the blocks of the sandwich (5) and of the support test (mm).
    pub block_mm: f64,
    /// Spacing of the outline points (px).
    pub spacing_px: f64,
    /// Outlines found needed to support a pose.
    pub min_outlines: usize,
    /// Length in view an outline needs to count (mm).
    pub min_length_mm: f64,
    /// Mean response (units of its spread, eq. (3)) an outline needs to be found.
    pub min_response: f64,
    /// Standard errors above zero its mean response needs to be found.
    pub min_z: f64,
    /// Newton iterations per scale at most.
    pub max_iterations: usize,
    /// The pivot pixel of the correction; `None`: [`probe_face_pivot`].
    pub pivot_px: Option<[f64; 2]>,
}

impl Default for PoseOptions {
    fn default() -> Self {
        PoseOptions {
            search: [3.0, 2.0, 6.0],
            scales_mm: vec![1.0, 0.5, 0.25, 0.15, 0.1],
            bone_weight: 4.0,
            skin_weight: 1.0,
            block_mm: 2.0,
            spacing_px: 0.5,
            min_outlines: 2,
            min_length_mm: 5.0,
            min_response: 0.5,
            min_z: 4.0,
            max_iterations: 60,
            pivot_px: None,
        }
    }
}

/// How well an outline is seen at the refined pose.
#[derive(Debug, Clone, serde::Serialize)]
pub struct OutlineSupport {
    pub name: String,
    /// Length inside the image at the initial pose (mm).
    pub length_in_view_mm: f64,
    /// Mean response along it at the refined pose (eq. (3), finest scale).
    pub response: f64,
    /// The mean response over its standard error (from the blocks).
    pub z: f64,
    pub found: bool,
}

/// The refined pose and its uncertainty.
#[derive(Debug, Clone, serde::Serialize)]
pub struct PoseFit {
    pub initial: ImagePose,
    pub pose: ImagePose,
    pub pivot_px: [f64; 2],
    /// The correction `(t_x mm, t_y mm, θ rad)` of eq. (1) from `initial` to `pose`.
    pub correction: [f64; 3],
    /// Sandwich covariance (5) of the correction (mm², mm·rad, rad²).
    pub covariance: [[f64; 3]; 3],
    /// Standard deviations of `t_x` (mm), `t_y` (mm), `θ` (degrees).
    pub sd: [f64; 3],
    /// Objective (4) at each scale's end, and the Newton iterations per scale.
    pub objective: Vec<f64>,
    pub iterations: Vec<usize>,
    /// Every outline with a length in view, and the outlines of the model not in view.
    pub support: Vec<OutlineSupport>,
    pub not_in_view: Vec<String>,
    pub seconds: f64,
}

/// The response image (3) of `image` at the scale `sigma_px`, row-major.
pub fn ridge_response(image: &GreyImage, sigma_px: f64) -> Vec<f64> {
    let g = image.gaussian_blur(sigma_px);
    let (w, h) = (g.width, g.height);
    let at = |i: isize, j: isize| -> f64 {
        let i = i.clamp(0, w as isize - 1) as usize;
        let j = j.clamp(0, h as isize - 1) as usize;
        g.data[j * w + i]
    };
    let s2 = sigma_px * sigma_px;
    let mut r: Vec<f64> = (0..w * h)
        .map(|k| {
            let (i, j) = ((k % w) as isize, (k / w) as isize);
            -s2 * (at(i + 1, j) + at(i - 1, j) + at(i, j + 1) + at(i, j - 1) - 4.0 * at(i, j))
        })
        .collect();
    let mut v = r.clone();
    let med = median(&mut v);
    let mut dev: Vec<f64> = r.iter().map(|x| (x - med).abs()).collect();
    let mad = 1.4826 * median(&mut dev);
    let scale = if mad > 1e-12 { mad } else { 1.0 };
    r.iter_mut().for_each(|x| *x /= scale);
    r
}

fn median(v: &mut [f64]) -> f64 {
    if v.is_empty() {
        return 0.0;
    }
    let m = v.len() / 2;
    v.select_nth_unstable_by(m, |a, b| a.total_cmp(b));
    v[m]
}

/// Outline points: model position, weight, outline index, and length of the sub-piece.
#[derive(Debug, Clone, Copy)]
struct OutlinePoint {
    x: [f64; 2],
    w: f64,
    outline: usize,
}

/// Points of the outlines at `spacing_mm` (sub-piece midpoints), with weight
/// `length × kind weight × (0.1 + 0.9 cos⁴ φ)`, `φ` between the segment's normal and `beam`.
fn outline_points(
    outlines: &[Outline],
    spacing_mm: f64,
    beam: [f64; 2],
    opts: &PoseOptions,
) -> Vec<OutlinePoint> {
    let mut pts = Vec::new();
    for (o, ol) in outlines.iter().enumerate() {
        let kw = match ol.kind {
            OutlineKind::Skin => opts.skin_weight,
            OutlineKind::Fascia => 1.0,
            OutlineKind::Bone => opts.bone_weight,
        };
        if !(kw > 0.0) {
            continue;
        }
        for &[p, q] in &ol.segments {
            let d = [q[0] - p[0], q[1] - p[1]];
            let len = d[0].hypot(d[1]);
            if !(len > 0.0) {
                continue;
            }
            let cos = ((d[1] * beam[0] - d[0] * beam[1]) / len).abs();
            let inc = 0.1 + 0.9 * cos.powi(4);
            let n = (len / spacing_mm).ceil().max(1.0) as usize;
            for k in 0..n {
                let t = (k as f64 + 0.5) / n as f64;
                pts.push(OutlinePoint {
                    x: [p[0] + t * d[0], p[1] + t * d[1]],
                    w: kw * inc * len / n as f64,
                    outline: o,
                });
            }
        }
    }
    pts
}

/// Value, gradient and Hessian `(g, g_x, g_y, g_xx, g_xy, g_yy)` of a B-spline interpolant
/// (mirror extension outside, as [`BSpline::eval`]).
fn eval_hessian(sp: &BSpline, x: f64, y: f64) -> [f64; 6] {
    let (fx, fy) = (x.floor(), y.floor());
    let (ix, iy) = (fx as isize, fy as isize);
    let (tx, ty) = (x - fx, y - fy);
    let (wx, wy) = (weights(tx), weights(ty));
    let (dx, dy) = (weights_derivative(tx), weights_derivative(ty));
    // d²/dt² of the cubic B-spline weights.
    let dd = |t: f64| [1.0 - t, 3.0 * t - 2.0, 1.0 - 3.0 * t, t];
    let (ddx, ddy) = (dd(tx), dd(ty));
    let mirror = |k: isize, n: usize| -> usize {
        let n = n as isize;
        if n == 1 {
            return 0;
        }
        let period = 2 * (n - 1);
        let mut k = k.rem_euclid(period);
        if k >= n {
            k = period - k;
        }
        k as usize
    };
    let mut out = [0.0; 6];
    for j in 0..4 {
        let row = mirror(iy - 1 + j as isize, sp.height) * sp.width;
        let (mut s, mut sd, mut sdd) = (0.0, 0.0, 0.0);
        for i in 0..4 {
            let c = sp.coef[row + mirror(ix - 1 + i as isize, sp.width)];
            s += wx[i] * c;
            sd += dx[i] * c;
            sdd += ddx[i] * c;
        }
        out[0] += wy[j] * s;
        out[1] += wy[j] * sd;
        out[2] += dy[j] * s;
        out[3] += wy[j] * sdd;
        out[4] += dy[j] * sd;
        out[5] += ddy[j] * s;
    }
    out
}

/// The objective (4) at one scale over a fixed set of outline points.
pub struct PoseObjective {
    spline: BSpline,
    /// `(ξ₀, η₀)` of each point (mm, eq. (2)), its weight, block and outline.
    local: Vec<[f64; 2]>,
    weight: Vec<f64>,
    block: Vec<usize>,
    outline: Vec<usize>,
    blocks: usize,
    pivot_px: [f64; 2],
    pixel_size_mm: f64,
    /// Image size (columns, rows): points count where they fall inside it by `edge_px`.
    size: [f64; 2],
    edge_px: f64,
}

/// Points count where they are this far inside the image's edge (px). (Keeping them 3σ from
/// the edge, where the smoothing no longer sees the mirrored image, loses most of the bone
/// at the bottom of the default window at the coarse scales, and with it the capture of the
/// pose along the skin.)
const EDGE_PX: f64 = 2.0;

/// Per block: its outline, `Σ w R` and `Σ w`.
type BlockSums = Vec<(usize, f64, f64)>;

/// Value, gradient and Hessian of (4) in `p = (t_x, t_y, θ)`.
pub type Evaluation = (f64, [f64; 3], [[f64; 3]; 3]);

impl PoseObjective {
    /// The objective on `image` smoothed at `sigma_mm`. Its points are the outline points
    /// within `pool_mm` of the image at `base.moved(pivot, p0)` (the pivot of `opts`); at a
    /// pose `p` those inside the image (2 px from its edge) count, the mean (4) is over them.
    pub fn new(
        image: &GreyImage,
        base: &ImagePose,
        outlines: &[Outline],
        sigma_mm: f64,
        p0: [f64; 3],
        pool_mm: f64,
        opts: &PoseOptions,
    ) -> Self {
        let pivot_px = opts
            .pivot_px
            .unwrap_or_else(|| probe_face_pivot(image.width));
        let s = base.pixel_size_mm;
        let r = ridge_response(image, sigma_mm / s);
        let spline = BSpline::new(&r, image.width, image.height);
        let start = base.moved(pivot_px, p0);
        let pts = outline_points(outlines, opts.spacing_px * s, start.y_axis, opts);
        let margin = -pool_mm / s;
        let xp = base.pixel_to_model(pivot_px);
        let mut obj = PoseObjective {
            spline,
            local: Vec::new(),
            weight: Vec::new(),
            block: Vec::new(),
            outline: Vec::new(),
            blocks: 0,
            pivot_px,
            pixel_size_mm: s,
            size: [image.width as f64, image.height as f64],
            edge_px: EDGE_PX,
        };
        let mut block_ids: HashMap<(usize, i64, i64), usize> = HashMap::new();
        let bpx = (opts.block_mm / s).max(1.0);
        for p in pts {
            let q = start.model_to_pixel(p.x);
            if !(q[0] >= margin
                && q[1] >= margin
                && q[0] <= image.width as f64 - 1.0 - margin
                && q[1] <= image.height as f64 - 1.0 - margin)
            {
                continue;
            }
            let d = [p.x[0] - xp[0], p.x[1] - xp[1]];
            obj.local.push([dot(d, base.x_axis), dot(d, base.y_axis)]);
            obj.weight.push(p.w);
            obj.outline.push(p.outline);
            let key = (
                p.outline,
                (q[0] / bpx).floor() as i64,
                (q[1] / bpx).floor() as i64,
            );
            let n = block_ids.len();
            obj.block.push(*block_ids.entry(key).or_insert(n));
        }
        obj.blocks = block_ids.len();
        obj
    }

    /// Number of points inside the image at `p`.
    pub fn points(&self, p: [f64; 3]) -> usize {
        (0..self.local.len())
            .filter(|&k| self.inside(self.map(k, p).0))
            .count()
    }

    fn inside(&self, uv: [f64; 2]) -> bool {
        let e = self.edge_px;
        uv[0] >= e
            && uv[1] >= e
            && uv[0] <= self.size[0] - 1.0 - e
            && uv[1] <= self.size[1] - 1.0 - e
    }

    /// The pose of largest (4) on a grid about `p0`: `half[i]` either side in steps of
    /// `step[i]` (mm, mm, rad).
    fn grid_search(&self, p0: [f64; 3], half: [f64; 3], step: [f64; 3]) -> [f64; 3] {
        use rayon::prelude::*;
        let n: Vec<i64> = (0..3)
            .map(|i| {
                if half[i] > 0.0 && step[i] > 0.0 {
                    (half[i] / step[i]).ceil() as i64
                } else {
                    0
                }
            })
            .collect();
        let mut cand = Vec::new();
        for a in -n[0]..=n[0] {
            for b in -n[1]..=n[1] {
                for c in -n[2]..=n[2] {
                    cand.push([
                        p0[0] + a as f64 * step[0],
                        p0[1] + b as f64 * step[1],
                        p0[2] + c as f64 * step[2],
                    ]);
                }
            }
        }
        cand.into_par_iter()
            .map(|p| (self.value(p), p))
            .reduce(
                || (f64::NEG_INFINITY, p0),
                |x, y| if y.0 > x.0 { y } else { x },
            )
            .1
    }

    /// Pixel position of point `k` under `p` (eq. (2)) and the derivatives of `(ξ, η)`.
    fn map(&self, k: usize, p: [f64; 3]) -> ([f64; 2], [f64; 2]) {
        let [x0, y0] = self.local[k];
        let (c, sn) = (p[2].cos(), p[2].sin());
        let (dx, dy) = (x0 - p[0], y0 - p[1]);
        let xi = dx * c + dy * sn;
        let eta = -dx * sn + dy * c;
        let s = self.pixel_size_mm;
        (
            [self.pivot_px[0] + xi / s, self.pivot_px[1] + eta / s],
            [xi, eta],
        )
    }

    /// The value of (4) and the per-point weighted gradient terms `w_k ∇_p R` (when `terms`).
    fn per_point(&self, p: [f64; 3], k: usize) -> (f64, [f64; 3], [[f64; 3]; 3]) {
        let (uv, [xi, eta]) = self.map(k, p);
        let s = self.pixel_size_mm;
        let (c, sn) = (p[2].cos(), p[2].sin());
        let h = eval_hessian(&self.spline, uv[0], uv[1]);
        // d(ξ, η)/dp (columns t_x, t_y, θ), divided by s for (u, v).
        let du = [-c / s, -sn / s, eta / s];
        let dv = [sn / s, -c / s, -xi / s];
        let g: [f64; 3] = std::array::from_fn(|i| h[1] * du[i] + h[2] * dv[i]);
        // Second derivatives of (u, v) (only those with θ are non-zero).
        let mut duu = [[0.0; 3]; 3];
        let mut dvv = [[0.0; 3]; 3];
        duu[0][2] = sn / s;
        duu[2][0] = sn / s;
        duu[1][2] = -c / s;
        duu[2][1] = -c / s;
        duu[2][2] = -xi / s;
        dvv[0][2] = c / s;
        dvv[2][0] = c / s;
        dvv[1][2] = sn / s;
        dvv[2][1] = sn / s;
        dvv[2][2] = -eta / s;
        let mut hh = [[0.0; 3]; 3];
        for i in 0..3 {
            for j in 0..3 {
                hh[i][j] = h[3] * du[i] * du[j]
                    + h[4] * (du[i] * dv[j] + dv[i] * du[j])
                    + h[5] * dv[i] * dv[j]
                    + h[1] * duu[i][j]
                    + h[2] * dvv[i][j];
            }
        }
        (h[0], g, hh)
    }

    /// The value of (4) alone.
    pub fn value(&self, p: [f64; 3]) -> f64 {
        let (mut f, mut wsum) = (0.0, 0.0);
        for k in 0..self.local.len() {
            let (uv, _) = self.map(k, p);
            if !self.inside(uv) {
                continue;
            }
            f += self.weight[k] * self.spline.eval(uv[0], uv[1]);
            wsum += self.weight[k];
        }
        if wsum > 0.0 {
            f / wsum
        } else {
            0.0
        }
    }

    /// Value, exact gradient and Hessian of (4).
    pub fn evaluate(&self, p: [f64; 3]) -> Evaluation {
        let (mut f, mut g, mut hh, mut wsum) = (0.0, [0.0; 3], [[0.0; 3]; 3], 0.0);
        for k in 0..self.local.len() {
            if !self.inside(self.map(k, p).0) {
                continue;
            }
            let w = self.weight[k];
            let (v, gk, hk) = self.per_point(p, k);
            f += w * v;
            for i in 0..3 {
                g[i] += w * gk[i];
                for j in 0..3 {
                    hh[i][j] += w * hk[i][j];
                }
            }
            wsum += w;
        }
        if wsum > 0.0 {
            f /= wsum;
            for i in 0..3 {
                g[i] /= wsum;
                for j in 0..3 {
                    hh[i][j] /= wsum;
                }
            }
        }
        (f, g, hh)
    }

    /// Maximizes (4) from `p0` (Newton with Levenberg–Marquardt damping, steps at most
    /// `max_step_mm`, θ scaled by a lever of 10 mm). Returns `p̂` and the iterations.
    fn maximize(&self, p0: [f64; 3], max_step_mm: f64, max_iterations: usize) -> ([f64; 3], usize) {
        const LEVER_MM: f64 = 10.0;
        let scale = [1.0, 1.0, LEVER_MM];
        let mut p = p0;
        let mut lambda = 1e-3;
        let mut it = 0;
        while it < max_iterations {
            it += 1;
            let (f, g, hh) = self.evaluate(p);
            // Scaled variables q_i = scale_i p_i: g_q = g / scale, H_q = H / (scale scale).
            let gq: [f64; 3] = std::array::from_fn(|i| g[i] / scale[i]);
            let a: [[f64; 3]; 3] =
                std::array::from_fn(|i| std::array::from_fn(|j| -hh[i][j] / (scale[i] * scale[j])));
            let diag = (0..3).map(|i| a[i][i].abs()).fold(1e-12, f64::max);
            let mut improved = false;
            let mut small = false;
            for _ in 0..30 {
                let mut m = a;
                for (i, row) in m.iter_mut().enumerate() {
                    row[i] += lambda * diag;
                }
                let Some(mut dq) = cholesky_solve(&m, &gq) else {
                    lambda *= 10.0;
                    continue;
                };
                let n = norm3(&dq);
                if n > max_step_mm {
                    dq.iter_mut().for_each(|v| *v *= max_step_mm / n);
                }
                let trial: [f64; 3] = std::array::from_fn(|i| p[i] + dq[i] / scale[i]);
                if self.value(trial) > f {
                    p = trial;
                    lambda = (lambda / 3.0).max(1e-9);
                    improved = true;
                    small = n.min(max_step_mm) < 1e-6;
                    break;
                }
                lambda *= 4.0;
                if n < 1e-7 {
                    small = true;
                    break;
                }
            }
            if !improved || small {
                break;
            }
        }
        (p, it)
    }

    /// The sandwich covariance (5) at `p` and the per-outline block means of the response.
    fn sandwich(&self, p: [f64; 3]) -> ([[f64; 3]; 3], BlockSums) {
        let mut hs = [[0.0; 3]; 3];
        let mut sg = vec![[0.0; 3]; self.blocks];
        let mut bw = vec![(usize::MAX, 0.0, 0.0); self.blocks];
        for k in 0..self.local.len() {
            if !self.inside(self.map(k, p).0) {
                continue;
            }
            let w = self.weight[k];
            let (v, gk, hk) = self.per_point(p, k);
            let b = self.block[k];
            for i in 0..3 {
                sg[b][i] += w * gk[i];
                for j in 0..3 {
                    hs[i][j] += w * hk[i][j];
                }
            }
            bw[b].0 = self.outline[k];
            bw[b].1 += w * v;
            bw[b].2 += w;
        }
        let g = self.blocks as f64;
        let c = g / (g - 3.0).max(1.0);
        let mut v = [[0.0; 3]; 3];
        for s in &sg {
            for i in 0..3 {
                for j in 0..3 {
                    v[i][j] += c * s[i] * s[j];
                }
            }
        }
        let cov = match inverse3(&hs) {
            Some(hi) => mul3(&mul3(&hi, &v), &hi),
            None => [[f64::INFINITY; 3]; 3],
        };
        (cov, bw)
    }
}

/// Refines the pose of `image` (the unloaded frame) from `initial` by matching `outlines`
/// (model frame) to its bright lines (module documentation). Errors when fewer than
/// `opts.min_outlines` outlines are found in the image, naming each outline in view with its
/// response and those not in view.
pub fn refine_pose(
    image: &GreyImage,
    initial: &ImagePose,
    outlines: &[Outline],
    opts: &PoseOptions,
) -> Result<PoseFit, UsError> {
    let t0 = std::time::Instant::now();
    if opts.scales_mm.is_empty() || opts.scales_mm.iter().any(|s| !(*s > 0.0)) {
        return Err(UsError::param(
            "pose scales_mm",
            format!("{:?}: positive scales needed", opts.scales_mm),
        ));
    }
    let pivot = opts
        .pivot_px
        .unwrap_or_else(|| probe_face_pivot(image.width));
    // Length of each outline in view at the initial pose.
    let s = initial.pixel_size_mm;
    let mut length = vec![0.0; outlines.len()];
    for (o, ol) in outlines.iter().enumerate() {
        for &[a, b] in &ol.segments {
            let (qa, qb) = (initial.model_to_pixel(a), initial.model_to_pixel(b));
            let n = ((a[0] - b[0]).hypot(a[1] - b[1]) / (opts.spacing_px * s))
                .ceil()
                .max(1.0);
            let inside = |q: [f64; 2]| {
                q[0] >= 0.0
                    && q[1] >= 0.0
                    && q[0] <= image.width as f64 - 1.0
                    && q[1] <= image.height as f64 - 1.0
            };
            let len = (a[0] - b[0]).hypot(a[1] - b[1]);
            for k in 0..n as usize {
                let t = (k as f64 + 0.5) / n;
                let q = [qa[0] + t * (qb[0] - qa[0]), qa[1] + t * (qb[1] - qa[1])];
                if inside(q) {
                    length[o] += len / n;
                }
            }
        }
    }
    let counted: Vec<usize> = (0..outlines.len())
        .filter(|&o| length[o] >= opts.min_length_mm)
        .collect();
    let not_in_view: Vec<String> = (0..outlines.len())
        .filter(|&o| length[o] < opts.min_length_mm)
        .map(|o| outlines[o].name.clone())
        .collect();
    if counted.len() < opts.min_outlines {
        return Err(UsError::Geometry(format!(
            "the image's pose cannot be refined: {} of the model's outlines {} in view with {} mm at least ({}), {} needed; not in view: {}",
            counted.len(),
            if counted.len() == 1 { "is" } else { "are" },
            opts.min_length_mm,
            names(counted.iter().map(|&o| format!("{} {:.1} mm", outlines[o].name, length[o]))),
            opts.min_outlines,
            names(not_in_view.iter().cloned())
        )));
    }
    let used: Vec<Outline> = counted.iter().map(|&o| outlines[o].clone()).collect();
    let mut p = [0.0; 3];
    let mut objective = Vec::new();
    let mut iterations = Vec::new();
    let mut last = None;
    for (level, &sigma) in opts.scales_mm.iter().enumerate() {
        let obj = PoseObjective::new(image, initial, &used, sigma, p, POOL_MM, opts);
        if level == 0 {
            // Half-steps of the scale: the coarse objective's peak is about σ wide.
            let lever = 0.5 * image.width.max(image.height) as f64 * s;
            p = obj.grid_search(
                p,
                [opts.search[0], opts.search[1], opts.search[2].to_radians()],
                [0.5 * sigma, 0.5 * sigma, 0.5 * sigma / lever],
            );
        }
        if obj.points(p) == 0 {
            return Err(UsError::Geometry(
                "the image's pose cannot be refined: no outline point inside the image".into(),
            ));
        }
        let (q, it) = obj.maximize(p, sigma, opts.max_iterations);
        p = q;
        objective.push(obj.value(p));
        iterations.push(it);
        last = Some(obj);
    }
    let obj = last.expect("one scale at least");
    let (covariance, blocks) = obj.sandwich(p);
    let mut support = Vec::new();
    for (u, &o) in counted.iter().enumerate() {
        let means: Vec<f64> = blocks
            .iter()
            .filter(|b| b.0 == u && b.2 > 0.0)
            .map(|b| b.1 / b.2)
            .collect();
        let (wsum, vsum) = blocks
            .iter()
            .filter(|b| b.0 == u)
            .fold((0.0, 0.0), |acc, b| (acc.0 + b.2, acc.1 + b.1));
        let response = if wsum > 0.0 { vsum / wsum } else { 0.0 };
        let z = if means.len() >= 2 {
            let (_, sd) = crate::stats::mean_sd(&means);
            response / (sd / (means.len() as f64).sqrt()).max(1e-12)
        } else {
            0.0
        };
        support.push(OutlineSupport {
            name: outlines[o].name.clone(),
            length_in_view_mm: length[o],
            response,
            z,
            found: response >= opts.min_response && z >= opts.min_z,
        });
    }
    let found = support.iter().filter(|s| s.found).count();
    if found < opts.min_outlines {
        return Err(UsError::Geometry(format!(
            "the image's pose is not supported by the frame: {found} of the model's outlines found as bright lines, {} needed (a mean ridge response of {} and {} standard errors at least); in view: {}{}",
            opts.min_outlines,
            opts.min_response,
            opts.min_z,
            names(support.iter().map(|s| format!(
                "{} ({:.1} mm, response {:.2}, {:.1} s.e.{})",
                s.name,
                s.length_in_view_mm,
                s.response,
                s.z,
                if s.found { ", found" } else { ", not found" }
            ))),
            if not_in_view.is_empty() {
                String::new()
            } else {
                format!("; not in view: {}", names(not_in_view.iter().cloned()))
            }
        )));
    }
    let sd = [
        covariance[0][0].max(0.0).sqrt(),
        covariance[1][1].max(0.0).sqrt(),
        covariance[2][2].max(0.0).sqrt().to_degrees(),
    ];
    Ok(PoseFit {
        initial: *initial,
        pose: initial.moved(pivot, p),
        pivot_px: pivot,
        correction: p,
        covariance,
        sd,
        objective,
        iterations,
        support,
        not_in_view,
        seconds: t0.elapsed().as_secs_f64(),
    })
}

fn names(it: impl Iterator<Item = String>) -> String {
    let v: Vec<String> = it.collect();
    if v.is_empty() {
        "none".into()
    } else {
        v.join(", ")
    }
}

fn dot(a: [f64; 2], b: [f64; 2]) -> f64 {
    a[0] * b[0] + a[1] * b[1]
}

fn norm3(v: &[f64; 3]) -> f64 {
    (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt()
}

/// Solves `m x = b` for a symmetric positive definite 3x3 `m` (Cholesky); `None` if `m` is
/// not positive definite.
fn cholesky_solve(m: &[[f64; 3]; 3], b: &[f64; 3]) -> Option<[f64; 3]> {
    let mut l = [[0.0; 3]; 3];
    for i in 0..3 {
        for j in 0..=i {
            let mut s = m[i][j];
            for k in 0..j {
                s -= l[i][k] * l[j][k];
            }
            if i == j {
                if !(s > 0.0) {
                    return None;
                }
                l[i][i] = s.sqrt();
            } else {
                l[i][j] = s / l[j][j];
            }
        }
    }
    let mut y = [0.0; 3];
    for i in 0..3 {
        let mut s = b[i];
        for k in 0..i {
            s -= l[i][k] * y[k];
        }
        y[i] = s / l[i][i];
    }
    let mut x = [0.0; 3];
    for i in (0..3).rev() {
        let mut s = y[i];
        for k in i + 1..3 {
            s -= l[k][i] * x[k];
        }
        x[i] = s / l[i][i];
    }
    Some(x)
}

fn inverse3(m: &[[f64; 3]; 3]) -> Option<[[f64; 3]; 3]> {
    let c = |i: usize, j: usize| {
        let (i1, i2) = ((i + 1) % 3, (i + 2) % 3);
        let (j1, j2) = ((j + 1) % 3, (j + 2) % 3);
        m[i1][j1] * m[i2][j2] - m[i1][j2] * m[i2][j1]
    };
    let det = m[0][0] * c(0, 0) + m[0][1] * c(0, 1) + m[0][2] * c(0, 2);
    if !(det.abs() > 1e-300) || !det.is_finite() {
        return None;
    }
    Some(std::array::from_fn(|i| {
        std::array::from_fn(|j| c(j, i) / det)
    }))
}

fn mul3(a: &[[f64; 3]; 3], b: &[[f64; 3]; 3]) -> [[f64; 3]; 3] {
    std::array::from_fn(|i| std::array::from_fn(|j| (0..3).map(|k| a[i][k] * b[k][j]).sum()))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn moved_and_offset_are_inverse() {
        for (a, b) in [([1.0, 0.0], [0.0, -1.0]), ([0.6, 0.8], [-0.8, 0.6])] {
            let pose = ImagePose::new([-20.0, 60.0], a, b, 0.1).unwrap();
            let pivot = probe_face_pivot(400);
            let p = [1.5, -1.0, 3f64.to_radians()];
            let m = pose.moved(pivot, p);
            let back = m.offset_from(&pose, pivot);
            for i in 0..3 {
                assert!((back[i] - p[i]).abs() < 1e-12, "{back:?} vs {p:?}");
            }
            // The pivot moves by (t_x, t_y) along the axes; other pixels also turn.
            let x = m.pixel_to_model(pivot);
            let x0 = pose.pixel_to_model(pivot);
            let d = [x[0] - x0[0], x[1] - x0[1]];
            assert!((dot(d, a) - 1.5).abs() < 1e-12 && (dot(d, b) + 1.0).abs() < 1e-12);
            let q = m.model_to_pixel(m.pixel_to_model([12.3, 45.6]));
            assert!((q[0] - 12.3).abs() < 1e-9 && (q[1] - 45.6).abs() < 1e-9);
        }
        assert!(ImagePose::new([0.0; 2], [1.0, 0.0], [1.0, 1.0], 0.1).is_err());
    }

    #[test]
    fn spline_hessian_matches_finite_differences() {
        let (w, h) = (12, 10);
        let data: Vec<f64> = (0..w * h)
            .map(|k| ((k % w) as f64 * 0.7).sin() * ((k / w) as f64 * 0.4).cos() * 50.0)
            .collect();
        let sp = BSpline::new(&data, w, h);
        let (x, y) = (4.3, 5.7);
        let e = 1e-5;
        let v = eval_hessian(&sp, x, y);
        let gx = |x: f64, y: f64| sp.eval_grad(x, y);
        assert!((v[0] - sp.eval(x, y)).abs() < 1e-10);
        let fd_xx = (gx(x + e, y).1 - gx(x - e, y).1) / (2.0 * e);
        let fd_xy = (gx(x, y + e).1 - gx(x, y - e).1) / (2.0 * e);
        let fd_yy = (gx(x, y + e).2 - gx(x, y - e).2) / (2.0 * e);
        // Central differences of a C² cubic: error O(e²) × third derivative (~50), well below 1e-6.
        for (a, b) in [(v[3], fd_xx), (v[4], fd_xy), (v[5], fd_yy)] {
            assert!((a - b).abs() < 1e-6, "{a} vs {b}");
        }
    }
}
