//! `femu batch`: a population of small cases (one template study, a table of per-case values)
//! run here with one case deliberately broken (it fails alone; `--resume` finishes it once its
//! file is fixed, leaving the others as they were), bad tables refused before anything runs,
//! and the same population run as a Slurm job array on the single-node Slurm `.ci/run` starts
//! (skipped with a message where no Slurm answers), its failed task resubmitted alone, its
//! collected table equal to the local run's.

use femu_batch::{BatchStatus, CaseState};
use std::path::{Path, PathBuf};
use std::process::Output;
use std::time::{Duration, Instant};

mod common;
use common::{femu, scratch, write, BATCH_TEMPLATE};

/// Six cases: four subjects, two of them with both legs (each its own fat and quadriceps C10,
/// the virtual experiment's truth, and its own noise seed); case s03-L measured from a file
/// whose third line is not a number.
const CASES: &str = "\
case,subject,side,materials.fat.c10_kpa,materials.quadriceps.c10_kpa,identification.seed,measurement.source,measurement.file
s01-L,s01,left,0.8,1.75,1,,
s01-R,s01,right,0.85,1.8,2,,
s02-L,s02,left,0.7,1.6,3,,
s02-R,s02,right,0.72,1.65,4,,
s03-L,s03,left,1.0,2.0,5,file,fields/s03-L.csv
s04-L,s04,left,0.9,1.9,6,,
";

const BATCH: &str = "template = \"study.toml\"\ncases = \"cases.csv\"\n\n[slurm]\ncpus_per_task = 1\nmem = \"1G\"\ntime = \"00:20:00\"\n";

/// A batch folder's inputs in `dir`: the template, the table, the broken field file.
fn inputs(dir: &Path, cases: &str) -> PathBuf {
    write(dir, "study.toml", BATCH_TEMPLATE);
    write(dir, "cases.csv", cases);
    std::fs::create_dir_all(dir.join("fields")).unwrap();
    write(dir, "fields/s03-L.csv", "x,y,ux,uy\n0,0,0,0\n1,1,nan,0\n");
    write(dir, "batch.toml", BATCH)
}

fn path(p: &Path) -> &str {
    p.to_str().unwrap()
}

/// `femu batch run BATCH --out OUT ARGS...`.
fn batch_run(batch: &Path, out: &Path, args: &[&str]) -> Output {
    let mut all = vec!["batch", "run", path(batch), "--out", path(out)];
    all.extend_from_slice(args);
    femu(&all)
}

fn stderr(o: &Output) -> String {
    String::from_utf8_lossy(&o.stderr).into_owned()
}

fn status(out: &Path) -> BatchStatus {
    let o = femu(&["batch", "status", path(out), "--json"]);
    assert!(o.status.success(), "{}", stderr(&o));
    serde_json::from_slice(&o.stdout).unwrap()
}

/// `femu batch collect OUT`; returns population.csv.
fn collect(out: &Path) -> String {
    let o = femu(&["batch", "collect", path(out), "--quiet"]);
    assert!(o.status.success(), "{}", stderr(&o));
    std::fs::read_to_string(out.join("collect/population.csv")).unwrap()
}

/// The fixed field of s03-L: a valid measured field on the same grid (s01-L's measurement).
fn fix_broken_case(dir: &Path, done_case: &Path) {
    std::fs::copy(
        done_case.join("measurement/measured.csv"),
        dir.join("fields/s03-L.csv"),
    )
    .unwrap();
}

