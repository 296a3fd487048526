//! The first stage of a run: its own transfer function, published or
//! measured. A run with a log is read (ingest), checked against the FRF
//! settings, its command-to-displacement and command-to-force FRFs
//! estimated, and, for the runs that identify or characterise the rig, its
//! transfer function fitted. Pure apart from `ingest` reading the file.

use crate::warning::Warning;
use std::path::PathBuf;

use crate::fit::TfFit;
use crate::frf::{self, Frf, FrfChoice, FrfError, FrfPlan};
use crate::identify::IdentificationPlan;
use crate::identify::{FitData, RunTfError, fit_run};
use crate::ingest::{self, IngestError, Log, LogFile, LogPlan, Needs};
use crate::lti::TransferFunction;
use crate::manifest::{Campaign, Role, RunPlan, RunSource};
use crate::model::SpecimenModel;
use crate::results::TfSource;

/// What the first stage gives for each run: its own transfer function, and
/// the log's signals and spectra when it has a log.
#[derive(Debug, Clone)]
pub struct OwnTf {
    pub tf: Option<TransferFunction>,
    /// Covariance of (n0, d1, d0) for a second-order fit.
    pub cov: Option<[[f64; 3]; 3]>,
    pub source: TfSource,
    pub warnings: Vec<Warning>,
    pub stage: Option<Box<LogStage>>,
}

/// The first stage of one run: its measured or published transfer function.
pub fn own_tf(campaign: &Campaign, run: &RunPlan) -> Result<OwnTf, LogStageError> {
    own_tf_with(campaign, run, None)
}

/// The first stage of one run, its log's bytes already read when given
/// (they are the log the plan names).
pub fn own_tf_with(
    campaign: &Campaign,
    run: &RunPlan,
    file: Option<LogFile>,
) -> Result<OwnTf, LogStageError> {
    match &run.source {
        RunSource::None => Ok(OwnTf {
            tf: None,
            cov: None,
            source: TfSource::Model,
            warnings: Vec::new(),
            stage: None,
        }),
        RunSource::Published { tf, .. } => Ok(OwnTf {
            tf: Some(tf.clone()),
            cov: None,
            source: TfSource::Published,
            warnings: Vec::new(),
            stage: None,
        }),
        RunSource::Log(plan) => {
            let file = match file {
                Some(f) => f,
                None => LogFile::read(&plan.path, plan.max_bytes)?,
            };
            let stage = log_stage_from(run, plan, &campaign.identification, file)?;
            let fit = stage.fit.as_ref();
            Ok(OwnTf {
                tf: fit.map(|f| f.tf.clone()),
                cov: fit.and_then(|f| f.second_order_cov()),
                source: TfSource::Fitted,
                warnings: stage.warnings.clone(),
                stage: Some(Box::new(stage)),
            })
        }
    }
}

/// What a log gave: the signals and their spectra, and the fit when one was made.
#[derive(Debug, Clone)]
pub struct LogStage {
    pub log: Log,
    /// A periodic command's steady periods, to which `log` is cut, and
    /// what their spread and empty lines say (None: not periodic, or the
    /// manifest names the estimator).
    pub periodic: Option<Periodic>,
    /// The FRF settings the run got, and why.
    pub choice: FrfChoice,
    /// What its command holds.
    pub excitation: frf::Excitation,
    /// Whether the rig answered a sweep linearly (None: not a sweep, or
    /// too short to tell).
    pub linearity: Option<frf::Linearity>,
    /// A spring run's force against its displacement, when it logs a
    /// force.
    pub spring: Option<frf::SpringForce>,
    /// How the displacement's gain against the command changes with
    /// amplitude where a sweep is slow (None: not a sweep, or no slow part).
    pub slow: Option<frf::SlowCubic>,
    /// What the run's own warnings already found wrong (FRF settings the
    /// log contradicts, a rig not linear): what any misfit of its fit is
    /// then put down to, rather than dynamics the model lacks.
    pub cause: Option<String>,
    /// Command to displacement (with the record's transient out, when the
    /// run's fit took it out).
    pub frf: Frf,
    /// Command to force, when the log has a force channel.
    pub force_frf: Option<Frf>,
    /// The command's whole one-sided DFT less its mean, where the FRF's
    /// is the one the tracking reads ([`LogStage::reference`]).
    pub command_dft: Option<Vec<nalgebra::Complex<f64>>>,
    /// The bins the fit used (band and coherence).
    pub mask: Vec<bool>,
    pub fit: Option<TfFit>,
    /// What the fit was given (with `fit`): the noise profile of a
    /// no-specimen run reads its variance from here.
    pub fit_data: Option<FitData>,
    pub warnings: Vec<Warning>,
}

impl LogStage {
    /// The command as the tracking measures against it, with the FRF's
    /// transform of it where there is one: one transform for both.
    pub fn reference(&self) -> crate::tracking::Reference<'_> {
        match &self.command_dft {
            Some(dft) => crate::tracking::Reference::with_spectrum(&self.log.command_m, dft),
            None => crate::tracking::Reference::new(&self.log.command_m),
        }
    }

    /// Whether the displacement holds harmonics of the command (seal
    /// friction's signature, `frf::linearity`): the joint fit then fits
    /// the friction.
    pub fn friction_signature(&self) -> bool {
        self.linearity
            .and_then(|l| l.displacement)
            .is_some_and(|f| f.blocks >= frf::linearity::MIN_BLOCKS)
    }
}

/// Why a log stage failed; the message names the run's file.
#[derive(Debug, thiserror::Error)]
pub enum LogStageError {
    #[error(transparent)]
    Ingest(#[from] IngestError),
    #[error("{}: the fit band's upper edge {hi} Hz (identification.band_hz) is at or above the log's Nyquist frequency {nyquist} Hz (sampled at {} Hz){hint}", path.display(), 2.0 * nyquist)]
    BandAboveNyquist {
        path: PathBuf,
        hi: f64,
        nyquist: f64,
        /// The likely unit mistake, when one explains it ("" otherwise).
        hint: String,
    },
    #[error(
        "{}: the no-specimen run's static gain x1/u is {}, where an actuator under P control follows its command at rest (1): the displacement reads {} times the command{hint}",
        path.display(),
        crate::units::format_number(*gain, 3),
        crate::units::format_number(*gain, 3)
    )]
    StaticGain {
        path: PathBuf,
        gain: f64,
        /// The likely unit mistake, when one explains it ("" otherwise).
        hint: String,
    },
    #[error(transparent)]
    Inverted(Box<Inverted>),
    #[error(
        "{}: the force against the displacement gives a stiffness of {} N/m where the specimen's is {} N/m ({} times it): a unit mistake? With channels.{channel}.unit = \"{}\" (the manifest says \"{}\") it gives {} N/m",
        path.display(),
        crate::units::format_number(*measured, 5),
        crate::units::format_number(*stated, 6),
        crate::units::format_number(measured / stated, 3),
        fix.symbol(),
        given.symbol(),
        crate::units::format_number(*fixed, 5)
    )]
    StiffnessUnit {
        path: PathBuf,
        measured: f64,
        stated: f64,
        /// The channel whose unit fits, the manifest's and the one that
        /// fits, and the stiffness with it (N/m).
        channel: &'static str,
        given: crate::units::Unit,
        fix: crate::units::Unit,
        fixed: f64,
    },
    #[error("{}: {source}", path.display())]
    Tf {
        path: PathBuf,
        #[source]
        source: RunTfError,
    },
}

