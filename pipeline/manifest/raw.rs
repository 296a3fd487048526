//! The campaign manifest as the user writes it (TOML, or the same structure
//! in JSON): these types are checked only for form, by serde; `campaign`
//! turns them into a checked [`super::Campaign`].
//! `schemas/manifest.schema.json` is generated from them (`servoid schema`).

use std::sync::OnceLock;

use schemars::JsonSchema;
use serde::{Deserialize, Serialize};
use serde_json::Value;

use crate::fit::Intersample;
use crate::frf::{Detrend, Estimator, Window};
use crate::ingest::{Column, CsvOptions, LogFormat, Repair, TableFormat};
use crate::model::RigParams;
use crate::units::{TimeUnit, Unit};

/// The campaign manifest's JSON Schema (cached: the loader consults it for
/// key suggestions).
pub fn manifest_schema() -> Value {
    static CACHE: OnceLock<Value> = OnceLock::new();
    CACHE
        .get_or_init(|| {
            serde_json::to_value(schemars::schema_for!(Manifest)).expect("schema serialises")
        })
        .clone()
}

/// The manifest format version this servoid reads.
pub const SCHEMA_VERSION: u32 = 1;

/// An experiment manifest: one test campaign on one rig.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
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
    /// The runs of the campaign, in the order results are written (before
    /// those of `run_table`).
    #[serde(default)]
    pub runs: Vec<Run>,
    /// Published values to compare the results against.
    #[serde(default)]
    pub references: Vec<Reference>,
    /// More runs, one per row of a side table, after those of `runs`.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub run_table: Option<RunTable>,
    /// Where the rig's history is kept and when its drift raises an alarm
    /// (defaults apply when the table is absent).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub history: Option<History>,
    /// The stiffness sensitivity's sweep and the precision it recommends
    /// springs for (defaults apply when the table is absent).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub sensitivity: Option<SensitivitySettings>,
    /// The model-based compensator designed for each validation run's
    /// specimen (defaults apply when the table is absent).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub compensator: Option<CompensatorSettings>,
    /// Resource limits (defaults apply when the table is absent).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub limits: Option<Limits>,
    /// What the job writes besides results.json (defaults apply when the
    /// table is absent).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub report: Option<ReportSettings>,
    /// What `servoid design` keeps the next night within (the command
    /// line's flags override each).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub design: Option<DesignSettings>,
    /// A publication's figures by their numbers (the paper's Fig. 8, ...),
    /// each standing for one the campaign draws.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub numbered_figures: Vec<NumberedFigure>,
}

/// A publication's figure by its number: a copy of the campaign's figure
/// that stands for it, written as `figures/fig-<number>.png` (and `.svg`,
/// as the figures are drawn) and shown on the campaign page with its
/// caption; or a figure the campaign cannot draw, with why.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
#[schemars(deny_unknown_fields)]
pub struct NumberedFigure {
    /// Its number as the publication gives it, digits and an optional
    /// letter (`8`, `16a`); the file is `fig-08`, `fig-16a`.
    pub number: String,
    /// The campaign's figure that stands for it: the stem of its file under
    /// `figures/` (`frf-no-specimen`). Absent where `not_drawn` says why.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub figure: Option<String>,
    /// What it shows, and what differs from the publication's.
    pub caption: String,
    /// Why the campaign draws no counterpart (a photograph, a block
    /// diagram).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub not_drawn: Option<String>,
}

impl NumberedFigure {
    /// The file stem: `fig-` and the number, its digits padded to two.
    pub fn stem(&self) -> String {
        let digits = self.number.chars().take_while(char::is_ascii_digit).count();
        format!(
            "fig-{:0>2}{}",
            &self.number[..digits],
            &self.number[digits..]
        )
    }
}

