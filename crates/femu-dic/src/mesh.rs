//! The region of interest and the structured Q4 mesh laid over it.
//!
//! Elements are squares of `h x h` pixels aligned with the pixel grid. Pixel centres sit at
//! integer coordinates and nodes on pixel edges, so element `(ex, ey)` covers the pixels
//! `x0 + ex h .. x0 + (ex+1) h` (and the same in y) exactly, and its pixel `(i, j)` has the
//! local coordinates `ξ = (i + ½)/h`, `η = (j + ½)/h` in `[0, 1]²`:
//!
//! ```text
//!  (x0 − ½, y0 − ½)                 x →
//!        3 ───────── 2      node order of an element: 0 (ξ=0,η=0), 1 (1,0), 2 (1,1), 3 (0,1)
//!        │ · · · · · │      (y points down, as in the image)
//!        │ · · · · · │      N0 = (1−ξ)(1−η), N1 = ξ(1−η), N2 = ξη, N3 = (1−ξ)η
//!        0 ───────── 1
//! ```
//!
//! (The drawing shows η increasing upwards for readability; in the image it increases with the
//! row index.) With a mask, only the elements whose pixels all lie inside the mask are kept,
//! so burned-in text and scales never enter the correlation.

use crate::error::DicError;
use crate::image::GreyImage;

/// A rectangle of pixels: columns `x .. x + w`, rows `y .. y + h`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize)]
pub struct Rect {
    pub x: usize,
    pub y: usize,
    pub w: usize,
    pub h: usize,
}

impl Rect {
    /// Parses the `--roi` of every command: `x,y,WxH` in pixels, the top-left corner then the
    /// size (`115,65,570x450`: columns 115..685, rows 65..515). Four plain numbers, which
    /// `femu dic` once read as `x,y,w,h` and `us-settings`/`us-noise` as corners
    /// `x0,y0,x1,y1`, are refused with both readings written in this form (issue 32.12: either
    /// command took the other's form without a word).
    pub fn parse(s: &str) -> Result<Self, DicError> {
        let bad = |why: String| DicError::Roi(format!("--roi '{s}': {why}"));
        let form = "give x,y,WxH in pixels (the top-left corner, then the width and height, e.g. 115,65,570x450)";
        let v: Vec<&str> = s.split(',').map(str::trim).collect();
        let int = |t: &str| t.parse::<usize>().ok();
        if let [a, b, c, d] = v[..] {
            if let (Some(a), Some(b), Some(c), Some(d)) = (int(a), int(b), int(c), int(d)) {
                let corners = if c > a && d > b {
                    format!(
                        ", or {a},{b},{}x{} if {c},{d} is the opposite corner",
                        c - a,
                        d - b
                    )
                } else {
                    String::new()
                };
                return Err(bad(format!(
                    "four numbers are ambiguous (width and height, or the opposite corner): write {a},{b},{c}x{d} if {c},{d} are the width and height{corners}"
                )));
            }
        }
        let [x, y, size] = v[..] else {
            return Err(bad(form.into()));
        };
        let (w, h) = size
            .split_once(['x', 'X'])
            .map(|(w, h)| (int(w.trim()), int(h.trim())))
            .unwrap_or((None, None));
        match (int(x), int(y), w, h) {
            (Some(x), Some(y), Some(w), Some(h)) if w > 0 && h > 0 => Ok(Rect { x, y, w, h }),
            (Some(_), Some(_), Some(_), Some(_)) => {
                Err(bad("the width and height must be positive".into()))
            }
            _ => Err(bad(form.into())),
        }
    }
}

/// Where to measure: a rectangle or a mask (`true` inside), both in reference-image pixels.
#[derive(Debug, Clone)]
pub enum Roi {
    Rect(Rect),
    Mask {
        width: usize,
        height: usize,
        inside: Vec<bool>,
    },
}

