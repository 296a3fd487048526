//! `servoid simulate` end to end: a closed loop through `servoid run`, the
//! same bytes for the same seed whatever the thread count, fresh noise for a
//! new seed, and bad inputs, each refused with exit code 2, a
//! message naming the file and the key, and nothing written.

use std::path::Path;

use crate::util::{root, run_by_id, scratch, servoid, servoid_into, tree, write};

/// A short campaign (20 s linear chirp at 1 kHz) on a rig that is not the
/// paper's, so nothing here can lean on the bundled numbers.
const BASE: &str = include_str!("fixtures/small-simulation.toml");

// The rig of BASE.
const BETA1: f64 = 250.0;
const A1B0: f64 = 2.0e9;
const A2: f64 = 7.0e5;
const A3: f64 = 15.0;

fn json(path: &Path) -> serde_json::Value {
    let text = std::fs::read_to_string(path)
        .unwrap_or_else(|e| panic!("{} is readable: {e}", path.display()));
    serde_json::from_str(&text).expect("valid JSON")
}

fn floats(v: &serde_json::Value) -> Vec<f64> {
    v.as_array()
        .expect("an array")
        .iter()
        .map(|x| x.as_f64().expect("a number"))
        .collect()
}

fn rel(a: f64, b: f64) -> f64 {
    (a - b).abs() / b.abs()
}

/// One column of a CSV log written by the simulator (header line, then
/// comma-separated numbers), parsed here without servoid's reader.
fn csv_column(path: &Path, name: &str) -> Vec<f64> {
    let text = std::fs::read_to_string(path).expect("log readable");
    let mut lines = text.lines().filter(|l| !l.starts_with('#'));
    let header: Vec<&str> = lines.next().expect("a header").split(',').collect();
    let j = header
        .iter()
        .position(|h| *h == name)
        .unwrap_or_else(|| panic!("column {name} in {header:?}"));
    lines
        .map(|l| l.split(',').nth(j).unwrap().parse::<f64>().unwrap())
        .collect()
}

/// simulate then run: truth.json holds the transfer functions of docs/model.md's
/// table (Eqs. 11-17, computed here from the four parameters), the generated
/// manifest runs, and the identified rig comes back close to the truth.
#[test]
fn simulate_then_run_is_a_closed_loop() {
    let dir = scratch();
    let manifest = write(dir.path(), "sim.toml", BASE);
    let out = dir.path().join("out");
    let r = servoid_into(dir.path(), "simulate", &manifest, &out, &["--run"]);
    assert_eq!(r.code, 0, "stdout:\n{}\nstderr:\n{}", r.stdout, r.stderr);
    assert!(r.stdout.contains("SYNTHETIC"), "{}", r.stdout);
    for f in [
        "truth.json",
        "campaign.toml",
        "results.json",
        "report.html",
        "logs/bare.csv",
        "logs/k1.csv",
        "logs/v1.csv",
    ] {
        assert!(out.join(f).is_file(), "{f} written");
    }

    // Truth: x1/u by Eqs. 11-17, normalised to a monic denominator.
    let truth = json(&out.join("truth.json"));
    assert_eq!(truth["seed"].as_u64(), Some(7));
    let run = |id: &str| run_by_id(&truth, id);
    let check_tf = |id: &str, num: &[f64], den: &[f64]| {
        let t = &run(id)["plant_tf_x1_u"];
        let (n, d) = (floats(&t["num"]), floats(&t["den"]));
        let lead = den[0];
        assert_eq!(d.len(), den.len(), "{id}: order");
        for (a, b) in d.iter().zip(den) {
            assert!(rel(*a, b / lead) < 1e-12, "{id}: den {d:?} vs {den:?}");
        }
        assert!(
            rel(n[n.len() - 1], num[0] / lead) < 1e-12,
            "{id}: num {n:?}"
        );
    };
    check_tf("bare", &[A1B0], &[A2, BETA1 * A2, A1B0]);
    let k = 1.0e5;
    check_tf(
        "k1",
        &[A1B0],
        &[k + A2, A3 * k + BETA1 * (k + A2), BETA1 * A3 * k + A1B0],
    );
    // The validation run at P = 1.5 scales a1b0 (Eq. 7).
    let (m, c, k, a1b0) = (4.0, 10.0, 1.2e5, 1.5 * A1B0);
    check_tf(
        "v1",
        &[a1b0],
        &[
            m,
            A3 * m + c + BETA1 * m,
            k + A3 * c + A2 + BETA1 * A3 * m + BETA1 * c,
            A3 * k + BETA1 * k + BETA1 * A3 * c + BETA1 * A2,
            BETA1 * A3 * k + a1b0,
        ],
    );

    // The identified rig: 20 s of sweep is enough for 1 %.
    let results = json(&out.join("results.json"));
    for (key, truth) in [("beta1", BETA1), ("a1b0", A1B0), ("a2", A2), ("a3", A3)] {
        let v = results["rig"][key]["value"].as_f64().unwrap();
        assert!(rel(v, truth) < 0.01, "{key} = {v}, truth {truth}");
    }
    let runs = results["runs"].as_array().unwrap();
    assert_eq!(runs.len(), 3);
    assert!(runs.iter().all(|r| r["status"] == "ok"), "{runs:?}");
    // The validation run is predicted from the identified rig: close to the
    // log, whose only departures from the model are noise and quantisation.
    let v = run_by_id(&results, "v1");
    let nrmse = v["validation"]["nrmse_pct"].as_f64().unwrap();
    assert!(nrmse < 1.0, "v1 NRMSE {nrmse} %");
}

