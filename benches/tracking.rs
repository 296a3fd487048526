//! Throughput of the tracking stage on a log of the paper's shape: 170 s at
//! 2048 Hz (348,160 samples), a quadratic chirp 0.1-35 Hz through Exp1's
//! plant (the paper's rig with Table 2's specimen, Eqs. 34-35) by exact
//! discretisation: every tracking measure of the record
//! (`tracking::measure`, the delay by cross-correlation refined below a
//! sample dominating), and the compensator designed for the specimen, run
//! on the command and through the plant (`compensated_displacement`); and
//! the three measures of a validation run against one command, over the
//! record and the paper's four windows of a sweep.
//!
//! `cargo bench --bench tracking`

use std::f64::consts::PI;
use std::hint::black_box;

use criterion::{Criterion, Throughput, criterion_group, criterion_main};
use servoid::model::{self, LinearSpecimen};
use servoid::simulate::discrete::simulate_linear;
use servoid::tracking::{self, compensator};

const FS_HZ: f64 = 2048.0;
const DURATION_S: f64 = 170.0;

fn exp1() -> LinearSpecimen {
    LinearSpecimen::Sdof {
        mass_kg: 3.8,
        damping_ns_per_m: 5.0,
        stiffness_n_per_m: 129_400.0,
    }
}

fn bench_tracking(c: &mut Criterion) {
    let n = (DURATION_S * FS_HZ) as usize;
    let (f0, f1) = (0.1, 35.0);
    let u: Vec<f64> = (0..n)
        .map(|i| {
            let t = i as f64 / FS_HZ;
            let phase = 2.0 * PI * (f0 * t + (f1 - f0) * t.powi(3) / (3.0 * DURATION_S.powi(2)));
            0.003 * phase.sin()
        })
        .collect();
    let ss = model::state_space(&model::PAPER_RIG, &exp1());
    let x = simulate_linear(&ss, &u, 1.0 / FS_HZ, &[0.0, 0.0])
        .unwrap()
        .swap_remove(0);
    let plant = model::tf_x1_u(&model::PAPER_RIG, &exp1()).unwrap();
    let comp = compensator::design(&plant, FS_HZ, 30.0, None, true).unwrap();
    let mut group = c.benchmark_group("tracking");
    group.throughput(Throughput::Elements(n as u64));
    group.bench_function("measure/348160_samples", |b| {
        b.iter(|| {
            // The command's transform included: a run's first measure pays it.
            let reference = tracking::Reference::new(black_box(&u));
            tracking::measure(&reference, black_box(&x), FS_HZ, None, &[])
        })
    });
    // A validation run measures three displacements against its command
    // (measured, predicted, compensated), each over the record and the
    // paper's four windows of a sweep: what the command alone gives is
    // formed once for the three.
    let windows = servoid::validate::locate_windows(&u, FS_HZ);
    let y: Vec<f64> = x.iter().map(|v| 0.98 * v).collect();
    group.throughput(Throughput::Elements(3 * n as u64));
    group.bench_function("three_measures_with_windows/348160_samples", |b| {
        b.iter(|| {
            let reference = tracking::Reference::new(black_box(&u));
            [&x, &y, &u].map(|d| tracking::measure(&reference, black_box(d), FS_HZ, None, &windows))
        })
    });
    group.throughput(Throughput::Elements(n as u64));
    group.bench_function("compensated_displacement/348160_samples", |b| {
        b.iter(|| compensator::compensated_displacement(&ss, &comp, black_box(&u)).unwrap())
    });
    group.finish();
}

criterion_group!(benches, bench_tracking);
criterion_main!(benches);
