//! Helpers shared by the CLI's integration tests: run the `femu` binary, make a scratch folder.
#![allow(dead_code)] // each test binary uses its own subset

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

/// Runs `femu ARGS...` and returns its output (status, stdout, stderr).
pub fn femu(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_femu"))
        .args(args)
        .output()
        .expect("the femu binary runs")
}

/// An empty scratch folder named after the test binary, the process and `name`; removed when
/// the test that made it passes (kept when it fails, for a look at what the run wrote).
pub fn scratch(name: &str) -> Scratch {
    let dir = std::env::temp_dir().join(format!(
        "femu-{}-{}-{name}",
        env!("CARGO_CRATE_NAME"),
        std::process::id()
    ));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    Scratch(dir)
}

/// A scratch folder that removes itself when dropped outside a panic.
pub struct Scratch(PathBuf);

impl std::ops::Deref for Scratch {
    type Target = Path;
    fn deref(&self) -> &Path {
        &self.0
    }
}

impl AsRef<Path> for Scratch {
    fn as_ref(&self) -> &Path {
        &self.0
    }
}

impl AsRef<std::ffi::OsStr> for Scratch {
    fn as_ref(&self) -> &std::ffi::OsStr {
        self.0.as_os_str()
    }
}

impl Drop for Scratch {
    fn drop(&mut self) {
        if !std::thread::panicking() {
            let _ = std::fs::remove_dir_all(&self.0);
        }
    }
}

/// Writes `text` to `dir/name` and returns the path.
pub fn write(dir: &Path, name: &str, text: &str) -> PathBuf {
    let p = dir.join(name);
    std::fs::write(&p, text).unwrap();
    p
}

/// Parses a JSON file.
pub fn json(path: &Path) -> serde_json::Value {
    serde_json::from_str(&std::fs::read_to_string(path).unwrap()).unwrap()
}

/// How a run stopped by a signal ended.
pub struct Stopped {
    /// The exit code (`None`: killed by the signal).
    pub code: Option<i32>,
    pub stderr: String,
    /// From the signal to the end of the process.
    pub after_signal: std::time::Duration,
}

/// `femu ARGS` started with stdout discarded and stderr piped (to be read while it runs).
fn spawn_femu(args: &[&str]) -> std::process::Child {
    use std::process::Stdio;
    Command::new(env!("CARGO_BIN_EXE_femu"))
        .args(args)
        .stdout(Stdio::null())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap()
}

/// Starts `femu ARGS`, sends `signal` (`INT`, `TERM`, `KILL`) after `delay` and waits for it.
pub fn signal_after(args: &[&str], signal: &str, delay: std::time::Duration) -> Stopped {
    let mut child = spawn_femu(args);
    // Read stderr while the process runs (a full pipe would block it).
    let mut pipe = child.stderr.take().unwrap();
    let reader = std::thread::spawn(move || {
        let mut s = String::new();
        let _ = std::io::Read::read_to_string(&mut pipe, &mut s);
        s
    });
    std::thread::sleep(delay);
    let sent = std::time::Instant::now();
    let _ = Command::new("kill")
        .args([&format!("-{signal}"), &child.id().to_string()])
        .status();
    let status = child.wait().unwrap();
    let after_signal = sent.elapsed();
    Stopped {
        code: status.code(),
        stderr: reader.join().unwrap(),
        after_signal,
    }
}

/// Starts `femu ARGS`, sends SIGINT as soon as a line of its stderr contains `line` (an event
/// of the run, not a moment: a loaded machine only makes the test slower), waits for the end and
/// returns (exit code, stderr). Panics with the stderr so far when the line has not come within
/// `timeout`.
pub fn interrupt_after_line(
    args: &[&str],
    line: &str,
    timeout: std::time::Duration,
) -> (Option<i32>, String) {
    use std::io::BufRead;
    let mut child = spawn_femu(args);
    let pipe = child.stderr.take().unwrap();
    let (tx, rx) = std::sync::mpsc::channel::<String>();
    let reader = std::thread::spawn(move || {
        for l in std::io::BufReader::new(pipe).lines().map_while(Result::ok) {
            if tx.send(l).is_err() {
                break;
            }
        }
    });
    let started = std::time::Instant::now();
    let mut stderr = String::new();
    loop {
        let left = timeout.saturating_sub(started.elapsed());
        match rx.recv_timeout(left) {
            Ok(l) => {
                let seen = l.contains(line);
                stderr.push_str(&l);
                stderr.push('\n');
                if seen {
                    break;
                }
            }
            Err(_) => {
                let _ = child.kill();
                panic!("no line with {line:?} within {timeout:?}; stderr:\n{stderr}");
            }
        }
    }
    let _ = Command::new("kill")
        .args(["-INT", &child.id().to_string()])
        .status();
    let status = child.wait().unwrap();
    reader.join().unwrap();
    stderr.extend(rx.try_iter().map(|l| l + "\n"));
    (status.code(), stderr)
}

