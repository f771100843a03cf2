//! The all-quad mesher of class images (label maps, and the parametric thigh sampled on a
//! raster).
//!
//! 1. **Classes.** Every pixel is background (0), bone (1) or a region (2, 3, ...).
//! 2. **Cleaning.** 4-connected components smaller than [`MeshOptions::min_island_mm2`] and
//!    background holes inside the body (unlabelled vessels) are merged into the class they
//!    border most; tissue pieces not connected to the largest one, and bone not touching it,
//!    are dropped. Each change is reported as a warning.
//! 3. **Interface curves.** The edges between pixels of different classes form a planar graph
//!    on the pixel corners. Corners where three classes meet (or two diagonally) are
//!    *junctions*; the curves between junctions, and closed loops, are traced.
//! 4. **Smoothing.** Every curve is smoothed by Taubin's λ|μ filter (λ = 0.5, μ = -0.53;
//!    G. Taubin, "A signal processing approach to fair surface design", SIGGRAPH 1995): a
//!    low-pass filter that removes the pixel staircase without the shrinkage of plain Laplacian
//!    smoothing. Junctions stay at their pixel corner, so curves that meet stay joined.
//! 5. **Triangles.** The curves are resampled at the element size, inserted as constraints into
//!    a constrained Delaunay triangulation (`spade`), refined to a maximum area and a 30° minimum
//!    angle. Each triangle takes the class of its constraint-bounded component, decided by an
//!    area-weighted vote of the pixels under the triangle centroids.
//! 6. **Quads.** Every tissue triangle is split into three quads joining a vertex, the two
//!    adjacent edge midpoints and the centroid:
//!
//!    ```text
//!              v2
//!             /  \              quad k = [v_k, m_(k,k+1), c, m_(k-1,k)]
//!           m20   m12           (counter-clockwise like the triangle)
//!           / \ c / \
//!          /   |     \          shared edges are split at their midpoint by both
//!        v0 ---m01--- v1        neighbours: the mesh is conforming
//!    ```
//!
//!    A triangle whose smallest angle is α gives quads whose smallest angle is about α, so the
//!    30° refinement bounds the scaled Jacobian from below by about sin 30° = 0.5 away from
//!    sharp junctions.
//! 7. **Relaxation.** A few sweeps of Laplacian smoothing move the nodes that are not on a
//!    curve; a move is kept only if it does not lower the smallest scaled Jacobian of the quads
//!    around the node.

use crate::labels::{LabelImage, LabelSpec};
use crate::quality::{aspect_ratio, element_area, scaled_jacobian};
use crate::GeometryError;
use femu_mesh::generate::GeneratedMesh;
use femu_mesh::{Element, ElementKind, Mesh};
use spade::handles::FixedVertexHandle;
use spade::{
    AngleLimit, ConstrainedDelaunayTriangulation, Point2, RefinementParameters, Triangulation,
};
use std::collections::{BTreeMap, HashMap};

/// Class of background pixels.
pub(crate) const BACKGROUND: u16 = 0;
/// Class of bone pixels.
pub(crate) const BONE: u16 = 1;
/// Class of the first region.
pub(crate) const FIRST_REGION: u16 = 2;

/// The largest mesh the meshers build (quads): the top of the built-in thigh's element range;
/// solving it takes some 2.5 GB (about 5 kB per quad: the 25 000-quad thigh peaks at 125 MB).
/// A mesh whose estimate (`area / h²`) exceeds it is refused before anything is allocated.
pub const MAX_ELEMENTS: usize = 500_000;

/// Meshing options shared by the label mesher and the parametric thigh.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct MeshOptions {
    /// Target element size h (mm): the mesh has about `area / h²` quads. Independent of the
    /// pixel size.
    pub element_size_mm: f64,
    /// Element formulation of the quads (CPE4 or CPE4H).
    pub kind: ElementKind,
    /// Connected pieces of one class smaller than this (mm²) are merged into their neighbour.
    pub min_island_mm2: f64,
    /// Taubin λ|μ iteration pairs applied to the interface curves.
    pub smoothing_iterations: usize,
}

impl Default for MeshOptions {
    fn default() -> Self {
        MeshOptions {
            element_size_mm: 1.0,
            kind: ElementKind::Cpe4h,
            min_island_mm2: 5.0,
            smoothing_iterations: 60,
        }
    }
}

impl MeshOptions {
    /// Checks the ranges: element size in (0, 100] mm, island threshold ≥ 0, smoothing ≤ 1000
    /// pairs, element kind a quad.
    pub fn validate(&self) -> Result<(), GeometryError> {
        let h = self.element_size_mm;
        if !(h > 0.0 && h <= 100.0) {
            return Err(GeometryError::param(
                "element_size_mm",
                h,
                "must be in (0, 100] mm",
            ));
        }
        if !(self.min_island_mm2 >= 0.0) || !self.min_island_mm2.is_finite() {
            return Err(GeometryError::param(
                "min_island_mm2",
                self.min_island_mm2,
                "must be a finite area >= 0",
            ));
        }
        if self.smoothing_iterations > 1000 {
            return Err(GeometryError::param(
                "smoothing_iterations",
                self.smoothing_iterations,
                "must be at most 1000",
            ));
        }
        if self.kind == ElementKind::Cpe3 {
            return Err(GeometryError::param(
                "kind",
                "CPE3",
                "the thigh meshers make quadrilaterals (CPE4 or CPE4H)",
            ));
        }
        Ok(())
    }
}

/// A meshed thigh model: the mesh with its sets and surfaces, its region names, the areas of
/// its source (pixel counts or the sampled parametric shapes) and the warnings of the meshing.
#[derive(Debug, Clone)]
pub struct ThighModel {
    /// The mesh: region element sets, node sets `FEMUR` and `SKIN`, surfaces `SKIN`, `FEMUR`.
    pub mesh: GeneratedMesh,
    /// Region (element-set) names, in order.
    pub regions: Vec<String>,
    /// Area of each region in the source (pixel area of the label image before cleaning), mm².
    pub source_areas_mm2: BTreeMap<String, f64>,
    /// Area of the bone in the source (mm²).
    pub source_bone_area_mm2: f64,
    /// The element size used (mm).
    pub element_size_mm: f64,
    /// What the cleaning changed (islands dropped, holes filled, ...).
    pub warnings: Vec<String>,
}

impl ThighModel {
    /// Meshed area of each region (mm²).
    pub fn region_areas(&self) -> BTreeMap<String, f64> {
        let m = &self.mesh.mesh;
        self.regions
            .iter()
            .map(|r| {
                let a = m
                    .element_set(r)
                    .unwrap_or(&[])
                    .iter()
                    .map(|&e| element_area(m, e))
                    .sum();
                (r.clone(), a)
            })
            .collect()
    }

