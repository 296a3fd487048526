//! The rig's history across nights and its drift alarm, end to end: a
//! simulated sequence of nights whose servo-valve pole beta1 drops 1 % a
//! night raises the alarm (exit code 3, results.json, stderr) on the night
//! the rule predicts and not before; a stable rig never raises it; a rerun
//! of a night adds nothing to the history.

use std::path::Path;

use serde_json::Value;

use crate::util::{scratch, servoid_into, write};

/// One night of the paper's identification runs (no specimen and two
/// springs; 20 s chirps at 2048 Hz), the rig's beta1 as given.
fn night_manifest(beta1: f64, seed: u64) -> String {
    night_manifest_delayed(beta1, seed, 0.0)
}

/// The same with the displacement transducer `delay_s` late: the actuator's
/// measured delay grows by as much.
fn night_manifest_delayed(beta1: f64, seed: u64, delay_s: f64) -> String {
    format!(
        r#"schema_version = 1

[simulation]
name = "night"
sample_rate_hz = 2048.0
seed = {seed}

[rig]
name = "frame B"

[rig.parameters]
beta1_per_s = {beta1}
a1b0_n_per_m_s2 = 2.412e9
a2_n_per_m = 7.881e5
a3_per_s = 16.118
p_gain = 1.0

[excitation]
kind = "chirp"
f0_hz = 0.5
f1_hz = 35.0
duration_s = 20.0
amplitude_m = 0.004
lead_in_s = 0.5
lead_out_s = 0.5

[instrument.command]
unit = "mm"

[instrument.displacement]
unit = "mm"
noise_rms = 0.1
delay_s = {delay_s:e}

[instrument.force]
unit = "kN"
noise_rms = 0.001

[identification]
band_hz = [0.5, 30.0]
frf = {{ estimator = "etfe", segment_length = 4096, window = "rectangular" }}

[[runs]]
id = "bare"
role = "no_specimen"
p_gain = 1.0

[[runs]]
id = "k1"
role = "spring"
p_gain = 1.0
specimen = {{ stiffness_n_per_m = 116640.0 }}

[[runs]]
id = "k2"
role = "spring"
p_gain = 1.0
specimen = {{ stiffness_n_per_m = 88540.0 }}
"#
    )
}

/// Simulate night `n` and run it into `out`: (exit code, results.json,
/// stderr).
fn night(dir: &Path, out: &Path, n: usize, beta1: f64) -> (i32, Value, String) {
    night_of(dir, out, n, &night_manifest(beta1, 100 + n as u64))
}

fn night_of(dir: &Path, out: &Path, n: usize, manifest: &str) -> (i32, Value, String) {
    let name = format!("night-{n}");
    let sim = write(dir, &format!("{name}.toml"), manifest);
    let folder = dir.join(&name);
    let o = servoid_into(dir, "simulate", &sim, &folder, &["--quiet"]);
    assert_eq!(o.code, 0, "{}", o.stderr);
    let o = servoid_into(
        dir,
        "run",
        &folder.join("campaign.toml"),
        out,
        &["--quiet", "--figures", "none"],
    );
    let results =
        serde_json::from_slice(&std::fs::read(out.join("results.json")).unwrap()).unwrap();
    (o.code, results, o.stderr)
}

/// The rule, restated from its description in docs/manifest.md: the median of
/// up to K = 10 earlier values (at least 3), the history's scatter from
/// successive differences (1.4826 MAD / sqrt 2), the limit 4 max(std,
/// scatter), and at least `floor` (the delay's 0.25 ms; 0 for the rig's
/// parameters).
fn rule_alarms(values: &[(f64, f64)], floor: f64) -> Vec<bool> {
    fn median(v: &[f64]) -> f64 {
        let mut s = v.to_vec();
        s.sort_by(f64::total_cmp);
        let n = s.len();
        if n % 2 == 1 {
            s[n / 2]
        } else {
            (s[n / 2 - 1] + s[n / 2]) / 2.0
        }
    }
    (0..values.len())
        .map(|n| {
            let past: Vec<f64> = values[n.saturating_sub(10)..n]
                .iter()
                .map(|v| v.0)
                .collect();
            if past.len() < 3 {
                return false;
            }
            let d: Vec<f64> = past.windows(2).map(|w| w[1] - w[0]).collect();
            let md = median(&d);
            let mad = median(&d.iter().map(|x| (x - md).abs()).collect::<Vec<_>>());
            let scatter = 1.4826 * mad / 2f64.sqrt();
            let (x, std) = values[n];
            (x - median(&past)).abs() > (4.0 * std.max(scatter)).max(floor)
        })
        .collect()
}