/// A channel that reads its signal inverted: its gain at the band's
/// lowest frequencies against the signal it follows, and what to set.
#[derive(Debug, thiserror::Error)]
#[error(
    "{}: the {channel} reads {what} (its gain to the {against} at {} Hz is {} at {:.0} degrees, where {expected}): {cause}? Set channels.{channel}.scale = {} (the sign reversed), or fix the sensor's wiring",
    path.display(),
    crate::units::format_number(*at_hz, 3),
    crate::units::format_number(gain.norm(), 3),
    gain.arg().to_degrees(),
    crate::units::format_number(-scale, 6)
)]
pub struct Inverted {
    pub path: PathBuf,
    pub channel: &'static str,
    /// What the channel reads, and against what its gain is taken.
    pub what: &'static str,
    pub against: &'static str,
    pub at_hz: f64,
    pub gain: nalgebra::Complex<f64>,
    /// What the gain should be, and what makes it otherwise.
    pub expected: &'static str,
    pub cause: &'static str,
    /// The channel's scale the manifest gives.
    pub scale: f64,
}

/// Largest tolerated sample-interval deviation (fraction of the interval)
/// and clipped fraction of a channel.
const MAX_JITTER_FRACTION: f64 = 0.05;
const CLIP_FRACTION: f64 = 0.01;
/// Below this fraction of the command's power inside the band, the log has
/// no excitation there.
const MIN_BAND_POWER_FRACTION: f64 = 1e-6;

/// Run the log stage of one run.
pub fn log_stage(
    run: &RunPlan,
    plan: &LogPlan,
    ident: &IdentificationPlan,
) -> Result<LogStage, LogStageError> {
    log_stage_from(run, plan, ident, LogFile::read(&plan.path, plan.max_bytes)?)
}

/// The command of run `plan`'s log as its fit saw it (trimmed when the
/// identification trims), for the Monte Carlo to replay; errors when the
/// log is no longer the one `sha256` names.
pub fn replayed_command(
    plan: &LogPlan,
    ident: &IdentificationPlan,
    sha256: &str,
) -> Result<Vec<f64>, IngestError> {
    let mut log = ingest::read_log(plan)?;
    if log.sha256 != sha256 {
        return Err(IngestError::Changed {
            path: plan.path.clone(),
            before: format!("SHA-256 {sha256} when its run was analysed"),
            after: format!(
                "SHA-256 {} when the Monte Carlo read its command",
                log.sha256
            ),
        });
    }
    if ident.trim_to_excitation {
        log = ingest::trim_to_excitation(&log, 0.01);
    }
    Ok(log.command_m)
}

/// A log read from `file` and checked (units, NaN, monotonic time, clipping,
/// length), trimmed to its excitation when the manifest asks, with its
/// warnings.
fn checked_log(
    run: &RunPlan,
    plan: &LogPlan,
    ident: &IdentificationPlan,
    file: LogFile,
) -> Result<(Log, Vec<Warning>), IngestError> {
    let mut log = ingest::read_log_from(plan, file)?;
    let needs = Needs {
        min_samples: ident.frf.min_samples(),
        max_jitter_fraction: MAX_JITTER_FRACTION,
        clip_fraction: CLIP_FRACTION,
        // Nothing attached loads the force, whatever the run's role.
        force_loaded: run.role != Role::NoSpecimen && run.specimen != SpecimenModel::None,
    };
    // check_log returns the log's own warnings with its findings, so each
    // warning is listed once.
    let mut warnings = ingest::check_log(&log, &needs)?;
    if ident.trim_to_excitation {
        log = ingest::trim_to_excitation(&log, 0.01);
        // Trimming can leave too little for one segment.
        warnings = ingest::check_log(&log, &needs)?;
    }
    Ok((log, warnings))
}

/// The command's power in `band` (Hz), from the FRF's input spectrum,
/// against its `total` over every bin but DC ([`frf::Estimate::input_total`]); 0
/// without power.
fn band_power_fraction(h: &Frf, total: f64, (lo, hi): (f64, f64)) -> f64 {
    let in_band: f64 = h
        .freq_hz
        .iter()
        .zip(&h.suu)
        .filter(|(f, _)| **f >= lo && **f <= hi)
        .map(|(_, s)| s)
        .sum();
    if total > 0.0 { in_band / total } else { 0.0 }
}

/// The warning for an explicit ETFE or Welch estimate of a command not at
/// rest at the record's ends, whose transient it counts as noise (`auto`
/// fits it, the LPM takes it out).
fn motion_warning(
    choice: &FrfChoice,
    command: &[f64],
    sample_rate_hz: f64,
    band_hz: (f64, f64),
) -> Option<Warning> {
    let plan = &choice.plan;
    if choice.chosen || plan.method() == frf::Method::Lpm {
        return None;
    }
    let w = frf::rest_window(sample_rate_hz, band_hz.0);
    let (end, ratio) = frf::ends_in_motion(command, w)?;
    let (estimator, short) = match plan.method() {
        frf::Method::H1 => ("Welch H1 estimate", "H1"),
        frf::Method::H2 => ("Welch H2 estimate", "H2"),
        _ => ("ETFE", "ETFE"),
    };
    Some(Warning::new(
        format!("identification.frf: the {short} takes the motion at the record's {end} as noise"),
        format!(
            "identification.frf: the command is not at rest at the record's {end} (over its first or last {} s, or between its ends, it moves by {:.0} % of its RMS): the {estimator} counts the transient's leakage as noise, and the fits' stds come out too large (1.5 to 7 times on sweeps cut in motion); the default estimator (identification.frf.estimator left out, \"auto\") fits the transient beside the model and takes it out",
            crate::units::format_number(w as f64 / sample_rate_hz, 3),
            100.0 * ratio,
        ),
    ))
}

/// Why settings the manifest names are wrong for this log, if they are:
/// Welch segments over a sweep (each sees another part of it), fewer
/// segments than the averages need, a tapered window over a whole sweep.
fn contradiction(plan: &FrfPlan, excitation: frf::Excitation, n: usize) -> Option<String> {
    let mut why = Vec::new();
    let welch = plan.method().is_welch();
    let sweep = matches!(excitation, frf::Excitation::Sweep { .. });
    if welch && sweep {
        why.push(format!(
            "the {} of {}: each segment sees another part of the sweep, which biases the estimate and its coherence (on simulated sweeps of the paper's rig a1b0 came out 16 % high from 20 s records with 8,192-sample segments, a3 1.1 % from 170 s ones)",
            frf::describe(plan),
            excitation.describe()
        ));
    }
    if welch {
        let l = plan.segment_length();
        let hop = l - (plan.overlap() * l as f64).floor() as usize;
        let segments = n.saturating_sub(l) / hop.max(1) + 1;
        if segments < MIN_WELCH_SEGMENTS {
            why.push(format!(
                "the record of {n} samples holds only {segments} of the {}-sample segments: the coherence and the variances are read from too few averages (at least {MIN_WELCH_SEGMENTS})",
                plan.segment_length()
            ));
        }
    }
    if !welch && plan.window() != frf::Window::Rectangular && sweep {
        why.push(format!(
            "a {:?} window over the whole record of {} weighs the sweep's start and end down to nothing",
            plan.window(),
            excitation.describe()
        ));
    }
    (!why.is_empty()).then(|| why.join("; "))
}

