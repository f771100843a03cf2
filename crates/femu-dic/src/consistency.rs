//! Self-consistency of DIC fields on a real sequence, where no ground truth exists:
//!
//! - **forward–backward**: `A→B` then `B→A` must cancel, `u_AB(X) + u_BA(X + u_AB(X)) = 0`;
//! - **composition**: `A→C` must equal `A→B→C`, `u_AC(X) = u_AB(X) + u_BC(X + u_AB(X))`;
//! - **repeated correlation** of frames of unloaded tissue: any displacement is error (the
//!   seed's random error, §2.2), reported by [`crate::noise`].
//!
//! The differences are evaluated at the nodes of the first field (`A→B`, resp. `A→C`) whose
//! transported position stays inside the other meshes, and summarized per region: the ROI cut
//! into three depth bands (superficial, middle, deep: ultrasound quality changes with depth),
//! over all points and over the points that every field involved trusts ([`crate::quality`]).
//! Each summary also carries the standard deviation of the difference predicted by the fields'
//! covariances (independent fields: the variances add), so that a difference can be read
//! against the noise: a ratio near 1 is noise, far above 1 a bias (decorrelation, a sliding
//! interface smoothed by the regularization, a local minimum).

use crate::quality::{NodalCovariance, Trust};
use crate::solver::DicResult;

/// A measured field with its quality, as the checks need it.
pub struct CheckedField<'a> {
    pub res: &'a DicResult,
    pub cov: &'a NodalCovariance,
    pub trust: &'a [Trust],
}

impl CheckedField<'_> {
    /// Displacement, its standard deviations and whether the element is trusted, at `(x, y)`.
    fn at(&self, x: f64, y: f64) -> Option<([f64; 2], [f64; 2], bool)> {
        let (e, _, _) = self.res.mesh.locate(x, y)?;
        let u = self.res.mesh.interpolate(&self.res.displacement, x, y)?;
        let sd = self.cov.point_sd(self.res, x, y)?;
        Some((u, sd, self.trust[e] == Trust::Trusted))
    }
}

/// One point of a check: its reference position, the difference (pixels), the predicted
/// standard deviation of the difference and whether all fields trust it.
#[derive(Debug, Clone, Copy)]
pub struct CheckPoint {
    pub x: [f64; 2],
    pub diff: [f64; 2],
    pub sd: [f64; 2],
    pub trusted: bool,
}

/// Forward–backward differences at the nodes of `ab`.
pub fn forward_backward(ab: &CheckedField, ba: &CheckedField) -> Vec<CheckPoint> {
    ab.res
        .mesh
        .nodes
        .iter()
        .filter_map(|p| {
            let (u1, s1, t1) = ab.at(p[0], p[1])?;
            let (u2, s2, t2) = ba.at(p[0] + u1[0], p[1] + u1[1])?;
            Some(CheckPoint {
                x: *p,
                diff: [u1[0] + u2[0], u1[1] + u2[1]],
                sd: [s1[0].hypot(s2[0]), s1[1].hypot(s2[1])],
                trusted: t1 && t2,
            })
        })
        .collect()
}

/// Composition differences `u_AC − (u_AB + u_BC ∘ (X + u_AB))` at the nodes of `ac`.
pub fn composition(ab: &CheckedField, bc: &CheckedField, ac: &CheckedField) -> Vec<CheckPoint> {
    ac.res
        .mesh
        .nodes
        .iter()
        .filter_map(|p| {
            let (u, s, t) = ac.at(p[0], p[1])?;
            let (u1, s1, t1) = ab.at(p[0], p[1])?;
            let (u2, s2, t2) = bc.at(p[0] + u1[0], p[1] + u1[1])?;
            let sd = |k: usize| (s[k] * s[k] + s1[k] * s1[k] + s2[k] * s2[k]).sqrt();
            Some(CheckPoint {
                x: *p,
                diff: [u[0] - u1[0] - u2[0], u[1] - u1[1] - u2[1]],
                sd: [sd(0), sd(1)],
                trusted: t && t1 && t2,
            })
        })
        .collect()
}

