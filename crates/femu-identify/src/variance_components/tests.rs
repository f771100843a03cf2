use super::*;
use rand::SeedableRng;
use rand_distr::{Distribution, Normal};

/// A linear model `e = J θ + ε` with `ε_i ~ N(0, σ²_{group(i)})`; `informs[a]`: the groups whose
/// rows column `a` is non-zero in (`None`: all).
struct Case {
    jacobian: Vec<Vec<f64>>,
    group: Vec<usize>,
}

fn case(counts: &[usize], informs: &[Option<usize>], rng: &mut rand::rngs::StdRng) -> Case {
    let std = Normal::new(0.0, 1.0).unwrap();
    let group: Vec<usize> = counts
        .iter()
        .enumerate()
        .flat_map(|(k, &n)| std::iter::repeat_n(k, n))
        .collect();
    let jacobian = informs
        .iter()
        .map(|only| {
            group
                .iter()
                .map(|&g| match only {
                    Some(k) if *k != g => 0.0,
                    _ => 1.0 + std.sample(rng),
                })
                .collect()
        })
        .collect();
    Case { jacobian, group }
}

fn data(c: &Case, theta: &[f64], sd: &[f64], rng: &mut rand::rngs::StdRng) -> Vec<f64> {
    let std = Normal::new(0.0, 1.0).unwrap();
    (0..c.group.len())
        .map(|i| {
            let m: f64 = (0..theta.len()).map(|a| c.jacobian[a][i] * theta[a]).sum();
            m + sd[c.group[i]] * std.sample(rng)
        })
        .collect()
}

#[test]
fn recovers_known_group_variances() {
    let mut rng = rand::rngs::StdRng::seed_from_u64(11);
    let c = case(&[1500, 300], &[None, None, Some(1)], &mut rng);
    let sd = [0.5, 2.0];
    let e = data(&c, &[0.3, -1.0, 2.0], &sd, &mut rng);
    let v = helmert(&c.jacobian, &e, &c.group, 2, 1e-10, 100).unwrap();
    assert!(v.converged, "{v:?}");
    let total: f64 = v.redundancy.iter().sum();
    // The redundancies sum to n − p (a trace identity; round-off only).
    assert!((total - (1800.0 - 3.0)).abs() < 1e-8, "{total}");
    for k in 0..2 {
        // A variance from r degrees of freedom has relative standard error √(2/r): 4 of them.
        let rel = v.variance[k] / (sd[k] * sd[k]) - 1.0;
        let tol = 4.0 * (2.0 / v.redundancy[k]).sqrt();
        assert!(rel.abs() < tol, "group {k}: {rel} (tol {tol})");
    }
    assert!(v.pooled.is_empty());
}

#[test]
fn one_group_is_the_ordinary_estimate() {
    // Intercept only: the estimate is the sample variance Σ(e − ē)² / (n − 1).
    let e = [1.0, 2.0, 4.0, 7.0, 11.0];
    let j = vec![vec![1.0; 5]];
    let v = helmert(&j, &e, &[0; 5], 1, 1e-12, 50).unwrap();
    let mean = e.iter().sum::<f64>() / 5.0;
    let s2 = e.iter().map(|x| (x - mean) * (x - mean)).sum::<f64>() / 4.0;
    assert!(
        (v.variance[0] - s2).abs() < 1e-12 * s2,
        "{} {s2}",
        v.variance[0]
    );
    assert!((v.redundancy[0] - 4.0).abs() < 1e-12);
    assert!((v.step[0] - mean).abs() < 1e-12);
}

#[test]
fn a_group_that_informs_parameters_is_charged_its_share() {
    // 12 values informing 4 parameters of their own next to 600 others: the residuals keep 8/12
    // of that group's variance. Spread evenly, the correction n/(n − p) cannot restore it
    // (the estimate of the error model before this module); Helmert's redundancy does.
    let mut rng = rand::rngs::StdRng::seed_from_u64(5);
    let sd = [1.0, 1.0];
    let (mut helm, mut naive) = (0.0, 0.0);
    let reps = 300;
    for _ in 0..reps {
        let c = case(
            &[600, 12],
            &[None, Some(1), Some(1), Some(1), Some(1)],
            &mut rng,
        );
        let e = data(&c, &[1.0, 0.5, -0.5, 0.2, 0.1], &sd, &mut rng);
        let v = helmert(&c.jacobian, &e, &c.group, 2, 1e-10, 100).unwrap();
        helm += v.variance[1] / reps as f64;
        // Residual of the same fit, mean square of the group, global correction.
        let ss: f64 = (0..c.group.len())
            .filter(|&i| c.group[i] == 1)
            .map(|i| {
                let f: f64 = (0..5).map(|a| c.jacobian[a][i] * v.step[a]).sum();
                (e[i] - f).powi(2)
            })
            .sum();
        naive += ss / 12.0 * 612.0 / 607.0 / reps as f64;
    }
    // Mean of 300 estimates with 8 degrees of freedom each: standard error √(2/8/300) = 0.029;
    // 0.1 is 3.5 of them.
    assert!((helm - 1.0).abs() < 0.1, "Helmert mean {helm}");
    assert!(naive < 0.75, "global-leverage mean {naive} (expected 8/12)");
}

