//! The stiffness sensitivity from the campaign's own noise (paper Sec.
//! 2.3): the no-specimen log's FRF variance, through the fit's Jacobian
//! for a planned spring run and then Eqs. 18-20, predicts how precisely a
//! spring of stiffness k gives the rig. At the campaign's own springs the
//! prediction must match what their actual fits gave (each fit's own
//! covariance, from its own noisy data, propagated through the same
//! equations): within 5 %.

use serde_json::Value;

use crate::shards::campaign;
use crate::util::{scratch, servoid_into};

/// `ys` at `x` by linear interpolation in log k and log y.
fn at(ks: &[f64], ys: &[f64], x: f64) -> f64 {
    let i = ks.windows(2).position(|w| w[0] <= x && x <= w[1]).unwrap();
    let t = (x / ks[i]).ln() / (ks[i + 1] / ks[i]).ln();
    (ys[i].ln() + t * (ys[i + 1] / ys[i]).ln()).exp()
}

#[test]
fn the_measured_noise_predicts_the_springs_own_precision() {
    let dir = scratch();
    let manifest = campaign(dir.path());
    let out = dir.path().join("out");
    let o = servoid_into(
        dir.path(),
        "run",
        &manifest,
        &out,
        &["--figures", "none", "--quiet"],
    );
    assert_eq!(o.code, 0, "{}", o.stderr);
    let r: Value =
        serde_json::from_slice(&std::fs::read(out.join("results.json")).unwrap()).unwrap();
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
