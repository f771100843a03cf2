//! Identifiability of parameters from a measurement, before any experiment (the quantitative
//! version of the seed's choice of test, §2.3).
//!
//! The measured displacements `m` (components at the DIC grid points) with independent
//! Gaussian noise of standard deviation σ, and the model's Jacobian with respect to the
//! log-parameters `J_ik = θ_k ∂m_i/∂θ_k`, give the Fisher information `F = Jᵀ J / σ²`. Its
//! inverse bounds the covariance of any unbiased estimate of `log θ` (Cramér–Rao), and for least
//! squares with small noise it is that covariance: `sd(log θ_k) = √(F⁻¹)_kk` is the predicted
//! relative standard deviation of θ_k. Tied parameters (the seed ties D of ischio, sartorius and
//! gracilis) share one log-parameter whose column is the sum of theirs. Informations of
//! independent tests add.

use serde::Serialize;

/// Why the identifiability could not be computed.
#[derive(Debug, thiserror::Error)]
pub enum FisherError {
    #[error("the noise standard deviation must be positive and finite, got {0}")]
    BadNoise(f64),
    #[error("{columns} Jacobian columns for {names} parameter names")]
    Mismatch { columns: usize, names: usize },
    #[error("column {column} has {found} rows, the first has {expected}")]
    Ragged {
        column: usize,
        expected: usize,
        found: usize,
    },
    #[error("group {group} names the unknown parameter '{name}'")]
    UnknownInGroup { group: usize, name: String },
    #[error("parameter '{0}' is in two groups")]
    TwiceGrouped(String),
    #[error("no data: the Jacobian has no row")]
    NoData,
}

/// Free parameters after tying: each is a set of original parameters moving together.
#[derive(Debug, Clone, Serialize, serde::Deserialize)]
pub struct Tied {
    /// Names of the free parameters (`"D_ISCHIO+D_SARTORIUS+D_GRACILIS"` for a group).
    pub names: Vec<String>,
    /// For each free parameter, the indices of the original parameters it moves.
    pub members: Vec<Vec<usize>>,
}

impl Tied {
    /// Ties the parameters named in each of `groups`; the others stay free on their own, in
    /// their original order (a group takes the place of its first member).
    pub fn new(names: &[String], groups: &[Vec<String>]) -> Result<Tied, FisherError> {
        let mut group_of = vec![None; names.len()];
        for (g, members) in groups.iter().enumerate() {
            for m in members {
                let k = names
                    .iter()
                    .position(|n| n.eq_ignore_ascii_case(m))
                    .ok_or_else(|| FisherError::UnknownInGroup {
                        group: g + 1,
                        name: m.clone(),
                    })?;
                if group_of[k].is_some() {
                    return Err(FisherError::TwiceGrouped(names[k].clone()));
                }
                group_of[k] = Some(g);
            }
        }
        let mut tied = Tied {
            names: Vec::new(),
            members: Vec::new(),
        };
        let mut placed = vec![false; groups.len()];
        for k in 0..names.len() {
            match group_of[k] {
                None => {
                    tied.names.push(names[k].clone());
                    tied.members.push(vec![k]);
                }
                Some(g) if !placed[g] => {
                    placed[g] = true;
                    let members: Vec<usize> = (0..names.len())
                        .filter(|&j| group_of[j] == Some(g))
                        .collect();
                    tied.names.push(
                        members
                            .iter()
                            .map(|&j| names[j].as_str())
                            .collect::<Vec<_>>()
                            .join("+"),
                    );
                    tied.members.push(members);
                }
                Some(_) => {}
            }
        }
        Ok(tied)
    }

    /// The identity (every parameter free on its own).
    pub fn none(names: &[String]) -> Tied {
        Tied {
            names: names.to_vec(),
            members: (0..names.len()).map(|k| vec![k]).collect(),
        }
    }
}

/// Fisher information `Jᵀ J / σ²` of the tied log-parameters; `columns[k]` is
/// `θ_k ∂m/∂θ_k` over the measured components.
pub fn information(
    columns: &[Vec<f64>],
    sigma: f64,
    tied: &Tied,
) -> Result<Vec<Vec<f64>>, FisherError> {
    if !(sigma > 0.0 && sigma.is_finite()) {
        return Err(FisherError::BadNoise(sigma));
    }
    let rows = columns.first().map_or(0, |c| c.len());
    if rows == 0 {
        return Err(FisherError::NoData);
    }
    for (k, c) in columns.iter().enumerate() {
        if c.len() != rows {
            return Err(FisherError::Ragged {
                column: k,
                expected: rows,
                found: c.len(),
            });
        }
    }
    let n = tied.members.len();
    let tied_cols: Vec<Vec<f64>> = tied
        .members
        .iter()
        .map(|m| {
            let mut c = vec![0.0; rows];
            for &k in m {
                for (ci, v) in c.iter_mut().zip(&columns[k]) {
                    *ci += v;
                }
            }
            c
        })
        .collect();
    let mut f = vec![vec![0.0; n]; n];
    for i in 0..n {
        for j in i..n {
            let v = tied_cols[i]
                .iter()
                .zip(&tied_cols[j])
                .map(|(a, b)| a * b)
                .sum::<f64>()
                / (sigma * sigma);
            f[i][j] = v;
            f[j][i] = v;
        }
    }
    Ok(f)
}

