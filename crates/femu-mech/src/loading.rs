//! The seed's three loading tests as named loadings (seed §2.1.2.3, Fig. 3):
//!
//! - **contention**: a follower pressure on the whole skin (20 mmHg = 2.666e-3 MPa);
//! - **compression**: a rigid flat plate pressed on one side of the thigh with a force
//!   (0.1 N per mm of thickness), frictionless, femur fixed;
//! - **indentation**: a rigid cylindrical indenter pressed at one site (3 N per mm).
//!
//! Sides are named in the cross-section frame used by every femu model: +y anterior,
//! -y posterior, +x lateral, -x medial (or any angle in degrees from +x, counter-clockwise).

use crate::contact::{ContactError, RigidContact, RigidCylinder, RigidPlate, TravelControl};
use crate::load::PressureFace;
use crate::model::Model;
use serde::{Deserialize, Serialize};
use std::sync::Arc;

/// A side of the thigh cross-section.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Side {
    /// +y.
    Anterior,
    /// -y.
    Posterior,
    /// +x.
    Lateral,
    /// -x.
    Medial,
    /// Any direction, degrees counter-clockwise from +x.
    Angle(f64),
}

impl Side {
    /// Unit vector from the section's centre towards this side.
    pub fn direction(self) -> [f64; 2] {
        let deg: f64 = match self {
            Side::Lateral => 0.0,
            Side::Anterior => 90.0,
            Side::Medial => 180.0,
            Side::Posterior => 270.0,
            Side::Angle(a) => a,
        };
        let (s, c) = deg.to_radians().sin_cos();
        [c, s]
    }

    /// Parses `anterior`, `posterior`, `lateral`, `medial` or an angle in degrees.
    pub fn parse(text: &str) -> Result<Side, String> {
        match text.trim().to_ascii_lowercase().as_str() {
            "anterior" => Ok(Side::Anterior),
            "posterior" => Ok(Side::Posterior),
            "lateral" => Ok(Side::Lateral),
            "medial" => Ok(Side::Medial),
            other => other
                .trim_end_matches("deg")
                .trim()
                .parse::<f64>()
                .ok()
                .filter(|a| a.is_finite())
                .map(Side::Angle)
                .ok_or_else(|| format!("'{text}' is not a side (anterior, posterior, lateral, medial or an angle in degrees)")),
        }
    }

    /// A short name for files and reports.
    pub fn name(self) -> String {
        match self {
            Side::Anterior => "anterior".into(),
            Side::Posterior => "posterior".into(),
            Side::Lateral => "lateral".into(),
            Side::Medial => "medial".into(),
            Side::Angle(a) => format!("{a}deg"),
        }
    }
}

/// One of the seed's loading tests.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Loading {
    /// Follower pressure (MPa) on the whole skin.
    Contention { pressure: f64 },
    /// Rigid flat plate against `side`, pushed with `force` (N per mm).
    Compression { side: Side, force: f64 },
    /// Rigid cylinder of `radius` (mm) at `site`, pushed with `force` (N per mm).
    Indentation { site: Side, radius: f64, force: f64 },
}

impl Loading {
    /// The seed's contention: 20 mmHg.
    pub const SEED_CONTENTION: Loading = Loading::Contention {
        pressure: 20.0 * femu_mesh::MMHG_IN_MPA,
    };
    /// The seed's compression: 0.1 N/mm, plate on the anterior side.
    pub const SEED_COMPRESSION: Loading = Loading::Compression {
        side: Side::Anterior,
        force: 0.1,
    };
    /// The seed's indentation: 3 N/mm with a 10 mm radius indenter, anterior site.
    pub const SEED_INDENTATION: Loading = Loading::Indentation {
        site: Side::Anterior,
        radius: 10.0,
        force: 3.0,
    };

    /// `contention`, `compression-anterior`, `indentation-medial`, ...
    pub fn name(&self) -> String {
        match self {
            Loading::Contention { .. } => "contention".into(),
            Loading::Compression { side, .. } => format!("compression-{}", side.name()),
            Loading::Indentation { site, .. } => format!("indentation-{}", site.name()),
        }
    }
}

