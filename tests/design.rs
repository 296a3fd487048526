//! The design's predicted precision against what an analysis states: the
//! Cramer-Rao stds of a campaign's rig (`servoid::design::precision`, from
//! its commands and the noise its manifest gives the instruments) are the
//! stds `servoid run` states for that campaign's logs.

use servoid::design::precision::{PlannedRun, etfe_variance, predict};
use servoid::fit::Intersample;
use servoid::model::{LinearSpecimen, RigParams};
use servoid::simulate::excitation::{ChirpLaw, Excitation, Padding, generate};

use crate::util::{bundled_simulation, scratch, servoid_into, write};

const SMALL: &str = include_str!("fixtures/small-simulation.toml");

/// The predicted stds of (beta1, a1b0, a2, a3): the identification runs
/// (`specimens`, at P = 1) each an ETFE of `command` over its whole record
/// at `fs`, on 0.5-30 Hz, the displacement's noise `noise_rms_m` RMS with
/// 18-bit steps over +-50 mm.
fn predicted(
    rig: &RigParams,
    command: &Excitation,
    padding: Padding,
    fs: f64,
    noise_rms_m: f64,
    specimens: &[LinearSpecimen],
) -> [f64; 4] {
    let u = generate(command, fs, padding).unwrap();
    let step = 0.1 / 2f64.powi(18);
    let noise = noise_rms_m.powi(2) + step * step / 12.0;
    let (freq_hz, variance) = etfe_variance(&u, fs, [0.5, 30.0], |_| noise);
    let runs: Vec<PlannedRun> = specimens
        .iter()
        .map(|s| PlannedRun {
            specimen: *s,
            p_gain: 1.0,
            freq_hz: freq_hz.clone(),
            variance: variance.clone(),
        })
        .collect();
    predict(rig, &runs, Intersample::SampleAndHold, fs)
        .expect("the runs determine the rig")
        .std()
}

/// The small campaign's rig, command and identification runs.
fn small() -> (RigParams, Excitation, Padding, [LinearSpecimen; 2]) {
    (
        RigParams {
            beta1_per_s: 250.0,
            a1b0_n_per_m_s2: 2.0e9,
            a2_n_per_m: 7.0e5,
            a3_per_s: 15.0,
            p_gain: 1.0,
        },
        Excitation::Chirp {
            law: ChirpLaw::Linear,
            f0_hz: 0.5,
            f1_hz: 40.0,
            duration_s: 20.0,
            amplitude_m: 0.003,
        },
        Padding {
            lead_in_s: 0.5,
            lead_out_s: 0.5,
        },
        [
            LinearSpecimen::None,
            LinearSpecimen::Spring {
                stiffness_n_per_m: 1.0e5,
            },
        ],
    )
}

/// `servoid simulate --run` of `manifest`: results.json.
fn stated(dir: &std::path::Path, manifest: &std::path::Path) -> serde_json::Value {
    let out = dir.join("out");
    let r = servoid_into(dir, "simulate", manifest, &out, &["--run", "--quiet"]);
    assert_eq!(r.code, 0, "{}", r.stderr);
    serde_json::from_str(&std::fs::read_to_string(out.join("results.json")).unwrap()).unwrap()
}

const NAMES: [&str; 4] = ["beta1", "a1b0", "a2", "a3"];

/// The bundled default (the paper's 172 s quadratic chirps at 2,048 Hz,
/// 2 um of LVDT noise, the no-specimen run and two springs in the joint
/// fit): the stds its main job states are the predicted ones to 3 %.
#[test]
fn the_bundled_defaults_stds_are_the_predicted_ones() {
    let chirp = Excitation::Chirp {
        law: ChirpLaw::Quadratic,
        f0_hz: 0.1,
        f1_hz: 35.0,
        duration_s: 170.0,
        amplitude_m: 0.004,
    };
    let padding = Padding {
        lead_in_s: 1.0,
        lead_out_s: 1.0,
    };
    let springs = [116_640.0, 88_540.0].map(|k| LinearSpecimen::Spring {
        stiffness_n_per_m: k,
    });
    let specimens = [LinearSpecimen::None, springs[0], springs[1]];
    let rig = servoid::model::PAPER_RIG;
    let predicted = predicted(&rig, &chirp, padding, 2048.0, 2e-6, &specimens);
    let dir = scratch();
    let results = stated(dir.path(), &bundled_simulation(dir.path(), false));
    for (j, name) in NAMES.iter().enumerate() {
        let stated = results["rig"][*name]["std"].as_f64().unwrap();
        let ratio = stated / predicted[j];
        assert!(
            (0.97..1.03).contains(&ratio),
            "{name}: stated {stated}, predicted {} (ratio {ratio})",
            predicted[j]
        );
    }
}

