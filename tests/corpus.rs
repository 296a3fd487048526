//! The bad-input corpus: every folder under `tests/bad/` is one
//! case, a hostile but realistic input with what servoid must answer.
//!
//! A case's `case.toml`:
//!
//! ```toml
//! about = "what is wrong, and why a lab would meet it"
//! args = ["check", "manifest.toml"]   # run in a copy of the case's folder
//! exit = 2
//! stderr = """the exact message"""     # the copy's path written {dir}
//! # For `run`: the runs that complete (status ok) in results.json, in
//! # manifest order; absent when the case writes no results.
//! completed = ["bare", "k1"]
//! # Lines stdout must have (a run's warnings are printed there).
//! stdout_has = ["warning: ..."]
//! ```
//!
//! The other files of the folder (manifests, logs) are the case's input.
//! Every case's message must name the file and the key, line and column, or
//! run; the case's `stderr` is the whole of it, so a message that loses its
//! place or its advice fails here.

use std::path::{Path, PathBuf};

use serde::Deserialize;

use crate::util::{root, scratch, servoid};

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct Case {
    about: String,
    args: Vec<String>,
    exit: i32,
    stderr: String,
    completed: Option<Vec<String>>,
    #[serde(default)]
    stdout_has: Vec<String>,
}

fn cases() -> Vec<(String, PathBuf)> {
    let dir = root().join("tests/bad");
    let mut out: Vec<(String, PathBuf)> = std::fs::read_dir(&dir)
        .expect("tests/bad exists")
        .map(|e| e.expect("a readable entry").path())
        .filter(|p| p.join("case.toml").is_file())
        .map(|p| (p.file_name().unwrap().to_string_lossy().into_owned(), p))
        .collect();
    out.sort();
    out
}

pub fn copy_dir(from: &Path, to: &Path) {
    for e in std::fs::read_dir(from).unwrap() {
        let e = e.unwrap();
        let target = to.join(e.file_name());
        if e.file_type().unwrap().is_dir() {
            std::fs::create_dir_all(&target).unwrap();
            copy_dir(&e.path(), &target);
        } else if e.file_name() != "case.toml" {
            std::fs::copy(e.path(), &target).unwrap();
        }
    }
}

/// The runs whose status is ok in `dir`'s results.json, in file order;
/// `None` without results.
fn completed(results: &Path) -> Option<Vec<String>> {
    let text = std::fs::read_to_string(results).ok()?;
    let doc: serde_json::Value = serde_json::from_str(&text).expect("results.json parses");
    Some(
        doc["runs"]
            .as_array()
            .expect("runs")
            .iter()
            .filter(|r| r["status"] == "ok")
            .map(|r| r["id"].as_str().unwrap().to_string())
            .collect(),
    )
}

/// Every case answers exactly as its case.toml says. All cases run, then
/// every mismatch is reported together.
#[test]
fn every_bad_input_gets_its_exact_answer() {
    let cases = cases();
    let mut failures = Vec::new();
    for (name, path) in &cases {
        let case: Case = toml::from_str(&std::fs::read_to_string(path.join("case.toml")).unwrap())
            .unwrap_or_else(|e| panic!("tests/bad/{name}/case.toml: {e}"));
        assert!(
            !case.about.trim().is_empty(),
            "{name}: say what the case is"
        );
        let dir = scratch();
        copy_dir(path, dir.path());
        let args: Vec<&str> = case.args.iter().map(String::as_str).collect();
        let o = servoid(dir.path(), &args);
        let place = dir.path().to_str().unwrap();
        let stderr = o.stderr.replace(place, "{dir}");
        let mut wrong = Vec::new();
        if o.code != case.exit {
            wrong.push(format!("exit {} (expected {})", o.code, case.exit));
        }
        if stderr.trim_end() != case.stderr.trim_end() {
            wrong.push(format!("stderr:\n{stderr}\n--- expected:\n{}", case.stderr));
        }
        for line in &case.stdout_has {
            if !o.stdout.lines().any(|l| l.trim() == line.trim()) {
                wrong.push(format!("stdout lacks the line {line:?}:\n{}", o.stdout));
            }
        }
        let out = args
            .windows(2)
            .find(|w| w[0] == "--out")
            .map(|w| dir.path().join(w[1]));
        let got = out.and_then(|o| completed(&o.join("results.json")));
        if got != case.completed {
            wrong.push(format!(
                "completed runs {got:?} (expected {:?})",
                case.completed
            ));
        }
        if !wrong.is_empty() {
            failures.push(format!("tests/bad/{name}: {}", wrong.join("; ")));
        }
    }
    eprintln!("{} bad-input cases", cases.len());
    assert!(failures.is_empty(), "{}", failures.join("\n\n"));
}

