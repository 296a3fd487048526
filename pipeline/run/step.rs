//! One run's work, pure: from its plan (and its log's bytes, when the cache
//! read them on the way) to what the campaign keeps of it and what is to be
//! written for it (figure specs, tables), nothing written here. The log is
//! read (by `ingest`, through `log_stage`) and dropped inside each step; the
//! writing is `sink`'s, as each run's output arrives.

use crate::warning::Warning;
use std::sync::Arc;

use super::sensitivity::NoiseSource;
use crate::analysis::evidence::Evidence;
use crate::analysis::log_stage::{LogStage, LogStageError, OwnTf, own_tf_with};
use crate::analysis::rig::RigError;
use crate::analysis::run_result::{
    CompensatorPlan, Cov4, at_p_gain, compensate, failed, fitted, frf_used, linearity_result,
    log_info, measured_tracking, models, new_result, predicted_tracking, record,
};
use crate::fit::Intersample;
use crate::ingest::{IngestError, LogFile};
use crate::lti::TransferFunction;
use crate::manifest::{Campaign, Role, RunPlan};
use crate::model::SpecimenModel;
use crate::model::{RigParams, Seals};
use crate::report::figures::catalogue::{self, ForceBins, OverlayRun, Prediction};
use crate::report::tables::RunTables;
use crate::report::{FigureSpec, Measured};
use crate::results::{RunResult, RunTracking, SpringForceResult};
use crate::sensitivity::{self, NoiseProfile};
use crate::tracking::Reference;
use crate::validate;
use crate::validate::csi::Csi;

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
            out.warnings.push(Warning::new(
                "no force model (Eq. 45)",
                format!("no force model (Eq. 45): {e}"),
            ));
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

/// The rig as the validation runs read it: its parameters, the covariance
/// of (beta1, a1b0, a2, a3) when identified and the seals' friction when
/// the joint fit found it, or why there is none.
pub(super) type RigOutcome = Result<(RigParams, Option<Cov4>, Option<Seals>), Arc<RigError>>;

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
                .map(|(r, ..)| r.at_p_gain(plan.p_gain).a1b0_n_per_m_s2);
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
    let (rig_at_p, rig_cov, seals) = match rig {
        Ok((r, cov, seals)) => {
            let (r, cov) = at_p_gain(r, cov.as_ref(), plan.p_gain);
            (r, cov, *seals)
        }
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
    validated(
        plan,
        out,
        st,
        (&rig_at_p, seals.as_ref()),
        rig_cov,
        &design,
        wants,
    )
}

/// A validation run with its log and model: the time-domain validation
/// (Eqs. 47-48), its tracking, the control-structure interaction, its
/// figures and tables.
fn validated(
    plan: &RunPlan,
    mut out: RunResult,
    st: &LogStage,
    (rig_at_p, seals): (&RigParams, Option<&Seals>),
    rig_cov: Option<Cov4>,
    design: &CompensatorPlan<'_>,
    wants: Wants,
) -> Output {
    let linear = plan.specimen.linear();
    let time = match validate::validation_run(rig_at_p, &plan.specimen, seals, &record(&st.log)) {
        Ok(t) => {
            out.validation = Some(t.metrics.clone());
            Some(t)
        }
        Err(e) => {
            out = failed(out, e.into());
            None
        }
    };
    let plant = out
        .tf
        .as_ref()
        .and_then(|tf| TransferFunction::with_delay(&tf.num, &tf.den, tf.delay_s).ok());
    out.tracking = Some(run_tracking(
        plan,
        st,
        time.as_ref(),
        plant.as_ref(),
        (rig_at_p, seals),
        design,
    ));
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

/// A validation run's tracking: the log's own, which stands whether or not
/// the model could be simulated (`time`), the model's prediction for the
/// same command, and the compensator designed on the identified `plant`,
/// all measured against one transform of the command.
fn run_tracking(
    plan: &RunPlan,
    st: &LogStage,
    time: Option<&validate::TimeStage>,
    plant: Option<&TransferFunction>,
    (rig_at_p, seals): (&RigParams, Option<&Seals>),
    design: &CompensatorPlan<'_>,
) -> RunTracking {
    let reference = Reference::new(&st.log.command_m);
    let measured = measured_tracking(&reference, st, time.map(|t| t.windows.as_slice()));
    let predicted = time.map(|t| predicted_tracking(&reference, st, t, plant));
    let compensator = match (plan.specimen.linear(), time, plant) {
        (Some(lin), Some(t), Some(g)) => Some(compensate(
            plan,
            (st, &reference),
            t,
            (rig_at_p, seals),
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

#[cfg(test)]
mod tests {
    use super::*;
    use crate::analysis::evidence::RigInput;
    use crate::analysis::run_result::validation_evidence;
    use crate::manifest::simulation::load_simulation_str;
    use crate::manifest::{RunSource, load};
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
        let rig = Ok((crate::model::PAPER_RIG, None, None));
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
