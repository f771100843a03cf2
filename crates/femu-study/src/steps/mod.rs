//! The pipeline's steps as library functions, each writing its own output folder and returning
//! its typed summary (the same struct its `summary.json` holds, read back by the report). A
//! step takes the part of the study it reads — a section (`&ModelSpec`, `&[TestSpec]`,
//! `&ProbeSection`, ...) or the inputs the caller builds once from the study
//! ([`sensitivity::SensitivityInputs`], [`design::DesignInputs`], [`ultrasound::SimInputs`],
//! [`measure::MeasureInputs`], [`parameters::IdentificationInputs`]) — and the artifacts of the
//! steps before it (the built model, the prepared measurements, the recorded frames, the
//! simulated images); the commands (`run`, `demo`, `synth`, `identify`, `sensitivity::run`,
//! `us-scan`) take the whole study and hand each step its part.
//!
//! | step | function | folder |
//! |---|---|---|
//! | model | [`model::write_study_model`], [`model::mesh_thigh`], [`model::mesh_labels`] | `model/` |
//! | forward | [`solve::solve_model`], [`solve::solve_file`] (a 3D deck: [`solve3::solve_deck3`]), [`solve::forward`] | `forward/TEST/` |
//! | 3D thigh deck | [`solve3::mesh_thigh3d`] | `femu mesh thigh3d --out` |
//! | sensitivity | [`sensitivity::run`] | `sensitivity/` |
//! | measurement | [`identify::synth`], [`measure::prepare`], [`ultrasound::sim`], [`frames::measure`] | `measurement/` |
//! | identification | [`identify::identify`], [`identify::identify_on`], [`images::identify_images`], [`frames::identify_frames`] | `identify/GROUPING/` |
//! | the whole study | [`run::run`], [`run::demo`] | all of the above, `report.html` |

pub mod design;
pub mod discretization;
pub mod frames;
pub mod identify;
pub mod images;
pub mod joint;
pub mod measure;
pub mod model;
pub mod parameters;
pub mod record;
pub mod run;
pub mod sensitivity;
pub mod sequence;
pub mod solve;
pub mod solve3;
pub mod ultrasound;