    /// Area enclosed by the femur edge (the hole), mm².
    pub fn hole_area(&self) -> f64 {
        -self.surface_signed_area("FEMUR")
    }

    /// Area enclosed by the skin, mm².
    pub fn skin_area(&self) -> f64 {
        self.surface_signed_area("SKIN")
    }

    /// Length of a surface (mm).
    pub fn surface_length(&self, name: &str) -> f64 {
        let m = &self.mesh.mesh;
        self.mesh.surfaces.get(name).map_or(0.0, |faces| {
            faces
                .iter()
                .map(|&(e, f)| {
                    let [a, b] = m.elements[e].face_nodes(f);
                    let (p, q) = (m.nodes[a], m.nodes[b]);
                    (q[0] - p[0]).hypot(q[1] - p[1])
                })
                .sum()
        })
    }

    /// `∮ (x dy - y dx) / 2` over the faces of a surface, oriented as the elements see them
    /// (counter-clockwise around the tissue): the enclosed area, negative for a hole.
    fn surface_signed_area(&self, name: &str) -> f64 {
        let m = &self.mesh.mesh;
        self.mesh.surfaces.get(name).map_or(0.0, |faces| {
            faces
                .iter()
                .map(|&(e, f)| {
                    let [a, b] = m.elements[e].face_nodes(f);
                    let (p, q) = (m.nodes[a], m.nodes[b]);
                    0.5 * (p[0] * q[1] - q[0] * p[1])
                })
                .sum()
        })
    }
}

/// Meshes a label image: `pixel_size_mm` overrides the file's pixel size (a NIfTI header); one
/// of the two must exist. Every label value of the image must be mapped (region, bone or
/// background); every bone label must occur.
pub fn mesh_label_image(
    image: &LabelImage,
    spec: &LabelSpec,
    pixel_size_mm: Option<f64>,
    options: &MeshOptions,
) -> Result<ThighModel, GeometryError> {
    options.validate()?;
    spec.validate()?;
    let [sx, sy] = match (pixel_size_mm, image.pixel_size_mm) {
        (Some(s), _) => [s, s],
        (None, Some(s)) => s,
        (None, None) => {
            return Err(GeometryError::InvalidLabelMap(
                "the image gives no pixel size: pass one (--pixel-size MM)".into(),
            ))
        }
    };
    for s in [sx, sy] {
        if !(s > 0.0) || !s.is_finite() {
            return Err(GeometryError::InvalidPixelSize(s));
        }
    }
    let names = spec.region_names();
    let mut class_of: HashMap<u32, u16> = HashMap::new();
    for (l, n) in &spec.regions {
        let r = names.iter().position(|x| x == n).expect("name listed") as u16;
        class_of.insert(*l, FIRST_REGION + r);
    }
    for &l in &spec.bone {
        class_of.insert(l, BONE);
    }
    for &l in &spec.background {
        class_of.insert(l, BACKGROUND);
    }
    let hist = image.histogram();
    for (&label, &count) in &hist {
        if !class_of.contains_key(&label) {
            let k = image.labels.iter().position(|&l| l == label).unwrap_or(0);
            let (i, j) = (k % image.width, k / image.width);
            return Err(GeometryError::UnmappedLabel {
                label,
                pixels: count,
                column: i,
                row: image.height - 1 - j,
            });
        }
    }
    let present = || {
        let labels: Vec<String> = hist.keys().map(|l| l.to_string()).collect();
        labels.join(", ")
    };
    if !hist
        .keys()
        .any(|l| spec.regions.iter().any(|(r, _)| r == l))
    {
        return Err(GeometryError::NoTissue(format!(
            "no pixel holds a tissue label of the map ({}); labels present: {}",
            spec.regions
                .iter()
                .map(|(l, n)| format!("{l}={n}"))
                .collect::<Vec<_>>()
                .join(","),
            present()
        )));
    }
    for (label, region) in &spec.regions {
        if !hist.contains_key(label) {
            return Err(GeometryError::MappedLabelAbsent {
                label: *label,
                region: region.clone(),
                present: present(),
            });
        }
    }
    for &b in &spec.bone {
        if !hist.contains_key(&b) {
            return Err(GeometryError::BoneLabelAbsent {
                label: b,
                present: present(),
            });
        }
    }
    let class: Vec<u16> = image.labels.iter().map(|l| class_of[l]).collect();
    let grid = ClassGrid {
        nx: image.width,
        ny: image.height,
        sx,
        sy,
        origin: [0.0, 0.0],
        class,
    };
    mesh_classes(grid, &names, options)
}

/// A class image on a regular grid: pixel `(i, j)` covers
/// `origin + [i sx, (i+1) sx] x [j sy, (j+1) sy]`.
#[derive(Debug, Clone)]
pub(crate) struct ClassGrid {
    pub nx: usize,
    pub ny: usize,
    pub sx: f64,
    pub sy: f64,
    pub origin: [f64; 2],
    pub class: Vec<u16>,
}

impl ClassGrid {
    fn pixel_area(&self) -> f64 {
        self.sx * self.sy
    }

    /// Class at a point of the model frame (background outside the grid).
    fn class_at(&self, p: [f64; 2]) -> u16 {
        let fi = ((p[0] - self.origin[0]) / self.sx).floor();
        let fj = ((p[1] - self.origin[1]) / self.sy).floor();
        if fi < 0.0 || fj < 0.0 || fi >= self.nx as f64 || fj >= self.ny as f64 {
            return BACKGROUND;
        }
        self.class[fj as usize * self.nx + fi as usize]
    }

    /// Area of each class (mm²).
    fn class_areas(&self, n_classes: usize) -> Vec<f64> {
        let mut a = vec![0.0; n_classes];
        for &c in &self.class {
            a[c as usize] += self.pixel_area();
        }
        a
    }
}