/// A no-specimen run's static gain beyond which its channels' units are
/// taken as wrong: the gain is 1 (Eqs. 11-12, n0 = d0 = a1b0), a real rig's
/// within a few per cent (the MTS press's 1.008); a unit mistake puts it a
/// factor of 2.54 (inches) or more away.
const STATIC_GAIN_LIMIT: f64 = 2.0;
/// Beyond this (but within the limit) the gain is a warning.
const STATIC_GAIN_WARN: f64 = 1.1;

/// The no-specimen run's static gain n0/d0 against 1: an error naming the
/// likely unit mistake beyond [`STATIC_GAIN_LIMIT`], a warning beyond
/// [`STATIC_GAIN_WARN`].
fn static_gain_check(
    path: &std::path::Path,
    plan: &LogPlan,
    fit: &TfFit,
) -> Result<Option<Warning>, LogStageError> {
    let (n0, d0) = (
        fit.tf.num.last().copied().unwrap_or(f64::NAN),
        fit.tf.den.last().copied().unwrap_or(f64::NAN),
    );
    let gain = n0 / d0;
    let off = gain.max(1.0 / gain);
    if !gain.is_finite() || gain <= 0.0 || off <= STATIC_GAIN_WARN {
        return Ok(None);
    }
    if off <= STATIC_GAIN_LIMIT {
        return Ok(Some(Warning::new(
            format!(
                "the no-specimen run's static gain is {gain:.4}, {:.0} % from 1",
                100.0 * (gain - 1.0).abs()
            ),
            format!(
                "{}: the no-specimen run's static gain x1/u is {gain:.4}, {:.0} % from the 1 an actuator under P control has at rest: check the channels' scale and offset, and that the run had no specimen",
                path.display(),
                100.0 * (gain - 1.0).abs()
            ),
        )));
    }
    let ch = &plan.channels;
    let unit_for = |factor: f64| {
        [
            crate::units::Unit::Meter,
            crate::units::Unit::Centimeter,
            crate::units::Unit::Millimeter,
            crate::units::Unit::Inch,
        ]
        .into_iter()
        .find(|u| (u.to_si() / factor - 1.0).abs() < 0.05)
    };
    // x1 = gain u: the displacement's factor to SI is gain times too
    // large, or the command's gain times too small.
    let mut fixes = Vec::new();
    if let Some(u) = unit_for(ch.displacement.unit.to_si() / gain) {
        fixes.push(format!(
            "channels.displacement.unit = \"{}\" (the manifest says \"{}\")",
            u.symbol(),
            ch.displacement.unit.symbol()
        ));
    }
    if let Some(u) = unit_for(ch.command.unit.to_si() * gain) {
        fixes.push(format!(
            "channels.command.unit = \"{}\" (the manifest says \"{}\")",
            u.symbol(),
            ch.command.unit.symbol()
        ));
    }
    let hint = if fixes.is_empty() {
        ": check the channels' units and scales".to_string()
    } else {
        format!(
            ": a unit mistake? The gain is 1 with {}",
            fixes.join(", or with ")
        )
    };
    Err(LogStageError::StaticGain {
        path: path.to_path_buf(),
        gain,
        hint,
    })
}

/// The bins a channel's polarity is read at: the fit band's lowest coherent
/// ones, up to twice the first's frequency (at most this many).
const POLARITY_BINS: usize = 64;

/// An FRF averaged (weighted by the command's power) over the band's lowest
/// coherent bins, with the first one's frequency: an actuator under P
/// control follows its command there with a gain near its static gain,
/// positive for any specimen (Eqs. 12, 14, 17: n0 / d0 > 0), and a
/// specimen's force follows its displacement with its stiffness. None
/// without a coherent bin.
fn low_band_gain(h: &Frf, mask: &[bool]) -> Option<(nalgebra::Complex<f64>, f64)> {
    let first = mask.iter().position(|m| *m)?;
    let top = 2.0 * h.freq_hz[first];
    let (sum, weight) = (first..h.h.len())
        .filter(|&k| mask[k] && h.freq_hz[k] <= top)
        .take(POLARITY_BINS)
        .fold((nalgebra::Complex::new(0.0, 0.0), 0.0), |(s, w), k| {
            (s + h.h[k] * h.suu[k], w + h.suu[k])
        });
    (weight > 0.0).then(|| (sum / weight, h.freq_hz[first]))
}

/// A gain whose phase is this far from zero reads a signal inverted.
const INVERTED_PHASE: f64 = 2.0 * std::f64::consts::PI / 3.0;

/// Refuse a displacement that answers its command with the opposite sign.
fn displacement_polarity(
    path: &std::path::Path,
    plan: &LogPlan,
    h: &Frf,
    mask: &[bool],
) -> Result<(), LogStageError> {
    match low_band_gain(h, mask) {
        Some((gain, at_hz)) if gain.arg().abs() > INVERTED_PHASE => {
            Err(LogStageError::Inverted(Box::new(Inverted {
                path: path.to_path_buf(),
                channel: "displacement",
                what: "the command's motion inverted",
                against: "command",
                at_hz,
                gain,
                expected: "an actuator under P control follows its command in phase",
                cause: "an LVDT wired backwards, or a negative scale",
                scale: manifest_scale(&plan.channels.displacement),
            })))
        }
        _ => Ok(()),
    }
}

/// A channel's `scale` as the manifest gives it: its gain to SI without
/// its unit's factor.
fn manifest_scale(channel: &ingest::ChannelPlan) -> f64 {
    channel.gain / channel.unit.to_si()
}

/// The units a channel's reading is tried in, by what it measures.
const FORCE_UNITS: [crate::units::Unit; 3] = [
    crate::units::Unit::Newton,
    crate::units::Unit::Kilonewton,
    crate::units::Unit::PoundForce,
];
const LENGTH_UNITS: [crate::units::Unit; 4] = [
    crate::units::Unit::Meter,
    crate::units::Unit::Centimeter,
    crate::units::Unit::Millimeter,
    crate::units::Unit::Inch,
];

