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
    let of = |kind: &str| -> Vec<&Value> { events.iter().filter(|e| e["event"] == kind).collect() };
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
    let lines: Vec<Value> = log
        .lines()
        .map(|l| serde_json::from_str(l).unwrap())
        .collect();
    assert_eq!(lines.len(), runs + 1);
    assert_eq!(lines[0]["event"], "campaign");
    assert!(
        lines[0]["started"]
            .as_str()
            .is_some_and(|s| s.ends_with('Z'))
    );
    let ids: Vec<&str> = lines[1..]
        .iter()
        .map(|l| l["run"].as_str().unwrap())
        .collect();
    assert_eq!(
        ids,
        [
            "no-specimen",
            "spring-k1",
            "spring-k2",
            "exp1",
            "exp2",
            "exp3",
            "exp4"
        ]
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
        .args([
            "run",
            paper().to_str().unwrap(),
            "--out",
            out.to_str().unwrap(),
        ])
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    drop(child.stdout.take());
    let mut stderr = String::new();
    child
        .stderr
        .take()
        .unwrap()
        .read_to_string(&mut stderr)
        .unwrap();
    let status = child.wait().unwrap();
    assert_eq!(status.code(), Some(0), "stderr:\n{stderr}");
    assert!(!stderr.contains("panicked"), "{stderr}");
    assert!(out.join("results.json").is_file());
}

/// The bundled default simulated twice (seeds 2018 and 7), its manifest
/// without the logs' pinned hashes so that a log can be swapped for the
/// other seed's.
struct Night {
    dir: tempfile::TempDir,
}

impl Night {
    fn new() -> Self {
        let dir = scratch();
        let sim =
            std::fs::read_to_string(crate::util::bundled_simulation(dir.path(), false)).unwrap();
        for (name, seed) in [("a", "2018"), ("b", "7")] {
            let text = sim.replace("seed = 2018", &format!("seed = {seed}"));
            let manifest = crate::util::write(dir.path(), &format!("{name}.toml"), &text);
            let o = servoid_into(
                dir.path(),
                "simulate",
                &manifest,
                &dir.path().join(name),
                &[],
            );
            assert_eq!(o.code, 0, "{}", o.stderr);
        }
        let campaign = dir.path().join("a/campaign.toml");
        let text = std::fs::read_to_string(&campaign).unwrap();
        let unpinned: String = text
            .lines()
            .filter(|l| !l.starts_with("sha256 = "))
            .collect::<Vec<_>>()
            .join("\n");
        assert!(!unpinned.contains("sha256 ="), "{unpinned}");
        std::fs::write(&campaign, unpinned).unwrap();
        Self { dir }
    }

    fn campaign(&self) -> std::path::PathBuf {
        self.dir.path().join("a/campaign.toml")
    }

    fn out(&self) -> std::path::PathBuf {
        self.dir.path().join("out")
    }

    /// Run the campaign into `out` with JSON events: (exit code, the runs
    /// done afresh, the runs taken from the cache, results.json).
    fn run(&self, extra: &[&str]) -> (i32, Vec<String>, Vec<String>, Vec<u8>) {
        let mut args = vec!["--log-format", "json"];
        args.extend_from_slice(extra);
        let o = servoid_into(self.dir.path(), "run", &self.campaign(), &self.out(), &args);
        let events: Vec<Value> = o
            .stdout
            .lines()
            .map(|l| serde_json::from_str(l).unwrap())
            .collect();
        let ids = |kind: &str| -> Vec<String> {
            let mut v: Vec<String> = events
                .iter()
                .filter(|e| e["event"] == kind)
                .map(|e| e["run"].as_str().unwrap().to_string())
                .collect();
            v.sort();
            v
        };
        let results = std::fs::read(self.out().join("results.json")).unwrap();
        (o.code, ids("run_finished"), ids("run_cached"), results)
    }

    /// Put run `id`'s log of the other seed in place of its own.
    fn swap_log(&self, id: &str) {
        let from = self.dir.path().join(format!("b/logs/{id}.csv"));
        let to = self.dir.path().join(format!("a/logs/{id}.csv"));
        std::fs::copy(from, to).unwrap();
    }
}

fn sorted(ids: &[&str]) -> Vec<String> {
    let mut v: Vec<String> = ids.iter().map(|s| s.to_string()).collect();
    v.sort();
    v
}

const ALL: [&str; 7] = [
    "no-specimen",
    "spring-k1",
    "spring-k2",
    "exp1",
    "exp2",
    "exp3",
    "exp4",
];
const VALIDATION: [&str; 4] = ["exp1", "exp2", "exp3", "exp4"];

