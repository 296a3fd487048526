//! Reading lab logs: the only module that reads data files.
//!
//! A log holds the command displacement u, the measured displacement x1 and,
//! optionally, the actuator force f, uniformly sampled. [`read_log`] reads one
//! file as a [`LogPlan`] describes it (CSV, Parquet, MAT, HDF5, TDMS or DAQ
//! text), verifies its SHA-256 over exactly the bytes it parses, and converts
//! every channel to SI once, here: SI value = raw * gain + offset.
//! [`check_log`] then judges whether the log suits the FRF settings (length,
//! uniform sampling, clipping), and [`trim_to_excitation`] keeps the excited
//! part. Every error and warning names the file and the 1-based line, row or
//! element at fault. [`read_table`] reads a side table (a run table, CSV or
//! Parquet) as text cells; [`collect`] finds the logs `servoid init` is given
//! and tells them from the run tables among them. How the readers read and
//! what they refuse: docs/methods.md, "Reading the logs".

mod arrays;
mod clipping;
pub mod command;
mod csv;
mod daq;
mod discover;
mod fields;
mod hdf5;
mod held;
mod inspect;
mod mat;
pub mod naming;
mod parquet;
mod parquet_footer;
mod plan;
mod quantisation;
pub mod spikes;
mod table;
mod tdms;
#[cfg(test)]
mod tests;

use crate::warning::Warning;
use std::fmt;
use std::path::{Path, PathBuf};

use polars::prelude::{DataType, PolarsError};
use sha2::{Digest, Sha256};

use crate::units::format_number;

pub use discover::{DiscoverError, Found, collect};
pub use inspect::{Inspected, inspect};
pub use plan::{
    ChannelPlan, Channels, Column, CsvOptions, DEFAULT_MAX_LOG_MIB, LogFormat, LogPlan, Repair,
    TimePlan,
};
pub use quantisation::quantum_step;
pub use table::{
    Table, TableError, TableFormat, TableProblem, TableText, read_table, read_table_as,
    table_from_bytes, table_from_bytes_as,
};

/// One column of a log, or one channel of a 2-D variable (`data:2`), as
/// `servoid init` lists them ([`inspect`]).
#[derive(Debug, Clone, PartialEq)]
pub struct LogColumn {
    pub name: String,
    /// The unit the file states for it (an HDF5 `units` attribute, a TDMS
    /// `unit_string`), when it does.
    pub unit: Option<String>,
}

/// A log read and converted to SI.
#[derive(Debug, Clone, PartialEq)]
pub struct Log {
    pub path: PathBuf,
    /// SHA-256 of the file's bytes, lowercase hexadecimal.
    pub sha256: String,
    pub format: LogFormat,
    /// 1 / (mean sample interval) (Hz).
    pub sample_rate_hz: f64,
    /// Time of the first sample (s): the first time stamp of a time column,
    /// else 0.
    pub t0_s: f64,
    /// Command displacement u (m).
    pub command_m: Vec<f64>,
    /// Measured actuator displacement x1 (m).
    pub displacement_m: Vec<f64>,
    /// Measured actuator force f (N), when the plan names a force channel.
    pub force_n: Option<Vec<f64>>,
    /// Number of samples in each channel (after [`trim_to_excitation`], the
    /// number kept).
    pub n_rows: usize,
    pub timing: Timing,
    /// Oddities found while reading; each names the file.
    pub warnings: Vec<Warning>,
    /// The isolated spikes a channel's `repair = "interpolate"` replaced.
    pub repairs: Vec<Repaired>,
}

/// An isolated spike in a channel whose `repair` is not set: where it is,
/// its value and its neighbours' in the channel's unit.
#[derive(Debug, thiserror::Error)]
#[error(
    "{}: {at} (sample {sample}, t = {} s): {channel} (column {column}) {}: {} {unit} where its neighbours read {} and {} {unit} ({} times the channel's local sample-to-sample scale): {}? Fix the file, or set channels.{channel}.repair = \"interpolate\" to replace it by its neighbours' line (results.json records it)",
    path.display(),
    format_number(*time_s, 6),
    spike_words(*width).0,
    format_number(*value, 6),
    format_number(*before, 6),
    format_number(*after, 6),
    format_number(*ratio, 2),
    spike_words(*width).1
)]
pub struct SpikeFound {
    pub path: PathBuf,
    pub at: At,
    pub sample: usize,
    /// Adjacent samples departing together (1 to `spikes::MAX_WIDTH`).
    pub width: usize,
    pub time_s: f64,
    pub channel: &'static str,
    pub column: String,
    pub value: f64,
    pub before: f64,
    pub after: f64,
    pub unit: &'static str,
    pub ratio: f64,
}

/// What a run of `width` bad samples is, and what likely made it: one or
/// two samples are an isolated spike, more a corrupt stretch.
fn spike_words(width: usize) -> (String, &'static str) {
    if width <= 2 {
        ("is an isolated spike".into(), "a corrupted sample")
    } else {
        (
            format!("starts a corrupt stretch of {width} adjacent samples"),
            "a corrupted stretch of the file or a DAQ glitch",
        )
    }
}

/// How a time column fails to increase.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum TimeFault {
    /// One stamp is out of order and the next is in order again.
    Swapped,
    /// Time goes back and carries on from there.
    Reset,
    /// A stamp repeats the one before, off any rounded grid.
    Repeated,
}

/// A displacement or force that holds one value while it should move
/// (`ingest::held`): where, for how long, and what it looks like.
#[derive(Debug, thiserror::Error)]
#[error(
    "{}: {at} (samples {sample} to {}, t = {} to {} s): {}: the run cannot be analysed; fix the file, record the run again, or cut the log to one side of it",
    path.display(),
    sample + len - 1,
    format_number(*time_s, 6),
    format_number(time_s + *len as f64 * dt_s, 6),
    held_words(self)
)]
pub struct HeldFound {
    pub path: PathBuf,
    pub at: At,
    pub sample: usize,
    pub len: usize,
    pub time_s: f64,
    pub dt_s: f64,
    pub channel: &'static str,
    pub column: String,
    pub kind: HeldKind,
    /// The held value, in the channel's unit, and its speed on either
    /// side (the slower), in that unit per second.
    pub value: f64,
    pub unit: &'static str,
    pub speed: f64,
}

/// What a held stretch looks like (`ingest::held`).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum HeldKind {
    /// The channel drops to zero and comes back.
    Dropout,
    /// The channel holds a value while its command moves, or leaves it by
    /// a jump.
    Stuck,
    /// Every channel holds its value at once.
    Frozen,
}

/// A held stretch in words, for [`HeldFound`].
fn held_words(h: &HeldFound) -> String {
    let HeldFound {
        len,
        dt_s,
        channel,
        column,
        kind,
        value,
        unit,
        speed,
        ..
    } = h;
    let seconds = format_number(*len as f64 * dt_s, 3);
    match kind {
        HeldKind::Dropout => format!(
            "the {channel} (column {column}) drops to 0 {unit} for {len} samples ({seconds} s) and comes back: a dropout of the sensor or its cable"
        ),
        HeldKind::Stuck => format!(
            "the {channel} (column {column}) holds {} {unit} for {len} samples ({seconds} s), where it moves at {} {unit}/s on either side: a stuck sensor or channel",
            format_number(*value, 6),
            format_number(*speed, 3)
        ),
        HeldKind::Frozen => format!(
            "every channel holds its value for {len} samples ({seconds} s), the {channel} at {} {unit}, and jumps on: the DAQ stalled and repeated its last sample",
            format_number(*value, 6)
        ),
    }
}

/// One isolated spike replaced by its neighbours' line (`ingest::spikes`).
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize, schemars::JsonSchema)]
pub struct Repaired {
    pub channel: String,
    /// Where it sits in the file (a line, row or element), and its first
    /// sample (0-based) and time (s from the record's start).
    pub at: String,
    pub sample: usize,
    pub time_s: f64,
    /// Samples replaced (1 to `spikes::MAX_WIDTH`).
    pub width: usize,
    /// The spike's value and its neighbours', in SI (m or N).
    pub value: f64,
    pub before: f64,
    pub after: f64,
}

/// How the time base was obtained.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Timing {
    /// From a sampling rate (the manifest's or the log's header): uniform by
    /// construction.
    Exact { dt_s: f64 },
    /// Measured from a time column. The jitter is the deviation of each
    /// interval t(k+1) - t(k) from the mean interval; `stamps` says how the
    /// stamps stand against a uniform grid, and the interval is the grid's
    /// where they stand on one.
    Measured {
        mean_dt_s: f64,
        jitter_rms_s: f64,
        jitter_max_s: f64,
        /// Where the interval with the largest deviation ends.
        worst_at: At,
        stamps: Stamps,
    },
}

/// How a time column's stamps stand against the uniform grid fitted to them
/// by least squares, t(k) = t0 + k dt.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Stamps {
    /// Uniform to what printing them in decimal costs.
    Exact,
    /// On the grid to their own resolution: stamps rounded to
    /// `resolution_s` (a DAQ writing 1 ms stamps at 2048 Hz repeats some).
    Rounded { resolution_s: f64 },
    /// Scattered about the grid by at most half an interval (the largest
    /// deviation and its place, and the RMS): a DAQ sampling on its clock
    /// and stamping each sample late by a varying amount.
    Scattered {
        max_s: f64,
        rms_s: f64,
        worst_at: At,
    },
    /// Off any uniform grid by more than half an interval: a rate that
    /// drifts, or sampling that is not uniform.
    Uneven,
}

