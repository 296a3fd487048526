//! Runs named by a side table (`[run_table]`, CSV or Parquet) and a glob or
//! a folder of logs, end to end: the same results as the same runs written
//! as `[[runs]]` tables; every bad row reported at once with its row and
//! column, beside the manifest's own problems (exit 2, nothing written); ids
//! unique across both; a missing log failing its run alone (exit 1); an
//! unreadable table one problem naming it; dates checked and normalised.

use std::path::{Path, PathBuf};

use polars::prelude::{Column, DataFrame, ParquetWriter};
use serde_json::Value;

use crate::util::{paper_tf_runs, run_by_id, scratch, servoid, servoid_into, write};

/// A short simulated campaign (20 s linear chirp at 1 kHz, as in
/// tests/simulate.rs): no specimen, two springs and two validation runs with
/// a specimen mass (so they have a controllable canonical form). No run has
/// a description: a table row has none.
fn sim() -> String {
    include_str!("fixtures/small-simulation.toml")
        .replace("name = \"cli-test\"", "name = \"table-test\"")
        .replace("seed = 7", "seed = 11")
        .replace(
            "[[runs]]\nid = \"v1\"",
            "[[runs]]\nid = \"k2\"\nrole = \"spring\"\np_gain = 1.0\nspecimen = { stiffness_n_per_m = 80000.0 }\n\n[[runs]]\nid = \"v1\"",
        )
        + r#"
[[runs]]
id = "v2"
role = "validation"
p_gain = 1.0
specimen = { mass_kg = 3.0, damping_ns_per_m = 5.0, stiffness_n_per_m = 90000.0 }
"#
}

/// sim()'s runs as a CSV run table, in its order.
const TABLE_CSV: &str = "\
id,role,p_gain,mass_kg,damping_ns_per_m,stiffness_n_per_m,date
bare,no_specimen,1,,,,2024-05-01
k1,spring,1,,,100000,2024-05-01T09:00:00Z
k2,spring,1,,,80000,
v1,validation,1.5,4,10,120000,
v2,validation,1.0,3,5,90000,
";

/// Simulate sim() into `dir/sim` (logs, truth and the `[[runs]]` manifest
/// `campaign.toml`) and return that folder.
fn simulate(dir: &Path) -> PathBuf {
    let sim = write(dir, "sim.toml", &sim());
    let out = dir.join("sim");
    let o = servoid_into(dir, "simulate", &sim, &out, &["--quiet"]);
    assert_eq!(o.code, 0, "simulate: {}", o.stderr);
    out
}

/// The simulated `[[runs]]` manifest with its runs replaced by a
/// `[run_table]` of `run_table` (TOML), written as `table.toml` beside it.
fn table_manifest(sim: &Path, run_table: &str) -> PathBuf {
    let text = std::fs::read_to_string(sim.join("campaign.toml")).unwrap();
    let mut doc: toml::Table = toml::from_str(&text).unwrap();
    assert!(doc.remove("runs").is_some());
    let spec: toml::Table = toml::from_str(run_table).unwrap();
    doc.insert("run_table".into(), toml::Value::Table(spec));
    write(sim, "table.toml", &toml::to_string(&doc).unwrap())
}

fn run(dir: &Path, manifest: &Path, out: &str) -> (i32, String, Value) {
    let out = dir.join(out);
    let o = servoid_into(
        dir,
        "run",
        manifest,
        &out,
        &["--figures", "none", "--quiet"],
    );
    let results = std::fs::read(out.join("results.json"))
        .map(|b| serde_json::from_slice(&b).unwrap())
        .unwrap_or(Value::Null);
    (o.code, o.stderr, results)
}

/// `runs` as written in `[[runs]]` tables and as the table gives them give
/// the same `runs`, `rig` and `ccf` in results.json, value for value.
/// Returns the table campaign's results.
fn assert_same_results(sim: &Path, table: &Path) -> Value {
    let (code, stderr, listed) = run(sim, &sim.join("campaign.toml"), "out-runs");
    assert_eq!(code, 0, "{stderr}");
    let (code, stderr, tabled) = run(sim, table, "out-table");
    assert_eq!(code, 0, "{stderr}");
    let ids = |r: &Value| -> Vec<String> {
        r["runs"]
            .as_array()
            .unwrap()
            .iter()
            .map(|x| x["id"].as_str().unwrap().to_string())
            .collect()
    };
    assert_eq!(ids(&tabled), ["bare", "k1", "k2", "v1", "v2"]);
    for id in ["bare", "k1", "k2", "v1", "v2"] {
        assert_eq!(run_by_id(&tabled, id)["status"], "ok", "{id}");
    }
    assert_eq!(listed["runs"], tabled["runs"]);
    assert!(listed["rig"]["beta1"]["value"].as_f64().unwrap() > 0.0);
    assert_eq!(listed["rig"], tabled["rig"]);
    assert_eq!(listed["ccf"].as_array().unwrap().len(), 2);
    assert_eq!(listed["ccf"], tabled["ccf"]);
    assert_eq!(tabled["manifest"]["runs"], Value::Array(Vec::new()));
    tabled
}

