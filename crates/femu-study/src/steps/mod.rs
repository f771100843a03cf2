//! The pipeline's steps as library functions, each writing its own output folder and returning
//! its typed summary (the same struct its `summary.json` holds, read back by the report):
//!
//! | step | function | folder |
//! |---|---|---|
//! | model | [`model::write_study_model`], [`model::mesh_thigh`], [`model::mesh_labels`] | `model/` |
//! | forward | [`solve::solve_model`], [`solve::solve_file`], [`solve::forward`] | `forward/TEST/` |
//! | sensitivity | [`sensitivity::run`] | `sensitivity/` |
//! | measurement | [`identify::synth`], [`ultrasound::sim`], [`frames::measure`] | `measurement/` |
//! | identification | [`identify::identify`] | `identify/GROUPING/` |
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
pub mod ultrasound;