/// Refuse a force whose ratio to the displacement (`measured`, N/m) has the
/// sign or the scale of another unit against the specimen's stiffness
/// `stated`: inverted (a load cell wired backwards), or a channel in
/// another unit than the manifest's (N declared as kN reads a thousandth
/// of the load, mm declared as cm ten times the displacement).
fn force_scale(
    path: &std::path::Path,
    plan: &LogPlan,
    measured: f64,
    stated: f64,
    at_hz: f64,
) -> Result<(), LogStageError> {
    let Some(force) = plan.channels.force.as_ref() else {
        return Ok(());
    };
    let ratio = measured / stated;
    if ratio < 0.0 && (0.5..2.0).contains(&-ratio) {
        return Err(LogStageError::Inverted(Box::new(Inverted {
            path: path.to_path_buf(),
            channel: "force",
            what: "the load inverted",
            against: "displacement",
            at_hz,
            gain: nalgebra::Complex::new(measured, 0.0),
            expected: "a specimen pushes back on its displacement, with its stiffness",
            cause: "a load cell wired backwards, or a negative scale",
            scale: manifest_scale(force),
        })));
    }
    if (ratio - 1.0).abs() <= 0.5 {
        return Ok(());
    }
    // The stiffness is force over displacement: a force unit's factor
    // multiplies it, a displacement unit's divides it.
    let displacement = &plan.channels.displacement;
    let fits = |channel, given: crate::units::Unit, units: &[crate::units::Unit], power: i32| {
        units
            .iter()
            .copied()
            .filter(|u| *u != given)
            .find_map(|fix| {
                let fixed = measured * (fix.to_si() / given.to_si()).powi(power);
                ((fixed / stated - 1.0).abs() < STIFFNESS_UNIT_TOLERANCE)
                    .then_some((channel, given, fix, fixed))
            })
    };
    let found = fits("force", force.unit, &FORCE_UNITS, 1)
        .or_else(|| fits("displacement", displacement.unit, &LENGTH_UNITS, -1));
    match found {
        Some((channel, given, fix, fixed)) => Err(LogStageError::StiffnessUnit {
            path: path.to_path_buf(),
            measured,
            stated,
            channel,
            given,
            fix,
            fixed,
        }),
        None => Ok(()),
    }
}

/// The force's scale against the specimen's stiffness ([`force_scale`]): a
/// spring's from its force against its displacement over the record, a
/// validation specimen's from the two FRFs at the band's lowest bins, where
/// its force is its stiffness times its displacement. Nothing for a run
/// without a specimen or a force.
fn check_force_scale(
    path: &std::path::Path,
    plan: &LogPlan,
    run: &RunPlan,
    spring: Option<&frf::SpringForce>,
    h: &Frf,
    force_frf: Option<&Frf>,
    mask: &[bool],
) -> Result<(), LogStageError> {
    let at_hz = || low_band_gain(h, mask).map_or(0.0, |(_, f)| f);
    match (run.specimen, spring, force_frf) {
        (SpecimenModel::Spring { stiffness_n_per_m }, Some(s), _) => {
            force_scale(path, plan, s.stiffness_n_per_m, stiffness_n_per_m, at_hz())
        }
        (
            SpecimenModel::LinearSdof {
                stiffness_n_per_m, ..
            },
            _,
            Some(hf),
        ) => match (low_band_gain(hf, mask), low_band_gain(h, mask)) {
            (Some((gf, at_hz)), Some((gx, _))) if gx.norm() > 0.0 => {
                force_scale(path, plan, (gf / gx).re, stiffness_n_per_m, at_hz)
            }
            _ => Ok(()),
        },
        _ => Ok(()),
    }
}

/// How near a unit's factor must bring a force's stiffness to the stated
/// one to name it.
const STIFFNESS_UNIT_TOLERANCE: f64 = 0.05;

/// The warning for a rig that did not answer the sweep linearly.
fn nonlinearity_warning(l: &frf::Linearity) -> Option<Warning> {
    l.nonlinear().then(|| {
        Warning::new(
            linearity_headline(l),
            format!(
                "{}: the rig is not linear at this amplitude ({}); a linear model's fit and the rig from it are an equivalent linear rig's at this amplitude, with an error their stds do not include: test again at another amplitude to see how far it moves",
                linearity_note(l),
                NONLINEAR_CAUSES
            ),
        )
    })
}

/// The largest harmonic a nonlinear rig's sweep holds, in a line.
fn linearity_headline(l: &frf::Linearity) -> String {
    let found = [("displacement", l.displacement), ("force", l.force)]
        .into_iter()
        .filter_map(|(name, f)| {
            f.filter(|f| f.blocks >= frf::linearity::MIN_BLOCKS)
                .map(|f| (name, f))
        })
        .max_by(|a, b| a.1.largest.total_cmp(&b.1.largest));
    match found {
        Some((name, f)) => format!(
            "not linear at this amplitude: the {name}'s {} harmonic is {:.1} % of it at {:.1} Hz",
            if f.order == 2 { "second" } else { "third" },
            100.0 * f.largest,
            f.at_hz
        ),
        None => "the rig is not linear at this amplitude".to_string(),
    }
}

/// The linearity check in words, as the run's page says it.
pub fn linearity_note(l: &frf::Linearity) -> String {
    if !l.nonlinear() {
        return format!(
            "no harmonics of the command beyond a linear rig's in the {} blocks of the sweep checked",
            l.checked
        );
    }
    let what = |name: &str, beyond: &str, f: &frf::linearity::Found| {
        format!(
            "the {name} holds harmonics of the command beyond the {beyond}'s in {} of {} blocks of the sweep (the largest, the {}, {:.2} % of the {name}'s amplitude where the sweep is at {:.1} Hz)",
            f.blocks,
            l.checked,
            if f.order == 2 { "second" } else { "third" },
            100.0 * f.largest,
            f.at_hz
        )
    };
    let mut parts = Vec::new();
    if let Some(f) = l
        .displacement
        .filter(|f| f.blocks >= frf::linearity::MIN_BLOCKS)
    {
        parts.push(what("displacement", "command", &f));
    }
    if let Some(f) = l.force.filter(|f| f.blocks >= frf::linearity::MIN_BLOCKS) {
        parts.push(what("force", "displacement", &f));
    }
    parts.join("; ")
}

/// Beyond this the stiffness a spring's force and displacement give and the
/// one the manifest states disagree: a load cell is good to a fraction of
/// a per cent, and the rig's a1b0 moves with k (Eq. 19).
pub const STIFFNESS_MISMATCH: f64 = 0.02;

/// The warning for a spring whose force and displacement give another
/// stiffness than the manifest's.
fn stiffness_warning(s: &frf::SpringForce, stated: f64) -> Option<Warning> {
    let off = s.stiffness_n_per_m / stated - 1.0;
    (off.abs() > STIFFNESS_MISMATCH).then(|| {
        Warning::new(
            format!(
                "the load cell gives k = {} N/m, {:+.1} % from the stated stiffness",
                crate::units::format_number(s.stiffness_n_per_m, 5),
                100.0 * off
            ),
            format!(
            "the spring's force against its displacement gives a stiffness of {} N/m, {:+.1} % from the {} N/m the manifest states (specimen.stiffness_n_per_m): a stiffness typed wrong, another run's log, or the load cell's scale? Eqs. 18-20 take the stated one as exact",
            crate::units::format_number(s.stiffness_n_per_m, 5),
            100.0 * off,
            crate::units::format_number(stated, 6)
            ),
        )
    })
}

