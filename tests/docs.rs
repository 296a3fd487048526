//! The commands the README and docs/ give run as written (issue 25, item
//! 6). Each fenced `sh` block's commands are read (a `\` continues a line):
//!
//! - `cargo run --release -- ARGS` and `servoid ARGS` whose manifest is in
//!   the repository run the binary with ARGS from the repository's root,
//!   with `--out` into a scratch folder (as written they write under
//!   `reports/`), and must succeed; the MTS campaign's where its logs are
//!   found (`util::mts_data`);
//! - a `servoid` command on a lab's own manifest (`night.toml`) cannot run
//!   here: its subcommand and every flag it uses must be ones
//!   `servoid SUBCOMMAND --help` lists;
//! - `cargo +nightly fuzz run TARGET CORPUS`: the target and its corpus
//!   exist;
//! - every `cargo bench --bench NAME` written anywhere in them names a
//!   bench Cargo.toml declares.
//!
//! `cargo test` is this test's own command; other shell lines (`case`,
//! `cargo install`) are the reader's.

use std::path::{Path, PathBuf};

use crate::util::{mts_data, root, scratch, servoid};

/// The markdown files a reader is pointed to.
fn documents() -> Vec<PathBuf> {
    let mut files = vec![root().join("README.md")];
    let mut docs: Vec<PathBuf> = std::fs::read_dir(root().join("docs"))
        .expect("docs/ exists")
        .map(|e| e.unwrap().path())
        .filter(|p| p.extension().is_some_and(|x| x == "md"))
        .collect();
    docs.sort();
    assert!(
        docs.len() >= 4,
        "docs/ holds the guides by reader: {docs:?}"
    );
    files.extend(docs);
    files
}

/// The commands of `text`'s fenced `sh` blocks, continuations joined,
/// comments dropped.
fn sh_commands(text: &str) -> Vec<String> {
    let mut commands = Vec::new();
    let mut in_sh = false;
    let mut pending = String::new();
    for line in text.lines() {
        let t = line.trim();
        if let Some(lang) = t.strip_prefix("```") {
            in_sh = !in_sh && lang.trim() == "sh";
            continue;
        }
        if !in_sh || t.starts_with('#') || t.is_empty() {
            continue;
        }
        match t.strip_suffix('\\') {
            Some(head) => {
                pending.push_str(head.trim_end());
                pending.push(' ');
            }
            None => {
                pending.push_str(t);
                commands.push(std::mem::take(&mut pending));
            }
        }
    }
    commands
}

/// `servoid`'s arguments in a command line, when it runs servoid.
fn servoid_args(command: &str) -> Option<Vec<String>> {
    let rest = command
        .strip_prefix("cargo run --release -- ")
        .or_else(|| command.strip_prefix("servoid "))?;
    // Stop at shell syntax: what follows is the shell's.
    let words = rest
        .split_whitespace()
        .take_while(|w| !matches!(*w, ">>" | ">" | "|" | "&&" | ";"))
        .map(|w| w.trim_matches('"').to_string())
        .collect();
    Some(words)
}

/// The MTS campaign's manifest, its log paths pointed at `data` (the logs'
/// folder) where they do not resolve from the checkout as written.
fn mts_manifest_for(manifest: &Path, data: &Path, dir: &Path) -> PathBuf {
    let text = std::fs::read_to_string(manifest).unwrap();
    let rewritten = text.replace(
        "../../../shared/data/utfsm-mts-mrdamper",
        &data.display().to_string(),
    );
    let path = dir.join("campaign.toml");
    std::fs::write(&path, rewritten).unwrap();
    path
}

fn run_in_scratch(mut args: Vec<String>, dir: &Path, n: usize) {
    let out = dir.join(format!("out-{n}"));
    // Right after the manifest: `simulate --run` passes what follows on.
    args.insert(2, out.display().to_string());
    args.insert(2, "--out".into());
    let refs: Vec<&str> = args.iter().map(String::as_str).collect();
    let o = servoid(&root(), &refs);
    assert_eq!(o.code, 0, "servoid {args:?}\n{}", o.stderr);
    assert!(
        out.join("results.json").exists(),
        "servoid {args:?} wrote no results.json"
    );
}

