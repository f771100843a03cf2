//! Joint identification: one least-squares problem over several measurements that share the
//! free parameters — several loading tests, each seen through one or more probe windows, or any
//! other residual with an exact Jacobian (grey levels of integrated DIC, say).
//!
//! The seed measured one test and found that each test pins down one family (compression C10,
//! contention D; §3.2, §4.5: "both contention and compression tests would be necessary"). With
//! independent measurement noise the joint cost is the sum of the blocks' costs,
//!
//! ```text
//!   J(φ) = ½ Σ_b |r_b(P_b φ)|²,      r = [r_1; r_2; ...],      ∂r/∂φ = [J_1 P_1; J_2 P_2; ...]
//! ```
//!
//! where `P_b` picks, for block `b`, its own free parameters out of the joint ones (a block whose
//! model lacks a material simply has zero columns there). The Fisher information is the sum of
//! the blocks' (`JᵀJ = Σ_b P_bᵀ J_bᵀ J_b P_b`), so each measurement's share of it is known at the
//! optimum ([`information_shares`]).
//!
//! The free parameters of a block are matched to the joint ones through the material registry's
//! typed parameters ([`Parameter`]: the material's name and the law's parameter), never through
//! name prefixes ([`block_free`]).

use crate::fisher::{self, Tied};
use crate::fit::{Columns, FitError, FreeParameter, LeastSquares};
use femu_mech::sensitivity::Parameter;
use femu_mech::Model;
use rayon::prelude::*;
use serde::{Deserialize, Serialize};
use std::ops::Range;

/// Named row ranges of a residual (the measurements it holds).
pub type Segments = Vec<(String, Range<usize>)>;

/// What a block's evaluation returns: residuals and, if asked, the Jacobian columns.
type Evaluation = Result<(Vec<f64>, Option<Columns>), FitError>;

/// One block of a joint problem: a least-squares problem and how its free parameters sit in the
/// joint ones.
pub struct Block {
    /// What the block measures (a loading test, an image pair, ...).
    pub name: String,
    pub problem: Box<dyn LeastSquares + Send>,
    /// For each free parameter of `problem`, the index of the joint free parameter it is.
    pub map: Vec<usize>,
    /// Named parts of the block's residuals (the measurements it holds, e.g. probe windows of
    /// one test; the rest of the rows, if any, form a part named after the block).
    pub segments: Vec<(String, Range<usize>)>,
}

/// Why a joint problem cannot be set up.
#[derive(Debug, thiserror::Error)]
pub enum JointError {
    #[error("a joint identification needs at least one measurement")]
    NoBlock,
    #[error("block {block}: free parameter {k} maps to the joint parameter {index}, but there are {count}")]
    BadMap {
        block: String,
        k: usize,
        index: usize,
        count: usize,
    },
    #[error("block {block}: {map} parameter indices for {free} free parameters")]
    MapLength {
        block: String,
        map: usize,
        free: usize,
    },
    #[error("no measurement sees the free parameter {0}: fix it or add a measurement of it")]
    Unseen(String),
}

/// The stacked problem of several blocks (see the module documentation).
pub struct JointProblem {
    free: Vec<FreeParameter>,
    blocks: Vec<Block>,
    /// Rows of each block in the stacked residual (known after the first evaluation).
    rows: Vec<Range<usize>>,
}

impl JointProblem {
    /// The joint problem of `blocks` over the free parameters `free`.
    pub fn new(free: Vec<FreeParameter>, blocks: Vec<Block>) -> Result<JointProblem, JointError> {
        if blocks.is_empty() {
            return Err(JointError::NoBlock);
        }
        let mut seen = vec![false; free.len()];
        for b in &blocks {
            if b.map.len() != b.problem.free().len() {
                return Err(JointError::MapLength {
                    block: b.name.clone(),
                    map: b.map.len(),
                    free: b.problem.free().len(),
                });
            }
            for (k, &i) in b.map.iter().enumerate() {
                if i >= free.len() {
                    return Err(JointError::BadMap {
                        block: b.name.clone(),
                        k,
                        index: i,
                        count: free.len(),
                    });
                }
                seen[i] = true;
            }
        }
        if let Some(k) = seen.iter().position(|s| !s) {
            return Err(JointError::Unseen(free[k].name.clone()));
        }
        Ok(JointProblem {
            free,
            rows: Vec::new(),
            blocks,
        })
    }

