//! One log of the bundled default, end to end through the identification:
//! 170 s at 2048 Hz (348,160 samples + 2 s of rest), the no-specimen run of
//! `experiments/maghareh2018/simulation.toml` (quadratic chirp 0.1-35 Hz,
//! 2 um LVDT noise, 18-bit I/O), written as Parquet by the simulator.
//!
//! - `log_stage/parquet`: what `servoid run` does per log: read and hash the
//!   file, convert to SI, the log checks, ETFE over the whole record with the
//!   Welch coherence, the local-polynomial noise variance, and the
//!   second-order fit with the hold modelled (throughput in file bytes/s);
//! - `frf_and_fit`: the same FRF and fit on signals already in memory
//!   (throughput in samples/s). Budget: under 20 ms. Measured on two cores
//!   (five runs): 13.6-16.2 ms, of which `frf_only` 8-10 ms,
//!   `variance_only` 0.7 ms and `fit_only` 2.6 ms. The three apart add up
//!   to less than together (most likely because each alone runs with its
//!   data in cache; not page faults, which were counted).
//!
//! - `auto`: what the default estimator costs on the same log beside the
//!   fit it replaces: its choice (`FrfRequest::resolve`), then the ETFE and
//!   `fit_run`'s two fits (the second on the noise level of what the first
//!   leaves), on the record as logged (at rest at both ends) and cut 1.5 s
//!   before its end (in motion: the transient fitted beside each model).
//!
//! - `campaign/*`: the rig from the bundled default's three identification
//!   runs (no specimen, k1, k2; no validation runs, no sensitivity), linear
//!   and with a 0.5 kg piston under 8 N of seal friction (tanh(v / 2 mm/s)),
//!   whose friction is then corrected by simulating the fitted rig at three
//!   widths (`analysis::friction`): what a campaign with friction pays for
//!   a friction whose std covers it (throughput in log samples/s).
//!   Measured on two cores (7 December 2026): linear 362 ms, with friction
//!   5.83 s, of which the correction 5.3 s (537 ms with it switched off).
//!
//! `cargo bench --bench identify`

use std::hint::black_box;

use criterion::{Criterion, Throughput, criterion_group, criterion_main};
use servoid::analysis::log_stage::log_stage;
use servoid::fit::fit;
use servoid::frf;
use servoid::frf::FrfRequest;
use servoid::identify::{FitData, fit_options, fit_run};
use servoid::ingest::LogFormat;
use servoid::manifest::simulation::load_simulation_str;
use servoid::manifest::{RunSource, load};
use servoid::run::simulate::simulate_campaign;

