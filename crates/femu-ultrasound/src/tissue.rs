//! Acoustic properties of the tissues: scatterer density, backscatter level, attenuation.
//!
//! Values for the built-in thigh's regions (defaults; every one can be overridden):
//!
//! | region | scatterers / mm² | backscatter (dB re muscle) | attenuation (dB/cm/MHz) |
//! |---|---|---|---|
//! | FAT | 250 | −8 (hypoechoic) | 0.6 |
//! | QUADRICEPS, ISCHIO, SARTORIUS, GRACILIS | 400 | −1 … +1 (one per muscle, so the muscles differ slightly) | 0.8 |
//! | FEMUR (bone) | — (a hole of the mesh) | surface echo +22 | 20 (a shadow below the cortex) |
//!
//! Attenuation values are the usual ones of the ultrasound literature (Goss, Johnston & Dunn,
//! J. Acoust. Soc. Am. 64, 1978; Duck, *Physical properties of tissue*, 1990: fat 0.5–0.6,
//! skeletal muscle 0.6–1.1 across fibres, cortical bone about 20 dB/cm/MHz); the densities
//! give at least ten scatterers per resolution cell from 5 to 15 MHz, so speckle is fully
//! developed (Rayleigh). Interfaces are bright: the fascia between two regions and the skin
//! reflect +12 / +10 dB above muscle, the bone surface +22 dB (specular: strongest where the
//! beam meets it at normal incidence).

/// One tissue.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Tissue {
    /// Region (element-set) name, upper case.
    pub name: String,
    /// Scatterers per mm² (in the image plane).
    pub density_per_mm2: f64,
    /// Mean backscatter level (dB): the RMS envelope of the tissue's speckle, before
    /// attenuation, is `10^(echo_db / 20)`.
    pub echo_db: f64,
    /// Attenuation (dB/cm/MHz, one way; the round trip doubles it).
    pub attenuation_db_per_cm_mhz: f64,
}

impl Tissue {
    fn new(name: &str, density: f64, echo: f64, att: f64) -> Self {
        Tissue {
            name: name.into(),
            density_per_mm2: density,
            echo_db: echo,
            attenuation_db_per_cm_mhz: att,
        }
    }
}

/// The acoustic model of a mesh: a tissue per region, interfaces and bone.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Acoustics {
    pub tissues: Vec<Tissue>,
    /// The tissue of elements in none of the named regions.
    pub default_tissue: Tissue,
    /// Backscatter of the fascia between two regions (dB), `None`: no interface echo.
    pub fascia_echo_db: Option<f64>,
    /// Backscatter of the skin (the mesh outline other than bone), `None`: none.
    pub skin_echo_db: Option<f64>,
    /// Backscatter of the bone surface (dB).
    pub bone_echo_db: f64,
    /// Attenuation inside the bone outline (dB/cm/MHz).
    pub bone_attenuation_db_per_cm_mhz: f64,
    /// Line scatterers per mm along interfaces.
    pub line_density_per_mm: f64,
}

impl Default for Acoustics {
    /// The built-in thigh (module table).
    fn default() -> Self {
        Acoustics {
            tissues: vec![
                Tissue::new("FAT", 250.0, -8.0, 0.6),
                Tissue::new("QUADRICEPS", 400.0, 0.0, 0.8),
                Tissue::new("ISCHIO", 400.0, 1.0, 0.8),
                Tissue::new("SARTORIUS", 400.0, -1.0, 0.8),
                Tissue::new("GRACILIS", 400.0, 0.5, 0.8),
            ],
            default_tissue: Tissue::new("SOFT TISSUE", 400.0, 0.0, 0.8),
            fascia_echo_db: Some(12.0),
            skin_echo_db: Some(10.0),
            bone_echo_db: 22.0,
            bone_attenuation_db_per_cm_mhz: 20.0,
            line_density_per_mm: 40.0,
        }
    }
}

impl Acoustics {
    /// One homogeneous tissue everywhere, no interface echo (speckle statistics tests).
    pub fn homogeneous(tissue: Tissue) -> Self {
        Acoustics {
            tissues: Vec::new(),
            default_tissue: tissue,
            fascia_echo_db: None,
            skin_echo_db: None,
            ..Acoustics::default()
        }
    }

    /// Checks the ranges: densities in (0, 10 000] /mm², levels within ±80 dB, attenuation in
    /// [0, 50] dB/cm/MHz.
    pub fn validate(&self) -> Result<(), crate::UsError> {
        for t in self
            .tissues
            .iter()
            .chain(std::iter::once(&self.default_tissue))
        {
            let name = |k: &str| format!("tissue {}: {k}", t.name);
            if !(t.density_per_mm2 > 0.0 && t.density_per_mm2 <= 10_000.0) {
                return Err(crate::UsError::param(
                    &name("density_per_mm2"),
                    format!("{} is outside (0, 10000]", t.density_per_mm2),
                ));
            }
            if !(t.echo_db.abs() <= 80.0) {
                return Err(crate::UsError::param(
                    &name("echo_db"),
                    format!("{} is outside [-80, 80]", t.echo_db),
                ));
            }
            if !(0.0..=50.0).contains(&t.attenuation_db_per_cm_mhz) {
                return Err(crate::UsError::param(
                    &name("attenuation_db_per_cm_mhz"),
                    format!("{} is outside [0, 50]", t.attenuation_db_per_cm_mhz),
                ));
            }
        }
        if !(self.line_density_per_mm > 0.0 && self.line_density_per_mm <= 1000.0) {
            return Err(crate::UsError::param(
                "line_density_per_mm",
                format!("{} is outside (0, 1000]", self.line_density_per_mm),
            ));
        }
        Ok(())
    }

    /// Index of the tissue of each element: the first tissue whose name is an element set
    /// holding it; `tissues.len()` (the default tissue) otherwise.
    pub fn tissue_of_elements(&self, mesh: &femu_mesh::Mesh) -> Vec<usize> {
        let mut out = vec![self.tissues.len(); mesh.elements.len()];
        for (k, t) in self.tissues.iter().enumerate().rev() {
            for (name, set) in &mesh.element_sets {
                if name.eq_ignore_ascii_case(&t.name) {
                    for &e in set {
                        if e < out.len() {
                            out[e] = k;
                        }
                    }
                }
            }
        }
        out
    }

    /// The tissue of index `k` (`tissues.len()`: the default).
    pub fn tissue(&self, k: usize) -> &Tissue {
        self.tissues.get(k).unwrap_or(&self.default_tissue)
    }
}