impl Timing {
    /// The (mean) sample interval (s).
    pub fn dt_s(&self) -> f64 {
        match *self {
            Timing::Exact { dt_s } => dt_s,
            Timing::Measured { mean_dt_s, .. } => mean_dt_s,
        }
    }
}

/// A place in a log file, 1-based.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum At {
    /// A line of a text file (CSV, DAQ text), counting every line.
    Line(usize),
    /// A row of a Parquet table.
    Row(usize),
    /// An element of a MAT variable.
    Element(usize),
}

impl fmt::Display for At {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            At::Line(n) => write!(f, "line {n}"),
            At::Row(n) => write!(f, "row {n}"),
            At::Element(n) => write!(f, "element {n}"),
        }
    }
}

/// What the later stages need from a log.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Needs {
    /// Fewest samples the FRF settings can use (e.g. one segment).
    pub min_samples: usize,
    /// Largest tolerated deviation of a sample interval from the mean, as a
    /// fraction of the mean interval; above it the log is refused.
    pub max_jitter_fraction: f64,
    /// Largest tolerated fraction of samples sitting exactly at a channel's
    /// maximum (or minimum); above it the channel is taken as clipped.
    pub clip_fraction: f64,
    /// Whether the force carries a load: not with no specimen, where a
    /// load cell reads zero and a coarse converter holds one code.
    pub force_loaded: bool,
}

/// A read error as a lab engineer would say it: a log that is not there is
/// "not found" (it may not have been copied yet), anything else verbatim.
fn io_message(path: &Path, e: &std::io::Error) -> String {
    match e.kind() {
        std::io::ErrorKind::NotFound => format!("log file not found{}", backslash_hint(path)),
        _ => format!("cannot read: {e}"),
    }
}

/// What to say of a path not found that holds backslashes: on Linux and
/// macOS a `\` is part of a file name, not a folder separator (a manifest
/// written on Windows).
pub fn backslash_hint(path: &Path) -> String {
    if path.to_string_lossy().contains('\\') {
        let fixed = path.to_string_lossy().replace('\\', "/");
        format!(
            " (its path holds `\\`, which here is part of a file name, not a folder separator: write it with `/`, as `{fixed}`)"
        )
    } else {
        String::new()
    }
}

/// Why a log cannot be used. Every message names the file.
#[derive(Debug, thiserror::Error)]
pub enum IngestError {
    #[error(
        "{}: the log is {:.1} MiB, over the limit of {} MiB: raise [limits] max_log_mib if this machine has some {:.0} MiB of memory to spare, or split the log",
        path.display(), *bytes as f64 / 1048576.0, max_bytes >> 20, 5.0 * *bytes as f64 / 1048576.0
    )]
    TooLarge {
        path: PathBuf,
        bytes: u64,
        max_bytes: u64,
    },
    #[error("{}: {}", path.display(), io_message(path, source))]
    Io {
        path: PathBuf,
        #[source]
        source: std::io::Error,
    },
    #[error("{}: is {what}, not a regular file: name the log file itself", path.display())]
    NotAFile { path: PathBuf, what: &'static str },
    #[error(
        "{}: changed while it was read ({before} before, {after} after): is it still being written? The run is left out; rerun when the file is complete",
        path.display()
    )]
    Changed {
        path: PathBuf,
        before: String,
        after: String,
    },
    #[error(
        "{}: SHA-256 is {actual} but the manifest expects {expected}: the file changed or is not the one recorded",
        path.display()
    )]
    Sha256Mismatch {
        path: PathBuf,
        expected: String,
        actual: String,
    },
    #[error("{}: the file is empty", path.display())]
    Empty { path: PathBuf },
    #[error("{}: no data rows ({what})", path.display())]
    HeaderOnly { path: PathBuf, what: String },
    #[error("{}: the {channel} channel needs column {column}, which is not there ({available})", path.display())]
    MissingColumn {
        path: PathBuf,
        channel: &'static str,
        column: String,
        available: String,
    },
    #[error("{}: {at}: cannot read {value:?} as a number ({channel}, column {column})", path.display())]
    BadValue {
        path: PathBuf,
        at: At,
        channel: &'static str,
        column: String,
        value: String,
    },
    #[error("{}: {at}: missing value ({channel}, column {column}: {detail})", path.display())]
    MissingValue {
        path: PathBuf,
        at: At,
        channel: &'static str,
        column: String,
        detail: String,
    },
    #[error(
        "{}: {at}: {channel} (column {column}) is {si} after scaling raw {raw}; values must be finite",
        path.display()
    )]
    NonFinite {
        path: PathBuf,
        at: At,
        channel: &'static str,
        column: String,
        raw: f64,
        si: f64,
    },
    #[error(transparent)]
    Spike(Box<SpikeFound>),
    #[error(transparent)]
    Held(Box<HeldFound>),
    #[error(
        "{}: the manifest states a sampling rate of {} Hz (channels.time.sample_rate_hz), but the log's own time column `{column}` steps {} s ({} Hz): name that column as the time base (time = {{ column = \"{column}\", unit = \"{unit}\" }}) or correct the rate",
        path.display(),
        format_number(*stated_hz, 6),
        format_number(*dt_s, 6),
        format_number(1.0 / dt_s, 6)
    )]
    RateContradicts {
        path: PathBuf,
        stated_hz: f64,
        column: String,
        dt_s: f64,
        /// The column's unit as its name or the file gives it ("s" where
        /// neither does).
        unit: &'static str,
    },
    #[error(
        "{}: {at}: {channel} (column {column}) is {si:e} {} after scaling, beyond {range}: a corrupted sample, or a wrong unit? Fix or remove the line",
        path.display(),
        physical_range(channel).1
    )]
    BeyondRange {
        path: PathBuf,
        at: At,
        channel: &'static str,
        column: String,
        si: f64,
        /// The range as the message says it: the manifest's, or the
        /// default beyond any test.
        range: String,
    },
    #[error(
        "{}: {at}: time {} ({t_s} s after {prev_s} s): {}",
        path.display(),
        match kind { TimeFault::Repeated => "does not increase", _ => "goes back" },
        match kind {
            TimeFault::Swapped => "two stamps out of order (the next one is in order again): samples or stamps swapped in writing the file; fix the file",
            TimeFault::Reset => "the time column starts again: two recordings in one file (the DAQ restarted?); split the file into one log per recording",
            TimeFault::Repeated => "time stamps must increase (stamps rounded coarser than the interval repeat, which servoid takes only where every stamp lies within half its resolution of a uniform grid)",
        }
    )]
    NotMonotonic {
        path: PathBuf,
        at: At,
        prev_s: f64,
        t_s: f64,
        kind: TimeFault,
    },
    #[error(
        "{}: {at}: sample number {next} follows {prev}; consecutive numbers were expected, so samples are missing or repeated and the time base is not uniform",
        path.display()
    )]
    SampleGap {
        path: PathBuf,
        at: At,
        prev: u64,
        next: u64,
    },
    #[error(
        "{}: sampling is not uniform: interval jitter max {jitter_max_s:.3e} s (interval ending at {worst_at}), rms {jitter_rms_s:.3e} s, against a mean interval of {dt_s:.6e} s; the max is {fraction:.3e} of the interval, above the tolerance {tolerance:e}, and the stamps stray from any uniform grid by more than half an interval (samples missing, or a rate that drifts). If the DAQ samples on a fixed clock and only its stamps are off, state its rate: channels.time.sample_rate_hz",
        path.display()
    )]
    Jitter {
        path: PathBuf,
        dt_s: f64,
        jitter_rms_s: f64,
        jitter_max_s: f64,
        worst_at: At,
        fraction: f64,
        tolerance: f64,
    },
    #[error(
        "{}: the {channel} channel is clipped: {:.2} % of its samples sit exactly at its {which} {level:e} {unit} (over the {:.2} % tolerated, and more than a quantised crest holds) while the command moves: a sensor or converter at the end of its range? Record again within the range",
        path.display(), 100.0 * fraction, 100.0 * tolerance
    )]
    Clipped {
        path: PathBuf,
        channel: &'static str,
        which: &'static str,
        level: f64,
        unit: &'static str,
        fraction: f64,
        tolerance: f64,
    },
    #[error("{}: {n} samples, but {need} needs at least {min}: {advice}", path.display())]
    TooShort {
        path: PathBuf,
        n: usize,
        min: usize,
        /// What asks for them, and what to do.
        need: &'static str,
        advice: &'static str,
    },
    #[error(
        "{}: the {channel} channel is constant ({level} {unit} in every sample): it carries no signal; check that the channel maps the right column and the log the right run",
        path.display()
    )]
    Constant {
        path: PathBuf,
        channel: &'static str,
        level: f64,
        unit: &'static str,
    },
    #[error("{}: sampling rate {hz} Hz ({from}) must be finite and positive", path.display())]
    BadRate {
        path: PathBuf,
        hz: f64,
        from: &'static str,
    },
    #[error("{}: {problem}", path.display())]
    Format {
        path: PathBuf,
        #[source]
        problem: FormatProblem,
    },
}