fn bench_identify(c: &mut Criterion) {
    let root = std::path::Path::new(env!("CARGO_MANIFEST_DIR"));
    let text = std::fs::read_to_string(root.join("experiments/maghareh2018/simulation.toml"))
        .expect("the bundled default")
        .replace("log_format = \"csv\"", "log_format = \"parquet\"");
    let dir = tempfile::tempdir().expect("a temporary folder");
    let plan = load_simulation_str(&text, &dir.path().join("simulation.toml")).unwrap();
    let sim = simulate_campaign(&plan, dir.path()).expect("simulates");
    let campaign = load(&sim.manifest).expect("the generated manifest loads");
    let run = campaign
        .runs
        .iter()
        .find(|r| r.id == "no-specimen")
        .expect("the no-specimen run");
    let RunSource::Log(log_plan) = &run.source else {
        panic!("a log run")
    };
    assert_eq!(log_plan.format, LogFormat::Parquet);
    let ident = &campaign.identification;
    let bytes = std::fs::metadata(&log_plan.path).unwrap().len();

    // Fail loudly rather than time a stage that does not work.
    let stage = log_stage(run, log_plan, ident).expect("the log stage runs");
    let fitted = stage.fit.as_ref().expect("a fit");
    assert!(fitted.converged && fitted.stable);
    let (u, y, fs) = (
        stage.log.command_m.clone(),
        stage.log.displacement_m.clone(),
        stage.log.sample_rate_hz,
    );

    let plan = &stage.choice.plan;
    let mut group = c.benchmark_group("identify_170s_2048hz");
    group.sample_size(20);
    group.throughput(Throughput::Bytes(bytes));
    group.bench_function("log_stage/parquet", |b| {
        b.iter(|| log_stage(black_box(run), black_box(log_plan), ident).unwrap())
    });

    // The FRF and the fit alone, as analysis/log_stage.rs calls them.
    group.throughput(Throughput::Elements(u.len() as u64));
    group.bench_function("frf_only", |b| {
        b.iter(|| frf::estimate_one(black_box(&u), black_box(&y), fs, plan).unwrap())
    });
    let h = frf::estimate_one(&u, &y, fs, plan).unwrap();
    let mask = frf::band_mask(&h, run.band_hz, ident.coherence_min);
    let bins: Vec<usize> = (0..h.freq_hz.len()).filter(|&i| mask[i]).collect();
    group.bench_function("variance_only", |b| {
        b.iter(|| frf::h_variance_at(black_box(&h), black_box(&bins)))
    });
    let opts = fit_options(ident, plan, fs);
    let data = FitData::of(&h, &mask, plan);
    group.bench_function(format!("fit_only/{}_bins", data.freq_hz.len()), |b| {
        b.iter(|| fit(black_box(&data.input()), &opts).unwrap())
    });
    group.bench_function("frf_and_fit", |b| {
        b.iter(|| {
            let h = frf::estimate_one(black_box(&u), black_box(&y), fs, plan).unwrap();
            let mask = frf::band_mask(&h, run.band_hz, ident.coherence_min);
            fit(&FitData::of(&h, &mask, plan).input(), &opts).unwrap()
        })
    });
    // The default estimator, on the record as logged and cut in motion.
    let auto = FrfRequest::default();
    let cut = u.len() - (1.5 * fs) as usize;
    for (name, u, y) in [
        ("auto/at_rest", &u[..], &y[..]),
        ("auto/in_motion", &u[..cut], &y[..cut]),
    ] {
        let choice = auto.resolve(u, y, fs, run.band_hz).unwrap();
        assert_eq!(choice.ends.at_rest(), name.ends_with("at_rest"));
        group.throughput(Throughput::Elements(u.len() as u64));
        group.bench_function(name, |b| {
            b.iter(|| {
                let choice = auto
                    .resolve(black_box(u), black_box(y), fs, run.band_hz)
                    .unwrap();
                let mut h = frf::estimate_one(u, y, fs, &choice.plan).unwrap();
                let mask = frf::band_mask(&h, run.band_hz, ident.coherence_min);
                fit_run(&mut h, &mask, run.band_hz, ident, &choice.plan, fs, None).unwrap()
            })
        });
    }
    group.finish();
}

/// The bundled default's three identification runs as a campaign, with
/// `unmodelled` in `[rig.unmodelled]`, simulated into `dir`: the campaign
/// and its logs' samples.
fn identification_campaign(
    root: &std::path::Path,
    dir: &std::path::Path,
    unmodelled: &str,
) -> (servoid::manifest::Campaign, u64) {
    let text = std::fs::read_to_string(root.join("experiments/maghareh2018/simulation.toml"))
        .expect("the bundled default");
    let runs = text.find("[[runs]]\nid = \"exp1\"").expect("exp1");
    let sensitivity = text.find("[sensitivity]").expect("its sensitivity");
    let identification = text.find("[[runs]]").expect("runs");
    let text = format!(
        "{}{}",
        &text[..sensitivity].replace("[excitation]", &format!("{unmodelled}\n[excitation]")),
        &text[identification..runs],
    );
    let plan = load_simulation_str(&text, &dir.join("simulation.toml")).unwrap();
    let sim = simulate_campaign(&plan, dir).expect("simulates");
    let campaign = load(&sim.manifest).expect("the generated manifest loads");
    let samples = 3 * (172.0 * 2048.0) as u64;
    (campaign, samples)
}

fn bench_campaign(c: &mut Criterion) {
    let root = std::path::Path::new(env!("CARGO_MANIFEST_DIR"));
    let mut group = c.benchmark_group("campaign");
    group.sample_size(10);
    for (name, unmodelled) in [
        ("linear", ""),
        (
            "seal_friction",
            "[rig.unmodelled]\npiston_mass_kg = 0.5\nactuator_friction = { coulomb_force_n = 8.0, smoothing_velocity_m_per_s = 0.002 }\n",
        ),
    ] {
        let dir = tempfile::tempdir().expect("a temporary folder");
        let (campaign, samples) = identification_campaign(root, dir.path(), unmodelled);
        // Fail loudly rather than time a campaign that does not do its work.
        let results = servoid::run::analyse(&campaign);
        let joint = results
            .rig
            .as_ref()
            .and_then(|r| r.joint.as_ref())
            .expect("a joint fit");
        assert_eq!(joint.friction_correction.is_some(), !unmodelled.is_empty());
        group.throughput(Throughput::Elements(samples));
        group.bench_function(name, |b| {
            b.iter(|| servoid::run::analyse(black_box(&campaign)))
        });
    }
    group.finish();
}

criterion_group!(benches, bench_identify, bench_campaign);
criterion_main!(benches);
