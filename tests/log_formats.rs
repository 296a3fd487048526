//! One simulated campaign written in every log format the simulator has
//! (CSV, Parquet, MATLAB level 5 and v7.3, HDF5, TDMS) and analysed from
//! each: the samples are the same f64s whatever the file, so the rig, every
//! run's fit and the validation must be the same to the last digit
//! results.json prints. The readers are also checked on files other tools
//! wrote (h5py, hdf5storage in MATLAB's v7.3 layout, npTDMS: the fuzz
//! seeds, in pipeline/ingest/tests.rs).

use serde_json::Value;

use crate::util::{scratch, servoid_into, write};

const BASE: &str = include_str!("fixtures/small-simulation.toml");

/// results.json's numbers that come from the logs: the rig and each run's
/// transfer function, fit and validation.
fn numbers_of(results: &Value) -> Value {
    let runs: Vec<Value> = results["runs"]
        .as_array()
        .unwrap()
        .iter()
        .map(|r| serde_json::json!([r["id"], r["tf"], r["fit"], r["validation"]]))
        .collect();
    serde_json::json!({ "rig": results["rig"], "runs": runs })
}

#[test]
fn every_log_format_gives_the_same_rig_to_the_last_digit() {
    let dir = scratch();
    let mut reference: Option<Value> = None;
    for (format, ext) in [
        ("csv", "csv"),
        ("parquet", "parquet"),
        ("mat", "mat"),
        ("mat_v73", "mat"),
        ("hdf5", "h5"),
        ("tdms", "tdms"),
    ] {
        let text = BASE.replace(
            "log_format = \"csv\"",
            &format!("log_format = \"{format}\""),
        );
        assert!(text.contains(&format!("log_format = \"{format}\"")));
        let sim = write(dir.path(), &format!("{format}.toml"), &text);
        let out = dir.path().join(format);
        let o = servoid_into(dir.path(), "simulate", &sim, &out, &["--run"]);
        assert_eq!(o.code, 0, "{format}: {}", o.stderr);
        let logs: Vec<String> = std::fs::read_dir(out.join("logs"))
            .unwrap()
            .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
            .collect();
        assert!(
            !logs.is_empty() && logs.iter().all(|l| l.ends_with(&format!(".{ext}"))),
            "{format}: {logs:?}"
        );
        let results: Value =
            serde_json::from_slice(&std::fs::read(out.join("results.json")).unwrap()).unwrap();
        for r in results["runs"].as_array().unwrap() {
            assert_eq!(r["status"], "ok", "{format}: {}", r["id"]);
            assert_eq!(
                r["log"]["file"].as_str().map(|f| f.ends_with(ext)),
                Some(true)
            );
        }
        let numbers = numbers_of(&results);
        assert!(numbers["rig"]["beta1"]["value"].is_f64(), "{format}: a rig");
        match &reference {
            None => reference = Some(numbers),
            Some(csv) => assert!(
                *csv == numbers,
                "{format} differs from CSV:\n{}\n{}",
                csv["rig"],
                numbers["rig"]
            ),
        }
    }
}
