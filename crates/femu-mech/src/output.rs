//! Result files of a solve (conventions.md): `displacements.csv`, `result.vtu` and the
//! element fields they carry (logarithmic strain LE as in the seed's Fig. 3, Cauchy stress).

use crate::element::{formulation, ElementAverages};
use crate::model::Model;
use crate::solver::Solution;
use femu_mesh::atomic::AtomicFile;
use femu_mesh::decimal::push_f64;
use femu_mesh::{FieldSet, FieldWriter, VtuField, VtuIntField, VtuWriter};
use rayon::prelude::*;
use std::io::{self, Write};
use std::path::Path;

/// Element-average fields of a deformed state.
#[derive(Debug, Clone)]
pub struct ElementFields {
    /// Logarithmic strain `[LExx, LEyy, LEzz, LExy]` per element.
    pub log_strain: Vec<[f64; 4]>,
    /// Cauchy stress `[σxx, σyy, σzz, σxy]` per element (MPa).
    pub cauchy_stress: Vec<[f64; 4]>,
    /// Volume ratio J = det F, averaged over the Gauss points.
    pub volume_ratio: Vec<f64>,
}

/// Computes LE, Cauchy stress and J for every element (in parallel). An element inverted in
/// `u` gets NaN entries (never the case for a converged state).
pub fn element_fields(model: &Model, u: &[f64]) -> ElementFields {
    let rows: Vec<ElementAverages> = (0..model.mesh.elements.len())
        .into_par_iter()
        .map(|e| {
            let geo = &model.geometry[e];
            let ue = model.gather(e, u);
            let mat = &model.materials[model.element_material[e]].law;
            formulation(geo.kind)
                .averages(geo, &**mat, &ue[..geo.n_nodes])
                .unwrap_or(ElementAverages {
                    log_strain: [f64::NAN; 4],
                    cauchy_stress: [f64::NAN; 4],
                    volume_ratio: f64::NAN,
                })
        })
        .collect();
    ElementFields {
        log_strain: rows.iter().map(|r| r.log_strain).collect(),
        cauchy_stress: rows.iter().map(|r| r.cauchy_stress).collect(),
        volume_ratio: rows.iter().map(|r| r.volume_ratio).collect(),
    }
}

/// Writes `node,x,y,ux,uy` with the deck's node labels, at full double precision: each value
/// as the shortest decimal that reads back to it ([`femu_mesh::decimal::push_f64`], Rust's
/// `{:?}` notation). The rows are formatted in parallel blocks of 2048, eight blocks at a
/// time, and written in order.
pub fn write_displacements_csv(path: &Path, model: &Model, u: &[f64]) -> io::Result<()> {
    const ROWS_PER_TASK: usize = 2048;
    const BLOCKS_PER_WAVE: usize = 8;
    let n_nodes = model.mesh.nodes.len();
    let n_blocks = n_nodes.div_ceil(ROWS_PER_TASK);
    let mut w = AtomicFile::create(path)?;
    writeln!(w, "node,x,y,ux,uy")?;
    for wave in (0..n_blocks).step_by(BLOCKS_PER_WAVE) {
        let blocks: Vec<Vec<u8>> = (wave..(wave + BLOCKS_PER_WAVE).min(n_blocks))
            .into_par_iter()
            .map(|b| {
                let rows = b * ROWS_PER_TASK..((b + 1) * ROWS_PER_TASK).min(n_nodes);
                let mut buf = Vec::with_capacity(rows.len() * 96);
                let (mut label, mut ryu) = (itoa::Buffer::new(), ryu::Buffer::new());
                for n in rows {
                    let x = model.mesh.nodes[n];
                    buf.extend_from_slice(label.format(model.mesh.node_labels[n]).as_bytes());
                    for v in [x[0], x[1], u[2 * n], u[2 * n + 1]] {
                        buf.push(b',');
                        push_f64(&mut buf, v, &mut ryu);
                    }
                    buf.push(b'\n');
                }
                buf
            })
            .collect();
        for b in &blocks {
            w.write_all(b)?;
        }
    }
    w.commit()
}

/// Writes the ParaView file ([`write_result_fields`] with [`VtuWriter`]).
pub fn write_result_vtu(path: &Path, model: &Model, solution: &Solution) -> io::Result<()> {
    write_result_fields(&VtuWriter, path, model, solution)
}

