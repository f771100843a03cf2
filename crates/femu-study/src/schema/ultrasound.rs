//! `[probe]` and `[ultrasound]`: the simulated B-mode acquisition (`femu us-sim`,
//! `[measurement] source = "ultrasound"`).
//!
//! ```toml
//! [probe]
//! side = "anterior"      # anterior, posterior, lateral, medial, or degrees
//! width_mm = 40
//! depth_mm = 40
//! px_per_mm = 10
//! [ultrasound]
//! frequency_mhz = 9      # also cycles, f_number
//! gain_db = 34           # also dynamic_db, black_level_db, tgc_db_per_cm_mhz, tgc_max_db, noise_db
//! dynamic_db = 42
//! seed = 1
//! render_refine = 2      # images rendered on a mesh of element size / 2 (no inverse crime)
//! decorrelation = 0.05   # fraction of the scatterers renewed per load step
//! ```

use femu_ultrasound::{Scanner, Transducer};
use serde::{Deserialize, Serialize};

/// `[probe]`: the linear probe on the skin.
#[derive(Debug, Clone, PartialEq, Deserialize, Serialize)]
#[serde(deny_unknown_fields, default)]
pub struct ProbeSection {
    pub side: String,
    pub width_mm: f64,
    pub depth_mm: f64,
    pub px_per_mm: f64,
}

impl Default for ProbeSection {
    fn default() -> Self {
        let real = |key: &str| super::keys::default("probe", key);
        ProbeSection {
            side: super::keys::default("probe", "side"),
            width_mm: real("width_mm"),
            depth_mm: real("depth_mm"),
            px_per_mm: real("px_per_mm"),
        }
    }
}

/// `[ultrasound]`: the transducer and the scanner's knobs.
#[derive(Debug, Clone, PartialEq, Deserialize, Serialize)]
#[serde(deny_unknown_fields, default)]
pub struct UltrasoundSection {
    pub frequency_mhz: f64,
    pub cycles: f64,
    pub f_number: f64,
    pub gain_db: f64,
    pub dynamic_db: f64,
    pub black_level_db: f64,
    pub tgc_db_per_cm_mhz: f64,
    pub tgc_max_db: f64,
    pub noise_db: Option<f64>,
    pub seed: u64,
    /// The images are rendered from the FE solution on a mesh whose element size is that of
    /// `[model]` divided by this (1: the same mesh, an inverse crime for the identification).
    pub render_refine: usize,
    /// Fraction of the scatterers renewed between successive load steps (out-of-plane motion).
    pub decorrelation: f64,
}

impl Default for UltrasoundSection {
    fn default() -> Self {
        let real = |key: &str| super::keys::default::<f64>("ultrasound", key);
        UltrasoundSection {
            frequency_mhz: real("frequency_mhz"),
            cycles: real("cycles"),
            f_number: real("f_number"),
            gain_db: real("gain_db"),
            dynamic_db: real("dynamic_db"),
            black_level_db: real("black_level_db"),
            tgc_db_per_cm_mhz: real("tgc_db_per_cm_mhz"),
            tgc_max_db: real("tgc_max_db"),
            noise_db: Some(real("noise_db")),
            seed: super::keys::default("ultrasound", "seed"),
            render_refine: super::keys::default("ultrasound", "render_refine"),
            decorrelation: real("decorrelation"),
        }
    }
}

impl UltrasoundSection {
    /// The transducer of these settings.
    pub fn transducer(&self) -> Transducer {
        Transducer {
            frequency_mhz: self.frequency_mhz,
            cycles: self.cycles,
            f_number: self.f_number,
        }
    }

    /// The scanner of these settings.
    pub fn scanner(&self) -> Scanner {
        Scanner {
            gain_db: self.gain_db,
            dynamic_db: self.dynamic_db,
            black_level_db: self.black_level_db,
            tgc_db_per_cm_mhz: self.tgc_db_per_cm_mhz,
            tgc_max_db: self.tgc_max_db,
            noise_db: self.noise_db,
        }
    }
}

/// A parameter error of the simulator as the error of its key in `table`.
fn key_error(
    e: femu_ultrasound::error::UsError,
    table: &str,
    fallback_key: &str,
    lines: &super::lines::KeyLines,
) -> super::StudyError {
    match e {
        femu_ultrasound::error::UsError::Parameter { name, message } => {
            let key = name.strip_prefix("probe").unwrap_or(&name).trim();
            let key = if key.is_empty() { fallback_key } else { key };
            lines.err(table, 0, key, message)
        }
        other => lines.err(table, 0, fallback_key, other.to_string()),
    }
}

/// Checks `[probe]` in full, whether or not a step uses it: its side, and its size and pixel
/// density as the simulator would (the same ranges and image size), naming the key and its line.
pub(crate) fn check_probe(
    probe: &ProbeSection,
    lines: &super::lines::KeyLines,
) -> Result<(), super::StudyError> {
    femu_mech::loading::Side::parse(&probe.side).map_err(|m| lines.err("probe", 0, "side", m))?;
    femu_ultrasound::probe::Probe::new(
        [0.0, 0.0],
        [0.0, 1.0],
        probe.width_mm,
        probe.depth_mm,
        probe.px_per_mm,
    )
    .map_err(|e| key_error(e, "probe", "px_per_mm", lines))?;
    Ok(())
}

/// Checks `[ultrasound]` in full, whether or not a step uses it: the transducer's and the
/// scanner's ranges (as the simulator checks them), and those the simulator does not check
/// itself, naming the key and its line.
pub(crate) fn check(
    section: &UltrasoundSection,
    lines: &super::lines::KeyLines,
) -> Result<(), super::StudyError> {
    section
        .transducer()
        .validate()
        .map_err(|e| key_error(e, "ultrasound", "frequency_mhz", lines))?;
    section
        .scanner()
        .validate()
        .map_err(|e| key_error(e, "ultrasound", "gain_db", lines))?;
    super::keys::check_int("ultrasound", "render_refine", section.render_refine)
        .map_err(|m| lines.err("ultrasound", 0, "render_refine", m))?;
    super::keys::check_real("ultrasound", "decorrelation", section.decorrelation).map_err(|m| {
        lines.err(
            "ultrasound",
            0,
            "decorrelation",
            format!("the fraction of scatterers renewed per load step {m}"),
        )
    })?;
    Ok(())
}
