//! DIC random error of repeated acquisitions per setting (seed §2.2 criterion c, §3.1.3,
//! Fig. 7): the images of unloaded tissue taken one after the other with one setting are
//! correlated in succession (`femu_dic::noise::successive_pairs`); the tissue did not deform,
//! so the standard deviation of the measured `ux`, `uy` over the region is the random error of
//! the pair. Settings are compared by paired t-tests on the pairs they share (same subject,
//! same pair rank), and the setting of lowest mean error is recommended.

use crate::error::UsError;
use crate::manifest::Manifest;
use crate::settings::Region;
use crate::stats::{mean_sd, paired_t_test, PairedTTest};
use femu_dic::DicOptions;
use std::collections::BTreeMap;
use std::path::Path;

/// The error of one pair.
#[derive(Debug, Clone, serde::Serialize)]
pub struct PairError {
    pub subject: String,
    /// Rank of the pair within its subject (0: images 1 → 2).
    pub rank: usize,
    pub reference_line: usize,
    pub deformed_line: usize,
    pub std_ux_px: f64,
    pub std_uy_px: f64,
    pub mean_ux_px: f64,
    pub mean_uy_px: f64,
    pub converged: bool,
}

/// One setting's pairs and summary.
#[derive(Debug, Clone, serde::Serialize)]
pub struct SettingError {
    pub label: String,
    pub frequency_mhz: f64,
    pub gain_db: f64,
    pub dynamic_db: f64,
    pub pairs: Vec<PairError>,
    /// Mean and standard deviation over the pairs of `std(ux)`, `std(uy)` (px).
    pub mean_std_ux_px: f64,
    pub sd_std_ux_px: f64,
    pub mean_std_uy_px: f64,
    pub sd_std_uy_px: f64,
}

/// A paired t-test between two settings on one component.
#[derive(Debug, Clone, serde::Serialize)]
pub struct Comparison {
    pub a: String,
    pub b: String,
    pub component: &'static str,
    pub test: PairedTTest,
    pub significant: bool,
}

/// The result of `us-noise`.
#[derive(Debug, Clone, serde::Serialize)]
pub struct NoiseReport {
    pub settings: Vec<SettingError>,
    pub comparisons: Vec<Comparison>,
    pub alpha: f64,
    /// The setting of lowest mean `(std ux + std uy) / 2`.
    pub recommended: String,
    /// Whether its error is significantly lower than every other setting's, on both components.
    pub recommended_significantly_lower: bool,
}

/// Correlates successive images per (setting, subject) and compares the settings.
pub fn analyse(
    manifest: &Manifest,
    region: &Region,
    dic: &DicOptions,
    alpha: f64,
    progress: &mut dyn FnMut(&str),
) -> Result<NoiseReport, UsError> {
    if !(alpha > 0.0 && alpha < 1.0) {
        return Err(UsError::param(
            "alpha",
            format!("{alpha} is outside (0, 1)"),
        ));
    }
    // Group: setting → subject → entries in manifest order.
    let key = |v: f64| (v * 1e6).round() as i64;
    let mut groups: BTreeMap<(i64, i64, i64), BTreeMap<String, Vec<usize>>> = BTreeMap::new();
    for (k, e) in manifest.entries.iter().enumerate() {
        groups
            .entry((key(e.frequency_mhz), key(e.gain_db), key(e.dynamic_db)))
            .or_default()
            .entry(e.subject.clone())
            .or_default()
            .push(k);
    }
    for by_subject in groups.values() {
        for (subject, idx) in by_subject {
            if idx.len() < 2 {
                let e = &manifest.entries[idx[0]];
                return Err(UsError::Manifest {
                    path: manifest.path.clone(),
                    line: e.line,
                    message: format!(
                        "setting {}{} has a single image ({}): the random error needs at least 2 successive acquisitions",
                        e.setting_label(),
                        if subject.is_empty() { String::new() } else { format!(", subject {subject}") },
                        e.file
                    ),
                });
            }
        }
    }
    if groups.is_empty() {
        return Err(UsError::param("manifest", "no image"));
    }
    let first = manifest.open(0, None)?;
    let size = (first.width, first.height);
    let roi = region.dic_roi(size.0, size.1)?;
    let mut settings = Vec::new();
    for by_subject in groups.values() {
        let e0 = &manifest.entries[by_subject.values().next().map_or(0, |v| v[0])];
        let label = e0.setting_label();
        let mut pairs = Vec::new();
        for (subject, idx) in by_subject {
            let images = idx
                .iter()
                .map(|&k| manifest.open(k, Some(size)))
                .collect::<Result<Vec<_>, _>>()?;
            progress(&format!(
                "{label}{}: {} images",
                if subject.is_empty() {
                    String::new()
                } else {
                    format!(" {subject}")
                },
                images.len()
            ));
            let res = femu_dic::noise::successive_pairs(&images, &roi, dic).map_err(|e| {
                UsError::Manifest {
                    path: manifest.path.clone(),
                    line: manifest.entries[idx[0]].line,
                    message: format!("setting {label}: {e}"),
                }
            })?;
            for (rank, p) in res.iter().enumerate() {
                pairs.push(PairError {
                    subject: subject.clone(),
                    rank,
                    reference_line: manifest.entries[idx[p.reference]].line,
                    deformed_line: manifest.entries[idx[p.deformed]].line,
                    std_ux_px: p.std_ux_px,
                    std_uy_px: p.std_uy_px,
                    mean_ux_px: p.mean_ux_px,
                    mean_uy_px: p.mean_uy_px,
                    converged: p.converged,
                });
            }
        }
        let ux: Vec<f64> = pairs.iter().map(|p| p.std_ux_px).collect();
        let uy: Vec<f64> = pairs.iter().map(|p| p.std_uy_px).collect();
        let (mx, sx) = mean_sd(&ux);
        let (my, sy) = mean_sd(&uy);
        settings.push(SettingError {
            label,
            frequency_mhz: e0.frequency_mhz,
            gain_db: e0.gain_db,
            dynamic_db: e0.dynamic_db,
            pairs,
            mean_std_ux_px: mx,
            sd_std_ux_px: sx,
            mean_std_uy_px: my,
            sd_std_uy_px: sy,
        });
    }
    // Paired t-tests on the pairs two settings share (same subject, same rank).
    let mut comparisons = Vec::new();
    for i in 0..settings.len() {
        for j in i + 1..settings.len() {
            let (a, b) = (&settings[i], &settings[j]);
            for component in ["ux", "uy"] {
                let pick = |p: &PairError| {
                    if component == "ux" {
                        p.std_ux_px
                    } else {
                        p.std_uy_px
                    }
                };
                let (mut va, mut vb) = (Vec::new(), Vec::new());
                for pa in &a.pairs {
                    if let Some(pb) = b
                        .pairs
                        .iter()
                        .find(|p| p.subject == pa.subject && p.rank == pa.rank)
                    {
                        va.push(pick(pa));
                        vb.push(pick(pb));
                    }
                }
                if va.len() < 2 {
                    continue;
                }
                let test = paired_t_test(&va, &vb)?;
                comparisons.push(Comparison {
                    a: a.label.clone(),
                    b: b.label.clone(),
                    component,
                    significant: test.p_value < alpha,
                    test,
                });
            }
        }
    }
    let best = settings
        .iter()
        .min_by(|a, b| {
            (a.mean_std_ux_px + a.mean_std_uy_px).total_cmp(&(b.mean_std_ux_px + b.mean_std_uy_px))
        })
        .map(|s| s.label.clone())
        .unwrap_or_default();
    let others = settings.len().saturating_sub(1) * 2;
    let wins = comparisons
        .iter()
        .filter(|c| c.significant && (c.a == best || c.b == best))
        .filter(|c| (c.a == best) == (c.test.mean_difference < 0.0))
        .count();
    Ok(NoiseReport {
        settings,
        recommended_significantly_lower: others > 0 && wins == others,
        recommended: best,
        comparisons,
        alpha,
    })
}

