use super::*;

/// Two CPE4 elements in two regions, sets by GENERATE and by name, comments, continuation
/// lines, mixed case.
const GOOD: &str = "\
** a comment
*Heading
 two quads
*Node, nset=Everything
1, 0.0, 0.0
2, 1.0, 0.0
3, 2.0, 0.0, 0.0
4, 0.0, 1.0
5, 1.0,
 1.0
6, 2.0, 1.0

*Element, type=CPE4, elset=Fat
1, 1, 2, 5, 4
*ELEMENT, TYPE=cpe4h, ELSET=Muscle
2, 2, 3,
6, 5
*nset, nset=Left, generate
1, 4, 3
*NSET, NSET=Right
3, 6
*NSET, NSET=Sides
left, RIGHT
*Elset, Elset=All, GENERATE
1, 2
*material, name=FatMat
*hyperelastic, neo hooke
0.00175, 1.0
*Material, Name=MUSCLEMAT
*HyperElastic,NEOHOOKE
0.01, 0.5d0
*Solid Section, Elset=FAT, Material=fatmat
1.
*SOLIDSECTION, ELSET=muscle, MATERIAL=MuscleMat
*BOUNDARY
LEFT, 1, 2
*Step, nlgeom, inc=50
*Static
0.1, 1.0
*BOUNDARY
right, 1, 1, 0.25
left, 1, 6
*Dload
2, p2, -0.01
FAT, P3, 0.02
*Cload
6, 2, 1e-3
*NODE PRINT, NSET=Everything
U
*EL FILE
S, E
*End Step
";

fn parse(text: &str) -> Result<Deck> {
    parse_inp(text, "model.inp")
}

fn err(text: &str) -> String {
    match parse(text) {
        Ok(_) => panic!("expected an error"),
        Err(e) => e.to_string(),
    }
}

#[test]
fn good_deck() {
    let d = parse(GOOD).unwrap();
    let m = &d.mesh;
    assert_eq!(m.nodes.len(), 6);
    assert_eq!(m.nodes[4], [1.0, 1.0]);
    assert_eq!(m.elements.len(), 2);
    assert_eq!(m.elements[0].kind, ElementKind::Cpe4);
    assert_eq!(m.elements[1].kind, ElementKind::Cpe4h);
    assert_eq!(m.elements[1].conn, [1, 2, 5, 4]);
    assert_eq!(m.node_sets["Left"], vec![0, 3]);
    assert_eq!(m.node_sets["Sides"], vec![0, 2, 3, 5]);
    assert_eq!(m.node_sets["Everything"].len(), 6);
    assert_eq!(m.element_sets["All"], vec![0, 1]);
    assert_eq!(m.element_sets["Fat"], vec![0]);
    assert_eq!(
        d.region_names,
        vec!["FAT".to_string(), "muscle".to_string()]
    );
    assert_eq!(d.element_region, vec![0, 1]);
    assert_eq!(d.element_material, vec![0, 1]);
    assert_eq!(d.materials[0].name, "FatMat");
    assert_eq!(d.materials[0].keyword, "NEO HOOKE");
    assert_eq!(d.materials[0].constants, vec![0.00175, 1.0]);
    assert_eq!(d.materials[0].line, Some(28));
    assert_eq!(d.materials[1].keyword, "NEOHOOKE");
    assert_eq!(d.materials[1].constants, vec![0.01, 0.5]);
    assert!(d.step.nlgeom);
    assert_eq!(d.step.max_increments, 50);
    assert_eq!(d.step.initial_increment, 0.1);
    assert_eq!(d.step.period, 1.0);
    assert_eq!(d.step.min_increment, 1e-5);
    assert_eq!(d.step.max_increment, 1.0);
    // LEFT fixed in x and y (again by the later `1, 6`: the out-of-plane dofs 3..6 are absent
    // in plane strain), RIGHT moved in x.
    let bc = |n: usize, dof: usize| {
        d.boundaries
            .iter()
            .find(|b| b.node == n && b.dof == dof)
            .map(|b| b.value)
    };
    assert_eq!(d.boundaries.len(), 6);
    assert_eq!(bc(0, 0), Some(0.0));
    assert_eq!(bc(3, 1), Some(0.0));
    assert_eq!(bc(2, 0), Some(0.25));
    assert_eq!(bc(5, 0), Some(0.25));
    assert_eq!(bc(2, 1), None);
    assert_eq!(
        d.pressures,
        vec![
            FacePressure {
                element: 1,
                face: 1,
                magnitude: -0.01
            },
            FacePressure {
                element: 0,
                face: 2,
                magnitude: 0.02
            }
        ]
    );
    assert_eq!(
        d.point_loads,
        vec![PointLoad {
            node: 5,
            dof: 1,
            magnitude: 1e-3
        }]
    );
}

