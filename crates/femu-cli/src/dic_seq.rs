//! `femu dic F0 F1 F2 ...`: DIC on a sequence of frames (`femu_dic::sequence::run_sequence`).
//! Thin glue: the arguments of `femu dic` made into a [`SequenceJob`].

use crate::dic_cmd::{parse_pair, DicArgs};
use anyhow::Result;
use femu_dic::sequence::{run_sequence, SequenceJob};

/// `femu dic` with more than two frames.
pub fn run(a: &DicArgs, quiet: bool) -> Result<()> {
    let origin = parse_pair("origin", &a.origin)?;
    let mut frames = vec![
        (a.reference.clone(), a.frame_ref),
        (a.deformed.clone(), a.frame_def),
    ];
    frames.extend(a.then.iter().map(|p| (p.clone(), 0)));
    let job = SequenceJob {
        frames,
        correlation: a.corr.spec()?,
        pixel_size: a.corr.pixel_size(None)?,
        origin_px: origin,
        x_left: a.x_left,
        y_up: a.y_up,
        grid_step_px: a.grid,
        out: a.out.clone(),
    };
    let show = |k: usize, n: usize| {
        if !quiet {
            eprintln!("increment {k}/{n} correlated");
        }
    };
    let r = run_sequence(&job, &show)?;
    if !quiet {
        for i in &r.increments {
            println!(
                "frames {} -> {}: element {} px, regularization {}, {} iterations{}, residual {:.2} % of the dynamic, {:.0} % of the elements trusted, mean increment ({:.2}, {:.2}) px, {:.2} s",
                i.from_frame,
                i.to_frame,
                i.element_size_px,
                i.regularization_px
                    .map_or("off".to_string(), |l| format!("{l} px")),
                i.iterations,
                if i.warm_start { " (warm start)" } else { "" },
                i.residual_percent_of_dynamic,
                100.0 * i.trusted_fraction,
                i.mean_u_px[0],
                i.mean_u_px[1],
                i.time_s
            );
        }
        println!(
            "composed: {} points in the reference, {} reach the last frame, {} trusted there; {:.2} s",
            r.points,
            r.points_reaching.last().copied().unwrap_or(0),
            r.points_trusted.last().copied().unwrap_or(0),
            r.wall_time_s
        );
        for w in &r.warnings {
            eprintln!("warning: {w}");
        }
        println!("results in {}", a.out.display());
    }
    Ok(())
}
