//! Design of the experiment: which measurements (loading tests seen through probe windows) to
//! make, ranked by the parameter uncertainty they predict before any is made.
//!
//! Each candidate measurement brings the Fisher information `F_m = J_mᵀ J_m / σ_m²` of the free
//! log-parameters at the reference (its Jacobian restricted to the points its window sees, its
//! noise). Independent measurements add their information, so a design (a set of candidates)
//! has `F = Σ_m F_m`, and its predicted covariance of the log-parameters is `F⁻¹`
//! (Cramér–Rao, [`crate::fisher`]). Two classical scalar criteria rank designs:
//!
//! - **A-optimal**: the mean variance, reported as the RMS relative standard deviation
//!   `√(tr F⁻¹ / n)`;
//! - **D-optimal**: the volume of the confidence ellipsoid, reported as the geometric mean of
//!   the relative standard deviations along its axes, `det(F)^(-1/2n)`.
//!
//! A parameter is identifiable by a design when its predicted relative sd is below a threshold
//! (10 % by default); a design that cannot see some direction at all has infinite criteria and
//! ranks last.

use crate::fisher::{self, add_information};
use serde::{Deserialize, Serialize};

/// A predicted relative sd above this does not identify the parameter (10 %).
pub const DEFAULT_IDENTIFIABLE_SD: f64 = 0.1;

/// A candidate measurement and its information.
#[derive(Debug, Clone)]
pub struct Candidate {
    /// `contention, anterior 40 x 40 mm`.
    pub name: String,
    /// Its loading test.
    pub group: String,
    /// Candidates sharing this key do not combine (the same test through nested windows on one
    /// side would count the same tissue twice).
    pub exclusive: String,
    /// Fisher information of the free log-parameters (whitened).
    pub information: Vec<Vec<f64>>,
    /// Measured points.
    pub points: usize,
}

/// A scored design.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Design {
    /// The candidates it makes, by name.
    pub measurements: Vec<String>,
    /// Their loading tests, without repeats.
    pub tests: Vec<String>,
    pub points: usize,
    /// RMS of the predicted relative sds (A-optimal criterion; lower is better).
    pub a_criterion: f64,
    /// Geometric mean of the relative sds along the ellipsoid's axes (D-optimal criterion).
    pub d_criterion: f64,
    /// Per free parameter: the predicted relative sd.
    pub relative_sd: Vec<f64>,
    /// Per parameter family (`C10`, `D`, ...): the worst predicted relative sd.
    pub worst_by_family: Vec<(String, f64)>,
    pub identifiable: Vec<String>,
    pub not_identifiable: Vec<String>,
    /// Ranks (1 = best) by each criterion.
    pub rank_a: usize,
    pub rank_d: usize,
}

/// Every design of 1 to `max_size` distinct candidates, no two sharing their `exclusive` key
/// (candidate indices, increasing).
pub fn designs(candidates: &[Candidate], max_size: usize) -> Vec<Vec<usize>> {
    let mut out = Vec::new();
    let mut current = Vec::new();
    fn extend(
        c: &[Candidate],
        from: usize,
        max_size: usize,
        current: &mut Vec<usize>,
        out: &mut Vec<Vec<usize>>,
    ) {
        for k in from..c.len() {
            if current.iter().any(|&j| c[j].exclusive == c[k].exclusive) {
                continue;
            }
            current.push(k);
            out.push(current.clone());
            if current.len() < max_size {
                extend(c, k + 1, max_size, current, out);
            }
            current.pop();
        }
    }
    extend(candidates, 0, max_size, &mut current, &mut out);
    out
}

