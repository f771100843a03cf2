//! The contention test (seed §2.1.2.3, Fig. 3.A): a follower pressure on the whole skin, the
//! seed's 20 mmHg (2.666e-3 MPa) of a compression garment.

use super::{KeyError, KeyValue, Loading, LoadingError, LoadingTest, TestKey, TestKeys, TestKind};
use crate::load::PressureFace;
use crate::model::Model;
use femu_mesh::MMHG_IN_MPA;

/// A follower pressure (MPa) on the whole skin.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Contention {
    pub pressure: f64,
}

/// The registered kind.
pub static KIND: TestKind = TestKind {
    name: "contention",
    doc: "follower pressure on the whole skin",
    keys: &[
        TestKey {
            name: "pressure_mmhg",
            doc: "pressure (mmHg; default 20, the seed's)",
        },
        TestKey {
            name: "pressure_mpa",
            doc: "pressure (MPa), instead of pressure_mmhg",
        },
    ],
    build,
};

/// The largest contention pressure (mmHg): 1 000 mmHg (0.13 MPa), three times a surgical
/// tourniquet's; the seed's garment applies 20.
pub const MAX_PRESSURE_MMHG: f64 = 1000.0;

fn build(keys: &TestKeys) -> Result<Loading, KeyError> {
    let pressure = match (keys.get("pressure_mmhg"), keys.get("pressure_mpa")) {
        (Some(_), Some(_)) => {
            return Err(KeyError {
                key: "pressure_mpa".into(),
                message: "give pressure_mmhg or pressure_mpa".into(),
            })
        }
        (Some(_), None) => {
            super::positive_key(keys, "pressure_mmhg", None, MAX_PRESSURE_MMHG)? * MMHG_IN_MPA
        }
        (None, Some(_)) => {
            super::positive_key(keys, "pressure_mpa", None, MAX_PRESSURE_MMHG * MMHG_IN_MPA)?
        }
        (None, None) => 20.0 * MMHG_IN_MPA,
    };
    Ok(Loading::new(Contention { pressure }))
}

impl LoadingTest for Contention {
    fn kind(&self) -> &'static TestKind {
        &KIND
    }

    fn name(&self) -> String {
        "contention".into()
    }

    fn apply(&self, model: &mut Model, skin: &[(usize, usize)]) -> Result<(), LoadingError> {
        if !self.pressure.is_finite() {
            return Err(LoadingError::BadPressure(self.pressure));
        }
        for &(element, face) in skin {
            let el = &model.mesh.elements[element];
            let n = el.kind.node_count();
            let local = [face, (face + 1) % n];
            model.pressures.push(PressureFace {
                element,
                local,
                nodes: [el.conn[local[0]], el.conn[local[1]]],
                pressure: self.pressure,
            });
        }
        Ok(())
    }

    fn scaled(&self, s: f64) -> Loading {
        Loading::new(Contention {
            pressure: self.pressure * s,
        })
    }

    fn keys(&self) -> Vec<(&'static str, KeyValue)> {
        vec![("pressure_mpa", KeyValue::Number(self.pressure))]
    }

    fn has_rigid_body(&self) -> bool {
        false
    }

    fn skin_pressure(&self) -> Option<f64> {
        Some(self.pressure)
    }
}
