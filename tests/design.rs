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
/// the log is read on its steady periods (7 of 2 s: the fades and the
/// period the response settles in are left out), the stated stds are
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
            assert_eq!(p["periods"].as_u64(), Some(7), "seed {seed} {id}: {p}");
            assert_eq!(p["period_s"].as_f64(), Some(2.0));
            assert!(!p["distorts"].as_bool().unwrap(), "seed {seed} {id}: {p}");
            let u = logged_command_m(&dir.path().join(format!("out/logs/{id}.csv")));
            let start = (p["start_s"].as_f64().unwrap() * 1000.0).round() as usize;
            let steady = &u[start..start + 14_000];
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
    eprintln!("stated / predicted {ratios:?}");
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

/// The bundled default simulated and run, then `servoid design` on its
/// results (the defaults: last night's peak command and record, no other
/// limit) into `dir`/design: the design's folder and design.json.
fn designed_from_the_bundled_default(dir: &std::path::Path, extra: &[&str]) -> serde_json::Value {
    let last = dir.join("out");
    let r = servoid_into(
        dir,
        "simulate",
        &bundled_simulation(dir, false),
        &last,
        &["--run", "--quiet"],
    );
    assert_eq!(r.code, 0, "{}", r.stderr);
    designed(dir, &last, &dir.join("design"), extra)
}

/// `servoid design FROM --out OUT EXTRA...` run in `cwd`, which must
/// succeed: the design.json it wrote.
fn designed(
    cwd: &std::path::Path,
    from: &std::path::Path,
    out: &std::path::Path,
    extra: &[&str],
) -> serde_json::Value {
    let mut args = vec![
        "design",
        from.to_str().unwrap(),
        "--out",
        out.to_str().unwrap(),
    ];
    args.extend_from_slice(extra);
    let r = crate::util::servoid(cwd, &args);
    assert_eq!(r.code, 0, "{}", r.stderr);
    serde_json::from_str(&std::fs::read_to_string(out.join("design.json")).unwrap()).unwrap()
}

/// The design's check.toml with `seed`, simulated and run: results.json
/// and truth.json.
fn checked(design: &std::path::Path, seed: u64) -> (serde_json::Value, serde_json::Value) {
    let text = std::fs::read_to_string(design.join("check.toml")).unwrap();
    assert!(text.contains("\nseed = 1\n"));
    let manifest = write(
        design,
        &format!("check-{seed}.toml"),
        &text.replace("\nseed = 1\n", &format!("\nseed = {seed}\n")),
    );
    let out = design.join(format!("check-{seed}"));
    let r = servoid_into(design, "simulate", &manifest, &out, &["--run", "--quiet"]);
    assert_eq!(r.code, 0, "{}", r.stderr);
    let read = |name: &str| -> serde_json::Value {
        serde_json::from_str(&std::fs::read_to_string(out.join(name)).unwrap()).unwrap()
    };
    (read("results.json"), read("truth.json"))
}