#[test]
fn static_defaults_and_nlgeom() {
    let base = GOOD.replace("*Step, nlgeom, inc=50", "*STEP");
    let d = parse(&base.replace("0.1, 1.0\n", "")).unwrap();
    assert!(
        d.step.nlgeom,
        "ccx switches NLGEOM on for hyperelastic materials"
    );
    assert_eq!(d.step.max_increments, 100);
    assert_eq!(
        (
            d.step.initial_increment,
            d.step.period,
            d.step.max_increment
        ),
        (1.0, 1.0, 1.0)
    );
    let d = parse(&base.replace("0.1, 1.0\n", ", 2.0, , 0.5\n")).unwrap();
    assert_eq!(d.step.initial_increment, 2.0);
    assert_eq!(d.step.period, 2.0);
    assert_eq!(d.step.min_increment, 2e-5);
    assert_eq!(d.step.max_increment, 0.5);
    let d = parse(&GOOD.replace("*Step, nlgeom, inc=50", "*STEP, NLGEOM=NO")).unwrap();
    assert!(!d.step.nlgeom);
}

#[test]
fn surfaces() {
    let text = GOOD.replace(
        "*Step, nlgeom, inc=50",
        "*SURFACE, NAME=Skin, TYPE=ELEMENT\nFat, S4\n2, S2\n*Step, nlgeom, inc=50",
    );
    let text = text.replace("2, p2, -0.01\nFAT, P3, 0.02", "skin, P, 0.03");
    let d = parse(&text).unwrap();
    assert_eq!(d.pressures.len(), 2);
    assert_eq!((d.pressures[0].element, d.pressures[0].face), (0, 3));
    assert_eq!((d.pressures[1].element, d.pressures[1].face), (1, 1));
}

#[test]
fn replaced_loads() {
    let text = GOOD.replace("6, 2, 1e-3", "6, 2, 1e-3\nRight, 2, 2e-3");
    let d = parse(&text).unwrap();
    assert_eq!(d.point_loads.len(), 2);
    assert_eq!(d.point_loads[0].magnitude, 2e-3);
}

