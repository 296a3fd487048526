//! One run's work, pure: from its plan (and its log's bytes, when the cache
//! read them on the way) to what the campaign keeps of it and what is to be
//! written for it (figure specs, tables), nothing written here. The log is
//! read (by `ingest`, through `log_stage`) and dropped inside each step; the
//! writing is `sink`'s, as each run's output arrives.

use std::sync::Arc;

use nalgebra::Complex;

use super::sensitivity::NoiseSource;
use crate::analysis::evidence::{Evidence, RigInput, ValidationEvidence};
use crate::analysis::log_stage::{LogStage, LogStageError, OwnTf, own_tf_with};
use crate::analysis::rig::RigError;
use crate::fit::adequacy::{self, Adequacy, Residuals};
use crate::fit::{self, DelayPlan, Intersample, TfFit};
use crate::frf::{self, Frf};
use crate::identify::{FitData, fit_options};
use crate::ingest::{IngestError, Log, LogFile};
use crate::lti::TransferFunction;
use crate::manifest::{
    Campaign, CompensatorSettings, IdentificationPlan, Role, RunPlan, RunSource,
};
use crate::model::{self, LinearSpecimen, RigParams};
use crate::report::figures::catalogue::{self, ForceBins, OverlayRun, Prediction};
use crate::report::tables::RunTables;
use crate::report::{FigureSpec, Measured};
use crate::results::{
    DelayTestResult, FitSummary, FrfUsed, HarmonicsFound, LinearityResult, LogInfo, RunResult,
    RunTracking, SpringForceResult, Status, TfResult, TfSource,
};
use crate::sensitivity::{self, NoiseProfile};
use crate::simulate::specimen::SpecimenModel;
use crate::tracking::compensator::{self, Compensator, CompensatorOutcome};
use crate::tracking::{self, FrfBins, Tracking};
use crate::validate::csi::Csi;
use crate::validate::{self, Record, ValidateError};

/// Below this fit percent (MATLAB tfest's FitPercent, [`crate::fit::TfFit`])
/// a run's model gets a warning naming the log's mapping.
const POOR_FIT_PERCENT: f64 = 50.0;

/// Why one run failed; recorded in that run's result.
#[derive(Debug, thiserror::Error)]
pub enum RunError {
    #[error(transparent)]
    Acquire(#[from] Arc<LogStageError>),
    #[error("the rig parameters are unavailable: {0}")]
    NoRig(Arc<RigError>),
    #[error("time-domain validation: {0}")]
    Validation(#[from] ValidateError),
    /// The rig with the run's specimen and P gain gives a model beyond
    /// f64's range (finite but extreme manifest numbers).
    #[error(
        "the model of the rig (beta1 {beta1:.4e} 1/s, a1b0 {a1b0:.4e} N/(m s^2) at p_gain = {p_gain}, a2 {a2:.4e} N/m, a3 {a3:.4e} 1/s) with the specimen (mass_kg = {m}, damping_ns_per_m = {c}, stiffness_n_per_m = {k}) leaves f64's range ({source}): check this run's specimen and p_gain, and the identification runs' published or measured data"
    )]
    Model {
        beta1: f64,
        a1b0: f64,
        a2: f64,
        a3: f64,
        p_gain: f64,
        m: f64,
        c: f64,
        k: f64,
        source: crate::lti::LtiError,
    },
}

impl RunError {
    /// [`RunError::Model`] for `rig` (at the run's P gain) and `specimen`.
    fn model(rig: &RigParams, specimen: &LinearSpecimen, source: crate::lti::LtiError) -> Self {
        let (m, c, k) = specimen.mck();
        RunError::Model {
            beta1: rig.beta1_per_s,
            a1b0: rig.a1b0_n_per_m_s2,
            a2: rig.a2_n_per_m,
            a3: rig.a3_per_s,
            p_gain: rig.p_gain,
            m,
            c,
            k,
            source,
        }
    }
}

impl From<Arc<RigError>> for RunError {
    fn from(e: Arc<RigError>) -> Self {
        RunError::NoRig(e)
    }
}

/// Covariance of (beta1, a1b0, a2, a3).
pub(super) type Cov4 = [[f64; 4]; 4];

/// What a run's step is asked to build besides its result: figure specs
/// (when the job draws figures) and tables (when it writes an output folder),
/// with the command's hold the models are shown with.
#[derive(Debug, Clone, Copy)]
pub(super) struct Wants {
    pub figures: bool,
    pub tables: bool,
    pub intersample: Intersample,
}

/// What the campaign keeps of a run once its log is dropped, and what the
/// cache stores of it.
#[derive(Debug, Clone, serde::Serialize, serde::Deserialize)]
pub(super) struct Kept {
    pub result: RunResult,
    /// What the rig is identified from (an identification or fit run).
    pub estimate: Option<Evidence>,
    /// The force FRF's bins, for the force figure once the rig is known.
    pub force: Option<ForceBins>,
    /// An identification run's FRF for Fig. 15.
    pub overlay: Option<OverlayRun>,
    /// A validation run's control-structure interaction.
    pub csi: Option<Csi>,
    /// A no-specimen run's FRF noise, for the stiffness sensitivity.
    pub noise: Option<NoiseSource>,
}

