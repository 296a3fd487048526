//! results.json: the machine-readable contract that reports, the nightly
//! batch and reviewers read. Its schema (`schemas/results.schema.json`) is
//! generated from these types. Keys are stable; new keys may be added.
//!
//! Units: beta1, a3 [1/s]; a1b0 [N/(m s^2)]; a2 [N/m]; R1 [1/s^2];
//! R2 [N/(m s)]; R3 [m s^2/N]; C1 [1/s^4], C2 [1/s^3], C3 [1/s^2], C4 [1/s],
//! C5 [1/(kg s^2)]; poles [rad/s]; transfer functions in SI (m/m, N/m).
//!
//! truth.json, what `servoid simulate` says a campaign should find, is here
//! too ([`Truth`]).

use std::collections::BTreeMap;

mod parked;
pub use parked::{Parked, PartStore};

use schemars::JsonSchema;

pub use crate::warning::Warning;
use serde::{Deserialize, Serialize};

use crate::drift::Check;
use crate::identify::joint::Structure;
use crate::identify::{Estimate, PerSpring};
use crate::lti::TransferFunction;
use crate::manifest::simulation::UnmodelledSpec;
use crate::manifest::{CompareMode, Manifest, Role, RunTableInfo};
use crate::model::RigParams;
use crate::model::SpecimenModel;

/// Version of the results.json format.
pub const RESULTS_SCHEMA_VERSION: u32 = 2;

/// The results.json schema.
pub fn results_schema() -> serde_json::Value {
    serde_json::to_value(schemars::schema_for!(Results)).expect("schema serialises")
}

/// Everything a campaign run produced.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
pub struct Results {
    pub schema_version: u32,
    /// The servoid version that wrote this file.
    pub servoid_version: String,
    pub campaign: CampaignSummary,
    /// The rig's parameters, identified or given; null when the campaign could
    /// not establish them (see `rig_error`).
    pub rig: Option<RigResult>,
    /// Why `rig` is null, when it is and the campaign needed it.
    pub rig_error: Option<String>,
    /// One entry per run, in manifest order.
    pub runs: Vec<RunResult>,
    /// Controllable canonical form (Eqs. 34-35) for every run with a specimen mass.
    pub ccf: Vec<CcfResult>,
    /// Control-structure interaction (Sec. 3.2.1, Eq. 45) per validation
    /// run with an SDOF specimen, in manifest order.
    pub csi: Vec<crate::validate::csi::Csi>,
    /// Published numbers beside the recomputed ones.
    pub comparisons: Vec<Comparison>,
    /// How the rig parameters' precision depends on the spring stiffness
    /// (paper Sec. 2.3), when the rig is known.
    pub sensitivity: Option<SensitivityResult>,
    /// The rig against its history: each parameter checked for drift, and
    /// the alarms raised; null when the campaign has no rig.
    pub drift: Option<DriftResult>,
    /// Campaign-level warnings.
    pub warnings: Vec<Warning>,
    /// The manifest as read (after defaults), for provenance.
    pub manifest: Manifest,
}

/// What was analysed.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
pub struct CampaignSummary {
    pub name: String,
    pub description: String,
    pub rig_name: String,
    pub rig_notes: String,
    /// The manifest's file name.
    pub manifest: String,
    /// SHA-256 of the manifest's bytes.
    pub manifest_sha256: String,
    /// The manifest's path relative to the folder holding results.json
    /// (`/`-separated), where `servoid verify` looks for it; null when the
    /// results were not written to a folder.
    #[serde(default)]
    pub manifest_path: Option<String>,
    /// The run table the campaign's runs came from, when they did.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub run_table: Option<RunTableInfo>,
}

/// Where the rig parameters come from.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, JsonSchema)]
#[serde(rename_all = "snake_case")]
pub enum RigSource {
    /// Identified by this campaign by the paper's sequential procedure
    /// (Eqs. 18-20).
    Identified,
    /// Identified by this campaign's joint grey-box fit across its runs.
    Joint,
    /// Given in the manifest's [rig.parameters].
    Given,
}

/// The rig (Eq. 10), with a1b0 and R1 at `p_gain`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
#[allow(non_snake_case)]
pub struct RigResult {
    pub source: RigSource,
    /// P gain at which a1b0 and R1 are stated.
    pub p_gain: f64,
    pub beta1: Estimate,
    pub a1b0: Estimate,
    pub a2: Estimate,
    pub a3: Estimate,
    pub R1: Estimate,
    /// Servo-valve time constant 1/beta1 (ms).
    pub valve_time_constant_ms: Estimate,
    /// Per-spring values (Eqs. 19-20); empty when the rig was given.
    pub per_spring: Vec<PerSpring>,
    /// Scatter of the per-spring values (sample standard deviation), when
    /// there are at least two springs.
    pub spread: Option<Spread>,
    /// Whether the springs agree within their propagated stds (a
    /// chi-square across springs, leave-one-out values, likely causes);
    /// null when the rig was given.
    pub consistency: Option<crate::identify::consistency::Consistency>,
    /// Covariance of (beta1, a1b0, a2, a3) (a1b0 at `p_gain`), first-order
    /// propagated from the fits; null when given or without the fits'
    /// covariances.
    pub covariance: Option<[[f64; 4]; 4]>,
    /// The sequential estimate (Eqs. 18-20) when the campaign identifies the
    /// rig, whichever estimate `source` says is used; `per_spring`,
    /// `spread` and `consistency` above are its.
    #[serde(default)]
    pub sequential: Option<RigEstimates>,
    /// The joint grey-box fit, when the campaign identifies the rig.
    #[serde(default)]
    pub joint: Option<JointResult>,
    /// The identification runs that repeat a specimen at other amplitudes:
    /// how x1/u moves with the amplitude and which nonlinear candidate the
    /// movement fits.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub amplitude_series: Vec<crate::identify::amplitude::AmplitudeSeries>,
}