/// The feedforward compensator designed on the identified plant with each
/// validation run's specimen: its inverse made proper by a Butterworth
/// low-pass, with a phase lead (docs/tracking.md).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
#[schemars(deny_unknown_fields)]
pub struct CompensatorSettings {
    /// The low-pass's cut-off in Hz (> 0, below 0.4 of each log's rate);
    /// by default 8 times the top of the run's band.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub cutoff_hz: Option<f64>,
    /// Whether to make up the delay the low-pass, the hold and the plant
    /// leave by extrapolating the command ahead (a cubic through the last
    /// four samples).
    #[serde(default = "default_lead")]
    pub lead: bool,
}

impl Default for CompensatorSettings {
    fn default() -> Self {
        Self {
            cutoff_hz: None,
            lead: default_lead(),
        }
    }
}

fn default_lead() -> bool {
    true
}

/// Which figures a job draws, and as which files, beside the pages that
/// show them (PNG where there is one, else SVG). The command line's
/// `--figures` and the manifest's `report.figures` take the same names
/// (lowercase), with these lines as their help.
#[derive(
    Debug,
    Clone,
    Copy,
    Default,
    PartialEq,
    Eq,
    serde::Serialize,
    serde::Deserialize,
    schemars::JsonSchema,
    clap::ValueEnum,
)]
#[serde(rename_all = "lowercase")]
pub enum FigureFormats {
    /// Every figure, as PNG and SVG files.
    #[default]
    All,
    /// Every figure, as PNG files.
    Png,
    /// Every figure, as SVG files.
    Svg,
    /// What a morning's look at a night needs, as PNG files: the
    /// campaign's own figures and each run's FRF, with a validation run's
    /// time windows.
    Summary,
    /// No figure is drawn at all.
    None,
}

/// What a job writes besides results.json.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize, JsonSchema)]
#[schemars(deny_unknown_fields)]
pub struct ReportSettings {
    /// Which figures are drawn, and as which files; the command line's
    /// `--figures` overrides it. Default: `summary`, or `all` for a
    /// campaign that numbers a publication's figures (`numbered_figures`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub figures: Option<FigureFormats>,
}

/// Resource limits of a job.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
#[schemars(deny_unknown_fields)]
pub struct Limits {
    /// The largest log read, in MiB (a log is read whole; parsing a CSV
    /// takes a few times its size in memory). Larger ones fail their run.
    #[serde(default = "default_max_log_mib")]
    pub max_log_mib: u64,
}

impl Default for Limits {
    fn default() -> Self {
        Self {
            max_log_mib: default_max_log_mib(),
        }
    }
}

fn default_max_log_mib() -> u64 {
    crate::ingest::DEFAULT_MAX_LOG_MIB
}

/// The limits and times `servoid design` plans the next night within.
/// Each one absent is taken from the campaign's results (the command's
/// peak, each run's record, the band, the rate, the noise) or not applied
/// (the stroke, the velocity, the force). A design from a manifest's
/// nominal `rig.parameters` has no results: it needs the command's peak,
/// the time per run (or the night's), the rate and the noise.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize, JsonSchema)]
#[schemars(deny_unknown_fields)]
pub struct DesignSettings {
    /// The command's largest magnitude (m).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub command_m: Option<f64>,
    /// The actuator's stroke: the predicted displacement stays within
    /// +-this (m).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub stroke_m: Option<f64>,
    /// The peak velocity: the valve's rated flow over the piston area
    /// (m/s).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub velocity_m_per_s: Option<f64>,
    /// The peak force on the specimen (N).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub force_n: Option<f64>,
    /// The band of interest [low, high] (Hz).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub band_hz: Option<[f64; 2]>,
    /// The time each run may take, its rest included (s).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub run_s: Option<f64>,
    /// The time the night's identification runs may take together (s),
    /// shared equally.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub night_s: Option<f64>,
    /// The worst relative std to reach (0.001 for 0.1 %): the runs are
    /// then as long as it needs.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub target_relative_std: Option<f64>,
    /// The DAQ's rate (Hz), the commands' too.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub sample_rate_hz: Option<f64>,
    /// The displacement channel's noise (m RMS at the DAQ's rate), taken
    /// as white; in place of the noise the results measured.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub displacement_noise_m: Option<f64>,
}

