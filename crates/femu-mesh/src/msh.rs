//! Gmsh MSH 4.1 reader (ASCII).
//!
//! Written here rather than with the `mshio` crate: `mshio` 0.4 does not parse
//! `$PhysicalNames` (so groups would have no names) and its errors carry no line numbers. The
//! ASCII format needs only the sections `$MeshFormat`, `$PhysicalNames`, `$Entities`, `$Nodes`
//! and `$Elements`; other sections are skipped. Binary files are refused with a message saying
//! how to save ASCII.
//!
//! What becomes what:
//! - 3-node triangles (Gmsh type 2) and 4-node quadrangles (type 3) become the elements
//!   ([`ElementKind::Cpe3`], [`ElementKind::Cpe4`]; the caller may switch quads to `Cpe4h`),
//!   labelled with their Gmsh element tags and turned counter-clockwise if needed;
//! - nodes used by those elements become the nodes (labels = Gmsh node tags, renumbered to
//!   0-based indices in file order); nodes used by no surface element are dropped, so a solver
//!   never sees a free node;
//! - physical surfaces become [`Mesh::element_sets`], physical curves become
//!   [`Mesh::node_sets`] (all nodes of their line elements, type 1) and
//!   [`MshModel::edge_sets`] (the node pairs of the line elements), named by `$PhysicalNames`
//!   or `surface_<tag>` / `curve_<tag>`; the physical groups of an element are those of its
//!   entity in `$Entities`;
//! - points (type 15) and physical points are ignored.

use std::collections::{BTreeMap, HashMap};
use std::fs;
use std::path::Path;

use crate::mesh::{Element, ElementKind, Mesh, MeshError};

/// A mesh read from a `.msh` file, with the edges of its physical curves.
#[derive(Debug, Clone, Default)]
pub struct MshModel {
    pub mesh: Mesh,
    /// For each physical curve, its line elements as pairs of 0-based node indices (in the
    /// order of the file). Use [`Mesh::find_face`] to turn an edge into `(element, face)`.
    pub edge_sets: BTreeMap<String, Vec<[usize; 2]>>,
}

/// An error reading a `.msh` file, naming the file and, where there is one, the 1-based line.
#[derive(Debug, thiserror::Error)]
pub enum MshError {
    /// The file could not be read.
    #[error("{file}: {source}")]
    Io {
        file: String,
        #[source]
        source: std::io::Error,
    },
    /// Something wrong on one line.
    #[error("{file}:{line}: {message}")]
    Line {
        file: String,
        line: usize,
        message: String,
    },
    /// Something wrong with the file as a whole.
    #[error("{file}: {message}")]
    File { file: String, message: String },
}

type Result<T> = std::result::Result<T, MshError>;

/// Reads a Gmsh MSH 4.1 ASCII file. See the [module documentation](self).
pub fn read_msh(path: &Path) -> Result<MshModel> {
    let file = path.display().to_string();
    let bytes = fs::read(path).map_err(|source| MshError::Io {
        file: file.clone(),
        source,
    })?;
    parse_msh(&String::from_utf8_lossy(&bytes), &file)
}

/// Parses the text of a Gmsh MSH 4.1 ASCII file; `file_name` is only used in error messages.
pub fn parse_msh(text: &str, file_name: &str) -> Result<MshModel> {
    Reader {
        file: file_name,
        lines: text.lines().collect(),
    }
    .read()
}

struct Reader<'a> {
    file: &'a str,
    lines: Vec<&'a str>,
}

/// The whitespace-separated tokens of one section, with their 1-based line numbers.
struct Tokens<'a> {
    toks: Vec<(&'a str, usize)>,
    pos: usize,
    section: &'a str,
    end_line: usize,
    file: &'a str,
}

impl<'a> Tokens<'a> {
    fn err(&self, line: usize, message: String) -> MshError {
        MshError::Line {
            file: self.file.to_string(),
            line,
            message,
        }
    }

    fn next(&mut self, what: &str) -> Result<(&'a str, usize)> {
        match self.toks.get(self.pos) {
            Some(&t) => {
                self.pos += 1;
                Ok(t)
            }
            None => Err(self.err(
                self.end_line,
                format!(
                    "${}: the section ends where {what} was expected",
                    self.section
                ),
            )),
        }
    }

    fn int(&mut self, what: &str) -> Result<(i64, usize)> {
        let (t, line) = self.next(what)?;
        t.parse::<i64>()
            .map(|v| (v, line))
            .map_err(|_| self.err(line, format!("cannot read '{t}' as {what} (an integer)")))
    }

