//! The acceptance campaign of the identification from images (issue 25): simulated B-mode
//! images of the built-in thigh (compression anterior, probe anterior 40 x 40 mm, D of ischio,
//! sartorius and gracilis grouped), rendered from a mesh `render_refine` times finer than the
//! one identified and decorrelated between load steps, over several scatterer seeds and
//! frequencies; each realization identified by integrated DIC and by the DIC → FEMU route on
//! the same images, side by side.
//!
//! ```sh
//! cargo run --release -p femu-study --example idic_campaign -- \
//!     --realizations 10 --frequencies 9,11 --elements 4000 --out out/idic_campaign
//! ```
//!
//! Writes per realization the measurement, `dic/` (DIC → FEMU) and `idic/` folders, and
//! `campaign.csv` (one row per parameter and realization: errors, intervals, coverage),
//! `campaign.json` (the summary: errors per parameter, coverage, error ratio, times).

use anyhow::{bail, Context, Result};
use femu_study::progress::Notes;
use femu_study::steps::images::{
    identify_image_measurement, identify_images, read_sequence, ImageRouteOptions,
};
use femu_study::steps::parameters::IdentificationInputs;
use femu_study::steps::ultrasound::{sim, SimInputs, SimOptions};
use serde::Serialize;
use std::io::Write;
use std::path::PathBuf;
use std::time::Instant;

struct Args {
    realizations: usize,
    frequencies: Vec<f64>,
    elements: usize,
    steps: usize,
    first_seed: u64,
    render_refine: usize,
    decorrelation: f64,
    out: PathBuf,
    /// Only the integrated DIC, on the frames of an earlier run's realization folder.
    idic_only: Option<PathBuf>,
}

fn args() -> Result<Args> {
    let mut a = Args {
        realizations: 10,
        frequencies: vec![9.0, 11.0],
        elements: 4000,
        steps: 4,
        first_seed: 1,
        render_refine: 2,
        decorrelation: 0.05,
        out: PathBuf::from("out/idic_campaign"),
        idic_only: None,
    };
    let mut it = std::env::args().skip(1);
    while let Some(k) = it.next() {
        let v = it.next().with_context(|| format!("{k} needs a value"))?;
        match k.as_str() {
            "--realizations" => a.realizations = v.parse()?,
            "--frequencies" => {
                a.frequencies = v.split(',').map(|x| x.parse()).collect::<Result<_, _>>()?
            }
            "--elements" => a.elements = v.parse()?,
            "--steps" => a.steps = v.parse()?,
            "--first-seed" => a.first_seed = v.parse()?,
            "--render-refine" => a.render_refine = v.parse()?,
            "--decorrelation" => a.decorrelation = v.parse()?,
            "--out" => a.out = PathBuf::from(v),
            "--idic-only" => a.idic_only = Some(PathBuf::from(v)),
            other => bail!("unknown option {other}"),
        }
    }
    Ok(a)
}

/// One (parameter, realization) pair.
#[derive(Debug, Clone, Serialize)]
struct Row {
    realization: usize,
    seed: u64,
    frequency_mhz: f64,
    parameter: String,
    reference: f64,
    idic: f64,
    idic_error: f64,
    idic_sd: f64,
    idic_sd_statistical: f64,
    idic_shift: f64,
    idic_covered: bool,
    idic_seen: bool,
    dic: f64,
    dic_error: f64,
    dic_sd: f64,
    dic_covered: bool,
    weighted: f64,
    weighted_error: f64,
    weighted_sd: f64,
    weighted_covered: bool,
}

/// One realization's times (s).
#[derive(Debug, Clone, Serialize)]
struct Times {
    realization: usize,
    render_and_dic: f64,
    dic: f64,
    femu: f64,
    femu_weighted: f64,
    idic_identification: f64,
    idic_discretization: f64,
    idic_total: f64,
    dic_route: f64,
    all_routes: f64,
}

/// The image route's options for `study`, with overrides for exploration: `IDIC_PAIRING=consecutive`,
/// `IDIC_LOCAL_NORM=4` (0: none),
/// `IDIC_SCALES=4,2,1,0`, `IDIC_BAND=64` (0: one band), `IDIC_BLOCK=32`, `IDIC_MESH_CORRECTION=1`;
/// with `--idic-only`, `IDIC_START=v1,v2,...` adds a start and `IDIC_NO_DIC_START=1` drops the
/// DIC optima.
fn route(study: &femu_study::schema::Study) -> Result<ImageRouteOptions> {
    let mut r = ImageRouteOptions::for_study(study);
    if let Ok(v) = std::env::var("IDIC_PAIRING") {
        r.correlation.pairing = v.parse().unwrap_or(femu_identify::idic::Pairing::Reference);
    }
    if let Ok(v) = std::env::var("IDIC_SCALES") {
        r.scales_px = v.split(',').map(|x| x.parse()).collect::<Result<_, _>>()?;
    }
    if let Ok(v) = std::env::var("IDIC_BAND") {
        let b: usize = v.parse()?;
        r.correlation.pixels.band_px = (b > 0).then_some(b);
    }
    if let Ok(v) = std::env::var("IDIC_BLOCK") {
        r.correlation.pixels.block_px = v.parse()?;
    }
    r.mesh_correction = std::env::var("IDIC_MESH_CORRECTION").is_ok();
    // `IDIC_LOCAL_NORM=0`: the grey levels as recorded.
    if let Ok(v) = std::env::var("IDIC_LOCAL_NORM") {
        let w: f64 = v.parse()?;
        r.correlation.local_normalization_px = (w > 0.0).then_some(w);
    }
    Ok(r)
}