/// The same manifest gives the same bytes with one worker thread or two,
/// logs, truth, results, figures and page alike.
#[test]
fn the_same_seed_gives_the_same_bytes_whatever_the_thread_count() {
    let dir = scratch();
    let manifest = write(dir.path(), "sim.toml", BASE);
    let mut trees = Vec::new();
    for jobs in ["1", "2"] {
        let out = dir.path().join(format!("out-{jobs}"));
        let r = servoid_into(
            dir.path(),
            "simulate",
            &manifest,
            &out,
            &["--run", "--quiet", "--jobs", jobs],
        );
        assert_eq!(r.code, 0, "{}", r.stderr);
        trees.push(tree(&out));
    }
    // The cache (.cache/) is the orchestrator's state, keyed by the logs'
    // paths, not an output.
    for t in &mut trees {
        t.retain(|n, _| !n.starts_with(".cache/"));
    }
    let names =
        |t: &std::collections::BTreeMap<String, Vec<u8>>| t.keys().cloned().collect::<Vec<_>>();
    assert_eq!(names(&trees[0]), names(&trees[1]));
    assert!(trees[0].len() > 10, "logs, truth, results, figures");
    for ((name, a), (_, b)) in trees[0].iter().zip(&trees[1]) {
        // run.jsonl is where the wall clock and durations go, by design.
        if name.ends_with("run.jsonl") {
            continue;
        }
        assert!(a == b, "{name} differs between --jobs 1 and --jobs 2");
    }
}

/// A new seed draws new noise and nothing else: the command (no noise
/// configured) is identical, and the displacement differs by two
/// independent noise draws, whose difference has RMS sqrt(2) x 2 um.
#[test]
fn a_different_seed_gives_different_noise() {
    let dir = scratch();
    let mut logs = Vec::new();
    for seed in ["7", "8"] {
        let text = BASE.replace("seed = 7", &format!("seed = {seed}"));
        let manifest = write(dir.path(), &format!("sim-{seed}.toml"), &text);
        let out = dir.path().join(format!("out-{seed}"));
        let r = servoid_into(dir.path(), "simulate", &manifest, &out, &["--quiet"]);
        assert_eq!(r.code, 0, "{}", r.stderr);
        logs.push(out.join("logs").join("k1.csv"));
    }
    assert_ne!(
        std::fs::read(&logs[0]).unwrap(),
        std::fs::read(&logs[1]).unwrap()
    );
    assert_eq!(
        csv_column(&logs[0], "command_mm"),
        csv_column(&logs[1], "command_mm")
    );
    let (a, b) = (
        csv_column(&logs[0], "displacement_mm"),
        csv_column(&logs[1], "displacement_mm"),
    );
    assert_eq!(a.len(), 21_000);
    let rms = (a.iter().zip(&b).map(|(x, y)| (x - y).powi(2)).sum::<f64>() / a.len() as f64).sqrt();
    let expected = 2f64.sqrt() * 0.002;
    assert!(
        (rms / expected - 1.0).abs() < 0.05,
        "difference RMS {rms} mm, expected {expected} mm"
    );
}

