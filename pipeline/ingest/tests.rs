//! Tests of log reading: the real DAQ logs against an independent parse,
//! round trips through the writers, a hand-built MAT-file, and every check
//! from a crafted bad file.

use std::path::{Path, PathBuf};

use approx::assert_relative_eq;

use super::*;
use crate::report::columns::{csv_bytes, parquet_bytes, write_csv, write_parquet};
use crate::units::Unit;

// ---------------------------------------------------------------- helpers

/// A channel as the manifest resolves it: gain = scale * unit-to-SI.
fn ch(column: Column, unit: Unit, scale: f64) -> ChannelPlan {
    ChannelPlan {
        column,
        unit,
        gain: scale * unit.to_si(),
        offset: 0.0,
        range: None,
        repair: Repair::None,
    }
}

fn name(n: &str) -> Column {
    Column::Name(n.into())
}

fn csv_options() -> CsvOptions {
    CsvOptions::default()
}

fn plan(
    path: &Path,
    format: LogFormat,
    time: TimePlan,
    command: ChannelPlan,
    displacement: ChannelPlan,
    force: Option<ChannelPlan>,
) -> LogPlan {
    LogPlan {
        path: path.to_path_buf(),
        format,
        csv: csv_options(),
        sha256: None,
        channels: Channels {
            time,
            command,
            displacement,
            force,
        },
        max_bytes: crate::ingest::DEFAULT_MAX_LOG_MIB << 20,
    }
}

/// A plan reading columns `t` (s), `u`, `x` (m) and `f` (N) by name.
fn plan_by_name(path: &Path, format: LogFormat) -> LogPlan {
    plan(
        path,
        format,
        TimePlan::Column {
            column: name("t"),
            to_s: 1.0,
        },
        ch(name("u"), Unit::Meter, 1.0),
        ch(name("x"), Unit::Meter, 1.0),
        Some(ch(name("f"), Unit::Newton, 1.0)),
    )
}

fn write_file(dir: &Path, file: &str, bytes: &[u8]) -> PathBuf {
    let p = dir.join(file);
    std::fs::write(&p, bytes).unwrap();
    p
}

fn err(plan: &LogPlan) -> String {
    read_log(plan)
        .expect_err("the log must be refused")
        .to_string()
}

fn assert_contains(msg: &str, parts: &[&str]) {
    for p in parts {
        assert!(msg.contains(p), "message {msg:?} lacks {p:?}");
    }
}

/// Deterministic pseudo-random numbers in (-1, 1) (64-bit LCG, Knuth's
/// MMIX constants), so the tests need no RNG crate.
pub(super) fn lcg(seed: u64, n: usize) -> Vec<f64> {
    let mut s = seed;
    (0..n)
        .map(|_| {
            s = s
                .wrapping_mul(6_364_136_223_846_793_005)
                .wrapping_add(1_442_695_040_888_963_407);
            (s >> 11) as f64 / (1u64 << 53) as f64 * 2.0 - 1.0
        })
        .collect()
}

/// Bit-for-bit equality of two series, reporting the first difference.
#[track_caller]
fn assert_same_bits(got: &[f64], want: &[f64]) {
    assert_eq!(got.len(), want.len(), "lengths differ");
    if let Some(k) = (0..got.len()).find(|&k| got[k].to_bits() != want[k].to_bits()) {
        panic!("sample {k}: got {:e}, want {:e}", got[k], want[k]);
    }
}

const NEEDS: Needs = Needs {
    min_samples: 1024,
    max_jitter_fraction: 0.01,
    clip_fraction: 0.01,
    force_loaded: true,
};

// ------------------------------------------------------- real DAQ logs

#[path = "../../tests/support/mts_data.rs"]
mod mts_data;

/// A real MTS log from the shared data folder (`tests/support/mts_data.rs`,
/// which the integration tests include too), or None after a SKIPPED line.
fn shared_log(file: &str) -> Option<PathBuf> {
    mts_data::mts_data_in(Path::new(env!("CARGO_MANIFEST_DIR"))).map(|d| d.join(file))
}

/// The UTFSM convention: CHANNEL2 = command (x 10 -> mm), CHANNEL0 =
/// displacement (x 10 -> mm), CHANNEL1 = force (x 9806.65 -> N).
fn daq_plan(path: &Path) -> LogPlan {
    plan(
        path,
        LogFormat::DaqText,
        TimePlan::FromLog,
        ch(name("CHANNEL2"), Unit::Millimeter, 10.0),
        ch(name("CHANNEL0"), Unit::Millimeter, 10.0),
        Some(ch(name("CHANNEL1"), Unit::Newton, 9806.65)),
    )
}

/// Independent parse of a DAQ export: skip the 7 header lines, split each
/// line with `str::split(',')`, and return per channel (CHANNEL0..2) the sum
/// and the max of the raw values, plus the line count.
fn independent_daq(path: &Path) -> ([f64; 3], [f64; 3], usize) {
    let text = std::fs::read_to_string(path).unwrap();
    let mut sum = [0.0; 3];
    let mut max = [f64::NEG_INFINITY; 3];
    let mut n = 0;
    for line in text.lines().skip(7) {
        let fields: Vec<&str> = line.split(',').collect();
        for k in 0..3 {
            let v: f64 = fields[2 + k].trim().parse().unwrap();
            sum[k] += v;
            max[k] = max[k].max(v);
        }
        n += 1;
    }
    (sum, max, n)
}

fn check_real_daq(file: &str, expected_rows: usize) {
    let Some(path) = shared_log(file) else {
        return;
    };
    let log = read_log(&daq_plan(&path)).unwrap();
    let (sum, max, n) = independent_daq(&path);
    assert_eq!(n, expected_rows);
    assert_eq!(log.n_rows, expected_rows);
    assert_eq!(log.command_m.len(), expected_rows);
    assert_relative_eq!(log.sample_rate_hz, 1000.0);
    assert!(matches!(log.timing, Timing::Exact { dt_s } if (dt_s - 1e-3).abs() < 1e-15));
    assert!(log.warnings.is_empty(), "{:?}", log.warnings);
    assert_eq!(log.sha256.len(), 64);

    // SI = raw * 10 mm * 1e-3 (m) or raw * 9806.65 (N).
    let to_m = 10.0 * 1e-3;
    let force = log.force_n.as_ref().unwrap();
    let sums = [
        log.displacement_m.iter().sum::<f64>(),
        force.iter().sum::<f64>(),
        log.command_m.iter().sum::<f64>(),
    ];
    let maxes = [
        log.displacement_m.iter().copied().fold(f64::MIN, f64::max),
        force.iter().copied().fold(f64::MIN, f64::max),
        log.command_m.iter().copied().fold(f64::MIN, f64::max),
    ];
    let gains = [to_m, 9806.65, to_m];
    for k in 0..3 {
        assert_relative_eq!(sums[k], sum[k] * gains[k], max_relative = 1e-12);
        assert_relative_eq!(maxes[k], max[k] * gains[k], max_relative = 1e-15);
    }
    // The real logs pass the checks with settings like the paper's
    // (2^14-point segments).
    let needs = Needs {
        min_samples: 1 << 14,
        ..NEEDS
    };
    assert!(check_log(&log, &needs).unwrap().is_empty());
}

#[test]
fn real_daq_log_0a_matches_an_independent_parse() {
    check_real_daq("0A.txt", 61_500);
}

#[test]
fn real_daq_log_1a_matches_an_independent_parse() {
    check_real_daq("1A.txt", 59_100);
}

#[test]
fn real_daq_log_first_and_last_values() {
    // Read off the file by eye: line 8 is the first sample, line 61507 the
    // last ("-0.0282, -0.0218, -0.0204, DAQ Pause, DAQ Stop").
    let Some(path) = shared_log("0A.txt") else {
        return;
    };
    let log = read_log(&daq_plan(&path)).unwrap();
    assert_relative_eq!(log.displacement_m[0], -0.0209 * 1e-2, max_relative = 1e-15);
    assert_relative_eq!(
        log.force_n.as_ref().unwrap()[0],
        -0.0166 * 9806.65,
        max_relative = 1e-15
    );
    assert_relative_eq!(log.command_m[0], -0.0169 * 1e-2, max_relative = 1e-15);
    assert_relative_eq!(log.command_m[61_499], -0.0204 * 1e-2, max_relative = 1e-15);
}

#[test]
fn real_daq_log_by_index_and_with_a_given_rate() {
    let Some(path) = shared_log("1A.txt") else {
        return;
    };
    let mut p = daq_plan(&path);
    p.channels.command.column = Column::Index(4); // CHANNEL2
    p.channels.time = TimePlan::SampleRate { hz: 1024.0 };
    let log = read_log(&p).unwrap();
    let by_name = read_log(&daq_plan(&path)).unwrap();
    assert_same_bits(&log.command_m, &by_name.command_m);
    assert_relative_eq!(log.sample_rate_hz, 1024.0);
    assert_eq!(log.warnings.len(), 1);
    assert_contains(&log.warnings[0].detail, &["1A.txt", "1024 Hz", "1000 Hz"]);
}

// ------------------------------------------------------------ CSV

/// Values that test shortest round-trip printing: tiny, large, negative
/// zero, sums that are not short decimals, subnormals. Within the +-10 m a
/// log may hold (`MAX_STROKE_M`): beyond it ingest refuses the sample.
fn awkward(n: usize, seed: u64) -> Vec<f64> {
    let mut v = lcg(seed, n);
    let special = [
        0.1 + 0.2,
        -0.0,
        1e-300,
        -2.5e-9,
        1.234_567_890_123_456_8,
        9.999_999_999_999_998,
        f64::MIN_POSITIVE / 8.0,
        -9.75e-3,
        1.0 / 3.0,
    ];
    for (k, s) in special.iter().enumerate() {
        v[k * 7 % n] = *s;
    }
    v
}

fn table(n: usize) -> Vec<(&'static str, Vec<f64>)> {
    let fs = 2048.0;
    vec![
        ("t", (0..n).map(|k| k as f64 / fs).collect()),
        ("u", awkward(n, 1)),
        ("x", awkward(n, 2)),
        ("f", awkward(n, 3)),
    ]
}

