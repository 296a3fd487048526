//! A lab's first night, as the docs tell it to run one: `servoid init` on
//! its logs, the placeholders filled with what only the lab knows (the
//! rig's name, each run's P gain and specimen) and nothing else, `servoid
//! check`, `servoid run`. Simulated campaigns of the paper's rig (a
//! no-specimen run and its two springs, quadratic chirps 0.1-35 Hz of
//! 4 mm, 2 um of LVDT noise, 18-bit converters) of 20, 60 and 170 s, the
//! sweep at rest at the record's ends or cut in motion, and a rich one
//! (a 150 Hz spool mode, sensor delays, offsets and drift): the rig the
//! defaults give against the one simulated.

use std::path::Path;

use serde_json::Value;

use crate::util::{PAPER_TRUTH, PaperSweep, scratch, servoid};

fn toml_of(path: &Path) -> toml::Table {
    toml::from_str(&std::fs::read_to_string(path).unwrap()).unwrap()
}

/// The first night of `sim`'s logs: simulated into `dir/sim`, `init` on
/// them, filled from the simulation's own campaign (the lab's knowledge),
/// checked and run. The night's results.json.
pub fn first_night(dir: &Path, sim: &str) -> Value {
    std::fs::write(dir.join("sim.toml"), sim).unwrap();
    let o = servoid(dir, &["simulate", "sim.toml", "--out", "sim"]);
    assert_eq!(o.code, 0, "{}", o.stderr);
    let o = servoid(dir, &["init", "sim/logs", "--out", "night.toml"]);
    assert_eq!(o.code, 0, "{}", o.stderr);
    let reference = toml_of(&dir.join("sim/campaign.toml"));
    let mut night = toml_of(&dir.join("night.toml"));
    // init leaves the FRF settings to servoid: nothing of them is written.
    assert!(
        night["identification"].get("frf").is_none(),
        "{}",
        night["identification"]
    );
    night["rig"]["name"] = reference["rig"]["name"].clone();
    let known = reference["runs"].as_array().unwrap().clone();
    for r in night["runs"].as_array_mut().unwrap() {
        let id = r["id"].as_str().unwrap().to_string();
        let want = known
            .iter()
            .find(|x| x["id"].as_str() == Some(id.as_str()))
            .unwrap_or_else(|| panic!("run {id} in the simulation"));
        let r = r.as_table_mut().unwrap();
        assert_eq!(r["role"], want["role"], "{id}: the role from its name");
        r.insert("p_gain".into(), want["p_gain"].clone());
        if let Some(s) = want.get("specimen") {
            r.insert("specimen".into(), s.clone());
        }
    }
    std::fs::write(dir.join("night.toml"), toml::to_string(&night).unwrap()).unwrap();
    let o = servoid(dir, &["check", "night.toml"]);
    assert_eq!(o.code, 0, "{}", o.stderr);
    let o = servoid(dir, &["run", "night.toml", "--out", "night"]);
    assert_eq!(o.code, 0, "{}\n{}", o.stdout, o.stderr);
    // One line per run says what its FRF settings are and why.
    assert_eq!(o.stdout.matches("      FRF: ").count(), 3, "{}", o.stdout);
    serde_json::from_slice(&std::fs::read(dir.join("night/results.json")).unwrap()).unwrap()
}

/// Each rig parameter's relative error and error in stated stds.
fn errors(results: &Value) -> Vec<(&'static str, f64, f64)> {
    let rig = &results["rig"];
    PAPER_TRUTH
        .iter()
        .map(|&(name, truth)| {
            let value = rig[name]["value"].as_f64().unwrap();
            let std = rig[name]["std"].as_f64().unwrap();
            (name, value / truth - 1.0, (value - truth) / std)
        })
        .collect()
}

/// The rig's errors in per cent and in stated stds, in a line.
fn summary(results: &Value) -> String {
    errors(results)
        .iter()
        .map(|(name, rel, z)| format!("{name} {:+.4} % ({z:+.2} std)", 100.0 * rel))
        .collect::<Vec<_>>()
        .join(", ")
}