/// The warning for a spring that stiffens at the test's amplitude.
fn stiffening_warning(s: &frf::SpringForce) -> Option<Warning> {
    s.stiffens().then(|| {
        Warning::new(
            format!(
                "not linear at this amplitude: the spring is {:+.2} % stiffer at {} mm than at rest",
                100.0 * s.stiffening,
                crate::units::format_number(1e3 * s.amplitude_m, 3)
            ),
            format!(
            "the spring's force grows faster than its displacement: its stiffness at the test's {} mm is {:+.2} % from its stiffness at rest (a cubic term of {:e} N/m^3, t = {:.0}): the rig is not linear at this amplitude (a stiffening spring); Eqs. 18-20 take one stiffness, so the sequential rig carries an error its stds do not include; the joint fit takes the spring at its amplitude (the rig's warnings say so). To use the paper's method, test at a smaller amplitude or with a spring that stays linear",
            crate::units::format_number(1e3 * s.amplitude_m, 3),
            100.0 * s.stiffening,
            s.cubic_n_per_m3,
            s.cubic_t
            ),
        )
    })
}

/// A channel whose consecutive samples are equal this often is not
/// dithered by its noise: its quantisation error follows the signal.
const UNDITHERED_SHARE: f64 = 0.25;
/// Beyond this share of its RMS an undithered converter step is coarse.
const COARSE_STEP_SHARE: f64 = 0.01;

/// What a misfit is put down to where the displacement's converter is
/// coarse and its noise too small to dither it: the quantisation error
/// then follows the signal (a distortion at each frequency the sweep
/// passes) where the FRF's variances take white noise. None otherwise.
fn coarse_quantisation(x: &[f64]) -> Option<String> {
    let n = x.len();
    if n < 2 {
        return None;
    }
    let equal = x.windows(2).filter(|w| w[0] == w[1]).count() as f64 / (n - 1) as f64;
    if equal < UNDITHERED_SHARE {
        return None;
    }
    let step = ingest::quantum_step(x)?;
    let mean = x.iter().sum::<f64>() / n as f64;
    let rms = (x.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / n as f64).sqrt();
    (step > COARSE_STEP_SHARE * rms).then(|| {
        format!(
            "the displacement's coarse quantisation: its converter's step of {} mm is {:.1} % of its RMS and its noise does not dither it ({:.0} % of consecutive samples equal), so the quantisation error follows the signal where the FRF's variances take white noise; log the displacement at a finer resolution or range",
            crate::units::format_number(1e3 * step, 3),
            100.0 * step / rms,
            100.0 * equal
        )
    })
}

/// A misfit put down to a nonlinear reading (`slow_gain_findings`).
pub const READING_CAUSE: &str = "the logged displacement or command read through a nonlinearity the loop does not see (the unloaded run's warning)";

/// Where a sweep is slow the loop makes the displacement it feeds back
/// follow the command through a gain flat with amplitude, and without a
/// specimen nothing loads the actuator there (no pressure, no leakage
/// flow): an unloaded run's logged displacement whose gain against the
/// command changes with amplitude there (`frf::slow_cubic`) is read
/// through something nonlinear that the loop does not see; a warning names
/// it, and it is what the run's misfit is put down to. A loaded run's gain
/// may change with its load as well (the servo-valve's flow falls with the
/// load pressure): the run states what it found and leaves the cause to
/// the campaign, which reads every run's (`rig::slow_gain_pattern`). Not
/// given a displacement that holds friction's harmonics: friction changes
/// the slow gain too, and the linearity check names it.
fn slow_gain_findings(
    run: &RunPlan,
    slow: Option<&frf::SlowCubic>,
) -> (Option<Warning>, Option<String>) {
    let Some(found) = slow.filter(|s| s.significant()) else {
        return (None, None);
    };
    if run.specimen.loads() {
        let cause = format!(
            "its gain against the command changes by {:+.2} % at {} mm where the sweep is below {} Hz (t = {:.0}): a gain that changes with amplitude, which the rig's warnings put down to the load or the reading",
            100.0 * found.share,
            crate::units::format_number(1e3 * found.amplitude_m, 2),
            frf::linearity::SLOW_HZ,
            found.t.abs()
        );
        return (None, Some(cause));
    }
    let warning = Warning::new(
        format!(
            "a nonlinear reading: the slow gain changes {:+.2} % at {} mm with no load (t = {:.0})",
            100.0 * found.share,
            crate::units::format_number(1e3 * found.amplitude_m, 2),
            found.t.abs()
        ),
        format!(
            "the displacement's gain against the command changes by {:+.2} % at {} mm where the sweep is below {} Hz (t = {:.0}, over {:.1} s), where the loop makes the displacement it feeds back follow the command and no specimen loads the actuator: the logged displacement or command is read through a nonlinearity the loop does not see (a sensor, its conditioning or a range other than the controller's); calibrate the logged channels against the controller's over their range",
            100.0 * found.share,
            crate::units::format_number(1e3 * found.amplitude_m, 2),
            frf::linearity::SLOW_HZ,
            found.t.abs(),
            found.seconds
        ),
    );
    (Some(warning), Some(READING_CAUSE.to_string()))
}

/// A run's misfit put down to its FRF settings, or to the rig's
/// nonlinearity, when its warnings found either.
pub const SETTINGS_CAUSE: &str = "the FRF settings the log contradicts (identification.frf: the warning above names them and what the default would use)";
pub const NONLINEAR_CAUSE: &str = "the rig is not linear at this amplitude (the warning above says how): no linear structure holds it";
pub const STIFFNESS_CAUSE: &str = "the spring's stiffness the manifest states, which its force and displacement contradict (the warning above)";

/// A cause a misfit is put down to (a run's, or the campaign's: the
/// constants above, `rig::LOAD_GAIN_CAUSE`, the springs' disagreement, the
/// friction's harmonics), named in a few words for a headline; a run's
/// cause may carry its run's id ("run k1: ...").
pub fn cause_name(cause: &str) -> Option<&'static str> {
    let cause = match cause.split_once(": ") {
        Some((run, rest)) if run.starts_with("run ") => rest,
        _ => cause,
    };
    let named: [(&str, &str); 10] = [
        (SETTINGS_CAUSE, "the FRF settings"),
        (STIFFNESS_CAUSE, "the stated stiffness"),
        (NONLINEAR_CAUSE, "a nonlinear rig"),
        (READING_CAUSE, "a nonlinear reading"),
        (
            "its gain against the command changes",
            "an amplitude-dependent gain",
        ),
        (
            "the displacement's coarse quantisation",
            "coarse quantisation",
        ),
        ("a gain that depends on the load", "a load-dependent gain"),
        ("the springs' disagreement", "the springs' disagreement"),
        ("the seal friction's harmonics", "seal friction's harmonics"),
        ("the valve flow law's harmonics", "the flow law's harmonics"),
    ];
    named
        .iter()
        .find(|(text, _)| cause.starts_with(text))
        .map(|(_, name)| *name)
}

