//! The declarative experiment manifest: one campaign on one rig.
//!
//! This module owns the manifest's types as the user writes them (TOML, or the
//! same structure in JSON). They are checked only for form here; `validate`
//! turns them into a [`Campaign`] whose values are known to be usable, and
//! `load` reads a file and reports every problem at once with its key path and,
//! for TOML, its line and column. `schemas/manifest.schema.json` is generated
//! from these types (`servoid schema`).

mod keypath;
mod load;
mod validate;

pub use keypath::{KeyPath, Seg};
pub use load::{ManifestError, Problem, load, load_str};
pub use validate::{
    Campaign, ChannelPlan, Channels as ResolvedChannels, FrfPlan, IdentificationPlan, LogPlan,
    Quantity, ReferencePlan, RunPlan, RunSource, SpecimenPlan, TimePlan,
};

use schemars::JsonSchema;
use serde::{Deserialize, Serialize};

use crate::model::RigParams;

/// The manifest format version this servoid reads.
pub const SCHEMA_VERSION: u32 = 1;

/// An experiment manifest: one test campaign on one rig.
#[derive(Debug, Clone, Serialize, Deserialize, JsonSchema)]
#[schemars(deny_unknown_fields)]
pub struct Manifest {
    /// Version of the manifest format (this servoid reads 1).
    pub schema_version: u32,
    pub campaign: CampaignInfo,
    pub rig: Rig,
    /// Default channel mapping of the logs; a run may override any channel.
    #[serde(default)]
    pub channels: Channels,
    /// How transfer functions are estimated and fitted.
    #[serde(default)]
    pub identification: Identification,
    /// The runs of the campaign, in the order results are written.
    pub runs: Vec<Run>,
    /// Published values to compare the results against.
    #[serde(default)]
    pub references: Vec<Reference>,
}

/// What the campaign is.
#[derive(Debug, Clone, Serialize, Deserialize, JsonSchema)]
#[schemars(deny_unknown_fields)]
pub struct CampaignInfo {
    /// Short name; also the default output folder under `reports/`
    /// (letters, digits, `.`, `_` and `-`).
    pub name: String,
    #[serde(default)]
    pub description: String,
}

/// The rig (hydraulic transfer system).
#[derive(Debug, Clone, Serialize, Deserialize, JsonSchema)]
#[schemars(deny_unknown_fields)]
pub struct Rig {
    pub name: String,
    /// Free-form notes: actuator, servo-valve, controller, sensors.
    #[serde(default)]
    pub notes: String,
    /// The rig's parameters when it was identified earlier; without them the
    /// campaign must identify the rig from a no-specimen run and spring runs.
    #[serde(default)]
    pub parameters: Option<RigParams>,
}

/// Mapping from log columns to the physical channels.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize, JsonSchema)]
#[schemars(deny_unknown_fields)]
pub struct Channels {
    /// Time base: a column, or a sampling rate (or, for DAQ text logs, the header).
    #[serde(default)]
    pub time: Option<TimeChannel>,
    /// Command displacement u sent to the controller.
    #[serde(default)]
    pub command: Option<Channel>,
    /// Measured actuator displacement x1.
    #[serde(default)]
    pub displacement: Option<Channel>,
    /// Measured actuator force f.
    #[serde(default)]
    pub force: Option<Channel>,
}

/// One measured channel: physical value = raw * scale + offset, in `unit`.
/// For a channel recorded in volts, `unit` is the calibrated unit and `scale`
/// the calibration (units per volt).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
#[schemars(deny_unknown_fields)]
pub struct Channel {
    /// Column name (or 0-based column index) in the log.
    pub column: Column,
    /// Unit of the scaled value.
    pub unit: Unit,
    #[serde(default = "one")]
    pub scale: f64,
    #[serde(default)]
    pub offset: f64,
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

/// The time base of a log.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
#[schemars(deny_unknown_fields)]
pub struct TimeChannel {
    /// Column holding time stamps.
    #[serde(default)]
    pub column: Option<Column>,
    /// Unit of the time column.
    #[serde(default)]
    pub unit: Option<TimeUnit>,
    /// Uniform sampling rate (Hz), when the log has no time column.
    #[serde(default)]
    pub sample_rate_hz: Option<f64>,
}

/// Physical units a channel may be given in; converted to SI once, at ingest.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, JsonSchema)]
pub enum Unit {
    #[serde(rename = "m")]
    Meter,
    #[serde(rename = "cm")]
    Centimeter,
    #[serde(rename = "mm")]
    Millimeter,
    #[serde(rename = "in")]
    Inch,
    #[serde(rename = "N")]
    Newton,
    #[serde(rename = "kN")]
    Kilonewton,
    #[serde(rename = "lbf")]
    PoundForce,
}

/// What a unit measures.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum UnitKind {
    Length,
    Force,
}