#[test]
fn a_broken_case_fails_alone_and_resume_finishes_it() {
    let dir = scratch("local");
    let batch = inputs(&dir, CASES);
    let out = dir.join("out");
    let o = batch_run(&batch, &out, &["--jobs", "2", "--quiet"]);
    // The batch reports the failure (non-zero exit) and names the case and the bad line.
    assert!(!o.status.success());
    let err = stderr(&o);
    assert!(err.contains("1 of 6 cases failed (s03-L)"), "{err}");
    let st = status(&out);
    for c in &st.cases {
        let expected = if c.name == "s03-L" {
            CaseState::Failed
        } else {
            CaseState::Done
        };
        assert_eq!(c.state, expected, "{}: {:?}", c.name, c.error);
    }
    let why = st.cases[4].error.as_deref().unwrap();
    assert!(
        why.contains("s03-L.csv:3") && why.contains("not finite"),
        "{why}"
    );
    // Each case identified its own truth (its row's C10 of the fat): within four predicted
    // standard deviations plus 1e-4, as the run test asks of one study — the per-case values
    // reached the cases, not the template's.
    for (case, c10_kpa) in [("s01-L", 0.8), ("s02-L", 0.7), ("s04-L", 0.9)] {
        let p = std::fs::read_to_string(
            out.join("cases")
                .join(case)
                .join("identify/grouped/parameters.csv"),
        )
        .unwrap();
        let row: Vec<&str> = p
            .lines()
            .find(|l| l.starts_with("C10_FAT,"))
            .unwrap()
            .split(',')
            .collect();
        let (reference, identified, sd) = (
            row[1].parse::<f64>().unwrap(),
            row[2].parse::<f64>().unwrap(),
            row[4].parse::<f64>().unwrap(),
        );
        // The row's kPa as the report's MPa: equal up to the rounding of the unit change.
        assert!(
            (reference / (c10_kpa * 1e-3) - 1.0).abs() < 1e-12,
            "{case}: {reference}"
        );
        let e = (identified / reference - 1.0).abs();
        assert!(e <= 4.0 * sd + 1e-4, "{case}: error {e}, sd {sd}");
    }
    // Fixed, the batch resumes: only s03-L runs; the others' records are untouched.
    let records = |names: &[&str]| -> Vec<String> {
        names
            .iter()
            .map(|n| std::fs::read_to_string(out.join("cases").join(n).join("case.json")).unwrap())
            .collect()
    };
    let others = ["s01-L", "s01-R", "s02-L", "s02-R", "s04-L"];
    let before = records(&others);
    fix_broken_case(&dir, &out.join("cases/s01-L"));
    let o = batch_run(&batch, &out, &["--jobs", "2", "--resume"]);
    assert!(o.status.success(), "{}", stderr(&o));
    assert!(
        stderr(&o).contains("--resume: 1 cases to run, 5 left as they are"),
        "{}",
        stderr(&o)
    );
    assert_eq!(records(&others), before);
    let st = status(&out);
    assert!(st.cases.iter().all(|c| c.state == CaseState::Done), "{st}");
    // Nothing left to do: a second --resume runs nothing.
    let o = batch_run(&batch, &out, &["--resume", "--quiet"]);
    assert!(o.status.success(), "{}", stderr(&o));
    assert_eq!(records(&others), before);
    // Gathered: one row per case and parameter (eight free parameters with the seed's
    // grouping), the report with its figures embedded and nothing fetched from elsewhere.
    let table = collect(&out);
    let lines: Vec<&str> = table.lines().collect();
    assert!(
        lines[0].starts_with(
            "case,subject,side,grouping,parameter,kind,tissue,unit,identified,ci95_low,ci95_high"
        ),
        "{}",
        lines[0]
    );
    assert_eq!(lines.len(), 1 + 6 * 8);
    let html = std::fs::read_to_string(out.join("collect/report.html")).unwrap();
    // Two distributions (C10, D), eight forest plots (one per parameter), four subjects.
    assert_eq!(
        html.matches("src=\"data:image/png;base64,").count(),
        2 + 8 + 4
    );
    assert!(!html.contains("src=\"http"));
    assert!(html.contains("Every case is done."));
}

#[test]
fn bad_cases_are_refused_before_anything_runs() {
    let dir = scratch("bad");
    let cases = "case,subject,materials.fat.c10_kpa,identification.seed,labels.image\n\
                 a,s01,0.8,1,\nb,s02,-0.5,2,\nc,s03,0.8,two,\nd,s04,0.8,4,mri/missing.png\na,s05,0.8,5,\n";
    let batch = inputs(&dir, cases);
    let out = dir.join("out");
    let o = batch_run(&batch, &out, &[]);
    assert!(!o.status.success());
    let err = stderr(&o);
    assert!(
        err.contains("4 of 5 cases cannot run (nothing was run)"),
        "{err}"
    );
    for says in [
        "case b (cases.csv line 3): [materials.fat] c10_kpa",
        "(the value of column materials.fat.c10_kpa)",
        "case c (cases.csv line 4): column identification.seed = \"two\"",
        "case d (cases.csv line 5)",
        "case a (cases.csv line 6): the name is taken by cases.csv line 2",
    ] {
        assert!(err.contains(says), "`{says}` not in:\n{err}");
    }
    assert!(!out.exists(), "nothing may be written");
    // A folder that holds a batch is not run into again without --resume.
    let good = inputs(&dir, "case,materials.fat.c10_kpa\nonly,0.8\n");
    std::fs::create_dir_all(&out).unwrap();
    std::fs::write(out.join("batch.json"), "{}").unwrap();
    let o = batch_run(&good, &out, &[]);
    assert!(!o.status.success());
    assert!(
        stderr(&o).contains("holds a batch already"),
        "{}",
        stderr(&o)
    );
}