/// `"; likely <name>"` for a headline whose misfit is put down to `cause`
/// ([`cause_name`]), or nothing.
pub fn likely(cause: Option<&str>) -> String {
    cause
        .and_then(cause_name)
        .map_or(String::new(), |n| format!("; likely {n}"))
}

/// What a response's harmonics point at, in a few words.
pub const NONLINEAR_CAUSES: &str = "seal friction puts odd harmonics into the displacement, a stiffening spring its third into the force";

/// The fewest Welch segments a record must hold for their averages.
const MIN_WELCH_SEGMENTS: usize = 8;

/// For settings the manifest names that the log contradicts
/// ([`contradiction`]), a warning naming what the default (`auto`) would
/// choose and, for a run fitted here, how far its own fit would move with
/// that choice, in its stds.
fn settings_warning(
    run: &RunPlan,
    ident: &IdentificationPlan,
    choice: &FrfChoice,
    excitation: frf::Excitation,
    log: &Log,
    fit: Option<&TfFit>,
) -> Option<Warning> {
    if choice.chosen {
        return None;
    }
    let why = contradiction(&choice.plan, excitation, log.command_m.len())?;
    let (u, y, fs) = (&log.command_m, &log.displacement_m, log.sample_rate_hz);
    let mut text = format!("identification.frf: {why}");
    let headline = "identification.frf: settings this log contradicts; the default would suit it";
    let Ok(auto) = frf::FrfRequest::default().resolve(u, y, fs, run.band_hz) else {
        return Some(Warning::new(headline, text));
    };
    text += &format!(
        "; the default (leave identification.frf.estimator out: \"auto\") would use the {}",
        frf::describe(&auto.plan)
    );
    let moved = fit.and_then(|fit| {
        let mut h = frf::estimate_one(u, y, fs, &auto.plan).ok()?;
        let mask = frf::band_mask(&h, run.band_hz, ident.coherence_min);
        let (other, _) = fit_run(&mut h, &mask, run.band_hz, ident, &auto.plan, fs, None).ok()?;
        let parts: Vec<String> = fit
            .param_names
            .iter()
            .zip(fit.params.iter().zip(&fit.std))
            .zip(&other.params)
            .map(|((name, (p, sd)), q)| {
                format!(
                    "{name} {:+.2} % ({:+.1} stds)",
                    100.0 * (q / p - 1.0),
                    (q - p) / sd
                )
            })
            .collect();
        Some(parts.join(", "))
    });
    if let Some(moved) = moved {
        text += &format!(", with which this run's own fit moves by {moved}");
    }
    Some(Warning::new(headline, text))
}

/// A run's bins as its own log stage makes them, with the logged
/// displacement replaced, in turn, by each of `n` displacements
/// `displacement(log, i)` of the checked log (simulations driven by its
/// own command), side by side; the log is read and checked once. Each is
/// None where `displacement` gives none; the whole None where the run has
/// no log.
pub fn fit_data_with(
    campaign: &Campaign,
    run: &RunPlan,
    n: usize,
    displacement: impl Fn(&Log, usize) -> Option<Vec<f64>> + Sync,
) -> Result<Option<Vec<Option<FitData>>>, LogStageError> {
    use rayon::prelude::*;
    let RunSource::Log(plan) = &run.source else {
        return Ok(None);
    };
    let ident = &campaign.identification;
    let file = LogFile::read(&plan.path, plan.max_bytes)?;
    let (log, _) = checked_log(run, plan, ident, file)?;
    let (log, _) = steady_part(log, ident, run.band_hz);
    let fs = log.sample_rate_hz;
    let data = (0..n)
        .into_par_iter()
        .map(|i| {
            let Some(displacement_m) = displacement(&log, i) else {
                return Ok(None);
            };
            let log = Log {
                displacement_m,
                ..log.clone()
            };
            let Frfs { choice, mut h, .. } = estimate_frfs(run, ident, &log, &plan.path, false)?;
            let mask = frf::band_mask(&h, run.band_hz, ident.coherence_min);
            let (_, data) = fit_run(&mut h, &mask, run.band_hz, ident, &choice.plan, fs, None)
                .map_err(|source| tf_error(&plan.path, source))?;
            Ok(Some(data))
        })
        .collect::<Result<Vec<_>, LogStageError>>()?;
    Ok(Some(data))
}

/// The log stage of one run whose log file is already read.
pub fn log_stage_from(
    run: &RunPlan,
    plan: &LogPlan,
    ident: &IdentificationPlan,
    file: LogFile,
) -> Result<LogStage, LogStageError> {
    let path = &plan.path;
    let (log, mut warnings) = checked_log(run, plan, ident, file)?;
    check_band_below_nyquist(run, &log, path)?;
    let (log, periodic) = steady_part(log, ident, run.band_hz);
    warnings.extend(periodic.as_ref().and_then(distortion_warning));
    let fs = log.sample_rate_hz;
    let Frfs {
        mut choice,
        mut h,
        force_frf,
        command_dft,
    } = estimate_frfs(run, ident, &log, path, true)?;
    // `auto`'s fit of a command of sparse lines reads the transient and the
    // noise from the lines between them (`identify::run_fit`), as the
    // reason then says.
    if choice.chosen && choice.plan.model_noise() && frf::sparse_lines(&h, run.band_hz) {
        choice.reason = lines_reason(&choice.reason, periodic.as_ref(), fs);
        choice.plan = choice.plan.clone().with_steady_periods(periodic.is_some());
    }
    let mask = frf::band_mask(&h, run.band_hz, ident.coherence_min);
    displacement_polarity(path, plan, &h, &mask)?;
    warnings.extend(motion_warning(&choice, &log.command_m, fs, run.band_hz));

    let fit = if matches!(run.role, Role::NoSpecimen | Role::Spring | Role::Fit) {
        let (fit, data) = fit_run(&mut h, &mask, run.band_hz, ident, &choice.plan, fs, None)
            .map_err(|source| tf_error(path, source))?;
        warnings.extend(fit.warnings.iter().cloned());
        Some((fit, data))
    } else {
        None
    };
    let (fit, fit_data) = fit.unzip();
    if run.role == Role::NoSpecimen
        && let Some(f) = &fit
    {
        warnings.extend(static_gain_check(path, plan, f)?);
    }
    let periodogram = (h.n_averages == 1).then_some(h.suu.as_slice());
    let excitation = frf::excitation(&log.command_m, fs, periodogram);
    let linearity = matches!(excitation, frf::Excitation::Sweep { .. })
        .then(|| linearity_of(&log, &run.specimen))
        .flatten();
    let fit_data = fit_data.map(|d| with_sweep_amplitude(d, excitation, &log));
    let spring = match (&run.specimen, &log.force_n) {
        (SpecimenModel::Spring { .. }, Some(f)) => frf::spring_force(&log.displacement_m, f, fs),
        _ => None,
    };
    check_force_scale(
        path,
        plan,
        run,
        spring.as_ref(),
        &h,
        force_frf.as_ref(),
        &mask,
    )?;
    let contradicted = settings_warning(run, ident, &choice, excitation, &log, fit.as_ref());
    let slow = matches!(excitation, frf::Excitation::Sweep { .. })
        .then(|| frf::slow_cubic(&log.command_m, &log.displacement_m, fs))
        .flatten();
    let friction = linearity
        .and_then(|l| l.displacement)
        .is_some_and(|f| f.blocks >= frf::linearity::MIN_BLOCKS);
    let (reading, slow_cause) = slow_gain_findings(run, slow.as_ref().filter(|_| !friction));
    warnings.extend(reading);
    let cause = findings(
        run,
        linearity.as_ref(),
        spring.as_ref(),
        contradicted,
        &mut warnings,
    )
    .or(slow_cause)
    .or_else(|| coarse_quantisation(&log.displacement_m));
    Ok(LogStage {
        log,
        periodic,
        choice,
        excitation,
        linearity,
        spring,
        slow,
        cause,
        frf: h,
        force_frf,
        command_dft,
        mask,
        fit,
        fit_data,
        warnings,
    })
}