impl Unit {
    /// Factor to the SI unit (m or N).
    pub fn to_si(self) -> f64 {
        match self {
            Unit::Meter => 1.0,
            Unit::Centimeter => 1e-2,
            Unit::Millimeter => 1e-3,
            Unit::Inch => 0.0254,
            Unit::Newton => 1.0,
            Unit::Kilonewton => 1e3,
            // 1 lbf = 0.45359237 kg * 9.80665 m/s^2 (exact by definition).
            Unit::PoundForce => 4.448_221_615_260_5,
        }
    }

    pub fn kind(self) -> UnitKind {
        match self {
            Unit::Meter | Unit::Centimeter | Unit::Millimeter | Unit::Inch => UnitKind::Length,
            Unit::Newton | Unit::Kilonewton | Unit::PoundForce => UnitKind::Force,
        }
    }

    pub fn symbol(self) -> &'static str {
        match self {
            Unit::Meter => "m",
            Unit::Centimeter => "cm",
            Unit::Millimeter => "mm",
            Unit::Inch => "in",
            Unit::Newton => "N",
            Unit::Kilonewton => "kN",
            Unit::PoundForce => "lbf",
        }
    }
}

/// Unit of a time column.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, JsonSchema)]
pub enum TimeUnit {
    #[serde(rename = "s")]
    Second,
    #[serde(rename = "ms")]
    Millisecond,
}

impl TimeUnit {
    pub fn to_si(self) -> f64 {
        match self {
            TimeUnit::Second => 1.0,
            TimeUnit::Millisecond => 1e-3,
        }
    }
}

/// Identification options (defaults suit a chirp logged at 1-2 kHz).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
#[schemars(deny_unknown_fields)]
pub struct Identification {
    /// Frequency band (Hz) the transfer functions are fitted over.
    #[serde(default = "default_band")]
    pub band_hz: [f64; 2],
    /// Bins whose coherence is below this are left out of the fit.
    #[serde(default = "default_coherence")]
    pub coherence_min: f64,
    #[serde(default)]
    pub frf: FrfSettings,
    /// How the command reaches the plant between samples: a D/A converter
    /// holds each sample (a half-sample delay), or the log is already continuous.
    #[serde(default)]
    pub command_intersample: Intersample,
    #[serde(default)]
    pub delay: DelaySettings,
    /// Orders of the fitted model n(s)/d(s); the paper's procedure uses 0/2.
    #[serde(default)]
    pub model: ModelOrders,
    /// Trim each log to where the command has energy before estimating.
    #[serde(default)]
    pub trim_to_excitation: bool,
}

impl Default for Identification {
    fn default() -> Self {
        Self {
            band_hz: default_band(),
            coherence_min: default_coherence(),
            frf: FrfSettings::default(),
            command_intersample: Intersample::default(),
            delay: DelaySettings::default(),
            model: ModelOrders::default(),
            trim_to_excitation: false,
        }
    }
}

/// Frequency-response estimation settings.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
#[schemars(deny_unknown_fields)]
pub struct FrfSettings {
    #[serde(default)]
    pub estimator: Estimator,
    /// Samples per Welch segment.
    #[serde(default = "default_segment")]
    pub segment_length: usize,
    /// Fraction of a segment shared with the next, in [0, 1).
    #[serde(default = "default_overlap")]
    pub overlap: f64,
    #[serde(default)]
    pub window: Window,
    #[serde(default)]
    pub detrend: Detrend,
}