/// The issue's loop through the CLI: the bundled default's results, its
/// design, and the design's check.toml (the commands played on the rig
/// identified, with the noise measured) simulated and run over 20 seeds
/// with the defaults. Over the seeds the stated stds are the predicted
/// ones within 20 % on average, and every parameter's z-scores against
/// the truth have an RMS within 0.6-1.4 and none beyond 4
/// (docs/accuracy.md, "The designed night, end to end", gives what it
/// measured). In prediction the night clears the issue's bar against the
/// paper's chirps (1.3 and 2); the stated stds over the seeds against the
/// bundled default's, the chirps' own, are printed for docs/accuracy.md.
#[test]
fn a_designed_night_states_the_stds_it_was_designed_for() {
    let dir = scratch();
    let design = designed_from_the_bundled_default(dir.path(), &[]);
    let baseline = &design["baseline"];
    assert!(
        baseline["worst_ratio"].as_f64().unwrap() >= 1.3
            && baseline["squares_ratio"].as_f64().unwrap() >= 2.0,
        "{baseline}"
    );
    let last: serde_json::Value = serde_json::from_str(
        &std::fs::read_to_string(dir.path().join("out/results.json")).unwrap(),
    )
    .unwrap();
    let predicted: Vec<f64> = (0..4)
        .map(|j| design["parameters"][j]["std"].as_f64().unwrap())
        .collect();
    let truth_key = ["beta1_per_s", "a1b0_n_per_m_s2", "a2_n_per_m", "a3_per_s"];
    let seeds = 20;
    let (mut ratio, mut z2, mut beyond, mut largest) = ([0.0; 4], [0.0; 4], 0, 0.0_f64);
    let mut stated_mean = [0.0; 4];
    for seed in 1..=seeds {
        let (results, truth) = checked(&dir.path().join("design"), seed);
        for (j, name) in NAMES.iter().enumerate() {
            let e = &results["rig"][*name];
            let (value, std) = (e["value"].as_f64().unwrap(), e["std"].as_f64().unwrap());
            let z = (value - truth["rig"][truth_key[j]].as_f64().unwrap()) / std;
            ratio[j] += std / predicted[j] / seeds as f64;
            stated_mean[j] += std / seeds as f64;
            z2[j] += z * z / seeds as f64;
            beyond += usize::from(z.abs() > 3.0);
            largest = largest.max(z.abs());
        }
    }
    let rel = |std: [f64; 4]| -> [f64; 4] {
        std::array::from_fn(|j| std[j] / last["rig"][NAMES[j]]["value"].as_f64().unwrap())
    };
    let chirps: [f64; 4] = std::array::from_fn(|j| last["rig"][NAMES[j]]["std"].as_f64().unwrap());
    let (ours, theirs) = (rel(stated_mean), rel(chirps));
    let max = |r: [f64; 4]| r.into_iter().fold(0.0, f64::max);
    let squares = |r: [f64; 4]| r.iter().map(|r| r * r).sum::<f64>();
    eprintln!(
        "stated / predicted {ratio:?}; z RMS {:?}; beyond 3: {beyond}; the bundled default's stated stds over the designed night's: worst {:.2}, squares {:.2}",
        z2.map(f64::sqrt),
        max(theirs) / max(ours),
        squares(theirs) / squares(ours)
    );
    for (j, name) in NAMES.iter().enumerate() {
        assert!(
            (0.8..1.2).contains(&ratio[j]),
            "{name}: stated {} times the predicted",
            ratio[j]
        );
        assert!(
            (0.6..1.4).contains(&z2[j].sqrt()),
            "{name}: z RMS {}",
            z2[j].sqrt()
        );
    }
    assert!(
        largest <= 4.0,
        "{beyond} of 80 beyond 3 stds, the largest {largest}"
    );
}

/// The command a design wrote (commands/<run>.csv): time_s and command_m.
fn written_command(path: &std::path::Path) -> (Vec<f64>, Vec<f64>) {
    let text = std::fs::read_to_string(path).unwrap();
    let mut lines = text.lines();
    assert_eq!(lines.next(), Some("time_s,command_m"));
    lines
        .map(|l| {
            let (t, u) = l.split_once(',').unwrap();
            (t.parse::<f64>().unwrap(), u.parse::<f64>().unwrap())
        })
        .unzip()
}