/// Starts `femu ARGS`, sends SIGINT after `delay`, returns (exit code, stderr).
pub fn interrupt(args: &[&str], delay: std::time::Duration) -> (Option<i32>, String) {
    let s = signal_after(args, "INT", delay);
    (s.code, s.stderr)
}

/// The fields of a CSV row (commas inside double quotes do not split).
fn csv_fields(row: &str) -> usize {
    let mut quoted = false;
    1 + row
        .chars()
        .filter(|&c| {
            if c == '"' {
                quoted = !quoted;
            }
            c == ',' && !quoted
        })
        .count()
}

/// Every file under `dir` is whole under its final name: a CSV has a header and rows of its
/// width and ends with a newline, a JSON file parses, a PNG ends with its IEND chunk, a VTU
/// with `</VTKFile>`, a deck, matrix or HTML file with a newline or its closing tag. Temporary
/// files of a killed writer (`.NAME.PID.femu-tmp`) are not results and are skipped. Returns
/// the number of files checked.
pub fn outputs_are_whole(dir: &Path) -> usize {
    const IEND: [u8; 12] = [0, 0, 0, 0, b'I', b'E', b'N', b'D', 0xAE, 0x42, 0x60, 0x82];
    let mut checked = 0;
    let mut stack: Vec<PathBuf> = vec![dir.to_path_buf()];
    while let Some(d) = stack.pop() {
        let Ok(entries) = std::fs::read_dir(&d) else {
            continue;
        };
        for e in entries.flatten() {
            let p = e.path();
            let name = p.file_name().unwrap().to_string_lossy().into_owned();
            if p.is_dir() {
                stack.push(p);
                continue;
            }
            if name.ends_with(".femu-tmp") {
                continue;
            }
            let bytes = std::fs::read(&p).unwrap();
            let text = String::from_utf8_lossy(&bytes);
            let what = p.display();
            match p.extension().and_then(|x| x.to_str()).unwrap_or("") {
                "csv" => {
                    let mut rows = text.lines().filter(|l| !l.starts_with('#'));
                    let width = rows.next().map_or(0, csv_fields);
                    assert!(width > 0, "{what}: no header");
                    assert!(text.ends_with('\n'), "{what}: cut short");
                    for r in rows {
                        assert_eq!(csv_fields(r), width, "{what}: {r}");
                    }
                }
                "json" => {
                    serde_json::from_slice::<serde_json::Value>(&bytes)
                        .unwrap_or_else(|e| panic!("{what}: {e}"));
                }
                "png" => assert!(bytes.ends_with(&IEND), "{what}: no IEND chunk"),
                "vtu" => assert!(text.trim_end().ends_with("</VTKFile>"), "{what}: cut short"),
                "html" => assert!(text.trim_end().ends_with("</html>"), "{what}: cut short"),
                "inp" | "mtx" => assert!(text.ends_with('\n'), "{what}: cut short"),
                _ => {}
            }
            checked += 1;
        }
    }
    checked
}

/// The template of the batch tests: a coarse thigh (700 quads; the built-in thigh's minimum is 622), the
/// compression test alone, a 24 x 24 grid, D of ischio, sartorius and gracilis tied, two
/// starts; no separate forward or sensitivity step. A few seconds per case (test build, one
/// thread).
pub const BATCH_TEMPLATE: &str = r#"
[model]
elements = 700
[[test]]
kind = "compression"
side = "anterior"
force_n_per_mm = 0.1
[grid]
counts = [24, 24]
[noise]
sigma_mm = 2e-3
[identification]
grouped = true
starts = 2
seed = 3
[run]
forward = false
sensitivity = false
"#;