/// The whole pipeline from a class grid (steps 2–7 of the module documentation).
pub(crate) fn mesh_classes(
    mut grid: ClassGrid,
    names: &[String],
    options: &MeshOptions,
) -> Result<ThighModel, GeometryError> {
    options.validate()?;
    let n_classes = FIRST_REGION as usize + names.len();
    let class_name = |c: u16| -> String {
        match c {
            BACKGROUND => "background".into(),
            BONE => "bone".into(),
            c => names[(c - FIRST_REGION) as usize].clone(),
        }
    };
    let areas = grid.class_areas(n_classes);
    let source_areas_mm2: BTreeMap<String, f64> = names
        .iter()
        .enumerate()
        .map(|(r, n)| (n.clone(), areas[FIRST_REGION as usize + r]))
        .collect();
    let source_bone_area_mm2 = areas[BONE as usize];
    if areas[FIRST_REGION as usize..].iter().all(|&a| a == 0.0) {
        return Err(GeometryError::NoTissue(
            "no pixel carries a region label".into(),
        ));
    }
    check_mesh_size(
        areas[FIRST_REGION as usize..].iter().sum(),
        options.element_size_mm,
    )?;
    let mut warnings = Vec::new();
    clean(
        &mut grid,
        options.min_island_mm2,
        &class_name,
        &mut warnings,
    )?;
    let after = grid.class_areas(n_classes);
    if after[FIRST_REGION as usize..].iter().all(|&a| a == 0.0) {
        return Err(GeometryError::NoTissue(
            "every tissue piece was below the island threshold".into(),
        ));
    }
    for (r, n) in names.iter().enumerate() {
        if after[FIRST_REGION as usize + r] == 0.0 && areas[FIRST_REGION as usize + r] > 0.0 {
            warnings.push(format!(
                "region {n} disappeared: all its pieces were below the island threshold or detached"
            ));
        }
    }
    if after[BONE as usize] == 0.0 {
        return Err(GeometryError::NoTissue(
            "the bone does not touch the tissue: nothing would hold the model".into(),
        ));
    }
    let chains = trace_chains(&grid);
    let chains: Vec<Chain> = chains
        .into_iter()
        .map(|c| taubin(c, options.smoothing_iterations))
        .collect();
    let mesh = triangulate_and_split(&grid, &chains, names, options)?;
    let mut used_names = Vec::new();
    for (r, n) in names.iter().enumerate() {
        if mesh.mesh.element_sets.contains_key(n) {
            used_names.push(n.clone());
        } else if after[FIRST_REGION as usize + r] > 0.0 {
            return Err(GeometryError::Meshing(format!(
                "region {n} ({:.0} mm²) has no element at an element size of {} mm: give smaller elements",
                after[FIRST_REGION as usize + r],
                options.element_size_mm
            )));
        }
    }
    if mesh.mesh.node_set("FEMUR").is_none_or(|s| s.is_empty()) {
        return Err(GeometryError::Meshing(format!(
            "the bone ({:.0} mm²) left no hole at an element size of {} mm: give smaller elements",
            after[BONE as usize], options.element_size_mm
        )));
    }
    mesh.mesh
        .check_orientation()
        .map_err(|e| GeometryError::Meshing(format!("the mesh is not valid: {e}")))?;
    let model = ThighModel {
        mesh,
        regions: used_names,
        source_areas_mm2,
        source_bone_area_mm2,
        element_size_mm: options.element_size_mm,
        warnings,
    };
    crate::quality::quality_report(&model.mesh.mesh, &model.regions)?;
    Ok(model)
}

/// Refuses a mesh of `tissue_mm2` at element size `h` whose estimated quad count, `area / h²`
/// (the meshes have 1.0-1.4 times that: 1 509 quads at 3 mm on the 12 579 mm² default thigh),
/// exceeds [`MAX_ELEMENTS`] (issue 32.8: `--size 0.01` on the MRI slice ran 40 s to 3.6 GB and
/// aborted on an allocation).
fn check_mesh_size(tissue_mm2: f64, h: f64) -> Result<(), GeometryError> {
    let estimate = tissue_mm2 / (h * h);
    if estimate > MAX_ELEMENTS as f64 {
        return Err(GeometryError::param(
            "element_size_mm",
            h,
            &format!(
                "about {estimate:.2e} quads ({tissue_mm2:.0} mm² of tissue / h²), above the limit of {MAX_ELEMENTS} (some 2.5 GB to solve): give elements of at least {:.3} mm",
                (tissue_mm2 / MAX_ELEMENTS as f64).sqrt()
            ),
        ));
    }
    Ok(())
}

// ---------------------------------------------------------------------------------------------
// Cleaning.

struct Component {
    class: u16,
    pixels: Vec<usize>,
    touches_border: bool,
}

/// 4-connected components of equal class (`same(a, b)` decides connectivity).
fn components(grid: &ClassGrid, same: impl Fn(u16, u16) -> bool) -> (Vec<usize>, Vec<Component>) {
    let (nx, ny) = (grid.nx, grid.ny);
    let mut id = vec![usize::MAX; nx * ny];
    let mut comps = Vec::new();
    let mut stack = Vec::new();
    for start in 0..nx * ny {
        if id[start] != usize::MAX {
            continue;
        }
        let c = grid.class[start];
        let k = comps.len();
        let mut comp = Component {
            class: c,
            pixels: Vec::new(),
            touches_border: false,
        };
        id[start] = k;
        stack.push(start);
        while let Some(p) = stack.pop() {
            comp.pixels.push(p);
            let (i, j) = (p % nx, p / nx);
            if i == 0 || j == 0 || i == nx - 1 || j == ny - 1 {
                comp.touches_border = true;
            }
            let mut visit = |q: usize| {
                if id[q] == usize::MAX && same(grid.class[q], c) {
                    id[q] = k;
                    stack.push(q);
                }
            };
            if i > 0 {
                visit(p - 1);
            }
            if i + 1 < nx {
                visit(p + 1);
            }
            if j > 0 {
                visit(p - nx);
            }
            if j + 1 < ny {
                visit(p + nx);
            }
        }
        comps.push(comp);
    }
    (id, comps)
}

/// The class that borders a set of pixels most (4-neighbours outside the set).
fn bordering_class(grid: &ClassGrid, id: &[usize], k: usize, pixels: &[usize]) -> Option<u16> {
    let (nx, ny) = (grid.nx, grid.ny);
    let mut count: BTreeMap<u16, usize> = BTreeMap::new();
    for &p in pixels {
        let (i, j) = (p % nx, p / nx);
        let mut see = |q: usize| {
            if id[q] != k {
                *count.entry(grid.class[q]).or_insert(0) += 1;
            }
        };
        if i > 0 {
            see(p - 1);
        }
        if i + 1 < nx {
            see(p + 1);
        }
        if j > 0 {
            see(p - nx);
        }
        if j + 1 < ny {
            see(p + nx);
        }
    }
    // Most frequent; ties go to the higher class (tissue before bone before background).
    count
        .into_iter()
        .max_by_key(|&(c, n)| (n, c))
        .map(|(c, _)| c)
}

/// A tissue piece detached from the largest one and at least this fraction of its area is a
/// second body (another thigh in the slice), not a speck of segmentation: refused, not dropped.
const SECOND_BODY_FRACTION: f64 = 0.1;