/// The four rig parameters and R1 with their stds and covariance.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
#[allow(non_snake_case)]
pub struct RigEstimates {
    pub beta1: Estimate,
    pub a1b0: Estimate,
    pub a2: Estimate,
    pub a3: Estimate,
    pub R1: Estimate,
    /// Covariance of (beta1, a1b0, a2, a3).
    pub covariance: Option<[[f64; 4]; 4]>,
}

/// An experiment that would settle which of the structures the data could
/// not tell apart is the rig's (`servoid design` adds its run).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, JsonSchema)]
#[serde(rename_all = "snake_case")]
pub enum Settle {
    /// A run at another P gain in the fit: a mode in the loop moves with it.
    PGain,
    /// A sweep to higher frequencies: a delay's phase lag grows with
    /// frequency, a mode's gain falls off.
    WiderBand,
    /// Runs of other stiffness or mass in the fit: the piston's mode moves
    /// with the specimen.
    Specimen,
    /// A run with a load cell in the fit: a mode in the command path
    /// reaches the force.
    LoadCell,
    /// A longer or stronger excitation.
    Longer,
}

impl Settle {
    /// The experiment in words, as the ambiguity warning gives it.
    pub fn text(self) -> &'static str {
        match self {
            Settle::PGain => {
                "add a run at another P gain to the fit (a validation run at a P gain the identification runs lack, with identification.joint.include_validation = true): a mode in the loop changes x1/u with the P gain, one outside the loop does not"
            }
            Settle::WiderBand => {
                "sweep to higher frequencies (the excitation and identification.band_hz): a delay's phase lag grows in proportion to frequency, a mode's gain falls off"
            }
            Settle::Specimen => {
                "add runs of other stiffness or mass (springs, identification.joint.include_validation with SDOF specimens): the piston's mode moves with the specimen, a mode in the valve or the command path does not"
            }
            Settle::LoadCell => {
                "add a run with a load cell to the fit (identification.joint.include_validation): a mode in the command path reaches the force, one on the displacement channel does not"
            }
            Settle::Longer => {
                "a longer or stronger excitation over the band, which narrows every fit's std"
            }
        }
    }
}

/// The joint grey-box fit of the rig across the identification runs
///: the structures tried, the one chosen and why, its rig with
/// the sequential one beside it, and the adequacy tests.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
pub struct JointResult {
    /// The structure whose estimate is reported (null when none could be
    /// fitted).
    pub structure: Option<Structure>,
    /// "data" (the F tests) or "manifest" (identification.joint.structure).
    pub chosen_by: String,
    /// What the data choose, with or without the manifest.
    pub data_choose: Option<Structure>,
    /// Why this structure, in a sentence.
    pub explanation: String,
    /// Every structure tried, smallest first.
    pub candidates: Vec<JointCandidate>,
    /// The reported structure's parameters: the four rig parameters
    /// (a1b0 at `p_gain` of the rig), then the delay, valve frequency and
    /// damping as it has them, each beside the sequential estimate.
    pub parameters: Vec<JointParameter>,
    /// R1 = a1b0 / a2 at the rig's P gain, with its total std.
    #[serde(rename = "R1")]
    pub r1: Option<Estimate>,
    /// Total covariance of (beta1, a1b0, a2, a3): the fit's plus the
    /// structure covariance.
    pub covariance: Option<[[f64; 4]; 4]>,
    /// The structure covariance alone: the candidates' Schwarz-weighted
    /// spread about the reported rig.
    pub structure_covariance: Option<[[f64; 4]; 4]>,
    /// When structures the data cannot tell apart put the rig in different
    /// places: which, what they move, and the experiment that would settle
    /// it (also among the warnings).
    pub ambiguity: Option<String>,
    /// The experiments that would settle the ambiguity, as it names them.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub settle: Vec<Settle>,
    /// When the chosen structure fails its adequacy tests and the runs
    /// pull the rig apart: by how much, and that the stds include it (also
    /// among the warnings).
    pub misfit: Option<String>,
    /// The adequacy tests over every run's bins, and per run.
    pub adequacy: Option<crate::fit::adequacy::Adequacy>,
    pub per_run: Vec<RunAdequacy>,
    /// Whether CCF, validation and the sensitivity use this estimate.
    pub used: bool,
    /// Why they do or do not.
    pub use_note: String,
    /// F_max (N) the valve's flow-pressure law is held at where the runs do
    /// not determine it: the nameplate's (`rig.supply_pressure_pa` times
    /// `rig.piston_area_m2`). A fitted F_max is among `parameters`.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub flow_law_held_n: Option<f64>,
    /// The seals' friction corrected for the describing function's bias,
    /// where friction is fitted (`coulomb_friction_n` among `parameters`
    /// is then the corrected value).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub friction_correction: Option<FrictionCorrection>,
}