impl Kept {
    fn of(result: RunResult) -> Self {
        Self {
            result,
            estimate: None,
            force: None,
            overlay: None,
            csi: None,
            noise: None,
        }
    }
}

/// A run's step done: what is kept, and what is to be written for it.
pub(super) struct Output {
    pub kept: Kept,
    /// Its figures, in page order (empty when figures are not wanted).
    pub figures: Vec<FigureSpec>,
    /// Its tables (None when not wanted, or when the run has nothing to
    /// tabulate because it failed).
    pub tables: Option<RunTables>,
    /// Why its log could not be read or analysed: such a run is not cached
    /// (the next job reads the log again) and gives the rig nothing.
    pub log_error: Option<Arc<LogStageError>>,
    /// Whether the outcome may be cached.
    pub cacheable: bool,
}

impl Output {
    /// A run whose log could not be read or analysed.
    fn unread(result: RunResult, error: Arc<LogStageError>) -> Self {
        Self {
            kept: Kept::of(failed(result, error.clone().into())),
            figures: Vec::new(),
            tables: None,
            log_error: Some(error),
            cacheable: false,
        }
    }

    /// A validation run that failed once its log was read: the measured FRF
    /// is still worth seeing; nothing is tabulated or cached.
    fn unfinished(result: RunResult, stage: Option<&LogStage>, wants: Wants) -> Self {
        let figures = match stage {
            Some(st) if wants.figures => {
                catalogue::log_figures(&result, &Measured::of(st), None, wants.intersample, None).0
            }
            _ => Vec::new(),
        };
        Self {
            kept: Kept::of(result),
            figures,
            tables: None,
            log_error: None,
            cacheable: false,
        }
    }
}

/// The tables of `run` if they are wanted.
fn tables(run: &RunResult, measured: Option<&Measured<'_>>, wants: Wants) -> Option<RunTables> {
    wants
        .tables
        .then(|| RunTables::of(run, measured, wants.intersample))
}

/// A run that does not need the rig (no-specimen, spring and fit runs):
/// read, estimated, fitted and checked in the time domain, with what the
/// rig needs of it (its model and the bins its fit was given). `file` is
/// its log's bytes when the cache read them on the way.
pub(super) fn without_rig(
    campaign: &Campaign,
    plan: &RunPlan,
    file: Option<LogFile>,
    wants: Wants,
) -> Output {
    let acq = match own_tf_with(campaign, plan, file) {
        Ok(a) => a,
        Err(e) => return Output::unread(new_result(plan), Arc::new(e)),
    };
    let (tf, cov) = (acq.tf.clone(), acq.cov);
    let (result, stage, time) = fitted(&campaign.identification, plan, new_result(plan), acq);
    let estimate = tf.map(|tf| Evidence {
        tf,
        cov,
        data: stage.as_ref().and_then(|st| st.fit_data.clone()),
        adequacy: result.fit.as_ref().and_then(|f| f.adequacy.clone()),
        sample_rate_hz: stage.as_ref().map(|st| st.log.sample_rate_hz),
        cause: stage.as_ref().and_then(|st| st.cause.clone()),
    });
    let mut kept = Kept {
        estimate,
        ..Kept::of(result)
    };
    let mut figures = Vec::new();
    let measured = stage.as_deref().map(Measured::of);
    if let (Some(st), Some(m)) = (&stage, &measured) {
        kept.force = ForceBins::of(m);
        if plan.role == Role::NoSpecimen {
            kept.noise = noise_profile(plan, st);
        }
        if wants.figures {
            let (mut specs, overlay) =
                catalogue::log_figures(&kept.result, m, time.as_ref(), wants.intersample, None);
            if let Some(t) = &time {
                specs.extend(catalogue::subspace_figure(
                    &kept.result,
                    &st.log.command_m,
                    t,
                    st.log.sample_rate_hz,
                ));
            }
            (figures, kept.overlay) = (specs, overlay);
        }
    }
    Output {
        tables: tables(&kept.result, measured.as_ref(), wants),
        kept,
        figures,
        log_error: None,
        cacheable: true,
    }
}

/// What a run done without the rig gets once the rig is known: a1b0 at its
/// P gain, the force model (Eq. 45) and, when figures are wanted and its log
/// had force, the force figure (Figs. 16-17).
pub(super) fn with_rig(
    kept: &mut Kept,
    plan: &RunPlan,
    rig_at_p: Option<&RigParams>,
    wants: Wants,
) -> Option<FigureSpec> {
    let out = &mut kept.result;
    out.a1b0 = rig_at_p.map(|r| r.a1b0_n_per_m_s2);
    // The run's own fit stands without the force model: its absence is a
    // warning, not the run's failure.
    out.force_tf = match rig_at_p.map(|r| models(r, &plan.specimen)) {
        Some(Ok((_, f))) => f,
        Some(Err(e)) => {
            out.warnings.push(format!("no force model (Eq. 45): {e}"));
            None
        }
        None => None,
    };
    match (&kept.force, &out.force_tf) {
        (Some(bins), Some(model)) if wants.figures => Some(catalogue::force_figure(
            out,
            bins,
            model,
            wants.intersample,
            None,
        )),
        _ => None,
    }
}