/// What the information says about each free parameter.
#[derive(Debug, Clone, Serialize, serde::Deserialize)]
pub struct Identifiability {
    pub names: Vec<String>,
    /// Predicted relative standard deviation of each free parameter (`sd(log θ)`, Cramér–Rao);
    /// infinite for a parameter the measurement cannot see.
    pub relative_sd: Vec<f64>,
    /// Correlation matrix of the estimates.
    pub correlation: Vec<Vec<f64>>,
    /// Singular values of `J/σ` (square roots of the eigenvalues of F), descending.
    pub singular_values: Vec<f64>,
    /// Ratio of the largest to the smallest singular value.
    pub condition: f64,
}

/// The pseudo-inverse of a symmetric positive semi-definite matrix by its eigen-decomposition:
/// directions with an eigenvalue below 1e-14 of the largest are dropped. Returns the inverse,
/// which rows touch a dropped direction (`unseen`), and the square roots of the eigenvalues,
/// descending.
pub fn pseudo_inverse(f: &[Vec<f64>]) -> (Vec<Vec<f64>>, Vec<bool>, Vec<f64>) {
    let n = f.len();
    let m = faer::Mat::<f64>::from_fn(n, n, |i, j| f[i][j]);
    let (vals, vecs) = match m.self_adjoint_eigen(faer::Side::Lower) {
        Ok(evd) => {
            let s = evd.S();
            let u = evd.U();
            (
                (0..n).map(|i| s[i].max(0.0)).collect::<Vec<f64>>(),
                faer::Mat::<f64>::from_fn(n, n, |i, j| u[(i, j)]),
            )
        }
        Err(_) => (vec![0.0; n], faer::Mat::<f64>::identity(n, n)),
    };
    let lmax = vals.iter().cloned().fold(0.0f64, f64::max);
    let cutoff = 1e-14 * lmax;
    let mut inv = vec![vec![0.0; n]; n];
    let mut singular = vec![];
    for (k, &l) in vals.iter().enumerate() {
        singular.push(l.sqrt());
        if l > cutoff && l > 0.0 {
            for i in 0..n {
                for j in 0..n {
                    inv[i][j] += vecs[(i, k)] * vecs[(j, k)] / l;
                }
            }
        }
    }
    let unseen: Vec<bool> = (0..n)
        .map(|i| {
            vals.iter()
                .enumerate()
                .any(|(k, &l)| !(l > cutoff && l > 0.0) && vecs[(i, k)].abs() > 1e-8)
        })
        .collect();
    singular.sort_by(|a, b| b.total_cmp(a));
    (inv, unseen, singular)
}

/// Inverts the information (symmetric eigen-decomposition; directions with eigenvalue below
/// 1e-14 of the largest are unidentifiable and give infinite standard deviations).
pub fn identifiability(f: &[Vec<f64>], names: &[String]) -> Identifiability {
    let (cov, unseen, singular) = pseudo_inverse(f);
    from_covariance(&cov, &unseen, singular, names)
}

/// The correlation matrix `C_ij / √(C_ii C_jj)` of a covariance (NaN where a variance is 0).
pub fn correlation(cov: &[Vec<f64>]) -> Vec<Vec<f64>> {
    let n = cov.len();
    (0..n)
        .map(|i| {
            (0..n)
                .map(|j| {
                    let d = (cov[i][i] * cov[j][j]).sqrt();
                    if d > 0.0 {
                        cov[i][j] / d
                    } else {
                        f64::NAN
                    }
                })
                .collect()
        })
        .collect()
}

/// The standard deviations and correlations of a covariance of log-parameters (`unseen`
/// parameters get infinite standard deviations), with the singular values of the information
/// it came from.
pub fn from_covariance(
    cov: &[Vec<f64>],
    unseen: &[bool],
    singular: Vec<f64>,
    names: &[String],
) -> Identifiability {
    let n = cov.len();
    let relative_sd: Vec<f64> = (0..n)
        .map(|i| {
            if unseen[i] {
                f64::INFINITY
            } else {
                cov[i][i].max(0.0).sqrt()
            }
        })
        .collect();
    let correlation = correlation(cov);
    let smin = singular.last().copied().unwrap_or(0.0);
    let condition = if smin > 0.0 {
        singular[0] / smin
    } else {
        f64::INFINITY
    };
    Identifiability {
        names: names.to_vec(),
        relative_sd,
        correlation,
        singular_values: singular,
        condition,
    }
}

