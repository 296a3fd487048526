//! The paper reproduced from its published numbers: `servoid run
//! experiments/maghareh2018/paper.toml`. Expected values are the paper's own
//! (Sec. 3.1, Tables 2-3) and an independent recomputation (docs/model.md) of
//! Table 3 with m = 3.8 kg.

use serde_json::Value;

use crate::util::{root, run_by_id, scratch, servoid};

fn run_paper(extra: &[&str]) -> (Value, Vec<u8>) {
    let dir = scratch();
    let out = dir.path().join("out");
    let manifest = root().join("experiments/maghareh2018/paper.toml");
    let mut args = vec![
        "run",
        manifest.to_str().unwrap(),
        "--out",
        out.to_str().unwrap(),
    ];
    args.extend_from_slice(extra);
    let o = servoid(dir.path(), &args);
    assert_eq!(o.code, 0, "stdout:\n{}\nstderr:\n{}", o.stdout, o.stderr);
    let bytes = std::fs::read(out.join("results.json")).expect("results.json written");
    (serde_json::from_slice(&bytes).unwrap(), bytes)
}

fn rel(a: f64, b: f64) -> f64 {
    (a - b).abs() / b.abs()
}

fn num(v: &Value) -> f64 {
    v.as_f64()
        .unwrap_or_else(|| panic!("expected a number, got {v}"))
}

#[test]
fn rig_parameters_match_the_paper() {
    let (r, _) = run_paper(&[]);
    let rig = &r["rig"];
    // Sec. 3.1: beta1 = 267, R1 = 3060; means a1b0 = 2.412e9, a2 = 7.881e5, a3 = 16.118.
    for (key, want) in [
        ("beta1", 267.0),
        ("R1", 3060.0),
        ("a1b0", 2.412e9),
        ("a2", 7.881e5),
        ("a3", 16.118),
    ] {
        let got = num(&rig[key]["value"]);
        assert!(rel(got, want) < 5e-3, "{key}: {got} vs {want}");
        assert!(
            rig[key]["std"].is_null(),
            "published TFs carry no covariance"
        );
    }
    // Per spring: a2 = 8.83e5 / 6.95e5, a3 = 20.35 / 11.89.
    let per = rig["per_spring"].as_array().unwrap();
    assert_eq!(per.len(), 2);
    for (s, a2, a3) in [(&per[0], 8.83e5, 20.35), (&per[1], 6.95e5, 11.89)] {
        assert!(rel(num(&s["a2"]["value"]), a2) < 5e-3, "{s}");
        assert!(rel(num(&s["a3"]["value"]), a3) < 5e-3, "{s}");
        for key in ["run", "stiffness_n_per_m", "R2", "R3", "a1b0"] {
            assert!(!s[key].is_null(), "per_spring lacks {key}");
        }
    }
}

#[test]
fn controllable_canonical_form_and_natural_frequencies() {
    let (r, _) = run_paper(&[]);
    let ccf = r["ccf"].as_array().unwrap();
    let ids: Vec<&str> = ccf.iter().map(|c| c["run"].as_str().unwrap()).collect();
    assert_eq!(ids, ["exp1", "exp2", "exp3", "exp4"]);
    // Eq. 35 with the signs checked (docs/model.md): C1 = a1b0/m (6.347e8 at P = 1),
    // C2 = -6.50e7 (k = 129,400) / -6.17e7 (k = 84,340), C3 = -2.078e5,
    // C4 = -283.118, C5 = -1.133e3.
    let want = [
        ("exp1", 6.347e8, -6.50e7),
        ("exp2", 2.0 * 6.347e8, -6.50e7),
        ("exp3", 6.347e8, -6.17e7),
        ("exp4", 2.0 * 6.347e8, -6.17e7),
    ];
    for (c, (id, c1, c2)) in ccf.iter().zip(want) {
        assert_eq!(c["run"], id);
        assert!(rel(num(&c["C1"]), c1) < 5e-3, "{id} C1 {}", c["C1"]);
        assert!(rel(num(&c["C2"]), c2) < 5e-3, "{id} C2 {}", c["C2"]);
        assert!(rel(num(&c["C3"]), -2.078e5) < 5e-3, "{id} C3 {}", c["C3"]);
        assert!(rel(num(&c["C4"]), -283.118) < 5e-3, "{id} C4 {}", c["C4"]);
        assert!(rel(num(&c["C5"]), -1.133e3) < 5e-3, "{id} C5 {}", c["C5"]);
        assert_eq!(c["poles_with_cn"].as_array().unwrap().len(), 4);
        assert_ne!(c["poles_with_cn"], c["poles_without_cn"]);
    }
    // Specimen natural frequencies (Sec. 3.2.1): 29.4 Hz and 23.7 Hz.
    let f = |id: &str| num(&run_by_id(&r, id)["natural_frequency_hz"]);
    assert!(rel(f("exp1"), 29.4) < 2e-3);
    assert!(rel(f("exp3"), 23.7) < 2e-3);
}