impl Roi {
    /// A mask from an image: pixels with a grey level above half of the maximum are inside.
    pub fn mask_from_image(img: &GreyImage) -> Self {
        let max = img.data.iter().cloned().fold(0.0, f64::max);
        Roi::Mask {
            width: img.width,
            height: img.height,
            inside: img
                .data
                .iter()
                .map(|&v| max > 0.0 && v > 0.5 * max)
                .collect(),
        }
    }

    /// The ROI one pyramid level down (a coarse pixel is inside when its 4 fine pixels are).
    pub fn half(&self) -> Roi {
        match self {
            Roi::Rect(r) => Roi::Rect(Rect {
                x: r.x.div_ceil(2),
                y: r.y.div_ceil(2),
                w: (r.x + r.w) / 2 - r.x.div_ceil(2).min((r.x + r.w) / 2),
                h: (r.y + r.h) / 2 - r.y.div_ceil(2).min((r.y + r.h) / 2),
            }),
            Roi::Mask {
                width,
                height,
                inside,
            } => {
                let (w, h) = (width / 2, height / 2);
                let mut m = vec![false; w * h];
                for j in 0..h {
                    for i in 0..w {
                        m[j * w + i] = inside[2 * j * width + 2 * i]
                            && inside[2 * j * width + 2 * i + 1]
                            && inside[(2 * j + 1) * width + 2 * i]
                            && inside[(2 * j + 1) * width + 2 * i + 1];
                    }
                }
                Roi::Mask {
                    width: w,
                    height: h,
                    inside: m,
                }
            }
        }
    }

    /// The bounding box of the ROI, checked against an image of `width x height`.
    pub fn bounding_box(&self, width: usize, height: usize) -> Result<Rect, DicError> {
        match self {
            Roi::Rect(r) => {
                if r.w == 0 || r.h == 0 {
                    return Err(DicError::Roi(format!("{r:?} is empty")));
                }
                if r.x + r.w > width || r.y + r.h > height {
                    return Err(DicError::Roi(format!(
                        "{},{},{}x{} reaches column {} and row {}, outside the {width} x {height} px image",
                        r.x,
                        r.y,
                        r.w,
                        r.h,
                        r.x + r.w,
                        r.y + r.h
                    )));
                }
                Ok(*r)
            }
            Roi::Mask {
                width: mw,
                height: mh,
                inside,
            } => {
                if (*mw, *mh) != (width, height) {
                    return Err(DicError::Roi(format!(
                        "the mask is {mw} x {mh} px, the image {width} x {height} px"
                    )));
                }
                let (mut x0, mut y0, mut x1, mut y1) = (usize::MAX, usize::MAX, 0, 0);
                for (k, _) in inside.iter().enumerate().filter(|(_, &b)| b) {
                    let (x, y) = (k % width, k / width);
                    x0 = x0.min(x);
                    y0 = y0.min(y);
                    x1 = x1.max(x + 1);
                    y1 = y1.max(y + 1);
                }
                if x0 == usize::MAX {
                    return Err(DicError::Roi("the mask selects no pixel".into()));
                }
                Ok(Rect {
                    x: x0,
                    y: y0,
                    w: x1 - x0,
                    h: y1 - y0,
                })
            }
        }
    }

    fn contains(&self, x: usize, y: usize) -> bool {
        match self {
            Roi::Rect(_) => true,
            Roi::Mask { width, inside, .. } => inside[y * width + x],
        }
    }
}

/// A structured Q4 mesh over a region of interest.
#[derive(Debug, Clone)]
pub struct DicMesh {
    /// Element size (pixels).
    pub h: usize,
    /// Top-left pixel of element (0, 0).
    pub x0: usize,
    pub y0: usize,
    /// Elements of the grid along x and y (active or not).
    pub nx: usize,
    pub ny: usize,
    /// Grid indices `(ex, ey)` of the active elements.
    pub cells: Vec<(usize, usize)>,
    /// Node indices of each active element, in the order of the module drawing.
    pub conn: Vec<[usize; 4]>,
    /// Node coordinates (pixels).
    pub nodes: Vec<[f64; 2]>,
    /// Grid indices `(i, j)` of each node.
    pub node_grid: Vec<(usize, usize)>,
    /// `(nx + 1) (ny + 1)` entries: the node at grid point `(i, j)`, or `usize::MAX`.
    pub grid_node: Vec<usize>,
    /// `nx ny` entries: the active element at grid cell `(ex, ey)`, or `usize::MAX`.
    pub grid_cell: Vec<usize>,
}