impl DesignSettings {
    /// These settings, each absent one taken from `under`.
    pub fn or(self, under: Option<&DesignSettings>) -> DesignSettings {
        let Some(u) = under else {
            return self;
        };
        DesignSettings {
            command_m: self.command_m.or(u.command_m),
            stroke_m: self.stroke_m.or(u.stroke_m),
            velocity_m_per_s: self.velocity_m_per_s.or(u.velocity_m_per_s),
            force_n: self.force_n.or(u.force_n),
            band_hz: self.band_hz.or(u.band_hz),
            run_s: self.run_s.or(u.run_s),
            night_s: self.night_s.or(u.night_s),
            target_relative_std: self.target_relative_std.or(u.target_relative_std),
            sample_rate_hz: self.sample_rate_hz.or(u.sample_rate_hz),
            displacement_noise_m: self.displacement_noise_m.or(u.displacement_noise_m),
        }
    }
}

/// The stiffness sensitivity (paper Sec. 2.3): which stiffnesses to sweep
/// and the relative standard deviation the recommendation aims at.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
#[schemars(deny_unknown_fields)]
pub struct SensitivitySettings {
    /// [low, high] in N/m, 0 < low < high; by default 0.01 to 10 times the
    /// identified rig's a2.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub stiffness_range_n_per_m: Option<[f64; 2]>,
    /// Stiffnesses in the sweep, log-spaced (at least 2).
    #[serde(default = "default_points")]
    pub points: usize,
    /// The relative standard deviation (fraction, > 0) the recommendation
    /// finds springs for; 0.01 is 1 %.
    #[serde(default = "default_target_rel_std")]
    pub target_rel_std: f64,
    /// The Monte Carlo beside the analytic sweep, over the same range: the
    /// no-specimen log's command replayed through the identified rig with
    /// the campaign's measured noise, identified as the campaign is. Off
    /// when absent; `monte_carlo = {}` turns it on with its defaults.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub monte_carlo: Option<MonteCarloSettings>,
}

impl Default for SensitivitySettings {
    fn default() -> Self {
        Self {
            stiffness_range_n_per_m: None,
            points: default_points(),
            target_rel_std: default_target_rel_std(),
            monte_carlo: None,
        }
    }
}

/// The stiffness sensitivity's Monte Carlo.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
#[schemars(deny_unknown_fields)]
pub struct MonteCarloSettings {
    /// Stiffnesses, log-spaced over the sweep's range (at least 2).
    #[serde(default = "default_mc_points")]
    pub points: usize,
    /// Simulated identifications per stiffness (at least 1; 50 gives each
    /// std to about 10 %).
    #[serde(default = "default_mc_seeds")]
    pub seeds: u64,
    /// The base seed of the noise; the same seed gives the same numbers.
    #[serde(default)]
    pub seed: u64,
}

impl Default for MonteCarloSettings {
    fn default() -> Self {
        Self {
            points: default_mc_points(),
            seeds: default_mc_seeds(),
            seed: 0,
        }
    }
}

fn default_mc_points() -> usize {
    20
}

fn default_mc_seeds() -> u64 {
    50
}

fn default_points() -> usize {
    61
}

fn default_target_rel_std() -> f64 {
    0.01
}

/// The rig's history: every campaign adds its identified (or given) rig to
/// a Parquet table, and a parameter that moves from the median of its last
/// `window` entries by more than `threshold` times the larger of its own
/// standard deviation and the history's scatter raises an alarm (exit code
/// 3).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
#[schemars(deny_unknown_fields)]
pub struct History {
    /// The history table, relative to the manifest's folder; by default
    /// `history.parquet` in the output folder.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub file: Option<String>,
    /// K: the entries the median is taken over (at least 3).
    #[serde(default = "default_window")]
    pub window: usize,
    /// N: how many standard deviations a parameter may move.
    #[serde(default = "default_threshold")]
    pub threshold: f64,
}

