//! Fit time for the paper's second-order model on the bins a real log gives:
//! 170 s at 2048 Hz, Welch segments of 8192 samples (0.25 Hz apart), band
//! 0.5-30 Hz, with the command's sample-and-hold modelled; without and with
//! a fitted delay. Budget: FRF + fit within 20 ms in release. And the fit a
//! night's spring run makes: a whole-record ETFE of 120 s at 1 kHz (3541
//! bins 1/120 Hz apart in the band), with a fitted delay, whose start is
//! the delay grid's; and a 60 s ETFE at 200 Hz, where the hold's aliases
//! matter. The data are the plant's exact sampled response
//! (`fit::sampled_response`) plus noise.
//!
//! What the hold's aliases cost (criterion medians on the shared two cores,
//! another build running, 6 December 2026; noisy): 119 bins at 2048 Hz
//! 83 -> 136 us without a delay and 253 -> 407 us with one (their effect,
//! below 1 % of a std there, is read on every 8th bin at the start and the
//! optimum, then left out); 3541 bins at 1 kHz 6.9 -> 9.7 ms; 1771 bins at
//! 200 Hz 2.2 ms and 6.1 ms.
//!
//! `cargo bench --bench fit`

use std::hint::black_box;

use criterion::{BenchmarkId, Criterion, Throughput, criterion_group, criterion_main};
use nalgebra::Complex;
use servoid::fit::Intersample;
use servoid::fit::{DelayPlan, FitInput, FitOptions, fit};
use servoid::lti::TransferFunction;

const SAMPLE_RATE_HZ: f64 = 2048.0;
const SEGMENT: usize = 8192;
const BAND_HZ: (f64, f64) = (0.5, 30.0);

/// The Welch bins inside the band, and a noisy measured response there:
/// the paper's no-specimen model (Eq. 36) with a 1 ms delay, held and
/// sampled, plus 2 % complex noise.
fn data(sample_rate_hz: f64, segment: usize) -> (Vec<f64>, Vec<Complex<f64>>, Vec<f64>) {
    let df = sample_rate_hz / segment as f64;
    let freq: Vec<f64> = (0..=segment / 2)
        .map(|k| k as f64 * df)
        .filter(|f| (BAND_HZ.0..=BAND_HZ.1).contains(f))
        .collect();
    let plant = TransferFunction::with_delay(&[3060.0], &[1.0, 267.0, 3060.0], 0.001).unwrap();
    let mut rng = servoid::simulate::Draws::new(2018, "fit bench");
    let mut h = Vec::with_capacity(freq.len());
    let mut variance = Vec::with_capacity(freq.len());
    let held =
        servoid::fit::sampled_response(Intersample::SampleAndHold, sample_rate_hz, &plant, &freq);
    for clean in held {
        let v = (0.02 * clean.norm()).powi(2);
        let s = (0.5 * v).sqrt();
        h.push(clean + Complex::new(s * rng.normal(), s * rng.normal()));
        variance.push(v);
    }
    (freq, h, variance)
}

fn bench_fit(c: &mut Criterion) {
    bench_bins(
        c,
        "fit_second_order_hold",
        (SAMPLE_RATE_HZ, SEGMENT),
        &[
            ("no_delay", DelayPlan::None),
            ("fitted_delay_max_10ms", DelayPlan::Fit { max_s: 0.01 }),
        ],
    );
    bench_bins(
        c,
        "fit_etfe_120s_1khz",
        (1000.0, 120_000),
        &[("fitted_delay_max_10ms", DelayPlan::Fit { max_s: 0.01 })],
    );
    // A rig logged at 200 Hz, where the hold's aliases are 0.6 % of the
    // response at the band's top and the fit evaluates them again at its
    // optimum and refits (`fit` module docs): a 60 s ETFE, 1,771 bins.
    bench_bins(
        c,
        "fit_etfe_60s_200hz",
        (200.0, 12_000),
        &[
            ("no_delay", DelayPlan::None),
            ("fitted_delay_max_10ms", DelayPlan::Fit { max_s: 0.01 }),
        ],
    );
}

/// The fits of `cases` on the bins of `segment` samples at `sample_rate_hz`.
fn bench_bins(
    c: &mut Criterion,
    group_name: &str,
    (sample_rate_hz, segment): (f64, usize),
    cases: &[(&str, DelayPlan)],
) {
    let (freq, h, variance) = data(sample_rate_hz, segment);
    let n = freq.len();
    let input = FitInput {
        freq_hz: &freq,
        h: &h,
        variance: &variance,
    };
    let mut group = c.benchmark_group(group_name);
    group.throughput(Throughput::Elements(n as u64));
    for &(name, delay) in cases {
        let mut opts = FitOptions::new(0, 2, sample_rate_hz);
        opts.delay = delay;
        // Fail loudly rather than time a fit that does not work.
        let check = fit(&input, &opts).expect("the benchmark data fit");
        assert!(check.converged, "{name}: {}", check.termination);
        group.bench_with_input(
            BenchmarkId::new(name, format!("{n}_bins")),
            &opts,
            |b, o| b.iter(|| fit(black_box(&input), black_box(o)).unwrap()),
        );
    }
    group.finish();
}

criterion_group!(benches, bench_fit);
criterion_main!(benches);
