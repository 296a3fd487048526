//! The stiffness sensitivity from the campaign's own noise (paper Sec.
//! 2.3): the no-specimen log's FRF variance, through the fit's Jacobian
//! for a planned spring run and then Eqs. 18-20, predicts how precisely a
//! spring of stiffness k gives the rig. At the campaign's own springs the
//! prediction must match what their actual fits gave (each fit's own
//! covariance, from its own noisy data, propagated through the same
//! equations): within 5 %.

use std::path::Path;

use serde_json::Value;

use crate::shards::campaign;
use crate::util::{scratch, servoid_into};

/// `ys` at `x` by linear interpolation in log k and log y.
fn at(ks: &[f64], ys: &[f64], x: f64) -> f64 {
    let i = ks.windows(2).position(|w| w[0] <= x && x <= w[1]).unwrap();
    let t = (x / ks[i]).ln() / (ks[i + 1] / ks[i]).ln();
    (ys[i].ln() + t * (ys[i + 1] / ys[i]).ln()).exp()
}

/// Run `manifest` into `dir/out` without figures; its results.json.
fn run(dir: &Path, manifest: &Path) -> Value {
    let out = dir.join("out");
    let o = servoid_into(
        dir,
        "run",
        manifest,
        &out,
        &["--figures", "none", "--quiet"],
    );
    assert_eq!(o.code, 0, "{}", o.stderr);
    serde_json::from_slice(&std::fs::read(out.join("results.json")).unwrap()).unwrap()
}

#[test]
fn the_measured_noise_predicts_the_springs_own_precision() {
    let dir = scratch();
    let manifest = campaign(dir.path());
    let r = run(dir.path(), &manifest);
    let s = &r["sensitivity"];
    assert!(
        s["basis"]
            .as_str()
            .unwrap()
            .starts_with("the FRF noise run no-specimen measured"),
        "{}",
        s["basis"]
    );
    assert!(s["sweep"]["coefficient_rel_std"].is_null());
    let sweep = &s["sweep"];
    let v = |key: &str| -> Vec<f64> {
        sweep[key]
            .as_array()
            .unwrap()
            .iter()
            .map(|x| x.as_f64().unwrap())
            .collect()
    };
    let ks = v("stiffness_n_per_m");
    // At least a decade either side of the springs.
    let springs: Vec<f64> = s["springs_n_per_m"]
        .as_array()
        .unwrap()
        .iter()
        .map(|x| x.as_f64().unwrap())
        .collect();
    assert!(ks[0] <= springs.iter().cloned().fold(f64::INFINITY, f64::min) / 10.0);
    assert!(*ks.last().unwrap() >= springs.iter().cloned().fold(0.0, f64::max) * 10.0);

    // Noise this small needs one spring test for +-2 % on a2 and a3.
    let rec = &s["recommendation"];
    assert!(
        rec["summary"]
            .as_str()
            .unwrap()
            .contains("this campaign's measured noise"),
        "{}",
        rec["summary"]
    );
    for t in rec["spring_tests"].as_array().unwrap() {
        assert_eq!(t["tests"], 1, "{t}");
        assert_eq!(t["basis"], "predicted", "{t}");
    }
    let rig = &r["rig"];
    let rel = |e: &Value| e["std"].as_f64().unwrap() / e["value"].as_f64().unwrap();
    // beta1 comes from the no-specimen run alone: the same at every k.
    for b in v("rel_std_beta1") {
        assert!((b / rel(&rig["beta1"]) - 1.0).abs() < 0.05, "{b}");
    }
    for spring in rig["per_spring"].as_array().unwrap() {
        let k = spring["stiffness_n_per_m"].as_f64().unwrap();
        for p in ["a1b0", "a2", "a3"] {
            let predicted = at(&ks, &v(&format!("rel_std_{p}")), k);
            let actual = rel(&spring[p]);
            assert!(
                (predicted / actual - 1.0).abs() < 0.05,
                "{} {p}: predicted {predicted:.3e}, its fit gave {actual:.3e}",
                spring["run"]
            );
        }
    }
}

/// paper.toml has no logs: its published transfer functions carry no
/// covariance, so the sweep assumes 0.1 % per coefficient, independent.
/// Then a1b0's relative std has the closed form eps sqrt((k + a2)^2 +
/// a2^2) / k (derived in sensitivity.rs), and the recommendation's lower
/// end for a1b0 solves it equal to the 1 % target:
/// (t^2 - eps^2) k^2 - 2 eps^2 a2 k - 2 eps^2 a2^2 = 0. Both paper springs
/// (116.6 and 88.5 kN/m) are below it, and the springs' scatter (a2 differs
/// by a fifth between them) sets the number of tests.
#[test]
fn the_papers_campaign_gets_a_recommendation_a_lab_can_act_on() {
    let dir = scratch();
    let manifest = crate::util::root().join("experiments/maghareh2018/paper.toml");
    let r = run(dir.path(), &manifest);
    let s = &r["sensitivity"];
    assert_eq!(s["sweep"]["coefficient_rel_std"], 1e-3);
    let rec = &s["recommendation"];
    assert_eq!(rec["target_rel_std"], 0.01);
    let (eps, t) = (1e-3_f64, 0.01_f64);
    let a2 = r["rig"]["a2"]["value"].as_f64().unwrap();
    let (qa, qb, qc) = (
        t * t - eps * eps,
        -2.0 * eps * eps * a2,
        -2.0 * eps * eps * a2 * a2,
    );
    let k_low = (-qb + (qb * qb - 4.0 * qa * qc).sqrt()) / (2.0 * qa);
    let a1b0 = rec["ranges"]
        .as_array()
        .unwrap()
        .iter()
        .find(|g| g["parameter"] == "a1b0")
        .unwrap();
    let got = a1b0["low_n_per_m"].as_f64().unwrap();
    assert!((got / k_low - 1.0).abs() < 0.01, "{got} vs {k_low}");
    assert!(a1b0["high_n_per_m"].is_null());
    let summary = rec["summary"].as_str().unwrap();
    assert!(
        summary.contains("an assumed 0.1 % relative std"),
        "{summary}"
    );
    assert!(
        summary.contains("Too soft for the target: 116.6 kN/m, 88.5 kN/m"),
        "{summary}"
    );
    assert!(summary.contains("massless, linearised spring"), "{summary}");
    // Tests for +-2 % from the springs' scatter: (1.96 s / 0.02)^2 with s
    // the per-spring values' relative sample std.
    let per: Vec<f64> = r["rig"]["per_spring"]
        .as_array()
        .unwrap()
        .iter()
        .map(|p| p["a2"]["value"].as_f64().unwrap())
        .collect();
    let mean = per.iter().sum::<f64>() / per.len() as f64;
    let sd = (per.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / (per.len() - 1) as f64).sqrt();
    let s_rel = sd / r["rig"]["a2"]["value"].as_f64().unwrap();
    let tests = rec["spring_tests"][0]["tests"].as_u64().unwrap();
    assert_eq!(rec["spring_tests"][0]["parameter"], "a2");
    assert_eq!(tests, (1.959_964 * s_rel / 0.02).powi(2).ceil() as u64);
    assert!(tests > 100, "the paper's springs disagree: {tests}");
    let page = std::fs::read_to_string(dir.path().join("out/report.html")).unwrap();
    assert!(page.contains("id=\"recommendation-summary\""));
}