impl Default for History {
    fn default() -> Self {
        Self {
            file: None,
            window: default_window(),
            threshold: default_threshold(),
        }
    }
}

fn default_window() -> usize {
    10
}

fn default_threshold() -> f64 {
    4.0
}

/// Runs named by a side table instead of one `[[runs]]` table each, as a
/// nightly batch over new logs writes them. The table has a header line of
/// column names: `id`, `role` and `p_gain` (required), `mass_kg`,
/// `damping_ns_per_m` and `stiffness_n_per_m` (as the role needs), `date`
/// (ISO 8601) and `log` (a path relative to the table's folder); an empty
/// cell is an absent value. The campaign's `channels` and `identification`
/// apply to every row.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
#[schemars(deny_unknown_fields)]
pub struct RunTable {
    /// The table, relative to the manifest's folder.
    pub file: String,
    /// Table format; inferred from the extension (`.csv`, `.parquet`, `.pq`)
    /// when omitted.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub format: Option<TableFormat>,
    /// Where the logs are, relative to the manifest's folder: a glob
    /// (`logs/*.parquet`) or a folder (every file in it with a log extension:
    /// csv, tsv, parquet, pq, mat, txt, h5, hdf5, tdms); hidden files (`.name`) are left out.
    /// A row without a `log` cell takes the matched file whose stem is its
    /// id; when there is none, its run fails alone (the log is not there
    /// yet), and a matched file no run uses is a warning.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub logs: Option<String>,
    /// A CSV table's field delimiter (one character: `,`, `;`, `\t`, ...);
    /// detected when omitted: tab for a `.tsv` file, else the one of `,`,
    /// `;` and tab its header line holds.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub delimiter: Option<String>,
    /// A CSV table's decimal mark, `.` or `,`; detected when omitted (a
    /// comma when the delimiter is not one, some number is written `4,5`
    /// and none `4.5`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub decimal: Option<String>,
    /// Whether a validation row without a log (no `log` cell, no `logs`)
    /// is a prediction from the rig model, as a `[[runs]]` validation run
    /// without data is: a table of specimens to predict. Without it such a
    /// row is a problem, as a spring's is: a night's validation that reads
    /// no log must not pass as done.
    #[serde(default, skip_serializing_if = "std::ops::Not::not")]
    pub predict: bool,
}

/// What the campaign is.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
#[schemars(deny_unknown_fields)]
pub struct CampaignInfo {
    /// Short name; also the default output folder under `reports/`
    /// (letters, digits, `.`, `_` and `-`).
    pub name: String,
    /// Free-form description, shown on the report.
    #[serde(default)]
    pub description: String,
    /// Set when the logs are synthetic: how they were made (shown as a banner
    /// in the report). `servoid simulate` writes it.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub synthetic: Option<String>,
}

/// The rig (hydraulic transfer system).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
#[schemars(deny_unknown_fields)]
pub struct Rig {
    /// The rig's name: the history and the drift alarm follow a rig by it.
    pub name: String,
    /// Free-form notes: actuator, servo-valve, controller, sensors.
    #[serde(default)]
    pub notes: String,
    /// The rig's parameters when it was identified earlier; without them the
    /// campaign must identify the rig from a no-specimen run and spring runs.
    #[serde(default)]
    pub parameters: Option<RigParams>,
    /// Supply pressure P_s (Pa) from the nameplate, with `piston_area_m2`:
    /// the servo-valve's flow falls with the load pressure as
    /// sqrt(1 - sign(r) f / F_max), F_max = A P_s (docs/model.md). The joint
    /// fit starts the law at this F_max and holds it there where the runs
    /// do not determine it; without the nameplate the law is fitted only
    /// where the loaded runs show it.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub supply_pressure_pa: Option<f64>,
    /// Piston area A (m^2) from the nameplate, with `supply_pressure_pa`.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub piston_area_m2: Option<f64>,
}

