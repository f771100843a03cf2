//! Records, for the report's "Versions" table, the compiler and the versions of the main crates
//! as locked in the workspace's Cargo.lock.

use std::process::Command;

fn main() {
    println!("cargo:rerun-if-changed=../../Cargo.lock");
    let rustc = std::env::var("RUSTC").unwrap_or_else(|_| "rustc".into());
    let version = Command::new(rustc)
        .arg("--version")
        .output()
        .ok()
        .and_then(|o| String::from_utf8(o.stdout).ok())
        .map(|s| s.trim().to_string())
        .unwrap_or_else(|| "unknown".into());
    println!("cargo:rustc-env=FEMU_RUSTC_VERSION={version}");
    let lock = std::fs::read_to_string("../../Cargo.lock").unwrap_or_default();
    let wanted = [
        "faer",
        "rayon",
        "dicom-object",
        "image",
        "plotters",
        "rustfft",
        "spade",
        "indicatif",
    ];
    let mut found = Vec::new();
    let mut name = "";
    for line in lock.lines() {
        if let Some(n) = line.strip_prefix("name = ") {
            name = n.trim_matches('"');
        } else if let Some(v) = line.strip_prefix("version = ") {
            if wanted.contains(&name) && !found.iter().any(|(n, _): &(String, String)| n == name) {
                found.push((name.to_string(), v.trim_matches('"').to_string()));
            }
        }
    }
    let list: Vec<String> = found.iter().map(|(n, v)| format!("{n} {v}")).collect();
    println!("cargo:rustc-env=FEMU_CRATE_VERSIONS={}", list.join(", "));
}
