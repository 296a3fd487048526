//! Log reading throughput (`cargo bench --bench ingest`): a 170 s log at
//! 2048 Hz (348,160 rows of time_s, command_mm, displacement_mm, force_kn)
//! from Parquet, CSV, MATLAB level 5 and v7.3, HDF5 (chunked, deflated)
//! and TDMS, as the simulator writes them, and the real 1 kHz DAQ text
//! export 0A.txt.
//! Throughput is file bytes per second; each read includes hashing the file
//! (SHA-256) and converting to SI, as `read_log` always does.

use std::hint::black_box;
use std::path::{Path, PathBuf};

use criterion::{Criterion, Throughput, criterion_group, criterion_main};
use servoid::ingest::{
    ChannelPlan, Channels, Column, CsvOptions, LogFormat, LogPlan, Repair, TimePlan,
};
use servoid::ingest::{Needs, check_log, read_log};
use servoid::report::columns::{
    UnitColumn, hdf5_bytes, mat_bytes, mat_v73_bytes, tdms_bytes, write_csv, write_parquet,
};
use servoid::units::Unit;

const FS_HZ: f64 = 2048.0;
const ROWS: usize = 348_160; // 170 s at 2048 Hz

fn channel(column: Column, unit: Unit, scale: f64) -> ChannelPlan {
    ChannelPlan {
        column,
        unit,
        gain: scale * unit.to_si(),
        offset: 0.0,
        range: None,
        repair: Repair::None,
    }
}

fn plan(path: &Path, format: LogFormat, time: TimePlan, chans: [ChannelPlan; 3]) -> LogPlan {
    let [command, displacement, force] = chans;
    LogPlan {
        path: path.to_path_buf(),
        format,
        csv: CsvOptions::default(),
        sha256: None,
        channels: Channels {
            time,
            command,
            displacement,
            force: Some(force),
        },
        max_bytes: servoid::ingest::DEFAULT_MAX_LOG_MIB << 20,
    }
}

/// A 0.1-20 Hz linear chirp command (mm), a lagging, smaller displacement
/// (mm) and a force (kN), with full-precision values like a simulator's.
fn columns() -> Vec<(&'static str, Vec<f64>)> {
    let t: Vec<f64> = (0..ROWS).map(|k| k as f64 / FS_HZ).collect();
    let duration_s = ROWS as f64 / FS_HZ;
    let rate = (20.0 - 0.1) / duration_s;
    let phase = |t: f64| 2.0 * std::f64::consts::PI * (0.1 * t + 0.5 * rate * t * t);
    let u: Vec<f64> = t.iter().map(|&t| 5.0 * phase(t).sin()).collect();
    let x: Vec<f64> = t.iter().map(|&t| 4.7 * (phase(t) - 0.3).sin()).collect();
    let f: Vec<f64> = t.iter().map(|&t| 12.5 * (phase(t) + 1.1).sin()).collect();
    vec![
        ("time_s", t),
        ("command_mm", u),
        ("displacement_mm", x),
        ("force_kn", f),
    ]
}

fn real_daq_log() -> PathBuf {
    [
        concat!(
            env!("CARGO_MANIFEST_DIR"),
            "/../shared/data/utfsm-mts-mrdamper/0A.txt"
        ),
        concat!(
            env!("CARGO_MANIFEST_DIR"),
            "/../../shared/data/utfsm-mts-mrdamper/0A.txt"
        ),
    ]
    .iter()
    .map(PathBuf::from)
    .find(|p| p.exists())
    .expect("the shared UTFSM logs")
}