/// Each bad input: exit code 2, the file and the key named, no output.
fn refused(text: &str, key: &str, what: &str) {
    let dir = scratch();
    let manifest = write(dir.path(), "bad-sim.toml", text);
    let out = dir.path().join("out");
    let r = servoid_into(dir.path(), "simulate", &manifest, &out, &[]);
    assert_eq!(r.code, 2, "{key}: stdout {} stderr {}", r.stdout, r.stderr);
    assert!(r.stderr.contains("bad-sim.toml"), "{key}: {}", r.stderr);
    assert!(r.stderr.contains(key), "expected {key} in: {}", r.stderr);
    assert!(
        r.stderr.contains(what),
        "expected `{what}` in: {}",
        r.stderr
    );
    assert!(!out.exists(), "{key}: nothing is written");
    // `servoid check` refuses it the same way.
    let c = servoid(dir.path(), &["check", manifest.to_str().unwrap()]);
    assert_eq!(c.code, 2, "check {key}: {}", c.stderr);
    assert!(c.stderr.contains(key), "check {key}: {}", c.stderr);
}

#[test]
fn a_band_above_nyquist_is_refused() {
    refused(
        &BASE.replace("band_hz = [0.5, 30.0]", "band_hz = [0.5, 600.0]"),
        "identification.band_hz",
        "Nyquist frequency (500 Hz",
    );
    refused(
        &BASE.replace("f1_hz = 40.0", "f1_hz = 700.0"),
        "excitation.f1_hz",
        "Nyquist frequency (500 Hz",
    );
}

#[test]
fn a_non_positive_duration_or_sample_rate_is_refused() {
    refused(
        &BASE.replace("duration_s = 20.0", "duration_s = 0.0"),
        "excitation.duration_s",
        "must be positive",
    );
    refused(
        &BASE.replace("duration_s = 20.0", "duration_s = -3.0"),
        "excitation.duration_s",
        "must be positive",
    );
    refused(
        &BASE.replace("sample_rate_hz = 1000.0", "sample_rate_hz = 0.0"),
        "simulation.sample_rate_hz",
        "must be positive",
    );
    refused(
        &BASE.replace("sample_rate_hz = 1000.0", "sample_rate_hz = -1000.0"),
        "simulation.sample_rate_hz",
        "must be positive",
    );
}

#[test]
fn a_nonlinear_specimen_with_missing_parameters_is_refused() {
    refused(
        &BASE.replace(
            "specimen = { mass_kg = 4.0, damping_ns_per_m = 10.0, stiffness_n_per_m = 120000.0 }",
            r#"specimen = { model = "duffing", mass_kg = 4.0, damping_ns_per_m = 10.0, stiffness_n_per_m = 120000.0 }"#,
        ),
        "cubic_stiffness_n_per_m3",
        "runs[2]",
    );
    refused(
        &BASE.replace(
            "specimen = { mass_kg = 4.0, damping_ns_per_m = 10.0, stiffness_n_per_m = 120000.0 }",
            r#"specimen = { model = "bouc_wen", mass_kg = 4.0, damping_ns_per_m = 10.0, stiffness_n_per_m = 120000.0 }"#,
        ),
        "bouc_wen",
        "runs[2]",
    );
}

/// A valve mode at 5 Hz with 5 % damping inside the position loop: the
/// closed loop's valve pair crosses into the right half-plane (the loop gain
/// a1b0/a2 = 2857 1/s^2 is far too high for that much phase lag).
#[test]
fn an_unstable_true_plant_is_refused() {
    let text = BASE.replace(
        "[rig.parameters]",
        "[rig.unmodelled]\nvalve_mode = { natural_frequency_hz = 5.0, damping_ratio = 0.05 }\n\n[rig.parameters]",
    );
    refused(&text, "runs[0]", "unstable");
    refused(
        &BASE.replace("beta1_per_s = 250.0", "beta1_per_s = -250.0"),
        "rig.parameters.beta1_per_s",
        "must be positive",
    );
}

#[test]
fn a_seed_that_is_not_an_integer_is_refused() {
    for seed in ["1.5", "\"seven\"", "-3"] {
        refused(
            &BASE.replace("seed = 7", &format!("seed = {seed}")),
            "simulation.seed",
            "must be a whole number, 0 or more, not the ",
        );
    }
}

