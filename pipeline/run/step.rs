//! One run's work: its analysis (`analysis::step`), then what is to be
//! written for it (figure specs, tables) and what the campaign keeps of it,
//! nothing written here. The log is read and dropped inside each step; the
//! writing is `sink`'s, as each run's output arrives.

use std::sync::Arc;

use crate::analysis::evidence::Evidence;
use crate::analysis::log_stage::{LogStage, LogStageError};
use crate::analysis::run_result::{failed, new_result};
use crate::analysis::sensitivity::NoiseSource;
use crate::analysis::step::{Validated, Validation};
use crate::analysis::{self};
use crate::fit::Intersample;
use crate::ingest::LogFile;
use crate::manifest::{Campaign, RunPlan};
use crate::model::RigParams;
use crate::report::figures::catalogue::{self, ForceBins, OverlayRun};
use crate::report::tables::RunTables;
use crate::report::{FigureSpec, Measured};
use crate::results::RunResult;
use crate::validate::csi::Csi;

pub(super) use crate::analysis::step::RigOutcome;

/// What a run's step is asked to build besides its result: figure specs
/// (when the job draws figures) and tables (when it writes an output folder),
/// with the command's hold the models are shown with.
#[derive(Debug, Clone, Copy)]
pub(super) struct Wants {
    pub figures: bool,
    /// Every figure, not only the summary's (false when none is drawn).
    pub every_figure: bool,
    pub tables: bool,
    pub intersample: Intersample,
}

/// What the campaign keeps of a run once its log is dropped, and what the
/// cache stores of it.
#[derive(Debug, Clone, serde::Serialize, serde::Deserialize)]
pub(super) struct Kept {
    pub result: RunResult,
    /// What the rig is identified from (an identification or fit run).
    /// Boxed: a validation run has none, and a night holds every run's
    /// until its files are written.
    pub estimate: Option<Box<Evidence>>,
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
                let m = Measured::of(st);
                catalogue::log_figures(
                    &result,
                    &m,
                    None,
                    wants.intersample,
                    None,
                    wants.every_figure,
                )
                .0
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

/// A run that does not need the rig (no-specimen, spring and fit runs),
/// analysed (`analysis::step::without_rig`), with its figures and tables.
/// `file` is its log's bytes when the cache read them on the way.
pub(super) fn without_rig(
    campaign: &Campaign,
    plan: &RunPlan,
    file: Option<LogFile>,
    wants: Wants,
) -> Output {
    let done = match analysis::step::without_rig(campaign, plan, file) {
        Ok(d) => d,
        Err(e) => return Output::unread(new_result(plan), Arc::new(e)),
    };
    let (figures, overlay) = match wants.figures {
        true => catalogue::fitted_figures(&done, wants.intersample, wants.every_figure),
        false => (Vec::new(), None),
    };
    let measured = done.stage.as_deref().map(Measured::of);
    // Kept for the force figure, drawn once the rig is known.
    let force = (measured.as_ref())
        .filter(|_| wants.every_figure)
        .and_then(ForceBins::of);
    let tables = tables(&done.result, measured.as_ref(), wants);
    Output {
        kept: Kept {
            estimate: done.evidence.map(Box::new),
            noise: done.noise,
            force,
            overlay,
            ..Kept::of(done.result)
        },
        tables,
        figures,
        log_error: None,
        cacheable: true,
    }
}

/// What a run done without the rig gets once the rig is known
/// (`analysis::step::with_rig`) and, when figures are wanted and its log
/// had force, the force figure (Figs. 16-17).
pub(super) fn with_rig(
    kept: &mut Kept,
    plan: &RunPlan,
    rig_at_p: Option<&RigParams>,
    wants: Wants,
) -> Option<FigureSpec> {
    analysis::step::with_rig(&mut kept.result, plan, rig_at_p);
    match (&kept.force, &kept.result.force_tf) {
        (Some(bins), Some(model)) if wants.every_figure => Some(catalogue::force_figure(
            &kept.result,
            bins,
            model,
            wants.intersample,
            None,
        )),
        _ => None,
    }
}

/// A validation run (`analysis::step::validation`), with its figures and
/// tables. `fitted` is the SHA-256 of the log as the joint fit read it,
/// when it did.
pub(super) fn validation(
    campaign: &Campaign,
    plan: &RunPlan,
    rig: &RigOutcome,
    fitted: Option<&str>,
    file: Option<LogFile>,
    wants: Wants,
) -> Output {
    match analysis::step::validation(campaign, plan, rig, fitted, file) {
        Validation::Unread(result, error) => Output {
            kept: Kept::of(result),
            figures: Vec::new(),
            tables: None,
            log_error: Some(error),
            cacheable: false,
        },
        Validation::Unfinished(result, stage) => {
            Output::unfinished(result, stage.as_deref(), wants)
        }
        Validation::Predicted(result) => Output {
            tables: tables(&result, None, wants),
            ..Output::unfinished(result, None, wants)
        },
        Validation::Validated(v) => validated(*v, wants),
    }
}

/// A validated run's figures and tables.
fn validated(v: Validated, wants: Wants) -> Output {
    let figures = match wants.figures {
        true => catalogue::validated_figures(&v, wants.intersample, wants.every_figure),
        false => Vec::new(),
    };
    let tables = tables(&v.result, Some(&Measured::of(&v.stage)), wants);
    Output {
        tables,
        kept: Kept {
            csi: v.csi,
            ..Kept::of(v.result)
        },
        figures,
        log_error: None,
        cacheable: true,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::analysis::evidence::RigInput;
    use crate::analysis::run_result::validation_evidence;
    use crate::manifest::RunSource;
    use crate::run::simulate::simulated;

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
        let campaign = simulated(CAMPAIGN, dir.path());
        let plan = campaign.runs.iter().find(|r| r.id == "v1").unwrap();
        let RigInput::Validation(read) = validation_evidence(&campaign, plan) else {
            panic!("the joint fit reads the validation run");
        };
        assert!(read.force.is_some() && !read.displacement.freq_hz.is_empty());
        let rig = Ok((crate::model::PAPER_RIG, None, Default::default()));
        let wants = Wants {
            figures: false,
            every_figure: false,
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
