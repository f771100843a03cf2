//! 3D decks: written by `write_inp3`, read back by `parse_inp3`, and the reader's errors.

use femu_mesh::deck::{BoundaryCondition, FacePressure, MaterialDef, PointLoad, StepDef};
use femu_mesh::inp::parse_inp3;
use femu_mesh::mesh3d::generate::block;
use femu_mesh::{write_inp3, Deck3, ElementKind3};

fn deck(kind: ElementKind3) -> Deck3 {
    let mut mesh = block([2.0, 1.0, 1.5], [2, 1, 2], kind);
    // Labels that are not the indices.
    mesh.node_labels = (0..mesh.nodes.len() as i64).map(|i| 10 + 3 * i).collect();
    mesh.element_labels = (0..mesh.elements.len() as i64).map(|i| 100 + i).collect();
    mesh.nodes[0][2] = -1.0 / 3.0;
    let n_el = mesh.elements.len();
    let faces = kind.face_count();
    mesh.surfaces
        .insert("SKIN".into(), (0..n_el).map(|e| (e, e % faces)).collect());
    let half = n_el / 2;
    mesh.element_sets
        .insert("LOWER".into(), (0..half).collect());
    let x1 = mesh.node_set("X1").unwrap().to_vec();
    let x0 = mesh.node_set("X0").unwrap().to_vec();
    let mut boundaries: Vec<BoundaryCondition> = x0
        .iter()
        .flat_map(|&node| {
            (0..3).map(move |dof| BoundaryCondition {
                node,
                dof,
                value: 0.0,
            })
        })
        .collect();
    boundaries.push(BoundaryCondition {
        node: x1[0],
        dof: 2,
        value: 0.125,
    });
    Deck3 {
        mesh,
        materials: vec![
            MaterialDef {
                name: "FAT".into(),
                keyword: "NEO HOOKE".into(),
                constants: vec![0.8e-3, 30.8],
                line: None,
            },
            MaterialDef {
                name: "Muscle".into(),
                keyword: "MOONEY-RIVLIN".into(),
                constants: vec![1e-3, 2e-4, 18.0],
                line: None,
            },
        ],
        element_material: (0..n_el).map(|e| usize::from(e >= half)).collect(),
        element_region: (0..n_el).map(|e| usize::from(e >= half)).collect(),
        region_names: vec!["FATSET".into(), "MUSCLESET".into()],
        step: StepDef {
            initial_increment: 0.1,
            max_increment: 0.5,
            ..StepDef::default()
        },
        boundaries,
        pressures: (0..n_el)
            .map(|e| FacePressure {
                element: e,
                face: (e + 1) % faces,
                // Binary fractions with short decimals: read back exactly.
                magnitude: (e as f64 + 0.5) / 1024.0,
            })
            .collect(),
        point_loads: x1
            .iter()
            .map(|&node| PointLoad {
                node,
                dof: 2,
                magnitude: -0.01,
            })
            .collect(),
    }
}

fn text(d: &Deck3) -> String {
    let mut out = Vec::new();
    write_inp3(d, &mut out).unwrap();
    String::from_utf8(out).unwrap()
}

