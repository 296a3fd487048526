//! The fuzz targets' bodies: each feeds arbitrary bytes to one of servoid's
//! readers, which must answer with a value or an error, never a panic.
//! Shared by the cargo-fuzz targets (`fuzz/fuzz_targets/`) and by the
//! stable replay of their corpus and crash inputs (`tests/fuzz_replay.rs`),
//! so CI needs no nightly toolchain.

use std::path::Path;

use servoid::ingest::{
    self, ChannelPlan, Channels, Column, CsvOptions, LogFile, LogFormat, LogPlan, TableFormat,
    TimePlan,
};
use servoid::units::Unit;

/// A target's body: whether the input read cleanly.
pub type Target = fn(&[u8]) -> bool;

/// Every target by name, each answering whether the input read cleanly
/// (the fuzzer ignores it; the replay checks that the seed corpus does), as `fuzz/fuzz_targets/<name>.rs` and the
/// folders `fuzz/corpus/<name>/` and `fuzz/regressions/<name>/` call them.
pub const TARGETS: &[(&str, Target)] = &[
    ("manifest_toml", manifest_toml),
    ("manifest_json", manifest_json),
    ("log_csv", log_csv),
    ("log_daq", log_daq),
    ("log_parquet", log_parquet),
    ("log_mat", log_mat),
    ("run_table_csv", run_table_csv),
    ("run_table_parquet", run_table_parquet),
];

/// Lets the panics `servoid::ingest` catches inside polars unwind to it:
/// libFuzzer's hook aborts on every panic, which would report a damaged
/// file that servoid handles as a crash. Every other panic still aborts.
pub fn let_caught_panics_unwind() {
    static ONCE: std::sync::Once = std::sync::Once::new();
    ONCE.call_once(|| {
        let next = std::panic::take_hook();
        std::panic::set_hook(Box::new(move |info| {
            if !ingest::caught_polars_panic(info) {
                next(info);
            }
        }));
    });
}

/// A campaign manifest's text (any bytes; not UTF-8 is the reader's first
/// answer). Logs it names are looked up under a folder that does not exist.
pub fn manifest_toml(data: &[u8]) -> bool {
    manifest(data, "/nonexistent/servoid-fuzz/campaign.toml")
}

/// The same as JSON.
pub fn manifest_json(data: &[u8]) -> bool {
    manifest(data, "/nonexistent/servoid-fuzz/campaign.json")
}

/// Read as a campaign and as a simulation manifest: clean when either is.
fn manifest(data: &[u8], path: &str) -> bool {
    let Ok(text) = std::str::from_utf8(data) else {
        return false;
    };
    let campaign = servoid::manifest::load_str(text, Path::new(path)).is_ok();
    let simulation =
        servoid::manifest::simulation::load_simulation_str(text, Path::new(path)).is_ok();
    campaign || simulation
}

fn channel(column: Column, unit: Unit) -> ChannelPlan {
    ChannelPlan {
        column,
        unit,
        gain: unit.to_si(),
        offset: 0.0,
    }
}

fn log(data: &[u8], file: &str, format: LogFormat, time: TimePlan, names: [Column; 3]) -> bool {
    let path = Path::new(file);
    let [command, displacement, force] = names;
    let plan = LogPlan {
        path: path.to_path_buf(),
        format,
        csv: CsvOptions::default(),
        sha256: None,
        channels: Channels {
            time,
            command: channel(command, Unit::Millimeter),
            displacement: channel(displacement, Unit::Millimeter),
            force: Some(channel(force, Unit::Newton)),
        },
        max_bytes: u64::MAX,
    };
    let Ok(log) = ingest::read_log_from(&plan, LogFile::from_bytes(path, data.to_vec())) else {
        return false;
    };
    let needs = ingest::Needs {
        min_samples: 16,
        max_jitter_fraction: 0.01,
        clip_fraction: 0.01,
    };
    ingest::check_log(&log, &needs).is_ok()
}

fn by_name(n: &str) -> Column {
    Column::Name(n.into())
}

/// A CSV log with columns t, u, x, f by name.
pub fn log_csv(data: &[u8]) -> bool {
    let time = TimePlan::Column {
        column: by_name("t"),
        to_s: 1.0,
    };
    log(
        data,
        "fuzz.csv",
        LogFormat::Csv,
        time,
        [by_name("u"), by_name("x"), by_name("f")],
    )
}

/// A DAQ text export: the rate from its header, channels by name.
pub fn log_daq(data: &[u8]) -> bool {
    log(
        data,
        "fuzz.txt",
        LogFormat::DaqText,
        TimePlan::FromLog,
        [
            by_name("CHANNEL2"),
            by_name("CHANNEL0"),
            by_name("CHANNEL1"),
        ],
    )
}

/// A Parquet log with columns t, u, x, f by name.
pub fn log_parquet(data: &[u8]) -> bool {
    let time = TimePlan::Column {
        column: by_name("t"),
        to_s: 1.0,
    };
    log(
        data,
        "fuzz.parquet",
        LogFormat::Parquet,
        time,
        [by_name("u"), by_name("x"), by_name("f")],
    )
}

/// A MAT file: the rate from its variables, channels by name and index.
pub fn log_mat(data: &[u8]) -> bool {
    log(
        data,
        "fuzz.mat",
        LogFormat::Mat,
        TimePlan::FromLog,
        [by_name("u"), by_name("data:1"), Column::Index(2)],
    )
}

/// A run table (side table) as CSV.
pub fn run_table_csv(data: &[u8]) -> bool {
    ingest::table_from_bytes(Path::new("fuzz.csv"), data.to_vec(), TableFormat::Csv).is_ok()
}

/// A run table as Parquet.
pub fn run_table_parquet(data: &[u8]) -> bool {
    ingest::table_from_bytes(
        Path::new("fuzz.parquet"),
        data.to_vec(),
        TableFormat::Parquet,
    )
    .is_ok()
}