/// The seals' friction corrected for the describing function's bias by
/// simulating the fitted rig through the runs' own commands
/// (docs/methods.md, "The friction's bias").
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
#[schemars(deny_unknown_fields)]
pub struct FrictionCorrection {
    /// The describing function's friction and its statistical std (N).
    pub describing_function_n: f64,
    pub describing_function_std_n: f64,
    /// The friction reported (N): the middle of the corrected values.
    pub value_n: f64,
    /// Its statistical std (N), the describing function's scaled by the
    /// correction.
    pub std_n: f64,
    /// Half the corrected values' range over the widths (N), added to the
    /// std: the friction's zero-crossing width, which the FRFs do not see.
    pub width_std_n: f64,
    /// Per width simulated.
    pub widths: Vec<WidthCorrection>,
}

/// The correction at one zero-crossing width.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
#[schemars(deny_unknown_fields)]
pub struct WidthCorrection {
    /// v0 (m/s) of the friction F tanh(v / v0) simulated.
    pub smoothing_m_per_s: f64,
    /// The friction the joint fit finds in the simulation with the friction
    /// found, F (N).
    pub refit_n: f64,
    /// F^2 / `refit_n` (N): the friction whose fit reads F, the bias being
    /// in proportion to the friction.
    pub corrected_n: f64,
}

/// One row of the structure table.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
pub struct JointCandidate {
    pub structure: Structure,
    /// Where its second-order mode sits: "loop", "command path",
    /// "measurement path", or "in series" (command or measurement path,
    /// which only force FRFs tell apart); "actuator (piston mass)" for the
    /// piston's, "loop and actuator (piston mass)" for both; null without a
    /// mode.
    pub place: Option<String>,
    pub parameters: usize,
    /// Null with `error` when the fit failed outright.
    pub cost: Option<f64>,
    pub dof: Option<usize>,
    pub reduced_chi2: Option<f64>,
    /// (cost - dof) / sqrt(2 dof).
    pub cost_z: Option<f64>,
    /// cost + p ln(2 N).
    pub bic: Option<f64>,
    /// The F test against the nested structure chosen before it.
    pub f_test: Option<FTestResult>,
    /// Its Schwarz (BIC) weight among the usable candidates: its share of
    /// the structure std.
    pub weight: Option<f64>,
    pub converged: Option<bool>,
    /// Why the fit cannot be used although it ran.
    pub unusable: Option<String>,
    pub error: Option<String>,
    pub chosen: bool,
}

/// An extra-sum-of-squares F test.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
pub struct FTestResult {
    pub against: Structure,
    pub f: f64,
    pub p_value: f64,
    /// p below 0.001.
    pub significant: bool,
}

/// A joint parameter beside the sequential estimate.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
pub struct JointParameter {
    /// beta1, a1b0, a2, a3, delay_s, then valve_hz and valve_damping (a
    /// mode in the loop) or mode_hz and mode_damping (outside it), then
    /// force_delay_s.
    pub name: String,
    pub value: f64,
    /// Statistical std, from the fit.
    pub std: f64,
    /// The structure std: the candidate structures' spread about this
    /// value, weighted by their Schwarz weights (rig parameters only).
    pub structure_std: Option<f64>,
    /// The model-error std from the runs' jackknife, when the chosen
    /// structure fails its adequacy tests (rig parameters only).
    pub misfit_std: Option<f64>,
    /// sqrt(std^2 + structure_std^2 + misfit_std^2): what the rig's std is
    /// when the joint estimate is used.
    pub total_std: f64,
    /// The sequential estimate and its std (rig parameters only).
    pub sequential: Option<Estimate>,
    /// (joint - sequential) / sqrt(std_joint^2 + std_sequential^2).
    pub difference_std: Option<f64>,
    /// The model-error term: |joint - sequential|, the spread between two
    /// estimators of the same parameter that weigh the model's errors
    /// differently.
    pub model_error: Option<f64>,
    /// "model error" when the two differ by more than 2 combined stds,
    /// else "statistical".
    pub dominant: Option<String>,
    /// The friction's std from its zero-crossing width
    /// ([`FrictionCorrection::width_std_n`]), in `total_std`.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub correction_std: Option<f64>,
}

/// A run's adequacy tests under a fit.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
pub struct RunAdequacy {
    pub run: String,
    pub adequacy: crate::fit::adequacy::Adequacy,
}

/// The stiffness sensitivity analysis (paper Sec. 2.3), with where the
/// campaign's springs sit.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
pub struct SensitivityResult {
    /// The campaign's spring stiffnesses (N/m).
    pub springs_n_per_m: Vec<f64>,
    /// The first-order prediction against k.
    pub analytic: AnalyticSensitivity,
    /// Simulated identifications against k, when the manifest asks for them
    /// (`sensitivity.monte_carlo`) and a no-specimen log allows them.
    pub monte_carlo: Option<crate::sensitivity::montecarlo::MonteCarlo>,
    /// Why there is no Monte Carlo although the manifest asked for one.
    pub monte_carlo_note: Option<String>,
    /// Where each parameter is within the manifest's target, and the spring
    /// tests a +-2 % a2 and a3 need.
    pub recommendation: crate::sensitivity::Recommendation,
}

