//! The first stage of a run: its own transfer function, published or
//! measured. A run with a log is read (ingest), checked against the FRF
//! settings, its command-to-displacement and command-to-force FRFs
//! estimated, and, for the runs that identify or characterise the rig, its
//! transfer function fitted. Pure apart from `ingest` reading the file.

use std::path::PathBuf;

use crate::fit::{self, DelayPlan, FitError, FitInput, FitOptions, TfFit};
use crate::frf::{self, Frf, FrfError};
use crate::ingest::{self, IngestError, Log, LogFile, LogPlan, Needs};
use crate::lti::TransferFunction;
use crate::manifest::{Campaign, IdentificationPlan, Role, RunPlan, RunSource};
use crate::report::Measured;
use crate::report::figures::catalogue;
use crate::results::TfSource;

/// What the first stage gives for each run: its own transfer function, and
/// the log's signals and spectra when it has a log.
#[derive(Debug, Clone)]
pub struct Acquired {
    pub tf: Option<TransferFunction>,
    /// Covariance of (n0, d1, d0) for a second-order fit.
    pub cov: Option<[[f64; 3]; 3]>,
    pub source: TfSource,
    pub warnings: Vec<String>,
    pub stage: Option<Box<LogStage>>,
}

/// The first stage of one run: its measured or published transfer function.
pub fn acquire(campaign: &Campaign, run: &RunPlan) -> Result<Acquired, AcquireError> {
    acquire_with(campaign, run, None)
}

/// The first stage of one run, its log's bytes already read when given
/// (they are the log the plan names).
pub fn acquire_with(
    campaign: &Campaign,
    run: &RunPlan,
    file: Option<LogFile>,
) -> Result<Acquired, AcquireError> {
    match &run.source {
        RunSource::None => Ok(Acquired {
            tf: None,
            cov: None,
            source: TfSource::Model,
            warnings: Vec::new(),
            stage: None,
        }),
        RunSource::Published { tf, .. } => Ok(Acquired {
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
            Ok(Acquired {
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
    /// Command to displacement.
    pub frf: Frf,
    /// Command to force, when the log has a force channel.
    pub force_frf: Option<Frf>,
    /// The bins the fit used (band and coherence).
    pub mask: Vec<bool>,
    pub fit: Option<TfFit>,
    /// What the fit was given (with `fit`): the noise profile of a
    /// no-specimen run reads its variance from here.
    pub fit_data: Option<FitData>,
    pub warnings: Vec<String>,
}

impl LogStage {
    /// The stage as its figures and tables show it.
    pub fn measured(&self) -> Measured<'_> {
        Measured {
            sample_rate_hz: self.log.sample_rate_hz,
            frf: &self.frf,
            force_frf: self.force_frf.as_ref(),
            mask: &self.mask,
            fit: self.fit.as_ref(),
        }
    }
}

/// What the fit is given from an FRF: the bins of `mask` whose variance is
/// defined, their frequencies, estimates and E|dH|^2.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct FitData {
    pub freq_hz: Vec<f64>,
    #[serde(with = "crate::results::complex_vec")]
    pub h: Vec<nalgebra::Complex<f64>>,
    pub variance: Vec<f64>,
    /// The input's one-sided auto-spectral density at those bins
    /// (unit^2/Hz), which turns the variance into a noise level.
    pub suu: Vec<f64>,
    /// The FRF's grid spacing (Hz).
    pub bin_hz: f64,
}

impl FitData {
    pub fn of(h: &Frf, mask: &[bool]) -> Self {
        let masked: Vec<usize> = (0..h.freq_hz.len()).filter(|&i| mask[i]).collect();
        // frf gives the variance of Re(H) and of Im(H) each; fit wants
        // E|dH|^2, their sum. A bin whose variance is undefined (no noise
        // information around it) carries no weight and is left out.
        let (bins, variance): (Vec<usize>, Vec<f64>) = masked
            .iter()
            .zip(frf::h_variance_at(h, &masked))
            .filter(|(_, v)| v.is_finite())
            .map(|(&i, v)| (i, 2.0 * v))
            .unzip();
        Self {
            freq_hz: bins.iter().map(|&i| h.freq_hz[i]).collect(),
            h: bins.iter().map(|&i| h.h[i]).collect(),
            variance,
            suu: bins.iter().map(|&i| h.suu[i]).collect(),
            bin_hz: h.resolution_hz,
        }
    }

    pub fn input(&self) -> FitInput<'_> {
        FitInput {
            freq_hz: &self.freq_hz,
            h: &self.h,
            variance: &self.variance,
        }
    }
}

/// The fewest band bins a fit may use: one per parameter, at least three
/// (each bin gives two real equations, a margin over the bare minimum).
fn bins_needed(ident: &IdentificationPlan) -> usize {
    let n_params = ident.numerator_order
        + 1
        + ident.denominator_order
        + usize::from(matches!(ident.delay, DelayPlan::Fit { .. }));
    n_params.max(3)
}

/// The fit options of a campaign's identification settings for a log
/// sampled at `sample_rate_hz`.
pub fn fit_options(ident: &IdentificationPlan, sample_rate_hz: f64) -> FitOptions {
    let mut opts = FitOptions::new(
        ident.numerator_order,
        ident.denominator_order,
        sample_rate_hz,
    );
    opts.intersample = ident.intersample;
    opts.delay = ident.delay;
    opts.max_iterations = fit::RUN_MAX_ITERATIONS;
    opts.independent_lag = ident.frf.independent_lag();
    opts
}

/// Why a log stage failed; the message names the run's file.
#[derive(Debug, thiserror::Error)]
pub enum AcquireError {
    #[error(transparent)]
    Ingest(#[from] IngestError),
    #[error("{}: the fit band's upper edge {hi} Hz (identification.band_hz) is at or above the log's Nyquist frequency {nyquist} Hz (sampled at {} Hz)", path.display(), 2.0 * nyquist)]
    BandAboveNyquist {
        path: PathBuf,
        hi: f64,
        nyquist: f64,
    },
    #[error("{}: {source}", path.display())]
    Tf {
        path: PathBuf,
        #[source]
        source: RunTfError,
    },
}

/// Why a run's FRF gives no transfer function: the one refusal `servoid
/// run` and the Monte Carlo's simulated runs share.
#[derive(Debug, thiserror::Error)]
pub enum RunTfError {
    #[error("FRF: {0}")]
    Frf(#[from] FrfError),
    #[error("the command has no energy in the fit band {lo}-{hi} Hz ({fraction:.2e} of its power)")]
    NoExcitation { lo: f64, hi: f64, fraction: f64 },
    #[error(
        "only {n} bins in {lo}-{hi} Hz have coherence >= {coherence_min}; the fit needs at least {need} (lower identification.coherence_min or widen the band)"
    )]
    TooFewBins {
        n: usize,
        need: usize,
        lo: f64,
        hi: f64,
        coherence_min: f64,
    },
    #[error("transfer-function fit: {0}")]
    Fit(#[from] FitError),
    #[error("the fit did not converge ({termination}); refusing a model that is not an optimum")]
    NotConverged { termination: String },
    #[error(
        "the fitted model is unstable (poles {poles}); refusing it. Swapped command and displacement columns give this: check the channels' columns"
    )]
    Unstable { poles: String },
}

impl RunTfError {
    /// What kind of refusal this is, in a few words: how the Monte Carlo
    /// counts its failed draws.
    pub fn kind(&self) -> &'static str {
        match self {
            RunTfError::Frf(_) => "the FRF failed",
            RunTfError::NoExcitation { .. } => "no excitation in the band",
            RunTfError::TooFewBins { .. } => "too few bins pass the coherence limit",
            RunTfError::Fit(_) => "the fit failed",
            RunTfError::NotConverged { .. } => "a fit that did not converge",
            RunTfError::Unstable { .. } => "an unstable fit",
        }
    }
}

