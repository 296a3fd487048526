//! Throughput of `servoid design`'s core on the paper's night: its three
//! identification runs (no specimen, springs k1 and k2 at P = 1), 172 s
//! each at 2,048 Hz, a 4 mm peak command and 2 um of white displacement
//! noise, over 0.5-30 Hz. Each of the 24 candidates (3 periods x 2 mixes
//! x 4 draws of the detection lines) gets its A-optimal shares, three
//! multisines with lowered crest factors, three commands simulated
//! through the plant for their peaks (x1, velocity, force) and its
//! predicted precision; the best is kept (`design::night::design`). The
//! same night on a rig with a 0.6 ms delay and a valve mode at 150 Hz
//! (damping 0.7) estimated beside the rig: seven parameters' information.
//!
//! `cargo bench --bench design`

use std::hint::black_box;

use criterion::{Criterion, Throughput, criterion_group, criterion_main};
use servoid::design::night::{Limits, NightPlan, Noise, design};
use servoid::design::precision::{Extension, Mode, Place};
use servoid::design::spectrum::RunModel;
use servoid::fit::Intersample;
use servoid::model::{self, LinearSpecimen};

const FS_HZ: f64 = 2048.0;

fn paper_night() -> NightPlan {
    let runs = [None, Some(116_640.0), Some(88_540.0)]
        .into_iter()
        .map(|k| RunModel {
            specimen: match k {
                None => LinearSpecimen::None,
                Some(k) => LinearSpecimen::Spring {
                    stiffness_n_per_m: k,
                },
            },
            p_gain: 1.0,
        })
        .collect();
    NightPlan {
        extension: Default::default(),
        rig: model::PAPER_RIG,
        runs,
        noise: Noise {
            freq_hz: vec![0.5, 30.0],
            psd_m2_per_hz: vec![2.0 * 4e-12 / FS_HZ; 2],
        },
        band_hz: [0.5, 30.0],
        sample_rate_hz: FS_HZ,
        record_s: 172.0,
        rest_s: 1.0,
        intersample: Intersample::SampleAndHold,
        limits: Limits {
            command_m: 0.004,
            stroke_m: None,
            velocity_m_per_s: None,
            force_n: None,
        },
        seed: 1,
    }
}

fn bench_design(c: &mut Criterion) {
    let plan = paper_night();
    let mut group = c.benchmark_group("design");
    group.sample_size(10);
    group.throughput(Throughput::Elements(24));
    group.bench_function("paper_night_24_candidates", |b| {
        b.iter(|| design(black_box(&plan), None).expect("a night"))
    });
    let extended = NightPlan {
        extension: Extension {
            delay_s: Some(6e-4),
            mode: Some(Mode {
                place: Place::Loop,
                hz: 150.0,
                damping: 0.7,
            }),
            piston_mass_kg: None,
        },
        ..plan.clone()
    };
    group.bench_function("delay_and_valve_mode_24_candidates", |b| {
        b.iter(|| design(black_box(&extended), None).expect("a night"))
    });
    group.finish();
}

criterion_group!(benches, bench_design);
criterion_main!(benches);