/// The analytic sweep and where its coefficient precision comes from.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
pub struct AnalyticSensitivity {
    /// Where the coefficient precision comes from.
    pub basis: String,
    #[serde(flatten)]
    pub sweep: crate::sensitivity::StiffnessSensitivity,
}

/// The rig checked against its history (see `servoid::drift` for the rule).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
pub struct DriftResult {
    /// The rig's name, which keys its history.
    pub rig: String,
    /// The history table, as the manifest or the default names it.
    pub history_file: String,
    /// Entries of this rig before this campaign.
    pub earlier_entries: usize,
    /// K and N of the rule.
    pub window: usize,
    pub threshold: f64,
    pub checks: Vec<Check>,
    /// One line per parameter in alarm.
    pub alarms: Vec<String>,
}

/// Sample standard deviation of the per-spring values.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
pub struct Spread {
    pub a1b0: f64,
    pub a2: f64,
    pub a3: f64,
}

/// Outcome of a run.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, JsonSchema)]
#[serde(rename_all = "snake_case")]
pub enum Status {
    Ok,
    Failed,
}

/// Where a run's transfer function comes from.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, JsonSchema)]
#[serde(rename_all = "snake_case")]
pub enum TfSource {
    /// Given in the manifest (a publication's fitted model).
    Published,
    /// Fitted to this run's log.
    Fitted,
    /// Predicted from the rig parameters and the specimen (Eqs. 12, 14, 17).
    Model,
}

/// A transfer function x1/u with `den[0] == 1`, highest power first.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
pub struct TfResult {
    pub num: Vec<f64>,
    pub den: Vec<f64>,
    pub delay_s: f64,
    pub source: TfSource,
    /// Poles (rad/s).
    pub poles: Vec<ComplexValue>,
    /// Standard deviation of each fitted coefficient (num then den after the
    /// leading 1, then the delay when fitted); null unless fitted.
    pub std: Option<Vec<f64>>,
    /// The same, relative to each coefficient's magnitude.
    pub rel_std: Option<Vec<f64>>,
}

impl TfResult {
    pub fn new(tf: &TransferFunction, source: TfSource) -> Self {
        Self {
            num: tf.num.clone(),
            den: tf.den.clone(),
            delay_s: tf.delay_s,
            source,
            poles: tf.poles().into_iter().map(ComplexValue::from).collect(),
            std: None,
            rel_std: None,
        }
    }
}

/// A complex number.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize, JsonSchema)]
pub struct ComplexValue {
    pub re: f64,
    pub im: f64,
}

impl From<nalgebra::Complex<f64>> for ComplexValue {
    fn from(c: nalgebra::Complex<f64>) -> Self {
        Self { re: c.re, im: c.im }
    }
}

/// One run's results.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
pub struct RunResult {
    pub id: String,
    pub role: Role,
    pub description: String,
    pub p_gain: f64,
    pub status: Status,
    /// Why the run failed (null when ok).
    pub error: Option<String>,
    /// Warnings that did not stop the run.
    pub warnings: Vec<Warning>,
    pub specimen: SpecimenModel,
    /// Undamped natural frequency of an SDOF specimen (Hz).
    pub natural_frequency_hz: Option<f64>,
    /// a1b0 at this run's P gain [N/(m s^2)], when the rig is known.
    pub a1b0: Option<f64>,
    /// x1/u: published, fitted, or (validation runs) the model's prediction.
    pub tf: Option<TfResult>,
    /// f/u predicted by the model (Eq. 45), for runs with a specimen.
    pub force_tf: Option<TfResult>,
    /// How the transfer function was fitted to the log, when it was.
    // Boxed: most of a night's runs (its validation runs) have none, and a
    // night holds every run's result until its files are written.
    pub fit: Option<Box<FitSummary>>,
    /// Measured vs simulated displacement (Eqs. 47-48), when the run has a log.
    pub validation: Option<ValidationMetrics>,
    /// How the actuator followed its command, when the run has a log:
    /// measured, and for a validation run as the identified model predicts
    /// it for the same command.
    // Parked once the run's files are written: it is most of a validation
    // run's result (the compensator's sweep over the specimen's
    // stiffness), and only the set's files read it.
    #[schemars(with = "Option<RunTracking>")]
    pub tracking: Option<Parked<RunTracking>>,
    /// The log this run read, when it has one.
    pub log: Option<LogInfo>,
    /// The FRF settings the run got and why, when it has a log.
    #[serde(default)]
    pub frf: Option<FrfUsed>,
    /// Whether the rig answered the run's sweep linearly, when its command
    /// is a sweep.
    #[serde(default)]
    pub linearity: Option<LinearityResult>,
    /// A spring run's force against its displacement, when it logs a force.
    #[serde(default)]
    pub spring_force: Option<SpringForceResult>,
    /// The steady periods of a periodic command (a designed odd
    /// multisine), which the run's FRF read, with the noise their spread
    /// gives and the distortion the command's empty lines hold; absent
    /// for other commands.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub periodic: Option<PeriodicResult>,
    /// The displacement's noise as the run's FRF variance states it, in
    /// bands over the bins its fit used: what `servoid design` plans the
    /// next night's precision from; absent for a run without a fit.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub noise: Option<crate::design::night::Noise>,
    /// A run table row's cells in the lab's own columns (a `notes`, an
    /// `operator`), by column; absent when there are none.
    #[serde(default, skip_serializing_if = "BTreeMap::is_empty")]
    pub annotations: BTreeMap<String, String>,
}