/// The bundled default and the rich campaign pass `servoid check`.
#[test]
fn the_bundled_simulation_manifests_check() {
    for m in [
        "experiments/maghareh2018/simulation.toml",
        "experiments/maghareh2018/simulation-rich.toml",
    ] {
        let r = servoid(&root(), &["check", m]);
        assert_eq!(r.code, 0, "{m}: {}", r.stderr);
        assert!(r.stdout.contains("7 runs"), "{m}: {}", r.stdout);
    }
}

/// A validation run whose manifest names the wrong specimen: simulated with
/// m = 4 kg, k = 80 kN/m, analysed as m = 12 kg, k = 200 kN/m. Its NRMSE is
/// far above the three honest runs', so results.json and the page flag it;
/// the honest runs stay unflagged, and Table 4 shows the paper's simplified
/// form beside the full one for every validation run.
#[test]
fn a_validation_run_with_the_wrong_specimen_is_flagged() {
    let runs = (1..=4)
        .map(|i| {
            format!(
                "[[runs]]\nid = \"v{i}\"\nrole = \"validation\"\np_gain = {}\nspecimen = {{ mass_kg = 4.0, damping_ns_per_m = 10.0, stiffness_n_per_m = {} }}\n",
                if i % 2 == 0 { 1.5 } else { 1.0 },
                if i <= 2 { 120000.0 } else { 80000.0 }
            )
        })
        .collect::<Vec<_>>()
        .join("\n");
    let cut = BASE.find("[[runs]]\nid = \"v1\"").expect("the v1 run");
    let text = format!("{}{runs}", &BASE[..cut]);
    let dir = scratch();
    let manifest = write(dir.path(), "sim.toml", &text);
    let out = dir.path().join("out");
    let r = servoid_into(dir.path(), "simulate", &manifest, &out, &["--quiet"]);
    assert_eq!(r.code, 0, "{}", r.stderr);
    // The lab's mistake: v3's specimen written down wrong.
    let campaign = out.join("campaign.toml");
    let generated = std::fs::read_to_string(&campaign).unwrap();
    let (i, j) = (
        generated.find("id = \"v3\"").unwrap(),
        generated.find("id = \"v4\"").unwrap(),
    );
    let wrong = generated[i..j]
        .replace("mass_kg = 4.0", "mass_kg = 12.0")
        .replace(
            "stiffness_n_per_m = 80000.0",
            "stiffness_n_per_m = 200000.0",
        );
    assert_ne!(wrong, generated[i..j], "the specimen was edited");
    std::fs::write(
        &campaign,
        format!("{}{wrong}{}", &generated[..i], &generated[j..]),
    )
    .unwrap();
    let r = servoid_into(dir.path(), "run", &campaign, &out, &["--quiet"]);
    assert_eq!(r.code, 0, "{}", r.stderr);
    let results = json(&out.join("results.json"));
    let validation = |id: &str| run_by_id(&results, id)["validation"].clone();
    for id in ["v1", "v2", "v4"] {
        let v = validation(id);
        assert_eq!(v["outlier"], false, "{id}: {v}");
        assert!(v["nrmse_pct"].as_f64().unwrap() < 0.5, "{id}: {v}");
    }
    let v3 = validation("v3");
    assert_eq!(v3["outlier"], true, "{v3}");
    let note = v3["note"].as_str().unwrap();
    assert!(note.contains("specimen"), "{note}");
    // The simplified form is checked for each run: stable or not, stated.
    for id in ["v1", "v2", "v3", "v4"] {
        let s = &validation(id)["simplified_ccf"];
        assert!(s["stable"].is_boolean(), "{id}: {s}");
        assert_eq!(s["errors"].is_null(), s["stable"] == false, "{id}: {s}");
    }
    let page = std::fs::read_to_string(out.join("report.html")).unwrap();
    let table4 = &page[page.find("id=\"table4\"").expect("Table 4 on the page")..];
    let row = &table4[table4.find("<td class=\"l\">v3</td>").expect("v3's row")
        ..table4.find("<td class=\"l\">v4</td>").expect("v4's row")];
    assert!(row.contains("flagcell"), "v3's row is flagged: {row}");
    assert!(
        table4.contains("CCF, Cn dropped"),
        "the side-by-side columns"
    );
}

