//! The numbers the README and docs/ state, against what produces them
//! (docs/accuracy.md, "How to read this page"):
//!
//! - the main job's time and the CPU ratio against the scipy script are
//!   stated in one place, docs/accuracy.md's section "The main job's time
//!   and the CPU ratio", with the date, the commit and the machine's cores;
//!   no other document, and no other section of accuracy.md, states either;
//! - every producer accuracy.md names exists: a test function
//!   (`tests/FILE.rs::FUNCTION`, `pipeline/PATH.rs::FUNCTION`), a bench
//!   (`cargo bench --bench NAME`, its filter after ` -- ` and the
//!   environment variables before it), or a script (`python3 PATH`);
//! - the bundled default's rig as accuracy.md states it is the one the
//!   main job identifies, to the rounding the doc states it at.
//!
//! A statement is found sentence by sentence, outside fenced blocks (each
//! table row and list item apart): a main job's time is a sentence that
//! names the main job (or its command, or its output folder) and holds a
//! number of seconds; a CPU ratio is one that says "ratio", names the scipy
//! side or the CPU, and holds a fraction 0.x.

use std::path::{Path, PathBuf};

use crate::util::{bundled_simulation, root, scratch, servoid_into};

/// The one section that states the main job's time and the CPU ratio
/// (the README links to its anchor, `#the-main-jobs-time-and-the-cpu-ratio`).
const SECTION: &str = "## The main job's time and the CPU ratio";

/// What names the main job in a sentence (lower case).
const MAIN_JOB: [&str; 3] = [
    "main job",
    "simulation.toml --run",
    "maghareh2018-synthetic",
];

/// What names the other side of the CPU ratio in a sentence (lower case).
const PEER: [&str; 5] = ["scipy", "numpy", "identify.py", "compare.py", "cpu"];

/// README.md and docs/*.md.
fn documents() -> Vec<PathBuf> {
    let mut docs: Vec<PathBuf> = std::fs::read_dir(root().join("docs"))
        .expect("docs/ exists")
        .map(|e| e.expect("a docs/ entry").path())
        .filter(|p| p.extension().is_some_and(|x| x == "md"))
        .collect();
    docs.sort();
    let mut files = vec![root().join("README.md")];
    files.extend(docs);
    files
}

fn read(path: &Path) -> String {
    std::fs::read_to_string(path).unwrap_or_else(|e| panic!("{}: {e}", path.display()))
}

/// The paragraphs of a markdown text, each one line: fenced blocks left
/// out; a heading, each table row and each list item a paragraph of its
/// own; a blank line ends one.
fn paragraphs(text: &str) -> Vec<String> {
    let mut out = Vec::new();
    let mut current: Vec<&str> = Vec::new();
    let mut fenced = false;
    for line in text.lines() {
        let t = line.trim();
        if t.starts_with("```") {
            fenced = !fenced;
            if !current.is_empty() {
                out.push(current.join(" "));
                current.clear();
            }
            continue;
        }
        if fenced {
            continue;
        }
        if t.starts_with("- ") && !current.is_empty() {
            out.push(current.join(" "));
            current.clear();
        }
        if t.is_empty() || t.starts_with('|') || t.starts_with('#') {
            if !current.is_empty() {
                out.push(current.join(" "));
                current.clear();
            }
            if !t.is_empty() {
                out.push(t.to_string());
            }
            continue;
        }
        current.push(t);
    }
    if !current.is_empty() {
        out.push(current.join(" "));
    }
    out
}

/// The sentences of a paragraph: split after `.`, `?` or `!` and a space.
fn sentences(paragraph: &str) -> Vec<String> {
    let mut out = Vec::new();
    let mut start = 0;
    let bytes = paragraph.as_bytes();
    for (i, c) in bytes.iter().enumerate() {
        if matches!(c, b'.' | b'?' | b'!') && bytes.get(i + 1) == Some(&b' ') {
            out.push(paragraph[start..=i].to_string());
            start = i + 2;
        }
    }
    if start < paragraph.len() {
        out.push(paragraph[start..].to_string());
    }
    out
}

/// Whether `s` holds a number of seconds: a digit, a space, `s`, then no
/// letter or digit ("5.5 s", "8.0-8.7 s;", "14 s").
fn has_seconds(s: &str) -> bool {
    let b = s.as_bytes();
    (1..b.len().saturating_sub(1)).any(|i| {
        b[i] == b' '
            && b[i + 1] == b's'
            && b[i - 1].is_ascii_digit()
            && b.get(i + 2).is_none_or(|c| !c.is_ascii_alphanumeric())
    })
}