/// Reruns: nothing changed is all cached and byte-identical; a changed
/// validation log redoes that run alone; a changed spring log redoes the
/// spring and every validation run (the rig changed) but not the no-specimen
/// run; `--force` redoes everything. After each change the results are the
/// bytes a fresh `--force` run gives.
#[test]
fn reruns_redo_what_changed_and_what_depends_on_it() {
    let night = Night::new();
    let (code, fresh, cached, first) = night.run(&[]);
    assert_eq!(code, 0);
    assert_eq!(fresh, sorted(&ALL));
    assert!(cached.is_empty());

    let (_, fresh, cached, again) = night.run(&[]);
    assert!(fresh.is_empty(), "{fresh:?}");
    assert_eq!(cached, sorted(&ALL));
    assert!(
        again == first,
        "a cached rerun's results.json is byte-identical"
    );

    night.swap_log("exp2");
    let (_, fresh, cached, after) = night.run(&[]);
    assert_eq!(fresh, ["exp2"]);
    assert_eq!(cached.len(), 6);
    assert!(after != first);
    let (_, _, _, forced) = night.run(&["--force"]);
    assert!(after == forced, "incremental and fresh results agree");

    night.swap_log("spring-k1");
    let (_, fresh, cached, after) = night.run(&[]);
    let mut want: Vec<&str> = VALIDATION.to_vec();
    want.push("spring-k1");
    assert_eq!(fresh, sorted(&want));
    assert_eq!(cached, sorted(&["no-specimen", "spring-k2"]));
    let (_, fresh, cached, forced) = night.run(&["--force"]);
    assert_eq!(fresh, sorted(&ALL));
    assert!(cached.is_empty());
    assert!(after == forced, "incremental and fresh results agree");
}

/// An unchanged log is not even read: its size and modification time are
/// what the cache compares. Here a log's bytes change behind servoid's back
/// with its size and time kept, and the rerun still takes the run from the
/// cache (the documented limit of stamps, as for make); a log whose time
/// changes is read and recomputed.
#[test]
fn an_unchanged_log_is_not_read_again() {
    let night = Night::new();
    let (_, _, _, first) = night.run(&[]);
    let log = night.dir.path().join("a/logs/exp3.csv");
    let modified = std::fs::metadata(&log).unwrap().modified().unwrap();
    let mut bytes = std::fs::read(&log).unwrap();
    // Another sample's last digit: same size, other content.
    let at = bytes.len() - 3;
    bytes[at] = if bytes[at] == b'1' { b'2' } else { b'1' };
    std::fs::write(&log, &bytes).unwrap();
    let f = std::fs::File::options().write(true).open(&log).unwrap();
    f.set_modified(modified).unwrap();
    drop(f);
    let (_, fresh, cached, again) = night.run(&[]);
    assert!(fresh.is_empty(), "{fresh:?}");
    assert_eq!(cached.len(), 7);
    assert!(again == first);
    // Touched: read, hashed, found changed, recomputed.
    let f = std::fs::File::options().write(true).open(&log).unwrap();
    f.set_modified(modified + std::time::Duration::from_secs(60))
        .unwrap();
    drop(f);
    let (_, fresh, _, _) = night.run(&[]);
    assert_eq!(fresh, ["exp3"]);
}

/// Parquet columns of `file` under `out/tables`, as f64 (booleans as 0/1).
fn table(out: &std::path::Path, file: &str) -> std::collections::BTreeMap<String, Vec<f64>> {
    use polars::prelude::{DataType, ParquetReader, SerReader};
    let f = std::fs::File::open(out.join("tables").join(file)).unwrap();
    let df = ParquetReader::new(f).finish().unwrap();
    df.columns()
        .iter()
        .filter(|c| c.dtype() != &DataType::String)
        .map(|c| {
            let v = c.cast(&DataType::Float64).unwrap();
            let v: Vec<f64> = v
                .f64()
                .unwrap()
                .iter()
                .map(|x| x.unwrap_or(f64::NAN))
                .collect();
            (c.name().to_string(), v)
        })
        .collect()
}