impl IngestError {
    /// The file at `path` has `problem`.
    fn format(path: &Path, problem: FormatProblem) -> Self {
        IngestError::Format {
            path: path.to_path_buf(),
            problem,
        }
    }
}

/// What is wrong with a file's layout, beyond any one value: the cause of an
/// [`IngestError::Format`].
#[derive(Debug, thiserror::Error)]
pub enum FormatProblem {
    // Table formats (CSV, Parquet).
    /// The plan asks the log for its rate, but a table holds samples only.
    #[error(
        "a {} log has no sampling rate of its own; give channels.time.column or channels.time.sample_rate_hz",
        format_name(*format)
    )]
    NoRate { format: LogFormat },

    // CSV.
    #[error("the CSV delimiter must be one ASCII character (got {delimiter:?})")]
    Delimiter { delimiter: String },
    /// A column addressed by name has several fields of that name (0-based
    /// indices).
    #[error(
        "column `{name}` ({channel} channel) appears {} times in the header (fields {}); rename one or address it by index",
        fields.len(),
        list(fields)
    )]
    DuplicateColumn {
        name: String,
        channel: &'static str,
        fields: Vec<usize>,
    },

    // DAQ text.
    /// A header value used (`Header Size`, `Sample Count`, `Sampling Rate`,
    /// `Sampling Interval`) is not a positive number.
    #[error("line {line}: header `{key}` is {value:?}, not a positive number")]
    HeaderValue {
        line: usize,
        key: String,
        value: String,
    },
    /// A channel addressed the `Date/Time` or `Events` column.
    #[error("column `{name}` (index {index}, {channel} channel) holds text, not numbers")]
    TextColumn {
        name: String,
        index: usize,
        channel: &'static str,
    },
    #[error(
        "no `Sampling Rate` or `Sampling Interval` in the header; give channels.time.sample_rate_hz"
    )]
    NoHeaderRate,

    // MAT, HDF5, TDMS.
    /// hdf5-pure cannot read the file (damaged, cut short, or a layout it
    /// does not know).
    #[error("not a readable {what} file ({why})")]
    Hdf5Unreadable { what: &'static str, why: String },
    /// The file is not TDMS as servoid reads it, or it is damaged.
    #[error("not a readable TDMS file ({why})")]
    TdmsUnreadable { why: String },
    /// The file states a channel's unit, and it is not the manifest's.
    #[error(
        "variable `{variable}` ({channel} channel) is in {stated:?} by the file's own word, but the manifest says `{manifest}`; correct the manifest's unit (a wrong one scales every parameter)"
    )]
    UnitDisagrees {
        variable: String,
        channel: &'static str,
        stated: String,
        manifest: &'static str,
    },
    #[error("not a level-5 MAT-file (no 128-byte header ending in the `IM`/`MI` endian mark)")]
    NotMat,
    /// A top-level element that is not a variable.
    #[error(
        "the element at byte {at_byte} is of MAT type {kind}, not a variable (miMATRIX or miCOMPRESSED): the file is damaged"
    )]
    MatElement { at_byte: usize, kind: u32 },
    /// A level-5 variable declares dimensions no file holds.
    #[error(
        "variable `{variable}` declares dimensions {dims:?}, more values than a MAT-file holds (the file is damaged)"
    )]
    MatDimensions { variable: String, dims: Vec<i32> },
    /// The file is another kind than its extension says, and servoid can
    /// tell which (`sniff`).
    #[error("this is {what}, not {expected}: {advice}")]
    OtherKind {
        what: &'static str,
        expected: &'static str,
        advice: &'static str,
    },
    /// A data element runs past the end of the file.
    #[error(
        "the MAT-file is cut short: the data element at byte {at_byte} needs {} bytes but {remain} remain",
        needed_bytes(*needed)
    )]
    CutShort {
        at_byte: usize,
        /// Bytes the element needs, its 8-byte tag included; `None` when
        /// not even the tag is whole.
        needed: Option<usize>,
        remain: usize,
    },
    #[error("not a readable level-5 MAT-file (matfile: {source})")]
    MatUnreadable {
        #[source]
        source: matfile::Error,
    },
    /// matfile panicked on damaged bytes (caught by `guard_reader`).
    #[error("not a readable level-5 MAT-file (its reader failed on damaged bytes: {why})")]
    MatReaderFailed { why: String },
    /// A channel addressed by index, with no 2-D variable to index.
    #[error(
        "the {channel} channel is column #{index}, but no variable is a 2-D table (variables: {}); name a vector variable instead",
        list(variables)
    )]
    NoTable {
        channel: &'static str,
        index: usize,
        variables: Vec<MatVariable>,
    },
    /// A channel addressed by index, with several 2-D variables (named).
    #[error(
        "the {channel} channel is column #{index}, but several variables are 2-D tables ({}); write it as \"variable:{index}\"",
        list(tables.iter().map(|name| format!("`{name}`")))
    )]
    SeveralTables {
        channel: &'static str,
        index: usize,
        tables: Vec<String>,
    },
    /// The plan asks the log for its time base, and there is no `t` or
    /// `time` variable.
    #[error(
        "no time base: no vector variable `t` or `time` (variables: {}); give channels.time.column or sample_rate_hz",
        list(variables)
    )]
    NoTimeBase { variables: Vec<MatVariable> },
    /// Each channel with its number of samples.
    #[error(
        "the channels differ in length: {}",
        list(lengths.iter().map(|(channel, n)| format!("{channel} {n}")))
    )]
    Lengths { lengths: Vec<(&'static str, usize)> },
    #[error("variable `{variable}` ({channel} channel) is complex; a log channel must be real")]
    Complex {
        variable: String,
        channel: &'static str,
    },
    /// The variable the plan names is in the file but holds no numbers a
    /// channel can take (text, booleans, a link servoid does not follow).
    #[error(
        "variable `{variable}` ({channel} channel) is {what}; a log channel must be a real numeric vector"
    )]
    NotNumericVariable {
        variable: String,
        channel: &'static str,
        what: String,
    },
    /// A bare channel name found in several groups.
    #[error(
        "the {channel} channel's `{name}` is in several groups ({}): name it with its group",
        list(found.iter().map(|v| format!("`{v}`")))
    )]
    AmbiguousName {
        name: String,
        channel: &'static str,
        found: Vec<String>,
    },
    /// A variable addressed as a vector has several rows and columns.
    #[error(
        "variable `{variable}` ({channel} channel) is {}, not a vector; address one of its channels as \"{variable}:0\"",
        dims(size)
    )]
    NotVector {
        variable: String,
        channel: &'static str,
        size: Vec<usize>,
    },
    /// A variable addressed as `variable:channel` has more than 2 dimensions.
    #[error(
        "variable `{variable}` ({channel} channel) is {}, not a 2-D table",
        dims(size)
    )]
    NotTable {
        variable: String,
        channel: &'static str,
        size: Vec<usize>,
    },
    /// The declared size and the elements held disagree (a damaged file).
    #[error(
        "variable `{variable}` ({channel} channel) is declared {} but holds {held} values: the file is damaged",
        dims(size)
    )]
    SizeMismatch {
        variable: String,
        channel: &'static str,
        size: Vec<usize>,
        held: usize,
    },

    // Parquet.
    /// The footer (schema) cannot be read.
    #[error("not a readable Parquet file: {source}")]
    ParquetUnreadable {
        #[source]
        source: PolarsError,
    },
    /// polars failed (panicked) on damaged bytes.
    #[error("a damaged Parquet file: polars failed reading it ({message})")]
    ParquetDamaged { message: String },
    /// Its metadata or page headers declare what the file cannot hold
    /// (servoid's check before polars reads them).
    #[error("a damaged Parquet file: {source}")]
    ParquetMetadata {
        #[source]
        source: parquet::ParquetDamage,
    },
    /// The schema reads, the wanted columns do not.
    #[error("polars cannot read it as Parquet: {source}")]
    ParquetRead {
        #[source]
        source: PolarsError,
    },
    #[error("column `{column}` lost in reading: {source}")]
    ColumnLost {
        column: String,
        #[source]
        source: PolarsError,
    },
    #[error("column `{column}` ({channel} channel) holds {dtype}, not numbers")]
    NotNumeric {
        column: String,
        channel: &'static str,
        /// Boxed: polars' type is 48 bytes, and inline it would make every
        /// `Result<_, IngestError>` too large to return cheaply.
        dtype: Box<DataType>,
    },
    #[error("column `{column}` cannot become f64: {source}")]
    NotF64 {
        column: String,
        #[source]
        source: PolarsError,
    },
}

/// A MAT variable as messages list it: `` `name` (rows x cols) ``.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct MatVariable {
    pub name: String,
    /// Its dimensions, as the file gives them.
    pub size: Vec<usize>,
}

impl fmt::Display for MatVariable {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "`{}` ({})", self.name, dims(&self.size))
    }
}