/// Whether `s` holds a fraction written 0.x ("0.31", not "10.3" or "1.05").
fn has_fraction(s: &str) -> bool {
    let b = s.as_bytes();
    (0..b.len().saturating_sub(2)).any(|i| {
        b[i] == b'0'
            && b[i + 1] == b'.'
            && b[i + 2].is_ascii_digit()
            && (i == 0 || !(b[i - 1].is_ascii_digit() || b[i - 1] == b'.'))
    })
}

/// Whether a sentence states a main job's time.
fn states_main_job_time(sentence: &str) -> bool {
    let l = sentence.to_lowercase();
    MAIN_JOB.iter().any(|m| l.contains(m)) && has_seconds(sentence)
}

/// Whether a sentence states a CPU ratio against the scipy script.
fn states_cpu_ratio(sentence: &str) -> bool {
    let l = sentence.to_lowercase();
    l.contains("ratio") && PEER.iter().any(|m| l.contains(m)) && has_fraction(sentence)
}

/// The sentences of `text` that state a main job's time or a CPU ratio.
fn statements(text: &str) -> Vec<String> {
    paragraphs(text)
        .iter()
        .flat_map(|p| sentences(p.as_str()))
        .filter(|s| states_main_job_time(s) || states_cpu_ratio(s))
        .collect()
}

/// `text` split at `SECTION`: (the section, from its heading to the next
/// heading of its level or above; the rest). None without the heading.
fn split_section(text: &str) -> Option<(String, String)> {
    let mut section = String::new();
    let mut rest = String::new();
    let mut inside = false;
    let mut found = false;
    for line in text.lines() {
        if line == SECTION {
            inside = true;
            found = true;
        } else if inside && (line.starts_with("## ") || line.starts_with("# ")) {
            inside = false;
        }
        let to = if inside { &mut section } else { &mut rest };
        to.push_str(line);
        to.push('\n');
    }
    found.then_some((section, rest))
}

/// Whether `text` holds a date written YYYY-MM-DD.
fn has_date(text: &str) -> bool {
    let b = text.as_bytes();
    (0..b.len().saturating_sub(9)).any(|i| {
        let w = &b[i..i + 10];
        w.iter().enumerate().all(|(k, c)| match k {
            4 | 7 => *c == b'-',
            _ => c.is_ascii_digit(),
        })
    })
}

/// Whether `text` holds a commit hash: a word of 7 to 40 hexadecimal
/// digits with at least one digit and one letter.
fn has_commit(text: &str) -> bool {
    text.split(|c: char| !c.is_ascii_alphanumeric()).any(|w| {
        (7..=40).contains(&w.len())
            && w.chars()
                .all(|c| c.is_ascii_hexdigit() && !c.is_ascii_uppercase())
            && w.chars().any(|c| c.is_ascii_digit())
            && w.chars().any(|c| c.is_ascii_alphabetic())
    })
}

/// The main job's time and the CPU ratio are stated in one place:
/// accuracy.md's section, with a date, a commit and the cores. No other
/// document, and no other part of accuracy.md, states either.
#[test]
fn the_main_jobs_time_and_the_cpu_ratio_are_stated_once() {
    let mut elsewhere = Vec::new();
    let mut section = None;
    for file in documents() {
        let text = read(&file);
        let name = file
            .strip_prefix(root())
            .unwrap_or(&file)
            .display()
            .to_string();
        let outside = if name == "docs/accuracy.md" {
            assert_eq!(
                text.lines().filter(|l| *l == SECTION).count(),
                1,
                "{name}: one section headed `{SECTION}`"
            );
            let (inside, rest) = split_section(&text).expect("the section");
            section = Some(inside);
            rest
        } else {
            text
        };
        for s in statements(&outside) {
            elsewhere.push(format!("{name}: {s}"));
        }
    }
    assert!(
        elsewhere.is_empty(),
        "the main job's time or the CPU ratio stated outside docs/accuracy.md's \
         section `{SECTION}` (link to it instead):\n{}",
        elsewhere.join("\n")
    );
    let section = section.expect("docs/accuracy.md is among the documents");
    let stated = statements(&section);
    assert!(
        stated.iter().any(|s| states_main_job_time(s.as_str())),
        "the section states no main job's time:\n{section}"
    );
    assert!(
        stated.iter().any(|s| states_cpu_ratio(s.as_str())),
        "the section states no CPU ratio:\n{section}"
    );
    assert!(has_date(&section), "the section names no date (YYYY-MM-DD)");
    assert!(has_commit(&section), "the section names no commit");
    assert!(
        section.contains("cores"),
        "the section names no machine's cores"
    );
}