    /// The blocks.
    pub fn blocks(&self) -> &[Block] {
        &self.blocks
    }

    /// The blocks, to reach their problems (e.g. the model of a FEMU block after a fit).
    pub fn blocks_mut(&mut self) -> &mut [Block] {
        &mut self.blocks
    }

    /// The named parts of the stacked residual (block segments, and each block's rows outside
    /// its segments under the block's name), after at least one evaluation.
    pub fn segments(&self) -> Segments {
        let mut out = Vec::new();
        for (b, rows) in self.blocks.iter().zip(&self.rows) {
            let mut covered = vec![false; rows.len()];
            for (name, r) in &b.segments {
                let r = r.start.min(rows.len())..r.end.min(rows.len());
                covered[r.clone()].iter_mut().for_each(|c| *c = true);
                out.push((name.clone(), rows.start + r.start..rows.start + r.end));
            }
            // The rows no segment names (all of them when there is no segment).
            let mut k = 0;
            while k < covered.len() {
                if covered[k] {
                    k += 1;
                    continue;
                }
                let start = k;
                while k < covered.len() && !covered[k] {
                    k += 1;
                }
                out.push((b.name.clone(), rows.start + start..rows.start + k));
            }
        }
        out
    }
}

impl LeastSquares for JointProblem {
    fn free(&self) -> &[FreeParameter] {
        &self.free
    }

    /// Evaluates the blocks in parallel and stacks their residuals and Jacobian columns. The
    /// first error of a block is the joint error ([`FitError::Interrupted`] first, then anything
    /// but a failed solve, then a failed solve: the optimizers treat the last as a rejected
    /// step).
    fn evaluate(
        &mut self,
        phi: &[f64],
        jacobian: bool,
    ) -> Result<(Vec<f64>, Option<Columns>), FitError> {
        let results: Vec<Evaluation> = self
            .blocks
            .par_iter_mut()
            .map(|b| {
                let phi_b: Vec<f64> = b.map.iter().map(|&k| phi[k]).collect();
                b.problem.evaluate(&phi_b, jacobian)
            })
            .collect();
        let rank = |e: &FitError| match e {
            FitError::Interrupted => 0,
            FitError::Solve(_) => 2,
            _ => 1,
        };
        let mut parts = Vec::with_capacity(results.len());
        let mut error: Option<FitError> = None;
        for r in results {
            match r {
                Ok(p) => parts.push(p),
                Err(e) => {
                    if error.as_ref().is_none_or(|old| rank(&e) < rank(old)) {
                        error = Some(e);
                    }
                }
            }
        }
        if let Some(e) = error {
            return Err(e);
        }
        let total: usize = parts.iter().map(|(r, _)| r.len()).sum();
        let mut r = Vec::with_capacity(total);
        self.rows.clear();
        for (rb, _) in &parts {
            self.rows.push(r.len()..r.len() + rb.len());
            r.extend_from_slice(rb);
        }
        let columns = jacobian.then(|| {
            let mut cols = vec![vec![0.0; total]; self.free.len()];
            for ((b, (_, jb)), rows) in self.blocks.iter().zip(&parts).zip(&self.rows) {
                let jb = jb.as_ref().expect("asked");
                for (k, &i) in b.map.iter().enumerate() {
                    // Two block parameters mapped to one joint parameter add (a tie across
                    // blocks).
                    for (c, v) in cols[i][rows.clone()].iter_mut().zip(&jb[k]) {
                        *c += v;
                    }
                }
            }
            cols
        });
        Ok((r, columns))
    }

    fn counts(&self) -> (usize, usize) {
        self.blocks.iter().fold((0, 0), |(s, j), b| {
            let (bs, bj) = b.problem.counts();
            (s + bs, j + bj)
        })
    }

    fn states(&self) -> Vec<Option<Vec<f64>>> {
        self.blocks
            .iter()
            .flat_map(|b| b.problem.states())
            .collect()
    }
}