/// The three programs `servoid simulate` makes for servo tuning and real
/// supplies, on BASE's rig with the ShoreWestern actuator's flow-pressure
/// law (A = 2.387e-4 m^2, P_s = 20.7 MPa, docs/model.md):
/// - k1 under a square wave of +-10 mm, 6 s period: the logged command holds
///   exact plateaus, switching at the sample nearest each edge; each plateau
///   ends, settled, at the force the reduced flow balances the leak at;
/// - v1 under a 3 mm chirp limited to 2 mm: the logged command never
///   exceeds the limit and sits at it on the samples where the chirp's own
///   formula is beyond it;
/// - truth.json holds F_max, and the campaign is not "clean".
#[test]
fn square_waves_command_limits_and_the_flow_law_are_simulated() {
    let (area, supply) = (2.387e-4, 20.7e6);
    let fmax = area * supply;
    let (amp, period, lead_in, fs) = (0.01, 6.0, 0.5, 1000.0);
    let (chirp_amp, limit) = (0.003, 0.002);
    let text = BASE
        .replace(
            "[rig.parameters]",
            &format!("supply_pressure_pa = {supply:e}\npiston_area_m2 = {area:e}\n\n[rig.parameters]"),
        )
        .replace("noise_rms = 1.0", "noise_rms = 0.0")
        .replace(
            "specimen = { stiffness_n_per_m = 100000.0 }",
            &format!(
                "specimen = {{ stiffness_n_per_m = 100000.0 }}\nexcitation = {{ kind = \"square\", amplitude_m = {amp}, period_s = {period:?}, duration_s = 12.0, lead_in_s = {lead_in} }}"
            ),
        )
        .replace(
            "specimen = { mass_kg = 4.0,",
            &format!(
                "excitation = {{ kind = \"chirp\", law = \"linear\", f0_hz = 0.5, f1_hz = 40.0, duration_s = 20.0, amplitude_m = {chirp_amp}, limit_m = {limit}, lead_in_s = 0.5, lead_out_s = 0.5 }}\nspecimen = {{ mass_kg = 4.0,"
            ),
        );
    let dir = scratch();
    let manifest = write(dir.path(), "sim.toml", &text);
    let out = dir.path().join("out");
    let r = servoid_into(dir.path(), "simulate", &manifest, &out, &["--quiet"]);
    assert_eq!(r.code, 0, "{}", r.stderr);

    // The square wave, in mm: zeros, then +10 and -10 in turn with edge j
    // on sample lead-in + round(j period fs / 2) = 500 + 3000 j.
    let command = csv_column(&out.join("logs/k1.csv"), "command_mm");
    assert_eq!(command.len(), 500 + 12_000);
    assert!(command[..500].iter().all(|v| *v == 0.0));
    let level = command[500];
    assert!((level - 10.0).abs() < 1e-12, "{level}");
    for (i, v) in command[500..].iter().enumerate() {
        let want = if (i / 3000) % 2 == 0 { level } else { -level };
        assert_eq!(*v, want, "sample {}", 500 + i);
    }

    // Each plateau's last force: the steady state of the rig with the law.
    // At rest r = a1b0 (u0 - x1) / beta1 and r sqrt(1 - f / F_max) = a3 f
    // with f = k x1 (u0 > 0; the run is odd in u0): bisection on x1. The
    // slow pole (about -12 1/s) has died out in a 3 s plateau.
    let k = 1.0e5;
    let gap = |x: f64| A1B0 / BETA1 * (amp - x) * (1.0 - k * x / fmax).sqrt() - A3 * k * x;
    let (mut lo, mut hi) = (0.0, amp);
    for _ in 0..200 {
        let mid = 0.5 * (lo + hi);
        if gap(mid) > 0.0 {
            lo = mid;
        } else {
            hi = mid;
        }
    }
    let steady_force = k * 0.5 * (lo + hi);
    // Eq. 14's static gain would put it 2 % higher.
    let linear_force = k * amp * A1B0 / (A1B0 + BETA1 * A3 * k);
    assert!(steady_force < 0.99 * linear_force);
    let force = csv_column(&out.join("logs/k1.csv"), "force_n");
    for j in 0..4 {
        let last = 500 + 3000 * (j + 1) - 1;
        let want = if j % 2 == 0 {
            steady_force
        } else {
            -steady_force
        };
        assert!(
            rel(force[last], want) < 1e-6,
            "plateau {j}: {} N vs {want} N",
            force[last]
        );
    }

    // The limited chirp: |command| <= 2 mm, and at 2 mm exactly where the
    // linear chirp A sin(2 pi (f0 t + (f1 - f0) t^2 / (2 t1))) is beyond it
    // (a sample or two of slack for round-off at the threshold); about
    // 1 - (2 / pi) asin(L / A) of the sweep, as for any sine.
    let command = csv_column(&out.join("logs/v1.csv"), "command_mm");
    assert_eq!(command.len(), 21_000);
    let lim_mm = limit * 1000.0;
    assert!(command.iter().all(|v| v.abs() <= lim_mm));
    let at_limit = command.iter().filter(|v| v.abs() == lim_mm).count();
    let beyond = (0..20_000)
        .filter(|&i| {
            let t = i as f64 / fs;
            let phase = 2.0 * std::f64::consts::PI * (0.5 * t + 39.5 * t * t / 40.0);
            (chirp_amp * phase.sin()).abs() >= limit
        })
        .count();
    assert!(at_limit.abs_diff(beyond) <= 2, "{at_limit} vs {beyond}");
    let share = at_limit as f64 / 20_000.0;
    let sine_share = 1.0 - 2.0 / std::f64::consts::PI * (limit / chirp_amp).asin();
    assert!((share - sine_share).abs() < 0.01, "{share} vs {sine_share}");

    let truth = json(&out.join("truth.json"));
    assert!(rel(truth["max_force_n"].as_f64().unwrap(), fmax) < 1e-12);
    assert_eq!(truth["clean"], false);
    // Nonlinear: no transfer function of the simulated plant.
    assert!(run_by_id(&truth, "k1")["plant_tf_x1_u"].is_null());
}