/// The score of the design made of `members` (indices into `candidates`); `names` and
/// `families` (`C10`, `D`, ...) of the free parameters; `identifiable_sd` the threshold.
pub fn score(
    candidates: &[Candidate],
    members: &[usize],
    names: &[String],
    families: &[String],
    identifiable_sd: f64,
) -> Design {
    let n = names.len();
    let mut f = vec![vec![0.0; n]; n];
    for &m in members {
        add_information(&mut f, &candidates[m].information);
    }
    let id = fisher::identifiability(&f, names);
    let seen = id.relative_sd.iter().all(|s| s.is_finite());
    let a_criterion = if seen {
        (id.relative_sd.iter().map(|s| s * s).sum::<f64>() / n as f64).sqrt()
    } else {
        f64::INFINITY
    };
    let d_criterion = if seen && id.singular_values.iter().all(|s| *s > 0.0) {
        (-id.singular_values.iter().map(|s| s.ln()).sum::<f64>() / n as f64).exp()
    } else {
        f64::INFINITY
    };
    let mut worst_by_family: Vec<(String, f64)> = Vec::new();
    for (fam, sd) in families.iter().zip(&id.relative_sd) {
        match worst_by_family.iter_mut().find(|(f, _)| f == fam) {
            Some(w) => w.1 = w.1.max(*sd),
            None => worst_by_family.push((fam.clone(), *sd)),
        }
    }
    let (identifiable, not_identifiable): (Vec<(&String, f64)>, Vec<_>) = names
        .iter()
        .zip(id.relative_sd.iter().copied())
        .partition(|(_, s)| *s <= identifiable_sd);
    let mut tests: Vec<String> = Vec::new();
    for &m in members {
        if !tests.contains(&candidates[m].group) {
            tests.push(candidates[m].group.clone());
        }
    }
    Design {
        measurements: members
            .iter()
            .map(|&m| candidates[m].name.clone())
            .collect(),
        tests,
        points: members.iter().map(|&m| candidates[m].points).sum(),
        a_criterion,
        d_criterion,
        relative_sd: id.relative_sd,
        worst_by_family,
        identifiable: identifiable.into_iter().map(|(n, _)| n.clone()).collect(),
        not_identifiable: not_identifiable
            .into_iter()
            .map(|(n, _)| n.clone())
            .collect(),
        rank_a: 0,
        rank_d: 0,
    }
}

/// Sorts `designs` by the A-optimal criterion (then D, then fewer measurements) and sets both
/// ranks.
pub fn rank(designs: &mut [Design]) {
    let key = |d: &Design| (d.d_criterion, d.measurements.len());
    let mut by_d: Vec<usize> = (0..designs.len()).collect();
    by_d.sort_by(|&a, &b| {
        key(&designs[a])
            .partial_cmp(&key(&designs[b]))
            .unwrap_or(std::cmp::Ordering::Equal)
    });
    for (r, &k) in by_d.iter().enumerate() {
        designs[k].rank_d = r + 1;
    }
    designs.sort_by(|a, b| {
        (a.a_criterion, a.d_criterion, a.measurements.len())
            .partial_cmp(&(b.a_criterion, b.d_criterion, b.measurements.len()))
            .unwrap_or(std::cmp::Ordering::Equal)
    });
    for (r, d) in designs.iter_mut().enumerate() {
        d.rank_a = r + 1;
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn candidate(name: &str, exclusive: &str, diag: [f64; 2]) -> Candidate {
        Candidate {
            name: name.into(),
            group: name.split(' ').next().unwrap().into(),
            exclusive: exclusive.into(),
            information: vec![vec![diag[0], 0.0], vec![0.0, diag[1]]],
            points: 10,
        }
    }

    /// Two measurements each seeing one parameter: alone they cannot identify the other; the
    /// pair can, with the sds of each; the criteria are the closed forms.
    #[test]
    fn complementary_measurements_rank_first_together() {
        let c = vec![
            candidate("compression a", "compression a", [1e4, 0.0]),
            candidate("contention a", "contention a", [0.0, 2.5e3]),
            candidate("compression b", "compression a", [4e4, 0.0]),
        ];
        let sets = designs(&c, 2);
        // Singles, and the pairs that do not share an exclusive key.
        assert_eq!(
            sets,
            vec![vec![0], vec![0, 1], vec![1], vec![1, 2], vec![2]]
        );
        let names = vec!["C10".to_string(), "D".to_string()];
        let mut scored: Vec<Design> = sets
            .iter()
            .map(|m| score(&c, m, &names, &names, 0.1))
            .collect();
        rank(&mut scored);
        let best = &scored[0];
        assert_eq!(best.measurements, ["contention a", "compression b"]);
        assert!((best.relative_sd[0] - 0.005).abs() < 1e-12);
        assert!((best.relative_sd[1] - 0.02).abs() < 1e-12);
        let a = ((0.005f64.powi(2) + 0.02f64.powi(2)) / 2.0).sqrt();
        assert!((best.a_criterion - a).abs() < 1e-12);
        assert!((best.d_criterion - (0.005f64 * 0.02).sqrt()).abs() < 1e-12);
        assert_eq!(best.identifiable, ["C10", "D"]);
        let single = scored
            .iter()
            .find(|d| d.measurements == ["compression a"])
            .unwrap();
        assert!(single.a_criterion.is_infinite());
        assert_eq!(single.not_identifiable, ["D"]);
        assert_eq!(
            scored.iter().map(|d| d.rank_a).collect::<Vec<_>>(),
            [1, 2, 3, 4, 5]
        );
    }
}