/// Writes `pairs.csv`, `settings.csv`, `ttests.csv` and the box plot `random_error.png`
/// (seed Fig. 7); returns the files written.
pub fn write_outputs(report: &NoiseReport, out: &Path) -> Result<Vec<String>, UsError> {
    let mut files = Vec::new();
    let mut write = |name: &str, body: String| -> Result<(), UsError> {
        let p = out.join(name);
        femu_mesh::atomic::write(&p, body).map_err(|e| UsError::write(&p, e))?;
        files.push(name.to_string());
        Ok(())
    };
    let mut s = String::from("setting,frequency_mhz,gain_db,dynamic_db,subject,pair,reference_line,deformed_line,std_ux_px,std_uy_px,mean_ux_px,mean_uy_px,converged\n");
    for st in &report.settings {
        for p in &st.pairs {
            s += &format!(
                "{},{},{},{},{},{},{},{},{:.6},{:.6},{:.6},{:.6},{}\n",
                st.label,
                st.frequency_mhz,
                st.gain_db,
                st.dynamic_db,
                p.subject,
                p.rank + 1,
                p.reference_line,
                p.deformed_line,
                p.std_ux_px,
                p.std_uy_px,
                p.mean_ux_px,
                p.mean_uy_px,
                p.converged
            );
        }
    }
    write("pairs.csv", s)?;
    let mut s = String::from("setting,frequency_mhz,gain_db,dynamic_db,pairs,mean_std_ux_px,sd_std_ux_px,mean_std_uy_px,sd_std_uy_px,recommended\n");
    for st in &report.settings {
        s += &format!(
            "{},{},{},{},{},{:.6},{:.6},{:.6},{:.6},{}\n",
            st.label,
            st.frequency_mhz,
            st.gain_db,
            st.dynamic_db,
            st.pairs.len(),
            st.mean_std_ux_px,
            st.sd_std_ux_px,
            st.mean_std_uy_px,
            st.sd_std_uy_px,
            st.label == report.recommended
        );
    }
    write("settings.csv", s)?;
    let mut s = String::from("a,b,component,pairs,mean_difference_px,t,df,p_value,significant\n");
    for c in &report.comparisons {
        s += &format!(
            "{},{},{},{},{:.6},{:.6},{},{:.6e},{}\n",
            c.a,
            c.b,
            c.component,
            c.test.n,
            c.test.mean_difference,
            c.test.t,
            c.test.degrees_of_freedom,
            c.test.p_value,
            c.significant
        );
    }
    write("ttests.csv", s)?;
    let mut groups = Vec::new();
    for st in &report.settings {
        groups.push((
            format!("{} ux", st.label),
            st.pairs.iter().map(|p| p.std_ux_px).collect(),
        ));
        groups.push((
            format!("{} uy", st.label),
            st.pairs.iter().map(|p| p.std_uy_px).collect(),
        ));
    }
    let p = out.join("random_error.png");
    femu_plot::box_plot_png(
        &p,
        &groups,
        &femu_plot::BoxPlot {
            title: "DIC random error of successive acquisitions per setting (seed Fig. 7)".into(),
            y_label: "standard deviation of the displacement (px)".into(),
            ..Default::default()
        },
    )
    .map_err(|e| UsError::plot(&p, e))?;
    files.push("random_error.png".into());
    Ok(files)
}