/// Read a log as `plan` describes it and convert its channels to SI.
///
/// Refuses the file when its SHA-256 differs from `plan.sha256`, when it is
/// empty or has no data rows, when a column is missing or a value is not a
/// number, when a value is NaN or infinite, and when time stamps do not
/// strictly increase (or DAQ sample numbers skip). Quality judgements that
/// depend on the analysis (length, jitter, clipping) are left to
/// [`check_log`].
pub fn read_log(plan: &LogPlan) -> Result<Log, IngestError> {
    read_log_from(plan, LogFile::read(&plan.path, plan.max_bytes)?)
}

/// A log file's bytes and their SHA-256, read once: a cache can look a run
/// up by the hash before the bytes are parsed, and parse them on a miss.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct LogFile {
    pub path: PathBuf,
    bytes: Vec<u8>,
    /// SHA-256 of the bytes, lowercase hexadecimal.
    pub sha256: String,
    /// The file's stamp when the bytes were read (unchanged during the
    /// read), for a cache that skips hashing an unchanged file next time.
    pub stamp: Option<FileStamp>,
}

impl LogFile {
    /// Read a log whole. Only a regular file is read (a FIFO matched by a
    /// glob would block a night forever, a folder cannot be a log), and
    /// its size and modification time must be the same before and after
    /// the read, and the size what was read: a log still being written (a
    /// DAQ appending to it, a copy in progress) is refused, not analysed
    /// half-written.
    ///
    /// A log over `max_bytes` is refused before it is read.
    pub fn read(path: &Path, max_bytes: u64) -> Result<Self, IngestError> {
        let io = |source| IngestError::Io {
            path: path.to_path_buf(),
            source,
        };
        let meta = std::fs::metadata(path).map_err(io)?;
        if !meta.is_file() {
            return Err(IngestError::NotAFile {
                path: path.to_path_buf(),
                what: kind_of(&meta.file_type()),
            });
        }
        if meta.len() > max_bytes {
            return Err(IngestError::TooLarge {
                path: path.to_path_buf(),
                bytes: meta.len(),
                max_bytes,
            });
        }
        let before = FileStamp::from_meta(&meta);
        let bytes = std::fs::read(path).map_err(io)?;
        let after = std::fs::metadata(path)
            .ok()
            .and_then(|m| FileStamp::from_meta(&m));
        unchanged(path, before, after, bytes.len())?;
        Ok(Self {
            path: path.to_path_buf(),
            sha256: sha256_hex(&bytes),
            bytes,
            stamp: after,
        })
    }
}

impl LogFile {
    /// A log's bytes as if read from `path` (no stamp): for input that is
    /// not a file, such as a fuzzer's.
    pub fn from_bytes(path: &Path, bytes: Vec<u8>) -> Self {
        Self {
            path: path.to_path_buf(),
            sha256: sha256_hex(&bytes),
            bytes,
            stamp: None,
        }
    }
}

/// What a path that is not a regular file is.
fn kind_of(t: &std::fs::FileType) -> &'static str {
    use std::os::unix::fs::FileTypeExt;
    if t.is_dir() {
        "a folder"
    } else if t.is_fifo() {
        "a named pipe"
    } else if t.is_socket() {
        "a socket"
    } else if t.is_block_device() || t.is_char_device() {
        "a device"
    } else {
        "not a file"
    }
}

/// The check of [`LogFile::read`]: the stamps before and after a read of
/// `len` bytes agree with each other and with the length.
fn unchanged(
    path: &Path,
    before: Option<FileStamp>,
    after: Option<FileStamp>,
    len: usize,
) -> Result<(), IngestError> {
    let show = |s: Option<FileStamp>| match s {
        Some(s) => format!("{} bytes, modified at {} ns", s.size, s.modified_ns),
        None => "gone".to_string(),
    };
    let same = before == after && after.is_some_and(|a| a.size == len as u64);
    if same {
        return Ok(());
    }
    let after = match after {
        Some(a) if before == Some(a) => format!("{len} bytes read"),
        a => show(a),
    };
    Err(IngestError::Changed {
        path: path.to_path_buf(),
        before: show(before),
        after,
    })
}

/// What the file system says of a file without reading it: its size and
/// modification time. A file whose stamp has not changed since its hash was
/// taken is taken to hold the same bytes (as make and git do).
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
pub struct FileStamp {
    pub size: u64,
    pub modified_ns: u128,
}

impl FileStamp {
    /// None when the file cannot be looked at (the read that follows will
    /// say why).
    pub fn of(path: &Path) -> Option<Self> {
        Self::from_meta(&std::fs::metadata(path).ok()?)
    }

    fn from_meta(meta: &std::fs::Metadata) -> Option<Self> {
        let modified = meta.modified().ok()?;
        let since = modified.duration_since(std::time::UNIX_EPOCH).ok()?;
        Some(Self {
            size: meta.len(),
            modified_ns: since.as_nanos(),
        })
    }
}

/// Parse a log file already read, as `plan` describes it; see [`read_log`].
pub fn read_log_from(plan: &LogPlan, file: LogFile) -> Result<Log, IngestError> {
    let path = plan.path.as_path();
    let LogFile { bytes, sha256, .. } = file;
    if let Some(expected) = &plan.sha256
        && !expected.eq_ignore_ascii_case(&sha256)
    {
        return Err(IngestError::Sha256Mismatch {
            path: path.to_path_buf(),
            expected: expected.to_ascii_lowercase(),
            actual: sha256,
        });
    }
    if bytes.iter().all(u8::is_ascii_whitespace) {
        return Err(IngestError::Empty {
            path: path.to_path_buf(),
        });
    }
    if let TimePlan::SampleRate { hz } = plan.channels.time
        && let Some((probe, unit_known)) = undeclared_time(plan, &bytes)
    {
        match read_raw(&probe, &bytes).and_then(|raw| assemble(&probe, sha256.clone(), raw)) {
            Ok(log) => return stated_rate(log, hz, &probe, unit_known),
            // A time column that goes back holds two recordings, or two
            // samples out of order, whatever rate the manifest states.
            Err(e @ IngestError::NotMonotonic { kind, .. }) if kind != TimeFault::Repeated => {
                return Err(e);
            }
            Err(_) => {}
        }
    }
    let raw = read_raw(plan, &bytes)?;
    assemble(plan, sha256, raw)
}

/// The columns `plan` names, read from the log's `bytes`.
fn read_raw<'a>(plan: &'a LogPlan, bytes: &'a [u8]) -> Result<Raw<'a>, IngestError> {
    let path = plan.path.as_path();
    Ok(match plan.format {
        LogFormat::Csv => off_pool(|| csv::read(path, bytes, plan))?,
        LogFormat::Parquet => off_pool(|| parquet::read(path, bytes, plan))?,
        LogFormat::Mat => mat::read(path, bytes, plan)?,
        LogFormat::DaqText => daq::read(path, bytes, plan)?,
        LogFormat::Hdf5 => hdf5::read(path, bytes, plan, false)?,
        LogFormat::Tdms => tdms::read(path, bytes, plan)?,
    })
}

/// The relative difference between a stated rate and the one a log's own
/// time column steps at beyond which the two contradict: a DAQ's clock is
/// good to parts per million, its time stamps' rounding to a part in ten
/// thousand.
pub const RATE_TOLERANCE: f64 = 1e-3;

/// For a plan that states a rate: the same plan with the log's own time
/// column as its time base, when the log has one the channels do not use
/// (found by its name and unit as `servoid init` finds one), and whether
/// its unit was known (stated, or in its name).
fn undeclared_time(plan: &LogPlan, bytes: &[u8]) -> Option<(LogPlan, bool)> {
    let columns = inspect::inspect_bytes(&plan.path, bytes, plan.format)
        .ok()?
        .columns;
    let ch = &plan.channels;
    let used: Vec<String> = [Some(&ch.command), Some(&ch.displacement), ch.force.as_ref()]
        .into_iter()
        .flatten()
        .filter_map(|c| match &c.column {
            Column::Name(n) => Some(n.clone()),
            Column::Index(i) => columns.get(*i).map(|c| c.name.clone()),
        })
        .collect();
    let free: Vec<LogColumn> = columns
        .into_iter()
        .filter(|c| !used.contains(&c.name))
        .collect();
    let (name, to_s, unit_known) = naming::time_column(&free)?;
    let mut probe = plan.clone();
    probe.channels.time = TimePlan::Column {
        column: Column::Name(name),
        to_s,
    };
    Some((probe, unit_known))
}

/// `log`, read with its own time column (`probe`'s), as the plan that
/// states `hz` reads it: an error when the column steps at another rate
/// (in seconds, or when its unit is not known also in milliseconds or
/// microseconds).
fn stated_rate(log: Log, hz: f64, probe: &LogPlan, unit_known: bool) -> Result<Log, IngestError> {
    let dt_s = log.timing.dt_s();
    let scales: &[f64] = if unit_known {
        &[1.0]
    } else {
        &[1.0, 1e-3, 1e-6]
    };
    let agrees = scales
        .iter()
        .any(|k| (hz * dt_s * k - 1.0).abs() <= RATE_TOLERANCE);
    if !agrees {
        let TimePlan::Column {
            column: Column::Name(column),
            to_s,
        } = &probe.channels.time
        else {
            unreachable!("the probe reads a time column by name")
        };
        return Err(IngestError::RateContradicts {
            path: log.path.clone(),
            stated_hz: hz,
            column: column.clone(),
            dt_s,
            unit: if *to_s == 1e-3 { "ms" } else { "s" },
        });
    }
    Ok(Log {
        sample_rate_hz: hz,
        t0_s: 0.0,
        timing: Timing::Exact { dt_s: 1.0 / hz },
        ..log
    })
}

