//! Throughput of the FRF stage on a log of the paper's shape: 170 s at
//! 2048 Hz (348,160 samples), a quadratic chirp 0.1-35 Hz through the
//! no-specimen plant of Eq. 36, Welch H1 with 8192-sample Hann segments at
//! 50 % overlap (the manifest's defaults). And the whole-record ETFE a run
//! makes (coherence from 8192-sample segments, the default's rectangular
//! window), whole and with only the bins up to 35 Hz an analysis keeps,
//! for one output and for two (a run's displacement and force). And one real transform each way, at the paper's record length and at a
//! night's (120 s at 1 kHz): the unit a run's cost is counted in.
//!
//! `cargo bench --bench frf`

use std::f64::consts::PI;
use std::hint::black_box;

use criterion::{Criterion, Throughput, criterion_group, criterion_main};
use servoid::frf;
use servoid::frf::{Detrend, FrfPlan, Keep, Method, Output, Window};

const FS_HZ: f64 = 2048.0;
const DURATION_S: f64 = 170.0;

/// Quadratic chirp f(t) = f0 + (f1 - f0) (t/T)^2 of 3 mm amplitude, and its
/// response through 3060/(s^2 + 267 s + 3060) (paper Eq. 36), written as two
/// first-order lags with poles at 12.1 and 254.9 rad/s, each discretised by
/// zero-order hold (a plausible signal; the timing does not depend on it).
fn synthetic_log() -> (Vec<f64>, Vec<f64>) {
    let n = (DURATION_S * FS_HZ) as usize;
    let (f0, f1) = (0.1, 35.0);
    let u: Vec<f64> = (0..n)
        .map(|i| {
            let t = i as f64 / FS_HZ;
            let phase = 2.0 * PI * (f0 * t + (f1 - f0) * t.powi(3) / (3.0 * DURATION_S.powi(2)));
            0.003 * phase.sin()
        })
        .collect();
    let disc = 267.0f64 * 267.0 - 4.0 * 3060.0;
    let poles = [(267.0 - disc.sqrt()) / 2.0, (267.0 + disc.sqrt()) / 2.0];
    let mut y = u.clone();
    for p in poles {
        let a = (-p / FS_HZ).exp();
        let mut state = 0.0;
        for v in y.iter_mut() {
            let input = *v;
            *v = state;
            state = a * state + (1.0 - a) * input;
        }
    }
    (u, y)
}

fn bench_frf(c: &mut Criterion) {
    let (u, y) = synthetic_log();
    let plan = FrfPlan::new(Method::H1, 8192, 0.5, Window::Hann, Detrend::Mean).unwrap();
    let mut group = c.benchmark_group("frf");
    group.throughput(Throughput::Elements(u.len() as u64));
    group.bench_function("welch_h1/348160_samples/seg8192", |b| {
        b.iter(|| frf::estimate_one(black_box(&u), black_box(&y), FS_HZ, &plan).unwrap())
    });
    // The command's amplitude along the sweep, which every sweep run's
    // bins carry for the friction's describing function.
    assert!(frf::sweep_amplitude(&u, FS_HZ).is_some());
    group.bench_function("sweep_amplitude/348160_samples", |b| {
        b.iter(|| frf::sweep_amplitude(black_box(&u), FS_HZ).unwrap())
    });
    let etfe = FrfPlan::new(
        Method::Etfe,
        8192,
        0.5,
        Window::Rectangular,
        Detrend::Linear,
    )
    .unwrap();
    group.bench_function("etfe_whole/348160_samples", |b| {
        b.iter(|| frf::estimate_one(black_box(&u), black_box(&y), FS_HZ, &etfe).unwrap())
    });
    let kept = Keep::UpTo {
        hz: frf::KEPT_MAX_HZ,
        extra_bins: frf::VARIANCE_REACH_BINS,
    };
    let one = [Output { y: &y, plan: &etfe }];
    group.bench_function("etfe_up_to_35hz/348160_samples", |b| {
        b.iter(|| frf::estimate(black_box(&u), &one, FS_HZ, kept).unwrap())
    });
    // A run's displacement and force FRFs (here the response and its
    // negative), the command's transforms made once for both.
    let force: Vec<f64> = y.iter().map(|v| -v).collect();
    let outputs = [
        Output { y: &y, plan: &etfe },
        Output {
            y: &force,
            plan: &etfe,
        },
    ];
    group.bench_function("etfe_two_outputs_up_to_35hz/348160_samples", |b| {
        b.iter(|| frf::estimate(black_box(&u), &outputs, FS_HZ, kept).unwrap())
    });
    group.finish();
}

/// One real-to-complex and one complex-to-real transform, planned once as
/// every stage plans them (`servoid::fft`), on the chirp's samples.
fn bench_transforms(c: &mut Criterion) {
    let (u, _) = synthetic_log();
    let mut group = c.benchmark_group("fft");
    for n in [120_000, u.len()] {
        let forward = servoid::fft::real_forward(n);
        let inverse = servoid::fft::real_inverse(n);
        let mut input = u[..n].to_vec();
        let mut spectrum = forward.make_output_vec();
        let mut scratch = forward.make_scratch_vec();
        group.throughput(Throughput::Elements(n as u64));
        group.bench_function(format!("real_forward/{n}_samples"), |b| {
            b.iter(|| {
                input.copy_from_slice(&u[..n]);
                forward
                    .process_with_scratch(black_box(&mut input), &mut spectrum, &mut scratch)
                    .unwrap()
            })
        });
        let mut bins = spectrum.clone();
        let mut output = inverse.make_output_vec();
        let mut scratch = inverse.make_scratch_vec();
        group.bench_function(format!("real_inverse/{n}_samples"), |b| {
            b.iter(|| {
                bins.copy_from_slice(&spectrum);
                // The bins a real signal's transform has no imaginary part at.
                bins[0].im = 0.0;
                if n % 2 == 0 {
                    let last = bins.len() - 1;
                    bins[last].im = 0.0;
                }
                inverse
                    .process_with_scratch(black_box(&mut bins), &mut output, &mut scratch)
                    .unwrap()
            })
        });
    }
    group.finish();
}

criterion_group!(benches, bench_frf, bench_transforms);
criterion_main!(benches);
