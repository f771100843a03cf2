//! Identification on a thigh whose quadriceps slides on the hamstrings (a frictionless
//! QUADRICEPS–ISCHIO `[[interface]]`): virtual data of the seed's compression test (anterior
//! plate, 0.1 N/mm, noise sigma 0.0176 mm on the `[grid]`), made on a mesh with the element
//! size halved (`[identification] data_refinement = 2`: no inverse crime), over `--repeats`
//! seeded noise realizations;
//!
//! - (a) identified with the TIED model (the same study without the interface): the bias of
//!   ignoring the sliding;
//! - (b) identified with the sliding model, through the study's own route (`identify_on`,
//!   the discretization check included): errors, 95 % intervals and their coverage.
//!
//! ```sh
//! cargo run --release -p femu-study --example interface_campaign -- \
//!     --repeats 10 --elements 1500 --out out/interface_campaign
//! ```
//!
//! Prints one line per parameter and route (the first realization's signed error, the mean and
//! largest Eq. 4 error |identified / reference - 1| over the realizations, the interval
//! coverage), and writes `campaign.json` and each route's
//! identification folder into `--out`.

use anyhow::{bail, Context, Result};
use femu_identify::campaign::{self, CampaignOptions};
use femu_study::progress::Notes;
use femu_study::steps::identify::identify_on;
use femu_study::steps::joint::{self, TestModels};
use femu_study::steps::measure::{self, MeasureInputs};
use femu_study::steps::parameters::IdentificationInputs;
use serde_json::json;
use std::path::PathBuf;
use std::time::Instant;

struct Args {
    repeats: usize,
    elements: usize,
    data_refinement: f64,
    discretization: String,
    out: PathBuf,
}

fn args() -> Result<Args> {
    let mut a = Args {
        repeats: 10,
        elements: 1500,
        data_refinement: 2.0,
        discretization: "check".into(),
        out: PathBuf::from("out/interface_campaign"),
    };
    let mut it = std::env::args().skip(1);
    while let Some(k) = it.next() {
        let v = it.next().with_context(|| format!("{k} needs a value"))?;
        match k.as_str() {
            "--repeats" => a.repeats = v.parse()?,
            "--elements" => a.elements = v.parse()?,
            "--data-refinement" => a.data_refinement = v.parse()?,
            "--discretization" => a.discretization = v,
            "--out" => a.out = PathBuf::from(v),
            other => bail!("unknown option {other}"),
        }
    }
    Ok(a)
}

/// The study: the built-in thigh, the seed's compression test, the sliding interface, and the
/// identification of C10 and D of fat and quadriceps (the others held at their reference).
fn study_text(a: &Args) -> String {
    format!(
        r#"
[model]
elements = {elements}
[[test]]
kind = "compression"
side = "anterior"
force_n_per_mm = 0.1
[[interface]]
between = ["QUADRICEPS", "ISCHIO"]
kind = "frictionless"
[identification]
test = "compression"
grouped = true
repeat = {repeats}
seed = 1
starts = 2
data_refinement = {refine}
discretization = "{disc}"
fixed = ["C10_ISCHIO", "C10_SARTORIUS", "C10_GRACILIS", "D_ISCHIO", "D_SARTORIUS", "D_GRACILIS"]
[run]
sensitivity = false
"#,
        elements = a.elements,
        repeats = a.repeats,
        refine = a.data_refinement,
        disc = a.discretization,
    )
}