/// The small campaign over 100 seeds: the joint estimates scatter as
/// predicted, each std within 20 % (a sample std of 100 is uncertain by
/// 7 %). Statistical, so `#[ignore]`d; `.ci/run` runs it by name. It prints
/// the mean stated std over the scatter, which docs/accuracy.md gives.
#[test]
#[ignore]
fn the_small_campaigns_scatter_over_seeds_is_the_predicted_one() {
    let (rig, chirp, padding, specimens) = small();
    let predicted = predicted(&rig, &chirp, padding, 1000.0, 2e-6, &specimens);
    let seeds = 100;
    let mut values = vec![Vec::new(); 4];
    let mut stds = vec![Vec::new(); 4];
    for seed in 1..=seeds {
        let dir = scratch();
        let manifest = write(
            dir.path(),
            "sim.toml",
            &SMALL.replace("seed = 7", &format!("seed = {seed}")),
        );
        let results = stated(dir.path(), &manifest);
        for (j, name) in NAMES.iter().enumerate() {
            values[j].push(results["rig"][*name]["value"].as_f64().unwrap());
            stds[j].push(results["rig"][*name]["std"].as_f64().unwrap());
        }
    }
    for (j, name) in NAMES.iter().enumerate() {
        let n = values[j].len() as f64;
        let mean = values[j].iter().sum::<f64>() / n;
        let scatter =
            (values[j].iter().map(|v| (v - mean).powi(2)).sum::<f64>() / (n - 1.0)).sqrt();
        let mean_stated = stds[j].iter().sum::<f64>() / n;
        eprintln!(
            "{name}: scatter / predicted {:.3}, mean stated / scatter {:.3}",
            scatter / predicted[j],
            mean_stated / scatter
        );
        assert!(
            (0.8..1.2).contains(&(scatter / predicted[j])),
            "{name}: scatter {scatter} against predicted {}",
            predicted[j]
        );
    }
}

/// The short campaign's rig, runs, command and noise, as its manifest
/// states them: the no-specimen run and the spring enter the joint fit,
/// each an ETFE over its whole 21 s record, the displacement's noise 2 um
/// RMS and 18-bit steps over +-50 mm. The stated stds are 1.03 (beta1) to
/// 1.23 (a3) times the predicted ones: the estimates scatter as predicted
/// over seeds (the ignored test below), so the analysis states this short
/// record's a1b0, a2 and a3 up to a fifth wider than they are
/// (docs/accuracy.md).
#[test]
fn the_predicted_stds_are_the_ones_an_analysis_states() {
    let (rig, chirp, padding, specimens) = small();
    let predicted = predicted(&rig, &chirp, padding, 1000.0, 2e-6, &specimens);
    let dir = scratch();
    let results = stated(dir.path(), &write(dir.path(), "sim.toml", SMALL));
    for (j, name) in NAMES.iter().enumerate() {
        let stated = results["rig"][*name]["std"].as_f64().unwrap();
        let ratio = stated / predicted[j];
        assert!(
            (0.9..1.3).contains(&ratio),
            "{name}: stated {stated}, predicted {}",
            predicted[j]
        );
    }
}

/// The small campaign on a 2 s odd multisine over 0.5-30 Hz (2 mm RMS, 10
/// periods, the first fading in and the last out) with servoid's default
/// FRF settings, seed `seed`, and `unmodelled` lines under `[rig]`.
fn periodic_campaign(seed: u64, unmodelled: &str) -> String {
    let excitation = SMALL
        .split("[excitation]")
        .nth(1)
        .and_then(|rest| rest.split("[instrument.command]").next())
        .expect("the small campaign's excitation");
    SMALL
        .replace(
            excitation,
            "\nkind = \"odd_multisine\"\nf_min_hz = 0.5\nf_max_hz = 30.0\nperiod_s = 2.0\nduration_s = 20.0\nrms_m = 0.002\nlead_in_s = 0.5\nlead_out_s = 0.5\n\n",
        )
        .replace("seed = 7", &format!("seed = {seed}"))
        .replace(
            "frf = { estimator = \"etfe\", segment_length = 4096, overlap = 0.5, window = \"rectangular\", detrend = \"mean\" }\n",
            "",
        )
        .replace("[rig.parameters]", &format!("{unmodelled}[rig.parameters]"))
}