/// Step 2: islands, holes, detached pieces (see the module documentation).
fn clean(
    grid: &mut ClassGrid,
    min_island_mm2: f64,
    class_name: &dyn Fn(u16) -> String,
    warnings: &mut Vec<String>,
) -> Result<(), GeometryError> {
    let pa = grid.pixel_area();
    // (from, to) -> (pieces, area)
    let mut merged: BTreeMap<(u16, u16), (usize, f64)> = BTreeMap::new();
    let mut holes = (0usize, 0.0f64);
    for _round in 0..20 {
        let (id, comps) = components(grid, |a, b| a == b);
        let mut changed = false;
        for (k, comp) in comps.iter().enumerate() {
            let area = comp.pixels.len() as f64 * pa;
            let hole = comp.class == BACKGROUND && !comp.touches_border;
            if !(hole || area < min_island_mm2) {
                continue;
            }
            let Some(to) = bordering_class(grid, &id, k, &comp.pixels) else {
                continue;
            };
            if to == comp.class {
                continue;
            }
            for &p in &comp.pixels {
                grid.class[p] = to;
            }
            changed = true;
            if hole {
                holes.0 += 1;
                holes.1 += area;
            } else {
                let e = merged.entry((comp.class, to)).or_insert((0, 0.0));
                e.0 += 1;
                e.1 += area;
            }
        }
        if !changed {
            break;
        }
    }
    for ((from, to), (n, a)) in merged {
        warnings.push(format!(
            "dropped {n} island(s) of {} smaller than {min_island_mm2} mm² ({a:.2} mm² in all), merged into {}",
            class_name(from),
            class_name(to)
        ));
    }
    if holes.0 > 0 {
        warnings.push(format!(
            "filled {} unlabelled hole(s) inside the body ({:.2} mm² in all) with the tissue around them",
            holes.0, holes.1
        ));
    }
    // Keep the largest tissue piece; drop other tissue pieces and bone that does not touch it.
    let is_tissue = |c: u16| c >= FIRST_REGION;
    let (id, comps) = components(grid, |a, b| is_tissue(a) == is_tissue(b));
    let main = comps
        .iter()
        .enumerate()
        .filter(|(_, c)| is_tissue(c.class))
        .max_by_key(|(_, c)| c.pixels.len())
        .map(|(k, _)| k);
    let Some(main) = main else { return Ok(()) };
    let main_pixels = comps[main].pixels.len();
    let mut bodies: Vec<usize> = comps
        .iter()
        .filter(|c| {
            is_tissue(c.class) && c.pixels.len() as f64 >= SECOND_BODY_FRACTION * main_pixels as f64
        })
        .map(|c| c.pixels.len())
        .collect();
    if bodies.len() > 1 {
        bodies.sort_unstable_by(|a, b| b.cmp(a));
        return Err(GeometryError::SeveralBodies {
            count: bodies.len(),
            areas: bodies
                .iter()
                .map(|&n| format!("{:.1}", n as f64 * pa))
                .collect::<Vec<_>>()
                .join(", "),
            percent: 100.0 * SECOND_BODY_FRACTION,
        });
    }
    let mut detached = (0usize, 0.0f64);
    for (k, comp) in comps.iter().enumerate() {
        if k != main && is_tissue(comp.class) {
            detached.0 += 1;
            detached.1 += comp.pixels.len() as f64 * pa;
            for &p in &comp.pixels {
                grid.class[p] = BACKGROUND;
            }
        }
    }
    if detached.0 > 0 {
        warnings.push(format!(
            "dropped {} tissue piece(s) not connected to the main cross-section ({:.1} mm² in all)",
            detached.0, detached.1
        ));
    }
    let (bid, bcomps) = components(grid, |a, b| a == b);
    let _ = id;
    let mut loose = (0usize, 0.0f64);
    for (k, comp) in bcomps.iter().enumerate() {
        if comp.class != BONE {
            continue;
        }
        let touches = {
            let nx = grid.nx;
            comp.pixels.iter().any(|&p| {
                let (i, j) = (p % nx, p / nx);
                let mut n = Vec::with_capacity(4);
                if i > 0 {
                    n.push(p - 1);
                }
                if i + 1 < nx {
                    n.push(p + 1);
                }
                if j > 0 {
                    n.push(p - nx);
                }
                if j + 1 < grid.ny {
                    n.push(p + nx);
                }
                n.into_iter()
                    .any(|q| bid[q] != k && is_tissue(grid.class[q]))
            })
        };
        if !touches {
            loose.0 += 1;
            loose.1 += comp.pixels.len() as f64 * pa;
            for &p in &comp.pixels {
                grid.class[p] = BACKGROUND;
            }
        }
    }
    if loose.0 > 0 {
        warnings.push(format!(
            "ignored {} bone piece(s) that touch no tissue ({:.1} mm²)",
            loose.0, loose.1
        ));
    }
    Ok(())
}

// ---------------------------------------------------------------------------------------------
// Interface curves on the pixel corners.

/// A curve between two junctions (`ends` = their corner ids), or a closed loop (`ends` = None,
/// first point not repeated).
#[derive(Debug, Clone)]
pub(crate) struct Chain {
    pub points: Vec<[f64; 2]>,
    pub ends: Option<[usize; 2]>,
}