/// The rig as the validation runs read it: its parameters and the
/// covariance of (beta1, a1b0, a2, a3) when identified, or why there is
/// none.
pub(super) type RigOutcome = Result<(RigParams, Option<Cov4>), Arc<RigError>>;

/// The rig and its covariance at P gain `p`: a1b0 scales with P, and its row
/// and column of the covariance with it.
fn at_p_gain(rig: &RigParams, cov: Option<&Cov4>, p: f64) -> (RigParams, Option<Cov4>) {
    let f = [1.0, p / rig.p_gain, 1.0, 1.0];
    let at_p = cov.map(|c| -> Cov4 {
        std::array::from_fn(|i| std::array::from_fn(|j| c[i][j] * f[i] * f[j]))
    });
    (rig.at_p_gain(p), at_p)
}

/// A validation run's log, read for its own run. `fitted` is the SHA-256 of
/// the log as the joint fit read it, when it did: the rig was fitted to
/// those bytes, and a log that has changed since is not what the rig says
/// it validates.
fn read_validation_log(
    campaign: &Campaign,
    plan: &RunPlan,
    fitted: Option<&str>,
    file: Option<LogFile>,
) -> Result<OwnTf, LogStageError> {
    let acq = own_tf_with(campaign, plan, file)?;
    match (fitted, &acq.stage) {
        (Some(before), Some(st)) if st.log.sha256 != before => {
            Err(LogStageError::Ingest(IngestError::Changed {
                path: st.log.path.clone(),
                before: format!("SHA-256 {before} when the joint fit read it"),
                after: format!("SHA-256 {} when its run was validated", st.log.sha256),
            }))
        }
        _ => Ok(acq),
    }
}

/// A validation run: the identified rig with its specimen, driven by its
/// measured command (Sec. 4), or the model's prediction alone without a log.
/// `fitted` is the SHA-256 of the log as the joint fit read it, when it did.
pub(super) fn validation(
    campaign: &Campaign,
    plan: &RunPlan,
    rig: &RigOutcome,
    fitted: Option<&str>,
    file: Option<LogFile>,
    wants: Wants,
) -> Output {
    let mut out = new_result(plan);
    // The log's own failure comes first; a good log without a rig still
    // records what it is.
    let acq = match read_validation_log(campaign, plan, fitted, file) {
        Ok(a) => a,
        Err(e) => {
            out.a1b0 = rig
                .as_ref()
                .ok()
                .map(|(r, _)| r.at_p_gain(plan.p_gain).a1b0_n_per_m_s2);
            return Output::unread(out, Arc::new(e));
        }
    };
    out.warnings = acq.warnings.clone();
    out.log = log_info(plan, acq.stage.as_deref());
    out.frf = acq.stage.as_deref().map(frf_used);
    out.linearity = acq
        .stage
        .as_deref()
        .and_then(|st| st.linearity.as_ref())
        .map(linearity_result);
    out.spring_force = acq.stage.as_deref().and_then(|st| {
        let s = st.spring?;
        let SpecimenModel::Spring { stiffness_n_per_m } = plan.specimen else {
            return None;
        };
        Some(SpringForceResult {
            stiffness_n_per_m: s.stiffness_n_per_m,
            stated_n_per_m: stiffness_n_per_m,
            cubic_n_per_m3: s.cubic_n_per_m3,
            cubic_t: s.cubic_t,
            amplitude_m: s.amplitude_m,
            stiffening: s.stiffening,
            linear: !s.stiffens(),
        })
    });
    let stage = acq.stage.as_deref();
    let (rig_at_p, rig_cov) = match rig {
        Ok((r, cov)) => at_p_gain(r, cov.as_ref(), plan.p_gain),
        Err(e) => return Output::unfinished(failed(out, e.clone().into()), stage, wants),
    };
    out.a1b0 = Some(rig_at_p.a1b0_n_per_m_s2);
    match models(&rig_at_p, &plan.specimen) {
        Ok((tf, force_tf)) => (out.tf, out.force_tf) = (tf, force_tf),
        Err(e) => return Output::unfinished(failed(out, e), stage, wants),
    }
    let Some(st) = stage else {
        return Output {
            tables: tables(&out, None, wants),
            ..Output::unfinished(out, None, wants)
        };
    };
    // The compensator's stiffness sweep covers the sensitivity analysis's
    // range (a2 does not depend on the P gain).
    let range = super::sensitivity::stiffness_range(campaign.sensitivity.range_n_per_m, &rig_at_p);
    let design = CompensatorPlan {
        settings: &campaign.compensator,
        range,
        stiffnesses: sensitivity::log_grid(range, campaign.sensitivity.points),
    };
    validated(plan, out, st, &rig_at_p, rig_cov, &design, wants)
}