fn main() -> Result<()> {
    let a = args()?;
    std::fs::create_dir_all(&a.out)?;
    if let Some(dir) = &a.idic_only {
        let text = std::fs::read_to_string(dir.join("measurement/study.toml"))?;
        let mut study = femu_study::schema::parse(&text, dir)?;
        // As in `identify_image_measurement`: the two DIC -> FEMU optima, no other start.
        study.identification.starts = 0;
        if let Ok(v) = std::env::var("IDIC_STARTS") {
            study.identification.starts = v.parse()?;
        }
        let seq = read_sequence(&dir.join("measurement"))?;
        let mut extra = Vec::new();
        // `IDIC_START=v1,v2,...` (model units, one per free parameter): one more start.
        if let Ok(v) = std::env::var("IDIC_START") {
            extra.push(
                v.split(',')
                    .map(|x| x.parse())
                    .collect::<Result<Vec<f64>, _>>()?,
            );
        }
        for route in ["dic", "dic-weighted"] {
            if std::env::var("IDIC_NO_DIC_START").is_ok() {
                break;
            }
            if let Ok(t) =
                std::fs::read_to_string(dir.join("identify").join(route).join("summary.json"))
            {
                let s: serde_json::Value = serde_json::from_str(&t)?;
                let theta: Vec<f64> = s["parameters"]
                    .as_array()
                    .context("parameters")?
                    .iter()
                    .map(|p| p["identified"].as_f64().unwrap_or(f64::NAN))
                    .collect();
                extra.push(theta);
            }
        }
        identify_images(
            &IdentificationInputs::of(&study),
            true,
            &seq,
            true,
            extra,
            &route(&study)?,
            &a.out,
            &Notes,
        )?;
        return Ok(());
    }
    let mut rows = Vec::new();
    let mut times = Vec::new();
    for r in 0..a.realizations {
        let seed = a.first_seed + r as u64;
        let f = a.frequencies[r % a.frequencies.len()];
        let dir = a.out.join(format!("r{r:02}_f{f}_s{seed}"));
        let text = format!(
            "[model]\nelements = {}\n[[test]]\nkind = \"compression\"\nside = \"anterior\"\nforce_n_per_mm = 0.1\n\
             [measurement]\nsource = \"ultrasound\"\n[probe]\nside = \"anterior\"\nwidth_mm = 40\ndepth_mm = 40\n\
             [ultrasound]\nfrequency_mhz = {f}\nseed = {seed}\nrender_refine = {}\ndecorrelation = {}\n\
             [identification]\ngrouped = true\nstarts = 5\nseed = {seed}\n",
            a.elements, a.render_refine, a.decorrelation
        );
        let mut study = femu_study::schema::parse(&text, &dir)?;
        // `IDIC_LOCAL_NORM` acts on the full campaign too.
        study.identification.image_normalization_px =
            route(&study)?.correlation.local_normalization_px;
        std::fs::create_dir_all(dir.join("measurement"))?;
        std::fs::write(dir.join("measurement/study.toml"), &text)?;
        eprintln!(
            "=== realization {r}: {f} MHz, seed {seed} -> {}",
            dir.display()
        );
        let t = Instant::now();
        let s = sim(
            SimInputs::of(&study),
            &SimOptions {
                steps: a.steps,
                ..SimOptions::default()
            },
            &dir.join("measurement"),
            &Notes,
        )?;
        let render_and_dic = t.elapsed().as_secs_f64();
        let t = Instant::now();
        let (dic, weighted, idic) = identify_image_measurement(
            &IdentificationInputs::of(&study),
            &study.measurements[0],
            true,
            &s,
            &dir.join("identify"),
            &Notes,
        )?;
        let all = t.elapsed().as_secs_f64();
        for ((p, q), w) in idic
            .parameters
            .iter()
            .zip(&dic.parameters)
            .zip(&weighted.parameters)
        {
            let reference = p.reference.context("simulated")?;
            let covers = |ci: [f64; 2]| ci[0] <= reference && reference <= ci[1];
            rows.push(Row {
                realization: r,
                seed,
                frequency_mhz: f,
                parameter: p.name.clone(),
                reference,
                idic: p.identified,
                idic_error: p.relative_error.unwrap_or(f64::NAN),
                idic_sd: p.relative_sd,
                idic_sd_statistical: p.sd_statistical,
                idic_shift: p.discretization_bias.unwrap_or(f64::NAN),
                idic_covered: covers(p.ci95),
                idic_seen: p.seen,
                dic: q.identified,
                dic_error: q.relative_error.unwrap_or(f64::NAN),
                dic_sd: q.relative_sd,
                dic_covered: covers(q.ci95),
                weighted: w.identified,
                weighted_error: w.relative_error.unwrap_or(f64::NAN),
                weighted_sd: w.relative_sd,
                weighted_covered: covers(w.ci95),
            });
        }
        times.push(Times {
            realization: r,
            render_and_dic,
            dic: s.summary.timings_s.dic,
            femu: dic.wall_time_s,
            femu_weighted: weighted.wall_time_s,
            idic_identification: idic.identification_s,
            idic_discretization: idic.discretization_s,
            idic_total: idic.wall_time_s,
            dic_route: s.summary.timings_s.dic + dic.wall_time_s,
            all_routes: all,
        });
        write_outputs(&a, &rows, &times)?;
    }
    Ok(())
}