/// A run's transfer function fitted to its FRF `h` on the bins of `mask`
/// (the band's, coherent enough), refused as `servoid run` refuses a run:
/// too few bins for the model, a fit that fails, is unstable or did not
/// converge. The fit's own warnings are in `TfFit::warnings`.
pub fn fit_run(
    h: &Frf,
    mask: &[bool],
    band_hz: (f64, f64),
    ident: &IdentificationPlan,
    sample_rate_hz: f64,
) -> Result<(TfFit, FitData), RunTfError> {
    let used = mask.iter().filter(|m| **m).count();
    let need = bins_needed(ident);
    if used < need {
        return Err(RunTfError::TooFewBins {
            n: used,
            need,
            lo: band_hz.0,
            hi: band_hz.1,
            coherence_min: ident.coherence_min,
        });
    }
    let data = FitData::of(h, mask);
    let fit = fit::fit(&data.input(), &fit_options(ident, sample_rate_hz))?;
    if !fit.stable {
        let poles = fit
            .tf
            .poles()
            .iter()
            .map(|p| format!("{:.4}{:+.4}j", p.re, p.im))
            .collect::<Vec<_>>()
            .join(", ");
        return Err(RunTfError::Unstable { poles });
    }
    if !fit.converged {
        return Err(RunTfError::NotConverged {
            termination: fit.termination.clone(),
        });
    }
    Ok((fit, data))
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
) -> Result<LogStage, AcquireError> {
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
    plan: &LogPlan,
    ident: &IdentificationPlan,
    file: LogFile,
) -> Result<(Log, Vec<String>), IngestError> {
    let mut log = ingest::read_log_from(plan, file)?;
    let needs = Needs {
        min_samples: ident.frf.segment_length,
        max_jitter_fraction: MAX_JITTER_FRACTION,
        clip_fraction: CLIP_FRACTION,
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

/// The command's power in `band` (Hz) against its total (without DC), from
/// the FRF's input spectrum; 0 without power.
fn band_power_fraction(h: &Frf, (lo, hi): (f64, f64)) -> f64 {
    let total: f64 = h.suu.iter().skip(1).sum();
    let in_band: f64 = h
        .freq_hz
        .iter()
        .zip(&h.suu)
        .filter(|(f, _)| **f >= lo && **f <= hi)
        .map(|(_, s)| s)
        .sum();
    if total > 0.0 { in_band / total } else { 0.0 }
}

/// The warning for a command not at rest at the record's ends, whose
/// transient the estimator (not the LPM) counts as noise.
fn motion_warning(ident: &IdentificationPlan, command: &[f64]) -> Option<String> {
    if ident.frf.estimator == frf::Estimator::Lpm {
        return None;
    }
    let (end, ratio) = frf::ends_in_motion(command)?;
    Some(format!(
        "the command is not at rest at the record's {end} (its RMS over the last or first {:.1} % of the record is {:.0} % of the whole): the {} counts the transient's leakage as noise, and the fits' stds come out too large (1.5 to 7 times on sweeps cut in motion); identification.frf = {{ estimator = \"lpm\" }} takes the transient out",
        100.0 * frf::REST_END_FRACTION,
        100.0 * ratio,
        match ident.frf.estimator {
            frf::Estimator::H1 => "Welch H1 estimate",
            frf::Estimator::H2 => "Welch H2 estimate",
            _ => "ETFE",
        }
    ))
}

/// The log stage of one run whose log file is already read.
pub fn log_stage_from(
    run: &RunPlan,
    plan: &LogPlan,
    ident: &IdentificationPlan,
    file: LogFile,
) -> Result<LogStage, AcquireError> {
    let path = plan.path.clone();
    let (log, mut warnings) = checked_log(plan, ident, file)?;
    let fs = log.sample_rate_hz;
    // The manifest cannot know the rate of a log that carries its own (a
    // time column, a DAQ header), so the band is checked against it here.
    if run.band_hz.1 >= 0.5 * fs {
        return Err(AcquireError::BandAboveNyquist {
            path,
            hi: run.band_hz.1,
            nyquist: 0.5 * fs,
        });
    }
    let tf_err = |source: RunTfError| AcquireError::Tf {
        path: path.clone(),
        source,
    };
    let frf_err = |source: FrfError| tf_err(RunTfError::Frf(source));
    let mut h =
        frf::estimate(&log.command_m, &log.displacement_m, fs, &ident.frf).map_err(frf_err)?;
    // Excitation in the band, taken before the bins above it are freed.
    let (lo, hi) = run.band_hz;
    let fraction = band_power_fraction(&h, run.band_hz);
    // Past that fraction, nothing reads a bin above the band, the tables or
    // the figures (and the noise estimate's reach beyond them): those are
    // freed before the force path's FRF is estimated (a long ETFE's bins up
    // to Nyquist took half the memory of a 1 GB log's analysis).
    let keep_hz = hi
        .max(crate::report::tables::TABLE_MAX_HZ)
        .max(catalogue::FRF_MAX_HZ)
        .max(catalogue::FORCE_FRF_MAX_HZ);
    h.keep_up_to(keep_hz, frf::VARIANCE_REACH_BINS);
    let force_frf = match &log.force_n {
        Some(f) => {
            let mut ff = frf::estimate(&log.command_m, f, fs, &ident.frf).map_err(frf_err)?;
            ff.keep_up_to(keep_hz, frf::VARIANCE_REACH_BINS);
            Some(ff)
        }
        None => None,
    };
    if fraction < MIN_BAND_POWER_FRACTION {
        return Err(tf_err(RunTfError::NoExcitation { lo, hi, fraction }));
    }
    let mask = frf::band_mask(&h, run.band_hz, ident.coherence_min);
    warnings.extend(motion_warning(ident, &log.command_m));

    let fit = if matches!(run.role, Role::NoSpecimen | Role::Spring | Role::Fit) {
        let (fit, data) = fit_run(&h, &mask, run.band_hz, ident, fs).map_err(tf_err)?;
        warnings.extend(fit.warnings.iter().cloned());
        Some((fit, data))
    } else {
        None
    };
    let (fit, fit_data) = fit.unzip();
    Ok(LogStage {
        log,
        frf: h,
        force_frf,
        mask,
        fit,
        fit_data,
        warnings,
    })
}