/// The statement finder fires on the statements it is for and not on
/// their neighbours.
#[test]
fn the_statement_check_can_fail() {
    for s in [
        "The first simulates the paper's test program and identifies it into `reports/maghareh2018-synthetic/`: about 6 s on two cores.",
        "- **The main job.** Then it runs in 8.0-8.7 s on two cores.",
        "`servoid run` against the scipy script: a CPU ratio of 0.31.",
    ] {
        assert_eq!(statements(s), vec![s.to_string()], "{s}");
    }
    for s in [
        "The second compiles the test binaries (115 s more, 2026-11-26).",
        "The main job writes 46 figures.",
        "The springs' stiffness ratio is 0.75.",
        "The ratio of CPU to wall time is 1.72.",
        "The main job takes seconds.",
    ] {
        assert!(statements(s).is_empty(), "{s}");
    }
    // Sentences, paragraphs, fenced blocks.
    let text = "A main job. It took 9 s.\n\n```sh\nmain job 5 s\n```\n- the main job took 3 s\n";
    assert_eq!(
        statements(text),
        vec!["- the main job took 3 s".to_string()]
    );
    assert!(has_date("on 2026-11-29, commit 5e05815"));
    assert!(has_commit("on 2026-11-29, commit 5e05815"));
    assert!(!has_commit("2026112 and deadbee and a1b0"));
    let (inside, rest) = split_section(&format!(
        "# T\n## A\nx\n{SECTION}\ny\n### Sub\nz\n## B\nw\n"
    ))
    .unwrap();
    assert_eq!(inside, format!("{SECTION}\ny\n### Sub\nz\n"));
    assert_eq!(rest, "# T\n## A\nx\n## B\nw\n");
}

/// A producer accuracy.md names.
#[derive(Debug, Clone, PartialEq)]
enum Producer {
    /// A test function in a file of the repository.
    Test { file: String, function: String },
    /// A bench, its criterion filter and the environment variables set
    /// before it.
    Bench {
        name: String,
        filter: Option<String>,
        env: Vec<String>,
    },
    /// A script run by python3.
    Script { path: String },
}

/// Whether `s` is a non-empty identifier.
fn is_identifier(s: &str) -> bool {
    !s.is_empty() && s.chars().all(|c| c.is_ascii_alphanumeric() || c == '_')
}

/// The producer a backticked span names, if it names one.
fn producer(span: &str) -> Option<Producer> {
    if let Some((file, function)) = span.split_once("::") {
        let path_like = file
            .chars()
            .all(|c| c.is_ascii_alphanumeric() || matches!(c, '/' | '_' | '.' | '-'));
        return ((file.starts_with("tests/") || file.starts_with("pipeline/"))
            && file.ends_with(".rs")
            && path_like
            && is_identifier(function))
        .then(|| Producer::Test {
            file: file.to_string(),
            function: function.to_string(),
        });
    }
    const BENCH: &str = "cargo bench --bench ";
    if let Some(at) = span.find(BENCH) {
        let env = span[..at]
            .split_whitespace()
            .filter_map(|w| w.split_once('=').map(|(k, _)| k.to_string()))
            .collect();
        let rest = &span[at + BENCH.len()..];
        let name = rest.split_whitespace().next().unwrap_or("").to_string();
        let filter = rest
            .split_once(" -- ")
            .and_then(|(_, f)| f.split_whitespace().next())
            .filter(|w| !w.starts_with('-'))
            .map(str::to_string);
        return Some(Producer::Bench { name, filter, env });
    }
    let mut words = span.split_whitespace();
    if words.next() == Some("python3") {
        let path = words.next()?;
        return (path.contains('/') && path.ends_with(".py")).then(|| Producer::Script {
            path: path.to_string(),
        });
    }
    None
}