/// The free parameters of a block whose model is `block_model`, from the joint ones defined on
/// `joint_model`: each joint parameter's members found in the block's model by material name
/// and law parameter (the registry's [`Parameter`] spec). Returns the block's free parameters
/// (same names and bounds) and, for each, its joint index; a joint parameter none of whose
/// members the block's model has is left out of the block.
pub fn block_free(
    joint: &[FreeParameter],
    joint_model: &Model,
    block_model: &Model,
) -> (Vec<FreeParameter>, Vec<usize>) {
    let mut free = Vec::new();
    let mut map = Vec::new();
    for (i, f) in joint.iter().enumerate() {
        let members: Vec<Parameter> = f
            .members
            .iter()
            .filter_map(|m| same_parameter(m, joint_model, block_model))
            .collect();
        if members.is_empty() {
            continue;
        }
        free.push(FreeParameter {
            name: f.name.clone(),
            members,
            lower: f.lower,
            upper: f.upper,
        });
        map.push(i);
    }
    (free, map)
}

/// The parameter of `to` that is `p` of `from`: the material of the same name (ignoring case)
/// with the same law parameter.
pub fn same_parameter(p: &Parameter, from: &Model, to: &Model) -> Option<Parameter> {
    let name = &from.materials.get(p.material)?.name;
    let spec = p.spec();
    to.materials
        .iter()
        .enumerate()
        .filter(|(_, m)| m.name.eq_ignore_ascii_case(name))
        .find_map(|(k, m)| {
            let law = m.law.spec();
            let index = law.parameters.iter().position(|q| q.name == spec.name)?;
            Parameter::new(k, law, index)
        })
}

/// A measurement's part of the Fisher information at the optimum.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct InformationShare {
    pub measurement: String,
    /// Residual rows (data) of the measurement.
    pub rows: usize,
    /// Per free parameter: the measurement's share of the diagonal of the information,
    /// `Σ_{i∈m} J_ik² / Σ_i J_ik²` (the shares of all measurements add to 1).
    pub share: Vec<f64>,
    /// Per free parameter: the relative standard deviation the measurement alone would give
    /// (Cramér–Rao, whitened residuals; infinite where it cannot see a parameter).
    pub alone_relative_sd: Vec<f64>,
}