/// A periodic log's steady periods and their levels over the band.
#[derive(Debug, Clone, PartialEq)]
pub struct Periodic {
    pub steady: frf::periodic::Steady,
    /// When the log's sample rate is known, the time its steady periods
    /// start at, from the log's first sample (s).
    pub start_s: f64,
    pub levels: frf::periodic::Levels,
    /// The log's samples before it was cut to the steady periods.
    pub log_rows: usize,
}

/// The empty lines' power over the noise floor above which a periodic
/// log's rig distorts: a linear rig's ratio scatters by 1 / sqrt(lines)
/// about 1, so this is many times that for a band's worth of lines.
pub const DISTORTION_RATIO: f64 = 2.0;

/// `log` cut to its command's steady periods where `auto` chooses the
/// estimator and the command has two or more: whole periods of a
/// periodic response hold only lines, with no transient between them, so
/// the FRF is read at the excited lines (`frf::at_lines`); and what the
/// periods say of the noise and the distortion.
fn steady_part(
    log: Log,
    ident: &IdentificationPlan,
    band_hz: (f64, f64),
) -> (Log, Option<Periodic>) {
    if ident.frf.estimator != frf::Estimator::Auto {
        return (log, None);
    }
    let fs = log.sample_rate_hz;
    // A period of a tenth of a second at least: shorter ones cannot hold a
    // band's worth of lines.
    let Some(mut steady) = frf::periodic::steady_periods(&log.command_m, fs, 0.1) else {
        return (log, None);
    };
    // The response settles a period after the command does: its first
    // period still holds the fade's transient (on the paper's rig some
    // 3 times the noise's density below 2 Hz), so it is left out where
    // two others remain.
    if steady.count >= 3 {
        steady.start += steady.period;
        steady.count -= 1;
    }
    // Only a command that leaves lines of the band empty (a random-odd
    // multisine, a square wave) is read on its lines; a repeated sweep
    // fills every line and keeps its whole record.
    let Some(levels) =
        frf::periodic::levels(&log.command_m, &log.displacement_m, steady, fs, band_hz)
    else {
        return (log, None);
    };
    let (start, end) = (steady.start, steady.start + steady.count * steady.period);
    let log_rows = log.n_rows;
    let mut cut = log;
    let keep = |v: &mut Vec<f64>| {
        v.truncate(end);
        v.drain(..start);
    };
    keep(&mut cut.command_m);
    keep(&mut cut.displacement_m);
    if let Some(f) = cut.force_n.as_mut() {
        keep(f);
    }
    cut.n_rows = end - start;
    cut.t0_s += start as f64 / fs;
    let periodic = Periodic {
        steady,
        start_s: start as f64 / fs,
        levels,
        log_rows,
    };
    (cut, Some(periodic))
}

/// The warning for a periodic log whose empty lines hold more than the
/// noise floor: the rig's own distortion (friction, a stiffening spring,
/// the valve's flow law), which the fit counts with the noise.
fn distortion_warning(p: &Periodic) -> Option<Warning> {
    let l = p.levels;
    let ratio = l.distortion_to_noise();
    (ratio > DISTORTION_RATIO).then(|| {
        Warning::new(
            format!("the rig distorts: the command's empty lines hold {ratio:.1} times the noise"),
            format!(
                "the {} lines the periodic command leaves empty in the band hold {} times the noise floor the {} periods' spread gives ({} lines excited): the rig answers the command with its own harmonics, a nonlinearity (seal friction, a stiffening spring, the valve's flow law); the fit counts them with the noise, so its stds include them",
                l.empty,
                crate::units::format_number(ratio, 3),
                p.steady.count,
                l.excited
            ),
        )
    })
}

/// `auto`'s reason where it reads a command of sparse lines at its
/// excited lines: a periodic log's steady periods, or (`reason` said of
/// the whole record) a record that holds whole periods.
fn lines_reason(reason: &str, periodic: Option<&Periodic>, fs: f64) -> String {
    match periodic {
        Some(p) => format!(
            "the FRF at the excited lines of the command's {} steady periods of {} s (from {} s into the log; the fades and rests around them left out), the noise level read from the lines between them (auto: whole periods of a periodic response hold only lines)",
            p.steady.count,
            crate::units::format_number(p.steady.period as f64 / fs, 6),
            crate::units::format_number(p.start_s, 6),
        ),
        None => format!(
            "{reason}; the command is sparse lines (a periodic command whose periods the record holds whole): the FRF is taken at its excited lines, the transient and the noise level read from the lines between them"
        ),
    }
}