/// `servoid design` with a stroke, a velocity and a force given: every
/// run's predicted peaks are within them and the command written peaks
/// where design.json says, at the DAQ's rate, from rest to rest. The
/// commands' MAT files play as the CSV ones do (the same logs), and the
/// next night's manifest analyses the check's logs as the check did.
#[test]
fn a_design_keeps_to_its_limits_and_its_files_play() {
    let dir = scratch();
    let design = designed_from_the_bundled_default(
        dir.path(),
        &[
            "--stroke-mm",
            "1.5",
            "--velocity-mm-s",
            "60",
            "--force-n",
            "150",
        ],
    );
    let folder = dir.path().join("design");
    let limits = [("stroke", 1.5e-3), ("velocity", 0.06), ("force", 150.0)];
    let mut bounds = Vec::new();
    for run in design["runs"].as_array().unwrap() {
        let peaks = &run["peaks"];
        let peak = |k: &str| peaks[k].as_f64();
        assert!(peak("displacement_m").unwrap() <= limits[0].1, "{run}");
        assert!(peak("velocity_m_per_s").unwrap() <= limits[1].1, "{run}");
        assert!(peak("force_n").is_none_or(|f| f <= limits[2].1), "{run}");
        assert!(peak("command_m").unwrap() <= 0.0040002, "{run}");
        bounds.push(run["bound_by"].as_str().unwrap().to_string());
        let (t, u) = written_command(&folder.join(run["command_csv"].as_str().unwrap()));
        assert!(
            t.windows(2)
                .all(|w| ((w[1] - w[0]) * 2048.0 - 1.0).abs() < 1e-9)
        );
        assert_eq!((u[0], *u.last().unwrap()), (0.0, 0.0));
        let largest = u.iter().fold(0.0_f64, |m, v| m.max(v.abs()));
        assert!((largest / peak("command_m").unwrap() - 1.0).abs() < 1e-12);
    }
    assert!(
        bounds.iter().any(|b| b != "command"),
        "some run meets a limit other than the command's: {bounds:?}"
    );
    let (checked_results, _) = checked(&folder, 1);
    let mat = std::fs::read_to_string(folder.join("check.toml"))
        .unwrap()
        .replace(".csv\"", ".mat\"")
        .replace("\nseed = 1\n", "\nseed = 1\nlog_format = \"csv\"\n")
        .replacen("log_format = \"csv\"\n", "", 1);
    let manifest = write(&folder, "check-mat.toml", &mat);
    let r = servoid_into(
        &folder,
        "simulate",
        &manifest,
        &folder.join("check-mat"),
        &[],
    );
    assert_eq!(r.code, 0, "{}", r.stderr);
    for run in design["runs"].as_array().unwrap() {
        let log = format!("logs/{}.csv", run["id"].as_str().unwrap());
        assert_eq!(
            std::fs::read(folder.join("check-1").join(&log)).unwrap(),
            std::fs::read(folder.join("check-mat").join(&log)).unwrap(),
            "{log}"
        );
    }
    std::fs::create_dir_all(folder.join("logs")).unwrap();
    for run in design["runs"].as_array().unwrap() {
        let log = run["log"].as_str().unwrap();
        std::fs::copy(folder.join("check-1").join(log), folder.join(log)).unwrap();
    }
    let night = folder.join("night");
    let r = servoid_into(
        &folder,
        "run",
        &folder.join("campaign.toml"),
        &night,
        &["--quiet"],
    );
    assert_eq!(r.code, 0, "{}", r.stderr);
    let results: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(night.join("results.json")).unwrap())
            .unwrap();
    for name in NAMES {
        let (a, b) = (&results["rig"][name], &checked_results["rig"][name]);
        for key in ["value", "std"] {
            let (x, y) = (a[key].as_f64().unwrap(), b[key].as_f64().unwrap());
            assert!((x / y - 1.0).abs() < 1e-9, "{name}.{key}: {x} against {y}");
        }
    }
}

/// `--target-std`: a reachable worst relative std gives the runs the
/// length it needs (shorter than last night's here) and reaches it in
/// prediction; one the time per run cannot reach is refused, naming that
/// limit and the one that sets the amplitudes, and writes nothing; a
/// limit given wrongly is a usage error naming its flag.
#[test]
fn a_target_std_sets_the_record_or_names_what_stops_it() {
    let dir = scratch();
    let design = designed_from_the_bundled_default(dir.path(), &["--target-std", "1e-4"]);
    let worst = design["parameters"]
        .as_array()
        .unwrap()
        .iter()
        .map(|p| p["relative_std"].as_f64().unwrap())
        .fold(0.0, f64::max);
    assert!(worst <= 1e-4 * (1.0 + 1e-9), "worst {worst}");
    assert!(
        design["record_s"].as_f64().unwrap() < 172.0,
        "{}",
        design["record_s"]
    );
    let refused = dir.path().join("refused");
    let r = crate::util::servoid(
        dir.path(),
        &[
            "design",
            dir.path().join("out").to_str().unwrap(),
            "--out",
            refused.to_str().unwrap(),
            "--target-std",
            "1e-6",
        ],
    );
    assert_eq!(r.code, 1, "{}", r.stderr);
    assert!(
        r.stderr.contains("--run-s")
            && r.stderr
                .contains("the peak command (--command-mm, [design] command_m)"),
        "{}",
        r.stderr
    );
    assert!(!refused.exists(), "nothing written");
    let results = dir.path().join("out");
    for (flag, value) in [("--stroke-mm", "0"), ("--band-hz", "30,0.5")] {
        let r = crate::util::servoid(
            dir.path(),
            &[
                "design",
                results.to_str().unwrap(),
                "--out",
                refused.to_str().unwrap(),
                flag,
                value,
            ],
        );
        assert_eq!(r.code, 2, "{flag} {value}: {}", r.stderr);
        assert!(r.stderr.contains(flag), "{flag}: {}", r.stderr);
        assert!(!refused.exists(), "nothing written");
    }
}

/// The gain at `f_hz` of a run's own fit, n0 / (s^2 + d1 s + d0).
fn fitted_gain(run: &serde_json::Value, f_hz: f64) -> f64 {
    let p: Vec<f64> = run["fit"]["params"]
        .as_array()
        .unwrap()
        .iter()
        .map(|v| v.as_f64().unwrap())
        .collect();
    let w = 2.0 * std::f64::consts::PI * f_hz;
    p[0] / ((p[2] - w * w).powi(2) + (p[1] * w).powi(2)).sqrt()
}