/// Each run's tables beside results.json: the model table holds the fitted
/// parameters of results.json, and the FRF table's model column is that
/// fitted n0/(s^2 + d1 s + d0) times the command's zero-order hold, computed
/// here from the parameters (exp(-jwT/2) sin(wT/2)/(wT/2), T = 1/2048 s).
#[test]
fn each_run_has_its_frf_and_model_as_parquet_tables() {
    let night = Night::new();
    let (code, _, _, results) = night.run(&[]);
    assert_eq!(code, 0);
    let results: Value = serde_json::from_slice(&results).unwrap();
    let out = night.out();
    for id in ALL {
        assert!(
            out.join(format!("tables/frf-{id}.parquet")).is_file(),
            "{id}"
        );
        assert!(
            out.join(format!("tables/model-{id}.parquet")).is_file(),
            "{id}"
        );
    }
    let run = crate::util::run_by_id(&results, "spring-k1");
    let params: Vec<f64> = serde_json::from_value(run["fit"]["params"].clone()).unwrap();
    let model = table(&out, "model-spring-k1.parquet");
    assert_eq!(model["value"], params);
    let frf = table(&out, "frf-spring-k1.parquet");
    let (n0, d1, d0) = (params[0], params[1], params[2]);
    let t = 1.0 / 2048.0;
    let fitted = frf["in_fit"].iter().filter(|b| **b == 1.0).count();
    assert!(fitted >= run["fit"]["n_bins"].as_u64().unwrap() as usize);
    for (k, f) in frf["freq_hz"].iter().enumerate().step_by(97) {
        let w = 2.0 * std::f64::consts::PI * f;
        let s = nalgebra::Complex::new(0.0, w);
        let half = w * t / 2.0;
        let hold = nalgebra::Complex::from_polar(half.sin() / half, -half);
        let h = n0 / (s * s + d1 * s + d0) * hold;
        let got = nalgebra::Complex::new(frf["model_re"][k], frf["model_im"][k]);
        assert!(
            (got - h).norm() <= 1e-10 * h.norm(),
            "{f} Hz: {got} against {h}"
        );
    }
    // The bins go to 35 Hz, the highest the figures show.
    let top = frf["freq_hz"].iter().copied().fold(0.0, f64::max);
    assert!(top <= 35.0 && top > 34.9, "{top}");
}