/// Every producer `text` names in backticks.
fn producers(text: &str) -> Vec<Producer> {
    paragraphs(text)
        .iter()
        .flat_map(|p| {
            p.split('`')
                .skip(1)
                .step_by(2)
                .filter_map(|span| producer(span.trim()))
                .collect::<Vec<_>>()
        })
        .collect()
}

/// What is wrong with `p` in the repository at `root`, if anything.
fn missing(root: &Path, p: &Producer) -> Option<String> {
    let source = |path: &Path| std::fs::read_to_string(path).ok();
    match p {
        Producer::Test { file, function } => match source(&root.join(file)) {
            None => Some(format!("`{file}::{function}`: no file {file}")),
            Some(text) => (!text.contains(&format!("fn {function}(")))
                .then(|| format!("`{file}::{function}`: no `fn {function}` in {file}")),
        },
        Producer::Bench { name, filter, env } => {
            let cargo = source(&root.join("Cargo.toml")).unwrap_or_default();
            if !cargo.contains(&format!("[[bench]]\nname = \"{name}\"")) {
                return Some(format!(
                    "`cargo bench --bench {name}`: no such [[bench]] in Cargo.toml"
                ));
            }
            let Some(text) = source(&root.join(format!("benches/{name}.rs"))) else {
                return Some(format!(
                    "`cargo bench --bench {name}`: no benches/{name}.rs"
                ));
            };
            if let Some(var) = env.iter().find(|v| !text.contains(&format!("\"{v}\""))) {
                return Some(format!(
                    "`cargo bench --bench {name}`: benches/{name}.rs reads no {var}"
                ));
            }
            let filter = filter.as_deref().unwrap_or("");
            filter
                .split('/')
                .find(|part| !part.is_empty() && !text.contains(part))
                .map(|part| {
                    format!(
                        "`cargo bench --bench {name} -- {filter}`: benches/{name}.rs has no `{part}`"
                    )
                })
        }
        Producer::Script { path } => {
            (!root.join(path).is_file()).then(|| format!("`python3 {path}`: no file {path}"))
        }
    }
}

/// Every test function and bench accuracy.md names as a number's producer
/// exists, with the filter and variables it is given.
#[test]
fn every_producer_accuracy_md_names_exists() {
    let text = read(&root().join("docs/accuracy.md"));
    let named = producers(&text);
    let tests = named
        .iter()
        .filter(|p| matches!(p, Producer::Test { .. }))
        .count();
    let benches = named
        .iter()
        .filter(|p| matches!(p, Producer::Bench { .. }))
        .count();
    assert!(
        tests >= 20 && benches >= 10,
        "docs/accuracy.md names {tests} tests and {benches} benches in the forms \
         `tests/FILE.rs::FUNCTION` and `cargo bench --bench NAME`: fewer than its numbers need"
    );
    let wrong: Vec<String> = named.iter().filter_map(|p| missing(&root(), p)).collect();
    assert!(
        wrong.is_empty(),
        "docs/accuracy.md names producers that do not exist:\n{}",
        wrong.join("\n")
    );
}

/// The producer check reports made-up names, and passes the real ones and
/// what only looks like a producer (a placeholder, a Rust path).
#[test]
fn the_producer_check_can_fail() {
    let text = "Made up: `tests/joint.rs::no_such_test_of_the_joint_fit`, \
        `tests/no_such_file.rs::a_test`, `cargo bench --bench no_such_bench`, \
        `cargo bench --bench frf -- no_such_filter`, \
        `NO_SUCH_VARIABLE=1 cargo bench --bench night` and \
        `python3 benches/scipy/no_such_script.py`.\n\n\
        Real: `tests/joint.rs::the_mismatch_suite_is_right_or_warned`, \
        `cargo bench --bench frf -- etfe_up_to_35hz`, \
        `SERVOID_NIGHT_LOGS=100 cargo bench --bench night` and \
        `python3 benches/scipy/compare.py --repeats 5`.\n\n\
        Neither: `tests/<file>.rs::<function>`, `frf::etfe_variance`, \
        `python3 identify.py`.\n";
    let named = producers(text);
    assert_eq!(named.len(), 10, "{named:#?}");
    assert_eq!(
        named[3],
        Producer::Bench {
            name: "frf".into(),
            filter: Some("no_such_filter".into()),
            env: vec![],
        }
    );
    let wrong: Vec<String> = named.iter().filter_map(|p| missing(&root(), p)).collect();
    assert_eq!(wrong.len(), 6, "{wrong:#?}");
    for name in [
        "no_such_test_of_the_joint_fit",
        "no_such_file.rs",
        "no_such_bench",
        "no_such_filter",
        "NO_SUCH_VARIABLE",
        "no_such_script.py",
    ] {
        assert!(
            wrong.iter().any(|w| w.contains(name)),
            "{name} not reported: {wrong:#?}"
        );
    }
}

