//! What ingest is asked to read: a [`LogPlan`] names the file, its format,
//! the columns of each channel and their conversion to SI. The manifest
//! builds it (its `data` and `channels` tables use [`Column`], [`LogFormat`]
//! and [`CsvOptions`] as written).

use std::path::{Path, PathBuf};

use schemars::JsonSchema;
use serde::{Deserialize, Serialize};

use crate::units::Unit;

/// A log to ingest, with its channels resolved.
#[derive(Debug, Clone, PartialEq)]
pub struct LogPlan {
    pub path: PathBuf,
    pub format: LogFormat,
    pub csv: CsvOptions,
    pub sha256: Option<String>,
    pub channels: Channels,
    /// The largest log read (bytes): `[limits] max_log_mib`.
    pub max_bytes: u64,
}

/// The default of `[limits] max_log_mib`: 4 GiB. A log is read whole, and
/// parsing takes a few times its size in memory (a 1 GB CSV took 4.5 GB),
/// so a larger one would exhaust a lab workstation's memory rather than be
/// analysed.
pub const DEFAULT_MAX_LOG_MIB: u64 = 4096;

/// A run's channels, defaults and overrides merged, with SI conversion.
#[derive(Debug, Clone, PartialEq)]
pub struct Channels {
    pub time: TimePlan,
    pub command: ChannelPlan,
    pub displacement: ChannelPlan,
    pub force: Option<ChannelPlan>,
}

/// How to get the time base.
#[derive(Debug, Clone, PartialEq)]
pub enum TimePlan {
    Column {
        column: Column,
        to_s: f64,
    },
    SampleRate {
        hz: f64,
    },
    /// The log's own header gives the rate (DAQ text, MAT).
    FromLog,
}

/// One channel: SI value = raw * gain + offset.
#[derive(Debug, Clone, PartialEq)]
pub struct ChannelPlan {
    pub column: Column,
    /// The unit the manifest gave.
    pub unit: Unit,
    /// scale * unit-to-SI.
    pub gain: f64,
    /// offset * unit-to-SI.
    pub offset: f64,
    /// The instrument's range in SI (the manifest's `range`), when given.
    pub range: Option<(f64, f64)>,
    /// What to do with an isolated spike (`ingest::spikes`).
    pub repair: Repair,
}

/// What ingest does with a channel's isolated spikes.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Serialize, Deserialize, JsonSchema)]
#[serde(rename_all = "snake_case")]
pub enum Repair {
    /// Fail the run, naming the sample.
    #[default]
    None,
    /// Replace each by the straight line between its neighbours, and
    /// record it in results.json.
    Interpolate,
}

impl Repair {
    pub fn is_none(&self) -> bool {
        *self == Repair::None
    }
}

/// A column by name or by 0-based index.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(untagged)]
pub enum Column {
    Name(String),
    Index(usize),
}

impl std::fmt::Display for Column {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Column::Name(n) => write!(f, "`{n}`"),
            Column::Index(i) => write!(f, "#{i}"),
        }
    }
}

/// Log file formats.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, JsonSchema)]
#[serde(rename_all = "snake_case")]
pub enum LogFormat {
    /// Delimited text with a header line (`.csv`, `.tsv`).
    Csv,
    /// Apache Parquet (`.parquet`).
    Parquet,
    /// MATLAB MAT-file (`.mat`), as real-time targets save logs: level 5
    /// (v5, v7) or v7.3 (HDF5).
    Mat,
    /// DAQ text export: a header block with the sampling rate, then
    /// `Sample Number, Date/Time, CHANNEL0, ..., Events` (`.txt`).
    DaqText,
    /// HDF5 (`.h5`, `.hdf5`): each channel a dataset.
    Hdf5,
    /// NI TDMS (`.tdms`): each channel `Group/Channel`.
    Tdms,
}

impl LogFormat {
    /// The extensions [`LogFormat::from_path`] knows, as messages list them.
    pub const EXTENSIONS: &'static str =
        ".csv, .tsv, .parquet, .pq, .mat, .txt, .h5, .hdf5 or .tdms";

    /// The format a log's extension names (`.csv`, `.tsv`, `.parquet`,
    /// `.pq`, `.mat`, `.txt`, `.h5`, `.hdf5`, `.tdms`, in any case), if it
    /// names one.
    pub fn from_path(path: &Path) -> Option<Self> {
        let ext = path.extension()?.to_str()?.to_ascii_lowercase();
        match ext.as_str() {
            "csv" | "tsv" => Some(LogFormat::Csv),
            "parquet" | "pq" => Some(LogFormat::Parquet),
            "mat" => Some(LogFormat::Mat),
            "txt" => Some(LogFormat::DaqText),
            "h5" | "hdf5" => Some(LogFormat::Hdf5),
            "tdms" => Some(LogFormat::Tdms),
            _ => None,
        }
    }
}

/// Options for delimited text logs.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
#[schemars(deny_unknown_fields)]
pub struct CsvOptions {
    /// Field delimiter (one character).
    #[serde(default = "comma")]
    pub delimiter: String,
    /// Lines skipped before the header.
    #[serde(default)]
    pub skip_lines: usize,
    /// Lines starting with this are ignored.
    #[serde(default)]
    pub comment_prefix: Option<String>,
    /// Whether the first line (after skipped lines) names the columns.
    #[serde(default = "yes")]
    pub header: bool,
    /// The decimal mark: "." or "," (European exports, which then delimit
    /// fields with ";").
    #[serde(default = "point")]
    pub decimal: String,
}

impl Default for CsvOptions {
    fn default() -> Self {
        Self {
            delimiter: comma(),
            skip_lines: 0,
            comment_prefix: None,
            header: yes(),
            decimal: point(),
        }
    }
}

fn point() -> String {
    ".".into()
}

fn comma() -> String {
    ",".into()
}

fn yes() -> bool {
    true
}
