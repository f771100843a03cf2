//! Interruption and failure keep the work (issue 28, item 3): Ctrl-C (SIGINT) or SIGTERM during
//! `femu identify`, `femu dic` or `femu convergence` stops the command within a second or two
//! (the Newton and DIC iterations check the stop request, `femu_mesh::stop`), with exit code
//! 130, the finished work kept and `summary.json` saying "interrupted"; a run killed outright
//! (SIGKILL, no chance to clean up) at any moment leaves no truncated CSV, JSON, PNG, VTU or deck
//! under its final name, because every output file is written under a temporary name and renamed
//! when complete (`femu_mesh::atomic`). `femu run` is covered in `run_folder.rs`. The moments
//! are drawn from a seeded generator, so a failure can be replayed.

#![cfg(unix)]

use femu_dic::lab::{self, Speckle};
use std::path::{Path, PathBuf};
use std::time::Duration;

mod common;
use common::{json, outputs_are_whole, scratch, signal_after, write, Stopped};

/// The longest a stopped command may take to end after the signal. The issue asks for "a
/// second or two"; measured 0.02–0.2 s on this 2-core machine (the stop is checked between
/// Newton and Gauss–Newton iterations, the longest unchecked piece is meshing a 12 000-quad
/// thigh, under a second).
const STOP_WITHIN: Duration = Duration::from_secs(2);

/// Seeded moments in `[lo, lo + span)` ms (xorshift64).
fn moments(seed: u64, n: usize, lo: u64, span: u64) -> Vec<Duration> {
    let mut x = seed;
    (0..n)
        .map(|_| {
            x ^= x << 13;
            x ^= x >> 7;
            x ^= x << 17;
            Duration::from_millis(lo + x % span)
        })
        .collect()
}

/// A stopped command ended as it should: stopped in time with 130 and an interrupted summary,
/// or finished before the signal (0); either way every file it left is whole.
fn check_stopped(what: &str, s: &Stopped, out: &Path) -> bool {
    eprintln!(
        "{what}: exit {:?}, {:?} after the signal",
        s.code, s.after_signal
    );
    assert!(
        matches!(s.code, Some(130) | Some(0)),
        "{what}: exit {:?}: {}",
        s.code,
        s.stderr
    );
    assert!(!s.stderr.contains("panicked"), "{what}: {}", s.stderr);
    if s.code == Some(130) {
        assert!(
            s.after_signal <= STOP_WITHIN,
            "{what}: stopped {:?} after the signal",
            s.after_signal
        );
        assert!(s.stderr.contains("interrupted"), "{what}: {}", s.stderr);
        let summary = json(&out.join("summary.json"));
        let said = summary["interrupted"].as_str().unwrap_or_default();
        assert!(!said.is_empty(), "{what}: summary.json: {summary}");
    }
    outputs_are_whole(out);
    s.code == Some(130)
}

/// A translated and stretched speckle pair large enough for the DIC to take a few seconds.
fn large_pair(dir: &Path) -> (PathBuf, PathBuf) {
    let s = Speckle::new(1400, 1100, 1.5, 7);
    let u = lab::affine([1.3, -0.6], [[0.004, 0.001], [0.0, -0.003]], [700.0, 550.0]);
    let (f, g) = (s.reference(), s.deformed(&u));
    let (pf, pg) = (dir.join("ref.png"), dir.join("def.png"));
    lab::quantize_8bit(&f).save_png(&pf).unwrap();
    lab::quantize_8bit(&g).save_png(&pg).unwrap();
    (pf, pg)
}

const CONVERGENCE: &str = r#"[convergence]
element_types = ["CPE4H", "CPE4"]
target_elements = [1500, 3000, 6000, 12000]
locking = false
"#;

#[test]
fn sigint_stops_convergence_keeping_its_finished_solves() {
    let dir = scratch("convergence");
    let study = write(&dir, "study.toml", CONVERGENCE);
    let mut stopped = 0;
    for (k, delay) in moments(0x9e37_79b9_7f4a_7c15, 3, 300, 3500)
        .into_iter()
        .enumerate()
    {
        let out = dir.join(format!("out{k}"));
        let args = [
            "convergence",
            study.to_str().unwrap(),
            "--out",
            out.to_str().unwrap(),
            "-q",
        ];
        let s = signal_after(&args, "INT", delay);
        if check_stopped(&format!("convergence at {delay:?}"), &s, &out) {
            stopped += 1;
            let summary = json(&out.join("summary.json"));
            assert_eq!(summary["status"], "interrupted");
            // Its finished solves, one row each.
            let said = summary["interrupted"].as_str().unwrap().to_string();
            let rows = std::fs::read_to_string(out.join("convergence.csv"))
                .unwrap()
                .lines()
                .count()
                - 1;
            assert!(said.contains(&format!("after {rows} solves")), "{said}");
        }
    }
    assert!(stopped > 0, "no moment fell inside the study");
}