fn borrowed<'a>(t: &'a [(&'static str, Vec<f64>)]) -> Vec<(&'a str, &'a [f64])> {
    t.iter().map(|(n, v)| (*n, v.as_slice())).collect()
}

#[test]
fn csv_round_trip_is_bit_exact_by_name_and_by_index() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("log.csv");
    let t = table(3000);
    write_csv(&path, &borrowed(&t)).unwrap();

    let log = read_log(&plan_by_name(&path, LogFormat::Csv)).unwrap();
    assert_eq!(log.n_rows, 3000);
    assert_same_bits(&log.command_m, &t[1].1);
    assert_same_bits(&log.displacement_m, &t[2].1);
    assert_same_bits(log.force_n.as_ref().unwrap(), &t[3].1);
    assert_relative_eq!(log.sample_rate_hz, 2048.0, max_relative = 1e-12);
    assert_relative_eq!(log.t0_s, 0.0);

    let mut p = plan_by_name(&path, LogFormat::Csv);
    p.channels.time = TimePlan::Column {
        column: Column::Index(0),
        to_s: 1.0,
    };
    p.channels.command.column = Column::Index(3);
    p.channels.displacement.column = Column::Index(1);
    p.channels.force = None;
    let by_index = read_log(&p).unwrap();
    assert_same_bits(&by_index.command_m, &t[3].1);
    assert_same_bits(&by_index.displacement_m, &t[1].1);
    assert!(by_index.force_n.is_none());
}

#[test]
fn csv_writer_prints_shortest_round_trip_text() {
    let cols = [("a", &[0.1 + 0.2, 1e-300, -0.0, 0.5, 1e22][..])];
    let text = String::from_utf8(csv_bytes(Path::new("x.csv"), &cols).unwrap()).unwrap();
    // 0.1 + 0.2 is 0.3000000000000000444...; 17 digits are the fewest that
    // tell it from 0.3.
    assert_eq!(text, "a\n0.30000000000000004\n1e-300\n-0\n0.5\n1e22\n");
}

#[test]
fn csv_with_delimiter_skipped_lines_comments_and_units() {
    let dir = tempfile::tempdir().unwrap();
    let text = "\
rig: MTS 244 (skipped)
operator: nobody (skipped)
time_ms;u_in;x_cm;f_lbf;f_kn
% a comment line
0;1;10;100;1
1;2;20;200;2
% another comment

2;-4;-40;-400;-4
3;0.5;5;50;0.5
";
    let path = write_file(dir.path(), "log.csv", text.as_bytes());
    let mut p = plan(
        &path,
        LogFormat::Csv,
        TimePlan::Column {
            column: name("time_ms"),
            to_s: 1e-3,
        },
        ch(name("u_in"), Unit::Inch, 1.0),
        ch(name("x_cm"), Unit::Centimeter, 1.0),
        Some(ch(name("f_lbf"), Unit::PoundForce, 1.0)),
    );
    p.csv = CsvOptions {
        delimiter: ";".into(),
        skip_lines: 2,
        comment_prefix: Some("%".into()),
        header: true,
        decimal: ".".into(),
    };
    let log = read_log(&p).unwrap();
    assert_eq!(log.n_rows, 4);
    assert_relative_eq!(log.sample_rate_hz, 1000.0, max_relative = 1e-12);
    // 1 in = 0.0254 m exactly; 1 cm = 0.01 m; 1 lbf = 4.4482216152605 N.
    let u = [0.0254, 0.0508, -0.1016, 0.0127];
    let x = [0.1, 0.2, -0.4, 0.05];
    let f = [
        444.82216152605,
        889.6443230521,
        -1779.2886461042,
        222.411080763025,
    ];
    for k in 0..4 {
        assert_relative_eq!(log.command_m[k], u[k], max_relative = 1e-15);
        assert_relative_eq!(log.displacement_m[k], x[k], max_relative = 1e-15);
        assert_relative_eq!(log.force_n.as_ref().unwrap()[k], f[k], max_relative = 1e-15);
    }

    // The same file, force in kN and millimetres for x (scale 10: cm -> mm).
    p.channels.force = Some(ch(name("f_kn"), Unit::Kilonewton, 1.0));
    p.channels.displacement = ch(name("x_cm"), Unit::Millimeter, 10.0);
    let log = read_log(&p).unwrap();
    let f = [1000.0, 2000.0, -4000.0, 500.0];
    for k in 0..4 {
        assert_relative_eq!(log.displacement_m[k], x[k], max_relative = 1e-15);
        assert_relative_eq!(log.force_n.as_ref().unwrap()[k], f[k], max_relative = 1e-15);
    }
}

#[test]
fn csv_without_header_is_addressed_by_index() {
    let dir = tempfile::tempdir().unwrap();
    let path = write_file(
        dir.path(),
        "log.csv",
        b"# comment\n0\t1\t2\n0.5\t3\t4\n1\t5\t6\n",
    );
    let mut p = plan(
        &path,
        LogFormat::Csv,
        TimePlan::Column {
            column: Column::Index(0),
            to_s: 1.0,
        },
        ch(Column::Index(2), Unit::Meter, 1.0),
        ch(Column::Index(1), Unit::Meter, 1.0),
        None,
    );
    p.csv = CsvOptions {
        delimiter: "\t".into(),
        skip_lines: 0,
        comment_prefix: Some("#".into()),
        header: false,
        decimal: ".".into(),
    };
    let log = read_log(&p).unwrap();
    assert_eq!(log.n_rows, 3);
    assert_relative_eq!(log.sample_rate_hz, 2.0, max_relative = 1e-15);
    assert_relative_eq!(log.command_m[2], 6.0);
    assert_relative_eq!(log.displacement_m[1], 3.0);

    // A name cannot address a headerless file; the error says how to.
    p.channels.command.column = name("u");
    let msg = err(&p);
    assert_contains(&msg, &["log.csv", "`u`", "no header", "index 0 to 2"]);
}

/// A European export: fields delimited by `;`, numbers with a decimal
/// comma, read with `decimal = ","`: the same values as written with
/// points. Both readers: polars (clean fields) and the line parser (a field
/// with spaces around it sends the file there).
#[test]
fn csv_with_decimal_commas() {
    let dir = tempfile::tempdir().unwrap();
    for (file, text) in [
        (
            "clean.csv",
            "t;u;x\n0;1,5;-2,25\n0,5;-0,125;3\n1;1e-3;4,5E-2\n",
        ),
        (
            "spaced.csv",
            "t;u;x\n0; 1,5 ;-2,25\n0,5;-0,125;3\n1;1e-3;4,5E-2\n",
        ),
    ] {
        let path = write_file(dir.path(), file, text.as_bytes());
        let mut p = plan_by_name(&path, LogFormat::Csv);
        p.channels.force = None;
        p.csv = CsvOptions {
            delimiter: ";".into(),
            decimal: ",".into(),
            ..CsvOptions::default()
        };
        let log = read_log(&p).unwrap_or_else(|e| panic!("{file}: {e}"));
        // Exact: each value is parsed once and scaled by 1 (the unit is m).
        assert_eq!(log.command_m, vec![1.5, -0.125, 1e-3], "{file}");
        assert_eq!(log.displacement_m, vec![-2.25, 3.0, 0.045], "{file}");
        assert_relative_eq!(log.sample_rate_hz, 2.0, max_relative = 1e-15);
    }
}

#[test]
fn csv_comment_before_header_byte_order_mark_and_spaces() {
    let dir = tempfile::tempdir().unwrap();
    let text = "\u{feff}# exported by the rig\nt,u,x,f\n0,1,2,3\n0.5, 1.5 ,2,3\n1,1,2,3\n";
    let path = write_file(dir.path(), "spaces.csv", text.as_bytes());
    let mut p = plan_by_name(&path, LogFormat::Csv);
    p.csv.comment_prefix = Some("#".into());
    let log = read_log(&p).unwrap();
    assert_eq!(log.n_rows, 3);
    assert_relative_eq!(log.command_m[1], 1.5);
    assert_relative_eq!(log.sample_rate_hz, 2.0);
}

/// A logger's free-text column whose values and name hold the delimiter in
/// quotes: polars reads the clean file, and where a value padded with
/// spaces sends the file to the line parser, that parser splits the quoted
/// fields as CSV does too (it used to split them at the quoted commas and
/// read the note's second half as the displacement). The header's quoted
/// name with a comma is one column.
#[test]
fn csv_quoted_fields_may_hold_the_delimiter_in_either_reader() {
    let dir = tempfile::tempdir().unwrap();
    for (file, text) in [
        (
            "clean.csv",
            "t,\"note, free text\",u,x\n0,\"start, slow\",1,2\n0.5,\"a, b, c\",1.5,2.5\n1,\"\",1,2\n",
        ),
        (
            "spaced.csv",
            "t,\"note, free text\",u,x\n0,\"start, slow\",1,2\n0.5,\"a, b, c\", 1.5 ,2.5\n1,\"\",1,2\n",
        ),
    ] {
        let path = write_file(dir.path(), file, text.as_bytes());
        let mut p = plan_by_name(&path, LogFormat::Csv);
        p.channels.force = None;
        let log = read_log(&p).unwrap_or_else(|e| panic!("{file}: {e}"));
        // Exact: halves and integers, parsed and scaled by 1.
        assert_eq!(log.command_m, vec![1.0, 1.5, 1.0], "{file}");
        assert_eq!(log.displacement_m, vec![2.0, 2.5, 2.0], "{file}");
        let mut by_index = p.clone();
        by_index.channels.command.column = Column::Index(2);
        by_index.channels.displacement.column = Column::Index(3);
        let log = read_log(&by_index).unwrap_or_else(|e| panic!("{file} by index: {e}"));
        assert_eq!(log.displacement_m, vec![2.0, 2.5, 2.0], "{file}");
    }
    // The column list in a refusal names the quoted column whole.
    let path = write_file(
        dir.path(),
        "named.csv",
        b"t,\"note, free text\",u,x\n0,a,1,2\n1,b,1,2\n",
    );
    let mut p = plan_by_name(&path, LogFormat::Csv);
    p.channels.force = None;
    p.channels.displacement.column = name("disp");
    let msg = err(&p);
    assert_contains(&msg, &["`note, free text`", "`disp`"]);
}

// ------------------------------------------------------------ Parquet

#[test]
fn parquet_round_trip_is_bit_exact_by_name_and_by_index() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("log.parquet");
    let t = table(5000);
    write_parquet(&path, &borrowed(&t)).unwrap();

    let log = read_log(&plan_by_name(&path, LogFormat::Parquet)).unwrap();
    assert_eq!(log.n_rows, 5000);
    assert_same_bits(&log.command_m, &t[1].1);
    assert_same_bits(&log.displacement_m, &t[2].1);
    assert_same_bits(log.force_n.as_ref().unwrap(), &t[3].1);
    assert_relative_eq!(log.sample_rate_hz, 2048.0, max_relative = 1e-12);

    let p = plan(
        &path,
        LogFormat::Parquet,
        TimePlan::SampleRate { hz: 2048.0 },
        ch(Column::Index(2), Unit::Millimeter, 1.0),
        ch(Column::Index(3), Unit::Meter, 1.0),
        Some(ch(Column::Index(1), Unit::Kilonewton, 1.0)),
    );
    let log = read_log(&p).unwrap();
    assert!(matches!(log.timing, Timing::Exact { .. }));
    assert_same_bits(&log.displacement_m, &t[3].1);
    for k in (0..5000).step_by(97) {
        assert_relative_eq!(log.command_m[k], t[2].1[k] / 1000.0, max_relative = 1e-15);
        assert_relative_eq!(
            log.force_n.as_ref().unwrap()[k],
            t[1].1[k] * 1000.0,
            max_relative = 1e-15
        );
    }
}

