//! ParaView output: VTK XML `UnstructuredGrid` (`.vtu`) files.
//!
//! Written directly (the format is small and stable, and the Rust crate `vtkio` is only
//! available as a release candidate). The XML is text; every data array is inline binary
//! (`format="binary"`): the base64 text of one stream holding the array's length in bytes
//! (`UInt64`, the file's `header_type`) followed by its values, little-endian (the layout VTK's
//! own writer uses for uncompressed arrays). Values are stored exactly, the file is a third the
//! size of its ASCII form, and writing it is a copy and an encoding, done in parallel blocks.
//! A non-finite value is an error (`InvalidData`) naming the field and the item: it is a
//! result gone wrong, not something to plot.
//!
//! Points are written in 3D with z = 0; cells are `VTK_QUAD` (9) and `VTK_TRIANGLE` (5).
//!
//! Callers that may want another format write through the [`FieldWriter`] trait (a
//! [`FieldSet`]: mesh, displacement, point and cell fields); [`VtuWriter`] is this format.

use base64::engine::general_purpose::STANDARD as BASE64;
use base64::Engine;
use rayon::prelude::*;
use std::io::{self, Write};
use std::path::Path;

use crate::mesh::Mesh;
use crate::mesh3d::Mesh3;

/// A named `f64` field: `data` holds `components` values per point (or per cell), point after
/// point. Pass 3 components for vectors (x, y, 0) so ParaView's *Warp By Vector* can use them.
/// A 4-component field is taken to be a symmetric 2D tensor in the order `xx, yy, zz, xy` and
/// its components are named so in ParaView.
#[derive(Debug, Clone, Copy)]
pub struct VtuField<'a> {
    pub name: &'a str,
    pub components: usize,
    pub data: &'a [f64],
}

/// A named `Int32` cell field, one value per cell (e.g. the region index).
#[derive(Debug, Clone, Copy)]
pub struct VtuIntField<'a> {
    pub name: &'a str,
    pub data: &'a [i32],
}

/// What a field file holds: a mesh with an optional displacement, point fields and cell
/// fields (`f64` and `Int32`).
///
/// `displacement` (one `[ux, uy]` per node) is the point field `displacement`; each
/// [`VtuField`] holds `components` values per point (or per cell), and each [`VtuIntField`]
/// one value per cell.
#[derive(Debug, Clone, Copy)]
pub struct FieldSet<'a> {
    pub mesh: &'a Mesh,
    pub displacement: Option<&'a [[f64; 2]]>,
    pub point_fields: &'a [VtuField<'a>],
    pub cell_fields: &'a [VtuField<'a>],
    pub int_cell_fields: &'a [VtuIntField<'a>],
}

impl<'a> FieldSet<'a> {
    /// The mesh alone (no displacement, no fields).
    pub fn mesh(mesh: &'a Mesh) -> Self {
        FieldSet {
            mesh,
            displacement: None,
            point_fields: &[],
            cell_fields: &[],
            int_cell_fields: &[],
        }
    }
}

/// A writer of a mesh with its fields to a file ([`VtuWriter`]: ParaView's `.vtu`).
pub trait FieldWriter: Sync {
    /// The file name extension of the format, without the dot.
    fn extension(&self) -> &'static str;

    /// Writes `fields` to `path`. The fields are checked before the file is created: a field of
    /// the wrong length or with zero components is `InvalidInput`, a non-finite value
    /// `InvalidData` (naming the field and the item).
    fn write(&self, path: &Path, fields: &FieldSet) -> io::Result<()>;
}

/// The VTK XML `UnstructuredGrid` writer of the module documentation. The displacement is
/// written as the 3-component point field `displacement` (z = 0).
#[derive(Debug, Clone, Copy, Default)]
pub struct VtuWriter;

impl FieldWriter for VtuWriter {
    fn extension(&self) -> &'static str {
        "vtu"
    }

    fn write(&self, path: &Path, fields: &FieldSet) -> io::Result<()> {
        // Check everything before creating the file.
        check(
            fields.mesh,
            fields.displacement,
            fields.point_fields,
            fields.cell_fields,
            fields.int_cell_fields,
        )?;
        crate::atomic::write_with(path, |w| {
            write_to(
                w,
                fields.mesh,
                fields.displacement,
                fields.point_fields,
                fields.cell_fields,
                fields.int_cell_fields,
            )
        })
    }
}