/// Run a polars call off the caller's rayon pool, on a thread of its own.
///
/// polars parallelises on a pool of its own, and a worker of another rayon
/// pool that calls into it waits by running its own pool's jobs. With one
/// job per run those waits nest as deep as there are runs, and a campaign of
/// a few hundred runs overflowed a worker's stack (seen at 500 runs, two
/// workers). On a thread that belongs to no pool, polars runs the call on
/// that thread alone: the parallelism is across runs.
pub fn off_pool<R: Send>(f: impl FnOnce() -> R + Send) -> R {
    if rayon::current_thread_index().is_none() {
        return f();
    }
    std::thread::scope(|s| match s.spawn(f).join() {
        Ok(r) => r,
        Err(panic) => std::panic::resume_unwind(panic),
    })
}

/// Calls into a third-party reader running now under [`guard_reader`].
static GUARDED: std::sync::atomic::AtomicUsize = std::sync::atomic::AtomicUsize::new(0);

/// A panic inside a third-party reader (polars, hdf5-pure, matfile), caught
/// by `guard_reader`, with its message.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("{message}")]
pub struct ReaderPanic {
    pub message: String,
}

/// A call into a third-party reader that may panic on damaged input (the
/// fuzz targets found index panics in polars' CSV and Parquet readers and
/// arithmetic overflows in matfile's, which a build with overflow checks
/// raises): the panic becomes `Err`
/// with its message, and the reader reports the file as unreadable.
pub(crate) fn guard_reader<R>(f: impl FnOnce() -> R) -> Result<R, ReaderPanic> {
    use std::sync::atomic::Ordering;
    GUARDED.fetch_add(1, Ordering::SeqCst);
    let result = std::panic::catch_unwind(std::panic::AssertUnwindSafe(f));
    GUARDED.fetch_sub(1, Ordering::SeqCst);
    result.map_err(|payload| ReaderPanic {
        message: payload
            .downcast_ref::<&str>()
            .map(|s| s.to_string())
            .or_else(|| payload.downcast_ref::<String>().cloned())
            .unwrap_or_else(|| "a panic without a message".into()),
    })
}

/// The crates whose panics [`guard_reader`] catches, as their source paths
/// name them.
const GUARDED_CRATES: [&str; 3] = ["polars", "hdf5-pure", "matfile"];

/// Whether a panic is one `guard_reader` catches: raised in a guarded
/// crate's code while a guarded call runs (a panic of servoid's own is
/// never one). A panic hook that skips these keeps a damaged file's report
/// to the reader's own error (the CLI's, the fuzz targets').
pub fn caught_reader_panic(info: &std::panic::PanicHookInfo<'_>) -> bool {
    GUARDED.load(std::sync::atomic::Ordering::SeqCst) > 0
        && info
            .location()
            .is_some_and(|l| GUARDED_CRATES.iter().any(|c| l.file().contains(c)))
}

/// What a file is by its first bytes, with what to do, where it is a
/// kind labs save logs as by mistake or in another tool's format: a MAT
/// level-5 file named `.h5`, MATLAB level 4, Octave's text format, and
/// the other formats servoid reads under another name.
fn sniff(bytes: &[u8]) -> Option<(&'static str, &'static str)> {
    let head = &bytes[..bytes.len().min(512)];
    Some(if head.starts_with(b"MATLAB 5.0 MAT-file") {
        (
            "a MATLAB level-5 MAT-file",
            "name it `.mat`, or give the run `data.format = \"mat\"`",
        )
    } else if head.starts_with(b"# Created by Octave") {
        (
            "an Octave text file (Octave's default `save` format)",
            "save it in Octave with `save -v7 log.mat` (a level-5 MAT-file) or `save -hdf5 log.h5`",
        )
    } else if mat::is_level4(bytes) {
        (
            "a MATLAB level-4 MAT-file (`save -v4`)",
            "save it with `save -v7` (level 5) or `save -v7.3`",
        )
    } else if head.starts_with(b"PAR1") {
        ("a Parquet file", "name it `.parquet`")
    } else if head.starts_with(b"TDSm") {
        ("an NI TDMS file", "name it `.tdms`")
    } else if hdf5::is_hdf5(bytes) {
        ("an HDF5 file", "name it `.h5` (or `.mat` for MATLAB v7.3)")
    } else if std::str::from_utf8(head).is_ok_and(|t| {
        t.chars()
            .all(|c| !c.is_control() || c.is_ascii_whitespace())
    }) {
        (
            "a text file",
            "a delimited log is read named `.csv` or `.tsv`, a DAQ text export `.txt`",
        )
    } else {
        return None;
    })
}

/// [`FormatProblem::OtherKind`] for a file that is not `expected`, where
/// [`sniff`] can tell what it is.
fn other_kind(bytes: &[u8], expected: &'static str) -> Option<FormatProblem> {
    sniff(bytes).map(|(what, advice)| FormatProblem::OtherKind {
        what,
        expected,
        advice,
    })
}

/// SHA-256 of `bytes` as lowercase hexadecimal.
pub fn sha256_hex(bytes: &[u8]) -> String {
    format!("{:x}", Sha256::digest(bytes))
}

/// SHA-256 of the file at `path` as lowercase hexadecimal, read in pieces
/// (an output set's figures and tables, for its record and `verify`).
pub fn file_sha256(path: &Path) -> std::io::Result<String> {
    let mut file = std::fs::File::open(path)?;
    let mut hasher = Sha256::new();
    std::io::copy(&mut file, &mut hasher)?;
    Ok(format!("{:x}", hasher.finalize()))
}

/// Raw channels as a format reader found them, before scaling.
struct Raw<'a> {
    time: RawTime,
    command: Vec<f64>,
    displacement: Vec<f64>,
    force: Option<Vec<f64>>,
    /// Where sample `i` (0-based) sits in the file.
    locate: Box<dyn Fn(usize) -> At + Send + 'a>,
    warnings: Vec<Warning>,
}

enum RawTime {
    /// Raw time stamps, times `to_s` gives seconds; `column` names where they
    /// came from.
    Column {
        raw: Vec<f64>,
        to_s: f64,
        column: String,
    },
    /// A rate, and what gave it (for messages).
    Rate { hz: f64, from: &'static str },
}

/// One column a plan asks for: which channel it feeds and how it is addressed.
struct Wanted<'p> {
    channel: &'static str,
    column: &'p Column,
}

/// The columns `plan` needs, in a fixed order: time (when it is a column),
/// command, displacement, force (when given).
fn wanted(plan: &LogPlan) -> Vec<Wanted<'_>> {
    let ch = &plan.channels;
    let mut out = Vec::with_capacity(4);
    if let TimePlan::Column { column, .. } = &ch.time {
        out.push(Wanted {
            channel: "time",
            column,
        });
    }
    out.push(Wanted {
        channel: "command",
        column: &ch.command.column,
    });
    out.push(Wanted {
        channel: "displacement",
        column: &ch.displacement.column,
    });
    if let Some(f) = &ch.force {
        out.push(Wanted {
            channel: "force",
            column: &f.column,
        });
    }
    out
}

/// Split the columns a table reader extracted (in [`wanted`] order) into a
/// [`Raw`], with the time base a table format supports (a column or a rate).
fn raw_from_table<'a>(
    path: &Path,
    plan: &LogPlan,
    mut columns: Vec<Vec<f64>>,
    locate: Box<dyn Fn(usize) -> At + Send + 'a>,
) -> Result<Raw<'a>, IngestError> {
    let mut it = columns.drain(..);
    let time = match &plan.channels.time {
        TimePlan::Column { column, to_s } => RawTime::Column {
            raw: it.next().expect("time column wanted"),
            to_s: *to_s,
            column: column.to_string(),
        },
        TimePlan::SampleRate { hz } => RawTime::Rate {
            hz: *hz,
            from: "manifest",
        },
        TimePlan::FromLog => {
            return Err(IngestError::format(
                path,
                FormatProblem::NoRate {
                    format: plan.format,
                },
            ));
        }
    };
    let command = it.next().expect("command wanted");
    let displacement = it.next().expect("displacement wanted");
    let force = it.next();
    drop(it);
    Ok(Raw {
        time,
        command,
        displacement,
        force,
        locate,
        warnings: Vec::new(),
    })
}

fn format_name(f: LogFormat) -> &'static str {
    match f {
        LogFormat::Csv => "CSV",
        LogFormat::Parquet => "Parquet",
        LogFormat::Mat => "MAT",
        LogFormat::DaqText => "DAQ text",
        LogFormat::Hdf5 => "HDF5",
        LogFormat::Tdms => "TDMS",
    }
}

/// The largest displacement or command a log may hold, m: ten times the
/// stroke of the largest shake-table actuators (about +-1 m). Beyond it a
/// sample is corrupt, or its unit wrong by a factor no lab means.
pub const MAX_STROKE_M: f64 = 10.0;