/// A logger's timestamps as the time column (`timestamp[us]`, as pandas
/// and many DAQs write Parquet, once refused as "not numbers"): the
/// seconds since the first sample, so the rate is the samples' own. At
/// 1 kHz in microseconds every step is exactly 1000 ticks, so the rate is
/// exactly 1000 Hz.
#[test]
fn parquet_timestamps_are_the_time_since_the_first_sample() {
    use polars::prelude::{
        Column as PlColumn, DataFrame, NamedFrom, ParquetWriter, Series, TimeUnit as Tu,
    };
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("stamped.parquet");
    let n = 4000;
    // 2024-05-01T09:30:00 in microseconds since 1970, then 1 ms a sample.
    let start = (19_844_i64 * 86_400 + 34_200) * 1_000_000;
    let t = Series::new(
        "t".into(),
        (0..n).map(|k| start + 1000 * k as i64).collect::<Vec<_>>(),
    )
    .cast(&polars::prelude::DataType::Datetime(Tu::Microseconds, None))
    .unwrap();
    let u = awkward(n, 1);
    let x = awkward(n, 2);
    let f = awkward(n, 3);
    let mut df = DataFrame::new_infer_height(vec![
        t.into(),
        PlColumn::new("u".into(), &u),
        PlColumn::new("x".into(), &x),
        PlColumn::new("f".into(), &f),
    ])
    .unwrap();
    ParquetWriter::new(std::fs::File::create(&path).unwrap())
        .finish(&mut df)
        .unwrap();
    let log = read_log(&plan_by_name(&path, LogFormat::Parquet)).unwrap();
    assert_eq!(log.n_rows, n);
    // Exact: 1 ms steps in microseconds are 1000 ticks each.
    assert_eq!(log.sample_rate_hz, 1000.0);
    assert_same_bits(&log.command_m, &u);
    assert_same_bits(&log.displacement_m, &x);
}

#[test]
fn writers_give_identical_bytes_for_identical_columns() {
    let dir = tempfile::tempdir().unwrap();
    let t = table(20_000);
    let cols = borrowed(&t);
    let (a, b) = (dir.path().join("a.parquet"), dir.path().join("b.parquet"));
    write_parquet(&a, &cols).unwrap();
    write_parquet(&b, &cols).unwrap();
    assert_eq!(std::fs::read(&a).unwrap(), std::fs::read(&b).unwrap());
    let (a, b) = (dir.path().join("a.csv"), dir.path().join("b.csv"));
    write_csv(&a, &cols).unwrap();
    write_csv(&b, &cols).unwrap();
    assert_eq!(std::fs::read(&a).unwrap(), std::fs::read(&b).unwrap());
    assert_eq!(
        parquet_bytes(Path::new("p"), &cols).unwrap(),
        std::fs::read(dir.path().join("a.parquet")).unwrap()
    );
    assert_eq!(
        csv_bytes(Path::new("c"), &cols).unwrap(),
        std::fs::read(dir.path().join("a.csv")).unwrap()
    );
}

#[test]
fn writers_refuse_ragged_columns_and_bad_names() {
    let p = Path::new("out/log.csv");
    let e = csv_bytes(p, &[("a", &[1.0, 2.0][..]), ("b", &[1.0][..])]).unwrap_err();
    assert_contains(&e.to_string(), &["out/log.csv", "`b` has 1", "`a` has 2"]);
    let e = parquet_bytes(p, &[("a,b", &[1.0][..])]).unwrap_err();
    assert_contains(&e.to_string(), &["\"a,b\""]);
    let e = csv_bytes(p, &[("a", &[1.0][..]), ("a", &[1.0][..])]).unwrap_err();
    assert_contains(&e.to_string(), &["unique"]);
}

// ------------------------------------------------------------ MAT

/// A minimal MAT level-5 writer, after MathWorks, "MAT-File Format"
/// (R2013b and later), chapter 1: a 128-byte header (116 bytes of text, 8
/// bytes of subsystem-data offset, version 0x0100, endian indicator "IM" as
/// written by a little-endian machine), then data elements. Each element is
/// an 8-byte tag (u32 data type, u32 byte count) and its data padded to 8
/// bytes; elements of 4 bytes or less may use the small format (byte count
/// in the upper half of the first u32, data in the second). A variable is a
/// miMATRIX (type 14) holding: array flags (miUINT32, class in the low byte,
/// mxDOUBLE_CLASS = 6), dimensions (miINT32), name (miINT8) and the real part
/// (miDOUBLE, type 9), column-major, then for a complex variable (flag
/// 0x0800 in the array flags) the imaginary part likewise. A compressed
/// variable is a miCOMPRESSED element (type 15) holding the zlib stream of
/// the whole miMATRIX element, unpadded.
mod matw {
    pub const MI_INT8: u32 = 1;
    pub const MI_INT32: u32 = 5;
    pub const MI_UINT32: u32 = 6;
    pub const MI_DOUBLE: u32 = 9;
    pub const MI_MATRIX: u32 = 14;
    pub const MI_COMPRESSED: u32 = 15;
    pub const MX_DOUBLE_CLASS: u32 = 6;
    pub const MX_COMPLEX_FLAG: u32 = 0x0800;

    pub fn header() -> Vec<u8> {
        let mut h = format!(
            "{:<116}",
            "MATLAB 5.0 MAT-file, written by the servoid tests"
        )
        .into_bytes();
        h.extend_from_slice(&[0u8; 8]);
        h.extend_from_slice(&0x0100u16.to_le_bytes());
        h.extend_from_slice(b"IM");
        assert_eq!(h.len(), 128);
        h
    }

    pub fn element(ty: u32, data: &[u8]) -> Vec<u8> {
        let mut e = Vec::new();
        if data.len() <= 4 && ty != MI_MATRIX {
            e.extend_from_slice(&(((data.len() as u32) << 16) | ty).to_le_bytes());
            e.extend_from_slice(data);
            e.resize(8, 0);
            return e;
        }
        e.extend_from_slice(&ty.to_le_bytes());
        e.extend_from_slice(&(data.len() as u32).to_le_bytes());
        e.extend_from_slice(data);
        e.resize(8 + data.len().div_ceil(8) * 8, 0);
        e
    }

    /// A rows x cols double variable, `values` column-major.
    pub fn matrix(name: &str, rows: usize, cols: usize, values: &[f64]) -> Vec<u8> {
        array(name, &[rows, cols], values, None)
    }

    /// A double variable of any dimensions, `real` column-major; an `imag`
    /// part makes it complex (the complex flag in the array flags, the
    /// imaginary part after the real one).
    pub fn array(name: &str, dims: &[usize], real: &[f64], imag: Option<&[f64]>) -> Vec<u8> {
        assert_eq!(real.len(), dims.iter().product::<usize>());
        let flags = MX_DOUBLE_CLASS | if imag.is_some() { MX_COMPLEX_FLAG } else { 0 };
        let mut body = element(
            MI_UINT32,
            &[flags.to_le_bytes(), 0u32.to_le_bytes()].concat(),
        );
        let dims: Vec<u8> = dims
            .iter()
            .flat_map(|&d| (d as i32).to_le_bytes())
            .collect();
        body.extend(element(MI_INT32, &dims));
        body.extend(element(MI_INT8, name.as_bytes()));
        for part in std::iter::once(real).chain(imag) {
            let data: Vec<u8> = part.iter().flat_map(|v| v.to_le_bytes()).collect();
            body.extend(element(MI_DOUBLE, &data));
        }
        element(MI_MATRIX, &body)
    }

    /// A 1 x n char variable (mxCHAR_CLASS = 4), its text as miUINT16
    /// (type 4) characters, as MATLAB saves text.
    pub fn char_array(name: &str, text: &str) -> Vec<u8> {
        let mut body = element(
            MI_UINT32,
            &[4u32.to_le_bytes(), 0u32.to_le_bytes()].concat(),
        );
        let dims = [1i32.to_le_bytes(), (text.len() as i32).to_le_bytes()].concat();
        body.extend(element(MI_INT32, &dims));
        body.extend(element(MI_INT8, name.as_bytes()));
        let chars: Vec<u8> = text.encode_utf16().flat_map(u16::to_le_bytes).collect();
        body.extend(element(4, &chars));
        element(MI_MATRIX, &body)
    }

    pub fn compressed(matrix: &[u8]) -> Vec<u8> {
        use std::io::Write;
        let mut z = flate2::write::ZlibEncoder::new(Vec::new(), flate2::Compression::default());
        z.write_all(matrix).unwrap();
        let z = z.finish().unwrap();
        let mut e = MI_COMPRESSED.to_le_bytes().to_vec();
        e.extend_from_slice(&(z.len() as u32).to_le_bytes());
        e.extend(z);
        e
    }
}

/// Samples of a MAT test log: t at 1 kHz, u, x1 and f.
fn mat_signals(n: usize) -> [Vec<f64>; 4] {
    [
        (0..n).map(|k| k as f64 * 1e-3).collect(),
        lcg(11, n),
        lcg(12, n),
        lcg(13, n),
    ]
}

fn mat_file(compress: bool, n: usize) -> Vec<u8> {
    let [t, u, x, f] = mat_signals(n);
    // One table `data` = [u x f] (n x 3), plus vectors t (1 x n), u (n x 1)
    // and a wide table `sim` = [t; x] (2 x n) as Simulink's To File writes.
    let data: Vec<f64> = [u.clone(), x.clone(), f.clone()].concat();
    let wide: Vec<f64> = t.iter().zip(&x).flat_map(|(a, b)| [*a, *b]).collect();
    let vars = [
        matw::matrix("t", 1, n, &t),
        matw::matrix("u", n, 1, &u),
        matw::matrix("data", n, 3, &data),
        matw::matrix("sim", 2, n, &wide),
    ];
    let mut file = matw::header();
    for v in vars {
        file.extend(if compress { matw::compressed(&v) } else { v });
    }
    file
}

fn mat_plan(path: &Path) -> LogPlan {
    plan(
        path,
        LogFormat::Mat,
        TimePlan::FromLog,
        ch(name("u"), Unit::Meter, 1.0),
        ch(name("data:1"), Unit::Meter, 1.0),
        Some(ch(Column::Index(2), Unit::Newton, 1.0)),
    )
}