/// `servoid verify`: a results.json reruns to the same numbers (exit 0);
/// a number edited in it, and a log changed since, are each named (exit 1);
/// a file that is not a results.json is a usage error (exit 2).
#[test]
fn verify_reruns_the_recorded_analysis_and_names_what_differs() {
    use polars::prelude::{ParquetReader, ParquetWriter, SerReader};
    let night = Night::new();
    let (code, _, _, _) = night.run(&["--figures", "png"]);
    assert_eq!(code, 0);
    let out = night.out();
    let results = out.join("results.json");
    let verify = |extra: &[&str]| {
        let mut args = vec!["verify", results.to_str().unwrap()];
        args.extend_from_slice(extra);
        crate::util::servoid(night.dir.path(), &args)
    };
    // The record lists every output file, and `sha256sum -c` reads it as
    // it is (an independent check of the hashes).
    let record = std::fs::read_to_string(out.join("outputs.sha256")).unwrap();
    for file in [
        "results.json",
        "report.html",
        "history.parquet",
        "runs/exp1.html",
        "figures/frf-exp1.png",
        "tables/frf-exp1.parquet",
    ] {
        assert!(record.contains(&format!("  {file}\n")), "{file}: {record}");
    }
    if let Ok(o) = std::process::Command::new("sha256sum")
        .args(["--check", "--quiet", "outputs.sha256"])
        .current_dir(&out)
        .output()
    {
        assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stdout));
    }
    let files = record.lines().count();
    let o = verify(&[]);
    assert_eq!(o.code, 0, "{}{}", o.stdout, o.stderr);
    assert!(o.stdout.contains("everything matches"), "{}", o.stdout);
    // The output folder stands for its results.json.
    let o = crate::util::servoid(night.dir.path(), &["verify", out.to_str().unwrap()]);
    assert_eq!(o.code, 0, "{}{}", o.stdout, o.stderr);
    assert!(o.stdout.contains("everything matches"), "{}", o.stdout);
    assert!(
        o.stdout.contains(&format!(
            "(7 logs checked by their hashes, {files} output files by the set's record)"
        )),
        "{}",
        o.stdout
    );

    // An edited number.
    let text = std::fs::read_to_string(&results).unwrap();
    let doc: Value = serde_json::from_str(&text).unwrap();
    let a2 = doc["rig"]["a2"]["value"].as_f64().unwrap();
    let edited = text.replacen(&format!("\"value\": {a2}"), "\"value\": 1.0", 1);
    assert_ne!(edited, text);
    std::fs::write(&results, &edited).unwrap();
    let o = verify(&[]);
    assert_eq!(o.code, 1, "{}", o.stdout);
    assert!(
        o.stdout.contains(&format!(
            "differs: rig.a2.value: recorded 1.0, recomputed {a2}"
        )),
        "{}",
        o.stdout
    );
    std::fs::write(&results, &text).unwrap();

    // A figure replaced by another run's, an edited page, a table whose
    // values were doubled, a run page deleted: each named, nothing else.
    std::fs::copy(
        out.join("figures/frf-exp2.png"),
        out.join("figures/frf-exp1.png"),
    )
    .unwrap();
    let page = std::fs::read_to_string(out.join("report.html")).unwrap();
    std::fs::write(
        out.join("report.html"),
        page.replacen("<h1", "<h1 data-x", 1),
    )
    .unwrap();
    let table = out.join("tables/frf-exp1.parquet");
    let mut df = ParquetReader::new(std::fs::File::open(&table).unwrap())
        .finish()
        .unwrap();
    let names: Vec<String> = df
        .get_column_names()
        .iter()
        .map(|n| n.to_string())
        .collect();
    let doubled = names
        .iter()
        .find(|n| n.contains("mag") || n.contains("re"))
        .expect("a numeric column")
        .clone();
    let col = df.column(&doubled).unwrap().as_materialized_series() * 2.0;
    df.with_column(col.into()).unwrap();
    ParquetWriter::new(std::fs::File::create(&table).unwrap())
        .finish(&mut df)
        .unwrap();
    std::fs::remove_file(out.join("runs/exp3.html")).unwrap();
    let o = verify(&[]);
    assert_eq!(o.code, 1, "{}", o.stdout);
    let lines: Vec<&str> = o.stdout.lines().collect();
    for file in [
        "figures/frf-exp1.png",
        "report.html",
        "tables/frf-exp1.parquet",
    ] {
        assert!(
            lines
                .iter()
                .any(|l| l.starts_with(&format!("file differs: {file}: recorded sha256 "))),
            "{file}: {}",
            o.stdout
        );
    }
    assert!(
        lines.contains(&"file missing: runs/exp3.html"),
        "{}",
        o.stdout
    );
    assert!(
        o.stdout
            .contains(": 0 logs, 4 files and 0 quantities differ"),
        "{}",
        o.stdout
    );

    // A log changed since: on its own line, before everything else.
    night.swap_log("exp4");
    let o = verify(&[]);
    assert_eq!(o.code, 1, "{}", o.stdout);
    let first = o.stdout.lines().next().unwrap();
    assert!(
        first.starts_with("log differs: run exp4: exp4.csv: recorded sha256 ")
            && first.contains(", now "),
        "{}",
        o.stdout
    );
    assert!(!o.stdout.contains("runs[6].log.sha256"), "{}", o.stdout);

    // The folders moved: the message names the flag; with it, verify runs.
    let moved = night.dir.path().join("moved");
    std::fs::create_dir(&moved).unwrap();
    std::fs::rename(&out, moved.join("out")).unwrap();
    let results = moved.join("out/results.json");
    let o = crate::util::servoid(night.dir.path(), &["verify", results.to_str().unwrap()]);
    assert_eq!(o.code, 2, "{}", o.stderr);
    assert!(
        o.stderr
            .contains("(../a/campaign.toml, relative to its folder) is not there (")
            && o.stderr
                .contains("if the folder moved, give the manifest with --manifest"),
        "{}",
        o.stderr
    );
    let o = crate::util::servoid(
        night.dir.path(),
        &[
            "verify",
            results.to_str().unwrap(),
            "--manifest",
            night.campaign().to_str().unwrap(),
        ],
    );
    assert_eq!(o.code, 1, "{}", o.stderr);
    assert!(
        o.stdout.starts_with("log differs: run exp4"),
        "{}",
        o.stdout
    );

    let o = crate::util::servoid(
        night.dir.path(),
        &["verify", night.campaign().to_str().unwrap()],
    );
    assert_eq!(o.code, 2, "{}", o.stderr);
    assert!(
        o.stderr.contains("not a results.json servoid wrote"),
        "{}",
        o.stderr
    );
}

