//! The study file of the analysis commands (`femu sensitivity`, and the identification to
//! come): the built-in thigh, its materials, the loading tests, the measurement grid and noise.
//! Every key is optional; units are in the key names (conventions.md). Unknown keys are errors
//! naming the key and the line.
//!
//! ```toml
//! [model]
//! elements = 6000              # target quads of the built-in thigh (or size_mm = 2.0)
//! element = "cpe4h"            # cpe4 or cpe4h
//!
//! [materials.QUADRICEPS]       # overrides of Table 1, by region
//! c10_kpa = 1.75               # or c10_mpa
//! d_per_mpa = 18.0
//!
//! [[test]]                     # default: the seed's three tests
//! kind = "contention"
//! pressure_mmhg = 20.0         # or pressure_mpa
//! [[test]]
//! kind = "compression"
//! side = "anterior"            # anterior, posterior, lateral, medial, or degrees
//! force_n_per_mm = 0.1
//! [[test]]
//! kind = "indentation"
//! side = "anterior"
//! radius_mm = 10.0
//! force_n_per_mm = 0.1
//!
//! [grid]                       # the measurement points (default: 64 x 64 over the thigh)
//! counts = [64, 64]
//! origin_mm = [-70.0, -60.0]   # lower-left point; default centres the grid on the skin
//! spacing_mm = 2.2             # default: the skin's larger extent / (count - 1)
//!
//! [noise]
//! sigma_mm = 0.0176            # the seed's 1.5 px
//!
//! [parameters]
//! groups = [["D_ISCHIO", "D_SARTORIUS", "D_GRACILIS"]]   # tied parameters (seed §2.4.2)
//!
//! [identification]
//! test = "compression"         # the test whose field is measured (default: compression)
//! fixed = []                   # parameters held at their reference value
//! grouped = true               # tie [parameters] groups
//! bounds_factor = 4.0          # bounds: reference / 4 .. reference x 4
//! starts = 5                   # Latin-hypercube starts
//! seed = 1                     # noise and starts
//! repeat = 1                   # noise realizations (Monte Carlo)
//! ```

use anyhow::{bail, Context, Result};
use femu_mech::loading::{Loading, Side};
use femu_mesh::MMHG_IN_MPA;
use serde::Deserialize;
use std::collections::BTreeMap;
use std::path::Path;