/// The command column (mm) of a simulated CSV log, in metres.
fn logged_command_m(path: &std::path::Path) -> Vec<f64> {
    let text = std::fs::read_to_string(path).unwrap();
    let mut lines = text.lines();
    let header: Vec<&str> = lines.next().unwrap().split(',').collect();
    let j = header.iter().position(|h| *h == "command_mm").unwrap();
    lines
        .map(|l| l.split(',').nth(j).unwrap().parse::<f64>().unwrap() * 1e-3)
        .collect()
}

/// Twenty seeds of a periodic night, each analysed with the defaults:
/// the log is read on its steady periods (8 of 2 s), the stated stds are
/// within 20 % of the ones predicted from the logged commands' steady
/// periods and the instruments' noise (on average over the seeds), and
/// each parameter is within 3 stated stds of the truth.
#[test]
fn a_periodic_nights_stds_are_the_predicted_ones() {
    let (rig, _, _, specimens) = small();
    let seeds = 20;
    let mut ratios = [0.0; 4];
    for seed in 1..=seeds {
        let dir = scratch();
        let manifest = write(dir.path(), "sim.toml", &periodic_campaign(seed, ""));
        let results = stated(dir.path(), &manifest);
        let step = 0.1 / 2f64.powi(18);
        let noise = 4e-12 + step * step / 12.0;
        let mut runs = Vec::new();
        for (id, specimen) in ["bare", "k1"].iter().zip(specimens) {
            let run = crate::util::run_by_id(&results, id);
            let p = &run["periodic"];
            assert_eq!(p["periods"].as_u64(), Some(8), "seed {seed} {id}: {p}");
            assert_eq!(p["period_s"].as_f64(), Some(2.0));
            assert!(!p["distorts"].as_bool().unwrap(), "seed {seed} {id}: {p}");
            let u = logged_command_m(&dir.path().join(format!("out/logs/{id}.csv")));
            let start = (p["start_s"].as_f64().unwrap() * 1000.0).round() as usize;
            let steady = &u[start..start + 16_000];
            let (freq_hz, variance) = etfe_variance(steady, 1000.0, [0.5, 30.0], |_| noise);
            runs.push(PlannedRun {
                specimen,
                p_gain: 1.0,
                freq_hz,
                variance,
            });
        }
        let predicted = predict(&rig, &runs, Intersample::SampleAndHold, 1000.0)
            .unwrap()
            .std();
        let truth = [250.0, 2.0e9, 7.0e5, 15.0];
        for (j, name) in NAMES.iter().enumerate() {
            let value = results["rig"][*name]["value"].as_f64().unwrap();
            let std = results["rig"][*name]["std"].as_f64().unwrap();
            assert!(
                (value - truth[j]).abs() <= 3.0 * std,
                "seed {seed}: {name} = {value} +/- {std}, truth {}",
                truth[j]
            );
            ratios[j] += std / predicted[j] / seeds as f64;
        }
    }
    for (name, ratio) in NAMES.iter().zip(ratios) {
        assert!(
            (0.8..1.2).contains(&ratio),
            "{name}: the stated stds are {ratio} times the predicted ones"
        );
    }
}

/// The periodic night on a rig whose piston's seals rub (Coulomb friction
/// of 20 N, the nonlinear suite's) distorts: the command's empty lines
/// hold well above the noise floor the periods' spread gives, and the run
/// says so; on the linear rig they hold the noise floor.
#[test]
fn a_periodic_log_tells_distortion_from_noise() {
    let friction = "[rig.unmodelled]\npiston_mass_kg = 2.0\nactuator_friction = { coulomb_force_n = 20.0, smoothing_velocity_m_per_s = 0.002 }\n\n";
    let ratio = |unmodelled: &str| -> (f64, bool, serde_json::Value) {
        let dir = scratch();
        let manifest = write(dir.path(), "sim.toml", &periodic_campaign(1, unmodelled));
        let results = stated(dir.path(), &manifest);
        let run = crate::util::run_by_id(&results, "bare").clone();
        let p = &run["periodic"];
        (
            p["distortion_to_noise"].as_f64().unwrap(),
            p["distorts"].as_bool().unwrap(),
            run,
        )
    };
    let (linear, distorts, _) = ratio("");
    assert!(
        !distorts && (0.6..1.4).contains(&linear),
        "linear rig: {linear}"
    );
    let (rubbing, distorts, run) = ratio(friction);
    assert!(distorts && rubbing > 10.0, "friction: {rubbing}");
    let warned = run["warnings"]
        .as_array()
        .unwrap()
        .iter()
        .any(|w| w.to_string().contains("the rig distorts"));
    assert!(warned, "{}", run["warnings"]);
}
