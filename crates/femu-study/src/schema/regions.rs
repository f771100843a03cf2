//! The regions of the model a study describes, their laws and their parameters, known before
//! the mesh is built: the built-in thigh's five tissues, a label map's region names (issue
//! 32.13: any name, `6=adductor`, with the material its `[materials.ADDUCTOR]` table gives), or
//! a deck's materials (read from the file by [`super::read`]).
//!
//! Checked at once, so that nothing runs on a study that would fail later (issue 32.11): every
//! `[materials.REGION]` names a region of the model; a region outside the seed's Table 1 gets
//! its whole material from its table (its law's every parameter; Neo-Hookean unless `law`
//! names another), and a region with no material at all names the table to add; every name in
//! `[identification] fixed` and `[parameters] groups` is a parameter of the model (even when
//! `grouped = false`, a misspelt group is a mistake).

use super::lines::KeyLines;
use super::{Geometry, MaterialSpec, StudyError};
use femu_geometry::{LabelSpec, SEED_REGIONS, TABLE1};
use femu_mech::material::{law, LawSpec};

/// A region (or a deck's material) and the law of its material.
pub(crate) struct RegionLaw {
    pub name: String,
    pub law: &'static LawSpec,
}

/// Whether `region` has a Table 1 material (the seed's five tissues).
fn in_table1(region: &str) -> bool {
    TABLE1
        .iter()
        .any(|(r, _, _)| r.eq_ignore_ascii_case(region))
}

/// The regions of a built-in thigh or a label map with their laws (`None` for a deck, whose
/// materials are in its file); errors name the `[materials]` table or the `[labels] map`.
pub(crate) fn of_geometry(
    geometry: &Geometry,
    materials: &[MaterialSpec],
    lines: &KeyLines,
) -> Result<Option<Vec<RegionLaw>>, StudyError> {
    let (regions, source): (Vec<String>, &str) = match geometry {
        Geometry::Thigh(_) => (
            SEED_REGIONS.iter().map(|s| s.to_string()).collect(),
            "the built-in thigh",
        ),
        Geometry::Labels(l) => (
            LabelSpec::new(&l.map, &l.bone, &l.background)
                .map_err(|e| lines.err("labels", 0, "map", e.to_string()))?
                .region_names(),
            "the [labels] map",
        ),
        Geometry::Deck(_) => return Ok(None),
    };
    for m in materials {
        if !regions.iter().any(|r| r.eq_ignore_ascii_case(&m.region)) {
            return Err(lines.err(
                &format!("materials.{}", m.region),
                0,
                "",
                format!(
                    "no region {} in {source} (regions: {})",
                    m.region,
                    regions.join(", ")
                ),
            ));
        }
    }
    let neo_hookean = law("neo-hookean").expect("registered").spec;
    regions
        .into_iter()
        .map(|r| {
            let spec = materials.iter().find(|m| m.region.eq_ignore_ascii_case(&r));
            let law = match spec {
                Some(s) if !in_table1(&r) => {
                    // A new region: its table is its whole material.
                    let at = format!("materials.{}", s.region);
                    s.build().map_err(|e| {
                        lines.err(&at, 0, "", format!("region {r} is not in Table 1, so its table gives its whole material: {e}"))
                    })?;
                    s.law.map_or(neo_hookean, |l| l.spec)
                }
                Some(s) => s.law.map_or(neo_hookean, |l| l.spec),
                None if in_table1(&r) => neo_hookean,
                None => {
                    return Err(lines.err(
                        "labels",
                        0,
                        "map",
                        format!(
                            "region {r} has no material (it is not in the seed's Table 1): add a [materials.{r}] table with c10_kpa and d_per_mpa (or law = \"...\" and its keys), or map its label to a Table 1 region"
                        ),
                    ))
                }
            };
            Ok(RegionLaw { name: r, law })
        })
        .collect::<Result<Vec<_>, _>>()
        .map(Some)
}

/// Checks that every name of `fixed` and of `groups` (when the study gives them) is a
/// parameter of `regions` (`C10_FAT`, `D_ADDUCTOR`, `C01_QUADRICEPS`, ...).
pub(crate) fn check_parameter_names(
    regions: &[RegionLaw],
    fixed: &[String],
    groups: Option<&[Vec<String>]>,
    lines: &KeyLines,
) -> Result<(), StudyError> {
    let names: Vec<String> = regions
        .iter()
        .flat_map(|r| {
            r.law
                .parameters
                .iter()
                .map(move |p| format!("{}_{}", p.name, r.name))
        })
        .collect();
    let known = |n: &String| names.iter().any(|k| k.eq_ignore_ascii_case(n));
    if let Some(f) = fixed.iter().find(|f| !known(f)) {
        return Err(lines.err(
            "identification",
            0,
            "fixed",
            format!("unknown parameter '{f}' (parameters: {})", names.join(", ")),
        ));
    }
    for (k, group) in groups.unwrap_or_default().iter().enumerate() {
        if let Some(n) = group.iter().find(|n| !known(n)) {
            return Err(lines.err(
                "parameters",
                0,
                "groups",
                format!(
                    "group {} names the unknown parameter '{n}' (parameters: {})",
                    k + 1,
                    names.join(", ")
                ),
            ));
        }
    }
    Ok(())
}