/// Step 3. The grid is padded by one background pixel so that every curve is closed or ends at
/// junctions. Corner `(I, J)` of the padded grid is at `origin + ((I-1) sx, (J-1) sy)`.
fn trace_chains(grid: &ClassGrid) -> Vec<Chain> {
    let (px, py) = (grid.nx + 2, grid.ny + 2);
    let class = |i: isize, j: isize| -> u16 {
        if i < 1 || j < 1 || i > grid.nx as isize || j > grid.ny as isize {
            BACKGROUND
        } else {
            grid.class[(j as usize - 1) * grid.nx + (i as usize - 1)]
        }
    };
    let cw = px + 1; // corners per row
    let corner = |i: usize, j: usize| j * cw + i;
    let n_corners = cw * (py + 1);
    // Edge ids: horizontal edge from corner (i, j) to (i+1, j) is 2*corner, vertical edge from
    // (i, j) to (i, j+1) is 2*corner + 1.
    let mut boundary = vec![false; 2 * n_corners];
    for j in 0..=py {
        for i in 0..=px {
            let (ii, jj) = (i as isize, j as isize);
            if i < px && j > 0 && j < py && class(ii, jj - 1) != class(ii, jj) {
                boundary[2 * corner(i, j)] = true;
            }
            if j < py && i > 0 && i < px && class(ii - 1, jj) != class(ii, jj) {
                boundary[2 * corner(i, j) + 1] = true;
            }
        }
    }
    // The boundary edges at corner c: (edge id, other corner).
    let incident = |c: usize| -> Vec<(usize, usize)> {
        let (i, j) = (c % cw, c / cw);
        let mut v = Vec::with_capacity(4);
        if i < px && boundary[2 * c] {
            v.push((2 * c, c + 1));
        }
        if i > 0 && boundary[2 * (c - 1)] {
            v.push((2 * (c - 1), c - 1));
        }
        if j < py && boundary[2 * c + 1] {
            v.push((2 * c + 1, c + cw));
        }
        if j > 0 && boundary[2 * (c - cw) + 1] {
            v.push((2 * (c - cw) + 1, c - cw));
        }
        v
    };
    let pos = |c: usize| -> [f64; 2] {
        let (i, j) = (c % cw, c / cw);
        [
            grid.origin[0] + (i as f64 - 1.0) * grid.sx,
            grid.origin[1] + (j as f64 - 1.0) * grid.sy,
        ]
    };
    let degree: Vec<u8> = (0..n_corners).map(|c| incident(c).len() as u8).collect();
    let mut visited = vec![false; 2 * n_corners];
    let mut chains = Vec::new();
    // Open chains from junctions.
    for c in 0..n_corners {
        if degree[c] == 0 || degree[c] == 2 {
            continue;
        }
        for (e0, next0) in incident(c) {
            if visited[e0] {
                continue;
            }
            visited[e0] = true;
            let mut pts = vec![pos(c), pos(next0)];
            let mut cur = next0;
            while degree[cur] == 2 {
                let Some((e, nxt)) = incident(cur).into_iter().find(|(e, _)| !visited[*e]) else {
                    break;
                };
                visited[e] = true;
                pts.push(pos(nxt));
                cur = nxt;
            }
            chains.push(Chain {
                points: pts,
                ends: Some([c, cur]),
            });
        }
    }
    // Closed loops (every corner of degree 2).
    for c in 0..n_corners {
        if degree[c] != 2 {
            continue;
        }
        let inc = incident(c);
        let Some(&(e0, next0)) = inc.iter().find(|(e, _)| !visited[*e]) else {
            continue;
        };
        visited[e0] = true;
        let mut pts = vec![pos(c)];
        let mut cur = next0;
        while cur != c {
            pts.push(pos(cur));
            let Some((e, nxt)) = incident(cur).into_iter().find(|(e, _)| !visited[*e]) else {
                break;
            };
            visited[e] = true;
            cur = nxt;
        }
        chains.push(Chain {
            points: pts,
            ends: None,
        });
    }
    chains
}

/// Step 4: Taubin λ|μ smoothing; the ends of open chains stay put.
fn taubin(mut chain: Chain, pairs: usize) -> Chain {
    let n = chain.points.len();
    let closed = chain.ends.is_none();
    if n < 3 {
        return chain;
    }
    let mut next = chain.points.clone();
    for _ in 0..pairs {
        for factor in [0.5, -0.53] {
            for k in 0..n {
                let (prev, nxt) = if closed {
                    ((k + n - 1) % n, (k + 1) % n)
                } else if k == 0 || k == n - 1 {
                    next[k] = chain.points[k];
                    continue;
                } else {
                    (k - 1, k + 1)
                };
                let p = chain.points[k];
                let (a, b) = (chain.points[prev], chain.points[nxt]);
                next[k] = [
                    p[0] + factor * (0.5 * (a[0] + b[0]) - p[0]),
                    p[1] + factor * (0.5 * (a[1] + b[1]) - p[1]),
                ];
            }
            std::mem::swap(&mut chain.points, &mut next);
        }
    }
    chain
}

/// Points at equal arc length along a polyline: `segments` segments; an open chain keeps both
/// ends, a closed one returns `segments` points (first not repeated).
fn resample(points: &[[f64; 2]], closed: bool, segments: usize) -> Vec<[f64; 2]> {
    let mut pts = points.to_vec();
    if closed {
        pts.push(points[0]);
    }
    let mut s = vec![0.0];
    for w in pts.windows(2) {
        let d = (w[1][0] - w[0][0]).hypot(w[1][1] - w[0][1]);
        s.push(s.last().unwrap() + d);
    }
    let total = *s.last().unwrap();
    let count = if closed { segments } else { segments + 1 };
    let mut out = Vec::with_capacity(count);
    let mut seg = 0;
    for k in 0..count {
        let t = total * k as f64 / segments as f64;
        while seg + 2 < s.len() && s[seg + 1] < t {
            seg += 1;
        }
        let len = s[seg + 1] - s[seg];
        let u = if len > 0.0 {
            ((t - s[seg]) / len).clamp(0.0, 1.0)
        } else {
            0.0
        };
        let (a, b) = (pts[seg], pts[seg + 1]);
        out.push([a[0] + u * (b[0] - a[0]), a[1] + u * (b[1] - a[1])]);
    }
    if !closed {
        out[0] = points[0];
        *out.last_mut().unwrap() = *points.last().unwrap();
    }
    out
}

fn polyline_length(points: &[[f64; 2]], closed: bool) -> f64 {
    let n = points.len();
    let m = if closed { n } else { n - 1 };
    (0..m)
        .map(|k| {
            let (a, b) = (points[k], points[(k + 1) % n]);
            (b[0] - a[0]).hypot(b[1] - a[1])
        })
        .sum()
}

// ---------------------------------------------------------------------------------------------
// Triangulation, classification, quads.

/// Target triangle area per target quad (three quads per triangle).
const QUADS_PER_TRIANGLE: f64 = 3.0;
/// Refinement area bound relative to the target triangle area: refined triangles come out
/// smaller than the bound; this factor was calibrated so that the quad count is about
/// `area / h²` (checked by the parametric-thigh tests).
const AREA_BOUND_FACTOR: f64 = 1.6;

