//! The commands the README and docs/ give run as written (item
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
//!   bench Cargo.toml declares;
//! - every fenced `toml` block passes `servoid check`: the complete
//!   manifest as written, each fragment merged into it;
//! - the worked night's commands (docs/manifest.md, on
//!   `experiments/nightly/`) depend on each other (tonight's logs, one
//!   history): they run in order, as written, in a copy of the example, and
//!   the nights' exit codes, alarm and history are checked against the
//!   simulated truth.
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
            if in_worked_night(&args) {
                // Run in order by the_worked_night_runs_as_written_and_alarms_on_the_drifted_night.
                continue;
            }
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

/// The fenced `toml` blocks of `text`, each without the indentation of its
/// fence (a block inside a list item is indented).
fn toml_blocks(text: &str) -> Vec<String> {
    fenced_blocks(text, "toml")
}

/// The fenced blocks of `text` in language `lang`, each without the
/// indentation of its fence.
pub(crate) fn fenced_blocks(text: &str, lang: &str) -> Vec<String> {
    let mut blocks = Vec::new();
    let mut current: Option<(usize, String)> = None;
    for line in text.lines() {
        let t = line.trim_start();
        match (&mut current, t.strip_prefix("```")) {
            (None, Some(l)) if l.trim() == lang => {
                current = Some((line.len() - t.len(), String::new()));
            }
            (Some(_), Some(_)) => blocks.push(current.take().expect("a block").1),
            (Some((indent, block)), None) => {
                block.push_str(line.get(*indent..).unwrap_or("").trim_end());
                block.push('\n');
            }
            _ => {}
        }
    }
    blocks
}

/// `fragment`'s keys put into `base`, tables merged key by key.
fn merge(base: &mut toml::Table, fragment: toml::Table) {
    for (key, value) in fragment {
        match (base.get_mut(&key), value) {
            (Some(toml::Value::Table(b)), toml::Value::Table(f)) => merge(b, f),
            (_, value) => {
                base.insert(key, value);
            }
        }
    }
}

/// Every manifest example in the docs passes `servoid check`: the complete one as written, and each fragment (`[history]`,
/// `[run_table]`, `[identification.joint]`, `[sensitivity]`) merged into
/// it. A run table's file is written for the check, with one row, as the
/// fragment names it. The complete example is the first block that has
/// `schema_version`.
#[test]
fn every_manifest_example_in_the_docs_passes_servoid_check() {
    let blocks: Vec<(PathBuf, String)> = documents()
        .into_iter()
        .flat_map(|doc| {
            let text = std::fs::read_to_string(&doc).unwrap();
            toml_blocks(&text)
                .into_iter()
                .map(move |b| (doc.clone(), b))
        })
        .collect();
    let (_, complete) = blocks
        .iter()
        .find(|(_, b)| b.contains("schema_version"))
        .expect("the docs show a complete manifest");
    let base: toml::Table = toml::from_str(complete).expect("the complete example is TOML");
    assert!(blocks.len() >= 5, "{} toml blocks", blocks.len());
    for (n, (doc, block)) in blocks.iter().enumerate() {
        let fragment: toml::Table = toml::from_str(block).unwrap_or_else(|e| {
            panic!(
                "{}: a toml block does not parse: {e}\n{block}",
                doc.display()
            )
        });
        let mut manifest = base.clone();
        merge(&mut manifest, fragment);
        let dir = scratch();
        if let Some(file) = manifest
            .get("run_table")
            .and_then(|t| t.get("file"))
            .and_then(toml::Value::as_str)
        {
            let table = dir.path().join(file);
            std::fs::create_dir_all(table.parent().unwrap()).unwrap();
            std::fs::write(
                &table,
                "id,role,p_gain,stiffness_n_per_m\nk9,spring,1.0,90000\n",
            )
            .unwrap();
        }
        let path = dir.path().join(format!("example-{n}.toml"));
        std::fs::write(&path, toml::to_string(&manifest).unwrap()).unwrap();
        let o = servoid(&root(), &["check", path.to_str().unwrap()]);
        assert_eq!(
            o.code,
            0,
            "{}: this example does not pass `servoid check`:\n{block}\n{}",
            doc.display(),
            o.stderr
        );
    }
}