#[test]
fn mat_level5_vectors_tables_and_wide_tables() {
    let dir = tempfile::tempdir().unwrap();
    let n = 700;
    let [_, u, x, f] = mat_signals(n);
    for compress in [false, true] {
        let path = write_file(dir.path(), "log.mat", &mat_file(compress, n));
        // `data` is the only n x 3 table... but `sim` is 2-D too, so an index
        // is ambiguous and the message says how to resolve it.
        let msg = err(&mat_plan(&path));
        assert_contains(
            &msg,
            &["log.mat", "force", "`data`", "`sim`", "\"variable:2\""],
        );

        let mut p = mat_plan(&path);
        p.channels.force = Some(ch(name("data:2"), Unit::Kilonewton, 1.0));
        let log = read_log(&p).unwrap();
        assert_eq!(log.n_rows, n);
        assert_relative_eq!(log.sample_rate_hz, 1000.0, max_relative = 1e-12);
        assert_same_bits(&log.command_m, &u);
        assert_same_bits(&log.displacement_m, &x);
        for (got, raw) in log.force_n.as_ref().unwrap().iter().zip(&f) {
            assert_relative_eq!(*got, raw * 1e3, max_relative = 1e-15);
        }
        // A wide table has its channels in rows.
        p.channels.displacement = ch(name("sim:1"), Unit::Meter, 1.0);
        p.channels.time = TimePlan::Column {
            column: name("sim:0"),
            to_s: 1.0,
        };
        let log = read_log(&p).unwrap();
        assert_same_bits(&log.displacement_m, &x);
        assert!(matches!(log.timing, Timing::Measured { .. }));
    }
}

#[test]
fn mat_index_addresses_the_only_table() {
    let dir = tempfile::tempdir().unwrap();
    let n = 300;
    let [t, u, x, _] = mat_signals(n);
    let mut file = matw::header();
    file.extend(matw::matrix("time", n, 1, &t));
    file.extend(matw::compressed(&matw::matrix(
        "log",
        n,
        2,
        &[u.clone(), x.clone()].concat(),
    )));
    let path = write_file(dir.path(), "idx.mat", &file);
    let p = plan(
        &path,
        LogFormat::Mat,
        TimePlan::FromLog,
        ch(Column::Index(0), Unit::Meter, 1.0),
        ch(Column::Index(1), Unit::Meter, 1.0),
        None,
    );
    let log = read_log(&p).unwrap();
    assert_same_bits(&log.command_m, &u);
    assert_same_bits(&log.displacement_m, &x);

    let mut p = p;
    p.channels.displacement.column = Column::Index(2);
    assert_contains(&err(&p), &["idx.mat", "`log:2`", "channels 0 to 1"]);
    p.channels.displacement.column = name("x1");
    assert_contains(
        &err(&p),
        &["idx.mat", "`x1`", "`time` (300x1)", "`log` (300x2)"],
    );
}

#[test]
fn mat_errors_name_the_file() {
    let dir = tempfile::tempdir().unwrap();
    let mut v73 = b"MATLAB 7.3 MAT-file, Platform: GLNXA64".to_vec();
    v73.resize(512, 0);
    let path = write_file(dir.path(), "v73.mat", &v73);
    // A v7.3 header with no HDF5 behind it: cut after MATLAB's user block.
    assert_contains(
        &err(&mat_plan(&path)),
        &[
            "v73.mat",
            "not a readable MAT v7.3 (HDF5) file",
            "signature",
        ],
    );

    let mut cut = mat_file(false, 50);
    cut.truncate(cut.len() - 100);
    let path = write_file(dir.path(), "cut.mat", &cut);
    assert_contains(&err(&mat_plan(&path)), &["cut.mat", "cut short", "remain"]);

    let path = write_file(dir.path(), "bare.mat", &matw::header());
    assert_contains(
        &err(&mat_plan(&path)),
        &["bare.mat", "no data rows", "no variables"],
    );

    let mut file = matw::header();
    file.extend(matw::matrix("u", 3, 1, &[1.0, 2.0, 3.0]));
    file.extend(matw::matrix("data", 2, 2, &[1.0, 2.0, 3.0, 4.0]));
    let path = write_file(dir.path(), "short.mat", &file);
    let mut p = mat_plan(&path);
    p.channels.force = None;
    // No `t` or `time` for FromLog.
    assert_contains(&err(&p), &["short.mat", "no vector variable `t` or `time`"]);
    p.channels.time = TimePlan::SampleRate { hz: 10.0 };
    // u has 3 samples, data:1 has 2.
    assert_contains(&err(&p), &["short.mat", "command 3", "displacement 2"]);

    // Text where a channel is asked for, stored plainly and compressed,
    // with a name in a small element (`x`) and in a normal one: named as
    // text, not as missing (the MAT reader passes char arrays over).
    for compress in [false, true] {
        for name in ["x", "displacement"] {
            let mut file = matw::header();
            let text = matw::char_array(name, "4 mm chirp");
            file.extend(matw::matrix("u", 3, 1, &[1.0, 2.0, 3.0]));
            file.extend(if compress {
                matw::compressed(&text)
            } else {
                text
            });
            let path = write_file(dir.path(), "text.mat", &file);
            let mut p = mat_plan(&path);
            p.channels.force = None;
            p.channels.time = TimePlan::SampleRate { hz: 10.0 };
            p.channels.displacement.column = Column::Name(name.into());
            assert_contains(
                &err(&p),
                &[
                    "text.mat",
                    &format!("`{name}`"),
                    "is a MATLAB char array (text)",
                ],
            );
        }
    }
}

// ------------------------------------------------------------ bad files

#[test]
fn empty_and_header_only_files_are_refused() {
    let dir = tempfile::tempdir().unwrap();
    let path = write_file(dir.path(), "empty.csv", b"");
    assert_contains(
        &err(&plan_by_name(&path, LogFormat::Csv)),
        &["empty.csv", "empty"],
    );
    let path = write_file(dir.path(), "blank.txt", b"\r\n\n");
    let msg = err(&daq_plan(&path));
    assert_contains(&msg, &["blank.txt", "empty"]);

    let path = write_file(dir.path(), "head.csv", b"t,u,x,f\n");
    assert_contains(
        &err(&plan_by_name(&path, LogFormat::Csv)),
        &["head.csv", "no data rows", "header at line 1"],
    );
    let path = write_file(dir.path(), "comments.csv", b"# only\n# comments\n");
    let mut p = plan_by_name(&path, LogFormat::Csv);
    p.csv.comment_prefix = Some("#".into());
    assert_contains(&err(&p), &["comments.csv", "no data rows"]);

    let daq_head = "Header Size:  7\r\nVersion:  2\r\nSampling Interval:  0.001\r\nSampling Rate:  1000\r\nSample Count:  0\r\nDevice Serial Number:  0\r\nSample Number, Date/Time, CHANNEL0, CHANNEL1, CHANNEL2, Events\r\n";
    let path = write_file(dir.path(), "head.txt", daq_head.as_bytes());
    assert_contains(
        &err(&daq_plan(&path)),
        &["head.txt", "no data rows", "line 7"],
    );

    let path = dir.path().join("empty.parquet");
    write_parquet(&path, &[("t", &[][..]), ("u", &[]), ("x", &[]), ("f", &[])]).unwrap();
    assert_contains(
        &err(&plan_by_name(&path, LogFormat::Parquet)),
        &["empty.parquet", "no data rows"],
    );
}

#[test]
fn sha256_mismatch_names_both_hashes() {
    let dir = tempfile::tempdir().unwrap();
    let path = write_file(dir.path(), "log.csv", b"t,u,x,f\n0,1,2,3\n1,1,2,3\n");
    let mut p = plan_by_name(&path, LogFormat::Csv);
    let actual = read_log(&p).unwrap().sha256;
    let wrong = "0".repeat(64);
    p.sha256 = Some(wrong.clone());
    let msg = err(&p);
    assert_contains(&msg, &["log.csv", &wrong, &actual]);
    p.sha256 = Some(actual.to_ascii_uppercase());
    assert!(read_log(&p).is_ok());
    // The digest itself: SHA-256 of "abc" (FIPS 180-2, appendix B.1).
    assert_eq!(
        sha256_hex(b"abc"),
        "ba7816bf8f01cfea414140de5dae2223b00361a396177a9cb410ff61f20015ad"
    );
}

#[test]
fn csv_bad_values_name_line_and_column() {
    let dir = tempfile::tempdir().unwrap();
    // 1500 rows: the bad value lies beyond polars' schema-inference window.
    let mut text = String::from("t,u,x,f\n");
    for k in 0..1500 {
        let x = if k == 1200 {
            "abc".to_string()
        } else {
            format!("{}", k as f64 * 0.5)
        };
        text.push_str(&format!("{},{},{x},1\n", k as f64 * 1e-3, (k % 7) as f64));
    }
    let path = write_file(dir.path(), "bad.csv", text.as_bytes());
    // Row k sits on line k + 2.
    assert_contains(
        &err(&plan_by_name(&path, LogFormat::Csv)),
        &["bad.csv", "line 1202", "\"abc\"", "displacement", "`x`"],
    );

    let path = write_file(
        dir.path(),
        "hole.csv",
        b"t,u,x,f\n0,1,2,3\n1,,2,3\n2,1,2,3\n",
    );
    assert_contains(
        &err(&plan_by_name(&path, LogFormat::Csv)),
        &[
            "hole.csv",
            "line 3",
            "missing value",
            "command",
            "field 1 is empty",
        ],
    );

    let path = write_file(dir.path(), "cols.csv", b"t,u,x\n0,1,2\n");
    assert_contains(
        &err(&plan_by_name(&path, LogFormat::Csv)),
        &["cols.csv", "force", "`f`", "`t`, `u`, `x`"],
    );
}

#[test]
fn nan_and_infinite_values_name_channel_and_place() {
    let dir = tempfile::tempdir().unwrap();
    // Comment and blank lines before the bad row must be counted.
    let text = "t,u,x,f\n# c\n0,1,2,3\n\n1,1,2,3\n# c\n2,1,NaN,3\n3,1,2,3\n";
    let path = write_file(dir.path(), "nan.csv", text.as_bytes());
    let mut p = plan_by_name(&path, LogFormat::Csv);
    p.csv.comment_prefix = Some("#".into());
    assert_contains(
        &err(&p),
        &["nan.csv", "line 7", "displacement", "`x`", "NaN"],
    );

    let path = dir.path().join("inf.parquet");
    let f = [3.0, 3.0, f64::INFINITY, 3.0];
    write_parquet(
        &path,
        &[
            ("t", &[0.0, 1.0, 2.0, 3.0][..]),
            ("u", &[1.0; 4]),
            ("x", &[2.0; 4]),
            ("f", &f),
        ],
    )
    .unwrap();
    assert_contains(
        &err(&plan_by_name(&path, LogFormat::Parquet)),
        &["inf.parquet", "row 3", "force", "`f`", "inf"],
    );
}