/// What a validation run's compensator is designed and swept with.
struct CompensatorPlan<'a> {
    settings: &'a CompensatorSettings,
    range: (f64, f64),
    stiffnesses: Vec<f64>,
}

/// A validation run with its log and model: the time-domain validation
/// (Eqs. 47-48), the control-structure interaction, its figures and tables.
fn validated(
    plan: &RunPlan,
    mut out: RunResult,
    st: &LogStage,
    rig_at_p: &RigParams,
    rig_cov: Option<Cov4>,
    design: &CompensatorPlan<'_>,
    wants: Wants,
) -> Output {
    let linear = plan.specimen.linear();
    let time = match validate::validation_run(rig_at_p, &plan.specimen, &record(&st.log)) {
        Ok(t) => {
            out.validation = Some(t.metrics.clone());
            Some(t)
        }
        Err(e) => {
            out = failed(out, e.into());
            None
        }
    };
    // The log's own tracking stands whether or not the model could be
    // simulated.
    let measured = measured_tracking(st, time.as_ref().map(|t| t.windows.as_slice()));
    let plant = out
        .tf
        .as_ref()
        .and_then(|tf| TransferFunction::with_delay(&tf.num, &tf.den, tf.delay_s).ok());
    let predicted = time
        .as_ref()
        .map(|t| predicted_tracking(st, t, plant.as_ref()));
    let compensator = match (linear, &time, &plant) {
        (Some(lin), Some(t), Some(g)) => Some(compensate(plan, st, t, rig_at_p, &lin, g, design)),
        _ => None,
    };
    out.tracking = Some(RunTracking {
        model_gap_s: measured
            .delay_xcorr_s
            .zip(predicted.as_ref().and_then(|p| p.delay_xcorr_s))
            .map(|(m, p)| m - p),
        measured,
        predicted,
        compensator,
    });
    let measured = Measured::of(st);
    let bins = ForceBins::of(&measured);
    let csi = linear.and_then(|lin| {
        validate::csi::csi(&plan.id, rig_at_p, &lin, bins.as_ref().map(ForceBins::bins))
    });
    let figures = if wants.figures {
        // The prediction's band, from the rig's covariance.
        let prediction = match (rig_cov, linear) {
            (Some(cov), Some(specimen)) => Some(Prediction {
                rig: *rig_at_p,
                cov,
                specimen,
            }),
            _ => None,
        };
        let (mut specs, _) = catalogue::log_figures(
            &out,
            &measured,
            time.as_ref(),
            wants.intersample,
            prediction.as_ref(),
        );
        if let (Some(bins), Some(model)) = (&bins, &out.force_tf) {
            let force = catalogue::force_figure(&out, bins, model, wants.intersample, csi.as_ref());
            specs.insert(1, force);
        }
        if let Some(g) = &plant {
            specs.extend(catalogue::compensator_figures(&out, g));
        }
        if let Some(t) = &time {
            specs.extend(catalogue::subspace_figure(
                &out,
                &st.log.command_m,
                t,
                st.log.sample_rate_hz,
            ));
        }
        specs
    } else {
        Vec::new()
    };
    Output {
        tables: tables(&out, Some(&measured), wants),
        kept: Kept {
            csi,
            ..Kept::of(out)
        },
        figures,
        log_error: None,
        cacheable: true,
    }
}

/// A run's result before anything is known of it.
fn new_result(plan: &RunPlan) -> RunResult {
    RunResult {
        id: plan.id.clone(),
        role: plan.role,
        description: plan.description.clone(),
        p_gain: plan.p_gain,
        status: Status::Ok,
        error: None,
        warnings: Vec::new(),
        specimen: plan.specimen,
        natural_frequency_hz: plan.specimen.natural_frequency_hz(),
        a1b0: None,
        tf: None,
        force_tf: None,
        fit: None,
        validation: None,
        tracking: None,
        log: None,
        frf: None,
        linearity: None,
        spring_force: None,
        annotations: plan.annotations.clone(),
    }
}

/// A validation run's FRFs for the joint fit, read ahead of the rig
/// (`identification.joint.include_validation`): the band's bins with the
/// coherence the identification runs need. Nothing when the run has no log
/// or its log fails here: the second pass reads it again and reports why.
pub(super) fn validation_evidence(campaign: &Campaign, plan: &RunPlan) -> RigInput {
    if !matches!(plan.source, RunSource::Log(_)) {
        return RigInput::Nothing;
    }
    let Ok(Some(st)) = own_tf_with(campaign, plan, None).map(|a| a.stage) else {
        return RigInput::Nothing;
    };
    let coherence_min = campaign.identification.coherence_min;
    let data = |h: &Frf| {
        FitData::of(
            h,
            &frf::band_mask(h, plan.band_hz, coherence_min),
            &st.choice.plan,
        )
    };
    RigInput::Validation(Box::new(ValidationEvidence {
        displacement: data(&st.frf),
        force: st.force_frf.as_ref().map(data),
        sample_rate_hz: st.log.sample_rate_hz,
        sha256: st.log.sha256.clone(),
    }))
}

