//! Identification accuracy against known truth: campaigns simulated
//! with known rig parameters, identified by the library's own pipeline
//! (ingest, FRF, fit, Eqs. 18-20), compared with the parameters they were
//! simulated from.
//!
//! - a clean campaign (the paper's model exactly; 1 kHz; sample-and-hold on
//!   the command; LVDT and load-cell noise and 16-bit quantisation) gives
//!   the four rig parameters within 0.5 %;
//! - the bundled rich campaign (a 150 Hz servo-valve mode, sensor delays,
//!   offsets and drift) within 3 %;
//! - the paper's rig logged at 200 Hz, where the hold's aliases matter,
//!   within 3 of its stated stds;
//! - the standard deviations are honest: over many seeds the truth lies
//!   within two standard deviations about 95 % of the time, and the noise
//!   variance the fit weights by matches the scatter of the FRF over seeds.
//!
//! The truth is the simulation manifest's parameters: the simulator and the
//! identification share only the model's equations (docs/model.md), whose
//! transfer functions are checked against hand-derived ones in
//! tests/simulate.rs and the unit tests.

use std::path::Path;

use servoid::manifest::load;
use servoid::manifest::simulation::{SimulationPlan, load_simulation, load_simulation_str};
use servoid::results::{Results, RigSource};
use servoid::run::analyse;
use servoid::run::simulate::simulate_campaign;

use crate::util::{PAPER_TRUTH, PaperSweep, root, run_by_id, scratch};

/// A campaign on a rig that is not the paper's: a no-specimen run and two
/// springs at about 0.16 and 0.11 a2 (the paper's ratios), at 1 kHz.
fn campaign(seed: u64, duration_s: f64, f0_hz: f64, noise_mm: f64) -> String {
    format!(
        r#"
schema_version = 1

[simulation]
name = "accuracy"
sample_rate_hz = 1000.0
seed = {seed}
log_format = "parquet"

[rig]
name = "a rig unlike the paper's"

[rig.parameters]
beta1_per_s = 180.0
a1b0_n_per_m_s2 = 3.1e9
a2_n_per_m = 9.5e5
a3_per_s = 22.0

[excitation]
kind = "chirp"
law = "quadratic"
f0_hz = {f0_hz}
f1_hz = 35.0
duration_s = {duration_s}
amplitude_m = 0.004
lead_in_s = 1.0
lead_out_s = 1.0

# 16-bit converters over +/- 50 mm and +/- 5 kN; LVDT and load-cell noise.
[instrument.command]
unit = "mm"
quantization = {{ bits = 16, full_scale = 50.0 }}

[instrument.displacement]
unit = "mm"
noise_rms = {noise_mm}
quantization = {{ bits = 16, full_scale = 50.0 }}

[instrument.force]
unit = "N"
noise_rms = 2.0
quantization = {{ bits = 16, full_scale = 5000.0 }}

[identification]
band_hz = [0.5, 30.0]
coherence_min = 0.8
command_intersample = "sample_and_hold"
frf = {{ estimator = "etfe", segment_length = 4096, overlap = 0.5, window = "rectangular", detrend = "mean" }}

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
id = "k2"
role = "spring"
p_gain = 1.0
specimen = {{ stiffness_n_per_m = 105000.0 }}
"#
    )
}

const TRUTH: [(&str, f64); 4] = [
    ("beta1", 180.0),
    ("a1b0", 3.1e9),
    ("a2", 9.5e5),
    ("a3", 22.0),
];

/// Simulate `text` into `dir` and identify it; the results and the truth.
fn simulate_and_identify(text: &str, dir: &Path) -> (Results, serde_json::Value) {
    let plan = load_simulation_str(text, &dir.join("sim.toml")).expect("a valid simulation");
    identify(&plan, dir)
}

fn identify(plan: &SimulationPlan, dir: &Path) -> (Results, serde_json::Value) {
    let sim = simulate_campaign(plan, dir).expect("simulates");
    let campaign = load(&sim.manifest).expect("the generated manifest loads");
    let results = analyse(&campaign);
    let truth: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&sim.truth).unwrap()).unwrap();
    for r in &results.runs {
        assert!(r.error.is_none(), "run {} failed: {:?}", r.id, r.error);
    }
    (results, truth)
}