#[test]
fn time_that_does_not_increase_names_the_row() {
    let dir = tempfile::tempdir().unwrap();
    let path = write_file(
        dir.path(),
        "back.csv",
        b"t,u,x,f\n0,1,2,3\n1,1,2,3\n3,1,2,3\n2,1,2,3\n",
    );
    assert_contains(
        &err(&plan_by_name(&path, LogFormat::Csv)),
        &["back.csv", "line 5", "2 s after 3 s", "goes back"],
    );
    let path = write_file(
        dir.path(),
        "same.csv",
        b"t,u,x,f\n0,1,2,3\n1,1,2,3\n1,1,2,3\n",
    );
    assert_contains(
        &err(&plan_by_name(&path, LogFormat::Csv)),
        &["same.csv", "line 4"],
    );
}

/// A CSV log of `n` samples at 1 kHz with time stamps perturbed by `jitter`.
fn jittered(dir: &Path, n: usize, jitter: impl Fn(usize) -> f64) -> LogPlan {
    let t: Vec<f64> = (0..n).map(|k| k as f64 * 1e-3 + jitter(k)).collect();
    let u = lcg(5, n);
    let path = dir.join("jitter.csv");
    write_csv(&path, &[("t", &t[..]), ("u", &u), ("x", &u), ("f", &u)]).unwrap();
    plan_by_name(&path, LogFormat::Csv)
}

/// Time stamps against the uniform grid fitted to them: scattered by a
/// DAQ's late stamping, rounded to a coarser resolution than the interval,
/// missing a sample, drifting, repeated. Each is taken or refused as the
/// samples it implies are uniform or not.
#[test]
fn time_stamps_are_read_against_a_uniform_grid() {
    let dir = tempfile::tempdir().unwrap();
    let n = 2000;
    let timing = |p: &LogPlan| match read_log(p).unwrap().timing {
        Timing::Measured {
            mean_dt_s, stamps, ..
        } => (mean_dt_s, stamps),
        Timing::Exact { .. } => panic!("a time column gives measured timing"),
    };

    // Each stamp late by up to 5 % of the interval (uniform in [0, 5e-5)):
    // the samples are uniform, and the grid's interval is the clock's to a
    // part in 1e6; a warning says how far the stamps scatter.
    let late = lcg(9, n);
    let p = jittered(dir.path(), n, |k| 2.5e-5 * (1.0 + late[k]));
    let (dt, stamps) = timing(&p);
    assert!((dt / 1e-3 - 1.0).abs() < 1e-6, "{dt}");
    let Stamps::Scattered { max_s, .. } = stamps else {
        panic!("{stamps:?}")
    };
    // Half the 5e-5 spread about the fitted grid, within a tenth (the
    // fitted offset and slope move with the draws).
    assert!((max_s / 2.5e-5 - 1.0).abs() < 0.1, "{max_s}");
    let warnings = check_log(&read_log(&p).unwrap(), &NEEDS).unwrap();
    assert_eq!(warnings.len(), 1, "{warnings:?}");
    assert_contains(
        &warnings[0].detail,
        &["jitter.csv", "scatter", "sample_rate_hz"],
    );

    // 2048 Hz stamps rounded to 1 ms repeat some stamps and step 0, 1 ms:
    // within half a millisecond of the grid, the samples are uniform, and
    // nothing is said.
    let path = dir.path().join("rounded.csv");
    let t: Vec<f64> = (0..n)
        .map(|k| (k as f64 / 2048.0 * 1e3).round() * 1e-3)
        .collect();
    let u = lcg(5, n);
    write_csv(&path, &[("t", &t[..]), ("u", &u), ("x", &u), ("f", &u)]).unwrap();
    let p = plan_by_name(&path, LogFormat::Csv);
    let (dt, stamps) = timing(&p);
    assert!((dt * 2048.0 - 1.0).abs() < 1e-5, "{dt}");
    let Stamps::Rounded { resolution_s } = stamps else {
        panic!("{stamps:?}")
    };
    assert_relative_eq!(resolution_s, 1e-3, max_relative = 1e-9);
    assert!(
        check_log(&read_log(&p).unwrap(), &NEEDS)
            .unwrap()
            .is_empty()
    );

    // One sample missing: an interval twice the others, off any grid by
    // half an interval; refused, with the advice to state the rate.
    let p = jittered(dir.path(), n, |k| if k >= 1000 { 1e-3 } else { 0.0 });
    assert_eq!(timing(&p).1, Stamps::Uneven);
    let msg = check_log(&read_log(&p).unwrap(), &NEEDS)
        .unwrap_err()
        .to_string();
    assert_contains(
        &msg,
        &["jitter.csv", "line 1002", "not uniform", "sample_rate_hz"],
    );

    // A clock drifting by 2 % over the record: intervals within the 1 %
    // tolerance of their mean, stamps 2.5 intervals off the straight line
    // at the middle: read at the mean interval, with the old warning.
    let p = jittered(dir.path(), n, |k| {
        let x = k as f64 / (n - 1) as f64;
        0.02 * 1e-3 * (n as f64) * x * x / 2.0
    });
    let (_, stamps) = timing(&p);
    assert_eq!(stamps, Stamps::Uneven);
    let warnings = check_log(&read_log(&p).unwrap(), &NEEDS).unwrap();
    assert_eq!(warnings.len(), 1, "{warnings:?}");
    assert_contains(&warnings[0].detail, &["jitter.csv", "uneven"]);

    // Time stamps k * 1e-3 printed shortest-round-trip carry only rounding.
    let p = jittered(dir.path(), n, |_| 0.0);
    assert_eq!(timing(&p).1, Stamps::Exact);
    assert!(
        check_log(&read_log(&p).unwrap(), &NEEDS)
            .unwrap()
            .is_empty()
    );
}

/// Time that goes back is two recordings in one file, or two stamps out of
/// order; the message tells which.
#[test]
fn time_that_goes_back_is_a_reset_or_a_swap() {
    let dir = tempfile::tempdir().unwrap();
    let n = 100;
    let p = jittered(dir.path(), n, |k| if k >= 60 { -0.06 } else { 0.0 });
    assert_contains(
        &err(&p),
        &[
            "jitter.csv",
            "line 62",
            "goes back",
            "two recordings in one file",
        ],
    );
    let p = jittered(dir.path(), n, |k| match k {
        40 => 1e-3,
        41 => -1e-3,
        _ => 0.0,
    });
    assert_contains(
        &err(&p),
        &[
            "jitter.csv",
            "line 43",
            "goes back",
            "two stamps out of order",
        ],
    );
}

#[test]
fn clipped_channel_names_channel_level_and_fraction() {
    let dir = tempfile::tempdir().unwrap();
    let n = 2000;
    let t: Vec<f64> = (0..n).map(|k| k as f64 * 1e-3).collect();
    let u: Vec<f64> = (0..n).map(|k| (k as f64 * 0.05).sin()).collect();
    // x saturates at 0.5 wherever the sine exceeds it: a third of the time
    // (sin > 0.5 on (pi/6, 5 pi/6) of each period).
    let x: Vec<f64> = u.iter().map(|v| v.min(0.5)).collect();
    let path = dir.path().join("clip.csv");
    write_csv(&path, &[("t", &t[..]), ("u", &u), ("x", &x), ("f", &u)]).unwrap();
    let log = read_log(&plan_by_name(&path, LogFormat::Csv)).unwrap();
    let msg = check_log(&log, &NEEDS).unwrap_err().to_string();
    let at_rail = x.iter().filter(|v| **v >= 0.5).count() as f64 / n as f64;
    assert_relative_eq!(at_rail, 1.0 / 3.0, epsilon = 0.01);
    assert_contains(
        &msg,
        &[
            "clip.csv",
            "displacement",
            "maximum 5e-1 m",
            &format!("{:.2} %", 100.0 * at_rail),
        ],
    );
}

#[test]
fn too_short_for_the_frf_settings() {
    let dir = tempfile::tempdir().unwrap();
    let p = jittered(dir.path(), 500, |_| 0.0);
    let msg = check_log(&read_log(&p).unwrap(), &NEEDS)
        .unwrap_err()
        .to_string();
    assert_contains(&msg, &["jitter.csv", "500 samples", "at least 1024"]);
}

const DAQ_HEAD: &str = "Header Size:  7\r\nVersion:  2\r\nSampling Interval:  0.001\r\nSampling Rate:  1000\r\nSample Count:  4\r\nDevice Serial Number:  0\r\nSample Number, Date/Time, CHANNEL0, CHANNEL1, CHANNEL2, Events\r\n";

fn daq_line(k: usize, c2: &str) -> String {
    format!("{k:>10},   06/29/2022 04:05:36.674 PM, -0.0209, -0.0166, {c2}\r\n")
}

#[test]
fn daq_malformed_lines_are_named() {
    let dir = tempfile::tempdir().unwrap();
    let body = |lines: &[String]| format!("{DAQ_HEAD}{}", lines.concat());
    let ok = [
        daq_line(1, "0.1, DAQ Start"),
        daq_line(2, "0.2"),
        daq_line(3, "0.3"),
        daq_line(4, "0.4, DAQ Pause, DAQ Stop"),
    ];
    let path = write_file(dir.path(), "ok.txt", body(&ok).as_bytes());
    let log = read_log(&daq_plan(&path)).unwrap();
    assert_eq!(log.n_rows, 4);
    assert_relative_eq!(log.command_m[3], 0.4 * 1e-2, max_relative = 1e-15);

    let mut bad = ok.clone();
    bad[2] = daq_line(3, "0.3x");
    let path = write_file(dir.path(), "bad.txt", body(&bad).as_bytes());
    assert_contains(
        &err(&daq_plan(&path)),
        &["bad.txt", "line 10", "\"0.3x\"", "command", "`CHANNEL2`"],
    );

    let mut gap = ok.clone();
    gap[2] = daq_line(5, "0.3");
    let path = write_file(dir.path(), "gap.txt", body(&gap).as_bytes());
    assert_contains(
        &err(&daq_plan(&path)),
        &["gap.txt", "line 10", "5 follows 2"],
    );

    let mut short = ok.clone();
    short[1] = "         2,   06/29/2022 04:05:36.675 PM, -0.0221\r\n".into();
    let path = write_file(dir.path(), "short.txt", body(&short).as_bytes());
    assert_contains(
        &err(&daq_plan(&path)),
        &[
            "short.txt",
            "line 9",
            "missing value",
            "command",
            "3 fields",
        ],
    );

    let mut nan = ok.clone();
    nan[3] = daq_line(4, "nan");
    let path = write_file(dir.path(), "nan.txt", body(&nan).as_bytes());
    assert_contains(
        &err(&daq_plan(&path)),
        &["nan.txt", "line 11", "command", "NaN"],
    );

    let mut p = daq_plan(&path);
    p.channels.command.column = name("CHANNEL9");
    assert_contains(
        &err(&p),
        &["nan.txt", "`CHANNEL9`", "`CHANNEL2`", "`Events`"],
    );
    p.channels.command.column = name("Date/Time");
    assert_contains(&err(&p), &["nan.txt", "`Date/Time`", "text"]);

    // A header without a rate: FromLog cannot work.
    let norate = body(&ok).replace("Sampling Interval:  0.001\r\nSampling Rate:  1000\r\n", "");
    let path = write_file(dir.path(), "norate.txt", norate.as_bytes());
    assert_contains(
        &err(&daq_plan(&path)),
        &["norate.txt", "Sampling Rate", "sample_rate_hz"],
    );
}