    fn count(&mut self, what: &str) -> Result<usize> {
        let (v, line) = self.int(what)?;
        // A count can never exceed the number of remaining tokens; this also guards against
        // absurd allocations.
        if v < 0 || v as usize > self.toks.len() {
            return Err(self.err(line, format!("{what} {v} is not a valid count")));
        }
        Ok(v as usize)
    }

    fn float(&mut self, what: &str) -> Result<f64> {
        let (t, line) = self.next(what)?;
        match t.parse::<f64>() {
            Ok(v) if v.is_finite() => Ok(v),
            _ => Err(self.err(
                line,
                format!("cannot read '{t}' as {what} (a finite number such as 0.5 or -1.5e-3)"),
            )),
        }
    }

    /// A node coordinate within [`crate::mesh::MAX_COORDINATE_MM`].
    fn coordinate(&mut self) -> Result<f64> {
        let line = self.toks.get(self.pos).map_or(self.end_line, |t| t.1);
        let v = self.float("a node coordinate")?;
        crate::mesh::check_coordinate(v).map_err(|m| self.err(line, m))?;
        Ok(v)
    }
}

/// Nodes per element of the Gmsh element types this reader knows.
fn gmsh_type(t: i64) -> Option<(usize, &'static str)> {
    match t {
        1 => Some((2, "2-node line")),
        2 => Some((3, "3-node triangle")),
        3 => Some((4, "4-node quadrangle")),
        15 => Some((1, "point")),
        _ => None,
    }
}

fn gmsh_type_name(t: i64) -> String {
    match t {
        4 => "4-node tetrahedron".into(),
        5 => "8-node hexahedron".into(),
        6 => "6-node prism".into(),
        7 => "5-node pyramid".into(),
        8 => "3-node line".into(),
        9 => "6-node triangle".into(),
        10 => "9-node quadrangle".into(),
        16 => "8-node quadrangle".into(),
        _ => format!("type {t}"),
    }
}

/// What [`Reader::front`] reads.
struct Front<'a> {
    sections: Vec<(&'a str, usize, usize)>,
    /// `$PhysicalNames` by (dimension, tag).
    names: HashMap<(i64, i64), String>,
    /// The physical tags of each (dimension, entity tag).
    physicals: HashMap<(i64, i64), Vec<i64>>,
    /// Node tags with their lines, in file order.
    node_tags: Vec<(i64, usize)>,
    coords: Vec<[f64; 3]>,
    /// File index of each node tag.
    node_of_tag: HashMap<i64, usize>,
}

struct RawElement {
    tag: i64,
    nodes: [i64; 4],
    n: usize,
    entity: i64,
    line: usize,
}

impl<'a> Reader<'a> {
    fn err(&self, line: usize, message: impl Into<String>) -> MshError {
        MshError::Line {
            file: self.file.to_string(),
            line,
            message: message.into(),
        }
    }

    fn file_err(&self, message: impl Into<String>) -> MshError {
        MshError::File {
            file: self.file.to_string(),
            message: message.into(),
        }
    }

    /// The sections as (name, first content line index, end line index), in file order.
    fn sections(&self) -> Result<Vec<(&'a str, usize, usize)>> {
        let mut out = Vec::new();
        let mut i = 0;
        while i < self.lines.len() {
            let t = self.lines[i].trim();
            if let Some(name) = t.strip_prefix('$') {
                let end_tag = format!("$End{name}");
                let Some(end) =
                    (i + 1..self.lines.len()).find(|&j| self.lines[j].trim() == end_tag)
                else {
                    return Err(self.err(i + 1, format!("${name} has no {end_tag}")));
                };
                out.push((name, i + 1, end));
                i = end + 1;
            } else if t.is_empty() {
                i += 1;
            } else {
                return Err(self.err(
                    i + 1,
                    format!("unexpected text '{t}' outside a $Section ... $EndSection"),
                ));
            }
        }
        Ok(out)
    }

