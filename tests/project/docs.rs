//! The reference in `docs/` keeps up with the command: every flag that `imubake <command>
//! --help` prints is documented on that command's page (`docs/src/commands/<command>.md`), and
//! every page the book's table of contents names exists.

use std::collections::BTreeSet;
use std::path::Path;
use std::process::Command;

const COMMANDS: [&str; 11] = [
    "convert",
    "batch",
    "fuse",
    "calibrate-sensors",
    "watch",
    "inspect",
    "simulate",
    "angles",
    "compare",
    "live",
    "view",
];

fn docs(rel: &str) -> String {
    let path = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("docs/src")
        .join(rel);
    std::fs::read_to_string(&path).unwrap_or_else(|e| panic!("{}: {e}", path.display()))
}

/// The long flags `--help` lists (each option line starts with its flags).
fn help_flags(command: &str) -> BTreeSet<String> {
    let out = Command::new(env!("CARGO_BIN_EXE_imubake"))
        .args([command, "--help"])
        .output()
        .unwrap();
    assert!(out.status.success());
    let text = String::from_utf8(out.stdout).unwrap();
    let flag = regex::Regex::new(r"^\s+(?:-\w, )?(--[a-z][a-z0-9-]*)").unwrap();
    text.lines()
        .filter_map(|l| flag.captures(l).map(|c| c[1].to_string()))
        .filter(|f| f != "--help" && f != "--version")
        .collect()
}

#[test]
fn every_flag_of_every_command_is_documented() {
    let mut missing = Vec::new();
    for command in COMMANDS {
        let flags = help_flags(command);
        assert!(!flags.is_empty(), "{command}: no flags read from --help");
        let page = docs(&format!("commands/{command}.md"));
        for flag in flags {
            // As written in the page: `--flag` or `--flag VALUE` in code.
            if !page.contains(&format!("`{flag}`")) && !page.contains(&format!("`{flag} ")) {
                missing.push(format!("{command} {flag}"));
            }
        }
    }
    assert!(
        missing.is_empty(),
        "flags not documented in docs/src/commands: {missing:?}"
    );
}

#[test]
fn the_table_of_contents_names_existing_pages() {
    let summary = docs("SUMMARY.md");
    let link = regex::Regex::new(r"\]\(([^)]+\.md)\)").unwrap();
    let pages: Vec<String> = link
        .captures_iter(&summary)
        .map(|c| c[1].to_string())
        .collect();
    assert!(pages.len() > 10, "{pages:?}");
    for page in pages {
        let _ = docs(&page);
    }
}

/// `--input-format`'s help lists exactly the formats the reference's format table documents
/// (`docs/src/formats/index.md`), for every command that reads captures.
#[test]
fn input_format_help_lists_the_documented_formats() {
    let table = docs("formats/index.md");
    let row = regex::Regex::new(r"(?m)^\| \[`([a-z0-9-]+)`\]\(").unwrap();
    let documented: BTreeSet<String> = row
        .captures_iter(&table)
        .map(|c| c[1].to_string())
        .collect();
    assert!(documented.len() >= 10, "{documented:?}");
    let listed =
        regex::Regex::new(r"--input-format <FORMAT>[^\[]*\[possible values: ([^\]]+)\]").unwrap();
    for command in ["convert", "batch", "watch", "inspect"] {
        let out = Command::new(env!("CARGO_BIN_EXE_imubake"))
            .args([command, "-h"])
            .output()
            .unwrap();
        let help = String::from_utf8(out.stdout).unwrap();
        let values: BTreeSet<String> = listed
            .captures(&help)
            .unwrap_or_else(|| panic!("{command} -h lists no --input-format values:\n{help}"))[1]
            .split(", ")
            .map(str::to_string)
            .collect();
        assert_eq!(values, documented, "{command}");
        // `--help` tells what each one is.
        let out = Command::new(env!("CARGO_BIN_EXE_imubake"))
            .args([command, "--help"])
            .output()
            .unwrap();
        let help = String::from_utf8(out.stdout).unwrap();
        for name in &documented {
            let line = regex::Regex::new(&format!(r"(?m)^\s+- {name}: +\S")).unwrap();
            assert!(line.is_match(&help), "{command} --help: {name}:\n{help}");
        }
    }
}
