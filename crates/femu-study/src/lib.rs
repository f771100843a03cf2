//! The femu study: one typed description of what a user asks for, and the pipeline that
//! computes it.
//!
//! - [`schema`]: the study file (TOML), one schema parsed and checked in one place; every
//!   command reads the view of it it needs.
//! - [`model`]: the model the study describes (built-in thigh, label image, deck, Gmsh mesh),
//!   built and ready to load.
//! - [`steps`]: the pipeline's steps (model, forward, sensitivity, measurement,
//!   identification, the whole run) as functions returning typed, serde-round-trippable
//!   summaries.
//! - [`report`]: the HTML report and `summary.json` of a run folder, from those summaries
//!   ([`html`]: the self-contained page it is written on).
//! - [`progress`]: how a long step tells its user what it is doing.
//!
//! The crate sits above every computing crate (mesh → mechanics → DIC and ultrasound →
//! identification) and below the command line, which parses arguments and calls one function
//! of this crate per command.

// The crate's documentation is for its developers (`cargo doc --document-private-items`):
// its items' docs link to the private functions they build on.
#![allow(rustdoc::private_intra_doc_links)]
#![forbid(unsafe_code)]

pub mod commands;
pub mod error;
pub(crate) mod figures;
pub mod html;
pub mod interfaces;
pub mod json;
pub mod model;
pub mod output;
pub mod progress;
pub mod report;
pub mod schema;
pub mod steps;

pub use error::{Error, ErrorKind};
pub use progress::{Progress, Quiet};
pub use schema::{load, parse, read, Study, StudyError};