/// A periodic log's steady periods and what they say
/// (`frf::periodic`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
pub struct PeriodicResult {
    /// The command's period (s).
    pub period_s: f64,
    /// The whole periods that repeat sample for sample, which the FRF
    /// read.
    pub periods: usize,
    /// Where they start, from the log's first sample (s).
    pub start_s: f64,
    /// Lines of 1 / period in the band the command excites, and leaves
    /// empty.
    pub lines_excited: usize,
    pub lines_empty: usize,
    /// The displacement's RMS over the excited lines' mean power (m, from
    /// the averaged periods), the noise floor (m, the RMS a line's average
    /// scatters by, from the periods' spread) and the empty lines' RMS (m).
    pub output_m: f64,
    pub noise_m: f64,
    pub empty_m: f64,
    /// The empty lines' power over the noise floor there: 1 within
    /// 1 / sqrt(lines_empty) for a linear rig, more where it distorts.
    pub distortion_to_noise: f64,
    /// Whether the empty lines hold more than the noise floor
    /// (distortion_to_noise above 2).
    pub distorts: bool,
}

/// Provenance of a run's log.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
pub struct LogInfo {
    /// The file as the manifest names it.
    pub file: String,
    pub sha256: String,
    pub sample_rate_hz: f64,
    pub n_samples: usize,
    pub duration_s: f64,
    /// The command's largest magnitude (m).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub command_peak_m: Option<f64>,
    /// Isolated spikes replaced by their neighbours' line, as a channel's
    /// `repair = "interpolate"` asked.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub repairs: Vec<crate::ingest::Repaired>,
}

/// Whether the rig answered a sweep linearly (`frf::harmonics`): harmonics
/// of the command in the response beyond what a linear rig gives.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
pub struct LinearityResult {
    /// Blocks of the sweep the check read.
    pub blocks_checked: usize,
    /// False when a signal holds harmonics in at least 3 blocks.
    pub linear: bool,
    /// Harmonics in the displacement beyond the command's.
    pub displacement: Option<HarmonicsFound>,
    /// Harmonics in the force beyond the displacement's.
    pub force: Option<HarmonicsFound>,
    /// In words.
    pub note: String,
}

/// A spring's force against its displacement (`frf::linearity::spring_force`):
/// f = k x + k3 x^3 + c x' + m x'' + f0 over the record.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
pub struct SpringForceResult {
    /// The stiffness the force and displacement give, and the manifest's
    /// (N/m).
    pub stiffness_n_per_m: f64,
    pub stated_n_per_m: f64,
    /// The cubic term (N/m^3) and its t statistic.
    pub cubic_n_per_m3: f64,
    pub cubic_t: f64,
    /// The largest displacement from the mean (m), and the secant
    /// stiffness there over k, less 1.
    pub amplitude_m: f64,
    pub stiffening: f64,
    /// False when the spring stiffens beyond 0.5 % at the test's
    /// amplitude, t beyond 10.
    pub linear: bool,
}

/// Harmonics found in one signal.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
pub struct HarmonicsFound {
    /// Blocks with a harmonic.
    pub blocks: usize,
    /// The largest harmonic's amplitude over the signal's in its part of
    /// the sweep, its order (2 or 3) and the sweep's frequency there (Hz).
    pub largest_ratio: f64,
    pub order: usize,
    pub at_hz: f64,
}

/// The FRF settings a run got and why (`frf::FrfRequest::resolve`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
pub struct FrfUsed {
    /// "auto" when the default estimator chose them from the log, else
    /// "manifest".
    pub chosen_by: String,
    pub estimator: crate::frf::Estimator,
    pub window: crate::frf::Window,
    /// Samples per Welch segment (for the ETFE, the coherence's segments).
    pub segment_length: usize,
    pub overlap: f64,
    pub detrend: crate::frf::Detrend,
    /// Whether the record's transient was fitted beside the run's model
    /// and taken out of its FRF.
    pub transient: bool,
    /// Whether the bins' noise level was read from what a first fit left.
    pub model_noise: bool,
    /// What the command holds: "sweep", "multisine", "noise",
    /// "narrowband" or "unknown"; and in words.
    pub excitation: String,
    pub excitation_note: String,
    /// How the record's ends stand, in words.
    pub ends: String,
    /// What was chosen and why, in a sentence.
    pub reason: String,
}

pub use crate::validate::{SimplifiedCcf, ValidationMetrics, WindowErrors};