/// Element-wise sum of informations (independent tests measured together).
pub fn add_information(a: &mut [Vec<f64>], b: &[Vec<f64>]) {
    for (ra, rb) in a.iter_mut().zip(b) {
        for (x, y) in ra.iter_mut().zip(rb) {
            *x += y;
        }
    }
}

/// The values the tests below measure, recorded for the guide (`scripts/guide/verify.sh`).
#[cfg(test)]
#[path = "../../../scripts/guide/measure.rs"]
mod measure;

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{Rng, SeedableRng};

    fn names(n: usize) -> Vec<String> {
        (0..n).map(|k| format!("P{k}")).collect()
    }

    /// Linear model m = J x + noise: the Cramér–Rao standard deviations equal the spread of
    /// least-squares estimates over many noise draws (Monte Carlo, 4000 draws: the sampling
    /// error of a standard deviation is ~1/√(2·4000) ≈ 1.1 %, 5 % asserted).
    #[test]
    fn predicted_sd_matches_least_squares_spread() {
        let mut rng = rand::rngs::StdRng::seed_from_u64(7);
        let rows = 60;
        let cols: Vec<Vec<f64>> = (0..3)
            .map(|_| (0..rows).map(|_| rng.gen_range(-1.0..1.0)).collect())
            .collect();
        let sigma = 0.05;
        let f = information(&cols, sigma, &Tied::none(&names(3))).unwrap();
        let id = identifiability(&f, &names(3));
        let fm = faer::Mat::<f64>::from_fn(3, 3, |i, j| f[i][j] * sigma * sigma);
        let draws = 4000;
        let mut est: Vec<Vec<f64>> = (0..3).map(|_| Vec::with_capacity(draws)).collect();
        for _ in 0..draws {
            let noise: Vec<f64> = (0..rows)
                .map(|_| {
                    let z: f64 =
                        rand_distr::Distribution::sample(&rand_distr::StandardNormal, &mut rng);
                    sigma * z
                })
                .collect();
            let b = faer::Mat::<f64>::from_fn(3, 1, |k, _| {
                cols[k].iter().zip(&noise).map(|(a, e)| a * e).sum::<f64>()
            });
            use faer::linalg::solvers::Solve;
            let x = fm.partial_piv_lu().solve(&b);
            for k in 0..3 {
                est[k].push(x[(k, 0)]);
            }
        }
        for k in 0..3 {
            let mean = est[k].iter().sum::<f64>() / draws as f64;
            let sd = (est[k].iter().map(|v| (v - mean).powi(2)).sum::<f64>() / (draws - 1) as f64)
                .sqrt();
            let rel = (sd - id.relative_sd[k]).abs() / id.relative_sd[k];
            super::measure::record(
                &format!("linear model, parameter {k}: Cramér–Rao sd against the spread of least-squares estimates over 4 000 noise draws, relative difference"),
                rel,
                "< 0.05",
                "",
            );
            assert!(
                rel < 0.05,
                "parameter {k}: spread {sd:.4e} vs predicted {:.4e}",
                id.relative_sd[k]
            );
        }
    }

    /// Two identical columns cannot be told apart: infinite sd, until they are tied.
    #[test]
    fn collinear_parameters_are_unidentifiable_until_tied() {
        let a: Vec<f64> = (0..10).map(|i| (i as f64).sin()).collect();
        let b: Vec<f64> = (0..10).map(|i| (i as f64).cos()).collect();
        let cols = vec![a.clone(), b, a];
        let n = names(3);
        let f = information(&cols, 0.1, &Tied::none(&n)).unwrap();
        let id = identifiability(&f, &n);
        assert!(id.relative_sd[0].is_infinite() && id.relative_sd[2].is_infinite());
        assert!(id.relative_sd[1].is_finite());
        assert!(id.condition.is_infinite() || id.condition > 1e6);
        let tied = Tied::new(&n, &[vec!["P0".into(), "p2".into()]]).unwrap();
        assert_eq!(tied.names, vec!["P0+P2".to_string(), "P1".to_string()]);
        let f = information(&cols, 0.1, &tied).unwrap();
        let id = identifiability(&f, &tied.names);
        assert!(id.relative_sd.iter().all(|s| s.is_finite()));
    }

    #[test]
    fn bad_inputs_are_named() {
        let n = names(2);
        assert!(matches!(
            Tied::new(&n, &[vec!["Q".into()]]),
            Err(FisherError::UnknownInGroup { .. })
        ));
        assert!(matches!(
            Tied::new(&n, &[vec!["P0".into()], vec!["P0".into()]]),
            Err(FisherError::TwiceGrouped(_))
        ));
        assert!(information(&[vec![1.0]], 0.0, &Tied::none(&n[..1])).is_err());
        assert!(information(&[vec![]], 1.0, &Tied::none(&n[..1])).is_err());
    }
}