#[test]
fn errors_name_file_line_and_problem() {
    let cases: Vec<(String, &str)> = vec![
        (
            GOOD.replace("type=CPE4, elset=Fat", "type=C3D8, elset=Fat"),
            "model.inp:13: unknown element type 'C3D8' in *ELEMENT (supported: CPE4, CPE4H, CPE3)",
        ),
        (
            GOOD.replace("4, 0.0, 1.0", "4, abc, 1.0"),
            "model.inp:8: cannot read 'abc' as a number",
        ),
        (
            GOOD.replace("Material=fatmat", "Material=FAT"),
            "model.inp:32: *SOLID SECTION: material 'FAT' is not defined",
        ),
        (
            GOOD.replace("LEFT, 1, 2", "FEMUR, 1, 2"),
            "model.inp:36: *BOUNDARY: node set 'FEMUR' is not defined",
        ),
        (
            GOOD.replace(
                "*Material, Name=MUSCLEMAT",
                "*PLASTIC\n*Material, Name=MUSCLEMAT",
            ),
            "model.inp:29: *PLASTIC is not supported (it would change the physics)",
        ),
        (
            GOOD.replace("*Static", "*Contact Pair, interaction=x\n*Static"),
            "model.inp:38: *CONTACT PAIR is not supported (it would change the physics)",
        ),
        (
            GOOD.replace("*SOLIDSECTION, ELSET=muscle, MATERIAL=MuscleMat", ""),
            "model.inp:16: element 2 has no *SOLID SECTION",
        ),
        (
            GOOD.replace("1, 1, 2, 5, 4", "1, 1, 4, 5, 2"),
            "model.inp:14: element 1 is inverted or degenerate",
        ),
        (
            GOOD.replace("0.01, 0.5d0", "0.01, x"),
            "model.inp:31: cannot read 'x' as a number",
        ),
        (
            GOOD.replace("0.01, 0.5d0", "0.01, 0.5\n0.02, 0.5"),
            "model.inp:32: *HYPERELASTIC: one data line expected",
        ),
        (
            GOOD.replace("0.01, 0.5d0\n", ""),
            "model.inp:30: *HYPERELASTIC, NEOHOOKE needs a data line",
        ),
        (
            GOOD.replace("*hyperelastic, neo hooke\n0.00175, 1.0\n", ""),
            "model.inp:26: material 'FatMat' has no *HYPERELASTIC definition",
        ),
        (
            GOOD.replace("*hyperelastic, neo hooke", "*hyperelastic, polynomial, n=1"),
            "model.inp:27: *HYPERELASTIC needs exactly one parameter, the law (e.g. *HYPERELASTIC, NEO HOOKE); given: POLYNOMIAL, N",
        ),
        (
            GOOD.replace("*End Step", "*End Step\n*STEP\n*STATIC\n*END STEP"),
            "model.inp:53: a second *STEP is not supported",
        ),
        (
            GOOD.replace("*End Step", ""),
            "model.inp:37: this *STEP has no *END STEP",
        ),
        (
            GOOD.replace("*End Step", "*End Step\n*NODE\n7, 0, 0"),
            "model.inp:53: *NODE is model data and must come before *STEP",
        ),
        (
            GOOD.replace("*Dload", "*DLOAD, AMPLITUDE=A1"),
            "model.inp:43: *DLOAD: parameter 'AMPLITUDE' is not supported",
        ),
        (
            GOOD.replace("2, p2, -0.01", "2, P5, -0.01"),
            "model.inp:44: *DLOAD: load type 'P5' is not supported",
        ),
        (
            GOOD.replace("2, p2, -0.01", "99, P2, -0.01"),
            "model.inp:44: *DLOAD: element 99 is not defined",
        ),
        (
            GOOD.replace(
                "*ELEMENT, TYPE=cpe4h, ELSET=Muscle\n2, 2, 3,\n6, 5",
                "*ELEMENT, TYPE=CPE3, ELSET=Muscle\n2, 2, 3, 6",
            )
            .replace("2, p2, -0.01", "2, P4, -0.01"),
            "model.inp:43: *DLOAD: element 2 is a CPE3 with faces P1..P3, not P4",
        ),
        (
            // Issue 28.4: a GENERATE range refused before it is allocated.
            GOOD.replace("1, 4, 3\n", "1, 1000000000, 1\n"),
            "model.inp:19: *NSET, GENERATE: 1, 1000000000, 1 makes 1000000000 members, above the limit of 10000000",
        ),
        (
            // A *BOUNDARY on a dof plane strain lacks would leave the node free (issue 32.5).
            GOOD.replace("right, 1, 1, 0.25", "right, 7, 7"),
            "model.inp:41: *BOUNDARY: dof 7: not a dof of plane strain (only 1 = x and 2 = y)",
        ),
        (
            GOOD.replace("right, 1, 1, 0.25", "right, 3, 6"),
            "model.inp:41: *BOUNDARY: dofs 3 to 6: not a dof of plane strain",
        ),
        (
            GOOD.replace("right, 1, 1, 0.25", "right, 1, 8"),
            "model.inp:41: *BOUNDARY: dof 8 is not a displacement dof",
        ),
        (
            GOOD.replace("6, 2, 1e-3", "6, 3, 1e-3"),
            "model.inp:47: *CLOAD: dof 3 does not exist in plane strain",
        ),
        (
            GOOD.replace("1.\n*SOLIDSECTION", "2.\n*SOLIDSECTION"),
            "model.inp:33: *SOLID SECTION: thickness 2 is not supported",
        ),
        (
            GOOD.replace("left, RIGHT", "left, FEMUR"),
            "model.inp:23: *NSET: node set 'FEMUR' is not defined",
        ),
        (
            GOOD.replace("3, 6\n", "3, 66\n"),
            "model.inp:21: set 'Right': node 66 is not defined",
        ),
        (
            GOOD.replace("1, 1, 2, 5, 4", "1, 1, 2, 5, 44"),
            "model.inp:14: element 1 refers to node 44, which is not defined",
        ),
        (
            GOOD.replace("1, 1, 2, 5, 4", "1, 1, 2, 5"),
            "model.inp:14: *ELEMENT, TYPE=CPE4: element 1 needs 4 node labels, got 3",
        ),
        (
            GOOD.replace("6, 2.0, 1.0", "5, 2.0, 1.0"),
            "model.inp:11: node 5 is defined twice",
        ),
        (
            GOOD.replace("2, 2, 3,\n6, 5", "1, 2, 3,\n6, 5"),
            "model.inp:16: element 1 is defined twice",
        ),
        (
            GOOD.replace(
                "*Elset, Elset=All, GENERATE",
                "*Elset, Elset=Fat\n2\n*Elset, Elset=All, GENERATE",
            ),
            "model.inp:36: element 2 is in two *SOLID SECTIONs (lines 34 and 36)",
        ),
        (
            GOOD.replace("*Static\n0.1, 1.0\n", ""),
            "model.inp:50: the *STEP on line 37 has no *STATIC procedure",
        ),
        (
            GOOD.replace("right, 1, 1, 0.25", "right, ENCASTRE"),
            "model.inp:41: *BOUNDARY: boundary type 'ENCASTRE' is not supported",
        ),
        (
            GOOD.replace("*hyperelastic, neo hooke", "*hyperelastic"),
            "model.inp:27: *HYPERELASTIC needs exactly one parameter, the law (e.g. *HYPERELASTIC, NEO HOOKE); given: none, which means POLYNOMIAL",
        ),
        (
            GOOD.replace("*Heading", "*Part, name=P"),
            "model.inp:2: *PART is not supported (femu reads",
        ),
        (
            GOOD.replace("*Step, nlgeom, inc=50", "*Step, nlgeom, inc=0"),
            "model.inp:37: *STEP: INC=0 is not a positive integer",
        ),
    ];
    for (text, expected) in cases {
        let msg = err(&text);
        assert!(
            msg.starts_with(expected),
            "expected '{expected}...'\n     got '{msg}'"
        );
    }
    let cases_no_step = GOOD.split("*Step").next().unwrap().to_string();
    assert_eq!(
        err(&cases_no_step),
        "model.inp: the deck has no *STEP (femu solves exactly one static step)"
    );
    assert!(err("1, 2, 3\n*NODE").starts_with("model.inp:1: data line before the first keyword"));
}