#[test]
fn intervals_from_the_components_cover_at_the_nominal_rate() {
    // The parameter informed by the noisy group alone: its 95 % interval from the estimated
    // components covers at ~95 %; with one pooled variance (the ordinary fit) it is too narrow.
    let mut rng = rand::rngs::StdRng::seed_from_u64(23);
    let sd = [0.2, 2.0];
    let theta = [0.3, 1.5];
    let reps = 400;
    let (mut covered, mut covered_pooled) = (0, 0);
    for _ in 0..reps {
        let c = case(&[400, 60], &[None, Some(1)], &mut rng);
        let e = data(&c, &theta, &sd, &mut rng);
        let v = helmert(&c.jacobian, &e, &c.group, 2, 1e-10, 100).unwrap();
        let half = 1.96 * v.covariance[1][1].sqrt();
        covered += usize::from((v.step[1] - theta[1]).abs() <= half);
        let o = helmert(&c.jacobian, &e, &vec![0; e.len()], 1, 1e-10, 100).unwrap();
        let half = 1.96 * o.covariance[1][1].sqrt();
        covered_pooled += usize::from((o.step[1] - theta[1]).abs() <= half);
    }
    let rate = covered as f64 / reps as f64;
    let pooled = covered_pooled as f64 / reps as f64;
    // Binomial standard error at 95 % over 400 repeats: 0.011; ±0.03 is 2.75 of them.
    assert!((rate - 0.95).abs() < 0.03, "coverage {rate}");
    assert!(pooled < 0.8, "pooled coverage {pooled}");
}

#[test]
fn small_groups_take_the_pooled_variance() {
    let mut rng = rand::rngs::StdRng::seed_from_u64(3);
    // Group 1: 2 values and a parameter of its own (redundancy 1 < MIN_REDUNDANCY).
    let c = case(&[200, 2], &[None, Some(1)], &mut rng);
    let e = data(&c, &[1.0, 1.0], &[1.0, 1.0], &mut rng);
    let v = helmert(&c.jacobian, &e, &c.group, 3, 1e-10, 100).unwrap();
    assert_eq!(v.pooled, vec![1]);
    assert_eq!(v.variance[1], v.variance[0]);
    // The empty group 2 too.
    assert_eq!(v.variance[2], v.variance[0]);
}

#[test]
fn bad_input_is_an_error_naming_it() {
    let j = vec![vec![1.0; 3]];
    let msg = |r: Result<VarianceComponents, FitError>| r.unwrap_err().to_string();
    assert!(msg(helmert(&j, &[1.0, 2.0, 3.0], &[0, 0], 1, 1e-9, 10)).contains("2 group labels"));
    assert!(msg(helmert(&j, &[1.0, 2.0, 3.0], &[0, 0, 4], 1, 1e-9, 10)).contains("group 4"));
    assert!(msg(helmert(&j, &[1.0, f64::NAN, 3.0], &[0; 3], 1, 1e-9, 10)).contains("residual 1"));
    let z = vec![vec![0.0; 3]];
    assert!(msg(helmert(&z, &[1.0, 2.0, 3.0], &[0; 3], 1, 1e-9, 10)).contains("singular"));
}

#[test]
fn field_groups_split_component_depth_and_edge() {
    let x = [[0.0, 0.0], [5.0, 3.0], [10.0, 12.0], [5.0, 30.0]];
    let (g, n) = field_groups(&x, 0.0, &[5.0, 11.0], 1.0);
    assert_eq!(n, 12);
    // (component·3 + band)·2 + edge.
    assert_eq!(g, vec![1, 7, 0, 6, 5, 11, 4, 10]);
    let (g, n) = field_groups(&x, 0.0, &[], 0.0);
    assert_eq!((g, n), (vec![0, 1, 0, 1, 0, 1, 0, 1], 2));
}