    fn tokens(&self, section: &'a str, start: usize, end: usize) -> Tokens<'a> {
        let mut toks = Vec::new();
        for i in start..end {
            toks.extend(self.lines[i].split_whitespace().map(|t| (t, i + 1)));
        }
        Tokens {
            toks,
            pos: 0,
            section,
            end_line: end + 1,
            file: self.file,
        }
    }

    /// The sections, physical names, entities' physical groups and nodes (3 coordinates) of
    /// the file: what the 2D and the 3D readers share.
    fn front(&self) -> Result<Front<'a>> {
        let sections = self.sections()?;
        let Some(&(_, fstart, fend)) = sections.iter().find(|s| s.0 == "MeshFormat") else {
            return Err(self.file_err("no $MeshFormat section: this is not a Gmsh .msh file"));
        };
        let fmt_line = self
            .lines
            .get(fstart)
            .filter(|_| fstart < fend)
            .ok_or_else(|| self.err(fstart, "$MeshFormat is empty"))?;
        let mut f = fmt_line.split_whitespace();
        let version = f.next().unwrap_or("");
        let file_type = f.next().unwrap_or("");
        if version != "4.1" {
            return Err(self.err(
                fstart + 1,
                format!(
                    "MSH version {version} is not supported: save the mesh as MSH 4.1 (Gmsh: -format msh41, or Mesh.MshFileVersion = 4.1)"
                ),
            ));
        }
        if file_type != "0" {
            return Err(self.err(
                fstart + 1,
                "binary MSH is not supported: save the mesh as ASCII (Gmsh: Mesh.Binary = 0)",
            ));
        }

        // $PhysicalNames: "dim tag "name"".
        let mut names: HashMap<(i64, i64), String> = HashMap::new();
        if let Some(&(_, start, end)) = sections.iter().find(|s| s.0 == "PhysicalNames") {
            for i in (start + 1)..end {
                let l = self.lines[i].trim();
                if l.is_empty() {
                    continue;
                }
                let mut parts = l.splitn(3, char::is_whitespace);
                let dim = parts.next().and_then(|s| s.parse::<i64>().ok());
                let tag = parts.next().and_then(|s| s.parse::<i64>().ok());
                let name = parts.next().map(|s| s.trim().trim_matches('"').to_string());
                match (dim, tag, name) {
                    (Some(d), Some(t), Some(n)) if !n.is_empty() => {
                        names.insert((d, t), n);
                    }
                    _ => {
                        return Err(self.err(
                            i + 1,
                            format!("cannot read '{l}' as 'dimension tag \"name\"'"),
                        ))
                    }
                }
            }
        }

        // $Entities: physical tags of each (dim, entity tag).
        let mut physicals: HashMap<(i64, i64), Vec<i64>> = HashMap::new();
        if let Some(&(name, start, end)) = sections.iter().find(|s| s.0 == "Entities") {
            let mut t = self.tokens(name, start, end);
            let mut counts = [0usize; 4];
            for c in counts.iter_mut() {
                *c = t.count("an entity count")?;
            }
            for (dim, &n) in counts.iter().enumerate() {
                for _ in 0..n {
                    let (tag, _) = t.int("an entity tag")?;
                    let coords = if dim == 0 { 3 } else { 6 };
                    for _ in 0..coords {
                        t.float("an entity coordinate")?;
                    }
                    let np = t.count("a number of physical tags")?;
                    // A count from the file: capacity capped, the file must hold the tags.
                    let mut tags = Vec::with_capacity(np.min(64));
                    for _ in 0..np {
                        tags.push(t.int("a physical tag")?.0);
                    }
                    if dim > 0 {
                        let nb = t.count("a number of bounding entities")?;
                        for _ in 0..nb {
                            t.int("a bounding entity tag")?;
                        }
                    }
                    physicals.insert((dim as i64, tag), tags);
                }
            }
        }
        if sections.iter().any(|s| s.0 == "PartitionedEntities") {
            return Err(self.file_err(
                "partitioned meshes ($PartitionedEntities) are not supported: save the mesh unpartitioned",
            ));
        }

        // $Nodes.
        let Some(&(name, start, end)) = sections.iter().find(|s| s.0 == "Nodes") else {
            return Err(self.file_err("no $Nodes section"));
        };
        let mut t = self.tokens(name, start, end);
        let blocks = t.count("a number of node blocks")?;
        let (declared_nodes, header_line) = (t.count("a number of nodes")?, t.end_line);
        let header_line = t.toks.first().map(|x| x.1).unwrap_or(header_line);
        t.int("the minimum node tag")?;
        t.int("the maximum node tag")?;
        let mut node_tags: Vec<(i64, usize)> = Vec::new();
        let mut coords: Vec<[f64; 3]> = Vec::new();
        for _ in 0..blocks {
            let (dim, _) = t.int("an entity dimension")?;
            t.int("an entity tag")?;
            let (parametric, _) = t.int("the parametric flag")?;
            let n = t.count("a number of nodes in the block")?;
            for _ in 0..n {
                node_tags.push(t.int("a node tag")?);
            }
            let extra = if parametric == 1 {
                dim.clamp(0, 3) as usize
            } else {
                0
            };
            for _ in 0..n {
                let (x, y) = (t.coordinate()?, t.coordinate()?);
                let z = t.float("a node coordinate")?;
                for _ in 0..extra {
                    t.float("a parametric coordinate")?;
                }
                coords.push([x, y, z]);
            }
        }
        if node_tags.len() != declared_nodes {
            return Err(self.err(
                header_line,
                format!(
                    "$Nodes declares {declared_nodes} nodes but its blocks hold {}",
                    node_tags.len()
                ),
            ));
        }
        let mut node_of_tag: HashMap<i64, usize> = HashMap::with_capacity(node_tags.len());
        for (i, &(tag, line)) in node_tags.iter().enumerate() {
            if node_of_tag.insert(tag, i).is_some() {
                return Err(self.err(line, format!("node tag {tag} appears twice")));
            }
        }

        Ok(Front {
            sections,
            names,
            physicals,
            node_tags,
            coords,
            node_of_tag,
        })
    }

