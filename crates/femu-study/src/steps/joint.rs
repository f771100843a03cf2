//! The identification of a study's measurements, together: one FEMU block per measured test
//! (its probe windows, grids and files sharing one forward solve), stacked into one cost over
//! the shared free parameters (`femu_identify::campaign::run_joint`).

use super::measure::{Prepared, PreparedData};
use super::parameters::IdentificationInputs;
use crate::error::{Context, Result};
use crate::model::StudyModel;
use crate::progress::Progress;
use crate::schema::TestSpec;
use femu_identify::campaign::{
    self, BlockSpec, Campaign, CampaignOptions, Data, Event, FieldBlock,
};
use femu_identify::fit::FreeParameter;
use femu_identify::measured::{MeasuredField, MeasuredPoint};
use femu_mech::Model;
use std::path::Path;

/// The models of the measured tests: on the study's mesh, on the multilevel's coarse mesh, and
/// on the mesh the virtual data come from (`[identification] data_refinement`).
pub struct TestModels {
    /// Indices of the measured tests, in the order of their first measurement.
    pub tests: Vec<usize>,
    pub full: Vec<Model>,
    pub coarse: Vec<Model>,
    pub truth: Vec<Model>,
    /// Per measured test, a solution of its full model at the study's reference parameters
    /// that an earlier step made ([`StudyModel::reference_state`]).
    pub warm: Vec<Option<Vec<f64>>>,
}

impl TestModels {
    /// The models on `built` of the tests `prepared` measures (of `inputs.tests`), and on the
    /// meshes `inputs` asks for (`coarse_elements`, `data_refinement`).
    pub fn new(
        inputs: &IdentificationInputs,
        built: &StudyModel,
        prepared: &[Prepared],
    ) -> Result<TestModels> {
        let mut tests: Vec<usize> = Vec::new();
        for p in prepared {
            if !tests.contains(&p.test) {
                tests.push(p.test);
            }
        }
        let load = |b: &StudyModel| -> Result<Vec<Model>> {
            tests
                .iter()
                .map(|&t| b.loaded(&inputs.tests[t].loading))
                .collect()
        };
        let coarse = match inputs.identification.coarse_elements {
            None => Vec::new(),
            Some(n) => {
                let mut spec = inputs.model.clone();
                spec.resolution = crate::schema::Resolution::Elements(n);
                load(&crate::model::build(&spec).context("[identification] coarse_elements")?)?
            }
        };
        let virtual_data = prepared
            .iter()
            .any(|p| matches!(p.data, PreparedData::Virtual { .. }));
        let truth = if virtual_data && inputs.identification.data_refinement > 1.0 {
            let fine = crate::model::build_refined(
                inputs.model,
                built,
                inputs.identification.data_refinement,
            )?
            .context("[identification] data_refinement: femu cannot refine this model")?;
            load(&fine)?
        } else {
            Vec::new()
        };
        let warm = tests
            .iter()
            .map(|&t| built.reference_state(&inputs.tests[t].loading))
            .collect();
        Ok(TestModels {
            full: load(built)?,
            tests,
            coarse,
            truth,
            warm,
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

/// The field blocks of `prepared` on `models`: one per test (named from `tests`), its
/// measurements in order.
pub fn blocks<'a>(
    prepared: &'a [Prepared],
    models: &'a TestModels,
    tests: &[TestSpec],
) -> Vec<BlockSpec<'a>> {
    models
        .tests
        .iter()
        .enumerate()
        .map(|(b, &t)| {
            let mine: Vec<&Prepared> = prepared.iter().filter(|p| p.test == t).collect();
            BlockSpec::Field(FieldBlock {
                name: tests[t].loading.name(),
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
                warm: models.warm.get(b).and_then(|w| w.as_deref()),
            })
        })
        .collect()
}

/// Fits every prepared measurement at once (groups tied when `grouped`).
pub fn fit(
    inputs: &IdentificationInputs,
    grouped: bool,
    models: &TestModels,
    prepared: &[Prepared],
    options: &CampaignOptions,
    on_event: &(dyn Fn(Event) + Sync),
) -> Result<JointFit, FitFailure> {
    let (free, reference) = inputs
        .free_parameters(&models.full[0], grouped)
        .map_err(FitFailure::Setup)?;
    let specs = blocks(prepared, models, inputs.tests);
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
    Setup(crate::Error),
    Campaign(campaign::CampaignError, Vec<FreeParameter>),
}

/// Each prepared measurement with its field as the identification fits it in its first repeat
/// (a virtual one's first noise realization; a file's mapped to the model frame).
pub fn realized<'a>(
    inputs: &IdentificationInputs,
    built: &StudyModel,
    prepared: &'a [Prepared],
) -> Result<Vec<(&'a Prepared, Vec<MeasuredPoint>)>> {
    let models = TestModels::new(inputs, built, prepared)?;
    let (free, reference) =
        inputs.free_parameters(&models.full[0], inputs.identification.grouped())?;
    let blocks = blocks(prepared, &models, inputs.tests);
    let seed = inputs.identification.seed;
    let fields = campaign::realized_fields(&models.full[0], &free, &reference, &blocks, seed, 0)?;
    let mut fitted = Vec::new();
    for (b, &t) in models.tests.iter().enumerate() {
        let mine = prepared.iter().filter(|p| p.test == t);
        for (p, range) in mine.zip(&fields[b].1) {
            fitted.push((p, fields[b].0.points[range.clone()].to_vec()));
        }
    }
    Ok(fitted)
}

/// Writes each prepared measurement's field as the identification fits it in its first repeat
/// ([`realized`]) to `dir/measured.csv`, or `dir/NAME/measured.csv` for a list of measurements
/// (an ultrasound measurement's folder already holds its own).
pub fn write_measured(
    inputs: &IdentificationInputs,
    built: &StudyModel,
    prepared: &[Prepared],
    dir: &Path,
    progress: &dyn Progress,
) -> Result<()> {
    let seed = inputs.identification.seed;
    let fitted = realized(inputs, built, prepared)?;
    for (p, points) in fitted {
        let path = if inputs.measurement_list {
            dir.join(&p.name).join("measured.csv")
        } else {
            dir.join("measured.csv")
        };
        let (comments, sigma) = match &p.data {
            PreparedData::Virtual {
                points,
                total,
                sigma,
            } => (
                vec![
                    "femu synth: virtual experiment (seed 2.4.1)".into(),
                    format!("{}; noise sigma {sigma} mm, seed {seed}", p.label),
                    format!("{} of {total} grid points in the tissue", points.len()),
                ],
                Some(*sigma),
            ),
            PreparedData::Measured(m) if m.reference_known => continue,
            PreparedData::Measured(m) => (vec![format!("{}: {}", p.label, m.source)], None),
        };
        if let Some(parent) = path.parent() {
            crate::output::create_dir(parent)?;
        }
        let field = MeasuredField { points, comments };
        field
            .write(&path, sigma)
            .with_context(|| format!("cannot write {}", path.display()))?;
        progress.note(&format!(
            "{}: {} measured points -> {}",
            p.label,
            field.points.len(),
            path.display()
        ));
    }
    Ok(())
}