/// Each segment's share of the information of `jacobian` (columns over the stacked, whitened
/// residuals), and what it would identify alone.
pub fn information_shares(
    jacobian: &[Vec<f64>],
    segments: &[(String, Range<usize>)],
    names: &[String],
) -> Vec<InformationShare> {
    let diag: Vec<f64> = jacobian
        .iter()
        .map(|c| c.iter().map(|v| v * v).sum())
        .collect();
    segments
        .iter()
        .map(|(name, rows)| {
            let part: Vec<Vec<f64>> = jacobian.iter().map(|c| c[rows.clone()].to_vec()).collect();
            let share = part
                .iter()
                .zip(&diag)
                .map(|(c, d)| {
                    let s: f64 = c.iter().map(|v| v * v).sum();
                    if *d > 0.0 {
                        s / d
                    } else {
                        0.0
                    }
                })
                .collect();
            let alone_relative_sd = match fisher::information(&part, 1.0, &Tied::none(names)) {
                Ok(f) => fisher::identifiability(&f, names).relative_sd,
                Err(_) => vec![f64::INFINITY; names.len()],
            };
            InformationShare {
                measurement: name.clone(),
                rows: rows.len(),
                share,
                alone_relative_sd,
            }
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use femu_mech::material::{MaterialLaw, NeoHookean};

    /// A linear least-squares block `r = A φ - b` (exact Jacobian `A`), standing for any block
    /// that is not FEMU.
    struct Linear {
        free: Vec<FreeParameter>,
        a: Vec<Vec<f64>>,
        b: Vec<f64>,
        solves: usize,
    }

    impl LeastSquares for Linear {
        fn free(&self) -> &[FreeParameter] {
            &self.free
        }
        fn evaluate(
            &mut self,
            phi: &[f64],
            jacobian: bool,
        ) -> Result<(Vec<f64>, Option<Columns>), FitError> {
            self.solves += 1;
            let r = (0..self.b.len())
                .map(|i| (0..phi.len()).map(|k| self.a[k][i] * phi[k]).sum::<f64>() - self.b[i])
                .collect();
            Ok((r, jacobian.then(|| self.a.clone())))
        }
        fn counts(&self) -> (usize, usize) {
            (self.solves, 0)
        }
    }

    fn param(name: &str, material: usize) -> FreeParameter {
        FreeParameter {
            name: name.into(),
            members: vec![Parameter::new(material, &NeoHookean::SPEC, 0).unwrap()],
            lower: 0.1,
            upper: 10.0,
        }
    }

    /// Two blocks seeing overlapping parameters: the stacked residual and Jacobian are the
    /// blocks' in order, columns placed by the map; the segments cover every row; the shares
    /// add to one per parameter.
    #[test]
    fn blocks_stack_in_order_with_their_columns_placed() {
        let free = vec![param("A", 0), param("B", 1), param("C", 2)];
        let one = Linear {
            free: vec![free[0].clone(), free[1].clone()],
            a: vec![vec![1.0, 2.0], vec![3.0, 4.0]],
            b: vec![1.0, 1.0],
            solves: 0,
        };
        let two = Linear {
            free: vec![free[2].clone(), free[1].clone()],
            a: vec![vec![5.0, 0.0, 1.0], vec![0.0, 6.0, 1.0]],
            b: vec![0.0; 3],
            solves: 0,
        };
        let mut j = JointProblem::new(
            free.clone(),
            vec![
                Block {
                    name: "one".into(),
                    problem: Box::new(one),
                    map: vec![0, 1],
                    segments: vec![],
                },
                Block {
                    name: "two".into(),
                    problem: Box::new(two),
                    map: vec![2, 1],
                    segments: vec![("two-window".into(), 0..2)],
                },
            ],
        )
        .unwrap();
        let phi = [0.5, -1.0, 2.0];
        let (r, cols) = j.evaluate(&phi, true).unwrap();
        let cols = cols.unwrap();
        // Block one: A φ_(A,B) - b; block two: A φ_(C,B).
        assert_eq!(r, vec![0.5 - 3.0 - 1.0, 1.0 - 4.0 - 1.0, 10.0, -6.0, 1.0]);
        assert_eq!(cols[0], vec![1.0, 2.0, 0.0, 0.0, 0.0]);
        assert_eq!(cols[1], vec![3.0, 4.0, 0.0, 6.0, 1.0]);
        assert_eq!(cols[2], vec![0.0, 0.0, 5.0, 0.0, 1.0]);
        assert_eq!(j.counts(), (2, 0));
        let seg = j.segments();
        let names: Vec<&str> = seg.iter().map(|s| s.0.as_str()).collect();
        assert_eq!(names, ["one", "two-window", "two"]);
        assert_eq!(seg[1].1, 2..4);
        assert_eq!(seg[2].1, 4..5);
        let n: Vec<String> = free.iter().map(|f| f.name.clone()).collect();
        let shares = information_shares(&cols, &seg, &n);
        for k in 0..3 {
            let total: f64 = shares.iter().map(|s| s.share[k]).sum();
            assert!((total - 1.0).abs() < 1e-14, "parameter {k}: {total}");
        }
        // Block one alone cannot see C.
        assert!(shares[0].alone_relative_sd[2].is_infinite());
    }

    #[test]
    fn unseen_parameters_and_bad_maps_are_refused() {
        let free = vec![param("A", 0), param("B", 1)];
        let block = |map: Vec<usize>| Block {
            name: "b".into(),
            problem: Box::new(Linear {
                free: vec![free[0].clone()],
                a: vec![vec![1.0]],
                b: vec![0.0],
                solves: 0,
            }),
            map,
            segments: vec![],
        };
        assert!(matches!(
            JointProblem::new(free.clone(), vec![block(vec![0])]),
            Err(JointError::Unseen(n)) if n == "B"
        ));
        assert!(matches!(
            JointProblem::new(free.clone(), vec![block(vec![5])]),
            Err(JointError::BadMap { .. })
        ));
        assert!(matches!(
            JointProblem::new(free.clone(), vec![block(vec![0, 1])]),
            Err(JointError::MapLength { .. })
        ));
        assert!(matches!(
            JointProblem::new(free, vec![]),
            Err(JointError::NoBlock)
        ));
    }
}