/// Writes `mesh` to `path` as a `.vtu` file with optional displacement and fields
/// ([`VtuWriter`] with a [`FieldSet`] without integer cell fields).
pub fn write_vtu(
    path: &Path,
    mesh: &Mesh,
    displacement: Option<&[[f64; 2]]>,
    point_fields: &[VtuField],
    cell_fields: &[VtuField],
) -> io::Result<()> {
    write_vtu_with_int_cells(path, mesh, displacement, point_fields, cell_fields, &[])
}

/// [`write_vtu`] with additional `Int32` cell fields (e.g. `region`).
pub fn write_vtu_with_int_cells(
    path: &Path,
    mesh: &Mesh,
    displacement: Option<&[[f64; 2]]>,
    point_fields: &[VtuField],
    cell_fields: &[VtuField],
    int_cell_fields: &[VtuIntField],
) -> io::Result<()> {
    VtuWriter.write(
        path,
        &FieldSet {
            mesh,
            displacement,
            point_fields,
            cell_fields,
            int_cell_fields,
        },
    )
}

fn invalid(kind: io::ErrorKind, msg: String) -> io::Error {
    io::Error::new(kind, msg)
}

fn check(
    mesh: &Mesh,
    displacement: Option<&[[f64; 2]]>,
    point_fields: &[VtuField],
    cell_fields: &[VtuField],
    int_cell_fields: &[VtuIntField],
) -> io::Result<()> {
    let (np, nc) = (mesh.nodes.len(), mesh.elements.len());
    finite("node coordinates", mesh.nodes.iter().flatten().copied(), 2)?;
    for (e, el) in mesh.elements.iter().enumerate() {
        if el.nodes().iter().any(|&n| n >= np) {
            return Err(invalid(
                io::ErrorKind::InvalidInput,
                format!("element index {e} refers to a node that does not exist"),
            ));
        }
    }
    if let Some(u) = displacement {
        if u.len() != np {
            return Err(invalid(
                io::ErrorKind::InvalidInput,
                format!("displacement has {} values for {np} nodes", u.len()),
            ));
        }
        finite("displacement", u.iter().flatten().copied(), 2)?;
    }
    check_fields(point_fields, np, "point")?;
    check_cell_fields(nc, cell_fields, int_cell_fields)
}

/// Checks the cell fields' lengths and values (`nc` cells).
fn check_cell_fields(
    nc: usize,
    cell_fields: &[VtuField],
    int_cell_fields: &[VtuIntField],
) -> io::Result<()> {
    check_fields(cell_fields, nc, "cell")?;
    for f in int_cell_fields {
        if f.data.len() != nc {
            return Err(invalid(
                io::ErrorKind::InvalidInput,
                format!(
                    "cell field '{}' has {} values for {nc} cells",
                    f.name,
                    f.data.len()
                ),
            ));
        }
    }
    Ok(())
}

/// Checks `f64` fields of `n` items (`what`: point or cell).
fn check_fields(fields: &[VtuField], n: usize, what: &str) -> io::Result<()> {
    for f in fields {
        if f.components == 0 || f.data.len() != n * f.components {
            return Err(invalid(
                io::ErrorKind::InvalidInput,
                format!(
                    "{what} field '{}' has {} values; expected {} components x {n} {what}s",
                    f.name,
                    f.data.len(),
                    f.components
                ),
            ));
        }
        finite(
            &format!("{what} field '{}'", f.name),
            f.data.iter().copied(),
            f.components,
        )?;
    }
    Ok(())
}

/// Errors if a value is not finite, naming the item (`per` values per item).
fn finite(what: &str, mut values: impl Iterator<Item = f64>, per: usize) -> io::Result<()> {
    match values.position(|v| !v.is_finite()) {
        None => Ok(()),
        Some(i) => Err(invalid(
            io::ErrorKind::InvalidData,
            format!(
                "{what}: value {} of item {} is not finite",
                i % per,
                i / per
            ),
        )),
    }
}