/// (name, value, std) of the identified rig.
fn rig(results: &Results) -> Vec<(&'static str, f64, f64)> {
    let r = results.rig.as_ref().expect("the rig is identified");
    [
        ("beta1", &r.beta1),
        ("a1b0", &r.a1b0),
        ("a2", &r.a2),
        ("a3", &r.a3),
    ]
    .into_iter()
    .map(|(n, e)| (n, e.value, e.std.expect("a fitted rig has a std")))
    .collect()
}

/// The paper's program at 1 kHz (quadratic chirp 0.1-35 Hz over 170 s):
/// every parameter within 0.5 % of the truth, and within 4 of its own
/// standard deviations (the error is noise, not bias).
#[test]
fn a_clean_campaign_gives_the_rig_within_half_a_percent() {
    let dir = scratch();
    let (results, _) = simulate_and_identify(&campaign(11, 170.0, 0.1, 0.002), dir.path());
    for ((name, value, std), (_, truth)) in rig(&results).into_iter().zip(TRUTH) {
        let err = (value - truth) / truth;
        eprintln!(
            "clean: {name} = {value:.6e} (truth {truth:.6e}): {:+.4} %, std {:.4} %",
            100.0 * err,
            100.0 * std / truth
        );
        assert!(err.abs() < 0.005, "{name}: {:.3} % off", 100.0 * err);
        assert!(
            (value - truth).abs() < 4.0 * std,
            "{name}: error {:.3e} is more than 4 std ({std:.3e})",
            value - truth
        );
    }
}

/// The paper's rig logged at 200 Hz (60 s sweeps, the defaults): the
/// hold's aliases are 0.6 % of the no-specimen response at 30 Hz, and a fit
/// that modelled the hold by its continuous factor alone put beta1 0.2 %
/// (15 stds) and a1b0 0.16-0.21 % (5-6 stds) high on these seeds, and for
/// one of them failed the joint fit's adequacy tests and blamed friction or
/// a nonlinear specimen. With the exact sampled response every rig
/// parameter is within 3 of its stated stds, and no warning names a cause
/// the rig does not have.
#[test]
fn a_campaign_sampled_at_200_hz_gives_the_rig_within_its_stds() {
    for seed in [2026, 2027] {
        let dir = scratch();
        let sim = PaperSweep {
            sample_rate_hz: 200.0,
            seed,
            ..PaperSweep::default()
        };
        let (results, _) = simulate_and_identify(&sim.text(), dir.path());
        let source = &results.rig.as_ref().expect("a rig").source;
        assert_eq!(*source, RigSource::Joint, "seed {seed}");
        for ((name, value, std), (_, truth)) in rig(&results).into_iter().zip(PAPER_TRUTH) {
            let z = (value - truth) / std;
            eprintln!(
                "200 Hz, seed {seed}: {name} {:+.4} % ({z:+.2} stds)",
                100.0 * (value / truth - 1.0)
            );
            assert!(z.abs() < 3.0, "seed {seed}: {name} {z:.2} stds off");
        }
        for w in &results.warnings {
            assert!(
                !(w.contains("friction") || w.contains("nonlinear")),
                "seed {seed}: {w}"
            );
        }
    }
}