#[test]
fn a_csv_table_and_a_glob_of_csv_logs_give_the_runs_of_runs_tables() {
    let dir = scratch();
    let sim = simulate(dir.path());
    std::fs::create_dir_all(sim.join("night")).unwrap();
    write(&sim, "night/specimens.csv", TABLE_CSV);
    let table = table_manifest(
        &sim,
        "file = \"night/specimens.csv\"\nlogs = \"logs/*.csv\"",
    );
    let tabled = assert_same_results(&sim, &table);
    assert_eq!(
        tabled["manifest"]["run_table"],
        serde_json::json!({ "file": "night/specimens.csv", "logs": "logs/*.csv" })
    );
}

#[test]
fn a_parquet_table_and_a_folder_of_logs_give_the_runs_of_runs_tables() {
    let dir = scratch();
    let sim = simulate(dir.path());
    let mut df = DataFrame::new_infer_height(vec![
        Column::new("id".into(), ["bare", "k1", "k2", "v1", "v2"]),
        Column::new(
            "role".into(),
            [
                "no_specimen",
                "spring",
                "spring",
                "validation",
                "validation",
            ],
        ),
        Column::new("p_gain".into(), [1.0, 1.0, 1.0, 1.5, 1.0]),
        Column::new("mass_kg".into(), [None, None, None, Some(4.0), Some(3.0)]),
        Column::new(
            "damping_ns_per_m".into(),
            [None, None, None, Some(10.0), Some(5.0)],
        ),
        // Integers: a Parquet table may hold any numeric type.
        Column::new(
            "stiffness_n_per_m".into(),
            [
                None,
                Some(100_000_i64),
                Some(80_000),
                Some(120_000),
                Some(90_000),
            ],
        ),
        Column::new(
            "date".into(),
            [Some("2024-05-01"), None, None, Some("2024-05-02"), None],
        ),
    ])
    .unwrap();
    let mut file = std::fs::File::create(sim.join("specimens.parquet")).unwrap();
    ParquetWriter::new(&mut file).finish(&mut df).unwrap();
    let table = table_manifest(&sim, "file = \"specimens.parquet\"\nlogs = \"logs\"");
    assert_same_results(&sim, &table);
}

/// A campaign whose rig comes from the paper's published transfer
/// functions and whose validation runs (predictions, no logs) come from
/// `night/specimens.csv`.
const PREDICTIONS: &str = concat!(
    r#"schema_version = 1

[campaign]
name = "table"

[rig]
name = "test rig"

[run_table]
file = "night/specimens.csv"
predict = true

"#,
    paper_tf_runs!()
);

/// Run `manifest` (with the table `table`) and return its problem lines,
/// asserting exit code 2 and nothing written.
fn problems(manifest: &str, table: &str) -> Vec<String> {
    let dir = scratch();
    std::fs::create_dir_all(dir.path().join("night")).unwrap();
    write(dir.path(), "night/specimens.csv", table);
    write(dir.path(), "campaign.toml", manifest);
    // Relative, so that messages name the files as the manifest does.
    let o = servoid(dir.path(), &["run", "campaign.toml", "--out", "out"]);
    assert_eq!(o.code, 2, "stderr:\n{}", o.stderr);
    assert!(
        !dir.path().join("out").exists(),
        "a bad manifest writes nothing"
    );
    let mut lines = o.stderr.lines();
    let head = lines.next().unwrap();
    let listed: Vec<String> = lines.map(str::to_string).collect();
    let n = listed.len();
    let plural = if n == 1 { "" } else { "s" };
    assert_eq!(
        head,
        format!("error: campaign.toml: {n} problem{plural} in the manifest:")
    );
    listed
}