/// A cell of accuracy.md's table of campaigns, "+0.006 % (+1.2)" or
/// "+0.0005 % (+0.2 std)": the relative error in per cent and the error in
/// stds, each with the number of decimals it is written with.
fn stated_error(cell: &str) -> ((f64, usize), (f64, usize)) {
    let number = |s: &str| -> (f64, usize) {
        let s = s.trim();
        let value = s
            .parse::<f64>()
            .unwrap_or_else(|e| panic!("`{s}` in `{cell}`: {e}"));
        let decimals = s.split_once('.').map_or(0, |(_, f)| f.len());
        (value, decimals)
    };
    let (pct, rest) = cell
        .split_once(" %")
        .unwrap_or_else(|| panic!("no per cent in `{cell}`"));
    let z = rest
        .split_once('(')
        .and_then(|(_, r)| r.split_once(')'))
        .map(|(z, _)| z.trim_end_matches("std").trim())
        .unwrap_or_else(|| panic!("no error in stds in `{cell}`"));
    (number(pct), number(z))
}

/// accuracy.md's row for the bundled default (table "Accuracy against
/// known truth") is what the main job identifies: each rig parameter's
/// relative error against truth.json and its error in results.json's
/// stated std, to the decimals the row writes them with. The main job is
/// run without its Monte Carlo, which takes the rig as given.
#[test]
fn the_bundled_defaults_rig_is_the_one_stated() {
    let text = read(&root().join("docs/accuracy.md"));
    let row = text
        .lines()
        .find(|l| l.starts_with("| bundled default"))
        .expect("docs/accuracy.md has a table row for the bundled default");
    let cells: Vec<&str> = row.split('|').map(str::trim).collect();
    assert!(cells.len() >= 7, "the row: {row}");
    let stated: Vec<_> = cells[2..6].iter().copied().map(stated_error).collect();

    let dir = scratch();
    let manifest = bundled_simulation(dir.path(), false);
    let out = dir.path().join("out");
    let o = servoid_into(
        dir.path(),
        "simulate",
        &manifest,
        &out,
        &["--run", "--quiet"],
    );
    assert_eq!(o.code, 0, "{}", o.stderr);
    let json = |name: &str| -> serde_json::Value {
        serde_json::from_str(&read(&out.join(name))).unwrap_or_else(|e| panic!("{name}: {e}"))
    };
    let (results, truth) = (json("results.json"), json("truth.json"));
    let keys = [
        ("beta1", "beta1_per_s"),
        ("a1b0", "a1b0_n_per_m_s2"),
        ("a2", "a2_n_per_m"),
        ("a3", "a3_per_s"),
    ];
    let mut wrong = Vec::new();
    for ((name, key), ((pct, pct_decimals), (z, z_decimals))) in keys.iter().zip(stated) {
        let value = results["rig"][*name]["value"]
            .as_f64()
            .unwrap_or_else(|| panic!("results.json: rig.{name}.value"));
        let std = results["rig"][*name]["std"]
            .as_f64()
            .unwrap_or_else(|| panic!("results.json: rig.{name}.std"));
        let true_value = truth["rig"][*key]
            .as_f64()
            .unwrap_or_else(|| panic!("truth.json: rig.{key}"));
        let got_pct = 100.0 * (value / true_value - 1.0);
        let got_z = (value - true_value) / std;
        // Half a unit of the last decimal written, and a hair for the
        // decimal text.
        let within = |got: f64, stated: f64, decimals: usize| {
            (got - stated).abs() <= 0.5 * 10f64.powi(-(decimals as i32)) + 1e-9
        };
        if !within(got_pct, pct, pct_decimals) || !within(got_z, z, z_decimals) {
            wrong.push(format!(
                "{name}: the main job gives {got_pct:+.6} % ({got_z:+.3} std), \
                 the doc states {pct:+} % ({z:+})"
            ));
        }
    }
    assert!(
        wrong.is_empty(),
        "docs/accuracy.md's bundled-default row is not what the main job gives:\n{}",
        wrong.join("\n")
    );
}