/// With `--log-format json` a night's log parser sees everything the text
/// output says: a failed run's error in its `run_failed` event,
/// each warning as an event naming its run, and a job that wrote nothing
/// (a manifest error) as an `error` event with its exit code, not only on
/// stderr.
#[test]
fn json_events_carry_errors_warnings_and_manifest_problems() {
    let events = |stdout: &str| -> Vec<Value> {
        stdout
            .lines()
            .map(|l| serde_json::from_str(l).unwrap_or_else(|e| panic!("{e}: {l}")))
            .collect()
    };
    let json = ["--log-format", "json", "--figures", "none"];

    // A run whose log is absent: its event says why.
    let dir = scratch();
    crate::corpus::copy_dir(&root().join("tests/bad/log-missing"), dir.path());
    let manifest = dir.path().join("manifest.toml");
    let o = servoid_into(dir.path(), "run", &manifest, &dir.path().join("out"), &json);
    assert_eq!(o.code, 1, "{}", o.stderr);
    let ev = events(&o.stdout);
    let failed: Vec<&Value> = ev.iter().filter(|e| e["event"] == "run_failed").collect();
    assert_eq!(failed.len(), 1, "{}", o.stdout);
    assert_eq!(failed[0]["run"], "log1");
    assert!(
        failed[0]["error"]
            .as_str()
            .unwrap()
            .ends_with("absent.csv: log file not found"),
        "{}",
        failed[0]
    );
    assert_eq!(ev.last().unwrap()["event"], "summary");

    // A run with a warning (its channels swapped): a warning event naming
    // it, before the summary, which counts it.
    let dir = scratch();
    crate::corpus::copy_dir(&root().join("tests/bad/log-swapped-columns"), dir.path());
    let manifest = dir.path().join("manifest.toml");
    let o = servoid_into(dir.path(), "run", &manifest, &dir.path().join("out"), &json);
    assert_eq!(o.code, 0, "{}", o.stderr);
    let ev = events(&o.stdout);
    let warned: Vec<&Value> = ev
        .iter()
        .filter(|e| e["event"] == "warning" && e["run"] == "log1")
        .collect();
    assert!(
        warned.iter().any(|e| e["warning"]["detail"]
            .as_str()
            .unwrap()
            .contains("the model explains only 31 % of the measured response")),
        "{}",
        o.stdout
    );
    let summary = ev.last().unwrap();
    assert_eq!(summary["event"], "summary");
    assert!(summary["warnings"].as_u64().unwrap() >= 1, "{summary}");

    // A manifest that does not parse: nothing is written, and the one
    // event says why, with the exit code.
    let bad = dir.path().join("bad.toml");
    std::fs::write(&bad, "schema_version = 1\n[campaign\n").unwrap();
    let o = servoid_into(dir.path(), "run", &bad, &dir.path().join("never"), &json);
    assert_eq!(o.code, 2, "{}", o.stderr);
    let ev = events(&o.stdout);
    assert_eq!(ev.len(), 1, "{}", o.stdout);
    assert_eq!(ev[0]["event"], "error");
    assert_eq!(ev[0]["exit"], 2);
    assert!(
        ev[0]["error"].as_str().unwrap().contains("bad.toml"),
        "{}",
        ev[0]
    );
    assert!(!dir.path().join("never").exists());
}

/// A night whose every run fails (its logs gone) computes none of its
/// comparisons with published values: the summary said "0 flagged", which
/// reads as all agreeing. It now counts those not computed, and the page
/// says so beside the flagged count.
#[test]
fn comparisons_not_computed_are_not_reported_as_agreeing() {
    let dir = scratch();
    let d = dir.path();
    let manifest = crate::shards::campaign(d);
    let mut gone = 0;
    for e in std::fs::read_dir(d.join("sim/logs")).unwrap().flatten() {
        let p = e.path();
        if p.extension().is_some_and(|x| x == "csv" || x == "parquet") {
            std::fs::remove_file(&p).unwrap();
            gone += 1;
        }
    }
    assert!(gone >= 7, "the bundled default's logs: {gone}");
    let out = d.join("out");
    let o = servoid_into(d, "run", &manifest, &out, &["--figures", "none"]);
    assert_eq!(o.code, 1, "{}", o.stderr);
    let line = o
        .stdout
        .lines()
        .find(|l| l.contains("comparisons:"))
        .unwrap_or_else(|| panic!("no comparisons line in {}", o.stdout));
    let results: serde_json::Value =
        serde_json::from_slice(&std::fs::read(out.join("results.json")).unwrap()).unwrap();
    let all = results["comparisons"].as_array().unwrap();
    let missing = all.iter().filter(|c| c["status"] == "not_computed").count();
    assert!(
        missing > 0,
        "the bundled default compares its rig with the paper's"
    );
    assert!(
        line.ends_with(&format!("0 flagged, {missing} not computed")),
        "{line}"
    );
    let page = std::fs::read_to_string(out.join("report.html")).unwrap();
    let count = format!("0 / {} ({missing} not computed)", all.len());
    assert!(page.contains(&count), "the page's count: {count}");
}