/// The 1-based line of `needle` in `text`.
fn line_of(text: &str, needle: &str) -> usize {
    text.lines().position(|l| l.contains(needle)).unwrap() + 1
}

#[test]
fn every_bad_row_is_reported_at_once_with_its_row_and_column() {
    let manifest = PREDICTIONS.replace(
        "id = \"k1\"\nrole = \"spring\"\n",
        "id = \"k1\"\nrole = \"spring\"\ndate = \"yesterday\"\n",
    );
    let table = "\
id,role,p_gain,mass_kg,dampng_ns_per_m,stiffness_n_per_m,date
exp1,validation,1,3.8,5,129400,2024-05-01
exp2,validaton,1,3.8,5,129400,
exp3,validation,0,3.8,5,129400,2024-02-30

k2,validation,1,-3.8,,-3,
,validation,one,,,,
ns2,no_specimen,1,,,116640,
";
    let date_line = line_of(&manifest, "date = \"yesterday\"");
    let f = "night/specimens.csv";
    assert_eq!(
        problems(&manifest, table),
        [
            // The table's problems where the manifest names the table (line
            // 9), before the runs' that follow it; by row, then column.
            format!(
                "  {f}: column dampng_ns_per_m: unknown column `dampng_ns_per_m`; did you mean `damping_ns_per_m`?"
            ),
            format!(
                "  {f}: row 2 (run \"exp2\"), column role: unknown role `validaton`; did you mean `validation`?"
            ),
            format!(
                "  {f}: row 3 (run \"exp3\"), column date: must be an ISO 8601 date, YYYY-MM-DD or YYYY-MM-DDTHH:MM:SS[Z] (got \"2024-02-30\": 2024-02 has days 01 to 29)"
            ),
            format!("  {f}: row 3 (run \"exp3\"), column p_gain: must be positive (got 0)"),
            // Row 4 is a blank line: no run, and no problem.
            format!("  {f}: row 5 (run \"k2\"), column mass_kg: must be positive (got -3.8)"),
            format!(
                "  {f}: row 5 (run \"k2\"), column stiffness_n_per_m: must be positive (got -3)"
            ),
            format!("  {f}: row 6, column id: required: the cell is empty"),
            format!("  {f}: row 6, column p_gain: must be a number (got \"one\")"),
            format!(
                "  {f}: row 7 (run \"ns2\"): a no_specimen run has no specimen; remove stiffness_n_per_m"
            ),
            format!(
                "  {f}: row 7 (run \"ns2\"), column log: a no_specimen run needs a log: give its `log` cell or [run_table] logs"
            ),
            format!(
                "  campaign.toml:{date_line}:1: runs[1].date (run \"k1\"): must be an ISO 8601 date, YYYY-MM-DD or YYYY-MM-DDTHH:MM:SS[Z] (got \"yesterday\": the date is not YYYY-MM-DD)"
            ),
        ]
    );
}

#[test]
fn a_missing_required_column_is_one_problem_not_one_per_row() {
    let table = "id,role,mass_kg,stiffness_n_per_m\nexp1,validation,3.8,129400\nexp2,validation,3.8,129400\n";
    assert_eq!(
        problems(PREDICTIONS, table),
        ["  night/specimens.csv: column p_gain: required column is missing"]
    );
}

#[test]
fn duplicate_ids_name_both_places() {
    let table = "\
id,role,p_gain,mass_kg,damping_ns_per_m,stiffness_n_per_m
exp1,validation,1,3.8,5,129400
k1,validation,1,3.8,5,129400
exp1,validation,2,3.8,5,129400
";
    assert_eq!(
        problems(PREDICTIONS, table),
        [
            "  night/specimens.csv: row 2 (run \"k1\"), column id: duplicate run id `k1` (first used by runs[1])",
            "  night/specimens.csv: row 3 (run \"exp1\"), column id: duplicate run id `exp1` (first used by row 1 of night/specimens.csv)",
        ]
    );
}