/// The block reader takes indented blocks and leaves the others.
#[test]
fn toml_blocks_are_read_with_their_indentation_taken_off() {
    let text = "a\n```toml\nx = 1\n```\n- item\n\n   ```toml\n   [t]\n   y = \"z\"\n   ```\n```sh\nservoid\n```\n";
    assert_eq!(toml_blocks(text), vec!["x = 1\n", "[t]\ny = \"z\"\n"]);
    let mut base: toml::Table = toml::from_str("[a]\nb = 1\nc = 2\n").unwrap();
    merge(
        &mut base,
        toml::from_str("[a]\nc = 3\n[d]\ne = 4\n").unwrap(),
    );
    assert_eq!(
        toml::to_string(&base).unwrap(),
        "[a]\nb = 1\nc = 3\n\n[d]\ne = 4\n"
    );
}

/// The worked night's folder (docs/manifest.md, "A worked night"): the
/// commands on its files run together, in order.
const WORKED_NIGHT: &str = "experiments/nightly/";

/// The worked night's output folder, which its `history` commands name.
const WORKED_NIGHT_OUT: &str = "reports/frame-b/";

/// Whether a command is one of the worked night's: on its manifests, or on
/// the history it writes.
fn in_worked_night(args: &[String]) -> bool {
    args.get(1).is_some_and(|m| m.starts_with(WORKED_NIGHT))
        || (args.first().is_some_and(|c| c == "history")
            && args.iter().any(|a| a.starts_with(WORKED_NIGHT_OUT)))
}

/// Copy the folder `from` into `to`, but for what the walkthrough writes
/// (`incoming/`, its lock): a checkout that tried the example copies as a
/// fresh one.
fn copy_example(from: &Path, to: &Path) {
    std::fs::create_dir_all(to).unwrap();
    for e in std::fs::read_dir(from).unwrap() {
        let e = e.unwrap();
        let name = e.file_name();
        if name.to_string_lossy().contains("incoming") {
            continue;
        }
        let target = to.join(name);
        if e.file_type().unwrap().is_dir() {
            copy_example(&e.path(), &target);
        } else {
            std::fs::copy(e.path(), &target).unwrap();
        }
    }
}

/// A simulation manifest's true rig as the history states it: beta1, a1b0
/// at P = 1, a2, a3.
fn simulated_rig(path: &Path) -> Vec<(&'static str, f64)> {
    let text = std::fs::read_to_string(path).unwrap();
    let sim: toml::Table = toml::from_str(&text).unwrap();
    let p = &sim["rig"]["parameters"];
    let num = |k: &str| p[k].as_float().unwrap_or_else(|| panic!("{path:?}: {k}"));
    let p_gain = p
        .get("p_gain")
        .and_then(toml::Value::as_float)
        .unwrap_or(1.0);
    vec![
        ("beta1", num("beta1_per_s")),
        ("a1b0", num("a1b0_n_per_m_s2") / p_gain),
        ("a2", num("a2_n_per_m")),
        ("a3", num("a3_per_s")),
    ]
}

/// The median (the mean of the middle two for an even count); None for
/// none.
fn median(v: &[f64]) -> Option<f64> {
    let mut s = v.to_vec();
    s.sort_by(f64::total_cmp);
    let n = s.len();
    match n {
        0 => None,
        _ if n % 2 == 1 => Some(s[n / 2]),
        _ => Some(0.5 * (s[n / 2 - 1] + s[n / 2])),
    }
}

/// How close each night's identified rig is to its truth: the simulator's
/// own tolerance for these logs (the `tolerance_pct = 0.5` of the
/// references it writes into its campaign.toml). A drift of a few percent
/// is several times this.
const TRUTH_TOLERANCE: f64 = 0.005;