/// What run `plan`'s log says of its FRF noise: the bins its fit used and
/// their variance, the white noise level that implies, the displacement's
/// quantisation step and the log's hash (for the Monte Carlo, which
/// replays its command).
fn noise_profile(plan: &RunPlan, st: &LogStage) -> Option<NoiseSource> {
    let (fit, data) = (st.fit.as_ref()?, st.fit_data.as_ref()?);
    let fs = st.log.sample_rate_hz;
    (!data.freq_hz.is_empty())
        .then(|| NoiseProfile {
            run: plan.id.clone(),
            white_noise: crate::sensitivity::montecarlo::white_noise(&data.variance, &data.suu, fs),
            freq_hz: data.freq_hz.clone(),
            variance: data.variance.clone(),
            sample_rate_hz: fs,
            delay_s: fit.tf.delay_s,
            displacement_step_m: crate::ingest::quantum_step(&st.log.displacement_m),
            log_sha256: st.log.sha256.clone(),
        })
        .map(|profile| NoiseSource {
            profile,
            frf: st.choice.plan.clone(),
        })
}

/// The model's x1/u (Eq. 17) and force path f/u (Eq. 45) for a linear
/// specimen (f/u None without one), or the error that names why the rig
/// and the specimen give no model in f64.
#[allow(clippy::type_complexity)]
fn models(
    rig_at_p: &RigParams,
    specimen: &SpecimenModel,
) -> Result<(Option<TfResult>, Option<TfResult>), RunError> {
    let Some(lin) = specimen.linear() else {
        return Ok((None, None));
    };
    let err = |e| RunError::model(rig_at_p, &lin, e);
    let x = model::tf_x1_u(rig_at_p, &lin).map_err(err)?;
    let f = match lin {
        LinearSpecimen::None => None,
        _ => Some(model::tf_f_u(rig_at_p, &lin).map_err(err)?),
    };
    Ok((
        Some(TfResult::new(&x, TfSource::Model)),
        f.map(|f| TfResult::new(&f, TfSource::Model)),
    ))
}

/// The log's tracking, the FRF's phase slope over the fitted bins, in the
/// paper's windows: those the time-domain check located when it ran (the
/// same command, the same windows), else located here.
fn measured_tracking(st: &LogStage, windows: Option<&[validate::Window]>) -> Tracking {
    let bins = FrfBins {
        freq_hz: &st.frf.freq_hz,
        h: &st.frf.h,
        keep: &st.mask,
    };
    tracking::measure(
        &st.log.command_m,
        &st.log.displacement_m,
        st.log.sample_rate_hz,
        Some(bins),
        &windows.map_or_else(
            || validate::locate_windows(&st.log.command_m, st.log.sample_rate_hz),
            <[validate::Window]>::to_vec,
        ),
    )
}

/// The tracking the model predicts for the log's command: its simulated
/// displacement, and the phase over the bins the measured FRF kept of the
/// plant as it was simulated, driven through the hold (times `comp` when
/// given).
fn predicted_tracking_of(
    st: &LogStage,
    windows: &[validate::Window],
    displacement: &[f64],
    plant: Option<&TransferFunction>,
    comp: Option<&Compensator>,
) -> Tracking {
    let fs = st.log.sample_rate_hz;
    let h: Option<Vec<_>> = plant.map(|g| {
        st.frf
            .freq_hz
            .iter()
            .map(|&f| {
                compensator::held_response(g, f, fs)
                    * comp.map_or(Complex::new(1.0, 0.0), |c| c.response(f))
            })
            .collect()
    });
    let bins = h.as_ref().map(|h| FrfBins {
        freq_hz: &st.frf.freq_hz,
        h,
        keep: &st.mask,
    });
    tracking::measure(&st.log.command_m, displacement, fs, bins, windows)
}

/// The tracking the model predicts for the log's command, uncompensated.
fn predicted_tracking(
    st: &LogStage,
    time: &validate::TimeStage,
    plant: Option<&TransferFunction>,
) -> Tracking {
    predicted_tracking_of(st, &time.windows, &time.x1_simulated, plant, None)
}