#[test]
fn a_table_that_cannot_be_read_is_one_problem_naming_it() {
    let dir = scratch();
    let check = |manifest: &str| -> Vec<String> {
        let path = write(dir.path(), "campaign.toml", manifest);
        let o = servoid(dir.path(), &["check", path.to_str().unwrap()]);
        assert_eq!(o.code, 2, "{}", o.stderr);
        o.stderr.lines().skip(1).map(str::to_string).collect()
    };
    assert_eq!(
        check(PREDICTIONS),
        ["  night/specimens.csv: cannot read: No such file or directory (os error 2)"]
    );
    write(dir.path(), "specimens.xlsx", "id,role,p_gain\n");
    assert_eq!(
        check(&PREDICTIONS.replace("night/specimens.csv", "specimens.xlsx")),
        [
            "  specimens.xlsx: cannot tell the table's format from its extension; give [run_table] format = \"csv\" or \"parquet\""
        ]
    );
    write(dir.path(), "specimens.parquet", "id,role,p_gain\n");
    let lines = check(&PREDICTIONS.replace("night/specimens.csv", "specimens.parquet"));
    assert_eq!(lines.len(), 1, "{lines:?}");
    assert!(
        lines[0].starts_with("  specimens.parquet: not a readable Parquet table: "),
        "{lines:?}"
    );
    // Told the format, the table reads whatever its extension.
    write(
        dir.path(),
        "specimens.txt",
        "id,role,p_gain,mass_kg,stiffness_n_per_m\nexp1,validation,1,3.8,129400\n",
    );
    let told = PREDICTIONS.replace(
        "file = \"night/specimens.csv\"",
        "file = \"specimens.txt\"\nformat = \"csv\"",
    );
    let path = write(dir.path(), "campaign.toml", &told);
    let o = servoid(dir.path(), &["check", path.to_str().unwrap()]);
    assert_eq!(o.code, 0, "{}", o.stderr);
    assert_eq!(
        o.stdout.trim(),
        format!("{}: ok (campaign `table`, 3 runs)", path.display())
    );
}

#[test]
fn a_row_whose_log_is_missing_fails_alone() {
    let dir = scratch();
    let sim = simulate(dir.path());
    std::fs::create_dir_all(sim.join("night")).unwrap();
    // v2's `log` cell names a file that is not there; v3 has no cell and
    // no log has its stem.
    let table = "\
id,role,p_gain,mass_kg,damping_ns_per_m,stiffness_n_per_m,log
bare,no_specimen,1,,,,
k1,spring,1,,,100000,
k2,spring,1,,,80000,
v2,validation,1.0,3,5,90000,../logs/v2-late.csv
v3,validation,1.0,3,5,90000,
v1,validation,1.5,4,10,120000,
";
    write(&sim, "night/specimens.csv", table);
    let manifest = table_manifest(
        &sim,
        "file = \"night/specimens.csv\"\nlogs = \"logs/*.csv\"",
    );
    let (code, stderr, results) = run(&sim, &manifest, "out");
    assert_eq!(code, 1, "{stderr}");
    for (id, path) in [
        ("v2", sim.join("night/../logs/v2-late.csv")),
        ("v3", sim.join("logs/v3.csv")),
    ] {
        let r = run_by_id(&results, id);
        assert_eq!(r["status"], "failed", "{id}");
        let error = r["error"].as_str().unwrap();
        let expected = format!("{}: log file not found", path.display());
        assert!(error.starts_with(&expected), "{id}: {error:?}");
        assert!(
            stderr.contains(&format!("run {id}: {expected}")),
            "{stderr}"
        );
    }
    for id in ["bare", "k1", "k2", "v1"] {
        assert_eq!(run_by_id(&results, id)["status"], "ok", "{id}");
    }
    // In the table's order, after the (no) `[[runs]]` runs.
    let ids: Vec<&str> = results["runs"]
        .as_array()
        .unwrap()
        .iter()
        .map(|r| r["id"].as_str().unwrap())
        .collect();
    assert_eq!(ids, ["bare", "k1", "k2", "v2", "v3", "v1"]);
    assert!(results["rig"]["beta1"]["value"].as_f64().unwrap() > 0.0);
    // The run table is a campaign's data: v2's log not being there yet is
    // not a manifest problem.
    let c = servoid::manifest::load(&manifest).unwrap();
    assert_eq!(c.runs.len(), 6);
    // v2's own log, `logs/v2.csv`, is matched but no run uses it.
    let details: Vec<&str> = c.warnings.iter().map(|w| w.detail.as_str()).collect();
    assert_eq!(
        details,
        ["logs/v2.csv: matched by [run_table] logs = \"logs/*.csv\", but no run uses it"]
    );
    // It reaches results.json with the table's provenance.
    assert_eq!(
        results["warnings"][0]["detail"],
        c.warnings[0].detail.as_str()
    );
    let table_sha = servoid::ingest::sha256_hex(table.as_bytes());
    assert_eq!(
        results["campaign"]["run_table"],
        serde_json::json!({"file": "night/specimens.csv", "sha256": table_sha, "rows": 6})
    );
}