/// A night whose rig rubs (the periodic small campaign with 20 N of seal
/// friction, whose empty lines hold far more than the noise): `servoid
/// design` adds for each such run the run that plays its command at half
/// the amplitude (role fit) and says what each answer would mean; both
/// manifests have it. On the linear rig it adds none. Played on the
/// rubbing rig (check.toml with the friction added), the half run's gain
/// at the band's lowest line is lower than the full run's, as the answer
/// says friction makes it.
#[test]
fn a_night_that_distorts_gets_the_run_at_half_the_amplitude() {
    let friction = "[rig.unmodelled]\npiston_mass_kg = 2.0\nactuator_friction = { coulomb_force_n = 20.0, smoothing_velocity_m_per_s = 0.002 }\n\n";
    let design = |dir: &std::path::Path, unmodelled: &str| -> serde_json::Value {
        let manifest = write(dir, "sim.toml", &periodic_campaign(1, unmodelled));
        stated(dir, &manifest);
        designed(dir, &dir.join("out"), &dir.join("design"), &[])
    };
    let linear = scratch();
    let d = design(linear.path(), "");
    assert_eq!(
        d["questions"].as_array().unwrap().len(),
        0,
        "{}",
        d["questions"]
    );
    let rubbing = scratch();
    let dir = rubbing.path();
    let d = design(dir, friction);
    let q = d["questions"]
        .as_array()
        .unwrap()
        .iter()
        .find(|q| q["run"] == "bare-half")
        .unwrap_or_else(|| panic!("{}", d["questions"]));
    assert!(q["answers"].as_str().unwrap().contains("friction"), "{q}");
    let folder = dir.join("design");
    let (_, full) = written_command(&folder.join("commands/bare.csv"));
    let (_, half) = written_command(&folder.join("commands/bare-half.csv"));
    assert_eq!(full.len(), half.len());
    assert!(full.iter().zip(&half).all(|(f, h)| *h == 0.5 * f));
    for manifest in ["campaign.toml", "check.toml"] {
        let text = std::fs::read_to_string(folder.join(manifest)).unwrap();
        assert!(text.contains("id = \"bare-half\""), "{manifest}");
    }
    let check = std::fs::read_to_string(folder.join("check.toml")).unwrap();
    let manifest = write(&folder, "rubbing.toml", &format!("{check}\n{friction}"));
    let out = folder.join("rubbing");
    let r = servoid_into(&folder, "simulate", &manifest, &out, &["--run", "--quiet"]);
    assert!(r.code == 0 || r.code == 1, "{}", r.stderr);
    let results: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("results.json")).unwrap()).unwrap();
    let run = |id: &str| crate::util::run_by_id(&results, id).clone();
    for id in ["bare", "bare-half"] {
        assert_eq!(run(id)["status"], "ok", "{id}: {}", run(id)["error"]);
    }
    let (g_full, g_half) = (
        fitted_gain(&run("bare"), 0.5),
        fitted_gain(&run("bare-half"), 0.5),
    );
    eprintln!("gain at 0.5 Hz: full {g_full}, half {g_half}");
    assert!(g_half < g_full, "full {g_full}, half {g_half}");
}