fn main() -> Result<()> {
    let a = args()?;
    std::fs::create_dir_all(&a.out)?;
    let study = femu_study::parse(&study_text(&a), &a.out)?;
    let inputs = IdentificationInputs::of(&study);
    let sliding = femu_study::model::build(&study.model)?;
    let mut tied_spec = study.model.clone();
    tied_spec.interfaces.clear();
    let tied = femu_study::model::build(&tied_spec)?;
    eprintln!(
        "sliding model: {} nodes, {} interface(s); tied: {} nodes; {} elements",
        sliding.model.node_count(),
        sliding.model.interfaces.len(),
        tied.model.node_count(),
        tied.model.mesh.elements.len()
    );

    // (b) The sliding model, by the study's route.
    let t0 = Instant::now();
    let prepared = measure::prepare(&MeasureInputs::of(&study), &sliding, &a.out, &Notes)?;
    let summary = identify_on(
        &inputs,
        true,
        &sliding,
        &prepared,
        &a.out.join("sliding"),
        &Notes,
    )?;
    let sliding_time = t0.elapsed().as_secs_f64();

    // (a) The tied model on the same data: the sliding model's data mesh, the tied model's
    // field. The data are drawn as in (b) (the same seed, the same points of the grid in the
    // tissue: the two meshes share their outline).
    let t0 = Instant::now();
    let prepared_tied = measure::prepare(&MeasureInputs::of(&study), &tied, &a.out, &Notes)?;
    let data = TestModels::new(&inputs, &sliding, &prepared)?;
    let models = TestModels {
        tests: data.tests.clone(),
        full: TestModels::new(&inputs, &tied, &prepared_tied)?.full,
        coarse: Vec::new(),
        truth: data.truth,
        warm: Vec::new(),
    };
    anyhow::ensure!(
        !models.truth.is_empty() && !models.truth[0].interfaces.is_empty(),
        "the data model has no sliding interface"
    );
    let spec = inputs.identification;
    let options = CampaignOptions {
        optimizer: spec.optimizer,
        starts: spec.starts,
        seed: spec.seed,
        repeats: spec.repeat,
        travel: None,
        stop: None,
        covariance: None,
        speckle_shift: None,
        loss: spec.loss,
    };
    let fit = joint::fit(&inputs, true, &models, &prepared_tied, &options, &|_| {})
        .map_err(|e| anyhow::anyhow!("tied fit: {e:?}"))?;
    let (tied_estimates, _) =
        campaign::estimates(&fit.campaign, &fit.free, &fit.reference, true, true)?;
    let tied_time = t0.elapsed().as_secs_f64();

    let row = |route: &str, e: &campaign::Estimate| {
        let cov = e.coverage95.unwrap_or(f64::NAN);
        println!(
            "{route:8} {:14} first {:+7.2} %, mean |err| {:6.2} % (sd {:5.2} %), max |err| {:6.2} %, predicted sd {:5.2} %, coverage {:2}/{}",
            e.name,
            100.0 * (e.identified / e.reference.unwrap_or(f64::NAN) - 1.0),
            100.0 * e.mean_relative_error.unwrap_or(f64::NAN),
            100.0 * e.sd_relative_error.unwrap_or(f64::NAN),
            100.0 * e.max_relative_error.unwrap_or(f64::NAN),
            100.0 * e.relative_sd,
            (cov * a.repeats as f64).round() as usize,
            a.repeats
        );
    };
    println!(
        "{} repeats, {} elements (data on {} x finer), discretization {}",
        a.repeats, a.elements, a.data_refinement, a.discretization
    );
    for e in &summary.parameters {
        row("sliding", e);
    }
    for e in &tied_estimates {
        row("tied", e);
    }
    if let Some(c) = &summary.discretization {
        println!(
            "discretization check (sliding): {} — {}",
            c.status, c.message
        );
    }
    println!("times: sliding {sliding_time:.0} s, tied {tied_time:.0} s");
    let out = json!({
        "repeats": a.repeats,
        "elements": a.elements,
        "data_refinement": a.data_refinement,
        "discretization": a.discretization,
        "sliding": summary.parameters,
        "sliding_discretization": summary.discretization,
        "tied": tied_estimates,
        "wall_time_s": {"sliding": sliding_time, "tied": tied_time},
    });
    std::fs::write(
        a.out.join("campaign.json"),
        serde_json::to_string_pretty(&out)?,
    )?;
    Ok(())
}
