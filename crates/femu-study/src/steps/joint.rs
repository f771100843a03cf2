//! The identification of a study's measurements, together: one FEMU block per measured test
//! (its probe windows, grids and files sharing one forward solve), stacked into one cost over
//! the shared free parameters (`femu_identify::campaign::run_joint`).

use super::discretization;
use super::identify::free_parameters;
use super::measure::{Prepared, PreparedData};
use crate::model::StudyModel;
use crate::schema::Study;
use anyhow::{Context, Result};
use femu_identify::campaign::{
    self, BlockSpec, Campaign, CampaignOptions, Data, Event, FieldBlock,
};
use femu_identify::fit::FreeParameter;
use femu_mech::Model;

/// The models of the measured tests: on the study's mesh, on the multilevel's coarse mesh, and
/// on the mesh the virtual data come from (`[identification] data_refinement`).
pub struct TestModels {
    /// Indices of the measured tests, in the order of their first measurement.
    pub tests: Vec<usize>,
    pub full: Vec<Model>,
    pub coarse: Vec<Model>,
    pub truth: Vec<Model>,
}

impl TestModels {
    /// The models of the tests `prepared` measures.
    pub fn new(study: &Study, built: &StudyModel, prepared: &[Prepared]) -> Result<TestModels> {
        let mut tests: Vec<usize> = Vec::new();
        for p in prepared {
            if !tests.contains(&p.test) {
                tests.push(p.test);
            }
        }
        let load = |b: &StudyModel| -> Result<Vec<Model>> {
            tests
                .iter()
                .map(|&t| b.loaded(&study.tests[t].loading))
                .collect()
        };
        let coarse = match study.identification.coarse_elements {
            None => Vec::new(),
            Some(n) => {
                let mut spec = study.model.clone();
                spec.resolution = crate::schema::Resolution::Elements(n);
                load(&crate::model::build(&spec).context("[identification] coarse_elements")?)?
            }
        };
        let virtual_data = prepared
            .iter()
            .any(|p| matches!(p.data, PreparedData::Virtual { .. }));
        let truth = if virtual_data && study.identification.data_refinement > 1.0 {
            let fine = discretization::refined(study, built, study.identification.data_refinement)?
                .context("[identification] data_refinement: femu cannot refine this model")?;
            load(&fine)?
        } else {
            Vec::new()
        };
        Ok(TestModels {
            full: load(built)?,
            tests,
            coarse,
            truth,
        })
    }

    /// Elements of the model of the first measured test.
    pub fn elements(&self) -> usize {
        self.full[0].mesh.elements.len()
    }
}

/// A fitted joint identification and what it was fitted with.
pub struct JointFit {
    pub campaign: Campaign,
    pub free: Vec<FreeParameter>,
    pub reference: Vec<f64>,
}

/// The field blocks of `prepared` on `models`: one per test, its measurements in order.
pub fn blocks<'a>(
    prepared: &'a [Prepared],
    models: &'a TestModels,
    study: &Study,
) -> Vec<BlockSpec<'a>> {
    models
        .tests
        .iter()
        .enumerate()
        .map(|(b, &t)| {
            let mine: Vec<&Prepared> = prepared.iter().filter(|p| p.test == t).collect();
            BlockSpec::Field(FieldBlock {
                name: study.tests[t].loading.name(),
                model: &models.full[b],
                coarse: models.coarse.get(b),
                truth: models.truth.get(b),
                segments: mine
                    .iter()
                    .map(|p| {
                        let data = match &p.data {
                            PreparedData::Virtual { points, sigma, .. } => Data::Virtual {
                                points,
                                sigma: *sigma,
                            },
                            PreparedData::Measured(m) => Data::Measured(&m.field),
                        };
                        (p.name.clone(), data)
                    })
                    .collect(),
                travel: mine.iter().find_map(|p| p.travel),
            })
        })
        .collect()
}

/// Fits every prepared measurement at once (groups tied when `grouped`).
pub fn fit(
    study: &Study,
    grouped: bool,
    models: &TestModels,
    prepared: &[Prepared],
    options: &CampaignOptions,
    on_event: &(dyn Fn(Event) + Sync),
) -> Result<JointFit, FitFailure> {
    let (free, reference) =
        free_parameters(study, &models.full[0], grouped).map_err(FitFailure::Setup)?;
    let specs = blocks(prepared, models, study);
    let campaign = campaign::run_joint(
        &models.full[0],
        &free,
        &reference,
        &specs,
        options,
        on_event,
    )
    .map_err(|e| FitFailure::Campaign(e, free.clone()))?;
    Ok(JointFit {
        campaign,
        free,
        reference,
    })
}

/// Why a joint fit stopped: before it began, or in the campaign (with the free parameters, to
/// write what finished).
#[derive(Debug)]
pub enum FitFailure {
    Setup(anyhow::Error),
    Campaign(campaign::CampaignError, Vec<FreeParameter>),
}