/// The flags `servoid SUBCOMMAND --help` lists.
fn flags_of(subcommand: &str) -> Vec<String> {
    let o = servoid(&root(), &[subcommand, "--help"]);
    assert_eq!(o.code, 0, "servoid {subcommand} --help: {}", o.stderr);
    o.stdout
        .split_whitespace()
        .filter(|w| w.starts_with("--"))
        .map(|w| {
            w.trim_end_matches([',', '.', ']'])
                .split('=')
                .next()
                .unwrap()
                .to_string()
        })
        .collect()
}

#[test]
fn every_command_in_the_readme_and_docs_runs_as_written() {
    let dir = scratch();
    let cargo = std::fs::read_to_string(root().join("Cargo.toml")).unwrap();
    let mut ran = 0;
    for file in documents() {
        let text = std::fs::read_to_string(&file).unwrap();
        for command in sh_commands(&text) {
            let Some(mut args) = servoid_args(&command) else {
                if let Some(rest) = command.strip_prefix("cargo +nightly fuzz run ") {
                    let w: Vec<&str> = rest.split_whitespace().collect();
                    let target = root().join(format!("fuzz/fuzz_targets/{}.rs", w[0]));
                    assert!(
                        target.exists(),
                        "{}: {command}: no {target:?}",
                        file.display()
                    );
                    assert!(
                        root().join(w[1]).is_dir(),
                        "{}: {command}: no corpus {}",
                        file.display(),
                        w[1]
                    );
                }
                continue;
            };
            let manifest = args.get(1).map(|m| root().join(m));
            match manifest {
                Some(m) if m.is_file() => {
                    if m.ends_with("utfsm-mts-mrdamper/campaign.toml") {
                        let Some(data) = mts_data() else { continue };
                        let as_written = m
                            .parent()
                            .unwrap()
                            .join("../../../shared/data/utfsm-mts-mrdamper/0A.txt");
                        if !as_written.exists() {
                            let copy = dir.path().join(format!("mts-{ran}"));
                            std::fs::create_dir_all(&copy).unwrap();
                            args[1] = mts_manifest_for(&m, &data, &copy).display().to_string();
                        }
                    }
                    eprintln!("{}: running `{command}`", file.display());
                    run_in_scratch(args, dir.path(), ran);
                    ran += 1;
                }
                _ => {
                    // A lab's own manifest: the subcommand and its flags.
                    let flags = flags_of(&args[0]);
                    for a in args.iter().filter(|a| a.starts_with("--")) {
                        assert!(
                            flags.contains(a),
                            "{}: `{command}`: servoid {} has no {a} (it has {flags:?})",
                            file.display(),
                            args[0]
                        );
                    }
                }
            }
        }
        // Benches named anywhere, fenced or inline.
        for (i, _) in text.match_indices("cargo bench --bench ") {
            let name: String = text[i + "cargo bench --bench ".len()..]
                .chars()
                .take_while(|c| c.is_alphanumeric() || *c == '_')
                .collect();
            assert!(
                cargo.contains(&format!("name = \"{name}\"")),
                "{}: `cargo bench --bench {name}` names no bench in Cargo.toml",
                file.display()
            );
        }
    }
    // The main job and the paper's campaign at least.
    assert!(ran >= 2, "only {ran} commands ran");
}

/// The reader of the extraction above: continuations join, comments and
/// other blocks do not count.
#[test]
fn sh_blocks_are_read_as_a_shell_reads_them() {
    let text = "x\n```sh\n# a comment\nservoid run a.toml \\\n    --out b\n```\n```toml\nservoid = 1\n```\n";
    assert_eq!(sh_commands(text), vec!["servoid run a.toml --out b"]);
    assert_eq!(
        servoid_args("servoid run n.toml --quiet >> night.jsonl").unwrap(),
        vec!["run", "n.toml", "--quiet"]
    );
}