#[test]
fn unreadable_files_matched_by_the_glob_fail_their_runs_alone() {
    let dir = scratch();
    let sim = simulate(dir.path());
    std::fs::create_dir_all(sim.join("night")).unwrap();
    write(&sim, "night/specimens.csv", TABLE_CSV);
    let manifest = table_manifest(
        &sim,
        "file = \"night/specimens.csv\"\nlogs = \"logs/*.csv\"",
    );
    // A night that went right first: its report must survive the next.
    let (code, stderr, before) = run(&sim, &manifest, "out");
    assert_eq!(code, 0, "{stderr}");

    // v1's log is now a folder, v2's a named pipe (a read would block
    // until a writer came), and a dangling link matches the glob too.
    let logs = sim.join("logs");
    std::fs::remove_file(logs.join("v1.csv")).unwrap();
    std::fs::create_dir(logs.join("v1.csv")).unwrap();
    std::fs::remove_file(logs.join("v2.csv")).unwrap();
    let fifo = std::process::Command::new("mkfifo")
        .arg(logs.join("v2.csv"))
        .status()
        .expect("mkfifo runs");
    assert!(fifo.success());
    std::os::unix::fs::symlink(logs.join("nowhere.csv"), logs.join("v9.csv")).unwrap();

    let (code, stderr, after) = run(&sim, &manifest, "out");
    assert_eq!(code, 1, "{stderr}");
    for (id, what) in [("v1", "a folder"), ("v2", "a named pipe")] {
        let r = run_by_id(&after, id);
        assert_eq!(r["status"], "failed", "{id}");
        let expected = format!(
            "{}: is {what}, not a regular file",
            logs.join(format!("{id}.csv")).display()
        );
        let error = r["error"].as_str().unwrap();
        assert!(error.starts_with(&expected), "{id}: {error:?}");
        assert!(
            stderr.contains(&format!("run {id}: {expected}")),
            "{stderr}"
        );
    }
    // The runs that can be read give what they gave before.
    for id in ["bare", "k1", "k2"] {
        assert_eq!(run_by_id(&after, id), run_by_id(&before, id), "{id}");
    }
    assert_eq!(after["rig"], before["rig"]);
    // Nothing half-written is left beside the new report.
    let stray: Vec<_> = std::fs::read_dir(sim.join("out"))
        .unwrap()
        .flatten()
        .filter(|e| e.file_name().to_string_lossy().contains(".tmp-"))
        .collect();
    assert!(stray.is_empty(), "{stray:?}");
}

#[test]
fn dates_are_checked_and_normalised_in_both_places() {
    let dir = scratch();
    let manifest = PREDICTIONS
        .replace(
            "id = \"ns\"\nrole = \"no_specimen\"\n",
            "id = \"ns\"\nrole = \"no_specimen\"\ndate = 2024-05-02\n",
        )
        .replace(
            "id = \"k1\"\nrole = \"spring\"\n",
            "id = \"k1\"\nrole = \"spring\"\ndate = \"2024-05-03 08:00:00\"\n",
        );
    std::fs::create_dir_all(dir.path().join("night")).unwrap();
    write(
        dir.path(),
        "night/specimens.csv",
        "id,role,p_gain,mass_kg,stiffness_n_per_m,date\nexp1,validation,1,3.8,129400,2024-05-01t07:30:00z\nexp2,validation,1,3.8,129400,\n",
    );
    let path = write(dir.path(), "campaign.toml", &manifest);
    let c = servoid::manifest::load(&path).unwrap_or_else(|e| panic!("{e}"));
    let dates: Vec<(&str, Option<&str>)> = c
        .runs
        .iter()
        .map(|r| (r.id.as_str(), r.date.as_deref()))
        .collect();
    assert_eq!(
        dates,
        [
            ("ns", Some("2024-05-02")),
            ("k1", Some("2024-05-03T08:00:00")),
            ("exp1", Some("2024-05-01T07:30:00Z")),
            ("exp2", None),
        ]
    );
    // The echo keeps the manifest as written (a TOML date as its text).
    assert_eq!(c.manifest.runs[0].date.as_deref(), Some("2024-05-02"));
    assert_eq!(
        c.manifest.runs[1].date.as_deref(),
        Some("2024-05-03 08:00:00")
    );

    // (Quoted: TOML itself refuses an unquoted impossible date.)
    let bad = manifest.replace("date = 2024-05-02", "date = \"2024-05-32\"");
    let line = line_of(&bad, "2024-05-32");
    assert_eq!(
        problems(&bad, "id,role,p_gain,date\nexp1,validation,1,2024-05-01T25:00:00\n"),
        [
            "  night/specimens.csv: row 1 (run \"exp1\"), column date: must be an ISO 8601 date, YYYY-MM-DD or YYYY-MM-DDTHH:MM:SS[Z] (got \"2024-05-01T25:00:00\": there is no time 25:00:00)".to_string(),
            format!(
                "  campaign.toml:{line}:1: runs[0].date (run \"ns\"): must be an ISO 8601 date, YYYY-MM-DD or YYYY-MM-DDTHH:MM:SS[Z] (got \"2024-05-32\": 2024-05 has days 01 to 31)"
            ),
        ]
    );
}