    fn read(&self) -> Result<MshModel> {
        let Front {
            sections,
            names,
            physicals,
            node_tags,
            coords,
            node_of_tag,
        } = self.front()?;
        // $Elements.
        let Some(&(name, start, end)) = sections.iter().find(|s| s.0 == "Elements") else {
            return Err(self.file_err("no $Elements section"));
        };
        let mut t = self.tokens(name, start, end);
        let blocks = t.count("a number of element blocks")?;
        let (declared_elements, header_line) = (t.count("a number of elements")?, t.end_line);
        let header_line = t.toks.first().map(|x| x.1).unwrap_or(header_line);
        let mut element_count = 0usize;
        t.int("the minimum element tag")?;
        t.int("the maximum element tag")?;
        let mut surface_elements: Vec<RawElement> = Vec::new();
        let mut line_elements: Vec<RawElement> = Vec::new();
        for _ in 0..blocks {
            let (dim, _) = t.int("an entity dimension")?;
            let (entity, _) = t.int("an entity tag")?;
            let (ty, ty_line) = t.int("an element type")?;
            let n = t.count("a number of elements in the block")?;
            let Some((nn, _)) = gmsh_type(ty) else {
                return Err(self.err(
                    ty_line,
                    format!(
                        "Gmsh element {} is not supported: femu reads 3-node triangles and 4-node quadrangles (use first-order 2D elements, Mesh.ElementOrder = 1)",
                        gmsh_type_name(ty)
                    ),
                ));
            };
            element_count += n;
            for _ in 0..n {
                let (tag, line) = t.int("an element tag")?;
                let mut nodes = [0i64; 4];
                for node in nodes.iter_mut().take(nn) {
                    *node = t.int("a node tag")?.0;
                }
                let raw = RawElement {
                    tag,
                    nodes,
                    n: nn,
                    entity,
                    line,
                };
                match (dim, ty) {
                    (2, 2 | 3) => surface_elements.push(raw),
                    (1, 1) => line_elements.push(raw),
                    (_, 15) => {}
                    _ => {
                        return Err(self.err(
                            line,
                            format!("element type {ty} in an entity of dimension {dim}"),
                        ))
                    }
                }
            }
        }
        if element_count != declared_elements {
            return Err(self.err(
                header_line,
                format!(
                    "$Elements declares {declared_elements} elements but its blocks hold {element_count}"
                ),
            ));
        }
        if surface_elements.is_empty() {
            return Err(self.file_err("no triangles or quadrangles: this is not a 2D surface mesh"));
        }

        // Nodes used by surface elements, renumbered in file order.
        let mut used = vec![false; node_tags.len()];
        for el in &surface_elements {
            for &tag in &el.nodes[..el.n] {
                match node_of_tag.get(&tag) {
                    Some(&i) => used[i] = true,
                    None => {
                        return Err(self.err(
                            el.line,
                            format!(
                                "element {} refers to node {tag}, which is not in $Nodes",
                                el.tag
                            ),
                        ))
                    }
                }
            }
        }
        let mut mesh = Mesh::default();
        let mut index_of_file_node = vec![usize::MAX; node_tags.len()];
        for (i, &(tag, _)) in node_tags.iter().enumerate() {
            if used[i] {
                index_of_file_node[i] = mesh.nodes.len();
                mesh.nodes.push([coords[i][0], coords[i][1]]);
                mesh.node_labels.push(tag);
            }
        }
        let index = |tag: i64| index_of_file_node[node_of_tag[&tag]];

        // Surface elements, counter-clockwise, and their physical surfaces.
        let mut element_sets: BTreeMap<String, Vec<usize>> = BTreeMap::new();
        let mut element_line: HashMap<i64, usize> = HashMap::new();
        for el in &surface_elements {
            let mut conn = [usize::MAX; 4];
            for (slot, &tag) in conn.iter_mut().zip(&el.nodes[..el.n]) {
                *slot = index(tag);
            }
            let mut area2 = 0.0;
            for k in 0..el.n {
                let p = mesh.nodes[conn[k]];
                let q = mesh.nodes[conn[(k + 1) % el.n]];
                area2 += p[0] * q[1] - q[0] * p[1];
            }
            if area2 < 0.0 {
                // Keep the first node, reverse the others.
                conn[1..el.n].reverse();
            }
            let element = if el.n == 4 {
                Element::quad(ElementKind::Cpe4, conn)
            } else {
                Element::tri([conn[0], conn[1], conn[2]])
            };
            if element_line.insert(el.tag, el.line).is_some() {
                return Err(self.err(el.line, format!("element tag {} appears twice", el.tag)));
            }
            let e = mesh.elements.len();
            mesh.elements.push(element);
            mesh.element_labels.push(el.tag);
            for &p in physicals
                .get(&(2, el.entity))
                .map(Vec::as_slice)
                .unwrap_or(&[])
            {
                let name = names
                    .get(&(2, p))
                    .cloned()
                    .unwrap_or_else(|| format!("surface_{p}"));
                element_sets.entry(name).or_default().push(e);
            }
        }
        mesh.element_sets = element_sets;

        // Physical curves: node sets and edges.
        let mut edge_sets: BTreeMap<String, Vec<[usize; 2]>> = BTreeMap::new();
        for el in &line_elements {
            for &p in physicals
                .get(&(1, el.entity))
                .map(Vec::as_slice)
                .unwrap_or(&[])
            {
                let name = names
                    .get(&(1, p))
                    .cloned()
                    .unwrap_or_else(|| format!("curve_{p}"));
                let mut pair = [0usize; 2];
                for (slot, &tag) in pair.iter_mut().zip(&el.nodes[..2]) {
                    let i = node_of_tag.get(&tag).map(|&i| index_of_file_node[i]);
                    match i {
                        Some(i) if i != usize::MAX => *slot = i,
                        _ => {
                            return Err(self.err(
                                el.line,
                                format!(
                                    "physical curve '{name}': line element {} has node {tag}, which belongs to no triangle or quadrangle",
                                    el.tag
                                ),
                            ))
                        }
                    }
                }
                edge_sets.entry(name).or_default().push(pair);
            }
        }
        for (name, edges) in &edge_sets {
            let mut nodes: Vec<usize> = edges.iter().flatten().copied().collect();
            nodes.sort_unstable();
            nodes.dedup();
            mesh.node_sets.insert(name.clone(), nodes);
        }

        mesh.check_orientation().map_err(|e| match &e {
            MeshError::Inverted { label, .. } | MeshError::MissingNode { label, .. } => {
                match element_line.get(label) {
                    Some(&line) => self.err(line, e.to_string()),
                    None => self.file_err(e.to_string()),
                }
            }
            _ => self.file_err(e.to_string()),
        })?;
        Ok(MshModel { mesh, edge_sets })
    }
}