fn bench(c: &mut Criterion) {
    let dir = tempfile::tempdir().unwrap();
    let cols = columns();
    let borrowed: Vec<(&str, &[f64])> = cols.iter().map(|(n, v)| (*n, v.as_slice())).collect();
    let parquet = dir.path().join("chirp.parquet");
    let csv = dir.path().join("chirp.csv");
    write_parquet(&parquet, &borrowed).unwrap();
    write_csv(&csv, &borrowed).unwrap();
    // The same CSV with a space before each comma: polars refuses a value
    // with a trailing space (a leading one it reads), so this measures the
    // line parser (ingest::csv's fallback, its fields split by csv-core).
    let spaced = dir.path().join("chirp-spaced.csv");
    let text = std::fs::read_to_string(&csv).unwrap().replace(',', " ,");
    std::fs::write(&spaced, text).unwrap();
    let units = ["s", "mm", "mm", "kN"];
    let with_units: Vec<UnitColumn<'_>> = cols
        .iter()
        .zip(units)
        .map(|((n, v), unit)| UnitColumn {
            name: n,
            unit,
            values: v,
        })
        .collect();
    let array_file = |file: &str, bytes: Vec<u8>| {
        let p = dir.path().join(file);
        std::fs::write(&p, bytes).unwrap();
        p
    };
    let mat5 = array_file(
        "chirp5.mat",
        mat_bytes(Path::new("x"), &with_units).unwrap(),
    );
    let mat73 = array_file(
        "chirp73.mat",
        mat_v73_bytes(Path::new("x"), &with_units).unwrap(),
    );
    let h5 = array_file("chirp.h5", hdf5_bytes(Path::new("x"), &with_units).unwrap());
    let tdms = array_file(
        "chirp.tdms",
        tdms_bytes(Path::new("x"), &with_units, "g", 1.0 / FS_HZ).unwrap(),
    );

    let name = |n: &str| Column::Name(n.into());
    let table_channels = || {
        [
            channel(name("command_mm"), Unit::Millimeter, 1.0),
            channel(name("displacement_mm"), Unit::Millimeter, 1.0),
            channel(name("force_kn"), Unit::Kilonewton, 1.0),
        ]
    };
    let tdms_channels = [
        channel(name("g/command_mm"), Unit::Millimeter, 1.0),
        channel(name("g/displacement_mm"), Unit::Millimeter, 1.0),
        channel(name("g/force_kn"), Unit::Kilonewton, 1.0),
    ];
    let time = TimePlan::Column {
        column: name("time_s"),
        to_s: 1.0,
    };
    let daq = real_daq_log();
    let cases = [
        (
            format!("parquet/{ROWS}x4"),
            plan(&parquet, LogFormat::Parquet, time.clone(), table_channels()),
        ),
        (
            format!("csv/{ROWS}x4"),
            plan(&csv, LogFormat::Csv, time.clone(), table_channels()),
        ),
        (
            format!("csv_line_parser/{ROWS}x4"),
            plan(&spaced, LogFormat::Csv, time.clone(), table_channels()),
        ),
        (
            format!("mat_level5/{ROWS}x4"),
            plan(&mat5, LogFormat::Mat, time.clone(), table_channels()),
        ),
        (
            format!("mat_v73/{ROWS}x4"),
            plan(&mat73, LogFormat::Mat, time.clone(), table_channels()),
        ),
        (
            format!("hdf5_deflate/{ROWS}x4"),
            plan(&h5, LogFormat::Hdf5, time, table_channels()),
        ),
        (
            format!("tdms/{ROWS}x4"),
            plan(&tdms, LogFormat::Tdms, TimePlan::FromLog, tdms_channels),
        ),
        (
            "daq_text/0A.txt".to_string(),
            plan(
                &daq,
                LogFormat::DaqText,
                TimePlan::FromLog,
                [
                    channel(name("CHANNEL2"), Unit::Millimeter, 10.0),
                    channel(name("CHANNEL0"), Unit::Millimeter, 10.0),
                    channel(name("CHANNEL1"), Unit::Newton, 9806.65),
                ],
            ),
        ),
    ];

    let mut group = c.benchmark_group("read_log");
    group.sample_size(20);
    for (id, p) in &cases {
        let bytes = std::fs::metadata(&p.path).unwrap().len();
        group.throughput(Throughput::Bytes(bytes));
        group.bench_function(id.as_str(), |b| {
            b.iter(|| black_box(read_log(black_box(p)).unwrap()))
        });
    }
    group.finish();

    // The checks a log passes before any spectrum (spikes and corrupt
    // stretches, held channels, clipping, the time base), on the paper's
    // 170 s record once read: what they add to each read above.
    let log = read_log(&cases[0].1).unwrap();
    let needs = Needs {
        min_samples: 4096,
        max_jitter_fraction: 0.05,
        clip_fraction: 0.01,
        force_loaded: true,
    };
    let mut group = c.benchmark_group("check_log");
    group.sample_size(20);
    group.throughput(Throughput::Elements(3 * ROWS as u64));
    group.bench_function(format!("{ROWS}x3"), |b| {
        b.iter(|| black_box(check_log(black_box(&log), &needs).unwrap()))
    });
    group.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