/// `campaign.csv` and `campaign.json` (rewritten after every realization: a long run that
/// stops keeps what it finished).
fn write_outputs(a: &Args, rows: &[Row], times: &[Times]) -> Result<()> {
    let mut w = std::io::BufWriter::new(std::fs::File::create(a.out.join("campaign.csv"))?);
    writeln!(
        w,
        "realization,seed,frequency_mhz,parameter,reference,idic,idic_error,idic_sd,idic_sd_statistical,idic_shift,idic_covered,idic_seen,dic,dic_error,dic_sd,dic_covered,weighted,weighted_error,weighted_sd,weighted_covered"
    )?;
    for r in rows {
        writeln!(
            w,
            "{},{},{},{},{:.6e},{:.6e},{:.6e},{:.6e},{:.6e},{:.6e},{},{},{:.6e},{:.6e},{:.6e},{},{:.6e},{:.6e},{:.6e},{}",
            r.realization,
            r.seed,
            r.frequency_mhz,
            r.parameter,
            r.reference,
            r.idic,
            r.idic_error,
            r.idic_sd,
            r.idic_sd_statistical,
            r.idic_shift,
            r.idic_covered,
            r.idic_seen,
            r.dic,
            r.dic_error,
            r.dic_sd,
            r.dic_covered,
            r.weighted,
            r.weighted_error,
            r.weighted_sd,
            r.weighted_covered
        )?;
    }
    w.flush()?;
    let names: Vec<String> = {
        let mut v: Vec<String> = rows.iter().map(|r| r.parameter.clone()).collect();
        v.dedup();
        v.truncate(rows.iter().filter(|r| r.realization == 0).count());
        v
    };
    let per_parameter: Vec<serde_json::Value> = names
        .iter()
        .map(|n| {
            let sel: Vec<&Row> = rows.iter().filter(|r| &r.parameter == n).collect();
            let k = sel.len() as f64;
            let mean_abs =
                |f: &dyn Fn(&Row) -> f64| sel.iter().map(|r| f(r).abs()).sum::<f64>() / k;
            let max_abs =
                |f: &dyn Fn(&Row) -> f64| sel.iter().map(|r| f(r).abs()).fold(0.0, f64::max);
            serde_json::json!({
                "parameter": n,
                "idic_mean_abs_error": mean_abs(&|r| r.idic_error),
                "idic_max_abs_error": max_abs(&|r| r.idic_error),
                "dic_mean_abs_error": mean_abs(&|r| r.dic_error),
                "dic_max_abs_error": max_abs(&|r| r.dic_error),
                "weighted_mean_abs_error": mean_abs(&|r| r.weighted_error),
                "weighted_max_abs_error": max_abs(&|r| r.weighted_error),
                "weighted_coverage": sel.iter().filter(|r| r.weighted_covered).count() as f64 / k,
                "idic_coverage": sel.iter().filter(|r| r.idic_covered).count() as f64 / k,
                "dic_coverage": sel.iter().filter(|r| r.dic_covered).count() as f64 / k,
                "idic_mean_sd": sel.iter().map(|r| r.idic_sd).sum::<f64>() / k,
                "idic_seen": sel.iter().filter(|r| r.idic_seen).count(),
            })
        })
        .collect();
    let n = rows.len() as f64;
    let mean = |f: &dyn Fn(&Times) -> f64| times.iter().map(f).sum::<f64>() / times.len() as f64;
    let summary = serde_json::json!({
        "realizations": times.len(),
        "idic_coverage_all": rows.iter().filter(|r| r.idic_covered).count() as f64 / n,
        "dic_coverage_all": rows.iter().filter(|r| r.dic_covered).count() as f64 / n,
        "weighted_coverage_all": rows.iter().filter(|r| r.weighted_covered).count() as f64 / n,
        "per_parameter": per_parameter,
        "mean_time_s": {
            "idic_total": mean(&|t| t.idic_total),
            "idic_identification": mean(&|t| t.idic_identification),
            "idic_discretization": mean(&|t| t.idic_discretization),
            "dic_route": mean(&|t| t.dic_route),
            "femu_weighted": mean(&|t| t.femu_weighted),
            "render_and_dic": mean(&|t| t.render_and_dic),
        },
        "times": times,
    });
    std::fs::write(
        a.out.join("campaign.json"),
        serde_json::to_string_pretty(&summary)?,
    )?;
    Ok(())
}