/// The bundled rich campaign: the paper's parameters on a rig with a 150 Hz
/// spool mode the model lacks, sensor delays, offsets and drift. The model
/// error is systematic, so only the 3 % bound is asserted.
#[test]
fn the_rich_campaign_gives_the_rig_within_three_percent() {
    let dir = scratch();
    let plan = load_simulation(&root().join("experiments/maghareh2018/simulation-rich.toml"))
        .expect("the bundled rich manifest loads");
    let (results, truth) = identify(&plan, dir.path());
    assert_eq!(truth["clean"], false);
    let t = &truth["rig"];
    for (name, value, _) in rig(&results) {
        let key = match name {
            "beta1" => "beta1_per_s",
            "a1b0" => "a1b0_n_per_m_s2",
            "a2" => "a2_n_per_m",
            _ => "a3_per_s",
        };
        let truth = t[key].as_f64().unwrap();
        let err = (value - truth) / truth;
        eprintln!(
            "rich: {name} = {value:.6e} (truth {truth:.6e}): {:+.3} %",
            100.0 * err
        );
        assert!(err.abs() < 0.03, "{name}: {:.2} % off", 100.0 * err);
    }
    // The fitted delay absorbs the LVDT's 0.6 ms and the spool mode's lag
    // (2 zeta / omega_n = 1.5 ms at low frequency): between the two and
    // their sum plus the hold's half sample.
    let delay = results.runs[0].tf.as_ref().unwrap().delay_s;
    assert!((0.0006..0.0026).contains(&delay), "fitted delay {delay} s");
}

/// Coverage: 2,000 seeds of a short campaign
/// (30 s sweeps, 10 um LVDT noise, so that noise dominates every other
/// error). For each seed, each run's three fitted coefficients against the
/// run's true transfer function (truth.json) and the four rig parameters
/// against the truth: the fraction within two standard deviations must be
/// 95 +- 1 % (a Gaussian's 95.4 %), and within one near 68 %. Too low means
/// the stds are optimistic, too high that they are padded.
///
/// Why so many seeds: a campaign's checks are correlated (a run's three
/// coefficients share its noise, the rig shares every run's), so a few
/// hundred seeds leave the fraction a percent or more from its expectation.
/// With the ETFE's former noise estimate (its average over the windows
/// that hold the bin's own noise) the first 300 seeds alone gave 93.1 %
/// (coefficients) and 93.8 % (rig), the first 200 93.3 %, and over 2,000
/// seeds the stds of the signed errors (estimate - truth) / std were
/// 1.01-1.04 per coefficient, their means within 0.06 of 0: 95.1 % within
/// 2 std and 67.5 % within 1; rig 94.8 % and 67.5 %. With those windows
/// left out and the average widened (`frf::etfe_variance`), measured
/// (2,000 seeds from 1000): coefficients 95.5 %
/// within 2 std and 68.4 % within 1; rig 95.5 % and 68.1 % (a Gaussian's
/// 95.4 % and 68.3 %); the scaled errors' RMS 0.997 (coefficients) and
/// 1.003 (rig).
#[test]
#[ignore = "statistical, 2,000 campaigns: .ci/run runs it by name (docs/developers.md)"]
fn the_standard_deviations_are_honest_across_seeds() {
    use rayon::prelude::*;
    let seeds: u64 = 2000;
    let checks: Vec<(Vec<f64>, Vec<f64>)> = (0..seeds)
        .into_par_iter()
        .map(|seed| {
            let (mut coef, mut rig_checks) = (Vec::new(), Vec::new());
            let dir = scratch();
            let (results, truth) =
                simulate_and_identify(&campaign(1000 + seed, 30.0, 0.5, 0.01), dir.path());
            for run in &results.runs {
                let tf = run.tf.as_ref().expect("a fitted model");
                let std = tf.std.as_ref().expect("fitted coefficients have stds");
                let t = run_by_id(&truth, &run.id);
                let num: Vec<f64> = t["plant_tf_x1_u"]["num"]
                    .as_array()
                    .unwrap()
                    .iter()
                    .map(|v| v.as_f64().unwrap())
                    .collect();
                let den: Vec<f64> = t["plant_tf_x1_u"]["den"]
                    .as_array()
                    .unwrap()
                    .iter()
                    .map(|v| v.as_f64().unwrap())
                    .collect();
                // num then den after the leading 1: n0, d1, d0.
                let fitted = [tf.num[0], tf.den[1], tf.den[2]];
                let true_ = [
                    num[num.len() - 1] / den[0],
                    den[1] / den[0],
                    den[2] / den[0],
                ];
                for k in 0..3 {
                    coef.push((fitted[k] - true_[k]).abs() / std[k]);
                }
            }
            for ((_, value, std), (_, truth)) in rig(&results).into_iter().zip(TRUTH) {
                rig_checks.push((value - truth).abs() / std);
            }
            (coef, rig_checks)
        })
        .collect();
    let coef: Vec<f64> = checks.iter().flat_map(|c| c.0.iter().copied()).collect();
    let rig_checks: Vec<f64> = checks.iter().flat_map(|c| c.1.iter().copied()).collect();
    let within = |z: &[f64], k: f64| z.iter().filter(|v| **v <= k).count() as f64 / z.len() as f64;
    let (c1, c2) = (within(&coef, 1.0), within(&coef, 2.0));
    let (r1, r2) = (within(&rig_checks, 1.0), within(&rig_checks, 2.0));
    let rms = |z: &[f64]| (z.iter().map(|v| v * v).sum::<f64>() / z.len() as f64).sqrt();
    let (c_rms, r_rms) = (rms(&coef), rms(&rig_checks));
    eprintln!(
        "coverage over {seeds} seeds: coefficients {} checks, {:.1} % within 1 std, {:.1} % within 2, scaled errors' RMS {c_rms:.3}; rig {} checks, {:.1} % within 1, {:.1} % within 2, RMS {r_rms:.3}",
        coef.len(),
        100.0 * c1,
        100.0 * c2,
        rig_checks.len(),
        100.0 * r1,
        100.0 * r2
    );
    // The issue's band, 95 +- 1 % within 2 std; within 1 std a Gaussian's
    // 68.3 % within about the same relative margin. An std 6 % optimistic
    // gives 94 % within 2 (the band's edge), 10 % optimistic 92.4 %.
    assert!(
        (0.94..=0.96).contains(&c2),
        "coefficients within 2 std: {c2}"
    );
    assert!(
        (0.655..=0.71).contains(&c1),
        "coefficients within 1 std: {c1}"
    );
    assert!((0.94..=0.96).contains(&r2), "rig within 2 std: {r2}");
    assert!((0.655..=0.71).contains(&r1), "rig within 1 std: {r1}");
    // The scaled errors' RMS (over 2,000 seeds a campaign's shared noise
    // leaves it a sampling std of about 0.015).
    assert!((0.97..=1.03).contains(&c_rms), "coefficients' RMS {c_rms}");
    assert!((0.97..=1.03).contains(&r_rms), "rig's RMS {r_rms}");
}