/// A run's tracking measures (`tracking::measure`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
pub struct RunTracking {
    /// The log's displacement against its command.
    pub measured: crate::tracking::Tracking,
    /// The displacement the identified rig with the run's specimen predicts
    /// for the measured command (validation runs): a model that predicts
    /// the measured tracking is one to design a compensator on.
    pub predicted: Option<crate::tracking::Tracking>,
    /// The measured delay by cross-correlation less the predicted (s): the
    /// delay the model lacks, which a compensator designed on it leaves on
    /// the rig.
    pub model_gap_s: Option<f64>,
    /// The model-based compensator for the run's specimen (validation runs
    /// whose specimen is linear).
    pub compensator: Option<crate::tracking::compensator::CompensatorOutcome>,
}

/// A transfer-function fit to a run's FRF.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
pub struct FitSummary {
    /// 100 (1 - ||h - h_model|| / ||h - mean(h)||) over the fitted bins.
    pub fit_percent: f64,
    pub n_bins: usize,
    pub band_hz: [f64; 2],
    /// Coherence over the fitted bins: mean and lowest.
    pub coherence_mean: f64,
    pub coherence_min: f64,
    /// Weighted residual per degree of freedom; about 1 for a right model
    /// with honest FRF variances.
    pub reduced_chi2: f64,
    pub iterations: u64,
    /// The solver's termination reason (argmin), verbatim.
    pub termination: String,
    pub converged: bool,
    pub stable: bool,
    pub param_names: Vec<String>,
    pub params: Vec<f64>,
    pub std: Vec<f64>,
    /// Covariance of `params`, row by row ((J^T W J)^-1 scaled by the
    /// reduced chi-square): `std` is the root of its diagonal.
    #[serde(default)]
    pub covariance: Option<Vec<Vec<f64>>>,
    /// Welch segments averaged, and the bin spacing (Hz).
    pub frf_averages: usize,
    pub frf_resolution_hz: f64,
    /// The adequacy tests of this run's own fit (`fit::adequacy`).
    #[serde(default)]
    pub adequacy: Option<crate::fit::adequacy::Adequacy>,
    /// For a fit made without a delay: whether the data support one
    /// (`fit::delay_significance`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub delay_test: Option<DelayTestResult>,
}

/// The run's fit made again with a delay, and the extra-sum-of-squares F
/// test of the delay against the fit without it.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
pub struct DelayTestResult {
    /// The fitted delay (s) and the reduced chi-square with it, when that
    /// fit converged to a stable model.
    pub delay_s: Option<f64>,
    pub reduced_chi2: Option<f64>,
    pub f: Option<f64>,
    pub p_value: Option<f64>,
    /// p below 0.001: the data support the delay.
    pub supported: bool,
    /// What became of the fit with the delay, in a sentence.
    pub note: String,
}

/// The controllable canonical form of one run (Eqs. 34-35, signs checked in docs/model.md).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
#[allow(non_snake_case)]
pub struct CcfResult {
    pub run: String,
    pub p_gain: f64,
    pub C1: f64,
    pub C2: f64,
    pub C3: f64,
    pub C4: f64,
    pub C5: f64,
    /// Poles of the CCF with Cn kept: the plant's own poles [rad/s].
    pub poles_with_cn: Vec<ComplexValue>,
    /// Poles of the paper's simplified CCF (Cn dropped) [rad/s].
    pub poles_without_cn: Vec<ComplexValue>,
    /// Every pole of the simplified CCF has a negative real part: dropping
    /// Cn can move the specimen's pair into the right half-plane.
    pub stable_without_cn: bool,
}

/// A published number beside the recomputed one.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
pub struct Comparison {
    pub quantity: String,
    pub published: f64,
    /// The recomputed value (signed); null when the campaign could not compute it.
    pub computed: Option<f64>,
    /// (computed - published) / |published|, with |computed| when `compare` is
    /// `magnitude`.
    pub rel_diff: Option<f64>,
    /// True when |rel_diff| exceeds the tolerance.
    pub flag: bool,
    pub compare: CompareMode,
    pub tolerance_pct: f64,
    /// Where the published number comes from.
    pub source: String,
    pub status: ComparisonStatus,
}

/// Outcome of a comparison.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, JsonSchema)]
#[serde(rename_all = "snake_case")]
pub enum ComparisonStatus {
    Agrees,
    Differs,
    NotComputed,
}

/// truth.json: what the identification should find.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
pub struct Truth {
    pub schema_version: u32,
    pub servoid_version: String,
    /// The simulation's name and its manifest's SHA-256.
    pub simulation: String,
    pub manifest_sha256: String,
    pub seed: u64,
    pub sample_rate_hz: f64,
    /// The true rig parameters (a1b0 at `rig.p_gain`).
    pub rig: RigParams,
    /// True when the plant is exactly the paper's model (no unmodelled
    /// dynamics, no flow-pressure law).
    pub clean: bool,
    pub unmodelled: Option<UnmodelledSpec>,
    /// F_max = A P_s (N) of the servo-valve's flow-pressure law (docs/model.md),
    /// when the rig has one.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub max_force_n: Option<f64>,
    pub runs: Vec<TruthRun>,
}

