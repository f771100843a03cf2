//! The compression test (seed §2.1.2.3, Fig. 3.C): a rigid flat plate pressed on one side of
//! the thigh, frictionless, force-controlled (the seed: 0.1 N per mm of thickness).

use super::{
    push_rigid_body, skin_extent, KeyError, KeyValue, Loading, LoadingError, LoadingTest, Side,
    TestKey, TestKeys, TestKind,
};
use crate::contact::RigidPlate;
use crate::model::Model;
use std::sync::Arc;

/// A rigid flat plate against `side`, pushed with `force` (N per mm).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Compression {
    pub side: Side,
    pub force: f64,
}

/// The registered kind.
pub static KIND: TestKind = TestKind {
    name: "compression",
    doc: "rigid frictionless plate, force-controlled",
    keys: &[
        TestKey {
            name: "side",
            doc: "anterior (default), posterior, lateral, medial, or an angle in degrees",
        },
        TestKey {
            name: "force_n_per_mm",
            doc: "force per mm of thickness (plane strain; required)",
        },
    ],
    build,
};

fn build(keys: &TestKeys) -> Result<Loading, KeyError> {
    Ok(Loading::new(Compression {
        side: super::side_key(keys, "side")?,
        force: super::positive_key(keys, "force_n_per_mm", None, super::MAX_FORCE_N_PER_MM)?,
    }))
}

impl LoadingTest for Compression {
    fn kind(&self) -> &'static TestKind {
        &KIND
    }

    fn name(&self) -> String {
        format!("compression-{}", self.side.name())
    }

    /// The plate starts 1 mm outside the skin, its normal towards the section's centre, and is
    /// moved to first contact automatically.
    fn apply(&self, model: &mut Model, skin: &[(usize, usize)]) -> Result<(), LoadingError> {
        let e = self.side.direction();
        let (c, reach) = skin_extent(model, skin, e);
        let point = [c[0] + (reach + 1.0) * e[0], c[1] + (reach + 1.0) * e[1]];
        let plate = RigidPlate::new(point, [-e[0], -e[1]])?;
        push_rigid_body(model, skin, &self.name(), Arc::new(plate), self.force)
    }

    fn scaled(&self, s: f64) -> Loading {
        Loading::new(Compression {
            force: self.force * s,
            ..*self
        })
    }

    fn keys(&self) -> Vec<(&'static str, KeyValue)> {
        vec![
            ("side", self.side.key_value()),
            ("force_n_per_mm", KeyValue::Number(self.force)),
        ]
    }

    fn has_rigid_body(&self) -> bool {
        true
    }
}