/// Whether the rig answered the log's sweep linearly. Harmonics a channel's
/// converter step could make are not counted; the steps are read (a sort
/// of the channel) only where harmonics are found.
fn linearity_of(log: &Log, specimen: &SpecimenModel) -> Option<frf::Linearity> {
    let (u, x) = (&log.command_m, &log.displacement_m);
    let fs = log.sample_rate_hz;
    // The force is checked against the specimen's linear force (at rest,
    // for a nonlinear one): a spring's k, or k - m w^2 + i c w (Eq. 15);
    // not without a specimen to load it.
    let (m, c, k) = specimen.linearised_at_rest();
    let stiffness = |f_hz: f64| {
        let w = 2.0 * std::f64::consts::PI * f_hz;
        nalgebra::Complex::new(k - m * w * w, c * w)
    };
    let loaded = specimen.loads();
    let f = log
        .force_n
        .as_deref()
        .filter(|_| loaded)
        .map(|f| (f, &stiffness as frf::linearity::Stiffness<'_>));
    let found = frf::linearity(u, x, f, fs, [0.0; 2])?;
    if !found.nonlinear() {
        return Some(found);
    }
    let step = |v: &[f64]| ingest::quantum_step(v).unwrap_or(0.0);
    let steps = [step(x), f.map_or(0.0, |(f, _)| step(f))];
    frf::linearity(u, x, f, fs, steps)
}

/// A run's bins with the displacement's amplitude along its sweep: seal
/// friction's describing function depends on it, should the joint fit
/// find friction in any run (`LogStage::friction_signature`).
fn with_sweep_amplitude(data: FitData, excitation: frf::Excitation, log: &Log) -> FitData {
    match sweep_of(excitation, log) {
        Some(sweep) => data.with_amplitude(&sweep),
        None => data,
    }
}

/// The command's amplitude along a sweep, when the log's command is one.
pub fn sweep_of(excitation: frf::Excitation, log: &Log) -> Option<frf::SweepAmplitude> {
    matches!(excitation, frf::Excitation::Sweep { .. })
        .then(|| frf::sweep_amplitude(&log.command_m, log.sample_rate_hz))
        .flatten()
}

/// A fit's failure, named by the run's file.
fn tf_error(path: &std::path::Path, source: RunTfError) -> LogStageError {
    LogStageError::Tf {
        path: path.to_path_buf(),
        source,
    }
}

/// Refuse a fit band at or above the log's Nyquist frequency.
///
/// The manifest cannot know the rate of a log that carries its own (a time
/// column, a DAQ header), so the band is checked against it here.
fn check_band_below_nyquist(
    run: &RunPlan,
    log: &Log,
    path: &std::path::Path,
) -> Result<(), LogStageError> {
    let fs = log.sample_rate_hz;
    if run.band_hz.1 < 0.5 * fs {
        return Ok(());
    }
    // A time column in milliseconds read as seconds: a thousand times too
    // slow a rate, which a band in Hz then lies above.
    let hint = match log.timing {
        ingest::Timing::Measured { .. } if 500.0 * fs > run.band_hz.1 => format!(
            ": the time column steps {:.4} per sample; were it milliseconds (channels.time.unit = \"ms\"), the rate would be {} Hz",
            1.0 / fs,
            1000.0 * fs
        ),
        _ => String::new(),
    };
    Err(LogStageError::BandAboveNyquist {
        path: path.to_path_buf(),
        hi: run.band_hz.1,
        nyquist: 0.5 * fs,
        hint,
    })
}

/// The FRF settings the run gets, its command-to-displacement FRF and,
/// when the log has a force, its command-to-force FRF, each kept up to
/// what is read of it; refused when the band holds too little of the
/// command's power. With `share`, the command's transform for the
/// tracking where the FRF's is it.
fn estimate_frfs(
    run: &RunPlan,
    ident: &IdentificationPlan,
    log: &Log,
    path: &std::path::Path,
    share: bool,
) -> Result<Frfs, LogStageError> {
    let fs = log.sample_rate_hz;
    let frf_err = |source: FrfError| tf_error(path, RunTfError::Frf(source));
    let choice = ident
        .frf
        .resolve(&log.command_m, &log.displacement_m, fs, run.band_hz)
        .map_err(frf_err)?;
    // Nothing reads a bin above the band, the tables or the figures (and
    // the noise estimate's reach beyond them) but the band's share of the
    // command's power: those bins are not kept (a long ETFE's bins up to
    // Nyquist took half the memory of a 1 GB log's analysis).
    let (lo, hi) = run.band_hz;
    let keep_hz = hi.max(frf::KEPT_MAX_HZ);
    let kept = frf::Keep::UpTo {
        hz: keep_hz,
        extra_bins: frf::VARIANCE_REACH_BINS,
    };
    // Both FRFs read the one command's transforms, and keep the same band
    // of the command's: a validation run's force FRF in the joint fit is
    // read at a periodic command's lines as its displacement's is
    // (`identify::FitData::at_lines`).
    let mut outputs = vec![frf::Output {
        y: &log.displacement_m,
        plan: &choice.plan,
    }];
    outputs.extend(log.force_n.as_deref().map(|y| frf::Output {
        y,
        plan: &choice.plan,
    }));
    let (estimates, command_dft) =
        frf::estimate_sharing(&log.command_m, &outputs, fs, kept, share).map_err(frf_err)?;
    let mut estimates = estimates.into_iter();
    let frf::Estimate {
        frf: h,
        input_total,
    } = estimates.next().expect("the displacement's FRF");
    let force_frf = estimates.next().map(|e| e.frf);
    let fraction = band_power_fraction(&h, input_total, run.band_hz);
    if fraction < MIN_BAND_POWER_FRACTION {
        return Err(tf_error(
            path,
            RunTfError::NoExcitation { lo, hi, fraction },
        ));
    }
    Ok(Frfs {
        choice,
        h,
        force_frf,
        command_dft,
    })
}

/// What [`estimate_frfs`] gives.
struct Frfs {
    choice: FrfChoice,
    h: Frf,
    force_frf: Option<Frf>,
    /// The command's whole transform, where the FRF's is the tracking's
    /// ([`frf::estimate_sharing`]).
    command_dft: Option<Vec<nalgebra::Complex<f64>>>,
}

/// Warn of what the log shows wrong (a stiffness the spring's force
/// contradicts, a rig not linear, FRF settings the log contradicts), in
/// that order, and name what any misfit of the run's fit is put down to:
/// the first of the settings, the stiffness and the nonlinearity found.
fn findings(
    run: &RunPlan,
    linearity: Option<&frf::Linearity>,
    spring: Option<&frf::SpringForce>,
    contradicted: Option<Warning>,
    warnings: &mut Vec<Warning>,
) -> Option<String> {
    let stated_k = match run.specimen {
        SpecimenModel::Spring { stiffness_n_per_m } => Some(stiffness_n_per_m),
        _ => None,
    };
    let mistyped = spring
        .zip(stated_k)
        .and_then(|(s, k)| stiffness_warning(s, k));
    let nonlinear = linearity
        .and_then(nonlinearity_warning)
        .or_else(|| spring.and_then(stiffening_warning));
    warnings.extend(mistyped.clone());
    warnings.extend(nonlinear.clone());
    let cause = if contradicted.is_some() {
        Some(SETTINGS_CAUSE.to_string())
    } else if mistyped.is_some() {
        Some(STIFFNESS_CAUSE.to_string())
    } else if nonlinear.is_some() {
        Some(NONLINEAR_CAUSE.to_string())
    } else {
        None
    };
    warnings.extend(contradicted);
    cause
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Each cause a misfit is put down to has a short name, short enough
    /// for a headline beside a fit's numbers, found past a run's id.
    #[test]
    fn each_cause_has_a_short_name() {
        let causes = [
            SETTINGS_CAUSE.to_string(),
            STIFFNESS_CAUSE.to_string(),
            NONLINEAR_CAUSE.to_string(),
            format!("run spring-k1: {READING_CAUSE}"),
            crate::analysis::rig::LOAD_GAIN_CAUSE.to_string(),
        ];
        for c in &causes {
            let name = cause_name(c).unwrap_or_else(|| panic!("no name for {c}"));
            assert!(name.len() <= 27, "{name}");
        }
        assert_eq!(
            cause_name(&format!("run k1: {READING_CAUSE}")),
            Some("a nonlinear reading")
        );
        assert_eq!(cause_name("run k1: something else"), None);
    }
}
