//! The values a verification test measures, recorded for the guide's generated tables
//! (`scripts/guide/verify.sh` runs the tests, `scripts/guide/tables.py verification` writes
//! docs/guide/src/measured/verification.md from what they record).
//!
//! One file for every test crate, included by path (no copy, no library code for tests):
//!
//! ```ignore
//! #[path = "../../../scripts/guide/measure.rs"]
//! mod measure;
//! ```

/// Records one measured `value` (in `unit`, "" for a ratio) beside the `bound` the test asserts
/// on it, as text ("< 1e-5", "2 ± 0.2"), when the environment variable `FEMU_MEASURE_DIR` is
/// set: one JSON line `{"test", "quantity", "value", "bound", "unit"}` appended to
/// `$FEMU_MEASURE_DIR/<package>-<test target>.jsonl`, the test being the name libtest gives the
/// test's thread. Without the variable it does nothing, so the tests behave as they would
/// without it. A value that is not finite is written as `null`.
pub fn record(quantity: &str, value: f64, bound: &str, unit: &str) {
    let Some(dir) = std::env::var_os("FEMU_MEASURE_DIR") else {
        return;
    };
    let text = |s: &str| {
        let mut o = String::from("\"");
        for c in s.chars() {
            match c {
                '"' => o.push_str("\\\""),
                '\\' => o.push_str("\\\\"),
                c if (c as u32) < 0x20 => o.push_str(&format!("\\u{:04x}", c as u32)),
                c => o.push(c),
            }
        }
        o + "\""
    };
    let test = std::thread::current().name().unwrap_or("?").to_string();
    let value = if value.is_finite() {
        format!("{value:e}")
    } else {
        "null".into()
    };
    let line = format!(
        "{{\"test\":{},\"quantity\":{},\"value\":{value},\"bound\":{},\"unit\":{}}}\n",
        text(&test),
        text(quantity),
        text(bound),
        text(unit)
    );
    let dir = std::path::PathBuf::from(dir);
    let file = dir.join(format!(
        "{}-{}.jsonl",
        env!("CARGO_PKG_NAME"),
        env!("CARGO_CRATE_NAME")
    ));
    std::fs::create_dir_all(&dir).expect("FEMU_MEASURE_DIR cannot be created");
    // One write of the whole line to a file opened for appending: the tests of one binary run
    // on several threads, and appended writes this short are not interleaved.
    use std::io::Write;
    std::fs::OpenOptions::new()
        .create(true)
        .append(true)
        .open(&file)
        .and_then(|mut f| f.write_all(line.as_bytes()))
        .expect("FEMU_MEASURE_DIR is not writable");
}