/// Writes the result fields with `writer`: point fields `displacement` and `reaction_force`;
/// cell fields `LE`, `S` (Cauchy stress, components xx, yy, zz, xy), `J`, and the integer
/// `region` and `material`.
pub fn write_result_fields(
    writer: &dyn FieldWriter,
    path: &Path,
    model: &Model,
    solution: &Solution,
) -> io::Result<()> {
    let fields = element_fields(model, &solution.u);
    let disp: Vec<[f64; 2]> = solution.u.chunks_exact(2).map(|c| [c[0], c[1]]).collect();
    let reaction: Vec<f64> = solution
        .reactions
        .chunks_exact(2)
        .flat_map(|c| [c[0], c[1], 0.0])
        .collect();
    let le: Vec<f64> = fields.log_strain.iter().flatten().copied().collect();
    let s: Vec<f64> = fields.cauchy_stress.iter().flatten().copied().collect();
    let region: Vec<i32> = model.element_region.iter().map(|&r| r as i32).collect();
    let material: Vec<i32> = model.element_material.iter().map(|&m| m as i32).collect();
    writer.write(
        path,
        &FieldSet {
            mesh: &model.mesh,
            displacement: Some(&disp),
            point_fields: &[VtuField {
                name: "reaction_force",
                components: 3,
                data: &reaction,
            }],
            cell_fields: &[
                VtuField {
                    name: "LE",
                    components: 4,
                    data: &le,
                },
                VtuField {
                    name: "S",
                    components: 4,
                    data: &s,
                },
                VtuField {
                    name: "J",
                    components: 1,
                    data: &fields.volume_ratio,
                },
            ],
            int_cell_fields: &[
                VtuIntField {
                    name: "region",
                    data: &region,
                },
                VtuIntField {
                    name: "material",
                    data: &material,
                },
            ],
        },
    )
}

/// Peak resident memory of this process so far (MB), from `/proc/self/status` (Linux).
pub fn peak_memory_mb() -> Option<f64> {
    let status = std::fs::read_to_string("/proc/self/status").ok()?;
    let line = status.lines().find(|l| l.starts_with("VmHWM:"))?;
    let kb: f64 = line.split_whitespace().nth(1)?.parse().ok()?;
    Some(kb / 1024.0)
}

/// The contact state of one skin node of a rigid body's surface.
#[derive(Debug, Clone, Copy)]
pub struct ContactPoint {
    pub node: usize,
    /// Current position (mm).
    pub position: [f64; 2],
    /// Angle of the position about the centre of the contact surface's nodes (degrees).
    pub angle_deg: f64,
    pub gap: f64,
    /// Nodal contact force (N per mm of thickness).
    pub force: f64,
    /// Force over the node's tributary length (MPa).
    pub pressure: f64,
}

/// Contact state of every candidate node of rigid body `b`, in candidate order.
pub fn contact_profile(model: &Model, solution: &Solution, b: usize) -> Vec<ContactPoint> {
    let c = &model.contacts[b];
    let body = &solution.bodies[b];
    let pts: Vec<[f64; 2]> = c
        .nodes
        .iter()
        .map(|&n| model.current_position(n, &solution.u))
        .collect();
    let inv = 1.0 / pts.len().max(1) as f64;
    let centre = pts
        .iter()
        .fold([0.0, 0.0], |a, p| [a[0] + p[0] * inv, a[1] + p[1] * inv]);
    c.nodes
        .iter()
        .enumerate()
        .map(|(k, &node)| {
            let p = pts[k];
            ContactPoint {
                node,
                position: p,
                angle_deg: (p[1] - centre[1]).atan2(p[0] - centre[0]).to_degrees(),
                gap: body.node_gaps[k],
                force: body.node_forces[k],
                pressure: body.node_forces[k] / c.tributary[k],
            }
        })
        .collect()
}

/// Writes, for rigid body `b`, `contact_pressure.csv` — one row per candidate node:
/// `node,x,y,angle_deg,gap_mm,force_n_per_mm,pressure_mpa` (see [`ContactPoint`]) — and
/// `force_displacement.csv` — `increment,load_factor,travel_mm,force_n_per_mm` over the
/// converged increments.
pub fn write_contact_csv(
    dir: &Path,
    model: &Model,
    solution: &Solution,
    b: usize,
) -> io::Result<()> {
    let mut w = AtomicFile::create(&dir.join("contact_pressure.csv"))?;
    writeln!(w, "node,x,y,angle_deg,gap_mm,force_n_per_mm,pressure_mpa")?;
    for p in contact_profile(model, solution, b) {
        writeln!(
            w,
            "{},{:.9e},{:.9e},{:.6},{:.9e},{:.9e},{:.9e}",
            model.mesh.node_labels[p.node],
            p.position[0],
            p.position[1],
            p.angle_deg,
            p.gap,
            p.force,
            p.pressure
        )?;
    }
    w.commit()?;
    let mut w = AtomicFile::create(&dir.join("force_displacement.csv"))?;
    writeln!(w, "increment,load_factor,travel_mm,force_n_per_mm")?;
    writeln!(w, "0,0,0,0")?;
    for rec in solution.report.increments.iter().filter(|r| r.converged) {
        if let Some(s) = rec.bodies.get(b) {
            writeln!(
                w,
                "{},{:.9},{:.9e},{:.9e}",
                rec.increment, rec.lambda, s[0], s[1]
            )?;
        }
    }
    w.commit()
}