/// A campaign's `[design]` section sets the limits `servoid design` keeps
/// to (here a 1 mm stroke, which then bounds a run), a flag overrides
/// it (0.8 mm), and `servoid check` names a limit given wrongly by its
/// key.
#[test]
fn a_campaigns_design_section_sets_the_limits_and_a_flag_overrides_it() {
    let dir = scratch();
    let dir = dir.path();
    stated(dir, &write(dir, "sim.toml", &periodic_campaign(1, "")));
    let manifest = dir.join("out/campaign.toml");
    let text = std::fs::read_to_string(&manifest).unwrap();
    let with = write(
        &dir.join("out"),
        "night.toml",
        &format!("{text}\n[design]\nstroke_m = 0.001\n"),
    );
    let r = servoid_into(dir, "run", &with, &dir.join("night"), &["--quiet"]);
    assert_eq!(r.code, 0, "{}", r.stderr);
    let design = |out: &str, extra: &[&str]| -> serde_json::Value {
        let mut args = vec![
            "design".to_string(),
            dir.join("night").to_str().unwrap().to_string(),
            "--out".into(),
            dir.join(out).to_str().unwrap().to_string(),
        ];
        args.extend(extra.iter().map(|s| s.to_string()));
        let args: Vec<&str> = args.iter().map(String::as_str).collect();
        let r = crate::util::servoid(dir, &args);
        assert_eq!(r.code, 0, "{}", r.stderr);
        serde_json::from_str(&std::fs::read_to_string(dir.join(out).join("design.json")).unwrap())
            .unwrap()
    };
    for (out, extra, stroke) in [
        ("from-section", &[][..], 0.001),
        ("from-flag", &["--stroke-mm", "0.8"][..], 0.0008),
    ] {
        let d = design(out, extra);
        assert_eq!(d["limits"]["stroke_m"].as_f64(), Some(stroke), "{out}");
        let runs = d["runs"].as_array().unwrap();
        for run in runs {
            let x = run["peaks"]["displacement_m"].as_f64().unwrap();
            assert!(x <= stroke, "{out}: {run}");
        }
        assert!(
            runs.iter().any(|r| r["bound_by"] == "stroke"),
            "{out}: a run meets the stroke"
        );
    }
    let wrong = write(
        &dir.join("out"),
        "wrong.toml",
        &format!("{text}\n[design]\nstroke_m = -1.0\n"),
    );
    let r = crate::util::servoid(dir, &["check", wrong.to_str().unwrap()]);
    assert_eq!(r.code, 2, "{}", r.stderr);
    assert!(
        format!("{}{}", r.stdout, r.stderr).contains("design.stroke_m"),
        "{}{}",
        r.stdout,
        r.stderr
    );
}

/// A new rig's first night, planned from a campaign manifest's nominal
/// `[rig.parameters]` (the paper's Table 3 rig) before any log exists.
/// Without the DAQ's rate and the displacement's noise the design names
/// both, by flag and key, and writes nothing; given them, it plans at the
/// nominal rig with white noise of the level given (2 s^2 / fs of
/// density), the next night's manifest checks, and its check.toml played
/// over 3 seeds states the predicted stds within 20 % with the rig within
/// 4 of them.
#[test]
fn a_manifests_nominal_rig_gives_a_night_and_names_what_it_lacks() {
    let dir = scratch();
    let manifest = write(
        dir.path(),
        "nominal.toml",
        &std::fs::read_to_string(crate::util::root().join("tests/fixtures/nominal-campaign.toml"))
            .unwrap(),
    );
    let out = dir.path().join("design");
    let (m, o) = (manifest.to_str().unwrap(), out.to_str().unwrap());
    let r = crate::util::servoid(dir.path(), &["design", m, "--out", o]);
    assert_eq!(r.code, 1, "{}", r.stderr);
    for named in [
        "--rate-hz",
        "[design] sample_rate_hz",
        "--noise-mm",
        "[design] displacement_noise_m",
    ] {
        assert!(r.stderr.contains(named), "{named}: {}", r.stderr);
    }
    assert!(!r.stderr.contains("--command-mm"), "{}", r.stderr);
    assert!(!out.exists());

    let design = designed(
        dir.path(),
        &manifest,
        &out,
        &["--rate-hz", "1000", "--noise-mm", "0.002"],
    );
    assert!(design["rig_from"].as_str().unwrap().contains("nominal"));
    for (key, v) in [
        ("beta1_per_s", 267.0),
        ("a1b0_n_per_m_s2", 2.412e9),
        ("a2_n_per_m", 7.881e5),
        ("a3_per_s", 16.118),
    ] {
        assert_eq!(design["rig"][key].as_f64().unwrap(), v, "{key}");
    }
    let psd = design["noise"]["psd_m2_per_hz"][0].as_f64().unwrap();
    assert!(
        (psd / (2.0 * 2e-6 * 2e-6 / 1000.0) - 1.0).abs() < 1e-12,
        "{psd}"
    );
    assert!(design["parameters"][0]["last_std"].is_null());
    let next = out.join("campaign.toml");
    let r = crate::util::servoid(dir.path(), &["check", next.to_str().unwrap()]);
    assert_eq!(r.code, 0, "{}", r.stderr);

    let predicted: Vec<f64> = (0..4)
        .map(|j| design["parameters"][j]["std"].as_f64().unwrap())
        .collect();
    let truth_key = ["beta1_per_s", "a1b0_n_per_m_s2", "a2_n_per_m", "a3_per_s"];
    for seed in 1..=3 {
        let (results, truth) = checked(&out, seed);
        for (j, name) in NAMES.iter().enumerate() {
            let e = &results["rig"][*name];
            let (value, std) = (e["value"].as_f64().unwrap(), e["std"].as_f64().unwrap());
            let z = (value - truth["rig"][truth_key[j]].as_f64().unwrap()) / std;
            assert!(
                (0.8..1.2).contains(&(std / predicted[j])),
                "seed {seed}, {name}: stated {std}, predicted {}",
                predicted[j]
            );
            assert!(z.abs() < 4.0, "seed {seed}, {name}: z {z}");
        }
    }
}