#[test]
fn daq_header_disagreements_are_warnings() {
    let dir = tempfile::tempdir().unwrap();
    let text = DAQ_HEAD
        .replace("Sample Count:  4", "Sample Count:  6")
        .to_string()
        + &daq_line(1, "0.1")
        + &daq_line(2, "0.2")
        + "\r\n"
        + &daq_line(3, "0.3")
        + &daq_line(4, "nan");
    let path = write_file(dir.path(), "warn.txt", text.as_bytes());
    // The blank line 10 is skipped and counted: the NaN is on line 12.
    assert_contains(&err(&daq_plan(&path)), &["warn.txt", "line 12", "NaN"]);
    let text = text.replace("nan", "0.4");
    let path = write_file(dir.path(), "warn.txt", text.as_bytes());
    let log = read_log(&daq_plan(&path)).unwrap();
    assert_eq!(log.warnings.len(), 1);
    assert_contains(
        &log.warnings[0].detail,
        &["warn.txt", "Sample Count: 6", "4 data lines", "truncated"],
    );
}

// ------------------------------------------------------- preparation

fn log_with_command(u: Vec<f64>, fs: f64) -> Log {
    let n = u.len();
    Log {
        path: "mem.csv".into(),
        sha256: String::new(),
        format: LogFormat::Csv,
        sample_rate_hz: fs,
        t0_s: 10.0,
        displacement_m: (0..n).map(|k| k as f64).collect(),
        force_n: Some((0..n).map(|k| -(k as f64)).collect()),
        command_m: u,
        n_rows: n,
        timing: Timing::Exact { dt_s: 1.0 / fs },
        warnings: Vec::new(),
        repairs: Vec::new(),
    }
}

#[test]
fn trim_keeps_the_excitation_and_half_a_second_around_it() {
    // 1 kHz; rest (0) for 2 s, a +-1 square wave from sample 2000 to 4999,
    // rest again to 7 s: excited samples 2000..=4999, margin 500 samples.
    let u: Vec<f64> = (0..7000)
        .map(|k| {
            if (2000..5000).contains(&k) {
                if k % 2 == 0 { 1.0 } else { -1.0 }
            } else {
                0.0
            }
        })
        .collect();
    let log = log_with_command(u, 1000.0);
    let cut = trim_to_excitation(&log, 0.05);
    assert_eq!(cut.n_rows, 4000);
    assert_eq!(cut.command_m.len(), 4000);
    assert_relative_eq!(cut.t0_s, 10.0 + 1.5, max_relative = 1e-12);
    assert_relative_eq!(cut.displacement_m[0], 1500.0);
    assert_relative_eq!(cut.force_n.as_ref().unwrap()[3999], -5499.0);
    assert!(cut.warnings.is_empty());

    // Excitation near the ends: the margin is clamped to the log.
    let u: Vec<f64> = (0..1000).map(|k| if k < 900 { 1.0 } else { 0.0 }).collect();
    // Rest level = mean of the first 0.1 s = 1; excited where |u - 1| > 0.05.
    let cut = trim_to_excitation(&log_with_command(u, 1000.0), 0.05);
    assert_eq!(cut.n_rows, 1000 - 400);
    assert_relative_eq!(cut.t0_s, 10.4, max_relative = 1e-12);

    let flat = trim_to_excitation(&log_with_command(vec![0.25; 100], 1000.0), 0.05);
    assert_eq!(flat.n_rows, 100);
    assert_contains(&flat.warnings[0].detail, &["mem.csv", "never departs"]);
}

// ------------------------------------------- format errors, word for word

/// Asserts that reading `plan` fails with exactly `text` after the file's
/// path: results.json carries these messages, so their wording is pinned.
fn assert_refused(plan: &LogPlan, text: &str) {
    assert_eq!(err(plan), format!("{}: {text}", plan.path.display()));
}

#[test]
fn table_logs_have_no_rate_of_their_own() {
    let dir = tempfile::tempdir().unwrap();
    let path = write_file(dir.path(), "log.csv", b"t,u,x,f\n0,1,2,3\n1,1,2,3\n");
    let mut p = plan_by_name(&path, LogFormat::Csv);
    p.channels.time = TimePlan::FromLog;
    assert_refused(
        &p,
        "a CSV log has no sampling rate of its own; give channels.time.column or channels.time.sample_rate_hz",
    );

    let path = dir.path().join("log.parquet");
    write_parquet(&path, &borrowed(&table(10))).unwrap();
    let mut p = plan_by_name(&path, LogFormat::Parquet);
    p.channels.time = TimePlan::FromLog;
    assert_refused(
        &p,
        "a Parquet log has no sampling rate of its own; give channels.time.column or channels.time.sample_rate_hz",
    );
}

#[test]
fn csv_format_errors_word_for_word() {
    let dir = tempfile::tempdir().unwrap();
    let path = write_file(dir.path(), "log.csv", b"t,u,x,u,f\n0,1,2,1,3\n1,1,2,1,3\n");
    let mut p = plan_by_name(&path, LogFormat::Csv);
    assert_refused(
        &p,
        "column `u` (command channel) appears 2 times in the header (fields 1, 3); rename one or address it by index",
    );
    p.csv.delimiter = ";;".into();
    assert_refused(
        &p,
        "the CSV delimiter must be one ASCII character (got \";;\")",
    );
}

#[test]
fn daq_format_errors_word_for_word() {
    let dir = tempfile::tempdir().unwrap();
    let body = format!("{DAQ_HEAD}{}{}", daq_line(1, "0.1"), daq_line(2, "0.2"));
    let bad_rate = body.replace("Sampling Rate:  1000", "Sampling Rate:  fast");
    let path = write_file(dir.path(), "rate.txt", bad_rate.as_bytes());
    assert_refused(
        &daq_plan(&path),
        "line 4: header `Sampling Rate` is \"fast\", not a positive number",
    );
    let bad_size = body.replace("Header Size:  7", "Header Size:  -7");
    let path = write_file(dir.path(), "size.txt", bad_size.as_bytes());
    assert_refused(
        &daq_plan(&path),
        "line 1: header `Header Size` is \"-7\", not a positive number",
    );

    let path = write_file(dir.path(), "ok.txt", body.as_bytes());
    let mut p = daq_plan(&path);
    p.channels.displacement.column = Column::Index(5);
    assert_refused(
        &p,
        "column `Events` (index 5, displacement channel) holds text, not numbers",
    );

    let norate = body.replace("Sampling Interval:  0.001\r\nSampling Rate:  1000\r\n", "");
    let path = write_file(dir.path(), "norate.txt", norate.as_bytes());
    assert_refused(
        &daq_plan(&path),
        "no `Sampling Rate` or `Sampling Interval` in the header; give channels.time.sample_rate_hz",
    );
}

#[test]
fn mat_format_errors_word_for_word() {
    let dir = tempfile::tempdir().unwrap();
    let mut v73 = b"MATLAB 7.3 MAT-file, Platform: GLNXA64".to_vec();
    v73.resize(512, 0);
    let path = write_file(dir.path(), "v73.mat", &v73);
    assert_refused(
        &mat_plan(&path),
        "not a readable MAT v7.3 (HDF5) file (HDF5 format error: HDF5 signature not found at any valid offset)",
    );
    let path = write_file(dir.path(), "text.mat", &[b'x'; 200]);
    assert_refused(
        &mat_plan(&path),
        "this is a text file, not a level-5 or v7.3 MAT-file: a delimited log is read named `.csv` or `.tsv`, a DAQ text export `.txt`",
    );
    // Dimensions whose product overflows MATLAB's 32-bit count (fuzzing
    // found matfile multiplying them in i32).
    let mut body = matw::element(
        matw::MI_UINT32,
        &[matw::MX_DOUBLE_CLASS.to_le_bytes(), 0u32.to_le_bytes()].concat(),
    );
    let dims: Vec<u8> = [1i32 << 30, 4]
        .iter()
        .flat_map(|d| d.to_le_bytes())
        .collect();
    body.extend(matw::element(matw::MI_INT32, &dims));
    body.extend(matw::element(matw::MI_INT8, b"big"));
    body.extend(matw::element(matw::MI_DOUBLE, &[]));
    let mut file = matw::header();
    file.extend(matw::element(matw::MI_MATRIX, &body));
    let path = write_file(dir.path(), "big.mat", &file);
    assert_refused(
        &mat_plan(&path),
        "variable `big` declares dimensions [1073741824, 4], more values than a MAT-file holds (the file is damaged)",
    );
    // A top-level element that is not a variable (matfile would print it
    // to stdout and pass over it).
    let mut file = matw::header();
    file.extend(matw::element(matw::MI_DOUBLE, &1.5f64.to_le_bytes()));
    let path = write_file(dir.path(), "loose.mat", &file);
    assert_refused(
        &mat_plan(&path),
        "the element at byte 128 is of MAT type 9, not a variable (miMATRIX or miCOMPRESSED): the file is damaged",
    );
    let path = write_file(dir.path(), "noise.mat", &[0xA5; 200]);
    assert_refused(
        &mat_plan(&path),
        "not a level-5 MAT-file (no 128-byte header ending in the `IM`/`MI` endian mark)",
    );

    // Version 2 in the header: matfile refuses it.
    let mut file = matw::header();
    file[124..126].copy_from_slice(&0x0200u16.to_le_bytes());
    file.extend(matw::matrix("u", 3, 1, &[1.0, 2.0, 3.0]));
    let path = write_file(dir.path(), "version.mat", &file);
    let e = matfile::MatFile::parse(&file[..]).unwrap_err();
    assert_refused(
        &mat_plan(&path),
        &format!("not a readable level-5 MAT-file (matfile: {e})"),
    );

    // Cut inside the first tag, and inside the first element's data.
    let mut file = matw::header();
    file.extend([0u8; 4]);
    let path = write_file(dir.path(), "tag.mat", &file);
    assert_refused(
        &mat_plan(&path),
        "the MAT-file is cut short: the data element at byte 128 needs an 8-byte tag and data bytes but 4 remain",
    );
    let mut file = matw::header();
    file.extend(matw::MI_MATRIX.to_le_bytes());
    file.extend(100u32.to_le_bytes());
    file.extend([0u8; 8]);
    let path = write_file(dir.path(), "data.mat", &file);
    assert_refused(
        &mat_plan(&path),
        "the MAT-file is cut short: the data element at byte 128 needs 108 bytes but 16 remain",
    );

    // Addressing: tables, vectors and the time base.
    let path = write_file(dir.path(), "log.mat", &mat_file(false, 5));
    assert_refused(
        &mat_plan(&path),
        "the force channel is column #2, but several variables are 2-D tables (`data`, `sim`); write it as \"variable:2\"",
    );
    let mut p = mat_plan(&path);
    p.channels.force = None;
    p.channels.command.column = name("data");
    assert_refused(
        &p,
        "variable `data` (command channel) is 5x3, not a vector; address one of its channels as \"data:0\"",
    );

    let mut file = matw::header();
    file.extend(matw::matrix("u", 3, 1, &[1.0, 2.0, 3.0]));
    file.extend(matw::matrix("x", 1, 3, &[1.0, 2.0, 3.0]));
    let path = write_file(dir.path(), "vectors.mat", &file);
    let mut p = mat_plan(&path);
    p.channels.displacement.column = Column::Index(1);
    assert_refused(
        &p,
        "the displacement channel is column #1, but no variable is a 2-D table (variables: `u` (3x1), `x` (1x3)); name a vector variable instead",
    );
    p.channels.displacement.column = name("x");
    p.channels.force = None;
    assert_refused(
        &p,
        "no time base: no vector variable `t` or `time` (variables: `u` (3x1), `x` (1x3)); give channels.time.column or sample_rate_hz",
    );

    let mut file = matw::header();
    file.extend(matw::matrix("t", 4, 1, &[0.0, 1.0, 2.0, 3.0]));
    file.extend(matw::matrix("u", 3, 1, &[1.0, 2.0, 3.0]));
    file.extend(matw::matrix("data", 2, 2, &[1.0, 2.0, 3.0, 4.0]));
    file.extend(matw::array("cube", &[2, 2, 2], &[0.0; 8], None));
    file.extend(matw::array("z", &[3, 1], &[1.0; 3], Some(&[0.5; 3])));
    let path = write_file(dir.path(), "short.mat", &file);
    let mut p = mat_plan(&path);
    p.channels.force = None;
    assert_refused(
        &p,
        "the channels differ in length: time 4, command 3, displacement 2",
    );
    p.channels.time = TimePlan::SampleRate { hz: 10.0 };
    assert_refused(
        &p,
        "the channels differ in length: command 3, displacement 2",
    );
    p.channels.displacement.column = name("cube:0");
    assert_refused(
        &p,
        "variable `cube` (displacement channel) is 2x2x2, not a 2-D table",
    );
    p.channels.displacement.column = name("z");
    assert_refused(
        &p,
        "variable `z` (displacement channel) is complex; a log channel must be real",
    );
}