#[test]
fn a_drifting_valve_raises_the_alarm_on_the_night_the_rule_predicts() {
    let dir = scratch();
    let out = dir.path().join("out");
    let mut values = Vec::new();
    let mut raised = Vec::new();
    for n in 0..9 {
        let (code, results, stderr) = night(dir.path(), &out, n, 267.0 * (1.0 - 0.01 * n as f64));
        let beta1 = &results["rig"]["beta1"];
        values.push((
            beta1["value"].as_f64().unwrap(),
            beta1["std"].as_f64().unwrap(),
        ));
        let drift = &results["drift"];
        assert_eq!(drift["earlier_entries"], n, "night {n}");
        let alarm = drift["checks"][0]["alarm"].as_bool().unwrap();
        assert_eq!(
            code == 3,
            !drift["alarms"].as_array().unwrap().is_empty(),
            "night {n}"
        );
        if alarm {
            assert_eq!(code, 3, "night {n}: {stderr}");
            assert!(
                stderr.contains("ALARM: rig `frame B`: beta1 = "),
                "{stderr}"
            );
        }
        raised.push(alarm);
    }
    let predicted = rule_alarms(&values, 0.0);
    assert_eq!(raised, predicted, "values (beta1, std): {values:?}");
    // The rule fires within the nine nights, but not on night 3, the first
    // it can check (3 earlier entries): there the median lags 2 % behind,
    // inside 4 times the stated std (about 0.7 % with this LVDT noise).
    let first = predicted.iter().position(|a| *a).expect("an alarm");
    assert!(first > 3, "{values:?}");
    crate::util::note(&format!(
        "drift: beta1 std {:.3} % of its value; first alarm on night {first} of 0-8",
        100.0 * values[0].1 / values[0].0
    ));
    // Every night is in the history, in order.
    let history = out.join("history.parquet");
    assert!(history.is_file());
}

#[test]
fn a_stable_rig_never_raises_it_and_a_rerun_adds_nothing() {
    let dir = scratch();
    let out = dir.path().join("out");
    for n in 0..8 {
        let (code, results, stderr) = night(dir.path(), &out, n, 267.0);
        assert_eq!(code, 0, "night {n}: {stderr}");
        assert_eq!(results["drift"]["earlier_entries"], n);
        assert!(results["drift"]["alarms"].as_array().unwrap().is_empty());
    }
    // Night 7 again: same inputs, same entry, same bytes.
    let before = std::fs::read(out.join("results.json")).unwrap();
    let history_before = std::fs::read(out.join("history.parquet")).unwrap();
    let o = servoid_into(
        dir.path(),
        "run",
        &dir.path().join("night-7/campaign.toml"),
        &out,
        &["--quiet", "--figures", "none"],
    );
    assert_eq!(o.code, 0);
    assert!(std::fs::read(out.join("results.json")).unwrap() == before);
    assert!(std::fs::read(out.join("history.parquet")).unwrap() == history_before);
}