/// The fit's weights on the campaign's own sweep: across 100 seeds of the
/// short campaign (the command is the same, only the noise changes), the
/// scatter of the ETFE's H at each band bin, E|H - mean H|^2, against the
/// local-polynomial estimate the fit weights by (`frf::h_variance_at`, the
/// mean over seeds of twice its per-component value). The Monte Carlo
/// scatter is the independent source. Bins are grouped into bands of at
/// least 48; a band's empirical variance then has a relative std of at most
/// 1 / sqrt(2 * 99 * 48) = 1.0 %, so 4 % is four of them. Also the errors of
/// neighbouring bins are uncorrelated, as the fit's covariance assumes (the
/// Monte Carlo's own floor is about 1 / sqrt(100 * 950) = 0.003).
///
/// Measured: ratios 0.989-1.006 in every band of the three runs,
/// correlations below 0.005. So the fit's inputs are not where the
/// coefficients' slightly short coverage (above) comes from.
#[test]
fn the_noise_variance_matches_the_scatter_of_h_over_seeds_on_a_sweep() {
    use nalgebra::Complex;
    use servoid::frf;
    use servoid::manifest::RunSource;

    let seeds = 100;
    let runs = ["bare", "k1", "k2"];
    // Per run: the band's bins, and per seed the estimate and variance there.
    let mut bins: Vec<Vec<usize>> = vec![Vec::new(); runs.len()];
    let mut freq: Vec<Vec<f64>> = vec![Vec::new(); runs.len()];
    let mut h: Vec<Vec<Vec<Complex<f64>>>> = vec![Vec::new(); runs.len()];
    let mut lpm: Vec<Vec<f64>> = vec![Vec::new(); runs.len()];
    for seed in 0..seeds {
        let dir = scratch();
        let plan = load_simulation_str(
            &campaign(1000 + seed, 30.0, 0.5, 0.01),
            &dir.path().join("sim.toml"),
        )
        .expect("a valid simulation");
        let sim = simulate_campaign(&plan, dir.path()).expect("simulates");
        let c = load(&sim.manifest).expect("the generated manifest loads");
        for (r, id) in runs.iter().enumerate() {
            let run = c.runs.iter().find(|run| run.id == *id).unwrap();
            let RunSource::Log(log_plan) = &run.source else {
                panic!("run {id} has a log")
            };
            let log = servoid::ingest::read_log(log_plan).expect("the log reads");
            let (u, y, fs) = (&log.command_m, &log.displacement_m, log.sample_rate_hz);
            let choice = c
                .identification
                .frf
                .resolve(u, y, fs, c.identification.band_hz)
                .expect("the campaign's FRF settings");
            assert!(!choice.chosen, "the campaign names the ETFE");
            let fr = frf::estimate_one(u, y, fs, &choice.plan).expect("an FRF");
            if seed == 0 {
                bins[r] = (0..fr.freq_hz.len())
                    .filter(|&k| (0.5..=30.0).contains(&fr.freq_hz[k]))
                    .collect();
                freq[r] = bins[r].iter().map(|&k| fr.freq_hz[k]).collect();
                lpm[r] = vec![0.0; bins[r].len()];
            }
            let v = frf::h_variance_at(&fr, &bins[r]);
            for (acc, v) in lpm[r].iter_mut().zip(&v) {
                *acc += 2.0 * v / seeds as f64;
            }
            h[r].push(bins[r].iter().map(|&k| fr.h[k]).collect());
        }
    }

    let n = seeds as f64;
    for (r, id) in runs.iter().enumerate() {
        let nb = bins[r].len();
        let mean: Vec<Complex<f64>> = (0..nb)
            .map(|i| h[r].iter().map(|hs| hs[i]).sum::<Complex<f64>>() / n)
            .collect();
        let scatter: Vec<f64> = (0..nb)
            .map(|i| {
                h[r].iter()
                    .map(|hs| (hs[i] - mean[i]).norm_sqr())
                    .sum::<f64>()
                    / (n - 1.0)
            })
            .collect();
        for band in [
            [0.5, 2.0],
            [2.0, 4.0],
            [4.0, 8.0],
            [8.0, 16.0],
            [16.0, 30.0],
        ] {
            let inside: Vec<usize> = (0..nb)
                .filter(|&i| freq[r][i] >= band[0] && freq[r][i] < band[1] + 1e-9)
                .collect();
            assert!(inside.len() >= 48, "{id} {band:?}: {} bins", inside.len());
            let empirical: f64 = inside.iter().map(|&i| scatter[i]).sum();
            let estimated: f64 = inside.iter().map(|&i| lpm[r][i]).sum();
            let ratio = empirical / estimated;
            eprintln!("{id} {band:?} Hz: scatter / LPM variance = {ratio:.4}");
            assert!(
                (ratio - 1.0).abs() < 0.04,
                "{id} {band:?} Hz: scatter / LPM variance = {ratio}"
            );
        }
        for lag in 1..=3 {
            let mut sum = Complex::new(0.0, 0.0);
            for i in 0..nb - lag {
                let cross: Complex<f64> = h[r]
                    .iter()
                    .map(|hs| (hs[i] - mean[i]) * (hs[i + lag] - mean[i + lag]).conj())
                    .sum::<Complex<f64>>()
                    / (n - 1.0);
                sum += cross / (scatter[i] * scatter[i + lag]).sqrt();
            }
            let rho = sum / (nb - lag) as f64;
            eprintln!("{id} lag {lag}: mean correlation {rho:.4}");
            assert!(rho.norm() < 0.02, "{id}: bins {lag} apart correlate: {rho}");
        }
    }
}