/// The largest force a log may hold, N: 1 GN, ten times the largest
/// servo-hydraulic actuators' (about 100 MN).
pub const MAX_FORCE_N: f64 = 1e9;

/// A channel's largest magnitude in SI, its SI unit, and the range as a
/// message says it.
fn physical_range(channel: &str) -> (f64, &'static str, &'static str) {
    match channel {
        "command" | "displacement" => (MAX_STROKE_M, "m", "+-10 m"),
        "force" => (MAX_FORCE_N, "N", "+-1e9 N"),
        _ => (f64::INFINITY, "", "range"),
    }
}

/// Scale, check finiteness, the physical range and monotonic time, measure
/// the timing, and refuse or repair isolated spikes.
fn assemble(plan: &LogPlan, sha256: String, raw: Raw<'_>) -> Result<Log, IngestError> {
    let path = &plan.path;
    let n = raw.command.len();
    if n == 0 {
        return Err(IngestError::HeaderOnly {
            path: path.clone(),
            what: "the channels are empty".into(),
        });
    }
    let Raw {
        time,
        command,
        displacement,
        force,
        locate,
        mut warnings,
    } = raw;
    let site = Site {
        path,
        locate: &*locate,
    };
    let (timing, sample_rate_hz, t0_s) = time_base(site, time)?;
    let ch = &plan.channels;
    let mut repairs = Vec::new();
    let dt_s = 1.0 / sample_rate_hz;
    let command_m = channel_samples(site, dt_s, "command", &ch.command, command, &mut repairs)?;
    let displacement_m = channel_samples(
        site,
        dt_s,
        "displacement",
        &ch.displacement,
        displacement,
        &mut repairs,
    )?;
    let force_n = match (&ch.force, force) {
        (Some(p), Some(v)) => Some(channel_samples(site, dt_s, "force", p, v, &mut repairs)?),
        _ => None,
    };
    push_repair_warnings(path, &repairs, &mut warnings);
    check_held(
        site,
        dt_s,
        ch,
        &command_m,
        &displacement_m,
        force_n.as_deref(),
    )?;
    Ok(Log {
        path: path.clone(),
        sha256,
        format: plan.format,
        sample_rate_hz,
        t0_s,
        command_m,
        displacement_m,
        force_n,
        n_rows: n,
        timing,
        warnings,
        repairs,
    })
}

/// Where a log's samples sit, for messages: its file, and each sample's
/// place in that file.
#[derive(Clone, Copy)]
struct Site<'a> {
    path: &'a PathBuf,
    locate: &'a dyn Fn(usize) -> At,
}

/// The time base: time stamps converted to seconds and measured, or a
/// stated rate checked. Gives the timing, the sample rate (Hz) and the
/// first sample's time (s).
fn time_base(site: Site<'_>, time: RawTime) -> Result<(Timing, f64, f64), IngestError> {
    match time {
        RawTime::Column { raw, to_s, column } => {
            let t = to_si(site, "time", column, None, raw, &|r| r * to_s)?;
            let timing = measure_timing(site.path, &t, site.locate)?;
            Ok((timing, 1.0 / timing.dt_s(), t[0]))
        }
        RawTime::Rate { hz, from } => {
            if !(hz.is_finite() && hz > 0.0) {
                return Err(IngestError::BadRate {
                    path: site.path.clone(),
                    hz,
                    from,
                });
            }
            Ok((Timing::Exact { dt_s: 1.0 / hz }, hz, 0.0))
        }
    }
}

/// One channel's samples in SI, checked against its range, with isolated
/// spikes refused or repaired as its plan says (each repair added to
/// `repairs`). `dt_s` is the sample interval.
fn channel_samples(
    site: Site<'_>,
    dt_s: f64,
    channel: &'static str,
    plan: &ChannelPlan,
    v: Vec<f64>,
    repairs: &mut Vec<Repaired>,
) -> Result<Vec<f64>, IngestError> {
    let v = channel_to_si(site, channel, plan, v)?;
    despiked(site, dt_s, channel, plan, v, repairs)
}

/// A channel's raw samples times its gain plus its offset, checked against
/// the manifest's range for it, or the physical one when none is given.
fn channel_to_si(
    site: Site<'_>,
    channel: &'static str,
    plan: &ChannelPlan,
    v: Vec<f64>,
) -> Result<Vec<f64>, IngestError> {
    let column = plan.column.to_string();
    let given = plan.range.map(|r| (r, plan.unit));
    // A zero offset is not added, so that -0 stays -0 and a log written in
    // SI reads back bit for bit.
    if plan.offset == 0.0 {
        to_si(site, channel, column, given, v, &|r| r * plan.gain)
    } else {
        to_si(site, channel, column, given, v, &|r| {
            r * plan.gain + plan.offset
        })
    }
}

/// Convert `v` to SI with `si` in place (a copy of a 14 M-row log's columns
/// is a third of its reading's peak memory) and refuse the first sample
/// that is not finite or lies outside the range: `given` is the manifest's
/// range in SI with the channel's unit, else the channel's physical range
/// applies.
fn to_si(
    site: Site<'_>,
    channel: &'static str,
    column: String,
    given: Option<((f64, f64), crate::units::Unit)>,
    mut v: Vec<f64>,
    si: &dyn Fn(f64) -> f64,
) -> Result<Vec<f64>, IngestError> {
    // A finite but absurd sample (say 9.9e37) would give an NRMSE of inf
    // and an "offset removed" of some 1e300 m: beyond the instrument's range
    // (the manifest's), or beyond what any test reaches, it is the line's
    // error.
    let (default, _, said) = physical_range(channel);
    let (lo, hi) = given.map_or((-default, default), |(r, _)| r);
    for (i, x) in v.iter_mut().enumerate() {
        let raw = *x;
        *x = si(raw);
        if !x.is_finite() {
            return Err(IngestError::NonFinite {
                path: site.path.clone(),
                at: (site.locate)(i),
                channel,
                column: column.to_string(),
                raw,
                si: *x,
            });
        }
        if !(lo..=hi).contains(x) {
            return Err(IngestError::BeyondRange {
                path: site.path.clone(),
                at: (site.locate)(i),
                channel,
                column: column.clone(),
                si: *x,
                range: range_in_words(channel, given.map(|(_, unit)| unit), (lo, hi), said),
            });
        }
    }
    Ok(v)
}

/// The range a sample fell outside, as a message says it: the manifest's
/// `[lo, hi]` (SI) in the channel's `unit` when it gave one, else the
/// physical range `said`.
fn range_in_words(
    channel: &str,
    unit: Option<crate::units::Unit>,
    (lo, hi): (f64, f64),
    said: &str,
) -> String {
    match unit {
        Some(unit) => format!(
            "its range [{}, {}] {} ([channels.{channel}] range)",
            lo / unit.to_si(),
            hi / unit.to_si(),
            unit.symbol()
        ),
        None => format!("the {said} no servo-hydraulic test reaches"),
    }
}

/// A channel in SI without its isolated spikes: refused when the channel's
/// `repair` is not set, else replaced by their neighbours' line and
/// recorded in `repairs`. `dt_s` is the sample interval.
fn despiked(
    site: Site<'_>,
    dt_s: f64,
    channel: &'static str,
    plan: &ChannelPlan,
    mut v: Vec<f64>,
    repairs: &mut Vec<Repaired>,
) -> Result<Vec<f64>, IngestError> {
    let found = spikes::find(&v);
    let Some(first) = found.first() else {
        return Ok(v);
    };
    let (unit, si) = (plan.unit.symbol(), plan.unit.to_si());
    if plan.repair == Repair::None {
        return Err(IngestError::Spike(Box::new(SpikeFound {
            path: site.path.clone(),
            at: (site.locate)(first.index),
            sample: first.index,
            width: first.width,
            time_s: first.index as f64 * dt_s,
            channel,
            column: plan.column.to_string(),
            value: first.value / si,
            before: first.before / si,
            after: first.after / si,
            unit,
            ratio: first.ratio,
        })));
    }
    spikes::interpolate(&mut v, &found);
    repairs.extend(found.iter().map(|s| Repaired {
        channel: channel.to_string(),
        at: (site.locate)(s.index).to_string(),
        sample: s.index,
        time_s: s.index as f64 * dt_s,
        width: s.width,
        value: s.value,
        before: s.before,
        after: s.after,
    }));
    Ok(v)
}