/// A history that cannot be read is the night's failure, not a line in
/// results.json: before, a truncated table gave exit
/// 0, nothing on stderr, a warning naming the deleted work folder, and no
/// update ever again (the drift alarm off for good). Each update keeps the
/// table it replaces as `history.parquet.prev`, which the message names
/// as the way back; a lab's own column survives the updates.
#[test]
fn an_unreadable_history_fails_the_night_and_says_how_to_recover() {
    use polars::prelude::{Column, ParquetReader, ParquetWriter, SerReader};
    let dir = scratch();
    let out = dir.path().join("out");
    let history = out.join("history.parquet");
    let prev = out.join("history.parquet.prev");
    assert_eq!(night(dir.path(), &out, 0, 267.0).0, 0);
    assert!(!prev.exists(), "no previous table yet");
    // The lab adds an operator column by hand.
    let mut df = ParquetReader::new(std::fs::File::open(&history).unwrap())
        .finish()
        .unwrap();
    df.with_column(Column::new("operator".into(), ["ana"]))
        .unwrap();
    ParquetWriter::new(std::fs::File::create(&history).unwrap())
        .finish(&mut df)
        .unwrap();
    let by_hand = std::fs::read(&history).unwrap();
    assert_eq!(night(dir.path(), &out, 1, 267.0).0, 0);
    assert_eq!(std::fs::read(&prev).unwrap(), by_hand);
    let table =
        servoid::ingest::read_table(&history, servoid::ingest::TableFormat::Parquet).unwrap();
    let op = table.column("operator").expect("the lab's column is kept");
    let campaign = table.column("campaign").unwrap();
    assert_eq!(table.rows.len(), 2);
    assert_eq!(table.rows[0][op].as_deref(), Some("ana"));
    assert_eq!(table.rows[1][op], None);
    assert!(table.rows.iter().all(|r| r[campaign].is_some()));

    // Truncated (a copy cut short): night 2 fails, on stderr and as a JSON
    // event, naming the file where the user knows it and the copy to
    // restore; the table is left as it was for someone to look at.
    let good = std::fs::read(&history).unwrap();
    std::fs::write(&history, &good[..good.len() / 2]).unwrap();
    let sim = dir.path().join("night-1/campaign.toml");
    let o = servoid_into(
        dir.path(),
        "run",
        &sim,
        &out,
        &["--figures", "none", "--log-format", "json"],
    );
    assert_eq!(o.code, 1, "{}", o.stderr);
    let shown = history.display().to_string();
    assert!(
        o.stderr
            .contains(&format!("error: the rig history {shown} cannot be read (")),
        "{}",
        o.stderr
    );
    assert!(
        o.stderr.contains(&format!(
            "its previous good copy is {shown}.prev: restore it"
        )),
        "{}",
        o.stderr
    );
    assert!(!o.stderr.contains(".servoid-"), "{}", o.stderr);
    let event = o
        .stdout
        .lines()
        .map(|l| serde_json::from_str::<Value>(l).unwrap())
        .find(|v| v["event"] == "history_unreadable")
        .expect("a history_unreadable event");
    assert!(event["error"].as_str().unwrap().contains("cannot be read"));
    assert_eq!(std::fs::read(&history).unwrap(), &good[..good.len() / 2]);
    // Restored as the message says, the next night updates it again.
    std::fs::copy(&prev, &history).unwrap();
    let (code, results, stderr) = night(dir.path(), &out, 2, 267.0);
    assert_eq!(code, 0, "{stderr}");
    assert_eq!(results["drift"]["earlier_entries"], 1);
}

/// A rig renamed by accident (`frame B` -> `Frame B`) starts a new history,
/// and its drift goes unchecked against the old one: the night says so,
/// naming the close name. A rig of another name says nothing.
#[test]
fn a_renamed_rig_is_told_it_starts_a_new_history() {
    let dir = scratch();
    let out = dir.path().join("out");
    assert_eq!(night(dir.path(), &out, 0, 267.0).0, 0);
    let (code, _, stderr) = night(dir.path(), &out, 1, 267.0);
    assert_eq!(code, 0, "{stderr}");
    let manifest = dir.path().join("night-1/campaign.toml");
    let text = std::fs::read_to_string(&manifest).unwrap();
    assert!(text.contains("name = \"frame B\""));
    let run_as = |name: &str| -> Value {
        let renamed = write(
            dir.path(),
            "night-1/renamed.toml",
            &text.replace("name = \"frame B\"", &format!("name = \"{name}\"")),
        );
        let o = servoid_into(dir.path(), "run", &renamed, &out, &["--figures", "none"]);
        assert_eq!(o.code, 0, "{}", o.stderr);
        serde_json::from_slice(&std::fs::read(out.join("results.json")).unwrap()).unwrap()
    };
    let said = "rig `Frame B` starts a new history in history.parquet, which holds 2 entries of rig `frame B`: if that is this rig renamed, give [rig] name = \"frame B\" to check its drift against them";
    let results = run_as("Frame B");
    assert_eq!(results["drift"]["earlier_entries"], 0);
    let warnings: Vec<&str> = results["warnings"]
        .as_array()
        .unwrap()
        .iter()
        .map(|w| w["detail"].as_str().unwrap())
        .collect();
    assert!(warnings.contains(&said), "{warnings:?}");
    let results = run_as("shake table 2");
    let warnings = results["warnings"].to_string();
    assert!(!warnings.contains("starts a new history"), "{warnings}");
}