/// The compensator for the run's specimen on the identified plant `plant`
/// (x1/u, Eqs. 34-35), its tracking over the run's band with and without
/// it, on the run's measured command (the desired displacement) through the
/// plant's state space, and over the sensitivity's stiffnesses.
fn compensate(
    plan: &RunPlan,
    st: &LogStage,
    time: &validate::TimeStage,
    rig_at_p: &RigParams,
    specimen: &LinearSpecimen,
    plant: &TransferFunction,
    design: &CompensatorPlan<'_>,
) -> CompensatorOutcome {
    let fs = st.log.sample_rate_hz;
    let band = plan.band_hz;
    let uncompensated = compensator::band_tracking(plant, None, band, fs);
    let settings = design.settings;
    let c = match compensator::design(plant, fs, band.1, settings.cutoff_hz, settings.lead) {
        Ok(c) => c,
        Err(note) => {
            return CompensatorOutcome {
                design: None,
                note: Some(note.to_string()),
                band_hz: [band.0, band.1],
                uncompensated,
                compensated: None,
                meets_target: None,
                predicted: None,
                peak_command_m: None,
                peak_desired_m: None,
                stiffness: Vec::new(),
                target_stiffness_n_per_m: None,
            };
        }
    };
    let compensated = compensator::band_tracking(plant, Some(&c), band, fs);
    let ss = model::state_space(rig_at_p, specimen);
    let (predicted, peak, note) =
        match compensator::compensated_displacement(&ss, &c, &st.log.command_m) {
            Ok((x, peak)) => (
                Some(predicted_tracking_of(
                    st,
                    &time.windows,
                    &x,
                    Some(plant),
                    Some(&c),
                )),
                Some(peak),
                None,
            ),
            Err(e) => (
                None,
                None,
                Some(format!("the compensated plant could not be simulated: {e}")),
            ),
        };
    CompensatorOutcome {
        stiffness: compensator::stiffness_sweep(rig_at_p, specimen, &c, &design.stiffnesses, band),
        target_stiffness_n_per_m: compensator::target_stiffness(
            rig_at_p,
            specimen,
            &c,
            design.range,
            band,
        ),
        design: Some(c),
        note,
        band_hz: [band.0, band.1],
        uncompensated,
        meets_target: Some(compensated.meets_target()),
        compensated: Some(compensated),
        predicted,
        peak_command_m: peak,
        peak_desired_m: Some(st.log.command_m.iter().fold(0.0_f64, |m, v| m.max(v.abs()))),
    }
}

/// A log's signals as the time-domain checks read them.
fn record(log: &Log) -> Record<'_> {
    Record {
        sample_rate_hz: log.sample_rate_hz,
        command_m: &log.command_m,
        displacement_m: &log.displacement_m,
        force_n: log.force_n.as_deref(),
    }
}

/// Provenance of a run's log, when it has one.
fn log_info(plan: &RunPlan, stage: Option<&LogStage>) -> Option<LogInfo> {
    let (st, RunSource::Log(lp)) = (stage?, &plan.source) else {
        return None;
    };
    Some(LogInfo {
        file: lp
            .path
            .file_name()
            .map(|f| f.to_string_lossy().into_owned())
            .unwrap_or_default(),
        sha256: st.log.sha256.clone(),
        sample_rate_hz: st.log.sample_rate_hz,
        n_samples: st.log.n_rows,
        duration_s: st.log.n_rows as f64 / st.log.sample_rate_hz,
        repairs: st.log.repairs.clone(),
    })
}

/// The FRF settings the run's log got, as results.json states them.
fn frf_used(st: &LogStage) -> FrfUsed {
    let (choice, plan) = (&st.choice, &st.choice.plan);
    FrfUsed {
        chosen_by: if choice.chosen { "auto" } else { "manifest" }.into(),
        estimator: plan.estimator,
        window: plan.window,
        segment_length: plan.segment_length,
        overlap: plan.overlap,
        detrend: plan.detrend,
        transient: plan.transient.is_some(),
        model_noise: plan.model_noise,
        excitation: st.excitation.kind().into(),
        excitation_note: st.excitation.describe(),
        ends: choice.ends.describe(),
        reason: choice.reason.clone(),
    }
}

/// The share of a fit's excess cost (its reduced chi-square above 1) a
/// delay must explain for the run's warning to name it.
const DELAY_EXPLAINS: f64 = 0.5;

/// The linearity check as results.json states it.
fn linearity_result(l: &frf::Linearity) -> LinearityResult {
    let found = |f: &frf::linearity::Found| HarmonicsFound {
        blocks: f.blocks,
        largest_ratio: f.largest,
        order: f.order,
        at_hz: f.at_hz,
    };
    LinearityResult {
        blocks_checked: l.checked,
        linear: !l.nonlinear(),
        displacement: l.displacement.as_ref().map(found),
        force: l.force.as_ref().map(found),
        note: crate::analysis::log_stage::linearity_note(l),
    }
}

/// A run marked failed with its error.
fn failed(mut out: RunResult, e: RunError) -> RunResult {
    out.status = Status::Failed;
    out.error = Some(e.to_string());
    out
}