/// Refuse a displacement or force that holds one value while it should
/// move (`ingest::held`): stuck, dropped to zero, or frozen with every
/// other channel.
fn check_held(
    site: Site<'_>,
    dt_s: f64,
    ch: &Channels,
    command: &[f64],
    displacement: &[f64],
    force: Option<&[f64]>,
) -> Result<(), IngestError> {
    let channels = [
        Some(("displacement", &ch.displacement, displacement)),
        ch.force.as_ref().zip(force).map(|(p, f)| ("force", p, f)),
    ];
    for (channel, plan, x) in channels.into_iter().flatten() {
        // A stretch held at the channel's extreme is the clip check's
        // (`check_log`): a rail, a quantised crest, or a step's level.
        let (lo, hi) = x
            .iter()
            .fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), &v| {
                (lo.min(v), hi.max(v))
            });
        let Some(h) = held::find(x)
            .into_iter()
            .find(|h| h.value != lo && h.value != hi)
        else {
            continue;
        };
        let others_hold = held::holds_over(command, h.start, h.len)
            && channels
                .iter()
                .flatten()
                .all(|(_, _, y)| held::holds_over(y, h.start, h.len));
        let entered_by_jump = h.start > 0 && x[h.start - 1] != h.value;
        let kind = if others_hold {
            HeldKind::Frozen
        } else if h.value == 0.0 && entered_by_jump {
            HeldKind::Dropout
        } else {
            HeldKind::Stuck
        };
        let si = plan.unit.to_si();
        return Err(IngestError::Held(Box::new(HeldFound {
            path: site.path.clone(),
            at: (site.locate)(h.start),
            sample: h.start,
            len: h.len,
            time_s: h.start as f64 * dt_s,
            dt_s,
            channel,
            column: plan.column.to_string(),
            kind,
            value: h.value / si,
            unit: plan.unit.symbol(),
            speed: h.speed / (si * dt_s),
        })));
    }
    Ok(())
}

/// One warning per channel whose spikes were repaired: how many, and the
/// first.
fn push_repair_warnings(path: &Path, repairs: &[Repaired], warnings: &mut Vec<Warning>) {
    for channel in ["command", "displacement", "force"] {
        let mut these = repairs.iter().filter(|r| r.channel == channel);
        if let Some(first) = these.next() {
            let count = 1 + these.count();
            warnings.push(Warning::new(
                format!(
                    "{count} spike(s) in the {channel} repaired, the first at t = {:.4} s",
                    first.time_s
                ),
                format!(
                    "{}: {count} isolated spike(s) in the {channel} replaced by their neighbours' line as channels.{channel}.repair asks, the first at {} (t = {:.4} s, {:e} where its neighbours read {:e} and {:e} in SI)",
                    path.display(),
                    first.at,
                    first.time_s,
                    first.value,
                    first.before,
                    first.after
                ),
            ));
        }
    }
}

/// Mean interval and jitter of time stamps `t` (s), and how they stand
/// against a uniform grid ([`Stamps`]); refuses time that goes back, and
/// repeated stamps but for rounding.
fn measure_timing(
    path: &Path,
    t: &[f64],
    locate: &dyn Fn(usize) -> At,
) -> Result<Timing, IngestError> {
    if t.len() < 2 {
        return Err(IngestError::TooShort {
            path: path.to_path_buf(),
            n: t.len(),
            min: 2,
            need: "a time base",
            advice: "the log has too few rows",
        });
    }
    let not_monotonic = |k: usize, kind| IngestError::NotMonotonic {
        path: path.to_path_buf(),
        at: locate(k + 1),
        prev_s: t[k],
        t_s: t[k + 1],
        kind,
    };
    if let Some(k) = t.windows(2).position(|w| w[1] < w[0]) {
        // In order again two stamps on: one stamp out of place.
        let swapped =
            t.get(k + 2).is_some_and(|&next| next > t[k]) && (k == 0 || t[k + 1] > t[k - 1]);
        let kind = if swapped {
            TimeFault::Swapped
        } else {
            TimeFault::Reset
        };
        return Err(not_monotonic(k, kind));
    }
    let intervals = (t.len() - 1) as f64;
    let mean_dt_s = (t[t.len() - 1] - t[0]) / intervals;
    let mut sum_sq = 0.0;
    let (mut jitter_max_s, mut worst) = (0.0_f64, 1);
    for (k, w) in t.windows(2).enumerate() {
        let dev = (w[1] - w[0]) - mean_dt_s;
        sum_sq += dev * dev;
        if dev.abs() > jitter_max_s {
            jitter_max_s = dev.abs();
            worst = k + 1;
        }
    }
    let repeated = t.windows(2).position(|w| w[1] == w[0]);
    let (mean_dt_s, stamps) = if jitter_max_s <= JITTER_WARN_FRACTION * mean_dt_s {
        (mean_dt_s, Stamps::Exact)
    } else {
        grid_of(t, jitter_max_s, locate)
    };
    if let Some(k) = repeated
        && !matches!(stamps, Stamps::Rounded { .. })
    {
        return Err(not_monotonic(k, TimeFault::Repeated));
    }
    Ok(Timing::Measured {
        mean_dt_s,
        jitter_rms_s: (sum_sq / intervals).sqrt(),
        jitter_max_s,
        worst_at: locate(worst),
        stamps,
    })
}

/// The uniform grid t0 + k dt fitted to stamps `t` by least squares, and
/// how the stamps stand against it: within half their own resolution
/// (rounded), within half an interval (scattered), or neither (uneven),
/// with the grid's interval, or the mean interval where they are uneven.
/// Scattered stamps keep every interval within half a grid interval of the
/// mean (`interval_max_s`): a longer one is a sample missing.
fn grid_of(t: &[f64], interval_max_s: f64, locate: &dyn Fn(usize) -> At) -> (f64, Stamps) {
    let n = t.len();
    let kbar = (n - 1) as f64 / 2.0;
    let tbar = t.iter().sum::<f64>() / n as f64;
    let (mut skt, mut skk) = (0.0, 0.0);
    for (k, &tk) in t.iter().enumerate() {
        let dk = k as f64 - kbar;
        skt += dk * (tk - tbar);
        skk += dk * dk;
    }
    let dt = skt / skk;
    let (mut max, mut sum_sq, mut worst) = (0.0_f64, 0.0, 0);
    for (k, &tk) in t.iter().enumerate() {
        let e = tk - tbar - dt * (k as f64 - kbar);
        sum_sq += e * e;
        if e.abs() > max {
            max = e.abs();
            worst = k;
        }
    }
    let mean = (t[n - 1] - t[0]) / (n - 1) as f64;
    // Rounding leaves each stamp within half a step of its true time; the
    // least-squares line is not the one that keeps them all within it, and
    // a tenth more allows for its error over a few thousand stamps.
    // Too few stamps cannot show a grid: a repeated one is then a fault.
    // Rounding moves each interval by less than a step, nearly always by
    // well under one (a missing sample moves one by a whole interval).
    let rounded = (n >= MIN_GRID_STAMPS)
        .then(|| stamp_resolution(t))
        .flatten()
        .filter(|&step| max <= 0.55 * step && interval_max_s < 0.9 * step);
    let stamps = match rounded {
        Some(resolution_s) => Stamps::Rounded { resolution_s },
        None if max <= 0.5 * dt && interval_max_s < 0.5 * dt => Stamps::Scattered {
            max_s: max,
            rms_s: (sum_sq / n as f64).sqrt(),
            worst_at: locate(worst),
        },
        None => return (mean, Stamps::Uneven),
    };
    (dt, stamps)
}

/// The fewest stamps whose grid is judged.
const MIN_GRID_STAMPS: usize = 16;

/// The step stamps `t` are rounded to: the smallest gap between them or a
/// whole fraction of it (up to a sixteenth), the coarsest on which every
/// stamp sits. Stamps rounded to 0.1 ms at 2048 Hz step 0.4 or 0.5 ms,
/// never 0.1 ms. None when they sit on no such grid.
fn stamp_resolution(t: &[f64]) -> Option<f64> {
    let gap = t
        .windows(2)
        .map(|w| w[1] - w[0])
        .filter(|d| *d > 0.0)
        .fold(f64::INFINITY, f64::min);
    if !gap.is_finite() {
        return None;
    }
    let t0 = t[0];
    (1..=16).map(|m| gap / m as f64).find(|&step| {
        t.iter().all(|&v| {
            let r = (v - t0) / step;
            (r - r.round()).abs() < 1e-3
        })
    })
}

/// Stamps scattered about their grid by more than this fraction of an
/// interval are worth a warning: the samples may be uneven, not only their
/// stamps.
const SCATTER_WARN_FRACTION: f64 = 0.01;

/// Jitter below this fraction of the interval is what printing time stamps
/// in decimal costs (a few ulps of t); above it a warning is worth giving.
const JITTER_WARN_FRACTION: f64 = 1e-6;

/// Judge whether `log` suits the analysis.
///
/// Errors: fewer than `needs.min_samples` samples; sample-interval jitter
/// above `needs.max_jitter_fraction` of the mean interval; a constant
/// channel; a displacement or force with more than `needs.clip_fraction` of
/// its samples exactly at its maximum or minimum that neither quantisation
/// nor a command holding still explains (`clipping`).
/// Warnings: jitter above 1e-6 of the interval but within tolerance; a
/// command limited at one level (it is what the valve received).
///
/// Returns every warning about the log: those found while reading
/// (`log.warnings`) followed by those of these checks.
pub fn check_log(log: &Log, needs: &Needs) -> Result<Vec<Warning>, IngestError> {
    if log.n_rows < needs.min_samples {
        return Err(IngestError::TooShort {
            path: log.path.clone(),
            n: log.n_rows,
            min: needs.min_samples,
            need: "identification.frf.segment_length",
            advice: "record this run longer, or leave segment_length out so that servoid chooses a segment for each log (a lower segment_length would change every run's FRF, and so the rig)",
        });
    }
    let mut warnings = log.warnings.clone();
    warnings.extend(check_timing(log, needs)?);
    warnings.extend(check_channels(log, needs)?);
    Ok(warnings)
}