#[test]
fn sigint_and_sigterm_stop_identify_keeping_its_finished_starts() {
    let dir = scratch("identify");
    let mut stopped = 0;
    for (k, delay) in moments(0x2545_f491_4f6c_dd1d, 3, 500, 4000)
        .into_iter()
        .enumerate()
    {
        let out = dir.join(format!("out{k}"));
        let args = [
            "identify",
            "--elements",
            "1500",
            "--starts",
            "2",
            "--repeat",
            "3",
            "--out",
            out.to_str().unwrap(),
            "-q",
        ];
        let signal = if k == 1 { "TERM" } else { "INT" };
        let s = signal_after(&args, signal, delay);
        if check_stopped(&format!("identify, SIG{signal} at {delay:?}"), &s, &out) {
            stopped += 1;
            // starts.csv holds what finished, when the identification had begun.
            let summary = json(&out.join("summary.json"));
            if summary["status"] == "interrupted" && summary["kept"][0] == "starts.csv" {
                assert!(out.join("starts.csv").is_file());
            }
        }
    }
    assert!(stopped > 0, "no moment fell inside the identification");
}

#[test]
fn sigint_stops_dic_within_two_seconds() {
    let dir = scratch("dic");
    let (f, g) = large_pair(&dir);
    let mut stopped = 0;
    // The correlation of this pair takes about a second in the test build: the moments fall
    // within it (a signal after it finds the outputs being written, exit 0).
    for (k, delay) in moments(0xd1b5_4a32_d192_ed03, 4, 100, 900)
        .into_iter()
        .enumerate()
    {
        let out = dir.join(format!("out{k}"));
        let args = [
            "dic",
            f.to_str().unwrap(),
            g.to_str().unwrap(),
            "--out",
            out.to_str().unwrap(),
            "-q",
        ];
        let s = signal_after(&args, "INT", delay);
        if check_stopped(&format!("dic at {delay:?}"), &s, &out) {
            stopped += 1;
            assert!(!out.join("field.csv").exists(), "no field was measured");
        }
    }
    assert!(stopped > 0, "no moment fell inside the correlation");
}

/// A design of many candidates: 3 tests x 4 sides x 7 window sizes, up to 3 per design (some
/// 8e4 designs to rank after the three solves).
const DESIGN: &str = "[model]
elements = 3000
[design]
max_measurements = 3
windows_mm = [[20.0, 20.0], [30.0, 20.0], [40.0, 20.0], [40.0, 30.0], [40.0, 40.0], [50.0, 40.0], [60.0, 40.0]]
";

#[test]
fn sigint_stops_design_keeping_its_finished_windows() {
    let dir = scratch("design");
    let study = write(&dir, "study.toml", DESIGN);
    let mut stopped = 0;
    for (k, delay) in moments(0xbb67_ae85_84ca_a73b, 3, 300, 3500)
        .into_iter()
        .enumerate()
    {
        let out = dir.join(format!("out{k}"));
        let args = [
            "design",
            study.to_str().unwrap(),
            "--out",
            out.to_str().unwrap(),
            "-q",
        ];
        let s = signal_after(&args, "INT", delay);
        if check_stopped(&format!("design at {delay:?}"), &s, &out) {
            stopped += 1;
            let summary = json(&out.join("summary.json"));
            assert_eq!(summary["status"], "interrupted");
            assert!(!out.join("designs.csv").exists(), "no ranking was finished");
            // The windows of the tests solved, one row each, as the summary says.
            if summary["kept"][0] == "candidates.csv" {
                let rows = std::fs::read_to_string(out.join("candidates.csv"))
                    .unwrap()
                    .lines()
                    .count()
                    - 1;
                let said = summary["interrupted"].as_str().unwrap();
                assert!(
                    rows > 0 && said.contains(&format!("the {rows} windows")),
                    "{said}"
                );
            }
        }
    }
    assert!(stopped > 0, "no moment fell inside the design");
}

/// SIGKILL gives no chance to clean up: what is left under a final name must still be whole.
#[test]
fn runs_killed_at_random_moments_leave_no_truncated_file() {
    let dir = scratch("killed");
    let study = write(
        &dir,
        "study.toml",
        "[model]\nelements = 1500\n[grid]\ncounts = [16, 16]\n[identification]\nstarts = 2\n",
    );
    let (f, g) = large_pair(&dir);
    let mut checked = 0;
    for (k, delay) in moments(0x853c_49e6_748f_ea9b, 6, 200, 5000)
        .into_iter()
        .enumerate()
    {
        let out = dir.join(format!("run{k}"));
        let s = signal_after(
            &[
                "run",
                study.to_str().unwrap(),
                "--out",
                out.to_str().unwrap(),
                "-q",
            ],
            "KILL",
            delay,
        );
        assert!(!s.stderr.contains("panicked"), "{}", s.stderr);
        checked += outputs_are_whole(&out);
    }
    for (k, delay) in moments(0x6a09_e667_f3bc_c908, 3, 1000, 2500)
        .into_iter()
        .enumerate()
    {
        let out = dir.join(format!("dic{k}"));
        let s = signal_after(
            &[
                "dic",
                f.to_str().unwrap(),
                g.to_str().unwrap(),
                "--out",
                out.to_str().unwrap(),
                "-q",
            ],
            "KILL",
            delay,
        );
        assert!(!s.stderr.contains("panicked"), "{}", s.stderr);
        checked += outputs_are_whole(&out);
    }
    // The kills landed while files were being written, not only before the first one.
    assert!(checked > 20, "only {checked} files were left to check");
}