/// An identification or fit run: its published or fitted model with the
/// coefficients' uncertainty, and the fitted model in the time domain (Figs.
/// 9, 12, 14). A failure of the time-domain check is a warning: the fit
/// stands on its own. Returns the result, the log stage and the
/// time-domain check for the figures.
fn fitted(
    ident: &IdentificationPlan,
    plan: &RunPlan,
    mut out: RunResult,
    acq: OwnTf,
) -> (
    RunResult,
    Option<Box<LogStage>>,
    Option<validate::TimeStage>,
) {
    out.warnings = acq.warnings.clone();
    out.log = log_info(plan, acq.stage.as_deref());
    out.frf = acq.stage.as_deref().map(frf_used);
    let stage = acq.stage;
    let fit = stage.as_ref().and_then(|s| s.fit.as_ref());
    out.tf = acq.tf.as_ref().map(|tf| tf_result(tf, acq.source, fit));
    let mut time = None;
    if let Some(st) = &stage
        && let Some(fit) = &st.fit
    {
        let summary = fit_summary(ident, plan, st, fit);
        out.warnings.extend(own_fit_warnings(&summary, st, fit));
        out.fit = Some(summary);
        match validate::fitted_run(&fit.tf, &record(&st.log)) {
            Ok(t) => {
                out.validation = Some(t.metrics.clone());
                time = Some(t);
            }
            Err(e) => out
                .warnings
                .push(format!("time-domain check of the fitted model: {e}")),
        }
    }
    if let Some(st) = &stage {
        let windows = time
            .as_ref()
            .map(|t: &validate::TimeStage| t.windows.as_slice());
        out.tracking = Some(RunTracking {
            measured: measured_tracking(st, windows),
            predicted: None,
            model_gap_s: None,
            compensator: None,
        });
    }
    (out, stage, time)
}

/// A run's transfer function as results.json states it, with the fit's
/// stds (absolute and relative) when it was fitted here.
fn tf_result(tf: &TransferFunction, source: TfSource, fit: Option<&TfFit>) -> TfResult {
    let mut t = TfResult::new(tf, source);
    if let Some(fit) = fit {
        t.std = Some(fit.std.clone());
        t.rel_std = Some(
            fit.std
                .iter()
                .zip(&fit.params)
                .map(|(s, p)| s / p.abs())
                .collect(),
        );
    }
    t
}

/// What the run's own fit says is wrong with it, in this order: a delay it
/// lacks, its misfit's diagnosis, stds it overstates, a model that
/// explains too little of the response.
fn own_fit_warnings(summary: &FitSummary, st: &LogStage, fit: &TfFit) -> Vec<String> {
    let mut warnings = Vec::new();
    // The delay is named as the cause only where it explains most of what
    // the fit leaves beyond the noise: a nonlinearity or the FRF settings
    // can make a delay of a hundredth of a sample significant on a long
    // record, explaining a few per cent of the misfit.
    if let Some(t) = summary.delay_test.as_ref().filter(|t| {
        t.supported
            && st.cause.is_none()
            && t.reduced_chi2.is_some_and(|with| {
                summary.reduced_chi2 - with >= DELAY_EXPLAINS * (summary.reduced_chi2 - 1.0)
            })
    }) {
        warnings.push(format!(
            "the run's own fit: {}; with a delay of {:.3} ms its reduced chi-square is {:.3} (without, {:.3}); set identification.delay = {{ mode = \"fit\" }}",
            t.note,
            1e3 * t.delay_s.unwrap_or(f64::NAN),
            t.reduced_chi2.unwrap_or(f64::NAN),
            summary.reduced_chi2
        ));
    }
    if let Some(d) = summary.adequacy.as_ref().and_then(|a| {
        a.diagnosis_because(
            (!fit.shape.fit_delay).then_some("set identification.delay = \"fit\""),
            st.choice.plan.estimator.understated_noise(),
            st.cause.as_deref(),
        )
    }) {
        warnings.push(format!("the run's own fit: {d}"));
    }
    if let Some(o) = summary.adequacy.as_ref().and_then(|a| {
        a.overstated_because(
            st.choice.plan.estimator.overstated_noise(),
            st.cause.as_deref(),
        )
    }) {
        warnings.push(format!("the run's own fit: {o}"));
    }
    // A model that explains under half of the measured response is not a
    // rig's: the likely causes are in the log's mapping, not in the model
    // (swapped command and displacement columns measured 31 %).
    if summary.fit_percent < POOR_FIT_PERCENT {
        warnings.push(format!(
            "the model explains only {:.0} % of the measured response (fit percent below {POOR_FIT_PERCENT:.0}); likely cause: the channels' columns (command and displacement swapped, or another run's log)",
            summary.fit_percent
        ));
    }
    warnings
}

/// The adequacy tests of a run's own fit on the bins it was given, its
/// model with the hold and delay.
fn fit_adequacy(ident: &IdentificationPlan, st: &LogStage, fit: &TfFit) -> Option<Adequacy> {
    let data = st.fit_data.as_ref()?;
    let fs = st.log.sample_rate_hz;
    let model: Vec<_> = data
        .freq_hz
        .iter()
        .map(|&f| fit.tf.freq_response(f) * crate::fit::hold_response(ident.intersample, fs, f))
        .collect();
    Some(adequacy::assess(
        &Residuals {
            freq_hz: &data.freq_hz,
            h: &data.h,
            model: &model,
            variance: &data.variance,
        },
        fit.params.len(),
        st.frf.resolution_hz,
        st.choice.plan.independent_lag(),
    ))
}