/// The state of case `name` in `st`.
fn state_of(st: &BatchStatus, name: &str) -> CaseState {
    st.cases.iter().find(|c| c.name == name).unwrap().state
}

/// Waits until `cond` holds of the batch's status (at most `limit`).
fn wait_until(out: &Path, limit: Duration, cond: impl Fn(&BatchStatus) -> bool) -> BatchStatus {
    let t0 = Instant::now();
    loop {
        if out.join("batch.json").is_file() {
            let st = status(out);
            if cond(&st) {
                return st;
            }
            assert!(t0.elapsed() < limit, "not reached in {limit:?}:\n{st}");
        }
        std::thread::sleep(Duration::from_millis(100));
    }
}

#[test]
fn a_stopped_batch_keeps_its_cases_and_resume_finishes_it() {
    let dir = scratch("stop");
    let cases = "case,materials.fat.c10_kpa,identification.seed\na,0.8,1\nb,0.9,2\nc,1.0,3\n";
    let batch = inputs(&dir, cases);
    let out = dir.join("out");
    let runner = std::process::Command::new(env!("CARGO_BIN_EXE_femu"))
        .args([
            "batch",
            "run",
            path(&batch),
            "--out",
            path(&out),
            "--jobs",
            "1",
            "--quiet",
        ])
        .stderr(std::process::Stdio::piped())
        .spawn()
        .unwrap();
    // Stopped (SIGTERM, as Ctrl-C) while its first case runs.
    wait_until(&out, Duration::from_secs(120), |st| {
        state_of(st, "a") == CaseState::Running
    });
    let kill = std::process::Command::new("kill")
        .args(["-TERM", &runner.id().to_string()])
        .status()
        .unwrap();
    assert!(kill.success());
    let o = runner.wait_with_output().unwrap();
    assert!(!o.status.success(), "a stopped batch is not a success");
    assert!(stderr(&o).contains("--resume"), "{}", stderr(&o));
    let st = status(&out);
    // The running case stopped cleanly (or had just finished), the others never started;
    // nothing is failed or lost.
    assert!(
        matches!(state_of(&st, "a"), CaseState::Interrupted | CaseState::Done),
        "{st}"
    );
    assert_eq!(state_of(&st, "c"), CaseState::Pending, "{st}");
    assert!(
        !st.cases.iter().any(|c| matches!(
            c.state,
            CaseState::Failed | CaseState::Lost | CaseState::Running
        )),
        "{st}"
    );
    let o = batch_run(&batch, &out, &["--resume", "--quiet"]);
    assert!(o.status.success(), "{}", stderr(&o));
    assert!(status(&out)
        .cases
        .iter()
        .all(|c| c.state == CaseState::Done));
}

/// Whether a Slurm with an idle node answers here (`.ci/slurm/start.sh` starts one).
fn slurm_ready() -> bool {
    std::process::Command::new("sinfo")
        .args(["-h", "-o", "%T"])
        .output()
        .is_ok_and(|o| {
            o.status.success()
                && String::from_utf8_lossy(&o.stdout)
                    .lines()
                    .any(|l| l.trim() == "idle" || l.trim() == "mixed")
        })
}

/// Waits until no case of the batch in `out` is queued or running (at most `limit`).
fn wait_for(out: &Path, limit: Duration) -> BatchStatus {
    let t0 = Instant::now();
    loop {
        let st = status(out);
        if !st
            .cases
            .iter()
            .any(|c| matches!(c.state, CaseState::Queued | CaseState::Running))
        {
            return st;
        }
        assert!(
            t0.elapsed() < limit,
            "the array did not finish in {limit:?}:\n{st}"
        );
        std::thread::sleep(Duration::from_secs(1));
    }
}