/// `text` (a TOML file as the serialiser writes it, a blank line after
/// each table) with table `header`'s keys replaced by `body`.
fn with_table(text: &str, header: &str, body: &str) -> String {
    let start = text.find(&format!("\n{header}\n")).expect(header) + header.len() + 2;
    let end = start + text[start..].find("\n\n").unwrap_or(text.len() - start);
    format!("{}{body}{}", &text[..start], &text[end..])
}

/// A thin campaign (the no-specimen run and one spring, 10 s chirps, 30 um
/// of LVDT noise) on a rig with a mode at 250 Hz in its loop, and a
/// validation run (an SDOF specimen at P = 2): last night's joint fit
/// cannot tell the structures apart (tests/joint.rs,
/// `a_run_at_another_p_gain_settles_the_place`). `servoid design` adds
/// that validation run to the night in the joint fit (campaign.toml and
/// check.toml set `include_validation`), with what each answer would mean.
/// The designed night played on the true rig (check.toml with the mode, the
/// delay and the force's noise), read with the defaults (the periodic
/// read: each FRF at its excited lines, the validation run's two among
/// them), settles it: over 4 seeds the loop's mode ("delay_valve") takes
/// the Schwarz weight, no ambiguity is left and the rig is within 1 % and 4
/// stds; the same night without the added run leaves an ambiguity or a
/// wrong structure on each seed (docs/accuracy.md, "The run that settles a
/// structure").
#[test]
fn a_structure_last_night_could_not_tell_gets_the_run_that_settles_it() {
    let dir = scratch();
    let dir = dir.path();
    let truth = [
        ("beta1_per_s", 180.0),
        ("a1b0_n_per_m_s2", 3.1e9),
        ("a2_n_per_m", 9.5e5),
        ("a3_per_s", 22.0),
    ];
    let parameters: String = truth
        .iter()
        .map(|(k, v)| format!("{k} = {v:e}\n"))
        .collect();
    let last = format!(
        r#"schema_version = 1

[simulation]
name = "thin"
sample_rate_hz = 1000.0
seed = 77
log_format = "parquet"

[rig]
name = "a simulated rig"

[rig.parameters]
{parameters}
[rig.unmodelled]
valve_mode = {{ natural_frequency_hz = 250.0, damping_ratio = 0.5 }}

[excitation]
kind = "chirp"
law = "quadratic"
f0_hz = 0.1
f1_hz = 35.0
duration_s = 10.0
amplitude_m = 0.004
lead_in_s = 1.0
lead_out_s = 1.0

[instrument.command]
unit = "mm"
quantization = {{ bits = 18, full_scale = 50.0 }}

[instrument.displacement]
unit = "mm"
noise_rms = 0.03
delay_s = 0.001
quantization = {{ bits = 18, full_scale = 50.0 }}

[instrument.force]
unit = "N"
noise_rms = 2.0
quantization = {{ bits = 18, full_scale = 5000.0 }}

[identification]
band_hz = [0.5, 30.0]

[[runs]]
id = "bare"
role = "no_specimen"
p_gain = 1.0

[[runs]]
id = "k1"
role = "spring"
p_gain = 1.0
specimen = {{ stiffness_n_per_m = 150000.0 }}

[[runs]]
id = "sdof"
role = "validation"
p_gain = 2.0
specimen = {{ mass_kg = 3.8, damping_ns_per_m = 5.0, stiffness_n_per_m = 129400.0 }}
"#
    );
    let results = stated(dir, &write(dir, "last.toml", &last));
    let joint = &results["rig"]["joint"];
    assert!(joint["ambiguity"].is_string(), "{joint}");
    let folder = dir.join("design");
    let design = designed(dir, &dir.join("out"), &folder, &["--run-s", "40"]);
    let q = &design["questions"][0];
    assert_eq!(q["run"], "sdof", "{}", design["questions"]);
    assert!(q["answers"].as_str().unwrap().contains("joint fit"), "{q}");
    let added = crate::util::run_by_id(&design, "sdof");
    assert_eq!(
        (added["role"].as_str(), added["p_gain"].as_f64()),
        (Some("validation"), Some(2.0))
    );
    for manifest in ["campaign.toml", "check.toml"] {
        let text = std::fs::read_to_string(folder.join(manifest)).unwrap();
        assert!(text.contains("include_validation = true"), "{manifest}");
        assert!(text.contains("id = \"sdof\""), "{manifest}");
    }

    // Last night's logs were Parquet: each command is written so too, and
    // plays as its CSV does (the same results, to the bit).
    let check = std::fs::read_to_string(folder.join("check.toml")).unwrap();
    for run in design["runs"].as_array().unwrap() {
        assert_eq!(
            run["command_log"].as_str(),
            Some(format!("commands/{}.parquet", run["id"].as_str().unwrap()).as_str())
        );
    }
    let as_parquet = write(
        &folder,
        "check-parquet.toml",
        &check.replace(".csv\"\nkind = \"file\"", ".parquet\"\nkind = \"file\""),
    );
    assert!(
        std::fs::read_to_string(&as_parquet)
            .unwrap()
            .contains("bare.parquet")
    );
    let played: Vec<serde_json::Value> =
        [("csv", folder.join("check.toml")), ("parquet", as_parquet)]
            .iter()
            .map(|(name, manifest)| {
                let out = folder.join(format!("played-{name}"));
                let r = servoid_into(&folder, "simulate", manifest, &out, &["--run", "--quiet"]);
                assert_eq!(r.code, 0, "{}", r.stderr);
                serde_json::from_str(&std::fs::read_to_string(out.join("results.json")).unwrap())
                    .unwrap()
            })
            .collect();
    for name in NAMES {
        assert_eq!(
            played[0]["rig"][name]["value"], played[1]["rig"][name]["value"],
            "{name}"
        );
    }
    let mut on_truth = with_table(&check, "[rig.parameters]", &(parameters + "p_gain = 1.0"));
    on_truth = with_table(
        &on_truth,
        "[instrument.displacement]",
        "noise_rms = 0.03\nunit = \"mm\"\ndelay_s = 0.001",
    );
    on_truth = with_table(
        &on_truth,
        "[instrument.force]",
        "noise_rms = 2.0\nunit = \"N\"",
    );
    on_truth.push_str(
        "\n[rig.unmodelled]\nvalve_mode = { natural_frequency_hz = 250.0, damping_ratio = 0.5 }\n",
    );
    let cut = on_truth.find("[[runs]]\nid = \"sdof\"").unwrap();
    let end = cut + on_truth[cut..].find("[simulation]").unwrap();
    let without = format!("{}{}", &on_truth[..cut], &on_truth[end..])
        .replace("include_validation = true\n", "");
    for seed in 1..=4u64 {
        for (name, text) in [("with", &on_truth), ("without", &without)] {
            let manifest = write(
                &folder,
                &format!("{name}-{seed}.toml"),
                &text.replace("\nseed = 1\n", &format!("\nseed = {seed}\n")),
            );
            let out = folder.join(format!("{name}-{seed}"));
            let r = servoid_into(&folder, "simulate", &manifest, &out, &["--run", "--quiet"]);
            assert_eq!(r.code, 0, "{}", r.stderr);
            let results: serde_json::Value =
                serde_json::from_str(&std::fs::read_to_string(out.join("results.json")).unwrap())
                    .unwrap();
            let (rig, joint) = (&results["rig"], &results["rig"]["joint"]);
            let errors: Vec<(f64, f64)> = NAMES
                .iter()
                .zip(&truth)
                .map(|(name, (_, t))| {
                    let (v, s) = (
                        rig[name]["value"].as_f64().unwrap(),
                        rig[name]["std"].as_f64().unwrap(),
                    );
                    (v / t - 1.0, (v - t) / s)
                })
                .collect();
            eprintln!(
                "{name} the added run, seed {seed}: {} ({}), errors and z {errors:?}",
                joint["structure"], joint["ambiguity"]
            );
            if name == "with" {
                assert_eq!(joint["structure"], "delay_valve", "seed {seed}");
                assert!(
                    joint["ambiguity"].is_null(),
                    "seed {seed}: {}",
                    joint["ambiguity"]
                );
                for (e, z) in errors {
                    assert!(e.abs() < 0.01 && z.abs() < 4.0, "seed {seed}: {e}, {z}");
                }
                // The validation run's FRFs weigh what their noise gives:
                // each one's weighted cost within 3 of its chi-square
                // spread about its dof.
                for fitted in ["sdof x1/u", "sdof f/u"] {
                    let z =
                        joint["per_run"]
                            .as_array()
                            .unwrap()
                            .iter()
                            .find(|r| r["run"] == fitted)
                            .unwrap_or_else(|| panic!("{fitted}: {}", joint["per_run"]))["adequacy"]
                            ["cost_z"]
                            .as_f64()
                            .unwrap();
                    assert!(z.abs() < 3.0, "seed {seed}, {fitted}: cost z {z}");
                }
            } else {
                assert!(
                    joint["ambiguity"].is_string() || joint["structure"] != "delay_valve",
                    "seed {seed}: {joint}"
                );
            }
        }
    }
    // A night with no validation run to add (last night's without its
    // validation run, which was not in its joint fit: the same
    // ambiguity): each experiment the ambiguity names gets its run
    // (another P gain: the no-specimen run at half of it; a wider band:
    // the no-specimen run over 0.5-120 Hz, four times the band's top;
    // another specimen: a spring as stiff as the oil column, a2 to two
    // digits).
    let bare_night = &last[..last.find("[[runs]]\nid = \"sdof\"").unwrap()];
    let night = dir.join("bare-night");
    let manifest = write(dir, "bare-night.toml", bare_night);
    let r = servoid_into(dir, "simulate", &manifest, &night, &["--run", "--quiet"]);
    assert_eq!(r.code, 0, "{}", r.stderr);
    let results: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(night.join("results.json")).unwrap())
            .unwrap();
    let settle: Vec<&str> = results["rig"]["joint"]["settle"]
        .as_array()
        .map_or(Vec::new(), |s| {
            s.iter().map(|s| s.as_str().unwrap()).collect()
        });
    assert!(!settle.is_empty(), "{}", results["rig"]["joint"]);
    let design = designed(dir, &night, &dir.join("design-2"), &["--run-s", "40"]);
    let a2 = results["rig"]["a2"]["value"].as_f64().unwrap();
    for s in settle {
        let run = match s {
            "p_gain" => crate::util::run_by_id(&design, "bare-p0.5"),
            "wider_band" => crate::util::run_by_id(&design, "bare-wide"),
            "specimen" => design["runs"]
                .as_array()
                .unwrap()
                .iter()
                .find(|r| r["role"] == "spring" && r["id"] != "k1")
                .unwrap_or_else(|| panic!("no spring added: {}", design["runs"])),
            other => panic!("{other}"),
        };
        match s {
            "p_gain" => assert_eq!(
                (run["role"].as_str(), run["p_gain"].as_f64()),
                (Some("validation"), Some(0.5))
            ),
            "wider_band" => assert_eq!(run["band_hz"], serde_json::json!([0.5, 120.0])),
            _ => {
                let k = run["specimen"]["stiffness_n_per_m"].as_f64().unwrap();
                assert!((k / a2 - 1.0).abs() < 0.05, "{k} against a2 {a2}");
            }
        }
        assert!(
            design["questions"]
                .as_array()
                .unwrap()
                .iter()
                .any(|q| q["run"] == run["id"]),
            "{s}"
        );
    }
}