/// Steps 5–7.
fn triangulate_and_split(
    grid: &ClassGrid,
    chains: &[Chain],
    names: &[String],
    options: &MeshOptions,
) -> Result<GeneratedMesh, GeometryError> {
    let h = options.element_size_mm;
    let tri_area = QUADS_PER_TRIANGLE * h * h;
    // Curves are resampled every 2h, so that the quad faces along them (half a triangle edge)
    // are h long: interior triangles of the target area are equilateral with edges of 2.6h,
    // slightly longer, which the refinement grades smoothly.
    let spacing = 2.0 * h;
    let mut cdt: ConstrainedDelaunayTriangulation<Point2<f64>> =
        ConstrainedDelaunayTriangulation::new();
    let mut junction: HashMap<usize, FixedVertexHandle> = HashMap::new();
    let insert = |cdt: &mut ConstrainedDelaunayTriangulation<Point2<f64>>, p: [f64; 2]| {
        cdt.insert(Point2::new(p[0], p[1]))
            .map_err(|e| GeometryError::Meshing(format!("cannot insert point {p:?}: {e:?}")))
    };
    for chain in chains {
        let closed = chain.ends.is_none();
        let len = polyline_length(&chain.points, closed);
        let min_segments = if closed { 12 } else { 1 };
        let segments = ((len / spacing).round() as usize)
            .max(min_segments)
            .min(if closed {
                chain.points.len()
            } else {
                chain.points.len() - 1
            })
            .max(if closed { 3 } else { 1 });
        let pts = resample(&chain.points, closed, segments);
        let mut handles = Vec::with_capacity(pts.len());
        for (k, &p) in pts.iter().enumerate() {
            let end = match chain.ends {
                Some([a, _]) if k == 0 => Some(a),
                Some([_, b]) if k == pts.len() - 1 => Some(b),
                _ => None,
            };
            let hdl = match end {
                Some(c) => match junction.get(&c) {
                    Some(&v) => v,
                    None => {
                        let v = insert(&mut cdt, p)?;
                        junction.insert(c, v);
                        v
                    }
                },
                None => insert(&mut cdt, p)?,
            };
            handles.push(hdl);
        }
        let m = handles.len();
        let pairs = if closed { m } else { m - 1 };
        for k in 0..pairs {
            let (a, b) = (handles[k], handles[(k + 1) % m]);
            if a != b {
                cdt.add_constraint_and_split(a, b, |p| p);
            }
        }
    }
    // A frame of constraint edges around everything, a few triangles away from the skin: the
    // refinement then never meets the convex hull, whose slivers would otherwise make it insert
    // circumcentres outside the hull and cascade along the skin.
    let margin = 3.0 * spacing;
    let lo = [grid.origin[0] - margin, grid.origin[1] - margin];
    let hi = [
        grid.origin[0] + grid.nx as f64 * grid.sx + margin,
        grid.origin[1] + grid.ny as f64 * grid.sy + margin,
    ];
    let frame = [lo, [hi[0], lo[1]], hi, [lo[0], hi[1]]];
    let mut frame_pts = Vec::new();
    for k in 0..4 {
        let (a, b) = (frame[k], frame[(k + 1) % 4]);
        let n = (((b[0] - a[0]).hypot(b[1] - a[1]) / spacing).ceil() as usize).max(1);
        for t in 0..n {
            let u = t as f64 / n as f64;
            frame_pts.push([a[0] + u * (b[0] - a[0]), a[1] + u * (b[1] - a[1])]);
        }
    }
    let frame_handles = frame_pts
        .iter()
        .map(|&p| insert(&mut cdt, p))
        .collect::<Result<Vec<_>, _>>()?;
    for k in 0..frame_handles.len() {
        cdt.add_constraint(
            frame_handles[k],
            frame_handles[(k + 1) % frame_handles.len()],
        );
    }
    let domain_area = (hi[0] - lo[0]) * (hi[1] - lo[1]);
    let params = RefinementParameters::<f64>::new()
        .with_angle_limit(AngleLimit::from_deg(30.0))
        .with_max_allowed_area(AREA_BOUND_FACTOR * tri_area)
        .with_max_additional_vertices(20 * (domain_area / tri_area) as usize + 100_000);
    let result = cdt.refine(params);

    if !result.refinement_complete {
        return Err(GeometryError::Meshing(
            "the triangulation refinement did not finish (too many vertices); try a larger element size".into(),
        ));
    }

    // Faces: vertices, constraint flags, neighbours (None = outer face).
    let n_faces = cdt.num_all_faces();
    let mut fverts = vec![[0usize; 3]; n_faces];
    let mut fnbr = vec![[None::<usize>; 3]; n_faces];
    let mut fcons = vec![[false; 3]; n_faces];
    let mut farea = vec![0.0; n_faces];
    let mut fcent = vec![[0.0; 2]; n_faces];
    let mut inner = vec![false; n_faces];
    for f in cdt.inner_faces() {
        let k = f.fix().index();
        inner[k] = true;
        let vs = f.vertices();
        fverts[k] = vs.map(|v| v.fix().index());
        let edges = f.adjacent_edges();
        for e in 0..3 {
            fcons[k][e] = edges[e].is_constraint_edge();
            fnbr[k][e] = edges[e].rev().face().as_inner().map(|g| g.fix().index());
        }
        farea[k] = f.area();
        let c = f.center();
        fcent[k] = [c.x, c.y];
    }
    let vpos: Vec<[f64; 2]> = cdt
        .vertices()
        .map(|v| {
            let p = v.position();
            [p.x, p.y]
        })
        .collect();

    // Constraint-bounded components and their classes.
    let mut comp = vec![usize::MAX; n_faces];
    let mut votes: Vec<BTreeMap<u16, f64>> = Vec::new();
    let mut stack = Vec::new();
    for start in 0..n_faces {
        if !inner[start] || comp[start] != usize::MAX {
            continue;
        }
        let c = votes.len();
        votes.push(BTreeMap::new());
        comp[start] = c;
        stack.push(start);
        while let Some(f) = stack.pop() {
            *votes[c].entry(grid.class_at(fcent[f])).or_insert(0.0) += farea[f];
            for e in 0..3 {
                if let (false, Some(g)) = (fcons[f][e], fnbr[f][e]) {
                    if comp[g] == usize::MAX {
                        comp[g] = c;
                        stack.push(g);
                    }
                }
            }
        }
    }
    let comp_class: Vec<u16> = votes
        .iter()
        .map(|v| {
            v.iter()
                .max_by(|a, b| a.1.total_cmp(b.1))
                .map_or(BACKGROUND, |(&c, _)| c)
        })
        .collect();
    let face_class = |f: Option<usize>| -> u16 { f.map_or(BACKGROUND, |f| comp_class[comp[f]]) };

    // Quads.
    let mut g = GeneratedMesh::default();
    let mesh = &mut g.mesh;
    let mut vnode: HashMap<usize, usize> = HashMap::new();
    let mut mid: HashMap<(usize, usize), usize> = HashMap::new();
    let mut fixed: Vec<bool> = Vec::new();
    let mut region_sets: Vec<Vec<usize>> = vec![Vec::new(); names.len()];
    let mut skin = Vec::new();
    let mut femur = Vec::new();
    for f in 0..n_faces {
        if !inner[f] {
            continue;
        }
        let cls = face_class(Some(f));
        if cls < FIRST_REGION {
            continue;
        }
        let vs = fverts[f];
        let mut feature = [false; 3];
        for e in 0..3 {
            feature[e] = fcons[f][e] || face_class(fnbr[f][e]) != cls;
        }
        let mut node_of_vertex = |v: usize, mesh: &mut Mesh, fixed: &mut Vec<bool>| -> usize {
            *vnode.entry(v).or_insert_with(|| {
                fixed.push(false);
                mesh.add_node(vpos[v])
            })
        };
        let vn: [usize; 3] = [
            node_of_vertex(vs[0], mesh, &mut fixed),
            node_of_vertex(vs[1], mesh, &mut fixed),
            node_of_vertex(vs[2], mesh, &mut fixed),
        ];
        let mut mn = [0usize; 3];
        for e in 0..3 {
            let (a, b) = (vs[e], vs[(e + 1) % 3]);
            let key = (a.min(b), a.max(b));
            mn[e] = *mid.entry(key).or_insert_with(|| {
                fixed.push(false);
                let (p, q) = (vpos[a], vpos[b]);
                mesh.add_node([0.5 * (p[0] + q[0]), 0.5 * (p[1] + q[1])])
            });
            if feature[e] {
                fixed[mn[e]] = true;
                fixed[vn[e]] = true;
                fixed[vn[(e + 1) % 3]] = true;
            }
        }
        fixed.push(false);
        let c = mesh.add_node(fcent[f]);
        let mut quads = [0usize; 3];
        for k in 0..3 {
            let conn = [vn[k], mn[k], c, mn[(k + 2) % 3]];
            let e = mesh.add_element(Element::quad(options.kind, conn));
            region_sets[(cls - FIRST_REGION) as usize].push(e);
            quads[k] = e;
        }
        for e in 0..3 {
            let target = match face_class(fnbr[f][e]) {
                BACKGROUND => Some(&mut skin),
                BONE => Some(&mut femur),
                _ => None,
            };
            if let Some(list) = target {
                // Edge e (v_e -> v_e+1) is face 0 of quad e and face 3 of quad e+1.
                list.push((quads[e], 0));
                list.push((quads[(e + 1) % 3], 3));
            }
        }
    }
    if mesh.elements.is_empty() {
        return Err(GeometryError::NoTissue(
            "no triangle fell inside the tissue (element size too large for the image?)".into(),
        ));
    }
    let adjacency = Adjacency::new(mesh);
    snap_to_curves(mesh, &fixed, chains, spacing, &adjacency);
    relax(mesh, &fixed, 4, &adjacency);
    for (r, set) in region_sets.into_iter().enumerate() {
        if !set.is_empty() {
            mesh.element_sets.insert(names[r].clone(), set);
        }
    }
    let nodes_of = |faces: &[(usize, usize)], mesh: &Mesh| -> Vec<usize> {
        let mut v: Vec<usize> = faces
            .iter()
            .flat_map(|&(e, f)| mesh.elements[e].face_nodes(f))
            .collect();
        v.sort_unstable();
        v.dedup();
        v
    };
    let femur_nodes = nodes_of(&femur, mesh);
    let skin_nodes = nodes_of(&skin, mesh);
    mesh.node_sets.insert("FEMUR".into(), femur_nodes);
    mesh.node_sets.insert("SKIN".into(), skin_nodes);
    femur.sort_unstable();
    skin.sort_unstable();
    g.surfaces.insert("SKIN".into(), skin);
    g.surfaces.insert("FEMUR".into(), femur);
    Ok(g)
}