/// The new keys are checked as the others: the key named, nothing written.
#[test]
fn square_waves_limits_and_the_supply_are_checked() {
    let square = "kind = \"square\"\n";
    let base_square = BASE.replace(
        "kind = \"chirp\"\nlaw = \"linear\"\nf0_hz = 0.5\nf1_hz = 40.0\n",
        square,
    );
    assert_ne!(base_square, BASE);
    refused(&base_square, "excitation.period_s", "needs `period_s`");
    refused(
        &base_square.replace(square, &format!("{square}period_s = 0.0015\n")),
        "excitation.period_s",
        "a square wave needs at least 2",
    );
    refused(
        &BASE.replace("duration_s = 20.0", "duration_s = 20.0\nlimit_m = -0.001"),
        "excitation.limit_m",
        "must be positive",
    );
    refused(
        &BASE.replace(
            "[rig.parameters]",
            "supply_pressure_pa = 2.07e7\n\n[rig.parameters]",
        ),
        "rig.piston_area_m2",
        "F_max = A P_s",
    );
}

/// A 50 kg specimen on a rig whose supply holds 300 N: swept to 40 Hz, its
/// inertia drives the chamber force past F_max against the flow, where the
/// valve passes no flow (BASE's 4 kg specimen and spring stay below it).
/// The run is named with the force and F_max, and nothing is written.
#[test]
fn a_force_beyond_the_supply_names_the_run() {
    let text = BASE
        .replace(
            "[rig.parameters]",
            "supply_pressure_pa = 3.0e7\npiston_area_m2 = 1.0e-5\n\n[rig.parameters]",
        )
        .replace("mass_kg = 4.0", "mass_kg = 50.0");
    let dir = scratch();
    let manifest = write(dir.path(), "sim.toml", &text);
    let out = dir.path().join("out");
    let r = servoid_into(dir.path(), "simulate", &manifest, &out, &[]);
    assert_ne!(r.code, 0, "{}", r.stdout);
    assert!(
        r.stderr.contains("run v1: the actuator force reached "),
        "{}",
        r.stderr
    );
    assert!(r.stderr.contains("F_max = A P_s = 300 N"), "{}", r.stderr);
    assert!(!out.join("truth.json").exists());
}

/// BASE with its command logged in metres, unquantised: each log is then
/// a command file (`time_s`, `command_m`) holding the command exactly.
fn base_in_metres() -> String {
    BASE.replace(
        "[instrument.command]\nunit = \"mm\"",
        "[instrument.command]\nunit = \"m\"",
    )
}

/// [`base_in_metres`] simulated into `a/` of a scratch folder: the folder
/// and the manifest's text.
fn generated_in_metres() -> (tempfile::TempDir, String) {
    let dir = scratch();
    let text = base_in_metres();
    let generated = write(dir.path(), "generated.toml", &text);
    let r = servoid_into(
        dir.path(),
        "simulate",
        &generated,
        &dir.path().join("a"),
        &[],
    );
    assert_eq!(r.code, 0, "{}", r.stderr);
    (dir, text)
}

