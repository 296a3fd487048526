//! A run's result from its log stage and the campaign's rig: its own fit
//! summarised and judged (`fitted`), a validation run's models, tracking
//! and compensator, what its log was and which FRF it got. Pure: `run`
//! calls it for each run and writes what it gives.

use super::evidence::{RigInput, ValidationEvidence};
use super::log_stage::{LogStage, LogStageError, OwnTf, own_tf_with};
use super::rig::RigError;
use crate::design::night::Noise;
use crate::fit::adequacy::{self, Adequacy, Residuals};
use crate::fit::{self, DelayPlan, TfFit};
use crate::frf::{self, Frf};
use crate::identify::{FitData, fit_options};
use crate::ingest::Log;
use crate::lti::TransferFunction;
use crate::manifest::{Campaign, CompensatorSettings, IdentificationPlan, RunPlan, RunSource};
use crate::model::SpecimenModel;
use crate::model::flow::RigAtLoad;
use crate::model::{self, LinearSpecimen, RigExtras, RigParams};
use crate::results::{
    DelayTestResult, FitSummary, FrfUsed, HarmonicsFound, LinearityResult, LogInfo, Parked,
    PeriodicResult, RunResult, RunTracking, Status, TfResult, TfSource,
};
use crate::tracking::compensator::{self, Compensator, CompensatorOutcome};
use crate::tracking::{self, FrfBins, Reference, Tracking};
use crate::validate::{self, Record, ValidateError};
use crate::warning::Warning;
use std::sync::Arc;

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
pub type Cov4 = [[f64; 4]; 4];

/// The rig and its covariance at P gain `p`: a1b0 scales with P, and its row
/// and column of the covariance with it.
pub fn at_p_gain(rig: &RigParams, cov: Option<&Cov4>, p: f64) -> (RigParams, Option<Cov4>) {
    let f = [1.0, p / rig.p_gain, 1.0, 1.0];
    let at_p = cov.map(|c| -> Cov4 {
        std::array::from_fn(|i| std::array::from_fn(|j| c[i][j] * f[i] * f[j]))
    });
    (rig.at_p_gain(p), at_p)
}

/// What a validation run's compensator is designed and swept with.
pub struct CompensatorPlan<'a> {
    pub settings: &'a CompensatorSettings,
    pub range: (f64, f64),
    pub stiffnesses: Vec<f64>,
}

/// A run's result before anything is known of it.
pub fn new_result(plan: &RunPlan) -> RunResult {
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
        periodic: None,
        noise: None,
        annotations: plan.annotations.clone(),
    }
}

/// A validation run's FRFs for the joint fit, read ahead of the rig
/// (`identification.joint.include_validation`): the band's bins with the
/// coherence the identification runs need. Nothing when the run has no log
/// or its log fails here: the second pass reads it again and reports why.
pub fn validation_evidence(campaign: &Campaign, plan: &RunPlan) -> RigInput {
    if !matches!(plan.source, RunSource::Log(_)) {
        return RigInput::Nothing;
    }
    let Ok(Some(mut st)) = own_tf_with(campaign, plan, None).map(|a| a.stage) else {
        return RigInput::Nothing;
    };
    let coherence_min = campaign.identification.coherence_min;
    // A periodic command's FRFs are read at its excited lines, their
    // variances from the lines it does not excite, as the identification
    // runs' are (`FitData::at_lines`): between the lines the ETFE's
    // neighbours hold noise over a command of nothing.
    let frf_plan = st.choice.plan.clone();
    let data = |h: &mut Frf| {
        let mask = frf::band_mask(h, plan.band_hz, coherence_min);
        FitData::at_lines(h, &mask, plan.band_hz, &frf_plan)
            .unwrap_or_else(|| FitData::of(h, &mask, &frf_plan))
    };
    let displacement = data(&mut st.frf);
    let force = st.force_frf.as_mut().map(data);
    // Both FRFs' bins carry the displacement's amplitude along a sweep,
    // which the friction's describing function needs should the joint fit
    // find friction.
    let sweep = crate::analysis::log_stage::sweep_of(st.excitation, &st.log);
    let with_amplitude = |d: FitData| match &sweep {
        Some(sweep) => d.with_displacement_amplitude(&st.frf, sweep),
        None => d,
    };
    RigInput::Validation(Box::new(ValidationEvidence {
        displacement: with_amplitude(displacement).for_rig(),
        force: force.map(|f| with_amplitude(f).for_rig()),
        sample_rate_hz: st.log.sample_rate_hz,
        sha256: st.log.sha256.clone(),
    }))
}