/// Elements around each node and nodes joined to it by an element edge.
struct Adjacency {
    node_elems: Vec<Vec<usize>>,
    nbrs: Vec<Vec<usize>>,
}

impl Adjacency {
    fn new(mesh: &Mesh) -> Self {
        let n = mesh.nodes.len();
        let mut node_elems: Vec<Vec<usize>> = vec![Vec::new(); n];
        let mut nbrs: Vec<Vec<usize>> = vec![Vec::new(); n];
        for (e, el) in mesh.elements.iter().enumerate() {
            let c = el.nodes();
            for k in 0..c.len() {
                node_elems[c[k]].push(e);
                let (a, b) = (c[k], c[(k + 1) % c.len()]);
                if !nbrs[a].contains(&b) {
                    nbrs[a].push(b);
                }
                if !nbrs[b].contains(&a) {
                    nbrs[b].push(a);
                }
            }
        }
        Adjacency { node_elems, nbrs }
    }

    /// Smallest scaled Jacobian of the elements around node `v`.
    fn worst(&self, mesh: &Mesh, v: usize) -> f64 {
        self.node_elems[v]
            .iter()
            .map(|&e| scaled_jacobian(&mesh.element_coords(e).0))
            .fold(f64::INFINITY, f64::min)
    }

    /// Largest aspect ratio of the elements around node `v`.
    fn stretch(&self, mesh: &Mesh, v: usize) -> f64 {
        self.node_elems[v]
            .iter()
            .map(|&e| aspect_ratio(&mesh.element_coords(e).0))
            .fold(0.0, f64::max)
    }
}

/// Moves the nodes on the curves (`on_curve`), which lie on chords between resampled curve
/// points, to the nearest point of the smoothed curve: the boundary then follows the curve at
/// the quad-edge resolution instead of the triangle-edge one (a quarter of the chord error).
/// A move is kept only if the elements around the node keep a scaled Jacobian above
/// min(before, 0.3) and an aspect ratio below max(before, 5).
fn snap_to_curves(
    mesh: &mut Mesh,
    on_curve: &[bool],
    chains: &[Chain],
    spacing: f64,
    adj: &Adjacency,
) {
    let cell = spacing;
    let mut segs: Vec<([f64; 2], [f64; 2])> = Vec::new();
    for c in chains {
        let n = c.points.len();
        let m = if c.ends.is_none() { n } else { n - 1 };
        for k in 0..m {
            segs.push((c.points[k], c.points[(k + 1) % n]));
        }
    }
    let key = |x: f64, y: f64| ((x / cell).floor() as i64, (y / cell).floor() as i64);
    let mut grid: HashMap<(i64, i64), Vec<usize>> = HashMap::new();
    for (s, (a, b)) in segs.iter().enumerate() {
        let (i0, j0) = key(a[0].min(b[0]), a[1].min(b[1]));
        let (i1, j1) = key(a[0].max(b[0]), a[1].max(b[1]));
        for i in i0..=i1 {
            for j in j0..=j1 {
                grid.entry((i, j)).or_default().push(s);
            }
        }
    }
    let radius = 0.25 * spacing;
    for v in 0..mesh.nodes.len() {
        if !on_curve[v] || adj.node_elems[v].is_empty() {
            continue;
        }
        let p = mesh.nodes[v];
        let (ci, cj) = key(p[0], p[1]);
        let mut best = (radius * radius, None);
        for i in ci - 1..=ci + 1 {
            for j in cj - 1..=cj + 1 {
                for &s in grid.get(&(i, j)).map_or(&[][..], Vec::as_slice) {
                    let (a, b) = segs[s];
                    let d = [b[0] - a[0], b[1] - a[1]];
                    let l2 = d[0] * d[0] + d[1] * d[1];
                    let t = if l2 > 0.0 {
                        (((p[0] - a[0]) * d[0] + (p[1] - a[1]) * d[1]) / l2).clamp(0.0, 1.0)
                    } else {
                        0.0
                    };
                    let q = [a[0] + t * d[0], a[1] + t * d[1]];
                    let dist2 = (q[0] - p[0]).powi(2) + (q[1] - p[1]).powi(2);
                    if dist2 < best.0 {
                        best = (dist2, Some(q));
                    }
                }
            }
        }
        if let (_, Some(q)) = best {
            let (before, stretch) = (adj.worst(mesh, v), adj.stretch(mesh, v));
            mesh.nodes[v] = q;
            if adj.worst(mesh, v) < before.min(0.3) || adj.stretch(mesh, v) > stretch.max(5.0) {
                mesh.nodes[v] = p;
            }
        }
    }
}