/// The corpus's base campaign (runs given as transfer functions, no logs).
fn base_manifest(dir: &Path) -> PathBuf {
    let from = root().join("tests/bad/manifest-unknown-key/manifest.toml");
    let text = std::fs::read_to_string(from)
        .unwrap()
        .replace("stifness_n_per_m", "stiffness_n_per_m");
    let path = dir.join("manifest.toml");
    std::fs::write(&path, text).unwrap();
    path
}

/// A closed stdout (`servoid check ... | head -0`) is not a panic: each
/// command keeps its own exit code. The pipe's read end is closed before
/// servoid starts, so every write to stdout fails.
#[test]
fn a_closed_stdout_is_not_a_panic_for_check_and_simulate() {
    use std::process::{Command, Stdio};
    let dir = scratch();
    let manifest = base_manifest(dir.path());
    let simulation = dir.path().join("simulation.toml");
    std::fs::copy(
        root().join("tests/bad/manifest-simulation-to-run/simulation.toml"),
        &simulation,
    )
    .unwrap();
    let cases: [(&[&str], i32); 4] = [
        (&["check", manifest.to_str().unwrap()], 0),
        (&["check", "absent.toml"], 2),
        (
            &["simulate", simulation.to_str().unwrap(), "--out", "sim"],
            0,
        ),
        (&["run", manifest.to_str().unwrap(), "--out", "out"], 0),
    ];
    for (args, code) in cases {
        let (reader, writer) = std::io::pipe().expect("a pipe");
        drop(reader);
        let out = Command::new(env!("CARGO_BIN_EXE_servoid"))
            .args(args)
            .current_dir(dir.path())
            .stdout(Stdio::from(writer))
            .stderr(Stdio::piped())
            .output()
            .expect("servoid runs");
        let stderr = String::from_utf8_lossy(&out.stderr);
        assert!(!stderr.contains("panicked"), "{args:?}: {stderr}");
        assert_eq!(out.status.code(), Some(code), "{args:?}: {stderr}");
    }
}

/// `--jobs` above four per core is lowered to that with a warning (100,000
/// threads stalled the machine); `--jobs 0` is a usage error.
#[test]
fn jobs_are_capped_at_four_per_core_and_zero_is_refused() {
    let dir = scratch();
    let manifest = base_manifest(dir.path());
    let cores = std::thread::available_parallelism().map_or(1, |n| n.get());
    let with_jobs = |jobs: &str| {
        servoid(
            dir.path(),
            &[
                "run",
                manifest.to_str().unwrap(),
                "--out",
                "out",
                "--jobs",
                jobs,
            ],
        )
    };
    let o = with_jobs("100000");
    assert_eq!(o.code, 0, "{}", o.stderr);
    assert_eq!(
        o.stderr.trim(),
        format!(
            "warning: --jobs 100000 is more than 4 per core ({cores} cores): using {}",
            4 * cores
        )
    );
    let o = with_jobs("0");
    assert_eq!(o.code, 2, "{}", o.stderr);
    assert!(
        o.stderr.contains("invalid value '0' for '--jobs <JOBS>'"),
        "{}",
        o.stderr
    );
}

/// A log over `[limits] max_log_mib` (default 4096) fails its run alone
/// before a byte is read, with the size, the limit and what to do; the
/// other runs complete. The log is a sparse file of 5 GiB, which takes no
/// disk.
#[test]
fn a_log_over_the_size_limit_fails_its_run_before_it_is_read() {
    let dir = scratch();
    let text = std::fs::read_to_string(root().join("tests/bad/log-empty/manifest.toml"))
        .unwrap()
        .replace("empty.csv", "huge.csv");
    std::fs::write(dir.path().join("manifest.toml"), text).unwrap();
    let huge = std::fs::File::create(dir.path().join("huge.csv")).unwrap();
    huge.set_len(5 << 30).unwrap();
    drop(huge);
    let o = servoid(
        dir.path(),
        &["run", "manifest.toml", "--out", "out", "--figures", "none"],
    );
    assert_eq!(o.code, 1, "{}", o.stderr);
    assert_eq!(
        o.stderr.trim(),
        "error: run log1: huge.csv: the log is 5120.0 MiB, over the limit of 4096 MiB: raise [limits] max_log_mib if this machine has some 25600 MiB of memory to spare, or split the log"
    );
    assert_eq!(
        completed(&dir.path().join("out/results.json")),
        Some(vec!["ns".to_string(), "k1".into(), "exp1".into()])
    );
}