impl Rig {
    /// The nameplate's F_max = A P_s (N), when the manifest gives both.
    pub fn max_force_n(&self) -> Option<f64> {
        Some(self.piston_area_m2? * self.supply_pressure_pa?)
    }
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
    /// Factor from the log's number to `unit`: value = scale x logged + offset.
    #[serde(default = "one")]
    pub scale: f64,
    /// Added after `scale`, in `unit`.
    #[serde(default)]
    pub offset: f64,
    /// The instrument's range `[min, max]` in `unit` (after `scale` and
    /// `offset`), say its full scale `[-50, 50]` mm: a sample beyond it is
    /// a corrupted sample or a wrong unit, and fails its run naming the
    /// line. Without it: +-10 m for the command and displacement, +-1e9 N
    /// for the force, beyond any servo-hydraulic test.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub range: Option<[f64; 2]>,
    /// What to do with an isolated spike in this channel (one or two
    /// samples far from both neighbours): by default the run fails naming
    /// the sample; `"interpolate"` replaces it by its neighbours' line and
    /// records it in results.json.
    #[serde(default, skip_serializing_if = "Repair::is_none")]
    pub repair: Repair,
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
    /// The joint grey-box fit of the rig across the identification runs.
    #[serde(default)]
    pub joint: JointSettings,
}

/// The joint grey-box fit: which nuisance dynamics it includes, and
/// whether its rig is the one the campaign uses downstream.
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize, Deserialize, JsonSchema)]
#[schemars(deny_unknown_fields)]
pub struct JointSettings {
    #[serde(default)]
    pub structure: crate::identify::joint::Choice,
    #[serde(default)]
    pub rig: JointRig,
    /// Also fit the validation runs, whose m, c and k the manifest gives:
    /// their x1/u (Eq. 17) and, with a force channel, f/u (Eq. 45). Their
    /// logs are then read twice, once for the rig and once to validate it.
    #[serde(default, skip_serializing_if = "std::ops::Not::not")]
    pub include_validation: bool,
    /// The seals' friction's zero-crossing width v0 (m/s), for a rig whose
    /// runs show friction: the joint fit then takes the friction as
    /// F tanh(v / v0), whose describing function falls short of a sign
    /// function's where the velocity amplitude is within a few v0 of zero.
    /// Unset: a sign function (Coulomb friction with a sharp zero crossing).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub friction_smoothing_m_per_s: Option<f64>,
}

/// Which rig CCF, validation and the sensitivity use.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Serialize, Deserialize, JsonSchema)]
#[serde(rename_all = "snake_case")]
pub enum JointRig {
    /// The joint estimate when it is adequate, else the sequential one.
    #[default]
    Auto,
    /// The paper's sequential estimate (Eqs. 18-20) always.
    Sequential,
    /// The joint estimate whenever it converged to a physical rig.
    Joint,
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
            joint: JointSettings::default(),
        }
    }
}

