//! Control-structure interaction end to end on the bundled default
//! simulated: per validation run, the specimen's natural frequency and
//! damping ratio from its m, c, k; the model's notch of |f/u| where
//! |m (jw)^2 + c jw + k| is least; the notch the log's force FRF shows
//! beside it; and x1/u at the natural frequency from Eq. 17, evaluated here
//! from the identified rig by hand.

use std::f64::consts::PI;

use serde_json::Value;

use crate::shards::campaign;
use crate::util::{run_by_id, scratch, servoid_into};

#[test]
fn each_sdof_specimen_has_its_notch_measured_and_modelled() {
    let dir = scratch();
    let manifest = campaign(dir.path());
    let out = dir.path().join("out");
    let o = servoid_into(dir.path(), "run", &manifest, &out, &["--quiet"]);
    assert_eq!(o.code, 0, "{}", o.stderr);
    let r: Value =
        serde_json::from_slice(&std::fs::read(out.join("results.json")).unwrap()).unwrap();
    let csi = r["csi"].as_array().unwrap();
    let ids: Vec<&str> = csi.iter().map(|c| c["run"].as_str().unwrap()).collect();
    assert_eq!(ids, ["exp1", "exp2", "exp3", "exp4"]);
    let rig = &r["rig"];
    let v = |q: &str| rig[q]["value"].as_f64().unwrap();
    for c in csi {
        let id = c["run"].as_str().unwrap();
        let run = run_by_id(&r, id);
        let spec = &r["manifest"]["runs"]
            .as_array()
            .unwrap()
            .iter()
            .find(|x| x["id"] == id)
            .unwrap()["specimen"];
        let (m, cd, k) = (
            spec["mass_kg"].as_f64().unwrap(),
            spec["damping_ns_per_m"].as_f64().unwrap(),
            spec["stiffness_n_per_m"].as_f64().unwrap(),
        );
        let f = |key: &str| c[key].as_f64().unwrap();
        let fn_hz = (k / m).sqrt() / (2.0 * PI);
        assert!(
            (f("natural_frequency_hz") / fn_hz - 1.0).abs() < 1e-12,
            "{id}"
        );
        assert!(
            (f("damping_ratio") / (cd / (2.0 * (k * m).sqrt())) - 1.0).abs() < 1e-12,
            "{id}"
        );
        // The zero pair: -c/2m +- j sqrt(k/m - (c/2m)^2).
        let (re, im) = (-cd / (2.0 * m), (k / m - (cd / (2.0 * m)).powi(2)).sqrt());
        assert!((c["zeros_rad_per_s"][1][0].as_f64().unwrap() / re - 1.0).abs() < 1e-9);
        assert!((c["zeros_rad_per_s"][1][1].as_f64().unwrap() / im - 1.0).abs() < 1e-9);

        // The model's notch: where the specimen polynomial is least.
        let w_star = (k / m - cd * cd / (2.0 * m * m)).sqrt();
        let model = c["notch_model"]["frequency_hz"].as_f64().unwrap();
        assert!(
            (model / (w_star / (2.0 * PI)) - 1.0).abs() < 2e-3,
            "{id}: {model}"
        );
        // The log's notch beside it, and deep (lightly damped specimens).
        let measured = c["notch_measured"]["frequency_hz"].as_f64().unwrap();
        assert!(
            (measured / model - 1.0).abs() < 5e-3,
            "{id}: {measured} vs {model}"
        );
        assert!(
            c["notch_measured"]["depth_db"].as_f64().unwrap() > 20.0,
            "{id}"
        );

        // x1/u at fn from Eq. 17 with the rig at the run's P gain.
        let p = run["p_gain"].as_f64().unwrap() / rig["p_gain"].as_f64().unwrap();
        let (b1, a1b0, a2, a3) = (v("beta1"), v("a1b0") * p, v("a2"), v("a3"));
        let den = [
            m,
            a3 * m + cd + b1 * m,
            k + a3 * cd + a2 + b1 * a3 * m + b1 * cd,
            a3 * k + b1 * k + b1 * a3 * cd + b1 * a2,
            b1 * a3 * k + a1b0,
        ];
        // s = j w, as (re, im).
        let s = (0.0, 2.0 * PI * fn_hz);
        let d = den.iter().fold((0.0, 0.0), |acc, &a| {
            // acc * s + a, complex with s = j w.
            let (re, im) = acc;
            (re * s.0 - im * s.1 + a, re * s.1 + im * s.0)
        });
        let h = (
            a1b0 * d.0 / (d.0 * d.0 + d.1 * d.1),
            -a1b0 * d.1 / (d.0 * d.0 + d.1 * d.1),
        );
        let mag_db = 10.0 * (h.0 * h.0 + h.1 * h.1).log10();
        let phase = h.1.atan2(h.0).to_degrees();
        let x = &c["x1_u_at_natural_frequency"];
        assert!(
            (x["magnitude_db"].as_f64().unwrap() - mag_db).abs() < 1e-9,
            "{id}"
        );
        assert!(
            (x["phase_deg"].as_f64().unwrap() - phase).abs() < 1e-9,
            "{id}"
        );
    }
    let page = std::fs::read_to_string(out.join("report.html")).unwrap();
    assert!(page.contains("id=\"csi\""));
    let run_page = std::fs::read_to_string(out.join("runs/exp1.html")).unwrap();
    assert!(
        run_page.contains("The notches of |f&#x2f;u| are marked"),
        "the force figure's caption"
    );
}
