//! The nightly batch as cron sees it: JSON-lines events and a summary on
//! stdout, run.jsonl with the timings beside results.json, and a closed
//! stdout that does not change the exit code.

use std::io::Read;
use std::process::{Command, Stdio};

use serde_json::Value;

use crate::util::{root, scratch, servoid_into};

fn paper() -> std::path::PathBuf {
    root().join("experiments/maghareh2018/paper.toml")
}

#[test]
fn json_events_name_every_run_and_end_with_a_summary() {
    let dir = scratch();
    let out = dir.path().join("out");
    let o = servoid_into(
        dir.path(),
        "run",
        &paper(),
        &out,
        &["--log-format", "json", "--figures", "none"],
    );
    assert_eq!(o.code, 0, "{}", o.stderr);
    let events: Vec<Value> = o
        .stdout
        .lines()
        .map(|l| serde_json::from_str(l).unwrap_or_else(|e| panic!("{e}: {l}")))
        .collect();
    let manifest = std::fs::read_to_string(paper()).unwrap();
    let runs = manifest.matches("[[runs]]").count();
    // paper.toml: no-specimen, two springs and Exp1-Exp4.
    assert_eq!(runs, 7);
    let of = |kind: &str| -> Vec<&Value> {
        events.iter().filter(|e| e["event"] == kind).collect()
    };
    assert_eq!(of("run_started").len(), runs);
    let finished = of("run_finished");
    assert_eq!(finished.len(), runs);
    for e in &finished {
        assert!(e["run"].is_string());
        assert!(e["seconds"].as_f64().is_some_and(|s| s >= 0.0), "{e}");
    }
    let summary = events.last().expect("events");
    assert_eq!(summary["event"], "summary");
    assert_eq!(summary["ok"], runs);
    assert_eq!(summary["failed"], 0);
    assert!(summary["logs_per_s"].as_f64().is_some_and(|r| r > 0.0));

    // run.jsonl: the campaign line, then one line per run in manifest order.
    let log = std::fs::read_to_string(out.join("run.jsonl")).unwrap();
    let lines: Vec<Value> = log.lines().map(|l| serde_json::from_str(l).unwrap()).collect();
    assert_eq!(lines.len(), runs + 1);
    assert_eq!(lines[0]["event"], "campaign");
    assert!(lines[0]["started"].as_str().is_some_and(|s| s.ends_with('Z')));
    let ids: Vec<&str> = lines[1..].iter().map(|l| l["run"].as_str().unwrap()).collect();
    assert_eq!(
        ids,
        ["no-specimen", "spring-k1", "spring-k2", "exp1", "exp2", "exp3", "exp4"]
    );
    // Nothing of the wall clock reaches results.json.
    let results = std::fs::read_to_string(out.join("results.json")).unwrap();
    assert!(!results.contains("seconds") && !results.contains("started"));
}

#[test]
fn text_output_ends_with_a_summary_line() {
    let dir = scratch();
    let out = dir.path().join("out");
    let o = servoid_into(dir.path(), "run", &paper(), &out, &["--figures", "none"]);
    assert_eq!(o.code, 0, "{}", o.stderr);
    let last = o.stdout.lines().last().unwrap();
    assert!(
        last.starts_with("summary: 7 ok, 0 failed, 0 cached in ") && last.ends_with(" logs/s)"),
        "{last}"
    );
}

/// `servoid run ... | head -1`: the reader goes away. Here it is gone
/// before servoid prints anything, so every line meets a closed pipe. The
/// run still completes, writes its outputs and exits with its own code (0),
/// not a panic (101).
#[test]
fn a_closed_stdout_is_not_a_panic() {
    let dir = scratch();
    let out = dir.path().join("out");
    let mut child = Command::new(env!("CARGO_BIN_EXE_servoid"))
        .args(["run", paper().to_str().unwrap(), "--out", out.to_str().unwrap()])
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    drop(child.stdout.take());
    let mut stderr = String::new();
    child.stderr.take().unwrap().read_to_string(&mut stderr).unwrap();
    let status = child.wait().unwrap();
    assert_eq!(status.code(), Some(0), "stderr:\n{stderr}");
    assert!(!stderr.contains("panicked"), "{stderr}");
    assert!(out.join("results.json").is_file());
}