/// A transducer (or valve) that adds 0.5 ms of delay a night: the night's
/// measured delay grows by as much (within the 20 s sweeps' night-to-night
/// scatter, about 0.07 ms here), and the delay's alarm fires where the rule
/// restated here predicts from the reported delays: on night 3, the first
/// with three nights before it, whose median is a whole millisecond behind.
#[test]
fn a_delay_that_grows_raises_the_delay_alarm_on_the_night_the_rule_predicts() {
    let dir = scratch();
    let out = dir.path().join("out");
    let step = 0.5e-3;
    let mut delays = Vec::new();
    let mut raised = Vec::new();
    for n in 0..6 {
        let manifest = night_manifest_delayed(267.0, 300 + n as u64, step * n as f64);
        let (code, results, stderr) = night_of(dir.path(), &out, n, &manifest);
        let checks = results["drift"]["checks"].as_array().unwrap();
        let delay = checks
            .iter()
            .find(|c| c["parameter"] == "delay")
            .unwrap_or_else(|| panic!("night {n}: a delay check in {checks:?}"));
        delays.push(delay["value"].as_f64().unwrap());
        let alarm = delay["alarm"].as_bool().unwrap();
        if alarm {
            assert_eq!(code, 3, "night {n}: {stderr}");
            assert!(
                stderr.contains("ALARM: rig `frame B`: delay = "),
                "{stderr}"
            );
        }
        raised.push(alarm);
    }
    // The measured delay follows the transducer's, night by night, within
    // its scatter.
    for n in 1..delays.len() {
        let grew = delays[n] - delays[0];
        assert!(
            (grew - step * n as f64).abs() < 0.25e-3,
            "night {n}: grew {grew} s, not {} s: {delays:?}",
            step * n as f64
        );
    }
    // The rule, restated, with the delay's floor and no stated std.
    let values: Vec<(f64, f64)> = delays.iter().map(|d| (*d, 0.0)).collect();
    let predicted = rule_alarms(&values, 0.25e-3);
    assert_eq!(raised, predicted, "delays: {delays:?}");
    assert_eq!(
        raised.iter().position(|a| *a),
        Some(3),
        "the first alarm on night 3: {delays:?}"
    );
    crate::util::note(&format!(
        "drift: the bare actuator's delay {:.3} ms on night 0, growing 0.5 ms a night; the delay alarm on night 3",
        1e3 * delays[0]
    ));
}