/// What the time column says of the sampling: stamps scattered about
/// their grid (a warning beyond [`SCATTER_WARN_FRACTION`]), or intervals
/// that jitter (an error beyond `needs.max_jitter_fraction`, a warning
/// within it).
fn check_timing(log: &Log, needs: &Needs) -> Result<Vec<Warning>, IngestError> {
    let path = &log.path;
    let mut warnings = Vec::new();
    if let Timing::Measured {
        mean_dt_s,
        jitter_rms_s,
        jitter_max_s,
        worst_at,
        stamps,
    } = log.timing
    {
        match stamps {
            Stamps::Exact | Stamps::Rounded { .. } => {}
            Stamps::Scattered {
                max_s,
                rms_s,
                worst_at,
            } => {
                if max_s > SCATTER_WARN_FRACTION * mean_dt_s {
                    warnings.push(Warning::new(
                        format!(
                            "time stamps scatter up to {:.1} % of an interval about a {} Hz grid",
                            100.0 * max_s / mean_dt_s,
                            format_number(1.0 / mean_dt_s, 8)
                        ),
                        format!(
                        "{}: the time stamps scatter about a uniform grid by up to {:.1} % of an interval (rms {:.1} %, the largest at {worst_at}): the rate, {} Hz, is the grid's, fitted to all {} stamps, and the samples are taken as uniform, as a DAQ's clock samples; state channels.time.sample_rate_hz if the DAQ's rate is known",
                        path.display(),
                        100.0 * max_s / mean_dt_s,
                        100.0 * rms_s / mean_dt_s,
                        format_number(1.0 / mean_dt_s, 8),
                        log.n_rows
                    ),
                    ));
                }
            }
            Stamps::Uneven => {
                let fraction = jitter_max_s / mean_dt_s;
                if fraction > needs.max_jitter_fraction {
                    return Err(IngestError::Jitter {
                        path: path.clone(),
                        dt_s: mean_dt_s,
                        jitter_rms_s,
                        jitter_max_s,
                        worst_at,
                        fraction,
                        tolerance: needs.max_jitter_fraction,
                    });
                }
                warnings.push(Warning::new(
                    format!("sampling slightly uneven: intervals jitter up to {fraction:.1e} of the mean"),
                    format!(
                        "{}: sampling is slightly uneven: interval jitter max {jitter_max_s:.3e} s (interval ending at {worst_at}), rms {jitter_rms_s:.3e} s, against a mean interval of {mean_dt_s:.6e} s ({fraction:.3e} of it, within the tolerance {:e}); the analysis assumes uniform sampling",
                        path.display(),
                        needs.max_jitter_fraction
                    ),
                ));
            }
        }
    }
    Ok(warnings)
}

/// Each channel judged: none constant, a displacement or force not
/// clipped where its command does not hold, a command limited at a level
/// said.
fn check_channels(log: &Log, needs: &Needs) -> Result<Vec<Warning>, IngestError> {
    let path = &log.path;
    let mut warnings = Vec::new();
    let mut channels: Vec<(&'static str, &'static str, &[f64])> = vec![
        ("command", "m", &log.command_m),
        ("displacement", "m", &log.displacement_m),
    ];
    if let Some(f) = &log.force_n {
        channels.push(("force", "N", f));
    }
    for (channel, unit, x) in channels {
        // An unloaded force reads zero, or holds a coarse converter's code:
        // nothing to judge.
        if channel == "force" && !needs.force_loaded {
            continue;
        }
        // A constant channel sits at both extremes: "clipped at 0 m" for an
        // all-zero command misled; it is a missing signal.
        if let Some(&first) = x.first()
            && x.len() > 1
            && x.iter().all(|&v| v == first)
        {
            return Err(IngestError::Constant {
                path: path.clone(),
                channel,
                level: first,
                unit,
            });
        }
        if let Some(p) = clipping::plateau(x)
            && p.fraction > needs.clip_fraction
            && !clipping::quantised_crest(x, &p)
        {
            if channel == "command" {
                warnings.extend(limited_command(path, x, &p));
            } else if clipping::held_with_command(x, &log.command_m, &p) < 0.5 {
                return Err(IngestError::Clipped {
                    path: path.clone(),
                    channel,
                    which: p.which,
                    level: p.level,
                    unit,
                    fraction: p.fraction,
                    tolerance: needs.clip_fraction,
                });
            }
        }
    }
    Ok(warnings)
}

/// What to say of a command that holds one of its extremes beyond a
/// quantised crest: nothing for a step or square wave (its levels hold
/// nearly every sample, as the test intends); for a command limited at a
/// level, that it is analysed as the valve received it.
fn limited_command(path: &Path, u: &[f64], p: &clipping::Plateau) -> Option<Warning> {
    (clipping::at_levels(u) < STEP_LEVELS_SHARE).then(|| {
        let level = format_number(1e3 * p.level, 4);
        Warning::new(
            format!(
                "the command holds its {} {level} mm in {:.1} % of its samples: a limit set in the controller?",
                p.which,
                100.0 * p.fraction
            ),
            format!(
                "{}: the command holds its {} {level} mm in {:.1} % of its samples (a limit set in the controller?): it is analysed as the command the valve received",
                path.display(),
                p.which,
                100.0 * p.fraction
            ),
        )
    })
}

/// A command whose extremes and rest level hold this share of its samples
/// is a step or square wave.
const STEP_LEVELS_SHARE: f64 = 0.9;

/// Margin kept before the first and after the last excited sample (s): many
/// times the actuator's time constants (1/beta1 is tens of milliseconds), so
/// the response's onset and decay stay in the record.
pub const TRIM_MARGIN_S: f64 = 0.5;

/// Rest period at the start of the log whose mean is taken as the command's
/// rest level u0 (s).
pub const REST_WINDOW_S: f64 = 0.1;

/// Keep the excited part of a log.
///
/// The command's rest level u0 is the mean of its first [`REST_WINDOW_S`]
/// (at least one sample); a sample is excited where |u - u0| exceeds
/// `threshold_fraction` times the largest |u - u0| in the log. The result runs
/// from [`TRIM_MARGIN_S`] before the first excited sample to
/// [`TRIM_MARGIN_S`] after the last (clamped to the log), with every channel
/// cut alike, `t0_s` moved to the new first sample and `n_rows` updated. A
/// command that never leaves its rest level leaves the log whole, with a
/// warning added.
pub fn trim_to_excitation(log: &Log, threshold_fraction: f64) -> Log {
    let u = &log.command_m;
    let n = u.len();
    let mut out = log.clone();
    if n == 0 {
        return out;
    }
    let dt_s = 1.0 / log.sample_rate_hz;
    let rest = ((REST_WINDOW_S / dt_s).round() as usize).clamp(1, n);
    let u0 = u[..rest].iter().sum::<f64>() / rest as f64;
    let peak = u.iter().map(|x| (x - u0).abs()).fold(0.0, f64::max);
    let threshold = threshold_fraction * peak;
    let first = u.iter().position(|x| (x - u0).abs() > threshold);
    let last = u.iter().rposition(|x| (x - u0).abs() > threshold);
    let (Some(first), Some(last)) = (first, last) else {
        out.warnings.push(Warning::new(
            "the command never leaves its rest level: nothing trimmed",
            format!(
                "{}: the command never departs from its rest level {u0:e} m by more than {threshold_fraction} of its largest excursion ({peak:e} m); nothing trimmed",
                log.path.display()
            ),
        ));
        return out;
    };
    let margin = (TRIM_MARGIN_S / dt_s).round() as usize;
    let start = first.saturating_sub(margin);
    let end = (last + margin + 1).min(n);
    let cut = |v: &[f64]| v[start..end].to_vec();
    out.command_m = cut(&log.command_m);
    out.displacement_m = cut(&log.displacement_m);
    out.force_n = log.force_n.as_deref().map(cut);
    out.n_rows = end - start;
    out.t0_s = log.t0_s + start as f64 * dt_s;
    out
}

/// Comma-separated list of names for messages ("none" when empty).
fn list(names: impl IntoIterator<Item = impl fmt::Display>) -> String {
    let v: Vec<String> = names.into_iter().map(|n| n.to_string()).collect();
    if v.is_empty() {
        "none".into()
    } else {
        v.join(", ")
    }
}

/// Dimensions as MATLAB writes them: `300x2`.
fn dims(size: &[usize]) -> String {
    size.iter()
        .map(usize::to_string)
        .collect::<Vec<_>>()
        .join("x")
}

/// What a cut-short MAT element needs, for [`FormatProblem::CutShort`].
fn needed_bytes(needed: Option<usize>) -> String {
    needed.map_or_else(|| "an 8-byte tag and data".to_string(), |n| n.to_string())
}

/// Signals the ingest checks are tried on in their tests.
#[cfg(test)]
pub(crate) mod test_signals {
    /// `n` samples at 1 kHz of a 4 mm quadratic chirp from 0.1 Hz, rising
    /// 0.6 Hz a second.
    pub fn sweep(n: usize) -> Vec<f64> {
        (0..n)
            .map(|i| {
                let t = i as f64 / 1000.0;
                0.004 * (2.0 * std::f64::consts::PI * (0.1 * t + 0.3 * t * t)).sin()
            })
            .collect()
    }
}
