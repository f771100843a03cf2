//! The identification from recorded frames in the report (`[measurement] source = "frames"`):
//! what was read (files, pixel size, placement, loads), the force log with the chosen frames,
//! the integrated-DIC estimates with their intervals beside the DIC → FEMU start, the frames and
//! the grey-level residual.

use super::{esc, g, Html};
use crate::steps::frames::FramesRecord;
use crate::steps::identify::IdentificationSummary;
use crate::steps::images::ImageIdentificationSummary;
use std::path::Path;

/// Whether `dir` (`identify/GROUPING/`) holds an identification from recorded frames.
pub fn is_frames_route(dir: &Path, measurement: &Path) -> bool {
    dir.join("dic").join("summary.json").is_file() && measurement.join("frames.json").is_file()
}

/// The section of one grouping.
pub fn section(html: &mut Html, grouping: &str, dir: &Path, measurement: &Path) {
    let Some(record) = html.read::<FramesRecord>(&measurement.join("frames.json")) else {
        return;
    };
    let Some(idic) = html.read::<ImageIdentificationSummary>(&dir.join("summary.json")) else {
        return;
    };
    let dic: Option<IdentificationSummary> = html.read(&dir.join("dic").join("summary.json"));
    let weighted: Option<IdentificationSummary> =
        html.read(&dir.join("dic-weighted").join("summary.json"));
    let f = &record.frames;
    html.h3(&format!("{grouping}: integrated DIC from recorded frames"));
    html.p(&format!(
        "{} frames of {} x {} px{} at {} mm/px ({}), placed by {}; {} at {} N/mm, loads {} N/mm{}. \
         Integrated DIC over {} pixels of {} elements, started from the DIC → FEMU optimum of the \
         sequence's DIC; {:.1} s. {}",
        f.sources.len(),
        f.width,
        f.height,
        f.region.map_or(String::new(), |r| format!(
            " (the ultrasound region x {}..{}, y {}..{})",
            r.x0, r.x1, r.y0, r.y1
        )),
        g(f.pixel_size_mm),
        esc(&f.pixel_size_from),
        esc(&record.placement_from),
        esc(&record.test),
        g(record.test_force_n_per_mm),
        f.loads_n_per_mm.iter().map(|l| g(*l)).collect::<Vec<_>>().join(", "),
        f.force_log.as_ref().map_or(String::new(), |l| format!(
            " (from the force log {}, offset {} s)",
            esc(&l.path.display().to_string()),
            g(l.offset_s)
        )),
        idic.pixels,
        idic.elements,
        idic.wall_time_s,
        record
            .notes
            .iter()
            .chain(&idic.notes)
            .map(|n| esc(n))
            .collect::<Vec<_>>()
            .join(" ")
    ));
    let rows: Vec<Vec<String>> = idic
        .parameters
        .iter()
        .enumerate()
        .map(|(k, p)| {
            vec![
                format!(
                    "{} ({}){}",
                    p.name,
                    super::internal_unit(&p.name),
                    if p.seen { "" } else { " (not seen)" }
                ),
                format!("{} [{}, {}]", g(p.identified), g(p.ci95[0]), g(p.ci95[1])),
                format!("{:.1} %", 100.0 * p.relative_sd),
                dic.as_ref()
                    .and_then(|d| d.parameters.get(k))
                    .map_or("-".into(), |q| g(q.identified)),
                weighted
                    .as_ref()
                    .and_then(|d| d.parameters.get(k))
                    .map_or("-".into(), |q| {
                        format!("{} [{}, {}]", g(q.identified), g(q.ci95[0]), g(q.ci95[1]))
                    }),
            ]
        })
        .collect();
    html.table(
        &[
            "parameter (unit)",
            "I-DIC [95 % interval]",
            "relative sd",
            "DIC → FEMU (the start)",
            "DIC → weighted FEMU [95 % interval] (for comparison)",
        ],
        &rows,
    );
    let last = f.sources.len() - 1;
    for (path, caption) in [
        (
            measurement.join("force_log.png"),
            "Force log and the frames chosen.".to_string(),
        ),
        (
            measurement.join("frame_00.png"),
            "Unloaded frame as read.".to_string(),
        ),
        (
            measurement.join(format!("frame_{last:02}.png")),
            "Last frame as read.".to_string(),
        ),
        (
            dir.join("residual_after.png"),
            "Grey-level residual of the last load step at the I-DIC optimum.".to_string(),
        ),
        (
            dir.join("displacement_uy.png"),
            "Identified model: displacement uy over the unloaded frame.".to_string(),
        ),
    ] {
        if path.is_file() {
            html.figure(&path, &format!("{grouping}: {caption}"));
        }
    }
}