/// One simulated run's truth.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
pub struct TruthRun {
    pub id: String,
    pub role: Role,
    pub p_gain: f64,
    /// The specimen as simulated.
    pub specimen: SpecimenModel,
    /// a1b0 at this run's P gain.
    pub a1b0: f64,
    /// x1/u of the paper's model (Eqs. 12, 14, 17) at the true parameters;
    /// null for a nonlinear specimen.
    pub model_tf_x1_u: Option<TransferFunction>,
    /// x1/u of the simulated linear plant, unmodelled dynamics included;
    /// equal to `model_tf_x1_u` for a clean campaign.
    pub plant_tf_x1_u: Option<TransferFunction>,
    /// The log, relative to the output folder.
    pub log: String,
    pub log_sha256: String,
    pub n_samples: usize,
    /// The SHA-256 of the command file played, where the run played one.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub command_sha256: Option<String>,
}

impl Results {
    /// What differs between these results and `other` (recomputed from the
    /// same manifest): each quantity by its path into results.json, its
    /// logs' hashes apart, by run.
    pub fn differences(&self, other: &Results) -> (Vec<Difference>, Vec<LogDifference>) {
        let mut differences = Vec::new();
        let a = serde_json::to_value(self).expect("results serialise");
        let b = serde_json::to_value(other).expect("results serialise");
        diff("", &a, &b, &mut differences);
        differences.retain(|d| !is_log_hash(&d.key));
        (differences, log_differences(self, other))
    }
}

/// One quantity that differs: where in results.json, and both values.
#[derive(Debug, Clone, PartialEq)]
pub struct Difference {
    /// A path into results.json, e.g. `runs[3].validation.nrmse_pct`.
    pub key: String,
    pub recorded: String,
    pub recomputed: String,
}

/// A run's log whose bytes are not those results.json records.
#[derive(Debug, Clone, PartialEq)]
pub struct LogDifference {
    pub run: String,
    /// The log as the manifest names it.
    pub file: String,
    pub recorded: String,
    /// None when the log cannot be read now.
    pub now: Option<String>,
}

/// Whether `key` is a run's log hash (`runs[3].log.sha256`).
fn is_log_hash(key: &str) -> bool {
    key.starts_with("runs[") && key.ends_with("].log.sha256")
}

/// Each run whose log hash differs, with the run and the file named.
fn log_differences(recorded: &Results, recomputed: &Results) -> Vec<LogDifference> {
    recorded
        .runs
        .iter()
        .filter_map(|r| {
            let was = r.log.as_ref()?;
            let now = recomputed.runs.iter().find(|n| n.id == r.id);
            let now_sha = now.and_then(|n| n.log.as_ref()).map(|l| l.sha256.clone());
            (now_sha.as_deref() != Some(was.sha256.as_str())).then(|| LogDifference {
                run: r.id.clone(),
                file: was.file.clone(),
                recorded: was.sha256.clone(),
                now: now_sha,
            })
        })
        .collect()
}

/// Every leaf where `a` and `b` differ, with its path.
fn diff(key: &str, a: &serde_json::Value, b: &serde_json::Value, out: &mut Vec<Difference>) {
    match (a, b) {
        (serde_json::Value::Object(x), serde_json::Value::Object(y)) => {
            let keys: std::collections::BTreeSet<&String> = x.keys().chain(y.keys()).collect();
            for k in keys {
                let sub = if key.is_empty() {
                    k.clone()
                } else {
                    format!("{key}.{k}")
                };
                let none = serde_json::Value::Null;
                diff(
                    &sub,
                    x.get(k).unwrap_or(&none),
                    y.get(k).unwrap_or(&none),
                    out,
                );
            }
        }
        (serde_json::Value::Array(x), serde_json::Value::Array(y)) if x.len() == y.len() => {
            for (i, (p, q)) in x.iter().zip(y).enumerate() {
                diff(&format!("{key}[{i}]"), p, q, out);
            }
        }
        _ if a != b => out.push(Difference {
            key: key.to_string(),
            recorded: a.to_string(),
            recomputed: b.to_string(),
        }),
        _ => {}
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn differences_are_named_by_their_path() {
        let a = serde_json::json!({"rig": {"a2": 1.0, "a3": [1, 2]}, "runs": [{"id": "x"}]});
        let b = serde_json::json!({"rig": {"a2": 1.5, "a3": [1, 3]}, "runs": [{"id": "x"}, {"id": "y"}]});
        let mut out = Vec::new();
        diff("", &a, &b, &mut out);
        let keys: Vec<&str> = out.iter().map(|d| d.key.as_str()).collect();
        assert_eq!(keys, ["rig.a2", "rig.a3[1]", "runs"]);
        assert_eq!(out[0].recorded, "1.0");
        assert_eq!(out[0].recomputed, "1.5");
    }
}

/// What `servoid design` wrote (design.json): tomorrow night's
/// identification runs, their commands, and what the night is predicted to
/// determine of the rig.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct DesignResult {
    /// The servoid version that wrote this file.
    pub servoid_version: String,
    /// The results.json or manifest designed from (as given) and its
    /// SHA-256.
    pub source: String,
    pub source_sha256: String,
    pub campaign: String,
    pub rig_name: String,
    /// The rig the night is planned at, a1b0 at its `p_gain`, and where it
    /// came from (the results' rig, or a manifest's nominal values).
    pub rig: RigParams,
    pub rig_from: String,
    pub sample_rate_hz: f64,
    pub band_hz: [f64; 2],
    /// Each run's record, its rest included (s).
    pub record_s: f64,
    /// Rest before and after each command (s).
    pub rest_s: f64,
    /// The odd multisines' period (s) and the periods in each run (the
    /// first fading in, the last out).
    pub period_s: f64,
    pub periods: usize,
    /// The A-optimal shares' part of each line's share of the power, the
    /// rest spread flat.
    pub optimal_share: f64,
    /// Which draw of the lines left out for detection (of those tried).
    pub draw: u64,
    pub lines_excited: usize,
    /// Odd lines in the band left empty, where odd distortion shows.
    pub lines_detection: usize,
    pub limits: DesignLimits,
    /// The worst relative std asked for (--target-std).
    pub target_relative_std: Option<f64>,
    /// beta1, a1b0, a2, a3: last night's stated std, the designed night's
    /// predicted one, and the paper's chirps' at the same record and peak.
    pub parameters: Vec<DesignedParameter>,
    /// The designed night against the paper's chirps.
    pub baseline: Option<DesignBaseline>,
    /// The identification runs, then the runs that settle a question.
    pub runs: Vec<DesignedRunResult>,
    /// What last night left open, the run added to settle it and what
    /// each answer would mean.
    pub questions: Vec<DesignQuestion>,
    /// The displacement noise the night is planned for (the mean of the
    /// identification runs' results.json `noise`, or white at a level
    /// given), and where it came from.
    pub noise: crate::design::night::Noise,
    pub noise_from: String,
    /// The noise density's largest band over its smallest: check.toml
    /// plays white noise at their mean, which reads as planned only where
    /// this is near 1.
    pub noise_spread: f64,
    /// Each identification run's displacement at the excited lines and
    /// the noise it has to clear there (the page's figure).
    pub lines: crate::design::night::LineLevels,
    /// Every period and mix tried, with the sum of squared relative stds
    /// each predicts.
    pub tried: Vec<crate::design::night::Tried>,
}