impl Default for FrfSettings {
    fn default() -> Self {
        Self {
            estimator: Estimator::default(),
            segment_length: default_segment(),
            overlap: default_overlap(),
            window: Window::default(),
            detrend: Detrend::default(),
        }
    }
}

/// FRF estimator.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Serialize, Deserialize, JsonSchema)]
#[serde(rename_all = "snake_case")]
pub enum Estimator {
    /// Welch H1 = Syu/Suu (noise on the output).
    #[default]
    H1,
    /// Welch H2 = Syy/Suy (noise on the input).
    H2,
    /// Empirical transfer-function estimate Y/U over the whole record.
    Etfe,
}

/// Window applied to each segment.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Serialize, Deserialize, JsonSchema)]
#[serde(rename_all = "snake_case")]
pub enum Window {
    #[default]
    Hann,
    Hamming,
    BlackmanHarris,
    Rectangular,
}

/// Trend removed from each segment.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Serialize, Deserialize, JsonSchema)]
#[serde(rename_all = "snake_case")]
pub enum Detrend {
    None,
    #[default]
    Mean,
    Linear,
}

/// Intersample behaviour of the logged command.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Serialize, Deserialize, JsonSchema)]
#[serde(rename_all = "snake_case")]
pub enum Intersample {
    /// Played through a D/A converter that holds each sample.
    #[default]
    SampleAndHold,
    /// No hold modelled.
    None,
}

/// Pure delay in the fitted model (sensor and conditioning delays).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
#[schemars(deny_unknown_fields)]
pub struct DelaySettings {
    #[serde(default)]
    pub mode: DelayMode,
    /// Known delay (s) when `mode = "fixed"`.
    #[serde(default)]
    pub value_s: f64,
    /// Upper bound (s) on a fitted delay.
    #[serde(default = "default_max_delay")]
    pub max_s: f64,
}

impl Default for DelaySettings {
    fn default() -> Self {
        Self {
            mode: DelayMode::default(),
            value_s: 0.0,
            max_s: default_max_delay(),
        }
    }
}

/// How a pure delay is handled.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Serialize, Deserialize, JsonSchema)]
#[serde(rename_all = "snake_case")]
pub enum DelayMode {
    #[default]
    None,
    Fixed,
    Fit,
}

/// Orders of the fitted transfer function.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize, JsonSchema)]
#[schemars(deny_unknown_fields)]
pub struct ModelOrders {
    #[serde(default)]
    pub numerator: usize,
    #[serde(default = "two")]
    pub denominator: usize,
}

impl Default for ModelOrders {
    fn default() -> Self {
        Self {
            numerator: 0,
            denominator: 2,
        }
    }
}

/// One run of the campaign.
#[derive(Debug, Clone, Serialize, Deserialize, JsonSchema)]
#[schemars(deny_unknown_fields)]
pub struct Run {
    /// Unique id (letters, digits, `.`, `_` and `-`).
    pub id: String,
    pub role: Role,
    #[serde(default)]
    pub description: String,
    /// Proportional gain of the analog controller in this run.
    pub p_gain: f64,
    /// The physical specimen; omit for `no_specimen` runs.
    #[serde(default)]
    pub specimen: Option<Specimen>,
    /// The run's data: a log file, or a published transfer function.
    #[serde(default)]
    pub data: Option<RunData>,
    /// Channel overrides for this run's log (each given channel replaces the default).
    #[serde(default)]
    pub channels: Option<Channels>,
    /// Fit band (Hz) for this run, overriding `identification.band_hz`.
    #[serde(default)]
    pub band_hz: Option<[f64; 2]>,
}

/// What a run is for.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, JsonSchema)]
#[serde(rename_all = "snake_case")]
pub enum Role {
    /// The actuator alone: gives beta1 and R1 (Eq. 18).
    NoSpecimen,
    /// A massless linear spring: gives R2 and R3 (Eq. 19).
    Spring,
    /// A specimen whose measured response is compared with the model's prediction.
    Validation,
    /// A transfer-function fit only, not used for the rig parameters
    /// (e.g. a specimen the paper's procedure does not cover).
    Fit,
}

impl Role {
    pub fn as_str(self) -> &'static str {
        match self {
            Role::NoSpecimen => "no_specimen",
            Role::Spring => "spring",
            Role::Validation => "validation",
            Role::Fit => "fit",
        }
    }
}