/// docs/manifest.md, "A worked night": the commands on
/// `experiments/nightly/` run as written, in order, from the root of a
/// copy of the example (the repository gets neither logs nor reports):
/// `simulate` leaves tonight's logs, `run` reads them into one folder. The
/// expectations come from the simulation manifests, not from the output: a
/// night whose true rig is the first night's exits 0 without an alarm; a
/// night whose truth moved exits 3 with one alarm per moved parameter,
/// naming it, its deviation the truth's move (it needs `MIN_HISTORY`
/// earlier nights, which the walkthrough must give it). Each night is run
/// with its `--date`, and `history remove --date` takes one out:
/// history.parquet then holds every other night once, in order, with its
/// date, each within 0.5 % of its truth.
#[test]
fn the_worked_night_runs_as_written_and_alarms_on_the_drifted_night() {
    use servoid::drift::MIN_HISTORY;
    use servoid::ingest::{TableFormat, read_table};

    let mut commands = Vec::new();
    let mut doc = None;
    for file in documents() {
        let text = std::fs::read_to_string(&file).unwrap();
        for command in sh_commands(&text) {
            let Some(args) = servoid_args(&command) else {
                continue;
            };
            if in_worked_night(&args) {
                assert_eq!(
                    *doc.get_or_insert_with(|| file.clone()),
                    file,
                    "the worked night's commands are in two documents: one walkthrough, one order"
                );
                commands.push((command, args));
            }
        }
    }
    let doc = doc.expect("docs/ walk through experiments/nightly/");
    let example = root().join(WORKED_NIGHT);

    // The manifest and run table the walkthrough shows are the files.
    let text = std::fs::read_to_string(&doc).unwrap();
    for (file, lang) in [("night.toml", "toml"), ("runs.csv", "csv")] {
        let bytes = std::fs::read_to_string(example.join(file)).unwrap();
        let as_file: String = bytes
            .lines()
            .map(|l| format!("{}\n", l.trim_end()))
            .collect();
        assert!(
            fenced_blocks(&text, lang).contains(&as_file),
            "{}: no `{lang}` block is {WORKED_NIGHT}{file} as it is:\n{as_file}",
            doc.display()
        );
    }
    let night: toml::Table =
        toml::from_str(&std::fs::read_to_string(example.join("night.toml")).unwrap()).unwrap();
    let rig = night["rig"]["name"].as_str().unwrap().to_string();

    let dir = scratch();
    copy_example(&example, &dir.path().join(WORKED_NIGHT));
    // Each night's truth, in order; whether tonight's logs are new.
    let mut truths: Vec<Vec<(&str, f64)>> = Vec::new();
    let mut fresh = false;
    let mut out = None;
    let mut alarmed = 0;
    // Each night's --date, and the dates removed from the history.
    let mut dates: Vec<String> = Vec::new();
    let mut removed: Vec<String> = Vec::new();
    let flag = |args: &[String], name: &str| -> Option<String> {
        let at = args.iter().position(|a| a == name)?;
        args.get(at + 1).cloned()
    };
    for (command, args) in &commands {
        eprintln!("{}: running `{command}`", doc.display());
        let refs: Vec<&str> = args.iter().map(String::as_str).collect();
        let o = servoid(dir.path(), &refs);
        match args[0].as_str() {
            "simulate" => {
                assert_eq!(o.code, 0, "`{command}`:\n{}", o.stderr);
                truths.push(simulated_rig(&dir.path().join(&args[1])));
                fresh = true;
            }
            "run" => {
                assert!(fresh, "`{command}` runs no new night's logs");
                fresh = false;
                dates.push(flag(args, "--date").expect("each night is run with its date"));
                let at = args.iter().position(|a| a == "--out");
                let given = Path::new(&args[at.expect("the nights' folder is given") + 1]);
                assert!(
                    given.is_relative(),
                    "`{command}`: --out inside the checkout"
                );
                let folder = dir.path().join(given);
                assert_eq!(
                    *out.get_or_insert_with(|| folder.clone()),
                    folder,
                    "every night runs into one folder"
                );
                let n = truths.len();
                let tonight = &truths[n - 1];
                let earlier = &truths[..n - 1];
                // Parameters whose truth tonight is not the earlier nights'
                // (their median, as the rule takes), with how far.
                let moved: Vec<(&str, f64)> = tonight
                    .iter()
                    .enumerate()
                    .filter_map(|(k, &(name, value))| {
                        let past: Vec<f64> = earlier.iter().map(|t| t[k].1).collect();
                        let by = value - median(&past)?;
                        (by.abs() > 1e-9 * value.abs()).then_some((name, by))
                    })
                    .collect();
                let results: serde_json::Value =
                    serde_json::from_slice(&std::fs::read(folder.join("results.json")).unwrap())
                        .unwrap();
                let drift = &results["drift"];
                assert_eq!(
                    drift["earlier_entries"],
                    earlier.len(),
                    "night {n}: one entry a night"
                );
                let alarms = drift["alarms"].as_array().unwrap();
                if moved.is_empty() {
                    assert_eq!(o.code, 0, "night {n}, the rig as before:\n{}", o.stderr);
                    assert!(alarms.is_empty(), "night {n}: {alarms:?}");
                    continue;
                }
                assert!(
                    earlier.len() >= MIN_HISTORY,
                    "night {n} moves {moved:?} with {} nights before it: the alarm needs {MIN_HISTORY}",
                    earlier.len()
                );
                assert_eq!(o.code, 3, "night {n} moved {moved:?}:\n{}", o.stderr);
                assert_eq!(
                    alarms.len(),
                    moved.len(),
                    "night {n} moved {moved:?}: {alarms:?}"
                );
                for (name, by) in &moved {
                    let line = format!("ALARM: rig `{rig}`: {name} = ");
                    assert!(
                        o.stderr.contains(&line),
                        "night {n}: no `{line}`:\n{}",
                        o.stderr
                    );
                    let check = drift["checks"]
                        .as_array()
                        .unwrap()
                        .iter()
                        .find(|c| c["parameter"] == *name)
                        .unwrap();
                    assert_eq!(check["alarm"], true, "{check}");
                    let deviation = check["deviation"].as_f64().unwrap();
                    let value = tonight.iter().find(|t| t.0 == *name).unwrap().1;
                    assert!(
                        (deviation - by).abs() < TRUTH_TOLERANCE * value.abs(),
                        "night {n}: {name} moved {deviation} from the median, the truth {by}"
                    );
                }
                alarmed += 1;
            }
            "history" => {
                assert_eq!(o.code, 0, "`{command}`:\n{}", o.stderr);
                let date = flag(args, "--date").expect("a removal names its date");
                assert!(dates.contains(&date), "`{command}`: no night of {date}");
                removed.push(date);
            }
            _ => assert_eq!(o.code, 0, "`{command}`:\n{}", o.stderr),
        }
    }
    assert!(alarmed > 0, "the walkthrough's nights raise no alarm");
    assert!(!removed.is_empty(), "the walkthrough removes no night");

    // The history: every night once, in order, each near its own truth.
    let history = out
        .expect("the walkthrough runs a night")
        .join("history.parquet");
    let table = read_table(&history, TableFormat::Parquet).unwrap();
    // The nights kept, each with its date and truth.
    let kept: Vec<(&String, &Vec<(&str, f64)>)> = dates
        .iter()
        .zip(&truths)
        .filter(|(d, _)| !removed.contains(d))
        .collect();
    assert_eq!(table.rows.len(), kept.len(), "one history row a night kept");
    let cell = |row: &[Option<String>], name: &str| -> String {
        let k = table
            .column(name)
            .unwrap_or_else(|| panic!("no column {name}"));
        row[k].clone().unwrap_or_else(|| panic!("{name} is empty"))
    };
    for (n, (row, (date, truth))) in table.rows.iter().zip(kept).enumerate() {
        assert_eq!(cell(row, "rig"), rig, "row {n}");
        assert_eq!(&cell(row, "date"), date, "row {n}");
        let p_gain: f64 = cell(row, "p_gain").parse().unwrap();
        for &(name, value) in truth {
            let mut got: f64 = cell(row, name).parse().unwrap();
            if name == "a1b0" {
                got /= p_gain;
            }
            assert!(
                (got - value).abs() <= TRUTH_TOLERANCE * value.abs(),
                "night {}: {name} = {got}, the truth {value}",
                n + 1
            );
        }
        let delay: f64 = cell(row, "delay_s").parse().unwrap();
        assert!(delay > 0.0, "night {}: delay {delay}", n + 1);
    }
}