#[test]
fn parquet_format_errors_word_for_word() {
    use polars::prelude::{DataFrame, DataType, ParquetReader, ParquetWriter, SerReader};

    let dir = tempfile::tempdir().unwrap();
    let junk = b"PAR1 but not a Parquet file".to_vec();
    let path = write_file(dir.path(), "junk.parquet", &junk);
    let e = ParquetReader::new(std::io::Cursor::new(&junk))
        .schema()
        .unwrap_err();
    assert_refused(
        &plan_by_name(&path, LogFormat::Parquet),
        &format!("not a readable Parquet file: {e}"),
    );

    // A readable schema, but the first page header (right after the magic
    // `PAR1`) is corrupt: its first byte, a field header, now declares
    // thrift type 15, which the compact protocol does not have.
    let path = dir.path().join("pages.parquet");
    write_parquet(&path, &borrowed(&table(50))).unwrap();
    let mut bytes = std::fs::read(&path).unwrap();
    bytes[4] = 0xff;
    std::fs::write(&path, &bytes).unwrap();
    assert_refused(
        &plan_by_name(&path, LogFormat::Parquet),
        "a damaged Parquet file: row group 0, column 0: the page header at byte 0 of its chunk does not read: bad data",
    );

    let cols = vec![
        polars::prelude::Column::new("t".into(), &[0.0, 1.0]),
        polars::prelude::Column::new("u".into(), &["a", "b"]),
        polars::prelude::Column::new("x".into(), &[2.0, 2.0]),
    ];
    let mut df = DataFrame::new(2, cols).unwrap();
    let mut bytes = Vec::new();
    ParquetWriter::new(&mut bytes).finish(&mut df).unwrap();
    let path = write_file(dir.path(), "text.parquet", &bytes);
    let mut p = plan_by_name(&path, LogFormat::Parquet);
    p.channels.force = None;
    assert_refused(
        &p,
        &format!(
            "column `u` (command channel) holds {}, not numbers",
            DataType::String
        ),
    );
}

#[test]
fn format_errors_keep_their_causes_typed() {
    // Causes no crafted file reaches: polars losing a column it has just
    // read, or failing to cast a numeric column to f64.
    let polars = || PolarsError::ComputeError("no such luck".into());
    let lost = FormatProblem::ColumnLost {
        column: "u".into(),
        source: polars(),
    };
    assert_eq!(
        lost.to_string(),
        format!("column `u` lost in reading: {}", polars())
    );
    let cast = FormatProblem::NotF64 {
        column: "u".into(),
        source: polars(),
    };
    assert_eq!(
        cast.to_string(),
        format!("column `u` cannot become f64: {}", polars())
    );

    // A foreign error is the problem's source, and the problem the error's.
    let dir = tempfile::tempdir().unwrap();
    let mut file = matw::header();
    file[124..126].copy_from_slice(&0x0200u16.to_le_bytes());
    file.extend(matw::matrix("u", 3, 1, &[1.0, 2.0, 3.0]));
    let path = write_file(dir.path(), "version.mat", &file);
    let e = read_log(&mat_plan(&path)).unwrap_err();
    let problem = std::error::Error::source(&e)
        .and_then(|s| s.downcast_ref::<FormatProblem>())
        .expect("the problem is the source");
    assert!(matches!(problem, FormatProblem::MatUnreadable { .. }));
    let cause = std::error::Error::source(problem).expect("matfile's error is kept");
    assert!(cause.is::<matfile::Error>());
}

// ------------------------------------------- files that cannot be read whole

#[test]
fn a_log_that_changes_during_its_read_is_refused_naming_the_file() {
    let path = Path::new("logs/exp1.csv");
    let stamp = |size, modified_ns| Some(FileStamp { size, modified_ns });
    // Unchanged, and the size what was read: accepted.
    assert!(unchanged(path, stamp(100, 7), stamp(100, 7), 100).is_ok());
    // A writer appended during the read: the size and time moved.
    let e = unchanged(path, stamp(100, 7), stamp(180, 9), 140).unwrap_err();
    assert!(matches!(e, IngestError::Changed { .. }), "{e:?}");
    let msg = e.to_string();
    assert!(
        msg.starts_with("logs/exp1.csv: changed while it was read"),
        "{msg}"
    );
    assert!(
        msg.contains("100 bytes") && msg.contains("180 bytes"),
        "{msg}"
    );
    // Rewritten in place within one time stamp: the length read differs.
    let msg = unchanged(path, stamp(100, 7), stamp(100, 7), 60)
        .unwrap_err()
        .to_string();
    assert!(msg.contains("60 bytes read"), "{msg}");
    // Removed during the read.
    let msg = unchanged(path, stamp(100, 7), None, 100)
        .unwrap_err()
        .to_string();
    assert!(msg.contains("gone"), "{msg}");
}

#[test]
fn a_folder_or_a_named_pipe_is_not_read_as_a_log() {
    let dir = tempfile::tempdir().unwrap();
    let folder = dir.path().join("exp1.csv");
    std::fs::create_dir(&folder).unwrap();
    let e = LogFile::read(&folder, u64::MAX).unwrap_err();
    assert!(
        matches!(
            e,
            IngestError::NotAFile {
                what: "a folder",
                ..
            }
        ),
        "{e:?}"
    );
    assert!(e.to_string().contains("exp1.csv: is a folder"), "{e}");

    // A FIFO would block a read until a writer came: refused at once.
    let fifo = dir.path().join("exp2.csv");
    let made = std::process::Command::new("mkfifo").arg(&fifo).status();
    if made.is_ok_and(|s| s.success()) {
        let e = LogFile::read(&fifo, u64::MAX).unwrap_err();
        assert!(
            matches!(
                e,
                IngestError::NotAFile {
                    what: "a named pipe",
                    ..
                }
            ),
            "{e:?}"
        );
    }

    // A regular file is read, and its stamp kept for the cache.
    let file = dir.path().join("exp3.csv");
    std::fs::write(&file, b"t,u,y\n0,0,0\n").unwrap();
    let read = LogFile::read(&file, u64::MAX).unwrap();
    assert_eq!(read.stamp.map(|s| s.size), Some(12));
    assert_eq!(read.stamp, FileStamp::of(&file));
}

/// The Parquet footer check against footers built by hand from the thrift
/// compact protocol's definition: a list declaring 2^30 elements where
/// polars reads a list (FileMetaData field 2, the schema) in a footer with
/// no bytes left, and metadata longer than the file, are refused with what
/// they declare; the same list where polars reads an i32 (field 1, the
/// version) is polars' to refuse, and it does, without reserving it; a
/// struct with a short list of strings, and bytes without the Parquet
/// magic, pass (polars judges the latter).
#[test]
fn parquet_footers_that_declare_more_than_they_hold_are_refused() {
    fn file(meta: &[u8], declared_len: u32) -> Vec<u8> {
        let mut b = b"PAR1".to_vec();
        b.extend_from_slice(meta);
        b.extend_from_slice(&declared_len.to_le_bytes());
        b.extend_from_slice(b"PAR1");
        b
    }
    // Field `id` (a delta from 0), type 9 (list); list header 0xFC: size 15
    // (a varint follows), element type 12 (struct); then 2^30 as a varint
    // (polars reads the count as an i32).
    let huge = |id: u8| {
        let mut b = vec![(id << 4) | 0x09, 0xFC];
        let mut v: u64 = 1 << 30;
        while v >= 0x80 {
            b.push((v as u8 & 0x7f) | 0x80);
            v >>= 7;
        }
        b.push(v as u8);
        b
    };
    let schema = huge(2);
    let refused = super::parquet::check_footer(&file(&schema, schema.len() as u32)).unwrap_err();
    assert_eq!(
        refused.to_string(),
        "its footer declares 1073741824 schema elements where 0 bytes remain"
    );
    let version = huge(1);
    let bytes = file(&version, version.len() as u32);
    assert_eq!(super::parquet::check_footer(&bytes), Ok(()));
    use polars::prelude::SerReader as _;
    let mut reader = polars::prelude::ParquetReader::new(std::io::Cursor::new(&bytes[..]));
    assert!(
        !matches!(super::guard_reader(|| reader.schema()), Ok(Ok(_))),
        "polars read a footer whose version is a list"
    );
    assert_eq!(
        super::parquet::check_footer(&file(&[0x00], 1000)).map_err(|e| e.to_string()),
        Err("its footer declares 1000 bytes of metadata in a file of 13 bytes".into())
    );
    // Field 1: a list of two strings "ab", "c"; field 2 (delta 1): i32 5; stop.
    let good = [0x19, 0x28, 0x02, b'a', b'b', 0x01, b'c', 0x15, 0x0a, 0x00];
    assert_eq!(
        super::parquet::check_footer(&file(&good, good.len() as u32)),
        Ok(())
    );
    assert_eq!(super::parquet::check_footer(b"not parquet at all"), Ok(()));
}

