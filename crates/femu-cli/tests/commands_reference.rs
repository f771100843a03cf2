//! The guide's command reference (`docs/guide/src/reference/commands.md`) is the binary's own
//! `--help` for `femu` and every subcommand it lists, never copied by hand: this test runs them
//! and fails when the committed page differs, so an option added to a command appears in the
//! reference by regenerating it.
//!
//! When a command or an option changed, regenerate the page with
//! `FEMU_BLESS=1 cargo test -p femu-cli --test commands_reference`.

use std::path::Path;
use std::process::Command;

const PAGE: &str = "docs/guide/src/reference/commands.md";

/// `femu ARGS... --help`, as a user sees it.
fn help(path: &[String]) -> String {
    let out = Command::new(env!("CARGO_BIN_EXE_femu"))
        .args(path)
        .arg("--help")
        .env_remove("COLUMNS")
        .output()
        .expect("run femu");
    assert!(
        out.status.success(),
        "femu {} --help failed: {}",
        path.join(" "),
        String::from_utf8_lossy(&out.stderr)
    );
    String::from_utf8(out.stdout).expect("help is UTF-8")
}

/// The subcommands a help text lists under `Commands:` (without `help`).
fn subcommands(text: &str) -> Vec<String> {
    let mut names = Vec::new();
    let mut inside = false;
    for line in text.lines() {
        if line.trim_end() == "Commands:" {
            inside = true;
            continue;
        }
        if inside {
            if line.trim().is_empty() || !line.starts_with("  ") {
                break;
            }
            // A name starts the line after two spaces; a wrapped description line is indented
            // further.
            if line.starts_with("   ") {
                continue;
            }
            let name = line.split_whitespace().next().unwrap_or("");
            if !name.is_empty() && name != "help" {
                names.push(name.to_string());
            }
        }
    }
    names
}

/// Every command path (`[]`, `["run"]`, `["batch", "run"]`, ...) in the order `--help` lists them.
fn command_paths() -> Vec<(Vec<String>, String)> {
    let mut out = Vec::new();
    let mut todo = vec![Vec::<String>::new()];
    while let Some(path) = todo.pop() {
        let text = help(&path);
        let subs = subcommands(&text);
        out.push((path.clone(), text));
        // Depth-first in the listed order.
        for s in subs.into_iter().rev() {
            let mut p = path.clone();
            p.push(s);
            todo.push(p);
        }
    }
    out
}

fn page() -> String {
    let commands = command_paths();
    let mut s = String::from(
        "# Commands and options\n\n\
         <!-- Generated from `femu --help` and each subcommand's `--help`: do not edit. \
         Regenerate with\n     FEMU_BLESS=1 cargo test -p femu-cli --test commands_reference -->\n\n\
         Every command of `femu`, with its options as `femu COMMAND --help` prints them. What \
         each command writes is in [What each command writes](outputs.md); the study file the \
         commands read is in [Study-file keys](study-file.md).\n\nCommands:",
    );
    let names: Vec<String> = commands
        .iter()
        .skip(1)
        .map(|(p, _)| {
            let name = format!("femu {}", p.join(" "));
            format!("[`{name}`](#{})", name.replace(' ', "-"))
        })
        .collect();
    s.push(' ');
    s.push_str(&names.join(", "));
    s.push_str(".\n");
    for (path, text) in &commands {
        let name = if path.is_empty() {
            "femu".to_string()
        } else {
            format!("femu {}", path.join(" "))
        };
        s.push_str(&format!(
            "\n## `{name}`\n\n```text\n{}\n```\n",
            text.trim_end()
        ));
    }
    s
}

#[test]
fn commands_page_is_the_binarys_help() {
    let generated = page();
    let file = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../..")
        .join(PAGE);
    if std::env::var_os("FEMU_BLESS").is_some() {
        std::fs::create_dir_all(file.parent().unwrap()).unwrap();
        std::fs::write(&file, &generated).unwrap();
        return;
    }
    let committed = std::fs::read_to_string(&file).unwrap_or_default();
    if committed != generated {
        let first = committed
            .lines()
            .zip(generated.lines())
            .position(|(a, b)| a != b)
            .unwrap_or(committed.lines().count().min(generated.lines().count()));
        panic!(
            "{PAGE} differs from femu's --help (first at line {}:\n  committed: {:?}\n  \
             generated: {:?}).\nRegenerate it with: FEMU_BLESS=1 cargo test -p femu-cli --test \
             commands_reference",
            first + 1,
            committed.lines().nth(first).unwrap_or("(end of file)"),
            generated.lines().nth(first).unwrap_or("(end of file)"),
        );
    }
}

/// The page lists the commands a user runs, nested ones included, each with its options.
#[test]
fn every_listed_command_has_its_section() {
    let commands = command_paths();
    let names: Vec<String> = commands.iter().map(|(p, _)| p.join(" ")).collect();
    for expected in [
        "demo",
        "run",
        "init",
        "dic",
        "identify",
        "batch run",
        "mesh labels",
    ] {
        assert!(
            names.iter().any(|n| n == expected),
            "{expected} in {names:?}"
        );
    }
    let text = page();
    assert!(text.contains("\n## `femu run`\n\n```text\n"));
    assert!(text.contains("--out"));
    // The listing parser: a description continued on an indented line is not a command.
    let listing =
        "Usage: x\n\nCommands:\n  a    first\n         continued\n  b    second\n  help  \
                   Print\n\nOptions:\n  -h\n";
    assert_eq!(subcommands(listing), ["a", "b"]);
}