fn fit_summary(
    ident: &IdentificationPlan,
    plan: &RunPlan,
    st: &LogStage,
    fit: &TfFit,
) -> FitSummary {
    let used: Vec<f64> = st
        .frf
        .coherence
        .iter()
        .zip(&st.mask)
        .filter(|(_, m)| **m)
        .map(|(c, _)| *c)
        .collect();
    FitSummary {
        fit_percent: fit.fit_percent,
        n_bins: fit.n_bins,
        band_hz: [plan.band_hz.0, plan.band_hz.1],
        coherence_mean: used.iter().sum::<f64>() / used.len().max(1) as f64,
        coherence_min: used.iter().copied().fold(f64::INFINITY, f64::min),
        reduced_chi2: fit.reduced_chi2,
        iterations: fit.iterations,
        termination: fit.termination.clone(),
        converged: fit.converged,
        stable: fit.stable,
        param_names: fit.param_names.clone(),
        params: fit.params.clone(),
        std: fit.std.clone(),
        covariance: Some(
            fit.covariance
                .row_iter()
                .map(|r| r.iter().copied().collect())
                .collect(),
        ),
        frf_averages: st.frf.n_averages,
        frf_resolution_hz: st.frf.resolution_hz,
        adequacy: fit_adequacy(ident, st, fit),
        delay_test: delay_test(ident, st, fit),
    }
}

/// For a fit made without a delay (`identification.delay` none): the same
/// fit with one, up to the default bound, and whether the data support it.
fn delay_test(ident: &IdentificationPlan, st: &LogStage, fit: &TfFit) -> Option<DelayTestResult> {
    if ident.delay != DelayPlan::None {
        return None;
    }
    let data = st.fit_data.as_ref()?;
    let opts = fit_options(ident, &st.choice.plan, st.log.sample_rate_hz);
    let t = fit::delay_significance::delay_test(&data.input(), &opts, fit, ident.max_delay_s);
    let with = t.with_delay.as_ref().ok();
    let converged = with.filter(|w| w.converged && w.stable);
    let note = match (&t.with_delay, t.f_test) {
        (Err(e), _) => format!("the fit with a delay failed: {e}"),
        (Ok(w), None) if !w.converged => format!(
            "the fit with a delay did not converge ({}); likely cause: the delay trades off against the model's poles in this band",
            w.termination
        ),
        (Ok(_), None) => "the fit with a delay is unstable".into(),
        (Ok(_), Some((f, p))) if t.supported() => {
            format!("the data support a delay: F = {f:.4e}, p = {p:.2e} (p < 0.001)")
        }
        (Ok(_), Some((f, p))) => {
            format!("the data do not support a delay: F = {f:.4e}, p = {p:.2e}")
        }
    };
    Some(DelayTestResult {
        delay_s: converged.and_then(|w| w.params.last().copied()),
        reduced_chi2: converged.map(|w| w.reduced_chi2),
        f: t.f_test.map(|(f, _)| f),
        p_value: t.f_test.map(|(_, p)| p),
        supported: t.supported(),
        note,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::manifest::load;
    use crate::manifest::simulation::load_simulation_str;
    use crate::run::simulate::simulate_campaign;

    /// The tests' short campaign (a no-specimen run, a spring and a
    /// validation run), the joint fit including the validation run.
    const CAMPAIGN: &str = concat!(
        include_str!("../../tests/fixtures/small-simulation.toml"),
        "\n[identification.joint]\ninclude_validation = true\n"
    );

    /// The joint fit read a validation run's log; the second pass finds
    /// other bytes there (here: told the fit read other ones). The run
    /// fails with an error naming the file and both hashes, rather than
    /// validating a rig against a log it was not fitted to; with the hash
    /// the fit read, the same run validates.
    #[test]
    fn a_validation_log_changed_since_the_joint_fit_read_it_fails_its_run() {
        let dir = tempfile::tempdir().unwrap();
        let sim =
            load_simulation_str(CAMPAIGN, &dir.path().join("sim.toml")).expect("a simulation");
        let out = simulate_campaign(&sim, dir.path()).expect("simulates");
        let campaign = load(&out.manifest).expect("the manifest loads");
        let plan = campaign.runs.iter().find(|r| r.id == "v1").unwrap();
        let RigInput::Validation(read) = validation_evidence(&campaign, plan) else {
            panic!("the joint fit reads the validation run");
        };
        assert!(read.force.is_some() && !read.displacement.freq_hz.is_empty());
        let rig = Ok((crate::model::PAPER_RIG, None));
        let wants = Wants {
            figures: false,
            tables: false,
            intersample: campaign.identification.intersample,
        };
        let other = "0".repeat(64);
        let done = validation(&campaign, plan, &rig, Some(&other), None, wants);
        let error = done.kept.result.error.expect("the run fails");
        let RunSource::Log(log) = &plan.source else {
            unreachable!()
        };
        for needle in [
            log.path.display().to_string(),
            format!("SHA-256 {other} when the joint fit read it"),
            format!("SHA-256 {} when its run was validated", read.sha256),
        ] {
            assert!(error.contains(&needle), "{needle:?} not in {error:?}");
        }
        let done = validation(&campaign, plan, &rig, Some(&read.sha256), None, wants);
        assert!(
            done.kept.result.error.is_none(),
            "{:?}",
            done.kept.result.error
        );
        assert!(done.kept.result.validation.is_some());
    }
}