/// simulation-rich.toml's rig has a delay and a valve mode at 150 Hz,
/// which its joint fit estimates beside the rig's four (structure
/// "delay_valve"). The design's prediction extends to them (the joint
/// fit's model, identify::joint, differentiated in all seven): its
/// prediction of last night's own chirps, an independent check, is each
/// of the seven stds last night stated, within 15 %; the design states
/// what it predicts for the delay and the mode, and shapes its spectrum
/// for the rig's four with the seven estimated.
#[test]
fn a_rig_with_a_delay_and_a_mode_is_predicted_with_them() {
    let dir = scratch();
    let dir = dir.path();
    let text = std::fs::read_to_string(
        crate::util::root().join("experiments/maghareh2018/simulation-rich.toml"),
    )
    .unwrap();
    stated(dir, &write(dir, "rich.toml", &text));
    let design = designed(dir, &dir.join("out"), &dir.join("design"), &[]);
    let names: Vec<&str> = design["parameters"]
        .as_array()
        .unwrap()
        .iter()
        .map(|p| p["name"].as_str().unwrap())
        .collect();
    assert_eq!(
        names,
        [
            "beta1",
            "a1b0",
            "a2",
            "a3",
            "delay_s",
            "valve_hz",
            "valve_damping"
        ]
    );
    for p in design["parameters"].as_array().unwrap() {
        let (last, chirp) = (
            p["last_std"].as_f64().unwrap(),
            p["chirp_std"].as_f64().unwrap(),
        );
        eprintln!(
            "{}: last night stated {last:.4e}, its chirps predicted {chirp:.4e}, the design {:.4e}",
            p["name"],
            p["std"].as_f64().unwrap()
        );
        assert!((chirp / last - 1.0).abs() < 0.15, "{p}");
    }
    eprintln!("against the chirps: {}", design["baseline"]);
}
