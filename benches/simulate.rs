//! Simulator throughput: the paper's 170 s chirp at 2048 Hz (348,160 samples)
//! through the linear Exp1 plant (exact ZOH), and a Duffing specimen on the
//! same rig with RK4 for comparison; and the simulator's CSV log of that
//! run (time, command, displacement: shortest round-trip decimals).
//! `cargo bench --bench simulate`.

use std::hint::black_box;
use std::path::Path;

use criterion::{Criterion, Throughput, criterion_group, criterion_main};
use servoid::model::{Duffing, SpecimenModel};
use servoid::report::columns::csv_bytes;
use servoid::simulate::multisine::odd_multisine;
use servoid::simulate::{
    ChirpLaw, Excitation, Integrator, Padding, PlantSpec, Unmodelled, generate, seeded_rng,
    simulate,
};

const FS_HZ: f64 = 2048.0;

/// Quadratic chirp 0.1 -> 35 Hz, 2 mm (the paper's command).
fn paper_command(duration_s: f64) -> Vec<f64> {
    generate(
        &Excitation::Chirp {
            law: ChirpLaw::Quadratic,
            f0_hz: 0.1,
            f1_hz: 35.0,
            duration_s,
            amplitude_m: 2e-3,
        },
        FS_HZ,
        Padding::default(),
    )
    .expect("valid chirp")
}

fn bench_simulate(c: &mut Criterion) {
    let mut group = c.benchmark_group("simulate");

    let u = paper_command(170.0);
    assert_eq!(u.len(), 348_160);
    let exp1 = PlantSpec {
        rig: servoid::model::PAPER_RIG,
        specimen: SpecimenModel::LinearSdof {
            mass_kg: 3.8,
            damping_ns_per_m: 5.0,
            stiffness_n_per_m: 129_400.0,
        },
        unmodelled: Unmodelled::default(),
    };
    group.throughput(Throughput::Elements(u.len() as u64));
    group.bench_function("linear_exp1_zoh/170s_2048hz", |b| {
        b.iter(|| {
            simulate(
                black_box(&exp1),
                black_box(&u),
                FS_HZ,
                [0.0, 0.0],
                Integrator::default(),
            )
            .expect("simulates")
        })
    });

    // The CSV log the simulator writes of that run, in values per second.
    let out = simulate(&exp1, &u, FS_HZ, [0.0, 0.0], Integrator::default()).expect("simulates");
    let time: Vec<f64> = (0..u.len()).map(|k| k as f64 / FS_HZ).collect();
    let columns = [
        ("time_s", &time[..]),
        ("command_m", &u[..]),
        ("displacement_m", &out.x1_m[..]),
    ];
    group.throughput(Throughput::Elements(3 * u.len() as u64));
    group.bench_function("csv_log/170s_2048hz_3_columns", |b| {
        b.iter(|| csv_bytes(Path::new("log.csv"), black_box(&columns)).expect("writes"))
    });

    // The nonlinear path for information: 10 s of the same command.
    let u = paper_command(10.0);
    let duffing = PlantSpec {
        specimen: SpecimenModel::Duffing(Duffing {
            mass_kg: 3.8,
            damping_ns_per_m: 5.0,
            stiffness_n_per_m: 129_400.0,
            cubic_stiffness_n_per_m3: 1e10,
        }),
        ..exp1
    };
    group.throughput(Throughput::Elements(u.len() as u64));
    group.sample_size(20);
    group.bench_function("duffing_rk4_4substeps/10s_2048hz", |b| {
        b.iter(|| {
            simulate(
                black_box(&duffing),
                black_box(&u),
                FS_HZ,
                [0.0, 0.0],
                Integrator::Rk4 { substeps: 4 },
            )
            .expect("simulates")
        })
    });

    // A random-odd multisine designed: the odd harmonics of 0.05 Hz in
    // 0.5-35 Hz, a third left out (230 lines), over a 20 s period at
    // 2048 Hz, its crest factor lowered; in lines per second.
    let period = (20.0 * FS_HZ) as usize;
    let probe = odd_multisine(0.5, 35.0, FS_HZ, period, 1e-3, &mut seeded_rng(1, "bench"))
        .expect("lines in the band");
    group.throughput(Throughput::Elements(probe.excited.len() as u64));
    group.sample_size(10);
    group.bench_function("odd_multisine/0.5-35hz_20s_2048hz", |b| {
        b.iter(|| {
            odd_multisine(0.5, 35.0, FS_HZ, period, 1e-3, &mut seeded_rng(1, "bench"))
                .expect("lines in the band")
        })
    });
    group.finish();
}

criterion_group!(benches, bench_simulate);
criterion_main!(benches);