/// The physical specimen. Springs give `stiffness_n_per_m`; a linear SDOF
/// specimen gives `mass_kg`, `damping_ns_per_m` and `stiffness_n_per_m`.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize, JsonSchema)]
#[schemars(deny_unknown_fields)]
pub struct Specimen {
    /// Specimen model; `linear` unless a nonlinear model is named.
    #[serde(default)]
    pub model: SpecimenModel,
    #[serde(default)]
    pub mass_kg: Option<f64>,
    #[serde(default)]
    pub damping_ns_per_m: Option<f64>,
    #[serde(default)]
    pub stiffness_n_per_m: Option<f64>,
}

/// Specimen models servoid knows.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Serialize, Deserialize, JsonSchema)]
#[serde(rename_all = "snake_case")]
pub enum SpecimenModel {
    #[default]
    Linear,
}

/// A run's data.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize, JsonSchema)]
#[schemars(deny_unknown_fields)]
pub struct RunData {
    /// Log file, relative to the manifest's folder.
    #[serde(default)]
    pub log: Option<String>,
    /// Log format; inferred from the extension when omitted.
    #[serde(default)]
    pub format: Option<LogFormat>,
    /// Options for delimited text logs.
    #[serde(default)]
    pub csv: Option<CsvOptions>,
    /// SHA-256 of the log (hex); when given, a log that differs is refused.
    #[serde(default)]
    pub sha256: Option<String>,
    /// A published transfer function, when only the fitted model is known.
    #[serde(default)]
    pub transfer_function: Option<PublishedTf>,
}

/// Log file formats.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, JsonSchema)]
#[serde(rename_all = "snake_case")]
pub enum LogFormat {
    /// Delimited text with a header line (`.csv`, `.tsv`).
    Csv,
    /// Apache Parquet (`.parquet`).
    Parquet,
    /// MATLAB level-5 MAT-file (`.mat`), as real-time targets save logs.
    Mat,
    /// DAQ text export: a header block with the sampling rate, then
    /// `Sample Number, Date/Time, CHANNEL0, ..., Events` (`.txt`).
    DaqText,
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
}

/// A transfer function num(s)/den(s) exp(-s delay_s), highest power first.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
#[schemars(deny_unknown_fields)]
pub struct PublishedTf {
    pub num: Vec<f64>,
    pub den: Vec<f64>,
    #[serde(default)]
    pub delay_s: f64,
    /// Where it was published (e.g. "Eq. 36").
    #[serde(default)]
    pub source: String,
}

/// A published number to compare with the computed one.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
#[schemars(deny_unknown_fields)]
pub struct Reference {
    /// What is compared: `rig.beta1`, `rig.R1`, `rig.a1b0`, `rig.a2`, `rig.a3`,
    /// `rig.valve_time_constant_ms`, `per_spring.<run>.{R2,R3,a1b0,a2,a3}`,
    /// `runs.<run>.{a1b0,natural_frequency_hz,nrmse_pct,nae_pct}`,
    /// `ccf.<run>.{C1,C2,C3,C4,C5}`.
    pub quantity: String,
    pub published: f64,
    /// Where it was published (e.g. "Table 3").
    #[serde(default)]
    pub source: String,
    /// `signed`, or `magnitude` where the publication lost the sign.
    #[serde(default)]
    pub compare: CompareMode,
    /// Relative difference [%] above which the comparison is flagged.
    #[serde(default = "one")]
    pub tolerance_pct: f64,
}

/// How a published number is compared.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Serialize, Deserialize, JsonSchema)]
#[serde(rename_all = "snake_case")]
pub enum CompareMode {
    #[default]
    Signed,
    Magnitude,
}

fn one() -> f64 {
    1.0
}
fn two() -> usize {
    2
}
fn yes() -> bool {
    true
}
fn comma() -> String {
    ",".into()
}
fn default_band() -> [f64; 2] {
    [0.5, 30.0]
}
fn default_coherence() -> f64 {
    0.8
}
fn default_segment() -> usize {
    8192
}
fn default_overlap() -> f64 {
    0.5
}
fn default_max_delay() -> f64 {
    0.02
}
