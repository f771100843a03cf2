//! Sliding interfaces between two regions of a meshed thigh (`[[interface]]` tables, parsed by
//! [`crate::schema::parse_interfaces`]): the model with the mesh split along each sliding
//! interface ([`model_with_interfaces`]). A `tied` interface leaves the mesh as it is
//! (the regions share their nodes); `frictionless` and `friction` split the nodes of the two
//! regions' common boundary (its ends stay tied) and add a node-to-segment contact between the
//! two sides (`femu_mech::interface`), the first region's faces slave, the second's master.

use crate::bail;
use crate::error::Result;
use crate::schema::{InterfaceLaw, InterfaceSpec};
use femu_geometry::interface_split::{split_interface, InterfaceSplitError};
use femu_geometry::ThighModel;
use femu_mech::interface::{Interface, InterfaceKind};
use femu_mech::model::{ModelSpec as MechSpec, NamedMaterial};
use femu_mech::Model;

/// The model of `thigh` with `regions`' materials and the femur (node set `FEMUR`) fixed, its
/// mesh split along each sliding interface of `specs` and the interfaces added (search radius
/// twice the element size, each side also a surface `INTERFACE_A_B_SLAVE` / `_MASTER`), and its
/// skin faces (surface `SKIN`). Errors name the interface's
/// regions: a region the thigh does not have, two regions without a common edge. Without a
/// sliding interface (none, or only tied ones) it is the meshed thigh's model as meshed.
pub fn model_with_interfaces(
    thigh: &ThighModel,
    regions: Vec<NamedMaterial>,
    specs: &[InterfaceSpec],
) -> Result<(Model, Vec<(usize, usize)>)> {
    let mut mesh = thigh.mesh.clone();
    let mut splits = Vec::new();
    for spec in specs {
        let [a, b] = &spec.between;
        for r in [a, b] {
            if !thigh.regions.iter().any(|x| x.eq_ignore_ascii_case(r)) {
                bail!(
                    "[[interface]] between = [{a}, {b}]: no region {r} in the model ({})",
                    thigh.regions.join(", ")
                );
            }
        }
        let kind = match spec.law {
            InterfaceLaw::Tied => continue,
            InterfaceLaw::Frictionless => InterfaceKind::Frictionless,
            InterfaceLaw::Friction { mu } => InterfaceKind::Friction { mu },
        };
        let split = split_interface(&mut mesh.mesh, a, b).map_err(|e| match e {
            InterfaceSplitError::NoInterface(..) => crate::error::Error::Input(format!(
                "[[interface]] between = [{a}, {b}]: the regions do not touch (no common element edge)"
            )),
            e => crate::error::Error::Input(format!("[[interface]] between = [{a}, {b}]: {e}")),
        })?;
        // The two sides as surfaces of the model (`INTERFACE_A_B_SLAVE`, `..._MASTER`): the
        // model folder draws them, a deck written from the model names them.
        let name = spec.name();
        mesh.surfaces
            .insert(format!("INTERFACE_{name}_SLAVE"), split.a.faces.clone());
        mesh.surfaces
            .insert(format!("INTERFACE_{name}_MASTER"), split.b.faces.clone());
        splits.push((name, split, kind));
    }
    let spec = MechSpec::with_regions(mesh.mesh, mesh.surfaces, regions, "FEMUR")?;
    let mut model = Model::new(spec)?;
    for (name, split, kind) in splits {
        let iface = Interface::new(
            &name,
            &model.mesh,
            &split.a.faces,
            &split.b.faces,
            kind,
            2.0 * thigh.element_size_mm,
        )
        .map_err(|e| crate::error::Error::Input(format!("[[interface]] {name}: {e}")))?;
        model.interfaces.push(iface);
    }
    let skin = model.surface("SKIN").unwrap_or_default().to_vec();
    if skin.is_empty() {
        bail!("the model has no skin surface");
    }
    Ok((model, skin))
}

#[cfg(test)]
mod tests {
    use super::*;
    use femu_geometry::{parametric_thigh, ThighParams};
    use femu_mech::loading::{apply_loading, Loading};
    use femu_mech::{SolverOptions, StaticSolver};
    use femu_mesh::ElementKind;

    fn spec(a: &str, b: &str, law: InterfaceLaw) -> InterfaceSpec {
        InterfaceSpec {
            between: [a.to_string(), b.to_string()],
            law,
        }
    }

    /// The coarse built-in thigh: a tied interface gives the model without interfaces (the same
    /// solution, bit for bit); a frictionless QUADRICEPS–ISCHIO interface splits the nodes of
    /// their common boundary, and under the seed's compression the quadriceps slides (the
    /// solution differs from the tied one by less than its largest displacement); an unknown
    /// region and two regions that do not touch are errors naming the interface.
    #[test]
    fn the_thigh_splits_along_a_sliding_interface() {
        let t = parametric_thigh(&ThighParams::coarse(), ElementKind::Cpe4).unwrap();
        let regions = crate::model::materials(&[], &t.regions).unwrap();
        let solve = |specs: &[InterfaceSpec]| {
            let (mut model, skin) = model_with_interfaces(&t, regions.clone(), specs).unwrap();
            apply_loading(&mut model, &skin, &Loading::seed_compression()).unwrap();
            let mut solver = StaticSolver::new(&model, SolverOptions::default()).unwrap();
            let u = solver.solve(&model).unwrap().u;
            (model, u)
        };
        let (plain, u_plain) = solve(&[]);
        let (tied, u_tied) = solve(&[spec("QUADRICEPS", "ISCHIO", InterfaceLaw::Tied)]);
        assert!(tied.interfaces.is_empty());
        assert_eq!(u_plain, u_tied);
        let (sliding, u) = solve(&[spec("quadriceps", "ISCHIO", InterfaceLaw::Frictionless)]);
        assert_eq!(sliding.interfaces.len(), 1);
        assert!(sliding.node_count() > plain.node_count());
        let n = plain.node_count();
        let (mut du, mut umax) = (0.0f64, 0.0f64);
        for k in 0..n {
            du = du.max((u[2 * k] - u_plain[2 * k]).hypot(u[2 * k + 1] - u_plain[2 * k + 1]));
            umax = umax.max(u_plain[2 * k].hypot(u_plain[2 * k + 1]));
        }
        assert!(du > 0.0 && du < umax, "{du:.3e} vs {umax:.3e}");

        let bad = |specs: &[InterfaceSpec]| {
            model_with_interfaces(&t, regions.clone(), specs)
                .unwrap_err()
                .to_string()
        };
        let e = bad(&[spec("QUADRICEPS", "GLUTEUS", InterfaceLaw::Frictionless)]);
        assert!(
            e.contains("[[interface]]") && e.contains("no region GLUTEUS"),
            "{e}"
        );
        // Some pair of the thigh's regions has no common edge.
        let mut apart = 0;
        for (i, a) in t.regions.iter().enumerate() {
            for b in &t.regions[i + 1..] {
                if let Err(e) = model_with_interfaces(
                    &t,
                    regions.clone(),
                    &[spec(a, b, InterfaceLaw::Frictionless)],
                ) {
                    let e = e.to_string();
                    assert!(e.contains("do not touch") && e.contains(a.as_str()), "{e}");
                    apart += 1;
                }
            }
        }
        assert!(apart > 0, "every pair of {:?} touches", t.regions);
    }
}