/// Every warning of the night: the campaign's and its runs'.
fn warnings(results: &Value) -> Vec<String> {
    let mut out: Vec<String> = results["warnings"]
        .as_array()
        .unwrap()
        .iter()
        .map(|w| w.as_str().unwrap().to_string())
        .collect();
    for run in results["runs"].as_array().unwrap() {
        out.extend(
            run["warnings"]
                .as_array()
                .unwrap()
                .iter()
                .map(|w| w["detail"].as_str().unwrap().to_string()),
        );
    }
    out
}

/// Clean logs of 20, 60 and 170 s, at rest at their ends and cut in
/// motion: every rig parameter within 3 of its stated stds and within 1 %
/// of the truth (0.1 % from 60 s up), with the choice of each run's FRF
/// settings stated and right for its ends, and no warning.
#[test]
fn the_defaults_give_the_rig_on_the_first_night() {
    for (duration, fs) in [(20.0, 1000.0), (60.0, 1000.0), (170.0, 2048.0)] {
        for at_rest in [true, false] {
            let dir = scratch();
            let sim = PaperSweep {
                duration_s: duration,
                at_rest,
                sample_rate_hz: fs,
                ..PaperSweep::default()
            };
            let results = first_night(dir.path(), &sim.text());
            let case = format!("{duration} s, at rest: {at_rest}");
            let limit = if duration >= 60.0 { 1e-3 } else { 1e-2 };
            eprintln!("{case}: {}", summary(&results));
            for (name, rel, z) in errors(&results) {
                assert!(
                    rel.abs() < limit && z.abs() < 3.0,
                    "{case}: {name} off by {:.4} % ({z:.2} stds)",
                    100.0 * rel
                );
            }
            for run in results["runs"].as_array().unwrap() {
                let frf = &run["frf"];
                assert_eq!(frf["chosen_by"], "auto", "{case}");
                assert_eq!(frf["estimator"], "etfe", "{case}");
                assert_eq!(frf["window"], "rectangular", "{case}");
                assert_eq!(frf["transient"], !at_rest, "{case}: {frf}");
                assert_eq!(
                    frf["ends"] == "the record is at rest at both ends",
                    at_rest,
                    "{case}: {frf}"
                );
                assert_eq!(frf["excitation"], "sweep", "{case}: {frf}");
                assert!(
                    frf["reason"]
                        .as_str()
                        .unwrap()
                        .starts_with("ETFE over the whole record"),
                    "{case}: {frf}"
                );
            }
            let w = warnings(&results);
            assert!(w.is_empty(), "{case}: {w:#?}");
        }
    }
}

/// The rich rig (a 150 Hz spool mode in the loop, 0.6 ms of LVDT delay,
/// an offset and a drift), 60 s cut in motion and 170 s at rest: each rig
/// parameter within 1 % of the truth, or covered by 2 of its stated stds
/// with a warning.
#[test]
fn a_rich_rig_is_right_or_covered_and_warned_on_the_first_night() {
    for (duration, at_rest, fs) in [(60.0, false, 1000.0), (170.0, true, 2048.0)] {
        let dir = scratch();
        let sim = PaperSweep {
            duration_s: duration,
            at_rest,
            sample_rate_hz: fs,
            seed: 7,
            unmodelled: "valve_mode = { natural_frequency_hz = 150.0, damping_ratio = 0.7 }",
            sensor: "delay_s = 0.0006\noffset = 0.15\ndrift_per_s = 0.0004\n",
            ..PaperSweep::default()
        };
        let results = first_night(dir.path(), &sim.text());
        let warned = !warnings(&results).is_empty();
        // The drift leaves the displacement's ends apart by far more than
        // its noise, at rest or not: its leakage is fitted and taken out.
        for run in results["runs"].as_array().unwrap() {
            assert_eq!(run["frf"]["transient"], true, "{}", run["frf"]);
        }
        eprintln!(
            "rich, {duration} s, at rest: {at_rest}: {}; warnings: {:#?}",
            summary(&results),
            warnings(&results)
        );
        for (name, rel, z) in errors(&results) {
            assert!(
                rel.abs() < 1e-2 || (z.abs() <= 2.0 && warned),
                "{duration} s, at rest: {at_rest}: {name} off by {:.3} % ({z:.2} stds), warned: {warned}",
                100.0 * rel
            );
        }
    }
}
