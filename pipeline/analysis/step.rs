//! One run's analysis, pure: a run that does not need the rig (read,
//! estimated, fitted and checked in the time domain, with what the rig needs
//! of it), what such a run gets once the rig is known, and a validation run
//! with the rig (Sec. 4: Eqs. 47-48, its tracking, the control-structure
//! interaction). The log's stage stays in the outcome until the run's
//! figures are drawn from it; nothing is written here.

use crate::warning::Warning;
use std::sync::Arc;

use super::evidence::Evidence;
use super::log_stage::{LogStage, LogStageError, OwnTf, own_tf_with};
use super::rig::RigError;
use super::run_result::{
    CompensatorPlan, Cov4, at_p_gain, compensate, failed, fitted, frf_used, linearity_result,
    log_info, measured_tracking, models, new_result, periodic_result, predicted_tracking, record,
};
use super::sensitivity::NoiseSource;
use crate::frf;
use crate::identify::FitData;
use crate::ingest::{IngestError, LogFile};
use crate::lti::TransferFunction;
use crate::manifest::{Campaign, Role, RunPlan};
use crate::model::flow::{LoadLaw, RigAtLoad};
use crate::model::{self, LinearSpecimen, RigExtras, RigParams, SpecimenModel};
use crate::results::{Parked, RunResult, RunTracking, SpringForceResult};
use crate::sensitivity::{self, NoiseProfile};
use crate::validate::csi::Csi;
use crate::validate::{self, TimeStage};

/// The rig as the validation runs read it: its parameters, the covariance
/// of (beta1, a1b0, a2, a3) when identified and what the joint fit found
/// beyond Eq. 10 (the seals' friction, the valve's flow law), or why there
/// is none.
pub type RigOutcome = Result<(RigParams, Option<Cov4>, RigExtras), Arc<RigError>>;

/// A run analysed without the rig.
pub struct Fitted {
    pub result: RunResult,
    /// What the rig is identified from, when the run gave a model.
    pub evidence: Option<Evidence>,
    /// Its log's stage, for its figures and tables.
    pub stage: Option<Box<LogStage>>,
    /// The fitted model in the time domain (Figs. 9, 12, 14).
    pub time: Option<TimeStage>,
    /// A no-specimen run's FRF noise, for the stiffness sensitivity.
    pub noise: Option<NoiseSource>,
}

/// A run that does not need the rig (no-specimen, spring and fit runs):
/// read, estimated, fitted and checked in the time domain, with what the
/// rig needs of it (its model and the bins its fit was given). `file` is
/// its log's bytes when the cache read them on the way; Err when the log
/// could not be read or analysed.
pub fn without_rig(
    campaign: &Campaign,
    plan: &RunPlan,
    file: Option<LogFile>,
) -> Result<Fitted, LogStageError> {
    let acq = own_tf_with(campaign, plan, file)?;
    let (tf, cov) = (acq.tf.clone(), acq.cov);
    let (result, stage, time) = fitted(&campaign.identification, plan, new_result(plan), acq);
    let evidence = tf.map(|tf| Evidence {
        tf,
        cov,
        data: (stage.as_ref())
            .and_then(|st| st.fit_data.clone())
            .map(FitData::for_rig),
        stored: None,
        adequacy: result.fit.as_ref().and_then(|f| f.adequacy.clone()),
        sample_rate_hz: stage.as_ref().map(|st| st.log.sample_rate_hz),
        cause: stage.as_ref().and_then(|st| st.cause.clone()),
        friction_signature: stage.as_ref().is_some_and(|st| st.friction_signature()),
        spring_cubic_n_per_m3: stage
            .as_ref()
            .and_then(|st| st.spring)
            .filter(|s| s.stiffens())
            .map(|s| s.cubic_n_per_m3),
        load_cell: stage
            .as_ref()
            .and_then(|st| st.spring)
            .map(|s| (s.stiffness_n_per_m, s.amplitude_m)),
        slow: stage.as_ref().and_then(|st| st.slow),
    });
    let noise = stage
        .as_deref()
        .filter(|_| plan.role == Role::NoSpecimen)
        .and_then(|st| noise_profile(plan, st));
    Ok(Fitted {
        result,
        evidence,
        stage,
        time,
        noise,
    })
}