/// The limits a design kept to, as given or taken from the results.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct DesignLimits {
    /// The command's largest magnitude (m), and where it came from.
    pub command_m: f64,
    pub command_from: String,
    pub stroke_m: Option<f64>,
    pub velocity_m_per_s: Option<f64>,
    pub force_n: Option<f64>,
    /// The time each run may take (s), rest included, and where it came
    /// from.
    pub run_s: f64,
    pub run_from: String,
}

/// A rig parameter's precision: last night's and tomorrow's.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct DesignedParameter {
    pub name: String,
    pub value: f64,
    /// The std last night's results state.
    pub last_std: Option<f64>,
    /// The designed night's predicted std and its ratio to the value.
    pub std: f64,
    pub relative_std: f64,
    /// The paper's chirps' predicted std at the same record and peak.
    pub chirp_std: Option<f64>,
    /// The designed night's predicted std under check.toml's white noise:
    /// what the check should state.
    pub check_std: Option<f64>,
}

/// The designed night against the paper's command at the same record and
/// peak.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct DesignBaseline {
    pub description: String,
    /// The chirps' worst relative std over the night's.
    pub worst_ratio: f64,
    /// The chirps' sum of squared relative stds over the night's.
    pub squares_ratio: f64,
}

/// One designed run.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct DesignedRunResult {
    pub id: String,
    pub role: Role,
    pub description: String,
    pub p_gain: f64,
    pub specimen: SpecimenModel,
    /// Its command, relative to the design's folder: CSV and MAT, each
    /// with time_s (s) and command_m (m) at sample_rate_hz.
    pub command_csv: String,
    pub command_mat: String,
    /// The log the next night's manifest expects for it.
    pub log: String,
    /// The period's peak over its RMS, and the steady periods' RMS (m).
    pub crest_factor: f64,
    pub rms_m: f64,
    /// The peaks the identified plant predicts over the whole command.
    pub peaks: crate::design::night::Peaks,
    /// The limit its amplitude reaches; none for a run that plays another
    /// run's command at a share of its amplitude.
    pub bound_by: Option<crate::design::night::Limit>,
    /// Each limit given: the predicted peak over it.
    pub used: Vec<LimitUsed>,
    /// The identification run whose command it plays, and at what share
    /// of its amplitude (a run that settles a question).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub repeats: Option<String>,
    pub amplitude_share: f64,
    /// The band it is fitted over where it is not the campaign's (Hz).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub band_hz: Option<[f64; 2]>,
    /// The command in the campaign's log format, where that is another
    /// (Parquet, HDF5, TDMS).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub command_log: Option<String>,
}

/// Something last night's results left open, and the run that settles it.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct DesignQuestion {
    /// What the results said.
    pub question: String,
    /// The run added (in `runs`).
    pub run: String,
    /// What each answer would mean.
    pub answers: String,
}

/// A predicted peak against its limit.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct LimitUsed {
    pub limit: crate::design::night::Limit,
    pub peak: f64,
    pub value: f64,
    /// peak / value: at most 1.
    pub share: f64,
}