#[test]
fn a_slurm_array_runs_the_cases_and_collects_the_local_table() {
    if !slurm_ready() {
        eprintln!("skipped: no Slurm answers here (sinfo shows no idle node; .ci/run starts one with .ci/slurm/start.sh)");
        return;
    }
    // Five cases, s03-L broken: four to completion in the first array, s03-L resubmitted alone.
    let cases: String = CASES
        .lines()
        .filter(|l| !l.starts_with("s02-R"))
        .map(|l| format!("{l}\n"))
        .collect();
    let dir = scratch("slurm");
    let batch = inputs(&dir, &cases);
    let out = dir.join("slurm");
    // --dry-run prints the script and submits nothing.
    let o = batch_run(&batch, &out, &["--slurm", "--dry-run", "--quiet"]);
    assert!(o.status.success(), "{}", stderr(&o));
    let script = String::from_utf8_lossy(&o.stdout);
    assert!(
        script.contains("#SBATCH --array=0-4\n") && script.contains("#SBATCH --mem=1G\n"),
        "{script}"
    );
    assert!(
        script.contains("cases=(s01-L s01-R s02-L s03-L s04-L)"),
        "{script}"
    );
    assert!(!out.exists());
    let o = batch_run(&batch, &out, &["--slurm", "--quiet"]);
    assert!(o.status.success(), "{}", stderr(&o));
    let st = wait_for(&out, Duration::from_secs(600));
    for c in &st.cases {
        let expected = if c.name == "s03-L" {
            CaseState::Failed
        } else {
            CaseState::Done
        };
        assert_eq!(c.state, expected, "{}: {:?}\n{st}", c.name, c.error);
        assert!(
            c.slurm.as_deref().is_some_and(|s| s.contains(&format!(
                "_{}",
                ["s01-L", "s01-R", "s02-L", "s03-L", "s04-L"]
                    .iter()
                    .position(|n| *n == c.name)
                    .unwrap()
            ))),
            "{c:?}"
        );
    }
    // Fixed, --resume resubmits the failed task alone.
    fix_broken_case(&dir, &out.join("cases/s01-L"));
    let o = batch_run(&batch, &out, &["--slurm", "--resume", "--quiet"]);
    assert!(o.status.success(), "{}", stderr(&o));
    let jobs: femu_batch::slurm::Submissions =
        serde_json::from_str(&std::fs::read_to_string(out.join("slurm/jobs.json")).unwrap())
            .unwrap();
    assert_eq!(jobs.submissions.len(), 2);
    assert_eq!(jobs.submissions[1].cases, vec!["s03-L".to_string()]);
    let st = wait_for(&out, Duration::from_secs(300));
    assert!(st.cases.iter().all(|c| c.state == CaseState::Done), "{st}");
    let from_slurm = collect(&out);
    // The same cases run here give the same table, to the last digit: each case is the same
    // deterministic computation on one thread (Slurm's one CPU per task; two local jobs on two
    // cores give each case one thread too).
    let local = dir.join("local");
    let o = batch_run(&batch, &local, &["--jobs", "2", "--quiet"]);
    assert!(o.status.success(), "{}", stderr(&o));
    let from_here = collect(&local);
    assert_eq!(from_slurm.lines().count(), 1 + 5 * 8);
    assert_eq!(from_slurm, from_here);
}

#[test]
fn a_cancelled_slurm_task_is_lost_and_resubmitted() {
    if !slurm_ready() {
        eprintln!("skipped: no Slurm answers here (sinfo shows no idle node; .ci/run starts one with .ci/slurm/start.sh)");
        return;
    }
    let dir = scratch("cancel");
    let batch = inputs(&dir, "case,materials.fat.c10_kpa\nonly,0.8\n");
    // The task waits for `go` before femu starts: it is cancelled while it waits.
    let go = dir.join("go");
    let text = format!(
        "{BATCH}setup = [\"while [ ! -e {} ]; do sleep 0.2; done\"]\n",
        go.display()
    );
    std::fs::write(&batch, text).unwrap();
    let out = dir.join("out");
    let o = batch_run(&batch, &out, &["--slurm", "--quiet"]);
    assert!(o.status.success(), "{}", stderr(&o));
    wait_until(&out, Duration::from_secs(120), |st| {
        state_of(st, "only") == CaseState::Running
    });
    let jobs: femu_batch::slurm::Submissions =
        serde_json::from_str(&std::fs::read_to_string(out.join("slurm/jobs.json")).unwrap())
            .unwrap();
    let job = &jobs.submissions[0].job_id;
    assert!(std::process::Command::new("scancel")
        .arg(job)
        .status()
        .unwrap()
        .success());
    // Slurm ended the task before it could record anything: lost, with Slurm's state and the
    // task's log named.
    let st = wait_until(&out, Duration::from_secs(120), |st| {
        state_of(st, "only") == CaseState::Lost
    });
    let why = st.cases[0].error.as_deref().unwrap();
    assert!(
        why.contains("CANCELLED") && why.contains(&format!("{job}_0.out")),
        "{why}"
    );
    std::fs::write(&go, "").unwrap();
    let o = batch_run(&batch, &out, &["--slurm", "--resume", "--quiet"]);
    assert!(o.status.success(), "{}", stderr(&o));
    let st = wait_for(&out, Duration::from_secs(300));
    assert_eq!(state_of(&st, "only"), CaseState::Done, "{st}");
}