/// A lab's own columns (`notes`, `operator`) are carried, not refused
///: each row's cells reach its run in results.json and on its
/// page, a `description` column is the run's description, and editing a
/// note redoes no work. A column named like one of servoid's (a typo) is
/// still a problem with a suggestion: a misspelt stiffness must not
/// become a note.
#[test]
fn a_table_carries_the_labs_own_columns_and_refuses_a_misspelt_one() {
    let dir = scratch();
    let sim = simulate(dir.path());
    let with_notes = |note: &str| {
        let mut text = String::from(
            "id,role,p_gain,mass_kg,damping_ns_per_m,stiffness_n_per_m,date,description,notes,operator\n",
        );
        for (k, line) in TABLE_CSV.lines().skip(1).enumerate() {
            let notes = if k == 0 { note } else { "" };
            text.push_str(&format!("{line},run {k},{notes},ana\n"));
        }
        text
    };
    write(
        &sim,
        "specimens.csv",
        &with_notes("\"oil changed, new filter\""),
    );
    let table = table_manifest(&sim, "file = \"specimens.csv\"\nlogs = \"logs/*.csv\"");
    let (code, stderr, listed) = run(&sim, &sim.join("campaign.toml"), "out-runs");
    assert_eq!(code, 0, "{stderr}");
    let (code, stderr, tabled) = run(&sim, &table, "out-table");
    assert_eq!(code, 0, "{stderr}");
    assert_eq!(listed["rig"], tabled["rig"], "the notes change no number");
    let bare = run_by_id(&tabled, "bare");
    assert_eq!(
        bare["annotations"],
        serde_json::json!({ "notes": "oil changed, new filter", "operator": "ana" })
    );
    assert_eq!(bare["description"], "run 0");
    assert_eq!(
        run_by_id(&tabled, "k1")["annotations"],
        serde_json::json!({ "operator": "ana" }),
        "an empty cell is no annotation"
    );
    assert!(
        run_by_id(&listed, "bare").get("annotations").is_none(),
        "a [[runs]] run has none"
    );
    let page = std::fs::read_to_string(sim.join("out-table/runs/bare.html")).unwrap();
    assert!(page.contains("oil changed, new filter"), "the run's page");

    // A note edited: every run from the cache, the new note in place.
    write(&sim, "specimens.csv", &with_notes("filter changed"));
    let o = servoid_into(
        &sim,
        "run",
        &table,
        &sim.join("out-table"),
        &["--figures", "none"],
    );
    assert_eq!(o.code, 0, "{}", o.stderr);
    assert!(o.stdout.contains("5 cached"), "{}", o.stdout);
    let again: Value =
        serde_json::from_slice(&std::fs::read(sim.join("out-table/results.json")).unwrap())
            .unwrap();
    assert_eq!(
        run_by_id(&again, "bare")["annotations"]["notes"],
        "filter changed"
    );

    // A misspelt column of servoid's: refused, with the suggestion.
    let misspelt = TABLE_CSV.replacen("stiffness_n_per_m", "stifness_n_per_m", 1);
    write(&sim, "specimens.csv", &misspelt);
    let o = servoid(&sim, &["check", table.to_str().unwrap()]);
    assert_eq!(o.code, 2, "{}", o.stderr);
    assert!(
        o.stderr
            .contains("unknown column `stifness_n_per_m`; did you mean `stiffness_n_per_m`?"),
        "{}",
        o.stderr
    );
}