/// The model's x1/u (Eq. 17) and force path f/u (Eq. 45) for a linear
/// specimen (f/u None without one), or the error that names why the rig
/// and the specimen give no model in f64.
#[allow(clippy::type_complexity)]
pub fn models(
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
pub fn measured_tracking(
    reference: &Reference<'_>,
    st: &LogStage,
    windows: Option<&[validate::Window]>,
) -> Tracking {
    let bins = FrfBins {
        freq_hz: &st.frf.freq_hz,
        h: &st.frf.h,
        keep: &st.mask,
    };
    tracking::measure(
        reference,
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
    reference: &Reference<'_>,
    st: &LogStage,
    windows: &[validate::Window],
    displacement: &[f64],
    plant: Option<&TransferFunction>,
    comp: Option<&Compensator>,
) -> Tracking {
    let fs = st.log.sample_rate_hz;
    let h: Option<Vec<_>> = plant.map(|g| {
        compensator::HeldGrid::new(st.frf.freq_hz.clone(), fs, comp)
            .response(g)
            .collect()
    });
    let bins = h.as_ref().map(|h| FrfBins {
        freq_hz: &st.frf.freq_hz,
        h,
        keep: &st.mask,
    });
    tracking::measure(reference, displacement, fs, bins, windows)
}

/// The tracking the model predicts for the log's command, uncompensated.
pub fn predicted_tracking(
    reference: &Reference<'_>,
    st: &LogStage,
    time: &validate::TimeStage,
    plant: Option<&TransferFunction>,
) -> Tracking {
    predicted_tracking_of(
        reference,
        st,
        &time.windows,
        &time.x1_simulated,
        plant,
        None,
    )
}

/// The compensator for the run's specimen on the identified plant `plant`
/// (x1/u, Eqs. 34-35, the rig at the run's load), its tracking over the
/// run's band with and without it, on the run's measured command (the
/// desired displacement) through the plant's state space, and over the
/// sensitivity's stiffnesses, each at its own load.
pub fn compensate(
    plan: &RunPlan,
    (st, reference): (&LogStage, &Reference<'_>),
    time: &validate::TimeStage,
    (at_load, extras): (&RigAtLoad, &RigExtras),
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
                seals: Vec::new(),
            };
        }
    };
    let compensated = compensator::band_tracking(plant, Some(&c), band, fs);
    let rig_at_p = &at_load.for_specimen(specimen).unwrap_or(at_load.rig);
    let ss = model::state_space(rig_at_p, specimen);
    let (predicted, peak, note) =
        match compensator::compensated_displacement(&ss, &c, &st.log.command_m) {
            Ok((x, peak)) => (
                Some(predicted_tracking_of(
                    reference,
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
    let peak_desired = st.log.command_m.iter().fold(0.0_f64, |m, v| m.max(v.abs()));
    let seals = match &extras.seals {
        Some(seals) if peak_desired > 0.0 => compensator::seals_tracking(
            plant,
            &c,
            (rig_at_p, specimen),
            seals,
            &[peak_desired, peak_desired / 10.0, peak_desired / 100.0],
            band,
            fs,
        ),
        _ => Vec::new(),
    };
    CompensatorOutcome {
        stiffness: compensator::stiffness_sweep(at_load, specimen, &c, &design.stiffnesses, band),
        target_stiffness_n_per_m: compensator::target_stiffness(
            at_load,
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
        peak_desired_m: Some(peak_desired),
        seals,
    }
}

/// A log's signals as the time-domain checks read them.
pub fn record(log: &Log) -> Record<'_> {
    Record {
        sample_rate_hz: log.sample_rate_hz,
        command_m: &log.command_m,
        displacement_m: &log.displacement_m,
        force_n: log.force_n.as_deref(),
    }
}

/// Provenance of a run's log, when it has one.
pub fn log_info(plan: &RunPlan, stage: Option<&LogStage>) -> Option<LogInfo> {
    let (st, RunSource::Log(lp)) = (stage?, &plan.source) else {
        return None;
    };
    // The whole log's, where the analysis read only its steady periods.
    let rows = st.periodic.as_ref().map_or(st.log.n_rows, |p| p.log_rows);
    Some(LogInfo {
        file: lp
            .path
            .file_name()
            .map(|f| f.to_string_lossy().into_owned())
            .unwrap_or_default(),
        sha256: st.log.sha256.clone(),
        sample_rate_hz: st.log.sample_rate_hz,
        n_samples: rows,
        duration_s: rows as f64 / st.log.sample_rate_hz,
        command_peak_m: Some(st.log.command_m.iter().fold(0.0, |m, u| m.max(u.abs()))),
        repairs: st.log.repairs.clone(),
    })
}

/// The FRF settings the run's log got, as results.json states them.
pub fn frf_used(st: &LogStage) -> FrfUsed {
    let (choice, plan) = (&st.choice, &st.choice.plan);
    FrfUsed {
        chosen_by: if choice.chosen { "auto" } else { "manifest" }.into(),
        estimator: plan.method().into(),
        window: plan.window(),
        segment_length: plan.segment_length(),
        overlap: plan.overlap(),
        detrend: plan.detrend(),
        transient: plan.transient().is_some(),
        model_noise: plan.model_noise(),
        excitation: st.excitation.kind().into(),
        excitation_note: st.excitation.describe(),
        ends: choice.ends.describe(),
        reason: choice.reason.clone(),
    }
}

/// A periodic log's steady periods and levels as results.json states
/// them.
pub fn periodic_result(st: &LogStage) -> Option<PeriodicResult> {
    let p = st.periodic.as_ref()?;
    let fs = st.log.sample_rate_hz;
    let l = p.levels;
    Some(PeriodicResult {
        period_s: p.steady.period as f64 / fs,
        periods: p.steady.count,
        start_s: p.start_s,
        lines_excited: l.excited,
        lines_empty: l.empty,
        output_m: l.output.sqrt(),
        noise_m: l.noise.sqrt(),
        empty_m: l.empty_power.sqrt(),
        distortion_to_noise: l.distortion_to_noise(),
        distorts: l.distortion_to_noise() > crate::analysis::log_stage::DISTORTION_RATIO,
    })
}

/// Bands per octave of a run's noise spectrum ([`noise_result`]).
const NOISE_BANDS_PER_OCTAVE: f64 = 6.0;

/// The displacement's noise spectrum the run's fitted bins state, in
/// sixth-octave bands from the lowest.
pub fn noise_result(st: &LogStage) -> Option<Noise> {
    let data = st.fit_data.as_ref()?;
    // A Welch bin's E|dH|^2 is the noise density over (n_eff - 1) Suu
    // (frf::h_variance_at); a whole-record transform's over Suu.
    let dof = match st.frf.n_averages {
        1 => 1.0,
        _ => st.frf.effective_averages - 1.0,
    };
    let first = *data.freq_hz.first()?;
    let mut bands: Vec<(f64, usize)> = Vec::new();
    for ((&f, &v), &suu) in data.freq_hz.iter().zip(&data.variance).zip(&data.suu) {
        let psd = v * suu * dof;
        if !(psd.is_finite() && psd > 0.0 && f > 0.0) {
            continue;
        }
        let band = (NOISE_BANDS_PER_OCTAVE * (f / first).log2()).floor() as usize;
        if bands.len() <= band {
            bands.resize(band + 1, (0.0, 0));
        }
        bands[band].0 += psd;
        bands[band].1 += 1;
    }
    let (freq_hz, psd_m2_per_hz): (Vec<f64>, Vec<f64>) = bands
        .iter()
        .enumerate()
        .filter(|(_, (_, n))| *n > 0)
        .map(|(i, (sum, n))| {
            let centre = first * ((i as f64 + 0.5) / NOISE_BANDS_PER_OCTAVE).exp2();
            (centre, sum / *n as f64)
        })
        .unzip();
    (!freq_hz.is_empty()).then_some(Noise {
        freq_hz,
        psd_m2_per_hz,
    })
}

/// The share of a fit's excess cost (its reduced chi-square above 1) a
/// delay must explain for the run's warning to name it.
const DELAY_EXPLAINS: f64 = 0.5;

/// The linearity check as results.json states it.
pub fn linearity_result(l: &frf::Linearity) -> LinearityResult {
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
pub fn failed(mut out: RunResult, e: RunError) -> RunResult {
    out.status = Status::Failed;
    out.error = Some(e.to_string());
    out
}

/// An identification or fit run: its published or fitted model with the
/// coefficients' uncertainty, and the fitted model in the time domain (Figs.
/// 9, 12, 14). A failure of the time-domain check is a warning: the fit
/// stands on its own. Returns the result, the log stage and the
/// time-domain check for the figures.
pub fn fitted(
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
    out.periodic = acq.stage.as_deref().and_then(periodic_result);
    out.noise = acq.stage.as_deref().and_then(noise_result);
    let stage = acq.stage;
    let fit = stage.as_ref().and_then(|s| s.fit.as_ref());
    out.tf = acq.tf.as_ref().map(|tf| tf_result(tf, acq.source, fit));
    let mut time = None;
    if let Some(st) = &stage
        && let Some(fit) = &st.fit
    {
        let summary = fit_summary(ident, plan, st, fit);
        out.warnings.extend(own_fit_warnings(&summary, st, fit));
        out.fit = Some(Box::new(summary));
        match validate::fitted_run(&fit.tf, &record(&st.log)) {
            Ok(t) => {
                out.validation = Some(t.metrics.clone());
                time = Some(t);
            }
            Err(e) => out.warnings.push(Warning::new(
                "the time-domain check of the fitted model could not be made",
                format!("time-domain check of the fitted model: {e}"),
            )),
        }
    }
    if let Some(st) = &stage {
        let windows = time
            .as_ref()
            .map(|t: &validate::TimeStage| t.windows.as_slice());
        out.tracking = Some(Parked::new(RunTracking {
            measured: measured_tracking(&st.reference(), st, windows),
            predicted: None,
            model_gap_s: None,
            compensator: None,
        }));
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
fn own_fit_warnings(summary: &FitSummary, st: &LogStage, fit: &TfFit) -> Vec<Warning> {
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
        warnings.push(Warning::new(
            format!(
                "the run's own fit lacks a delay: {:.3} ms takes its reduced chi-square from {:.2} to {:.2}",
                1e3 * t.delay_s.unwrap_or(f64::NAN),
                summary.reduced_chi2,
                t.reduced_chi2.unwrap_or(f64::NAN),
            ),
            format!(
                "the run's own fit: {}; with a delay of {:.3} ms its reduced chi-square is {:.3} (without, {:.3}); set identification.delay = {{ mode = \"fit\" }}",
                t.note,
                1e3 * t.delay_s.unwrap_or(f64::NAN),
                t.reduced_chi2.unwrap_or(f64::NAN),
                summary.reduced_chi2
            ),
        ));
    }
    if let Some(a) = summary.adequacy.as_ref() {
        if let Some(d) = a.diagnosis_because(
            (!fit.shape.fit_delay).then_some("set identification.delay = \"fit\""),
            frf::Estimator::from(st.choice.plan.method()).understated_noise(),
            st.cause.as_deref(),
        ) {
            let likely = super::log_stage::likely(st.cause.as_deref());
            warnings.push(Warning::new(
                format!("the run's own fit misses: {}{likely}", a.failure_headline()),
                format!("the run's own fit: {d}"),
            ));
        }
        if let Some(o) = a.overstated_because(
            frf::Estimator::from(st.choice.plan.method()).overstated_noise(),
            st.cause.as_deref(),
        ) {
            warnings.push(Warning::new(
                format!("the run's own fit: {}", a.overstated_headline()),
                format!("the run's own fit: {o}"),
            ));
        }
    }
    // A model that explains under half of the measured response is not a
    // rig's: the likely causes are in the log's mapping, not in the model
    // (swapped command and displacement columns measured 31 %).
    if summary.fit_percent < POOR_FIT_PERCENT {
        warnings.push(Warning::new(
            format!(
                "the model explains only {:.0} % of the response: columns swapped, or another run's log?",
                summary.fit_percent
            ),
            format!(
                "the model explains only {:.0} % of the measured response (fit percent below {POOR_FIT_PERCENT:.0}); likely cause: the channels' columns (command and displacement swapped, or another run's log)",
                summary.fit_percent
            ),
        ));
    }
    warnings
}

/// The adequacy tests of a run's own fit on the bins it was given, its
/// model with the hold and delay.
fn fit_adequacy(ident: &IdentificationPlan, st: &LogStage, fit: &TfFit) -> Option<Adequacy> {
    let data = st.fit_data.as_ref()?;
    let fs = st.log.sample_rate_hz;
    let model = fit.as_logged(ident.intersample, fs, &data.freq_hz);
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