/// Repeated correlation of unloaded frames: the measured displacement itself is the error.
pub fn repeated(ab: &CheckedField) -> Vec<CheckPoint> {
    ab.res
        .mesh
        .nodes
        .iter()
        .filter_map(|p| {
            let (u, s, t) = ab.at(p[0], p[1])?;
            Some(CheckPoint {
                x: *p,
                diff: u,
                sd: s,
                trusted: t,
            })
        })
        .collect()
}

/// The statistics of a check over one region.
#[derive(Debug, Clone, serde::Serialize, serde::Deserialize)]
pub struct RegionStats {
    /// `superficial`, `middle`, `deep` (thirds of the depth range) or `all`.
    pub region: String,
    /// `true`: only the points every field trusts.
    pub trusted_only: bool,
    pub points: usize,
    pub mean_px: [f64; 2],
    pub rms_px: [f64; 2],
    /// RMS of the predicted standard deviation of the difference (pixels).
    pub predicted_sd_px: [f64; 2],
}

/// Statistics per depth band (thirds of `y_range`) and overall, for all and trusted points.
pub fn region_stats(points: &[CheckPoint], y_range: [f64; 2]) -> Vec<RegionStats> {
    let band = |p: &CheckPoint| {
        let t = (p.x[1] - y_range[0]) / (y_range[1] - y_range[0]);
        if t < 1.0 / 3.0 {
            "superficial"
        } else if t < 2.0 / 3.0 {
            "middle"
        } else {
            "deep"
        }
    };
    let mut out = Vec::new();
    for trusted_only in [false, true] {
        for region in ["all", "superficial", "middle", "deep"] {
            let sel: Vec<&CheckPoint> = points
                .iter()
                .filter(|p| (!trusted_only || p.trusted) && (region == "all" || band(p) == region))
                .collect();
            let n = sel.len().max(1) as f64;
            let mean = |k: usize| sel.iter().map(|p| p.diff[k]).sum::<f64>() / n;
            let rms =
                |k: usize| (sel.iter().map(|p| p.diff[k] * p.diff[k]).sum::<f64>() / n).sqrt();
            let sd = |k: usize| (sel.iter().map(|p| p.sd[k] * p.sd[k]).sum::<f64>() / n).sqrt();
            out.push(RegionStats {
                region: region.to_string(),
                trusted_only,
                points: sel.len(),
                mean_px: [mean(0), mean(1)],
                rms_px: [rms(0), rms(1)],
                predicted_sd_px: [sd(0), sd(1)],
            });
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::lab::{self, Speckle};
    use crate::{correlate, quality, DicOptions, Rect, Roi};

    /// On the virtual lab, a translation there and back cancels and two translations compose:
    /// the differences are at the level of the predicted standard deviation (noise-free images:
    /// only the interpolation error, well below 0.01 px).
    #[test]
    fn translations_cancel_and_compose() {
        let s = Speckle::new(128, 128, 1.5, 4);
        let im = |t: (f64, f64)| s.deformed(&lab::translation(t.0, t.1));
        let (a, b, c) = (im((0.0, 0.0)), im((0.4, -0.3)), im((0.9, 0.2)));
        let roi = Roi::Rect(Rect {
            x: 24,
            y: 24,
            w: 80,
            h: 80,
        });
        let o = DicOptions::default();
        let run = |f, g| {
            let r = correlate(f, g, &roi, &o).unwrap();
            let cov = quality::covariance(&r).unwrap();
            let t = quality::element_trust(&r, &cov, &Default::default());
            (r, cov, t)
        };
        let (ab, ba, bc, ac) = (run(&a, &b), run(&b, &a), run(&b, &c), run(&a, &c));
        fn f(x: &(DicResult, NodalCovariance, Vec<Trust>)) -> CheckedField<'_> {
            CheckedField {
                res: &x.0,
                cov: &x.1,
                trust: &x.2,
            }
        }
        let fb = forward_backward(&f(&ab), &f(&ba));
        let comp = composition(&f(&ab), &f(&bc), &f(&ac));
        for (name, pts) in [("forward-backward", &fb), ("composition", &comp)] {
            let st = region_stats(pts, [23.5, 103.5]);
            let all = &st[0];
            assert!(all.points > 20, "{name}: {} points", all.points);
            assert!(
                all.rms_px[0] < 0.01 && all.rms_px[1] < 0.01,
                "{name}: {:?}",
                all.rms_px
            );
            assert_eq!(st.len(), 8);
        }
    }
}