/// A loading that cannot be applied to the model.
#[derive(Debug, thiserror::Error)]
pub enum LoadingError {
    #[error("the skin surface is empty")]
    NoSkin,
    #[error("contention pressure must be finite, got {0} MPa")]
    BadPressure(f64),
    #[error(transparent)]
    Contact(#[from] ContactError),
}

/// Skin centre (mean of the face midpoints) and the largest extent of the skin along `e`.
fn skin_extent(model: &Model, skin: &[(usize, usize)], e: [f64; 2]) -> ([f64; 2], f64) {
    let mut c = [0.0, 0.0];
    let mut pts = Vec::with_capacity(2 * skin.len());
    for &(el, f) in skin {
        for n in model.mesh.elements[el].face_nodes(f) {
            pts.push(model.mesh.nodes[n]);
        }
    }
    for p in &pts {
        c[0] += p[0] / pts.len() as f64;
        c[1] += p[1] / pts.len() as f64;
    }
    let reach = pts
        .iter()
        .map(|p| (p[0] - c[0]) * e[0] + (p[1] - c[1]) * e[1])
        .fold(f64::NEG_INFINITY, f64::max);
    (c, reach)
}

/// Contact spreads from a single node at first contact: the first increment is kept at 2 % of
/// the load (increments then grow automatically), instead of trying the whole load at once.
fn start_contact_gently(model: &mut Model) {
    let period = if model.step.period > 0.0 {
        model.step.period
    } else {
        1.0
    };
    model.step.initial_increment = model.step.initial_increment.min(0.02 * period);
    model.step.max_increments = model.step.max_increments.max(200);
}

/// Applies `loading` to `model` on the skin faces `skin` (`(element, face)`): follower pressure
/// for contention, a force-controlled rigid body for compression and indentation, placed
/// 1 mm outside the skin and moved to first contact automatically.
pub fn apply_loading(
    model: &mut Model,
    skin: &[(usize, usize)],
    loading: &Loading,
) -> Result<(), LoadingError> {
    if skin.is_empty() {
        return Err(LoadingError::NoSkin);
    }
    match *loading {
        Loading::Contention { pressure } => {
            if !pressure.is_finite() {
                return Err(LoadingError::BadPressure(pressure));
            }
            for &(element, face) in skin {
                let el = &model.mesh.elements[element];
                let n = el.kind.node_count();
                let local = [face, (face + 1) % n];
                model.pressures.push(PressureFace {
                    element,
                    local,
                    nodes: [el.conn[local[0]], el.conn[local[1]]],
                    pressure,
                });
            }
        }
        Loading::Compression { side, force } => {
            let e = side.direction();
            let (c, reach) = skin_extent(model, skin, e);
            let point = [c[0] + (reach + 1.0) * e[0], c[1] + (reach + 1.0) * e[1]];
            let plate = RigidPlate::new(point, [-e[0], -e[1]])?;
            let contact = RigidContact::new(
                &loading.name(),
                &model.mesh,
                skin,
                Arc::new(plate),
                TravelControl::Force(force),
            )?;
            model.contacts.push(contact);
            start_contact_gently(model);
        }
        Loading::Indentation {
            site,
            radius,
            force,
        } => {
            let e = site.direction();
            let (c, reach) = skin_extent(model, skin, e);
            let centre = [
                c[0] + (reach + radius + 1.0) * e[0],
                c[1] + (reach + radius + 1.0) * e[1],
            ];
            let cyl = RigidCylinder::new(centre, radius, [-e[0], -e[1]])?;
            let contact = RigidContact::new(
                &loading.name(),
                &model.mesh,
                skin,
                Arc::new(cyl),
                TravelControl::Force(force),
            )?;
            contact.check_centre_outside(&model.mesh, centre)?;
            model.contacts.push(contact);
            start_contact_gently(model);
        }
    }
    Ok(())
}