/// What a run done without the rig gets once the rig is known: a1b0 at its
/// P gain and the force model (Eq. 45). The run's own fit stands without
/// the force model: its absence is a warning, not the run's failure.
pub fn with_rig(out: &mut RunResult, plan: &RunPlan, rig_at_p: Option<&RigParams>) {
    out.a1b0 = rig_at_p.map(|r| r.a1b0_n_per_m_s2);
    out.force_tf = match rig_at_p.map(|r| models(r, &plan.specimen)) {
        Some(Ok((_, f))) => f,
        Some(Err(e)) => {
            out.warnings.push(Warning::new(
                "no force model (Eq. 45)",
                format!("no force model (Eq. 45): {e}"),
            ));
            None
        }
        None => None,
    };
}

/// A validation run analysed.
pub enum Validation {
    /// Its log could not be read or analysed.
    Unread(RunResult, Arc<LogStageError>),
    /// It failed once its log was read (no rig, no model): the measured
    /// FRF is still worth seeing.
    Unfinished(RunResult, Option<Box<LogStage>>),
    /// Without a log: the model's prediction alone.
    Predicted(RunResult),
    /// Validated against its log.
    Validated(Box<Validated>),
}

/// A validation run validated against its log, with what its figures
/// show.
pub struct Validated {
    pub result: RunResult,
    pub stage: Box<LogStage>,
    /// The model driven by the measured command (Eqs. 47-48), unless it
    /// could not be simulated.
    pub time: Option<TimeStage>,
    /// The identified plant x1/u with its delay.
    pub plant: Option<TransferFunction>,
    pub csi: Option<Csi>,
    /// The rig at the run's P gain and its covariance, for the
    /// prediction's band.
    pub rig_at_p: RigParams,
    pub rig_cov: Option<Cov4>,
    /// The specimen, when linear (the prediction's band needs it).
    pub specimen: Option<LinearSpecimen>,
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
pub fn validation(
    campaign: &Campaign,
    plan: &RunPlan,
    rig: &RigOutcome,
    fitted: Option<&str>,
    file: Option<LogFile>,
) -> Validation {
    let mut out = new_result(plan);
    // The log's own failure comes first; a good log without a rig still
    // records what it is.
    let acq = match read_validation_log(campaign, plan, fitted, file) {
        Ok(a) => a,
        Err(e) => {
            out.a1b0 = rig
                .as_ref()
                .ok()
                .map(|(r, ..)| r.at_p_gain(plan.p_gain).a1b0_n_per_m_s2);
            let error = Arc::new(e);
            return Validation::Unread(failed(out, error.clone().into()), error);
        }
    };
    out.warnings = acq.warnings.clone();
    out.log = log_info(plan, acq.stage.as_deref());
    out.frf = acq.stage.as_deref().map(frf_used);
    out.periodic = acq.stage.as_deref().and_then(periodic_result);
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
    let stage = acq.stage;
    let (rig_at_p, rig_cov, extras) = match rig {
        Ok((r, cov, extras)) => {
            let (r, cov) = at_p_gain(r, cov.as_ref(), plan.p_gain);
            (r, cov, *extras)
        }
        Err(e) => return Validation::Unfinished(failed(out, e.clone().into()), stage),
    };
    out.a1b0 = Some(rig_at_p.a1b0_n_per_m_s2);
    match models(&rig_at_p, &plan.specimen) {
        Ok((tf, force_tf)) => (out.tf, out.force_tf) = (tf, force_tf),
        Err(e) => return Validation::Unfinished(failed(out, e), stage),
    }
    let Some(st) = stage else {
        return Validation::Predicted(out);
    };
    // The compensator's stiffness sweep covers the sensitivity analysis's
    // range (a2 does not depend on the P gain).
    let range = campaign.sensitivity.range.n_per_m(rig_at_p.a2_n_per_m);
    let design = CompensatorPlan {
        settings: &campaign.compensator,
        range,
        stiffnesses: sensitivity::log_grid(range, campaign.sensitivity.points),
    };
    Validation::Validated(Box::new(validated(
        plan,
        out,
        st,
        (&rig_at_p, &extras),
        rig_cov,
        &design,
    )))
}

/// A validation run with its log and model: the time-domain validation
/// (Eqs. 47-48), its tracking and the control-structure interaction.
fn validated(
    plan: &RunPlan,
    mut out: RunResult,
    st: Box<LogStage>,
    (rig_at_p, extras): (&RigParams, &RigExtras),
    rig_cov: Option<Cov4>,
    design: &CompensatorPlan<'_>,
) -> Validated {
    let time = match validate::validation_run(rig_at_p, &plan.specimen, extras, &record(&st.log)) {
        Ok(t) => {
            out.validation = Some(t.metrics.clone());
            Some(t)
        }
        Err(e) => {
            out = failed(out, e.into());
            None
        }
    };
    let at_load = rig_at_load(rig_at_p, extras, &st.log.command_m, plan.band_hz);
    let lin = plan.specimen.linear();
    // The plant the tracking and the compensator take: the rig at the
    // run's load where the valve's flow law was found.
    let plant = match (&at_load.law, lin) {
        (Some(law), Some(lin)) => {
            let rig = at_load.for_specimen(&lin);
            if let Some(load) = out.validation.as_mut().and_then(|v| v.load.as_mut()) {
                (load.amplitude_m, load.equivalent_rig) = (Some(law.amplitude_m), rig);
            }
            rig.and_then(|r| model::tf_x1_u(&r, &lin).ok())
        }
        _ => out
            .tf
            .as_ref()
            .and_then(|tf| TransferFunction::with_delay(&tf.num, &tf.den, tf.delay_s).ok()),
    };
    out.tracking = Some(Parked::new(run_tracking(
        plan,
        &st,
        time.as_ref(),
        plant.as_ref(),
        (&at_load, extras),
        design,
    )));
    // The measured force FRF at positive frequencies up to the kept top,
    // the bins Figs. 16-17 show it at.
    let force = st
        .force_frf
        .as_ref()
        .map(|ff| ff.positive_up_to(frf::KEPT_MAX_HZ));
    let csi = plan.specimen.linear().and_then(|lin| {
        let bins = force.as_ref().map(|(f, h, _)| (f.as_slice(), h.as_slice()));
        validate::csi::csi(&plan.id, rig_at_p, &lin, bins)
    });
    Validated {
        result: out,
        stage: st,
        time,
        plant,
        csi,
        rig_at_p: *rig_at_p,
        rig_cov,
        specimen: plan.specimen.linear(),
    }
}

/// The rig at a validation run's load: with the valve's flow law, the
/// equivalent linear rig at the amplitude of the run's command (half its
/// range), fitted over 100 frequencies spaced evenly in log over its band.
fn rig_at_load(
    rig_at_p: &RigParams,
    extras: &RigExtras,
    command_m: &[f64],
    band_hz: (f64, f64),
) -> RigAtLoad {
    let Some(max_force_n) = extras.max_force_n else {
        return RigAtLoad::zero_load(*rig_at_p);
    };
    let (lo, hi) = command_m
        .iter()
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), &u| {
            (a.min(u), b.max(u))
        });
    let ratio = band_hz.1 / band_hz.0;
    RigAtLoad {
        rig: *rig_at_p,
        law: Some(LoadLaw {
            max_force_n,
            amplitude_m: 0.5 * (hi - lo).max(0.0),
            freqs_hz: (0..100)
                .map(|i| band_hz.0 * ratio.powf(f64::from(i) / 99.0))
                .collect(),
        }),
    }
}

/// A validation run's tracking: the log's own, which stands whether or not
/// the model could be simulated (`time`), the model's prediction for the
/// same command, and the compensator designed on the identified `plant`,
/// all measured against one transform of the command.
fn run_tracking(
    plan: &RunPlan,
    st: &LogStage,
    time: Option<&TimeStage>,
    plant: Option<&TransferFunction>,
    (at_load, extras): (&RigAtLoad, &RigExtras),
    design: &CompensatorPlan<'_>,
) -> RunTracking {
    let reference = st.reference();
    let measured = measured_tracking(&reference, st, time.map(|t| t.windows.as_slice()));
    let predicted = time.map(|t| predicted_tracking(&reference, st, t, plant));
    let compensator = match (plan.specimen.linear(), time, plant) {
        (Some(lin), Some(t), Some(g)) => Some(compensate(
            plan,
            (st, &reference),
            t,
            (at_load, extras),
            &lin,
            g,
            design,
        )),
        _ => None,
    };
    RunTracking {
        model_gap_s: measured
            .delay_xcorr_s
            .zip(predicted.as_ref().and_then(|p| p.delay_xcorr_s))
            .map(|(m, p)| m - p),
        measured,
        predicted,
        compensator,
    }
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