#[test]
fn no_panic_on_garbage() {
    for text in [
        "",
        "*",
        "*NODE\n,",
        "*ELEMENT, TYPE=CPE3\n,\n",
        "*ELEMENT, TYPE=CPE3\n1,\n",
        "*NSET, NSET=A, GENERATE\n1\n",
        "*NSET, NSET=A, GENERATE\n9223372036854775806, 9223372036854775807\n",
        "*NSET, NSET=A, GENERATE\n-9223372036854775808, 9223372036854775807\n",
        "*STEP\n*STATIC\n,,,,\n*END STEP",
        "*STEP\n*STATIC\n*DLOAD\n1\n*END STEP",
        "*STEP\n*STATIC\n*BOUNDARY\n1,\n*END STEP",
        "*STEP\n*STATIC\n*BOUNDARY\nA, 2, 1\n*END STEP",
        "*MATERIAL\n*HYPERELASTIC, NEO HOOKE\n1e400, 1\n",
        "*STEP, NLGEOM=\n",
        "*SURFACE, NAME=S\nA\n",
        "*HYPERELASTIC, NEO HOOKE\n1, 1\n",
    ] {
        assert!(parse(text).is_err(), "{text:?} should be an error");
    }
}

#[test]
fn round_trip() {
    let d = parse(GOOD).unwrap();
    let mut buf = Vec::new();
    write_inp(&d, &mut buf).unwrap();
    let text = String::from_utf8(buf).unwrap();
    let d2 = parse(&text).unwrap();
    assert_eq!(d2.mesh.nodes, d.mesh.nodes);
    assert_eq!(d2.mesh.node_labels, d.mesh.node_labels);
    assert_eq!(d2.mesh.elements, d.mesh.elements);
    assert_eq!(d2.mesh.element_labels, d.mesh.element_labels);
    // The same materials; only the lines of their data differ.
    let without_lines = |d: &Deck| {
        d.materials
            .iter()
            .map(|m| (m.name.clone(), m.keyword.clone(), m.constants.clone()))
            .collect::<Vec<_>>()
    };
    assert_eq!(without_lines(&d2), without_lines(&d));
    assert!(d2.materials.iter().all(|m| m.line.is_some()));
    assert_eq!(d2.element_material, d.element_material);
    assert_eq!(d2.element_region, d.element_region);
    assert_eq!(d2.region_names, d.region_names);
    assert_eq!(d2.step, d.step);
    let mut b1 = d.boundaries.clone();
    let mut b2 = d2.boundaries.clone();
    let key = |b: &BoundaryCondition| (b.node, b.dof);
    b1.sort_by_key(key);
    b2.sort_by_key(key);
    assert_eq!(b1, b2);
    assert_eq!(d2.pressures, d.pressures);
    assert_eq!(d2.point_loads, d.point_loads);
    for (name, set) in &d.mesh.node_sets {
        assert_eq!(&d2.mesh.node_sets[name], set, "node set {name}");
    }
    for (name, set) in &d.mesh.element_sets {
        let found = d2
            .mesh
            .element_sets
            .iter()
            .find(|(n, _)| n.eq_ignore_ascii_case(name))
            .map(|(_, s)| s);
        assert_eq!(found, Some(set), "element set {name}");
    }
    // Full precision survives.
    let mut d3 = d.clone();
    d3.mesh.nodes[1][0] = 1.0 + f64::EPSILON;
    d3.mesh.nodes[2][1] = 1.0 / 3.0 * 1e-7;
    let mut buf = Vec::new();
    write_inp(&d3, &mut buf).unwrap();
    let d4 = parse(std::str::from_utf8(&buf).unwrap()).unwrap();
    assert_eq!(d4.mesh.nodes, d3.mesh.nodes);
}