/// The page check against a column chunk built by hand from parquet.thrift:
/// one data page of `page_values` values (a 17-byte header and 8 bytes of
/// data) in a chunk of 4 values. A negative count (polars read it as about
/// 2^64 and reserved 2^61 bytes), a count beyond the chunk's, a page longer
/// than the chunk and a chunk whose pages stop short are refused.
#[test]
fn parquet_pages_that_declare_impossible_counts_are_refused() {
    fn zigzag(v: i64) -> u8 {
        let z = ((v << 1) ^ (v >> 63)) as u64;
        assert!(z < 0x80, "one varint byte");
        z as u8
    }
    // PageHeader: 1 type = 0 (DATA_PAGE), 2 uncompressed = 8, 3 compressed
    // = `size`, 5 data_page_header { 1 num_values, 2-4 encodings = 0 }.
    fn chunk(page_values: i64, size: i64) -> Vec<u8> {
        let mut b = vec![0x15, 0x00, 0x15, 0x10, 0x15, zigzag(size), 0x2C, 0x15];
        b.push(zigzag(page_values));
        b.extend_from_slice(&[0x15, 0x00, 0x15, 0x00, 0x15, 0x00, 0x00, 0x00]);
        b.extend_from_slice(&[0; 8]);
        b
    }
    let pages = super::parquet::chunk_pages;
    assert_eq!(pages(&chunk(4, 8), 4), Ok(()));
    assert_eq!(
        pages(&chunk(-1, 8), 4).map_err(|e| e.to_string()),
        Err("a page at byte 0 of its chunk declares a count of -1 where its chunk has 4 values in 25 bytes".into())
    );
    assert_eq!(
        pages(&chunk(5, 8), 4).map_err(|e| e.to_string()),
        Err("a page at byte 0 of its chunk declares a count of 5 where its chunk has 4 values in 25 bytes".into())
    );
    assert_eq!(
        pages(&chunk(4, 9), 4).map_err(|e| e.to_string()),
        Err(
            "a page at byte 0 of its chunk declares 9 bytes (uncompressed 8) where 8 remain".into()
        )
    );
    assert_eq!(
        pages(&chunk(3, 8), 4).map_err(|e| e.to_string()),
        Err("its chunk ends after pages of 3 of its 4 values".into())
    );
}

// ------------------------------------------------- HDF5, MAT v7.3, TDMS

/// The fuzz seeds of the array formats, written by other tools (h5py,
/// hdf5storage in MATLAB's v7.3 layout, npTDMS) by
/// `fuzz/seeds/make_array_seeds.py`.
fn seed(target: &str, file: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("fuzz/corpus")
        .join(target)
        .join(file)
}

/// What the seed script wrote: 256 samples at 1 kHz of u, x (mm) and f (N),
/// in SI.
fn seed_signals() -> [Vec<f64>; 3] {
    let w = 2.0 * std::f64::consts::PI * 37.0;
    let t = |k: usize| k as f64 / 1000.0;
    [
        (0..256).map(|k| 2e-3 * (w * t(k)).sin()).collect(),
        (0..256).map(|k| 1.8e-3 * (w * t(k) - 0.3).sin()).collect(),
        (0..256).map(|k| 150.0 * (w * t(k) - 0.1).sin()).collect(),
    ]
}

fn assert_signals(log: &Log, what: &str) {
    let [u, x, f] = seed_signals();
    for (got, want, name) in [
        (&log.command_m, &u, "u"),
        (&log.displacement_m, &x, "x"),
        (log.force_n.as_ref().expect("force"), &f, "f"),
    ] {
        assert_eq!(got.len(), 256, "{what} {name}");
        for (g, w) in got.iter().zip(want) {
            // numpy's sine and Rust's may differ in the last bit.
            assert!(
                (g - w).abs() <= 1e-12 * w.abs().max(1e-3),
                "{what} {name}: {g} vs {w}"
            );
        }
    }
    assert_relative_eq!(log.sample_rate_hz, 1000.0, max_relative = 1e-12);
}

fn seed_plan(path: &Path, format: LogFormat, time: TimePlan, cols: [Column; 3]) -> LogPlan {
    let [u, x, f] = cols;
    plan(
        path,
        format,
        time,
        ch(u, Unit::Millimeter, 1.0),
        ch(x, Unit::Millimeter, 1.0),
        Some(ch(f, Unit::Newton, 1.0)),
    )
}

fn v73_plan(path: &Path) -> LogPlan {
    seed_plan(
        path,
        LogFormat::Mat,
        TimePlan::FromLog,
        [name("u"), name("log.x"), Column::Index(2)],
    )
}

fn hdf5_plan(path: &Path) -> LogPlan {
    let time = TimePlan::Column {
        column: name("t"),
        to_s: 1.0,
    };
    seed_plan(
        path,
        LogFormat::Hdf5,
        time,
        [name("u"), name("run/x"), name("table:2")],
    )
}

fn tdms_plan(path: &Path) -> LogPlan {
    seed_plan(
        path,
        LogFormat::Tdms,
        TimePlan::FromLog,
        [name("g/u"), name("g/x"), name("g/f")],
    )
}

/// Files other tools wrote read back to the values written: MATLAB's v7.3
/// layout (a struct's field `log.x`, a 256 x 3 matrix stored transposed,
/// the time base from `t`), h5py's (a dataset in a group, deflated; a
/// row-major 256 x 3 table), and NI's TDMS (the rate from `wf_increment`).
#[test]
fn hdf5_v73_and_tdms_files_of_other_tools_read_back() {
    let log = read_log(&v73_plan(&seed("log_mat_v73", "vectors.mat"))).unwrap();
    assert_signals(&log, "v7.3");
    let log = read_log(&hdf5_plan(&seed("log_hdf5", "datasets.h5"))).unwrap();
    assert_signals(&log, "HDF5");
    assert!(matches!(log.timing, Timing::Measured { .. }));
    let log = read_log(&tdms_plan(&seed("log_tdms", "waveforms.tdms"))).unwrap();
    assert_signals(&log, "TDMS");
    assert!(matches!(log.timing, Timing::Exact { .. }));
}

/// Damaged and cut files, channels that are not there and a unit the file
/// contradicts: each refused with a message naming the file and what to
/// do; an unknown unit is a warning.
#[test]
fn hdf5_v73_and_tdms_errors_name_the_file_and_the_channel() {
    let dir = tempfile::tempdir().unwrap();
    for (target, file, make) in [
        (
            "log_mat_v73",
            "vectors.mat",
            v73_plan as fn(&Path) -> LogPlan,
        ),
        ("log_hdf5", "datasets.h5", hdf5_plan),
        ("log_tdms", "waveforms.tdms", tdms_plan),
    ] {
        let bytes = std::fs::read(seed(target, file)).unwrap();
        let cut = write_file(
            dir.path(),
            &format!("cut-{file}"),
            &bytes[..bytes.len() / 2],
        );
        let msg = err(&make(&cut));
        assert!(msg.starts_with(&cut.display().to_string()), "{msg}");
        let mut damaged = bytes.clone();
        let mid = damaged.len() / 3;
        damaged[mid..mid + 64].fill(0xA5);
        let path = write_file(dir.path(), &format!("damaged-{file}"), &damaged);
        // Either refused or read: never a panic; refused, it names the file.
        if let Err(e) = read_log(&make(&path)) {
            assert!(
                e.to_string().starts_with(&path.display().to_string()),
                "{e}"
            );
        }
        let path = seed(target, file);
        let mut p = make(&path);
        p.channels.displacement.column = name("nope");
        assert_contains(&err(&p), &[file, "`nope`", "displacement", "variables: "]);
    }
    let path = seed("log_hdf5", "datasets.h5");
    let mut p = hdf5_plan(&path);
    p.channels.command = ch(name("u"), Unit::Meter, 1.0);
    assert_refused(
        &p,
        "variable `u` (command channel) is in \"mm\" by the file's own word, but the manifest says `m`; correct the manifest's unit (a wrong one scales every parameter)",
    );
    let path = seed("log_tdms", "waveforms.tdms");
    let mut p = tdms_plan(&path);
    p.channels.force = Some(ch(name("g/f"), Unit::Kilonewton, 1.0));
    assert_contains(&err(&p), &["`g/f`", "\"N\"", "`kN`"]);
    // A bare name is the one group's channel of that name; a name no
    // group holds lists the channels.
    let mut p = tdms_plan(&path);
    p.channels.time = TimePlan::SampleRate { hz: 1000.0 };
    let grouped = read_log(&p).unwrap();
    p.channels.command.column = name("u");
    assert_eq!(read_log(&p).unwrap().command_m, grouped.command_m);
    p.channels.command.column = name("v");
    assert_contains(&err(&p), &["`v`", "`g/u` (256x1)", "`g/x` (256x1)"]);
}

/// The soft-link pass leaves a file without old-style links byte for byte
/// (h5py's seed), and on one with links (h5py's default layout) removes
/// exactly those: the file then lists its datasets.
#[test]
fn soft_links_are_skipped_and_nothing_else_is_touched() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let plain = std::fs::read(root.join("fuzz/corpus/log_hdf5/datasets.h5")).unwrap();
    let mut copy = plain.clone();
    assert_eq!(super::hdf5::skip_v1_links(&mut copy), 0);
    assert!(copy == plain);
    let linked = std::fs::read(root.join("fuzz/corpus/log_hdf5/links_and_text.h5")).unwrap();
    let mut copy = linked.clone();
    // u_alias and gone at the root, latest in run/.
    assert_eq!(super::hdf5::skip_v1_links(&mut copy), 3);
    assert_eq!(copy.len(), linked.len());
}
