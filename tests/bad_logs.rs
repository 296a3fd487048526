//! Logs that read cleanly but cannot identify anything: the log stage's own
//! checks. Each such run is marked `failed` in results.json with an error
//! that names its file and what is wrong, the other runs still complete (the
//! rig is identified from them), the report is written, and the exit code
//! is 1.

use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

use crate::util::{paper_tf_runs, run_by_id, scratch, servoid_into, write};

const FS_HZ: f64 = 1000.0;
const SAMPLES: usize = 20_000;

/// The rig comes from the paper's published transfer functions (Eqs. 36-37),
/// so it does not depend on the bad logs; the two `fit` runs carry them.
const MANIFEST: &str = concat!(
    r#"schema_version = 1

[campaign]
name = "bad-logs"

[rig]
name = "test rig"

[channels]
time = { column = "t", unit = "s" }
command = { column = "u", unit = "mm" }
displacement = { column = "x", unit = "mm" }

[identification]
band_hz = [0.5, 30.0]
coherence_min = 0.8
frf = { estimator = "h1", segment_length = 1024, overlap = 0.5, window = "hann" }

"#,
    paper_tf_runs!(),
    r#"
[[runs]]
id = "quiet"
role = "fit"
p_gain = 1.0
data = { log = "quiet.csv" }

[[runs]]
id = "noise"
role = "fit"
p_gain = 1.0
data = { log = "noise.csv" }
"#
);

fn csv(u: &[f64], x: &[f64]) -> String {
    let mut text = String::from("t,u,x\n");
    for (i, (u, x)) in u.iter().zip(x).enumerate() {
        text.push_str(&format!("{},{u},{x}\n", i as f64 / FS_HZ));
    }
    text
}

#[test]
fn logs_without_excitation_or_coherence_fail_alone_and_name_their_files() {
    let dir = scratch();
    let t = |i: usize| i as f64 / FS_HZ;
    // "quiet": a command of two tones far above the 0.5-30 Hz band, on
    // the bins of the 1024-sample segments (154 and 243 periods in each, at
    // 150.4 and 237.3 Hz), so that no segment's mean removal leaves a
    // remainder at the first bins (off-bin tones left 1e-6 of the power in
    // the band, at the check's threshold) and Hann's leakage stays within a
    // bin. Their sum repeats its extremes once per 1024 samples: 0.1 % of
    // the log, below the 1 % that marks a clipped channel. The displacement
    // follows the command.
    let bin_hz = FS_HZ / 1024.0;
    let tone = |i: usize| {
        (2.0 * std::f64::consts::PI * 154.0 * bin_hz * t(i)).sin()
            + 0.7 * (2.0 * std::f64::consts::PI * 243.0 * bin_hz * t(i)).sin()
    };
    let u_quiet: Vec<f64> = (0..SAMPLES).map(tone).collect();
    let x_quiet: Vec<f64> = u_quiet.iter().map(|v| 0.5 * v).collect();
    write(dir.path(), "quiet.csv", &csv(&u_quiet, &x_quiet));
    // "noise": command and displacement independent white noise, so the
    // coherence is about 1/(number of averages) ~ 0.03 and no bin reaches
    // 0.8.
    let mut rng = ChaCha8Rng::seed_from_u64(2018);
    let mut white = || -> Vec<f64> { (0..SAMPLES).map(|_| rng.random_range(-1.0..1.0)).collect() };
    let (u_noise, x_noise) = (white(), white());
    write(dir.path(), "noise.csv", &csv(&u_noise, &x_noise));
    let manifest = write(dir.path(), "campaign.toml", MANIFEST);
    let out = dir.path().join("out");

    let o = servoid_into(dir.path(), "run", &manifest, &out, &["--quiet"]);
    assert_eq!(o.code, 1, "a failed run exits 1; stderr:\n{}", o.stderr);
    let results: serde_json::Value =
        serde_json::from_slice(&std::fs::read(out.join("results.json")).unwrap()).unwrap();
    let run = |id: &str| run_by_id(&results, id);

    let quiet = run("quiet");
    assert_eq!(quiet["status"], "failed");
    let error = quiet["error"].as_str().unwrap();
    for fragment in ["quiet.csv", "no energy in the fit band 0.5-30 Hz"] {
        assert!(error.contains(fragment), "{fragment:?} not in {error:?}");
    }

    let noise = run("noise");
    assert_eq!(noise["status"], "failed");
    let error = noise["error"].as_str().unwrap();
    for fragment in [
        "noise.csv",
        "have coherence >= 0.8",
        "lower identification.coherence_min or widen the band",
    ] {
        assert!(error.contains(fragment), "{fragment:?} not in {error:?}");
    }

    // The other runs completed and the rig came from them (Eqs. 18-20 on
    // the paper's Eqs. 36-37: beta1 = 267 1/s exactly, as d1/d2).
    assert_eq!(run("ns")["status"], "ok");
    assert_eq!(run("k1")["status"], "ok");
    let beta1 = results["rig"]["beta1"]["value"].as_f64().unwrap();
    assert!((beta1 - 267.0).abs() < 1e-9, "beta1 = {beta1}");
    assert!(out.join("report.html").is_file(), "the report is written");
}
