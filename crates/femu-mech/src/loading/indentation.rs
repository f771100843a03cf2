//! The indentation test (seed §2.1.2.3, Fig. 3.B): a rigid cylindrical indenter pressed at one
//! site, frictionless, force-controlled (the seed: 3 N per mm).

use super::{
    push_rigid_body, skin_extent, KeyError, KeyValue, Loading, LoadingError, LoadingTest, Side,
    TestKey, TestKeys, TestKind,
};
use crate::contact::RigidCylinder;
use crate::model::Model;
use std::sync::Arc;

/// A rigid cylinder of `radius` (mm) at `site`, pushed with `force` (N per mm).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Indentation {
    pub site: Side,
    pub radius: f64,
    pub force: f64,
}

/// The registered kind.
pub static KIND: TestKind = TestKind {
    name: "indentation",
    doc: "rigid frictionless cylinder, force-controlled",
    keys: &[
        TestKey {
            name: "side",
            doc: "anterior (default), posterior, lateral, medial, or an angle in degrees",
        },
        TestKey {
            name: "radius_mm",
            doc: "indenter radius (default 10)",
        },
        TestKey {
            name: "force_n_per_mm",
            doc: "force per mm of thickness (plane strain; required)",
        },
    ],
    build,
};

fn build(keys: &TestKeys) -> Result<Loading, KeyError> {
    Ok(Loading::new(Indentation {
        site: super::side_key(keys, "side")?,
        radius: super::positive_key(keys, "radius_mm", Some(10.0), super::MAX_BODY_SIZE_MM)?,
        force: super::positive_key(keys, "force_n_per_mm", None, super::MAX_FORCE_N_PER_MM)?,
    }))
}

impl LoadingTest for Indentation {
    fn kind(&self) -> &'static TestKind {
        &KIND
    }

    fn name(&self) -> String {
        format!("indentation-{}", self.site.name())
    }

    /// The cylinder starts 1 mm outside the skin and is moved to first contact automatically;
    /// its centre must stay outside the tissue.
    fn apply(&self, model: &mut Model, skin: &[(usize, usize)]) -> Result<(), LoadingError> {
        let e = self.site.direction();
        let (c, reach) = skin_extent(model, skin, e);
        let centre = [
            c[0] + (reach + self.radius + 1.0) * e[0],
            c[1] + (reach + self.radius + 1.0) * e[1],
        ];
        let cyl = RigidCylinder::new(centre, self.radius, [-e[0], -e[1]])?;
        let n_before = model.contacts.len();
        push_rigid_body(model, skin, &self.name(), Arc::new(cyl), self.force)?;
        if let Err(e) = model.contacts[n_before].check_centre_outside(&model.mesh, centre) {
            model.contacts.truncate(n_before);
            return Err(e.into());
        }
        Ok(())
    }

    fn scaled(&self, s: f64) -> Loading {
        Loading::new(Indentation {
            force: self.force * s,
            ..*self
        })
    }

    fn keys(&self) -> Vec<(&'static str, KeyValue)> {
        vec![
            ("side", self.site.key_value()),
            ("radius_mm", KeyValue::Number(self.radius)),
            ("force_n_per_mm", KeyValue::Number(self.force)),
        ]
    }

    fn has_rigid_body(&self) -> bool {
        true
    }
}