mod solid;
pub use solid::{parse_msh3, read_msh3};

#[cfg(test)]
mod tests {
    use super::*;
    use std::path::PathBuf;

    fn data(name: &str) -> PathBuf {
        PathBuf::from(env!("CARGO_MANIFEST_DIR"))
            .join("tests/data")
            .join(name)
    }

    #[test]
    fn hand_written_file() {
        let m = read_msh(&data("two_regions.msh")).unwrap();
        let mesh = &m.mesh;
        // Node 99 (on a point entity only) is dropped.
        assert_eq!(mesh.nodes.len(), 7);
        assert_eq!(mesh.node_labels, vec![1, 2, 3, 4, 5, 6, 7]);
        assert_eq!(mesh.nodes[6], [1.5, 2.0]);
        assert_eq!(mesh.elements.len(), 3);
        assert_eq!(mesh.element_labels, vec![10, 11, 20]);
        assert_eq!(mesh.elements[0].kind, ElementKind::Cpe4);
        assert_eq!(mesh.elements[2].kind, ElementKind::Cpe3);
        // Element 11 is clockwise in the file and was flipped.
        assert_eq!(mesh.elements[1].conn, [1, 2, 5, 4]);
        assert!(mesh.check_orientation().is_ok());
        assert_eq!(mesh.element_sets["Fat"], vec![0, 1]);
        assert_eq!(mesh.element_sets["surface_7"], vec![2]);
        assert_eq!(mesh.node_sets["Femur"], vec![0, 1, 2]);
        assert_eq!(m.edge_sets["Femur"], vec![[0, 1], [1, 2]]);
        assert_eq!(mesh.find_face(0, 1), Some((0, 0)));
        assert!(!mesh.node_sets.contains_key("Corner"));
    }

