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
        ProbeSection {
            side: "anterior".into(),
            width_mm: 40.0,
            depth_mm: 40.0,
            px_per_mm: 10.0,
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
}

impl Default for UltrasoundSection {
    fn default() -> Self {
        let (t, s) = (Transducer::default(), Scanner::default());
        UltrasoundSection {
            frequency_mhz: t.frequency_mhz,
            cycles: t.cycles,
            f_number: t.f_number,
            gain_db: s.gain_db,
            dynamic_db: s.dynamic_db,
            black_level_db: s.black_level_db,
            tgc_db_per_cm_mhz: s.tgc_db_per_cm_mhz,
            tgc_max_db: s.tgc_max_db,
            noise_db: s.noise_db,
            seed: 1,
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
