//! The fuzz targets' bodies: each feeds arbitrary bytes to one of servoid's
//! readers, which must answer with a value or an error, never a panic.
//! Shared by the cargo-fuzz targets (`fuzz/fuzz_targets/`) and by the
//! stable replay of their corpus and crash inputs (`tests/fuzz_replay.rs`),
//! so CI needs no nightly toolchain.

use std::path::Path;

use servoid::ingest::{
    self, ChannelPlan, Channels, Column, CsvOptions, LogFile, LogFormat, LogPlan, Repair,
    TableFormat, TimePlan,
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
    ("log_mat_v73", log_mat_v73),
    ("log_hdf5", log_hdf5),
    ("log_tdms", log_tdms),
    ("run_table_csv", run_table_csv),
    ("run_table_parquet", run_table_parquet),
    ("manifest_numbers", manifest_numbers),
];

/// Lets the panics `servoid::ingest` catches inside the readers it calls
/// (polars, hdf5-pure, matfile) unwind to it:
/// libFuzzer's hook aborts on every panic, which would report a damaged
/// file that servoid handles as a crash. Every other panic still aborts.
pub fn let_caught_panics_unwind() {
    static ONCE: std::sync::Once = std::sync::Once::new();
    ONCE.call_once(|| {
        let next = std::panic::take_hook();
        std::panic::set_hook(Box::new(move |info| {
            if !ingest::caught_reader_panic(info) {
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
        range: None,
        repair: Repair::None,
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
        force_loaded: true,
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

/// A MAT v7.3 file (HDF5 behind MATLAB's header): the rate from its `t`,
/// channels by name (one in a struct) and one by index of a table.
pub fn log_mat_v73(data: &[u8]) -> bool {
    log(
        data,
        "fuzz.mat",
        LogFormat::Mat,
        TimePlan::FromLog,
        [by_name("u"), by_name("log.x"), Column::Index(2)],
    )
}

/// A plain HDF5 file: time, command and displacement datasets by path,
/// force a channel of a 2-D dataset.
pub fn log_hdf5(data: &[u8]) -> bool {
    let time = TimePlan::Column {
        column: by_name("t"),
        to_s: 1.0,
    };
    log(
        data,
        "fuzz.h5",
        LogFormat::Hdf5,
        time,
        [by_name("u"), by_name("run/x"), by_name("table:1")],
    )
}

/// A TDMS file: the rate from a channel's `wf_increment`, channels by
/// group and name.
pub fn log_tdms(data: &[u8]) -> bool {
    log(
        data,
        "fuzz.tdms",
        LogFormat::Tdms,
        TimePlan::FromLog,
        [by_name("g/u"), by_name("g/x"), by_name("g/f")],
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

/// Finite numbers from the whole of f64's range (and integers from i64's)
/// in every numeric key of two campaigns, which are then analysed (issue
/// 24): the paper's (published transfer functions) and a small simulated
/// one with logs (`numbers_campaign`). No finite number may panic: each is
/// an answer or an error naming its key or run.
///
/// The input is a template choice (its first byte) and then records of ten
/// bytes: a literal's index (two bytes, modulo the count) and the value's
/// eight bytes (an f64's bits for a float literal, an i64 for an integer;
/// a non-finite float is skipped, as the manifest refuses it by name).
pub fn manifest_numbers(data: &[u8]) -> bool {
    let Some((&which, records)) = data.split_first() else {
        return false;
    };
    let (text, path) = if which % 2 == 0 {
        (
            PAPER.to_string(),
            Path::new("/nonexistent/paper.toml").to_path_buf(),
        )
    } else {
        let (text, path) = numbers_campaign();
        (text.clone(), path.clone())
    };
    let literals = numeric_literals(&text);
    let mut edits = Vec::new();
    for r in records.chunks_exact(10) {
        let i = u16::from_le_bytes([r[0], r[1]]) as usize % literals.len();
        let bits: [u8; 8] = r[2..].try_into().unwrap();
        let (range, integer) = literals[i].clone();
        let value = if integer {
            i64::from_le_bytes(bits).to_string()
        } else {
            let v = f64::from_le_bytes(bits);
            if !v.is_finite() {
                continue;
            }
            toml_float(v)
        };
        edits.push((range, value));
    }
    analyse_text(&with_numbers(&text, edits), &path)
}

/// The paper's campaign, the bundled default.
pub const PAPER: &str = include_str!("../../experiments/maghareh2018/paper.toml");

/// A float as TOML writes it: Rust's shortest round-trip exponent form
/// ("1e300", "-5e-324", "0e0") is a valid TOML float.
pub fn toml_float(v: f64) -> String {
    format!("{v:e}")
}

/// Whether the manifest `text` (at `path`) analyses cleanly; false when the
/// manifest is refused (an answer too). A panic is the failure.
pub fn analyse_text(text: &str, path: &Path) -> bool {
    match servoid::manifest::load_str(text, path) {
        Ok(campaign) => {
            let results = servoid::run::analyse(&campaign);
            results.runs.iter().all(|r| r.error.is_none())
        }
        Err(_) => false,
    }
}

/// The byte ranges of `text`'s numeric literals (a TOML value that starts
/// with a digit, or a sign and a digit, after `=`, `[`, `,` or `{`), each
/// with whether it is an integer. Comments and strings are skipped.
pub fn numeric_literals(text: &str) -> Vec<(std::ops::Range<usize>, bool)> {
    let b = text.as_bytes();
    let mut out = Vec::new();
    let mut i = 0;
    let mut prev = b'\n';
    while i < b.len() {
        let c = b[i];
        if c == b'#' {
            while i < b.len() && b[i] != b'\n' {
                i += 1;
            }
            continue;
        }
        if c == b'"' || c == b'\'' {
            let triple = b[i..].starts_with(&[c, c, c]);
            let close: &[u8] = if triple { &b[i..i + 3] } else { &b[i..i + 1] };
            let close = close.to_vec();
            i += close.len();
            while i < b.len() && !b[i..].starts_with(&close) {
                i += if b[i] == b'\\' && c == b'"' { 2 } else { 1 };
            }
            i += close.len();
            prev = c;
            continue;
        }
        let starts = c.is_ascii_digit()
            || ((c == b'-' || c == b'+') && b.get(i + 1).is_some_and(u8::is_ascii_digit));
        if starts && matches!(prev, b'=' | b'[' | b',' | b'{') {
            let start = i;
            i += 1;
            while i < b.len() && (b[i].is_ascii_alphanumeric() || b"._+-".contains(&b[i])) {
                i += 1;
            }
            let token = &text[start..i];
            let integer = !token.contains(['.', 'e', 'E']);
            out.push((start..i, integer));
            prev = b'0';
            continue;
        }
        if !c.is_ascii_whitespace() {
            prev = c;
        }
        i += 1;
    }
    out
}

/// `text` with each range replaced by its value (later edits of the same
/// range win).
pub fn with_numbers(text: &str, mut edits: Vec<(std::ops::Range<usize>, String)>) -> String {
    edits.sort_by_key(|(r, _)| r.start);
    edits.dedup_by(|later, earlier| {
        let same = later.0 == earlier.0;
        if same {
            std::mem::swap(&mut earlier.1, &mut later.1);
        }
        same
    });
    let mut out = String::with_capacity(text.len());
    let mut at = 0;
    for (r, v) in edits {
        out.push_str(&text[at..r.start]);
        out.push_str(&v);
        at = r.end;
    }
    out.push_str(&text[at..]);
    out
}

/// A small simulated campaign with logs (8 s at 400 Hz: a no-specimen
/// run, a spring and an SDOF validation run with force), simulated once
/// per process into the temporary folder: its analysis manifest's text and
/// path. A process cannot remove its folder as it exits (a static is never
/// dropped), so each removes those of processes that have ended.
pub fn numbers_campaign() -> &'static (String, std::path::PathBuf) {
    static CAMPAIGN: std::sync::OnceLock<(String, std::path::PathBuf)> = std::sync::OnceLock::new();
    CAMPAIGN.get_or_init(|| {
        const PREFIX: &str = "servoid-numbers-";
        let tmp = std::env::temp_dir();
        // Only where /proc tells which processes live.
        let entries = match std::path::Path::new("/proc/self").exists() {
            true => std::fs::read_dir(&tmp).ok(),
            false => None,
        };
        for entry in entries.into_iter().flatten().flatten() {
            let name = entry.file_name();
            let pid = name.to_str().and_then(|n| n.strip_prefix(PREFIX));
            let ended = pid.is_some_and(|p| {
                p.parse::<u32>().is_ok() && !std::path::Path::new("/proc").join(p).exists()
            });
            if ended {
                let _ = std::fs::remove_dir_all(entry.path());
            }
        }
        let dir = tmp.join(format!("{PREFIX}{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        std::fs::create_dir_all(&dir).expect("a temporary folder");
        let sim = dir.join("simulation.toml");
        let plan = servoid::manifest::simulation::load_simulation_str(NUMBERS_SIMULATION, &sim)
            .expect("the numbers campaign's simulation manifest is valid");
        let done = servoid::run::simulate::simulate_campaign(&plan, &dir)
            .expect("the numbers campaign simulates");
        let text = std::fs::read_to_string(&done.manifest).expect("its manifest reads");
        (text, done.manifest)
    })
}

const NUMBERS_SIMULATION: &str = r#"
schema_version = 1

[simulation]
name = "numbers"
sample_rate_hz = 400.0
seed = 24
log_format = "csv"

[rig]
name = "a simulated rig"

[rig.parameters]
beta1_per_s = 267.0
a1b0_n_per_m_s2 = 2.412e9
a2_n_per_m = 7.881e5
a3_per_s = 16.118

[excitation]
kind = "chirp"
law = "quadratic"
f0_hz = 0.5
f1_hz = 30.0
duration_s = 8.0
amplitude_m = 0.004
lead_in_s = 0.5
lead_out_s = 0.5

[instrument.command]
unit = "mm"
quantization = { bits = 18, full_scale = 50.0 }

[instrument.displacement]
unit = "mm"
noise_rms = 0.002
quantization = { bits = 18, full_scale = 50.0 }

[instrument.force]
unit = "N"
noise_rms = 1.0
quantization = { bits = 18, full_scale = 5000.0 }

[identification]
band_hz = [1.0, 25.0]
coherence_min = 0.8
command_intersample = "sample_and_hold"
frf = { estimator = "etfe", segment_length = 512, overlap = 0.5, window = "rectangular", detrend = "mean" }

[[runs]]
id = "bare"
role = "no_specimen"
p_gain = 1.0

[[runs]]
id = "k1"
role = "spring"
p_gain = 1.0
specimen = { stiffness_n_per_m = 116640.0 }

[[runs]]
id = "exp1"
role = "validation"
p_gain = 1.0
specimen = { mass_kg = 3.8, damping_ns_per_m = 5.0, stiffness_n_per_m = 129400.0 }
"#;