/// Step 7: guarded Laplacian smoothing of the free nodes.
fn relax(mesh: &mut Mesh, fixed: &[bool], sweeps: usize, adj: &Adjacency) {
    let n = mesh.nodes.len();
    let nbrs = &adj.nbrs;
    for _ in 0..sweeps {
        for v in 0..n {
            if fixed[v] || nbrs[v].is_empty() {
                continue;
            }
            let k = nbrs[v].len() as f64;
            let mut avg = [0.0; 2];
            for &u in &nbrs[v] {
                avg[0] += mesh.nodes[u][0] / k;
                avg[1] += mesh.nodes[u][1] / k;
            }
            let old = mesh.nodes[v];
            let before = adj.worst(mesh, v);
            mesh.nodes[v] = avg;
            let after = adj.worst(mesh, v);
            if after < before.min(0.9) {
                mesh.nodes[v] = old;
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn disk_grid(n: usize, r_px: f64) -> ClassGrid {
        let c = n as f64 / 2.0;
        let mut class = vec![BACKGROUND; n * n];
        for j in 0..n {
            for i in 0..n {
                let d = ((i as f64 + 0.5 - c).powi(2) + (j as f64 + 0.5 - c).powi(2)).sqrt();
                if d < r_px * 0.4 {
                    class[j * n + i] = BONE;
                } else if d < r_px {
                    class[j * n + i] = FIRST_REGION;
                }
            }
        }
        ClassGrid {
            nx: n,
            ny: n,
            sx: 1.0,
            sy: 1.0,
            origin: [0.0, 0.0],
            class,
        }
    }

    #[test]
    fn chains_of_an_annulus_are_two_loops() {
        let g = disk_grid(40, 15.0);
        let chains = trace_chains(&g);
        assert_eq!(chains.len(), 2);
        assert!(chains.iter().all(|c| c.ends.is_none()));
        // Staircase perimeters: 4/pi times the circle's (Manhattan length), up to pixelation.
        let outer = chains
            .iter()
            .map(|c| polyline_length(&c.points, true))
            .fold(0.0, f64::max);
        assert!((outer / (8.0 * 15.0) - 1.0).abs() < 0.05, "{outer}");
        // Taubin smoothing brings the length close to the circle's without shrinking it.
        let smooth = taubin(
            chains.into_iter().max_by_key(|c| c.points.len()).unwrap(),
            40,
        );
        let l = polyline_length(&smooth.points, true);
        assert!(
            (l / (2.0 * std::f64::consts::PI * 15.0) - 1.0).abs() < 0.02,
            "{l}"
        );
    }

    #[test]
    fn resample_keeps_ends_and_counts() {
        let pts = [[0.0, 0.0], [1.0, 0.0], [3.0, 0.0]];
        let r = resample(&pts, false, 3);
        assert_eq!(r.len(), 4);
        assert!((r[1][0] - 1.0).abs() < 1e-12 && (r[2][0] - 2.0).abs() < 1e-12);
        let sq = [[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 1.0]];
        let r = resample(&sq, true, 8);
        assert_eq!(r.len(), 8);
        assert!((r[1][0] - 0.5).abs() < 1e-12);
    }

    #[test]
    fn islands_and_holes_are_cleaned() {
        let mut g = disk_grid(40, 15.0);
        // A 2-pixel island of bone in the tissue, a 1-pixel hole, a detached tissue speck.
        g.class[10 * 40 + 30] = BONE;
        g.class[10 * 40 + 31] = BONE;
        g.class[28 * 40 + 12] = BACKGROUND;
        g.class[40 + 1] = FIRST_REGION;
        let mut w = Vec::new();
        clean(&mut g, 3.0, &|c| format!("class {c}"), &mut w).unwrap();
        assert_eq!(g.class[10 * 40 + 30], FIRST_REGION);
        assert_eq!(g.class[28 * 40 + 12], FIRST_REGION);
        assert_eq!(g.class[40 + 1], BACKGROUND);
        assert_eq!(w.len(), 3, "{w:?}");
    }

    /// Two separate bodies of tissue (two thighs in one slice) are refused with their areas;
    /// a piece below a tenth of the largest is a speck, dropped with a warning.
    #[test]
    fn two_bodies_are_refused_with_their_areas() {
        let (nx, ny) = (60, 20);
        let mut g = ClassGrid {
            nx,
            ny,
            sx: 0.5,
            sy: 0.5,
            origin: [0.0, 0.0],
            class: vec![BACKGROUND; nx * ny],
        };
        let mut put = |i0: usize, w: usize| {
            for j in 5..15 {
                for i in i0..i0 + w {
                    g.class[j * nx + i] = FIRST_REGION;
                }
            }
        };
        put(5, 20);
        put(35, 16);
        let mut w = Vec::new();
        let e = clean(&mut g, 0.0, &|c| format!("class {c}"), &mut w)
            .unwrap_err()
            .to_string();
        // 200 and 160 pixels of 0.25 mm².
        assert!(e.contains("2 separate bodies of 50.0, 40.0 mm²"), "{e}");
        // A piece of 10 x 1 pixels next to the 200-pixel body: a speck.
        for i in 35..60 {
            for j in 0..ny {
                g.class[j * nx + i] = BACKGROUND;
            }
        }
        for i in 40..50 {
            g.class[10 * nx + i] = FIRST_REGION;
        }
        let mut w = Vec::new();
        clean(&mut g, 0.0, &|c| format!("class {c}"), &mut w).unwrap();
        assert_eq!(g.class[10 * nx + 45], BACKGROUND);
        assert!(
            w.iter().any(|m| m.contains("dropped 1 tissue piece")),
            "{w:?}"
        );
    }
}