/// Each run of BASE playing the command file `logs/<id>.csv` of `from`.
fn playing(text: &str, from: &str) -> String {
    ["bare", "k1", "v1"].iter().fold(text.to_string(), |t, id| {
        t.replace(
            &format!("id = \"{id}\"\n"),
            &format!(
                "id = \"{id}\"\nexcitation = {{ kind = \"file\", file = \"{from}/logs/{id}.csv\" }}\n"
            ),
        )
    })
}

/// A command file plays sample for sample: each run replaying the command
/// its chirp generated (read back from the log, whose text holds every
/// double exactly) gives the same log bytes as generating it, and truth.json
/// records the SHA-256 of the file each run played.
#[test]
fn a_command_file_plays_as_the_command_it_holds() {
    let (dir, text) = generated_in_metres();
    assert_ne!(text, BASE, "the command is logged in metres");
    let played = write(dir.path(), "played.toml", &playing(&text, "a"));
    let r = servoid_into(dir.path(), "simulate", &played, &dir.path().join("b"), &[]);
    assert_eq!(r.code, 0, "{}", r.stderr);
    let truth = json(&dir.path().join("b/truth.json"));
    for id in ["bare", "k1", "v1"] {
        let log =
            |set: &str| std::fs::read(dir.path().join(format!("{set}/logs/{id}.csv"))).unwrap();
        assert!(
            log("a") == log("b"),
            "{id}: the played log is the generated one"
        );
        let sha = run_by_id(&truth, id)["command_sha256"]
            .as_str()
            .unwrap()
            .to_string();
        assert_eq!(sha, sha256_of(&log("a")), "{id}");
    }
    let generated_truth = json(&dir.path().join("a/truth.json"));
    assert!(
        run_by_id(&generated_truth, "bare")
            .get("command_sha256")
            .is_none()
    );
}

/// SHA-256 by the `sha2` crate, independently of servoid's own helper.
fn sha256_of(bytes: &[u8]) -> String {
    use sha2::Digest;
    sha2::Sha256::digest(bytes)
        .iter()
        .map(|b| format!("{b:02x}"))
        .collect()
}

/// A command file that cannot be played is refused naming the run and the
/// file: at another rate than the simulation's (both rates said), without
/// a command_m column, absent; a file excitation without `file` or with a
/// duration of its own is a manifest problem.
#[test]
fn a_command_file_that_cannot_be_played_is_refused() {
    let (dir, text) = generated_in_metres();
    let fails = |text: &str, words: &[&str]| {
        let manifest = write(dir.path(), "played.toml", text);
        let out = dir.path().join("b");
        let r = servoid_into(dir.path(), "simulate", &manifest, &out, &[]);
        assert_ne!(r.code, 0, "{}", r.stdout);
        for w in words {
            assert!(r.stderr.contains(w), "expected `{w}` in: {}", r.stderr);
        }
        assert!(!out.join("truth.json").exists(), "nothing is written");
    };
    let played = playing(&text, "a");
    fails(
        &played.replace("sample_rate_hz = 1000.0", "sample_rate_hz = 2000.0"),
        &["run bare", "bare.csv", "sampled at 1000 Hz", "is 2000 Hz"],
    );
    std::fs::create_dir_all(dir.path().join("c/logs")).unwrap();
    write(
        dir.path(),
        "c/logs/bare.csv",
        "time_s,u_m\n0,0\n0.001,0\n0.002,0\n",
    );
    fails(
        &played.replace("a/logs/bare.csv", "c/logs/bare.csv"),
        &["run bare", "bare.csv", "command_m"],
    );
    fails(
        &played.replace("a/logs/k1.csv", "nowhere/k1.csv"),
        &["run k1", "nowhere/k1.csv"],
    );
    refused(
        &text.replace(
            "id = \"bare\"\n",
            "id = \"bare\"\nexcitation = { kind = \"file\" }\n",
        ),
        "runs[0].excitation.file",
        "a file excitation needs `file`",
    );
    refused(
        &playing(&text, "a").replace(
            "file = \"a/logs/bare.csv\"",
            "file = \"a/logs/bare.csv\", duration_s = 20.0",
        ),
        "runs[0].excitation.duration_s",
        "a command file's length is its own",
    );
}