/// Every element type: the deck read back is the deck written (nodes exactly, connectivity,
/// labels, sets, surfaces, materials, regions, step, supports, pressures on every face
/// number, point loads), and writing it again gives the same text.
#[test]
fn decks_round_trip() {
    for kind in ElementKind3::ALL {
        let d = deck(kind);
        let t = text(&d);
        let r = parse_inp3(&t, "round.inp").unwrap_or_else(|e| panic!("{kind:?}: {e}\n{t}"));
        assert_eq!(r.mesh.nodes, d.mesh.nodes);
        assert_eq!(r.mesh.node_labels, d.mesh.node_labels);
        assert_eq!(r.mesh.element_labels.len(), d.mesh.elements.len());
        // Elements are written per region; compare by label.
        for (e, el) in d.mesh.elements.iter().enumerate() {
            let i = r
                .mesh
                .element_labels
                .iter()
                .position(|&l| l == d.mesh.element_labels[e])
                .unwrap();
            assert_eq!(r.mesh.elements[i], *el);
            assert_eq!(r.element_material[i], d.element_material[e]);
            assert_eq!(
                r.region_names[r.element_region[i]],
                d.region_names[d.element_region[e]]
            );
        }
        let same_order = r.mesh.element_labels == d.mesh.element_labels;
        assert!(same_order, "{kind:?}: the block's regions are contiguous");
        assert_eq!(r.mesh.element_set("LOWER"), d.mesh.element_set("LOWER"));
        assert_eq!(r.mesh.node_set("X1"), d.mesh.node_set("X1"));
        let mut skin = r.mesh.surface("SKIN").unwrap().to_vec();
        skin.sort_unstable();
        assert_eq!(skin, d.mesh.surfaces["SKIN"]);
        assert_eq!(r.materials.len(), 2);
        for (a, b) in r.materials.iter().zip(&d.materials) {
            assert_eq!(
                (&a.name, &a.keyword, &a.constants),
                (&b.name, &b.keyword, &b.constants)
            );
        }
        assert_eq!(r.step, d.step);
        let mut bcs = r.boundaries.clone();
        let mut want = d.boundaries.clone();
        let key = |b: &BoundaryCondition| (b.node, b.dof);
        bcs.sort_by_key(key);
        want.sort_by_key(key);
        assert_eq!(bcs, want);
        assert_eq!(r.pressures, d.pressures);
        assert_eq!(r.point_loads, d.point_loads);
        assert_eq!(text(&r), t, "{kind:?}: written twice");
    }
}

/// `t` with the z coordinate of its first node left out.
fn drop_z(t: &str) -> String {
    let mut lines: Vec<String> = t.lines().map(str::to_string).collect();
    let i = 1 + lines.iter().position(|l| l.starts_with("*NODE")).unwrap();
    let cut = lines[i].rfind(',').unwrap();
    lines[i].truncate(cut);
    lines.join("\n")
}

/// The reader's messages name the line and what is wrong.
#[test]
fn bad_3d_decks_are_refused_with_their_line() {
    let good = text(&deck(ElementKind3::C3d8));
    let line_of =
        |t: &str, needle: &str| 1 + t.lines().position(|l| l.starts_with(needle)).unwrap();
    let cases: Vec<(String, &str)> = vec![
        (
            good.replace("TYPE=C3D8,", "TYPE=CPE4,"),
            "C3D8, C3D8H, C3D4, C3D10",
        ),
        (good.replacen("100, S1", "100, S7", 1), "is not S1..S6"),
        (good.replacen(", P2,", ", P9,", 1), "P1..P6"),
        (drop_z(&good), "expected 'label, x, y, z'"),
        (
            good.replace("*CLOAD\n", "*CLOAD\n10, 4, 1.0\n"),
            "dof 4 is not a displacement dof",
        ),
        (
            good.replace("*BOUNDARY\n", "*BOUNDARY\n10, 4, 6\n"),
            "not a displacement dof",
        ),
    ];
    for (t, want) in cases {
        let err = parse_inp3(&t, "bad.inp").unwrap_err().to_string();
        assert!(err.contains(want), "{want}: {err}");
        assert!(err.starts_with("bad.inp:"), "{err}");
    }
    // An inverted hexahedron is named with its element's line.
    let inverted = good.replacen(
        "100, 10, 13, 22, 19, 28, 31, 40, 37",
        "100, 28, 31, 40, 37, 10, 13, 22, 19",
        1,
    );
    assert_ne!(inverted, good);
    let err = parse_inp3(&inverted, "bad.inp").unwrap_err().to_string();
    let line = line_of(&inverted, "100, 28");
    assert!(
        err.starts_with(&format!("bad.inp:{line}: element 100 is inverted")),
        "{err}"
    );
}