#[test]
fn every_published_number_is_listed_and_table3_c1_to_c3_are_flagged() {
    let (r, _) = run_paper(&[]);
    let comps = r["comparisons"].as_array().unwrap();
    assert!(comps.len() >= 40);
    for c in comps {
        let q = c["quantity"].as_str().unwrap();
        let table3_c123 =
            q.starts_with("ccf.") && ["C1", "C2", "C3"].iter().any(|n| q.ends_with(n));
        if q.ends_with("nrmse_pct") || q.ends_with("nae_pct") {
            // Table 4 needs the measured logs.
            assert_eq!(c["status"], "not_computed", "{q}");
            assert!(c["computed"].is_null());
        } else if table3_c123 {
            assert_eq!(c["flag"], true, "{q} should be flagged: {c}");
            assert!(num(&c["rel_diff"]).abs() > 0.01);
        } else {
            assert_eq!(c["flag"], false, "{q} should agree: {c}");
            assert!(num(&c["rel_diff"]).abs() <= 0.01 * num(&c["tolerance_pct"]));
        }
    }
}

#[test]
fn results_json_keeps_its_contract() {
    let (r, _) = run_paper(&[]);
    for key in [
        "schema_version",
        "campaign",
        "rig",
        "runs",
        "ccf",
        "comparisons",
    ] {
        assert!(r.get(key).is_some(), "results.json lacks {key}");
    }
    for run in r["runs"].as_array().unwrap() {
        for key in ["id", "role", "status", "error", "tf", "validation"] {
            assert!(run.get(key).is_some(), "run lacks {key}: {run}");
        }
        assert_eq!(run["status"], "ok");
        let tf = &run["tf"];
        // Exact: the denominator is divided by its leading coefficient.
        assert_eq!(num(&tf["den"][0]), 1.0, "den[0] must be 1: {tf}");
        assert!(tf["num"].is_array() && tf["delay_s"].is_number());
    }
    for key in ["quantity", "published", "computed", "rel_diff", "flag"] {
        assert!(r["comparisons"][0].get(key).is_some());
    }
    // Validation runs at P = 2 have twice the a1b0 (Table 3: 4.823e9).
    let exp2 = run_by_id(&r, "exp2");
    assert!(rel(num(&exp2["a1b0"]), 4.823e9) < 5e-3);
}

#[test]
fn same_bytes_whatever_the_thread_count() {
    let (_, one) = run_paper(&["--jobs", "1"]);
    let (_, four) = run_paper(&["--jobs", "4"]);
    assert_eq!(one, four);
}

#[test]
fn json_manifest_gives_the_same_results() {
    // The same manifest as JSON, converted with the toml crate.
    let text = std::fs::read_to_string(root().join("experiments/maghareh2018/paper.toml")).unwrap();
    let value: Value = toml::from_str(&text).unwrap();
    let dir = scratch();
    let json = dir.path().join("paper.json");
    std::fs::write(&json, serde_json::to_string_pretty(&value).unwrap()).unwrap();
    let out = dir.path().join("out");
    let o = servoid(
        dir.path(),
        &[
            "run",
            json.to_str().unwrap(),
            "--out",
            out.to_str().unwrap(),
        ],
    );
    assert_eq!(o.code, 0, "{}", o.stderr);
    let from_json: Value =
        serde_json::from_slice(&std::fs::read(out.join("results.json")).unwrap()).unwrap();
    let (from_toml, _) = run_paper(&[]);
    assert_eq!(from_json["rig"], from_toml["rig"]);
    assert_eq!(from_json["ccf"], from_toml["ccf"]);
    assert_eq!(from_json["comparisons"], from_toml["comparisons"]);
}

#[test]
fn default_output_folder_is_named_after_the_campaign() {
    let dir = scratch();
    let manifest = root().join("experiments/maghareh2018/paper.toml");
    let o = servoid(dir.path(), &["run", manifest.to_str().unwrap(), "--quiet"]);
    assert_eq!(o.code, 0, "{}", o.stderr);
    assert!(
        dir.path()
            .join("reports/maghareh2018-paper/results.json")
            .is_file()
    );
}