impl DicMesh {
    /// Lays elements of `h` pixels over `roi` in an image of `width x height`.
    pub fn new(roi: &Roi, width: usize, height: usize, h: usize) -> Result<Self, DicError> {
        if h < 4 {
            return Err(DicError::option(
                "element size",
                format!("{h} px is below 4 px (too few pixels per element to be measurable)"),
            ));
        }
        let bb = roi.bounding_box(width, height)?;
        if h > bb.w || h > bb.h {
            return Err(DicError::option(
                "element size",
                format!(
                    "{h} px is larger than the region of interest ({} x {} px)",
                    bb.w, bb.h
                ),
            ));
        }
        let (nx, ny) = (bb.w / h, bb.h / h);
        let mut grid_cell = vec![usize::MAX; nx * ny];
        let mut cells = Vec::new();
        for ey in 0..ny {
            for ex in 0..nx {
                let (px, py) = (bb.x + ex * h, bb.y + ey * h);
                let all_in = (0..h).all(|j| (0..h).all(|i| roi.contains(px + i, py + j)));
                if all_in {
                    grid_cell[ey * nx + ex] = cells.len();
                    cells.push((ex, ey));
                }
            }
        }
        if cells.is_empty() {
            return Err(DicError::Roi(format!(
                "no element of {h} x {h} px fits entirely inside the mask"
            )));
        }
        let mut grid_node = vec![usize::MAX; (nx + 1) * (ny + 1)];
        let mut nodes = Vec::new();
        let mut node_grid = Vec::new();
        // Number nodes row by row so that the matrix has a narrow profile.
        for j in 0..=ny {
            for i in 0..=nx {
                let touches = [
                    (i, j),
                    (i.wrapping_sub(1), j),
                    (i, j.wrapping_sub(1)),
                    (i.wrapping_sub(1), j.wrapping_sub(1)),
                ]
                .iter()
                .any(|&(ex, ey)| ex < nx && ey < ny && grid_cell[ey * nx + ex] != usize::MAX);
                if touches {
                    grid_node[j * (nx + 1) + i] = nodes.len();
                    nodes.push([
                        bb.x as f64 - 0.5 + (i * h) as f64,
                        bb.y as f64 - 0.5 + (j * h) as f64,
                    ]);
                    node_grid.push((i, j));
                }
            }
        }
        let conn = cells
            .iter()
            .map(|&(ex, ey)| {
                let n = |i: usize, j: usize| grid_node[j * (nx + 1) + i];
                [n(ex, ey), n(ex + 1, ey), n(ex + 1, ey + 1), n(ex, ey + 1)]
            })
            .collect();
        Ok(DicMesh {
            h,
            x0: bb.x,
            y0: bb.y,
            nx,
            ny,
            cells,
            conn,
            nodes,
            node_grid,
            grid_node,
            grid_cell,
        })
    }

    /// Number of active elements.
    pub fn n_elements(&self) -> usize {
        self.cells.len()
    }

    /// Number of nodes.
    pub fn n_nodes(&self) -> usize {
        self.nodes.len()
    }

    /// Top-left pixel of active element `e`.
    pub fn element_origin(&self, e: usize) -> (usize, usize) {
        let (ex, ey) = self.cells[e];
        (self.x0 + ex * self.h, self.y0 + ey * self.h)
    }

    /// Shape functions `N0..N3` at local coordinates `(ξ, η)`.
    #[inline(always)]
    pub fn shape(xi: f64, eta: f64) -> [f64; 4] {
        [
            (1.0 - xi) * (1.0 - eta),
            xi * (1.0 - eta),
            xi * eta,
            (1.0 - xi) * eta,
        ]
    }