#[test]
fn writer_rejects_bad_names_and_mixed_regions() {
    let mut d = parse(GOOD).unwrap();
    d.region_names[0] = "fat layer".into();
    assert!(write_inp(&d, &mut Vec::new()).is_err());
    let mut d = parse(GOOD).unwrap();
    d.element_material[1] = 0;
    d.element_region[1] = 0;
    assert!(write_inp(&d, &mut Vec::new()).is_ok());
    d.element_material[1] = 1;
    let e = write_inp(&d, &mut Vec::new()).unwrap_err();
    assert!(e.to_string().contains("two materials"), "{e}");
}

/// A 2x2 CPE4 block, 1 mm squares, left edge fixed, pressure on the right edge, pulled up at
/// the top right corner.
fn block_2x2() -> Deck {
    let mut mesh = Mesh::default();
    for j in 0..3 {
        for i in 0..3 {
            mesh.add_node([i as f64, j as f64]);
        }
    }
    for j in 0..2 {
        for i in 0..2 {
            let n = j * 3 + i;
            mesh.add_element(Element::quad(ElementKind::Cpe4, [n, n + 1, n + 4, n + 3]));
        }
    }
    mesh.node_sets.insert("Left".into(), vec![0, 3, 6]);
    let mut boundaries = Vec::new();
    for n in [0, 3, 6] {
        for dof in 0..2 {
            boundaries.push(BoundaryCondition {
                node: n,
                dof,
                value: 0.0,
            });
        }
    }
    boundaries.push(BoundaryCondition {
        node: 8,
        dof: 0,
        value: 0.02,
    });
    Deck {
        mesh,
        materials: vec![MaterialDef {
            name: "Fat".into(),
            keyword: "NEO HOOKE".into(),
            constants: vec![0.00175, 10.0],
            line: None,
        }],
        element_material: vec![0; 4],
        element_region: vec![0; 4],
        region_names: vec!["Tissue".into()],
        step: StepDef {
            initial_increment: 0.25,
            ..StepDef::default()
        },
        boundaries,
        pressures: vec![FacePressure {
            element: 1,
            face: 1,
            magnitude: 1e-4,
        }],
        point_loads: vec![PointLoad {
            node: 8,
            dof: 1,
            magnitude: 1e-4,
        }],
    }
}