#[derive(Debug, Deserialize, Default)]
#[serde(deny_unknown_fields)]
struct PlanFile {
    model: Option<ModelEntry>,
    #[serde(default)]
    materials: BTreeMap<String, MaterialEntry>,
    #[serde(default)]
    test: Vec<TestEntry>,
    grid: Option<GridEntry>,
    noise: Option<NoiseEntry>,
    parameters: Option<ParametersEntry>,
    identification: Option<IdentificationEntry>,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct IdentificationEntry {
    test: Option<String>,
    #[serde(default)]
    fixed: Vec<String>,
    bounds_factor: Option<f64>,
    starts: Option<usize>,
    seed: Option<u64>,
    repeat: Option<usize>,
    grouped: Option<bool>,
}

/// The identification settings (`[identification]`).
#[derive(Debug, Clone, PartialEq)]
pub struct IdentificationPlan {
    /// Index into [`Plan::tests`] of the test whose field is measured.
    pub test: usize,
    /// Parameters held at their reference value (`C10_FAT`, ...).
    pub fixed: Vec<String>,
    /// Bounds: reference / factor .. reference x factor.
    pub bounds_factor: f64,
    pub starts: usize,
    pub seed: u64,
    /// Noise realizations (Monte Carlo).
    pub repeat: usize,
    /// Whether `[parameters] groups` are tied.
    pub grouped: bool,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct ModelEntry {
    elements: Option<usize>,
    size_mm: Option<f64>,
    element: Option<String>,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct MaterialEntry {
    c10_kpa: Option<f64>,
    c10_mpa: Option<f64>,
    d_per_mpa: Option<f64>,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct TestEntry {
    kind: String,
    pressure_mmhg: Option<f64>,
    pressure_mpa: Option<f64>,
    side: Option<String>,
    force_n_per_mm: Option<f64>,
    radius_mm: Option<f64>,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct GridEntry {
    counts: Option<[usize; 2]>,
    origin_mm: Option<[f64; 2]>,
    spacing_mm: Option<f64>,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct NoiseEntry {
    sigma_mm: f64,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct ParametersEntry {
    #[serde(default)]
    groups: Vec<Vec<String>>,
}

/// The measurement grid: `counts` points `spacing` apart from `origin` (mm); `None` fields are
/// fitted to the model's skin.
#[derive(Debug, Clone, PartialEq)]
pub struct GridSpec {
    pub counts: [usize; 2],
    pub origin: Option<[f64; 2]>,
    pub spacing: Option<f64>,
}

impl GridSpec {
    /// The grid points (row by row, x fastest) for a model whose reference bounding box is
    /// `lo..hi`.
    pub fn points(&self, lo: [f64; 2], hi: [f64; 2]) -> Vec<[f64; 2]> {
        let [nx, ny] = self.counts;
        let extent = (hi[0] - lo[0]).max(hi[1] - lo[1]);
        let spacing = self
            .spacing
            .unwrap_or(extent / (nx.max(ny).max(2) - 1) as f64);
        let origin = self.origin.unwrap_or([
            0.5 * (lo[0] + hi[0]) - 0.5 * spacing * (nx - 1) as f64,
            0.5 * (lo[1] + hi[1]) - 0.5 * spacing * (ny - 1) as f64,
        ]);
        (0..ny)
            .flat_map(|j| {
                (0..nx).map(move |i| {
                    [
                        origin[0] + i as f64 * spacing,
                        origin[1] + j as f64 * spacing,
                    ]
                })
            })
            .collect()
    }
}

/// A checked study.
#[derive(Debug, Clone)]
pub struct Plan {
    pub elements: Option<usize>,
    pub size_mm: Option<f64>,
    pub element: crate::QuadElement,
    /// `(region, C10 MPa, D MPa⁻¹)` overrides of Table 1.
    pub materials: Vec<(String, Option<f64>, Option<f64>)>,
    pub tests: Vec<Loading>,
    pub grid: GridSpec,
    pub sigma_mm: f64,
    pub groups: Vec<Vec<String>>,
    pub identification: IdentificationPlan,
}

impl Default for Plan {
    fn default() -> Self {
        parse("").expect("the empty study is valid")
    }
}

/// The seed's measurement noise: 1.5 px = 1.76e-2 mm (§3.1.3).
pub const SEED_SIGMA_MM: f64 = 1.76e-2;

/// The seed's grouping (§2.4.2): D of ischio, sartorius and gracilis tied.
pub fn seed_groups() -> Vec<Vec<String>> {
    vec![vec![
        "D_ISCHIO".into(),
        "D_SARTORIUS".into(),
        "D_GRACILIS".into(),
    ]]
}

/// The study of a command: the file if given (else the defaults), `--elements` over it, and the
/// seed's grouping when the study names none.
pub fn load(study: Option<&Path>, elements: Option<usize>) -> Result<Plan> {
    let mut plan = match study {
        Some(p) => read(p)?,
        None => Plan::default(),
    };
    if let Some(n) = elements {
        plan.elements = Some(n);
        plan.size_mm = None;
    }
    if plan.groups.is_empty() {
        plan.groups = seed_groups();
    }
    Ok(plan)
}

/// Reads and checks a study file.
pub fn read(path: &Path) -> Result<Plan> {
    let text = std::fs::read_to_string(path)
        .with_context(|| format!("cannot read study file {}", path.display()))?;
    parse(&text).with_context(|| format!("study file {}", path.display()))
}

fn positive(name: &str, v: f64) -> Result<f64> {
    if !(v > 0.0 && v.is_finite()) {
        bail!("{name} must be positive and finite, got {v}");
    }
    Ok(v)
}

/// Parses and checks a study (see the module documentation).
pub fn parse(text: &str) -> Result<Plan> {
    let file: PlanFile = toml::from_str(text).map_err(|e| anyhow::anyhow!("{e}"))?;
    let model = file.model.unwrap_or(ModelEntry {
        elements: None,
        size_mm: None,
        element: None,
    });
    if model.elements.is_some() && model.size_mm.is_some() {
        bail!("[model]: give elements or size_mm, not both");
    }
    if let Some(h) = model.size_mm {
        positive("[model] size_mm", h)?;
    }
    let element = match model
        .element
        .as_deref()
        .map(str::to_ascii_lowercase)
        .as_deref()
    {
        None | Some("cpe4h") => crate::QuadElement::Cpe4h,
        Some("cpe4") => crate::QuadElement::Cpe4,
        Some(other) => bail!("[model] element: unknown element type '{other}' (cpe4, cpe4h)"),
    };
    let mut materials = Vec::new();
    for (region, m) in &file.materials {
        let c10 = match (m.c10_kpa, m.c10_mpa) {
            (Some(_), Some(_)) => bail!("[materials.{region}]: give c10_kpa or c10_mpa, not both"),
            (Some(k), None) => Some(positive(&format!("[materials.{region}] c10_kpa"), k)? * 1e-3),
            (None, Some(v)) => Some(positive(&format!("[materials.{region}] c10_mpa"), v)?),
            (None, None) => None,
        };
        let d = m
            .d_per_mpa
            .map(|d| positive(&format!("[materials.{region}] d_per_mpa"), d))
            .transpose()?;
        materials.push((region.to_ascii_uppercase(), c10, d));
    }
    let mut tests = Vec::new();
    for (k, t) in file.test.iter().enumerate() {
        let at = format!("[[test]] {} ({})", k + 1, t.kind);
        let side = |t: &TestEntry| -> Result<Side> {
            Side::parse(t.side.as_deref().unwrap_or("anterior"))
                .map_err(|e| anyhow::anyhow!("{at} side: {e}"))
        };
        let force = |t: &TestEntry| -> Result<f64> {
            positive(
                &format!("{at} force_n_per_mm"),
                t.force_n_per_mm
                    .with_context(|| format!("{at}: force_n_per_mm is missing"))?,
            )
        };
        let loading = match t.kind.to_ascii_lowercase().as_str() {
            "contention" => {
                let p = match (t.pressure_mmhg, t.pressure_mpa) {
                    (Some(_), Some(_)) => bail!("{at}: give pressure_mmhg or pressure_mpa"),
                    (Some(mmhg), None) => {
                        positive(&format!("{at} pressure_mmhg"), mmhg)? * MMHG_IN_MPA
                    }
                    (None, Some(mpa)) => positive(&format!("{at} pressure_mpa"), mpa)?,
                    (None, None) => 20.0 * MMHG_IN_MPA,
                };
                Loading::Contention { pressure: p }
            }
            "compression" => Loading::Compression {
                side: side(t)?,
                force: force(t)?,
            },
            "indentation" => Loading::Indentation {
                site: side(t)?,
                radius: positive(&format!("{at} radius_mm"), t.radius_mm.unwrap_or(10.0))?,
                force: force(t)?,
            },
            other => bail!(
                "[[test]] {}: unknown kind '{other}' (contention, compression, indentation)",
                k + 1
            ),
        };
        let extra = match t.kind.to_ascii_lowercase().as_str() {
            "contention" => t.side.is_some() || t.force_n_per_mm.is_some() || t.radius_mm.is_some(),
            "compression" => {
                t.pressure_mmhg.is_some() || t.pressure_mpa.is_some() || t.radius_mm.is_some()
            }
            _ => t.pressure_mmhg.is_some() || t.pressure_mpa.is_some(),
        };
        if extra {
            bail!("{at}: a key of another kind of test is given");
        }
        tests.push(loading);
    }
    if tests.is_empty() {
        tests = vec![
            Loading::SEED_CONTENTION,
            Loading::SEED_COMPRESSION,
            Loading::Indentation {
                site: Side::Anterior,
                radius: 10.0,
                force: 0.1,
            },
        ];
    }
    let grid = match file.grid {
        None => GridSpec {
            counts: [64, 64],
            origin: None,
            spacing: None,
        },
        Some(g) => {
            let counts = g.counts.unwrap_or([64, 64]);
            if counts[0] < 2 || counts[1] < 2 || counts[0] * counts[1] > 4_000_000 {
                bail!(
                    "[grid] counts must be at least 2 x 2 and at most 4e6 points, got {counts:?}"
                );
            }
            if let Some(s) = g.spacing_mm {
                positive("[grid] spacing_mm", s)?;
            }
            if let Some(o) = g.origin_mm {
                if !(o[0].is_finite() && o[1].is_finite()) {
                    bail!("[grid] origin_mm must be finite, got {o:?}");
                }
            }
            GridSpec {
                counts,
                origin: g.origin_mm,
                spacing: g.spacing_mm,
            }
        }
    };
    let sigma_mm = match file.noise {
        None => SEED_SIGMA_MM,
        Some(n) => positive("[noise] sigma_mm", n.sigma_mm)?,
    };
    let identification = {
        let e = file.identification.unwrap_or(IdentificationEntry {
            test: None,
            fixed: Vec::new(),
            bounds_factor: None,
            starts: None,
            seed: None,
            repeat: None,
            grouped: None,
        });
        let test = match &e.test {
            None => tests
                .iter()
                .position(|t| matches!(t, Loading::Compression { .. }))
                .unwrap_or(0),
            Some(name) => tests
                .iter()
                .position(|t| {
                    t.name().eq_ignore_ascii_case(name)
                        || t.name()
                            .split('-')
                            .next()
                            .is_some_and(|k| k.eq_ignore_ascii_case(name))
                })
                .with_context(|| {
                    format!(
                        "[identification] test: no test '{name}' (tests: {})",
                        tests
                            .iter()
                            .map(|t| t.name())
                            .collect::<Vec<_>>()
                            .join(", ")
                    )
                })?,
        };
        let bounds_factor = e.bounds_factor.unwrap_or(4.0);
        if !(bounds_factor > 1.0 && bounds_factor.is_finite()) {
            bail!("[identification] bounds_factor must be above 1, got {bounds_factor}");
        }
        let starts = e.starts.unwrap_or(5);
        if !(1..=64).contains(&starts) {
            bail!("[identification] starts must be in [1, 64], got {starts}");
        }
        let repeat = e.repeat.unwrap_or(1);
        if !(1..=1000).contains(&repeat) {
            bail!("[identification] repeat must be in [1, 1000], got {repeat}");
        }
        IdentificationPlan {
            test,
            fixed: e.fixed,
            bounds_factor,
            starts,
            seed: e.seed.unwrap_or(1),
            repeat,
            grouped: e.grouped.unwrap_or(true),
        }
    };
    Ok(Plan {
        identification,
        elements: model.elements,
        size_mm: model.size_mm,
        element,
        materials,
        tests,
        grid,
        sigma_mm,
        groups: file.parameters.map(|p| p.groups).unwrap_or_default(),
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn defaults_are_the_seed() {
        let p = Plan::default();
        assert_eq!(p.tests.len(), 3);
        assert_eq!(p.grid.counts, [64, 64]);
        assert_eq!(p.sigma_mm, SEED_SIGMA_MM);
        let pts = p.grid.points([-70.0, -60.0], [70.0, 60.0]);
        assert_eq!(pts.len(), 64 * 64);
        assert!((pts[0][0] + 70.0).abs() < 1e-12 && (pts[63][0] - 70.0).abs() < 1e-12);
    }

    #[test]
    fn reads_keys_and_names_bad_ones() {
        let p = parse(
            "[model]\nelements = 800\nelement = \"cpe4\"\n[materials.fat]\nc10_kpa = 1.0\n\
             [[test]]\nkind = \"compression\"\nside = \"lateral\"\nforce_n_per_mm = 0.2\n\
             [noise]\nsigma_mm = 0.01\n[parameters]\ngroups = [[\"D_ISCHIO\", \"D_GRACILIS\"]]\n",
        )
        .unwrap();
        assert_eq!(p.elements, Some(800));
        assert_eq!(p.materials, vec![("FAT".into(), Some(1e-3), None)]);
        assert_eq!(p.tests.len(), 1);
        assert_eq!(p.groups.len(), 1);
        let err = |t: &str| format!("{:#}", parse(t).unwrap_err());
        let e = err("[model]\nelemnts = 3\n");
        assert!(e.contains("elemnts") && e.contains("line 2"), "{e}");
        assert!(err("[[test]]\nkind = \"stretch\"\n").contains("stretch"));
        assert!(err("[[test]]\nkind = \"compression\"\n").contains("force_n_per_mm"));
        assert!(err("[noise]\nsigma_mm = -1\n").contains("sigma_mm"));
        assert!(err("[materials.fat]\nc10_kpa = 1\nc10_mpa = 1\n").contains("not both"));
        assert!(
            err("[[test]]\nkind = \"contention\"\nforce_n_per_mm = 1\n").contains("another kind")
        );
    }
}