    #[test]
    fn gmsh_generated_file() {
        // Written by Gmsh 4.8.4 from two_regions.geo (mixed triangles and quadrangles).
        let m = read_msh(&data("gmsh_two_surfaces.msh")).unwrap();
        let mesh = &m.mesh;
        assert_eq!(mesh.nodes.len(), 13);
        assert_eq!(mesh.elements.len(), 12);
        assert_eq!(mesh.element_sets["Fat"].len(), 4);
        assert_eq!(mesh.element_sets["surface_7"].len(), 8);
        assert_eq!(m.edge_sets["Bottom"].len(), 2);
        for &[a, b] in &m.edge_sets["Bottom"] {
            assert_eq!(mesh.nodes[a][1], 0.0);
            assert_eq!(mesh.nodes[b][1], 0.0);
            assert!(mesh.find_face(a, b).is_some());
        }
        assert!(mesh.check_orientation().is_ok());
        let area: f64 = (0..mesh.elements.len())
            .map(|e| {
                let (x, n) = mesh.element_coords(e);
                (0..n)
                    .map(|k| {
                        let (p, q) = (x[k], x[(k + 1) % n]);
                        0.5 * (p[0] * q[1] - q[0] * p[1])
                    })
                    .sum::<f64>()
            })
            .sum();
        assert!((area - 4.0).abs() < 1e-9, "{area}");
    }

    #[test]
    fn errors_name_file_and_line() {
        let good = fs::read_to_string(data("two_regions.msh")).unwrap();
        let cases = [
            (
                good.replace("4.1 0 8", "2.2 0 8"),
                "t.msh:2: MSH version 2.2 is not supported",
            ),
            (
                good.replace("4.1 0 8", "4.1 1 8"),
                "t.msh:2: binary MSH is not supported",
            ),
            (good.replace("1.5 2 0", "1.5 abc 0"), "t.msh:"),
            (good.replace("2 2 2 1\n20", "2 2 9 1\n20"), "t.msh:"),
            (good.replace("$EndNodes", ""), "t.msh:"),
            (good.replace("10 1 2 5 4", "10 1 2 5 44"), "t.msh:"),
        ];
        for (text, expected) in cases {
            let msg = parse_msh(&text, "t.msh").unwrap_err().to_string();
            assert!(
                msg.starts_with(expected),
                "expected '{expected}...', got '{msg}'"
            );
        }
        let msg = parse_msh(&good.replace("1.5 2 0", "1.5 abc 0"), "t.msh")
            .unwrap_err()
            .to_string();
        assert!(
            msg.contains("cannot read 'abc' as a node coordinate"),
            "{msg}"
        );
        let msg = parse_msh(&good.replace("2 2 2 1\n20", "2 2 9 1\n20"), "t.msh")
            .unwrap_err()
            .to_string();
        assert!(msg.contains("6-node triangle is not supported"), "{msg}");
        let msg = parse_msh(&good.replace("4 8 1 99", "4 9 1 99"), "t.msh")
            .unwrap_err()
            .to_string();
        assert_eq!(
            msg,
            "t.msh:18: $Nodes declares 9 nodes but its blocks hold 8"
        );
        assert!(parse_msh("", "t.msh").is_err());
        assert!(parse_msh("$MeshFormat\n$EndMeshFormat\n", "t.msh").is_err());
        assert!(parse_msh(
            "$MeshFormat\n4.1 0 8\n$EndMeshFormat\n$Nodes\n99999999999 1\n$EndNodes\n",
            "t.msh"
        )
        .is_err());
    }
}