/// A night corrected. The bundled default's logs, dated 2026-11-20, run
/// first with spring k1's stiffness mistyped (+5 %), then again with it
/// right: both rows stayed in the history, the wrong one too, and nothing
/// could drop it. Now the corrected night (same rig, campaign, date, logs)
/// replaces the wrong row and says so, the audit file beside the history
/// keeps what was replaced, and `servoid history remove --date` takes out
/// a night's row, recorded there too.
#[test]
fn a_corrected_night_replaces_its_row_and_a_row_can_be_removed() {
    let dir = scratch();
    let d = dir.path();
    let manifest = crate::shards::campaign(d);
    let text = std::fs::read_to_string(&manifest).unwrap();
    let dated = |date: &str, text: &str| {
        text.replace(
            "role = \"no_specimen\"\n",
            &format!("role = \"no_specimen\"\ndate = \"{date}\"\n"),
        )
    };
    let k1 = "stiffness_n_per_m = 116640.0";
    assert!(text.contains(k1), "spring k1 as the bundled default has it");
    let night = |name: &str, text: String| {
        let path = d.join(format!("sim/{name}.toml"));
        std::fs::write(&path, text).unwrap();
        path
    };
    let wrong = night(
        "wrong",
        dated("2026-11-20", &text).replace(k1, "stiffness_n_per_m = 122472.0"),
    );
    let right = night("right", dated("2026-11-20", &text));
    let next = night("next", dated("2026-11-21", &text));
    let out = d.join("night");
    let history = out.join("history.parquet");
    let audit = out.join("history.parquet.audit.jsonl");
    let run = |m: &Path| {
        let o = servoid_into(d, "run", m, &out, &["--quiet", "--figures", "none"]);
        assert!(o.code == 0 || o.code == 3, "{}", o.stderr);
        let results: Value =
            serde_json::from_slice(&std::fs::read(out.join("results.json")).unwrap()).unwrap();
        results
    };
    let a1b0_of = |r: &Value| r["rig"]["a1b0"]["value"].as_f64().unwrap();
    let first = run(&wrong);
    assert!(!audit.exists());
    let second = run(&right);
    let said: Vec<&str> = second["warnings"]
        .as_array()
        .unwrap()
        .iter()
        .filter_map(|w| w["detail"].as_str())
        .filter(|w| w.starts_with("history: this night's logs were analysed before"))
        .collect();
    assert_eq!(said.len(), 1, "{}", second["warnings"]);
    assert!(said[0].contains("date 2026-11-20"), "{}", said[0]);
    // The table holds the corrected night alone.
    let rows = history_rows(&history);
    assert_eq!(rows.len(), 1, "{rows:?}");
    assert_eq!(rows[0].1, a1b0_of(&second));
    assert!(
        (a1b0_of(&first) / a1b0_of(&second) - 1.0).abs() > 0.01,
        "the typo moved a1b0"
    );
    // The audit keeps the wrong row.
    let records: Vec<Value> = std::fs::read_to_string(&audit)
        .unwrap()
        .lines()
        .map(|l| serde_json::from_str(l).unwrap())
        .collect();
    assert_eq!(records.len(), 1);
    assert_eq!(records[0]["action"], "replaced");
    assert_eq!(
        records[0]["entry"]["a1b0"].as_f64().unwrap(),
        a1b0_of(&first)
    );
    // Rerun, the corrected night gives the same results, saying the same.
    let bytes = std::fs::read(out.join("results.json")).unwrap();
    run(&right);
    assert!(std::fs::read(out.join("results.json")).unwrap() == bytes);
    assert_eq!(std::fs::read_to_string(&audit).unwrap().lines().count(), 1);
    // Another date is another night, kept beside it; then removed by date.
    run(&next);
    assert_eq!(history_rows(&history).len(), 2);
    let o = crate::util::servoid(
        d,
        &[
            "history",
            "remove",
            history.to_str().unwrap(),
            "--date",
            "2026-11-21",
        ],
    );
    assert_eq!(o.code, 0, "{}", o.stderr);
    assert!(
        o.stdout.contains("removed the entry of rig"),
        "{}",
        o.stdout
    );
    let rows = history_rows(&history);
    assert_eq!(rows.len(), 1);
    assert_eq!(rows[0].0.as_deref(), Some("2026-11-20"));
    let records = std::fs::read_to_string(&audit).unwrap();
    let last: Value = serde_json::from_str(records.lines().last().unwrap()).unwrap();
    assert_eq!(last["action"], "removed");
    assert_eq!(last["entry"]["date"], "2026-11-21");
    // A date with no entry removes nothing and says which dates there are.
    let o = crate::util::servoid(
        d,
        &[
            "history",
            "remove",
            history.to_str().unwrap(),
            "--date",
            "2026-12-01",
        ],
    );
    assert_eq!(o.code, 2);
    assert!(
        o.stderr
            .contains("no entry of date 2026-12-01 (its dates: 2026-11-20)"),
        "{}",
        o.stderr
    );
    assert_eq!(history_rows(&history).len(), 1);
}

/// The history's rows as (date, a1b0), read by polars.
fn history_rows(path: &Path) -> Vec<(Option<String>, f64)> {
    use polars::prelude::{ParquetReader, SerReader};
    let file = std::fs::File::open(path).unwrap();
    let df = ParquetReader::new(file).finish().unwrap();
    let dates = df.column("date").unwrap().str().unwrap().clone();
    let a1b0 = df.column("a1b0").unwrap().f64().unwrap().clone();
    dates
        .iter()
        .zip(a1b0.iter())
        .map(|(d, a)| (d.map(str::to_string), a.unwrap()))
        .collect()
}