    /// The element containing the point `(x, y)` (pixels) and its local coordinates, or `None`
    /// outside the active elements. Points on a shared edge go to either element.
    pub fn locate(&self, x: f64, y: f64) -> Option<(usize, f64, f64)> {
        let h = self.h as f64;
        let sx = (x - (self.x0 as f64 - 0.5)) / h;
        let sy = (y - (self.y0 as f64 - 0.5)) / h;
        if !(sx >= 0.0 && sy >= 0.0 && sx <= self.nx as f64 && sy <= self.ny as f64) {
            return None;
        }
        let ex = (sx.floor() as usize).min(self.nx - 1);
        let ey = (sy.floor() as usize).min(self.ny - 1);
        let e = self.grid_cell[ey * self.nx + ex];
        (e != usize::MAX).then_some((e, sx - ex as f64, sy - ey as f64))
    }

    /// The displacement interpolated at `(x, y)` from nodal values `u` (`[ux, uy]` per node).
    pub fn interpolate(&self, u: &[[f64; 2]], x: f64, y: f64) -> Option<[f64; 2]> {
        let (e, xi, eta) = self.locate(x, y)?;
        Some(self.interpolate_in(u, e, xi, eta))
    }

    /// The nodal values `u` interpolated in element `e` at its local coordinates `(ξ, η)`.
    #[inline]
    pub fn interpolate_in(&self, u: &[[f64; 2]], e: usize, xi: f64, eta: f64) -> [f64; 2] {
        let n = Self::shape(xi, eta);
        let c = &self.conn[e];
        let mut v = [0.0; 2];
        for a in 0..4 {
            v[0] += n[a] * u[c[a]][0];
            v[1] += n[a] * u[c[a]][1];
        }
        v
    }

    /// Displacement gradient `[[∂ux/∂x, ∂ux/∂y], [∂uy/∂x, ∂uy/∂y]]` at the centre of element
    /// `e` (pixels per pixel).
    pub fn gradient_at_centre(&self, u: &[[f64; 2]], e: usize) -> [[f64; 2]; 2] {
        let h = self.h as f64;
        let dx = [-0.5 / h, 0.5 / h, 0.5 / h, -0.5 / h];
        let dy = [-0.5 / h, -0.5 / h, 0.5 / h, 0.5 / h];
        let c = &self.conn[e];
        let mut g = [[0.0; 2]; 2];
        for a in 0..4 {
            for i in 0..2 {
                g[i][0] += dx[a] * u[c[a]][i];
                g[i][1] += dy[a] * u[c[a]][i];
            }
        }
        g
    }

    /// Small-strain tensor `(εxx, εyy, εxy)` at the centre of element `e`.
    pub fn strain_at_centre(&self, u: &[[f64; 2]], e: usize) -> [f64; 3] {
        // dN/dξ and dN/dη at ξ = η = ½, divided by h.
        let h = self.h as f64;
        let dx = [-0.5 / h, 0.5 / h, 0.5 / h, -0.5 / h];
        let dy = [-0.5 / h, -0.5 / h, 0.5 / h, 0.5 / h];
        let c = &self.conn[e];
        let (mut uxx, mut uxy, mut uyx, mut uyy) = (0.0, 0.0, 0.0, 0.0);
        for a in 0..4 {
            uxx += dx[a] * u[c[a]][0];
            uxy += dy[a] * u[c[a]][0];
            uyx += dx[a] * u[c[a]][1];
            uyy += dy[a] * u[c[a]][1];
        }
        [uxx, uyy, 0.5 * (uxy + uyx)]
    }