/// Escapes a string for an XML attribute.
fn xml_escape(s: &str) -> String {
    let mut out = String::with_capacity(s.len());
    for c in s.chars() {
        match c {
            '&' => out.push_str("&amp;"),
            '<' => out.push_str("&lt;"),
            '>' => out.push_str("&gt;"),
            '"' => out.push_str("&quot;"),
            '\'' => out.push_str("&apos;"),
            c => out.push(c),
        }
    }
    out
}

/// A value stored in a binary data array: its VTK type name and its little-endian bytes.
trait Binary: Copy + Sync {
    const VTK_TYPE: &'static str;
    fn put(self, out: &mut Vec<u8>);
}

/// `Binary` for number types whose little-endian bytes are their stored form.
macro_rules! binary_le {
    ($($t:ty => $name:literal),*) => {$(
        impl Binary for $t {
            const VTK_TYPE: &'static str = $name;
            #[inline]
            fn put(self, out: &mut Vec<u8>) {
                out.extend_from_slice(&self.to_le_bytes());
            }
        }
    )*};
}

binary_le!(f64 => "Float64", i64 => "Int64", i32 => "Int32", u8 => "UInt8");

/// Input bytes per parallel base64 block (a multiple of 3, so that the blocks' texts join into
/// the text of the whole stream).
const ENCODE_BLOCK: usize = 3 << 16;

/// Writes one inline binary `DataArray`: `attributes` (name, components) in its start tag, and
/// as its text the base64 of the byte count (`UInt64`) followed by the values.
fn write_array<T: Binary>(
    w: &mut impl Write,
    attributes: &str,
    values: impl Iterator<Item = T>,
) -> io::Result<()> {
    // The byte count goes in front of the values once they are all there.
    let mut raw = Vec::with_capacity(8 + values.size_hint().0 * std::mem::size_of::<T>());
    raw.extend_from_slice(&[0; 8]);
    for v in values {
        v.put(&mut raw);
    }
    let n_bytes = (raw.len() - 8) as u64;
    raw[..8].copy_from_slice(&n_bytes.to_le_bytes());
    let mut text = vec![0u8; raw.len().div_ceil(3) * 4];
    text.par_chunks_mut(ENCODE_BLOCK / 3 * 4)
        .zip(raw.par_chunks(ENCODE_BLOCK))
        .for_each(|(out, bytes)| {
            let written = BASE64
                .encode_slice(bytes, out)
                .expect("the output block holds the encoding of its input block");
            debug_assert_eq!(written, out.len());
        });
    writeln!(
        w,
        r#"        <DataArray type="{}"{attributes} format="binary">"#,
        T::VTK_TYPE
    )?;
    w.write_all(b"          ")?;
    w.write_all(&text)?;
    writeln!(w, "\n        </DataArray>")
}

fn write_field(w: &mut impl Write, f: &VtuField) -> io::Result<()> {
    let names = match f.components {
        4 => r#" ComponentName0="xx" ComponentName1="yy" ComponentName2="zz" ComponentName3="xy""#,
        6 => {
            r#" ComponentName0="xx" ComponentName1="yy" ComponentName2="zz" ComponentName3="xy" ComponentName4="xz" ComponentName5="yz""#
        }
        _ => "",
    };
    let attributes = format!(
        r#" Name="{}" NumberOfComponents="{}"{names}"#,
        xml_escape(f.name),
        f.components
    );
    write_array(w, &attributes, f.data.iter().copied())
}

fn write_to(
    w: &mut impl Write,
    mesh: &Mesh,
    displacement: Option<&[[f64; 2]]>,
    point_fields: &[VtuField],
    cell_fields: &[VtuField],
    int_cell_fields: &[VtuIntField],
) -> io::Result<()> {
    let u3: Option<Vec<f64>> =
        displacement.map(|u| u.iter().flat_map(|d| [d[0], d[1], 0.0]).collect());
    write_grid(
        w,
        Grid {
            n_points: mesh.nodes.len(),
            n_cells: mesh.elements.len(),
            displacement: u3.as_deref(),
            point_fields,
            cell_fields,
            int_cell_fields,
        },
        mesh.nodes.iter().flat_map(|p| [p[0], p[1], 0.0]),
        mesh.elements
            .iter()
            .flat_map(|el| el.nodes().iter().map(|&n| n as i64)),
        mesh.elements.iter().map(|el| el.kind.node_count()),
        mesh.elements.iter().map(|el| el.kind.vtk_cell_type()),
    )
}