/// Frequency-response estimation settings. With the estimator left out
/// (`auto`) each run's are chosen from its log and the band; a setting
/// given beside `auto` is kept.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize, JsonSchema)]
#[schemars(deny_unknown_fields)]
pub struct FrfSettings {
    #[serde(default)]
    pub estimator: Estimator,
    /// Samples per Welch segment (for the ETFE and the LPM, the coherence's
    /// segments). Default: 8192 for H1 and H2; chosen from the record and
    /// the band by `auto`.
    #[serde(default)]
    pub segment_length: Option<usize>,
    /// Fraction of a segment shared with the next, in [0, 1); default 0.5.
    #[serde(default)]
    pub overlap: Option<f64>,
    /// Default: Hann for H1 and H2, rectangular for `auto`.
    #[serde(default)]
    pub window: Option<Window>,
    /// Default: the mean.
    #[serde(default)]
    pub detrend: Option<Detrend>,
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
    /// Order of the numerator n(s).
    #[serde(default)]
    pub numerator: usize,
    /// Order of the denominator d(s).
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
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
#[schemars(deny_unknown_fields)]
pub struct Run {
    /// Unique id (letters, digits, `.`, `_` and `-`).
    pub id: String,
    pub role: Role,
    /// Free-form description, shown on the run's page.
    #[serde(default)]
    pub description: String,
    /// When the run was made (ISO 8601: `YYYY-MM-DD` or
    /// `YYYY-MM-DDTHH:MM:SS`, optionally ending in `Z`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub date: Option<String>,
    /// Proportional gain of the analog controller in this run: the
    /// servo-valve's drive per unit of position error (mA/m in the paper's
    /// Table 1). Only ratios between runs matter: a1b0 is proportional to
    /// it (Eq. 10), and results give a1b0 at the rig's P gain.
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
    /// Every role, in the order messages list them.
    pub const ALL: [Role; 4] = [Role::NoSpecimen, Role::Spring, Role::Validation, Role::Fit];

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
/// specimen gives `mass_kg`, `damping_ns_per_m` and `stiffness_n_per_m`;
/// a nonlinear one names its `model` and adds that model's parameters.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize, JsonSchema)]
#[schemars(deny_unknown_fields)]
pub struct Specimen {
    /// Specimen model; `linear` unless a nonlinear model is named.
    #[serde(default)]
    pub model: SpecimenKind,
    /// Specimen mass m (kg).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub mass_kg: Option<f64>,
    /// Specimen damping c (N s/m).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub damping_ns_per_m: Option<f64>,
    /// Linear (or, for Bouc-Wen, initial elastic) stiffness.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub stiffness_n_per_m: Option<f64>,
    /// Duffing: k3 in g = c x2 + k x1 + k3 x1^3 (hardening when positive).
    /// In a simulation manifest a spring run may name `model = "duffing"`
    /// with only the stiffness and k3: the simulator's spring hardens, the
    /// analysis is handed the linear k (a spring the lab takes as linear).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub cubic_stiffness_n_per_m3: Option<f64>,
    /// Friction: the sliding force f_c in g = c x2 + k x1 + f_c tanh(x2 / v_s).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub coulomb_force_n: Option<f64>,
    /// Friction: the smoothing velocity v_s.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub smoothing_velocity_m_per_s: Option<f64>,
    /// Bouc-Wen hysteresis parameters (Wen 1976).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub bouc_wen: Option<BoucWenParams>,
}

/// Specimen models servoid knows.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Serialize, Deserialize, JsonSchema)]
#[serde(rename_all = "snake_case")]
pub enum SpecimenKind {
    /// None, a spring, or a linear SDOF specimen (Eq. 15), by the keys given.
    #[default]
    Linear,
    /// Cubic stiffness.
    Duffing,
    /// Bouc-Wen hysteresis.
    BoucWen,
    /// Viscous spring-mass with smoothed Coulomb friction.
    Friction,
}

/// Bouc-Wen in Wen's form: g = c x2 + alpha k x1 + (1 - alpha) k z,
/// z' = A x2 - beta |x2| |z|^(n-1) z - gamma x2 |z|^n.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
#[schemars(deny_unknown_fields)]
pub struct BoucWenParams {
    /// Post- to pre-yield stiffness ratio, in [0, 1].
    pub alpha: f64,
    /// A, the initial slope dz/dx1.
    pub a: f64,
    /// beta (1/m^n) of the Bouc-Wen law.
    pub beta_per_m_pow_n: f64,
    /// gamma (1/m^n) of the Bouc-Wen law.
    pub gamma_per_m_pow_n: f64,
    /// n >= 1, sharpness of the transition.
    pub n: f64,
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

/// A transfer function num(s)/den(s) exp(-s delay_s), highest power first.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
#[schemars(deny_unknown_fields)]
pub struct PublishedTf {
    /// Numerator coefficients, highest power of s first.
    pub num: Vec<f64>,
    /// Denominator coefficients, highest power of s first.
    pub den: Vec<f64>,
    /// Pure delay (s) in front of num/den.
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
    /// The published value, in the quantity's SI unit.
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
fn default_band() -> [f64; 2] {
    [0.5, 30.0]
}
fn default_coherence() -> f64 {
    0.8
}
fn default_max_delay() -> f64 {
    0.02
}