fn scratch_dir(name: &str) -> std::path::PathBuf {
    let dir = std::env::temp_dir().join(format!("femu-mesh-{}-{name}", std::process::id()));
    let _ = fs::remove_dir_all(&dir);
    fs::create_dir_all(&dir).unwrap();
    dir
}

#[test]
fn written_deck_runs_in_ccx() {
    let deck = block_2x2();
    let dir = scratch_dir("ccx");
    let inp = dir.join("block.inp");
    write_inp_file(&deck, &inp).unwrap();
    // Our own reader accepts it.
    let back = read_inp(&inp).unwrap();
    assert_eq!(back.mesh.nodes, deck.mesh.nodes);
    assert_eq!(back.pressures, deck.pressures);

    let ccx_found = std::env::var_os("PATH")
        .map(|p| std::env::split_paths(&p).any(|d| d.join("ccx").is_file()))
        .unwrap_or(false);
    if !ccx_found {
        println!("ccx is not on PATH: skipping the CalculiX run");
        return;
    }
    let out = std::process::Command::new("ccx")
        .args(["-i", "block"])
        .current_dir(&dir)
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "ccx failed: {}",
        String::from_utf8_lossy(&out.stdout)
    );
    let u = read_ccx_dat_displacements(&dir.join("block.dat")).unwrap();
    assert_eq!(u.len(), 9);
    let labels: Vec<i64> = u.iter().map(|r| r.0).collect();
    assert_eq!(labels, (1..=9).collect::<Vec<_>>());
    for (label, d) in &u {
        if [1, 4, 7].contains(label) {
            assert_eq!(*d, [0.0, 0.0]);
        }
    }
    // The prescribed displacement is reached at the end of the step.
    assert!((u[8].1[0] - 0.02).abs() < 1e-9, "{:?}", u[8]);
    assert!(u[8].1[1] > 0.0);
    let _ = fs::remove_dir_all(&dir);
}

#[test]
fn ccx_dat_parsing() {
    let text = "
 displacements (vx,vy,vz) for set NALL and time  0.5000000E+00

         1  0.000000E+00  0.000000E+00  0.000000E+00
         2  1.000000E-03  2.000000E-03  0.000000E+00

 displacements (vx,vy,vz) for set NALL and time  0.1000000E+01

         1  0.000000E+00  0.000000E+00  0.000000E+00
         2  3.413080E-03 -8.046404-100  0.000000E+00

 stresses (elem, integ.pnt.,sxx,syy,szz,sxy,sxz,syz) for set EALL and time  0.1000000E+01
";
    let u = parse_ccx_dat_displacements(text, "x.dat").unwrap();
    assert_eq!(u, vec![(1, [0.0, 0.0]), (2, [3.413080e-3, -8.046404e-100])]);
    assert!(parse_ccx_dat_displacements("nothing", "x.dat").is_err());
    let bad = " displacements (vx,vy,vz) for set NALL and time 1\n\n 1 a b c\n";
    assert_eq!(
        parse_ccx_dat_displacements(bad, "x.dat")
            .unwrap_err()
            .to_string(),
        "x.dat:3: cannot read '1 a b c' as 'node ux uy uz'"
    );
}

#[test]
fn deck_dimension_reads_the_first_element_type() {
    assert_eq!(deck_dimension(GOOD), 2);
    assert_eq!(
        deck_dimension(
            "** c\n*NODE\n1,0,0,0\n*Element , Type = c3d8h, elset=A\n1,1,2,3,4,5,6,7,8\n"
        ),
        3
    );
    assert_eq!(deck_dimension("*ELEMENT, ELSET=A, TYPE=C3D10\n"), 3);
    assert_eq!(deck_dimension("*ELEMENTOUTPUT\n*ELEMENT, TYPE=CPE4\n"), 2);
    assert_eq!(deck_dimension("*NODE\n1,0,0\n"), 2);
}