    /// The mesh as a `femu_mesh::Mesh` (pixels), for VTU output.
    pub fn to_mesh(&self) -> femu_mesh::Mesh {
        let mut m = femu_mesh::Mesh::default();
        for p in &self.nodes {
            m.add_node(*p);
        }
        for (k, c) in self.conn.iter().enumerate() {
            m.elements
                .push(femu_mesh::Element::quad(femu_mesh::ElementKind::Cpe4, *c));
            m.element_labels.push(k as i64 + 1);
        }
        m
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn rectangle_mesh_covers_whole_elements() {
        let roi = Roi::Rect(Rect {
            x: 10,
            y: 20,
            w: 70,
            h: 33,
        });
        let m = DicMesh::new(&roi, 100, 60, 16).unwrap();
        assert_eq!((m.nx, m.ny), (4, 2));
        assert_eq!(m.n_elements(), 8);
        assert_eq!(m.n_nodes(), 15);
        assert_eq!(m.nodes[0], [9.5, 19.5]);
        assert_eq!(m.element_origin(5), (26, 36));
        // Pixel (26, 36) is the first pixel of element (1, 1): ξ = η = 1/32.
        let (e, xi, eta) = m.locate(26.0, 36.0).unwrap();
        assert_eq!(m.cells[e], (1, 1));
        assert!((xi - 1.0 / 32.0).abs() < 1e-12 && (eta - 1.0 / 32.0).abs() < 1e-12);
    }

    #[test]
    fn mask_keeps_elements_fully_inside() {
        let (w, h) = (40, 40);
        let inside: Vec<bool> = (0..w * h).map(|k| (k % w) < 30 && (k / w) < 20).collect();
        let roi = Roi::Mask {
            width: w,
            height: h,
            inside,
        };
        let m = DicMesh::new(&roi, w, h, 8).unwrap();
        assert_eq!((m.nx, m.ny), (3, 2));
        assert_eq!(m.n_elements(), 6);
        // An L-shaped mask drops the elements that straddle its edge.
        let inside: Vec<bool> = (0..w * h).map(|k| (k % w) < 16 || (k / w) < 8).collect();
        let roi = Roi::Mask {
            width: w,
            height: h,
            inside,
        };
        let m = DicMesh::new(&roi, w, h, 8).unwrap();
        assert_eq!(m.n_elements(), 5 + 2 * 4);
    }

    #[test]
    fn bad_rois_are_errors() {
        let r = |x, y, w, h| Roi::Rect(Rect { x, y, w, h });
        assert!(matches!(
            DicMesh::new(&r(90, 0, 20, 20), 100, 100, 8),
            Err(DicError::Roi(_))
        ));
        assert!(matches!(
            DicMesh::new(&r(0, 0, 0, 20), 100, 100, 8),
            Err(DicError::Roi(_))
        ));
        let e = DicMesh::new(&r(0, 0, 20, 20), 100, 100, 32).unwrap_err();
        assert!(
            e.to_string().contains("larger than the region of interest"),
            "{e}"
        );
        assert!(Rect::parse("1,2,3").is_err());
        assert!(Rect::parse("1,2,0x4").is_err());
        // Issue 32.12: the four-number forms are refused with both readings.
        let e = Rect::parse("115,65,685,515").unwrap_err().to_string();
        assert!(
            e.contains("115,65,685x515") && e.contains("115,65,570x450"),
            "{e}"
        );
        assert_eq!(
            Rect::parse("1, 2,3X4").unwrap(),
            Rect {
                x: 1,
                y: 2,
                w: 3,
                h: 4
            }
        );
    }

    #[test]
    fn strain_of_an_affine_field() {
        let roi = Roi::Rect(Rect {
            x: 0,
            y: 0,
            w: 32,
            h: 32,
        });
        let m = DicMesh::new(&roi, 32, 32, 16).unwrap();
        let u: Vec<[f64; 2]> = m
            .nodes
            .iter()
            .map(|p| [0.01 * p[0] + 0.02 * p[1], -0.03 * p[0] + 0.005 * p[1]])
            .collect();
        let s = m.strain_at_centre(&u, 3);
        assert!((s[0] - 0.01).abs() < 1e-12 && (s[1] - 0.005).abs() < 1e-12);
        assert!((s[2] - 0.5 * (0.02 - 0.03)).abs() < 1e-12);
        let v = m.interpolate(&u, 20.3, 7.7).unwrap();
        assert!((v[0] - (0.01 * 20.3 + 0.02 * 7.7)).abs() < 1e-12);
    }
}