/// The counts and fields of a grid for [`write_grid`]; `displacement` has 3 components per
/// point.
struct Grid<'a> {
    n_points: usize,
    n_cells: usize,
    displacement: Option<&'a [f64]>,
    point_fields: &'a [VtuField<'a>],
    cell_fields: &'a [VtuField<'a>],
    int_cell_fields: &'a [VtuIntField<'a>],
}

/// Writes a grid: its fields, `points` (x, y, z per point), the cells' `connectivity`, the
/// node count of each cell and the VTK cell types.
fn write_grid(
    w: &mut impl Write,
    g: Grid,
    points: impl Iterator<Item = f64>,
    connectivity: impl Iterator<Item = i64>,
    cell_sizes: impl Iterator<Item = usize>,
    types: impl Iterator<Item = u8>,
) -> io::Result<()> {
    writeln!(w, r#"<?xml version="1.0"?>"#)?;
    writeln!(
        w,
        r#"<VTKFile type="UnstructuredGrid" version="1.0" byte_order="LittleEndian" header_type="UInt64">"#
    )?;
    writeln!(w, "  <UnstructuredGrid>")?;
    writeln!(
        w,
        r#"    <Piece NumberOfPoints="{}" NumberOfCells="{}">"#,
        g.n_points, g.n_cells
    )?;

    // Point data.
    let mut pfields: Vec<VtuField> = Vec::new();
    if let Some(u3) = g.displacement {
        pfields.push(VtuField {
            name: "displacement",
            components: 3,
            data: u3,
        });
    }
    pfields.extend_from_slice(g.point_fields);
    if pfields.is_empty() {
        writeln!(w, "      <PointData>")?;
    } else {
        let vectors = pfields
            .iter()
            .find(|f| f.components == 3)
            .map(|f| format!(r#" Vectors="{}""#, xml_escape(f.name)))
            .unwrap_or_default();
        writeln!(w, "      <PointData{vectors}>")?;
    }
    for f in &pfields {
        write_field(w, f)?;
    }
    writeln!(w, "      </PointData>")?;

    // Cell data.
    writeln!(w, "      <CellData>")?;
    for f in g.cell_fields {
        write_field(w, f)?;
    }
    for f in g.int_cell_fields {
        let attributes = format!(r#" Name="{}""#, xml_escape(f.name));
        write_array(w, &attributes, f.data.iter().copied())?;
    }
    writeln!(w, "      </CellData>")?;

    // Geometry.
    writeln!(w, "      <Points>")?;
    write_array(w, r#" Name="Points" NumberOfComponents="3""#, points)?;
    writeln!(w, "      </Points>")?;

    writeln!(w, "      <Cells>")?;
    write_array(w, r#" Name="connectivity""#, connectivity)?;
    let offsets = cell_sizes.scan(0i64, |offset, n| {
        *offset += n as i64;
        Some(*offset)
    });
    write_array(w, r#" Name="offsets""#, offsets)?;
    write_array(w, r#" Name="types""#, types)?;
    writeln!(w, "      </Cells>")?;
    writeln!(w, "    </Piece>")?;
    writeln!(w, "  </UnstructuredGrid>")?;
    writeln!(w, "</VTKFile>")?;
    Ok(())
}

/// Writes a 3D mesh to `path` as a VTU file: hexahedra (`VTK_HEXAHEDRON`, 12), tetrahedra
/// (`VTK_TETRA`, 10) and quadratic tetrahedra (`VTK_QUADRATIC_TETRA`, 24), whose VTK node
/// orders are the Abaqus ones; the point field `displacement` (`[ux, uy, uz]` per node) when
/// given, and `f64` and `Int32` cell fields (a 6-component cell field is named as the
/// symmetric tensor `xx, yy, zz, xy, xz, yz`, the order of [`Mesh3`] stresses). Checked as the
/// 2D files are (lengths, indices, finite values).
pub fn write_vtu3(
    path: &Path,
    mesh: &Mesh3,
    displacement: Option<&[[f64; 3]]>,
    cell_fields: &[VtuField],
    int_cell_fields: &[VtuIntField],
) -> io::Result<()> {
    let (np, nc) = (mesh.nodes.len(), mesh.elements.len());
    finite("node coordinates", mesh.nodes.iter().flatten().copied(), 3)?;
    if mesh
        .elements
        .iter()
        .any(|el| el.nodes().iter().any(|&n| n >= np))
    {
        return Err(invalid(
            io::ErrorKind::InvalidInput,
            "an element refers to a node that does not exist".to_string(),
        ));
    }
    if let Some(u) = displacement {
        if u.len() != np {
            return Err(invalid(
                io::ErrorKind::InvalidInput,
                format!("displacement has {} values for {np} nodes", u.len()),
            ));
        }
        finite("displacement", u.iter().flatten().copied(), 3)?;
    }
    check_cell_fields(nc, cell_fields, int_cell_fields)?;
    crate::atomic::write_with(path, |w| {
        write_grid(
            w,
            Grid {
                n_points: np,
                n_cells: nc,
                displacement: displacement.map(|u| u.as_flattened()),
                point_fields: &[],
                cell_fields,
                int_cell_fields,
            },
            mesh.nodes.iter().flatten().copied(),
            mesh.elements
                .iter()
                .flat_map(|el| el.nodes().iter().map(|&n| n as i64)),
            mesh.elements.iter().map(|el| el.kind.node_count()),
            mesh.elements.iter().map(|el| el.kind.vtk_cell_type()),
        )
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::mesh::{Element, ElementKind};
    use std::fs;

    fn two_elements() -> Mesh {
        let mut m = Mesh::default();
        for p in [[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 1.0], [2.0, 0.5]] {
            m.add_node(p);
        }
        m.add_element(Element::quad(ElementKind::Cpe4, [0, 1, 2, 3]));
        m.add_element(Element::tri([1, 4, 2]));
        m
    }

    fn scratch(name: &str) -> std::path::PathBuf {
        std::env::temp_dir().join(format!("femu-mesh-{}-{name}", std::process::id()))
    }

    /// Runs the Python `script` on the file at `path` (its output printed); `what` is skipped
    /// with a message when python3 is not installed.
    fn python_check(script: &str, path: &std::path::Path, what: &str) {
        match std::process::Command::new("python3")
            .args(["-c", script])
            .arg(path)
            .output()
        {
            Ok(out) => {
                assert!(
                    out.status.success(),
                    "{what} failed: {}",
                    String::from_utf8_lossy(&out.stderr)
                );
                print!("{}", String::from_utf8_lossy(&out.stdout));
            }
            Err(_) => println!("python3 not found: {what} skipped"),
        }
    }

    /// The decoded bytes of the data array named `name` in `text`: its base64 text decoded,
    /// the `UInt64` byte count at its head checked against what follows.
    fn array_bytes(text: &str, name: &str) -> (String, Vec<u8>) {
        let tag = format!(r#"Name="{name}""#);
        let start = text.find(&tag).unwrap_or_else(|| panic!("no array {name}"));
        let open = text[..start].rfind("<DataArray").unwrap();
        let body_start = start + text[start..].find('>').unwrap() + 1;
        let body_end = body_start + text[body_start..].find("</DataArray>").unwrap();
        let start_tag = &text[open..body_start];
        assert!(start_tag.contains(r#"format="binary""#), "{start_tag}");
        let raw = BASE64.decode(text[body_start..body_end].trim()).unwrap();
        let count = u64::from_le_bytes(raw[..8].try_into().unwrap()) as usize;
        assert_eq!(count, raw.len() - 8, "{name}: byte count");
        (start_tag.to_string(), raw[8..].to_vec())
    }

    fn f64s(bytes: &[u8]) -> Vec<f64> {
        bytes
            .chunks_exact(8)
            .map(|c| f64::from_le_bytes(c.try_into().unwrap()))
            .collect()
    }

    fn i64s(bytes: &[u8]) -> Vec<i64> {
        bytes
            .chunks_exact(8)
            .map(|c| i64::from_le_bytes(c.try_into().unwrap()))
            .collect()
    }

    #[test]
    fn writes_a_well_formed_grid() {
        let m = two_elements();
        let u = [
            [0.0, 0.0],
            [0.1, 0.0],
            [0.1, 0.2],
            [0.0, 0.2],
            [0.3, 1.0 / 3.0],
        ];
        let strain: Vec<f64> = (0..8).map(|k| 0.5 + k as f64 / 7.0).collect();
        let pressure: Vec<f64> = (0..5).map(|i| i as f64).collect();
        let region = [0, -1];
        let path = scratch("grid.vtu");
        write_vtu_with_int_cells(
            &path,
            &m,
            Some(&u),
            &[VtuField {
                name: "p<&>",
                components: 1,
                data: &pressure,
            }],
            &[VtuField {
                name: "log strain",
                components: 4,
                data: &strain,
            }],
            &[VtuIntField {
                name: "region",
                data: &region,
            }],
        )
        .unwrap();
        let text = fs::read_to_string(&path).unwrap();
        assert!(text.contains(r#"<Piece NumberOfPoints="5" NumberOfCells="2">"#));
        assert!(text.contains(r#"<PointData Vectors="displacement">"#));
        assert!(text.contains(r#"Name="p&lt;&amp;&gt;""#));
        assert!(text.contains(r#"ComponentName3="xy""#));
        // Every value exactly, in the type the start tag names.
        let (tag, disp) = array_bytes(&text, "displacement");
        assert!(tag.contains(r#"type="Float64""#) && tag.contains(r#"NumberOfComponents="3""#));
        let expected: Vec<f64> = u.iter().flat_map(|d| [d[0], d[1], 0.0]).collect();
        assert_eq!(f64s(&disp), expected);
        let (_, points) = array_bytes(&text, "Points");
        let expected: Vec<f64> = m.nodes.iter().flat_map(|p| [p[0], p[1], 0.0]).collect();
        assert_eq!(f64s(&points), expected);
        assert_eq!(f64s(&array_bytes(&text, "p&lt;&amp;&gt;").1), pressure);
        assert_eq!(f64s(&array_bytes(&text, "log strain").1), strain);
        let (tag, conn) = array_bytes(&text, "connectivity");
        assert!(tag.contains(r#"type="Int64""#));
        assert_eq!(i64s(&conn), [0, 1, 2, 3, 1, 4, 2]);
        assert_eq!(i64s(&array_bytes(&text, "offsets").1), [4, 7]);
        let (tag, types) = array_bytes(&text, "types");
        assert!(tag.contains(r#"type="UInt8""#));
        assert_eq!(types, [9, 5]);
        let (tag, reg) = array_bytes(&text, "region");
        assert!(tag.contains(r#"type="Int32""#));
        assert_eq!(reg, [0, 0, 0, 0, 255, 255, 255, 255]);

        // An independent reader: Python's XML parser, base64 and struct decode every array and
        // check its length against the piece's counts, and a few values.
        let script = r#"
import sys, base64, struct, xml.dom.minidom as m
d = m.parse(sys.argv[1])
piece = d.getElementsByTagName('Piece')[0]
npts, ncells = int(piece.getAttribute('NumberOfPoints')), int(piece.getAttribute('NumberOfCells'))
size = {'Float64': ('d', 8), 'Int64': ('q', 8), 'Int32': ('i', 4), 'UInt8': ('B', 1)}
def values(name):
    a = [a for a in d.getElementsByTagName('DataArray') if a.getAttribute('Name') == name][0]
    assert a.getAttribute('format') == 'binary'
    raw = base64.b64decode(a.firstChild.data.strip())
    (n,) = struct.unpack('<Q', raw[:8])
    assert n == len(raw) - 8
    code, width = size[a.getAttribute('type')]
    return struct.unpack('<%d%s' % (n // width, code), raw[8:])
assert len(values('Points')) == 3 * npts
assert values('displacement')[13] == 1.0 / 3.0
assert len(values('p<&>')) == npts
assert len(values('log strain')) == 4 * ncells
assert values('region') == (0, -1)
assert values('types') == (9, 5)
assert values('offsets') == (4, 7)
assert values('connectivity') == (0, 1, 2, 3, 1, 4, 2)
print('ok')
"#;
        python_check(script, &path, "XML check");
        // ParaView's own reader (VTK's vtkXMLUnstructuredGridReader, from the `vtk` Python
        // wheel that .ci/run installs), when it is there.
        let script = r#"
import sys
try:
    import vtk
except ImportError:
    print('SKIPPED: the vtk Python module is not installed'); sys.exit(0)
from vtk.util.numpy_support import vtk_to_numpy
r = vtk.vtkXMLUnstructuredGridReader(); r.SetFileName(sys.argv[1]); r.Update()
assert r.GetErrorCode() == 0
g = r.GetOutput()
assert (g.GetNumberOfPoints(), g.GetNumberOfCells()) == (5, 2)
u = vtk_to_numpy(g.GetPointData().GetArray('displacement'))
assert u[4, 1] == 1.0 / 3.0 and u[2, 0] == 0.1, u
assert vtk_to_numpy(g.GetCellData().GetArray('region')).tolist() == [0, -1]
assert vtk_to_numpy(g.GetCellData().GetArray('log strain')).shape == (2, 4)
assert [g.GetCellType(c) for c in range(2)] == [9, 5]
assert [g.GetCell(1).GetPointId(k) for k in range(3)] == [1, 4, 2]
print('ok')
"#;
        python_check(script, &path, "VTK reader check");
        let _ = fs::remove_file(&path);
    }

    /// Arrays longer than one parallel encoding block read back whole: the blocks' texts join
    /// into the text of the whole stream (a padding inside it would fail the strict decoding).
    #[test]
    fn long_arrays_are_encoded_in_blocks() {
        let n = 3 * ENCODE_BLOCK / 8 + 5;
        let mut nodes = Mesh::default();
        for k in 0..n {
            nodes.add_node([k as f64, -(k as f64) / 3.0]);
        }
        nodes.add_element(Element::tri([0, 1, 2]));
        let path = scratch("long.vtu");
        write_vtu(&path, &nodes, None, &[], &[]).unwrap();
        let text = fs::read_to_string(&path).unwrap();
        let points = f64s(&array_bytes(&text, "Points").1);
        assert_eq!(points.len(), 3 * n);
        assert!(points
            .chunks_exact(3)
            .enumerate()
            .all(|(k, p)| p == [k as f64, -(k as f64) / 3.0, 0.0]));
        let _ = fs::remove_file(&path);
    }

    #[test]
    fn rejects_bad_fields() {
        let m = two_elements();
        let path = scratch("bad.vtu");
        let short = [1.0; 3];
        let e = write_vtu(
            &path,
            &m,
            None,
            &[VtuField {
                name: "s",
                components: 1,
                data: &short,
            }],
            &[],
        )
        .unwrap_err();
        assert_eq!(e.kind(), io::ErrorKind::InvalidInput);
        assert!(e.to_string().contains("'s'"), "{e}");
        let nan = [0.0, f64::NAN];
        let e = write_vtu(
            &path,
            &m,
            None,
            &[],
            &[VtuField {
                name: "c",
                components: 1,
                data: &nan,
            }],
        )
        .unwrap_err();
        assert_eq!(e.kind(), io::ErrorKind::InvalidData);
        assert!(e.to_string().contains("item 1"), "{e}");
        assert!(!path.exists());
        let u = [[0.0; 2]; 4];
        assert!(write_vtu(&path, &m, Some(&u), &[], &[]).is_err());
    }
    /// The trait path (`&dyn FieldWriter`) and the free functions write the same bytes.
    #[test]
    fn field_writer_matches_the_free_functions() {
        let mesh = two_elements();
        let disp = vec![[0.1, -0.2]; mesh.nodes.len()];
        let p: Vec<f64> = (0..mesh.nodes.len()).map(|i| i as f64 * 0.5).collect();
        let c = vec![1.5, -2.5];
        let r = vec![3, 7];
        let pf = [VtuField {
            name: "p",
            components: 1,
            data: &p,
        }];
        let cf = [VtuField {
            name: "c",
            components: 1,
            data: &c,
        }];
        let rf = [VtuIntField {
            name: "region",
            data: &r,
        }];
        let a = scratch("trait-a.vtu");
        let b = scratch("trait-b.vtu");
        let writer: &dyn FieldWriter = &VtuWriter;
        assert_eq!(writer.extension(), "vtu");
        writer
            .write(
                &a,
                &FieldSet {
                    mesh: &mesh,
                    displacement: Some(&disp),
                    point_fields: &pf,
                    cell_fields: &cf,
                    int_cell_fields: &rf,
                },
            )
            .unwrap();
        write_vtu_with_int_cells(&b, &mesh, Some(&disp), &pf, &cf, &rf).unwrap();
        let (ba, bb) = (std::fs::read(&a).unwrap(), std::fs::read(&b).unwrap());
        assert!(!ba.is_empty());
        assert_eq!(ba, bb);
        // A bad field is refused through the trait too, before the file is created.
        let short = [VtuField {
            name: "short",
            components: 1,
            data: &c[..1],
        }];
        let e = writer
            .write(
                &scratch("trait-bad.vtu"),
                &FieldSet {
                    cell_fields: &short,
                    ..FieldSet::mesh(&mesh)
                },
            )
            .unwrap_err();
        assert_eq!(e.kind(), io::ErrorKind::InvalidInput);
        assert!(!scratch("trait-bad.vtu").exists());
        let _ = std::fs::remove_file(a);
        let _ = std::fs::remove_file(b);
    }

    /// A 3D block of each element type written and read back: points with their z, the
    /// connectivity in the Abaqus order, offsets, cell types, displacement and cell fields.
    #[test]
    fn writes_a_3d_grid() {
        use crate::mesh3d::{generate::block, ElementKind3};
        for kind in ElementKind3::ALL {
            let m = block([1.0, 2.0, 3.0], [1, 1, 2], kind);
            let u: Vec<[f64; 3]> = m
                .nodes
                .iter()
                .map(|p| [0.1 * p[2], 0.0, -0.2 * p[0]])
                .collect();
            let stress: Vec<f64> = (0..6 * m.elements.len()).map(|i| i as f64).collect();
            let region: Vec<i32> = (0..m.elements.len() as i32).collect();
            let path = scratch(&format!("block3-{}.vtu", kind.deck_name()));
            write_vtu3(
                &path,
                &m,
                Some(&u),
                &[VtuField {
                    name: "stress",
                    components: 6,
                    data: &stress,
                }],
                &[VtuIntField {
                    name: "region",
                    data: &region,
                }],
            )
            .unwrap();
            let text = fs::read_to_string(&path).unwrap();
            let (_, points) = array_bytes(&text, "Points");
            assert_eq!(f64s(&points), m.nodes.as_flattened());
            let (_, disp) = array_bytes(&text, "displacement");
            assert_eq!(f64s(&disp), u.as_flattened());
            let (_, conn) = array_bytes(&text, "connectivity");
            let expected: Vec<i64> = m
                .elements
                .iter()
                .flat_map(|e| e.nodes().iter().map(|&n| n as i64))
                .collect();
            assert_eq!(i64s(&conn), expected);
            let (_, offsets) = array_bytes(&text, "offsets");
            let n = kind.node_count() as i64;
            assert_eq!(*i64s(&offsets).last().unwrap(), n * m.elements.len() as i64);
            let (_, types) = array_bytes(&text, "types");
            assert!(types.iter().all(|&t| t == kind.vtk_cell_type()));
            let (tag, s) = array_bytes(&text, "stress");
            assert!(tag.contains(r#"ComponentName5="yz""#), "{tag}");
            assert_eq!(f64s(&s), stress);
            let (_, r) = array_bytes(&text, "region");
            let r: Vec<i32> = r
                .chunks_exact(4)
                .map(|c| i32::from_le_bytes(c.try_into().unwrap()))
                .collect();
            assert_eq!(r, region);
            // A displacement of the wrong length and a non-finite value are refused.
            assert!(write_vtu3(&path, &m, Some(&u[1..]), &[], &[]).is_err());
            let mut bad = u.clone();
            bad[0][2] = f64::NAN;
            assert!(write_vtu3(&path, &m, Some(&bad), &[], &[]).is_err());
            let _ = fs::remove_file(&path);
        }
    }
}
