//! The orchestrator: the one module that knows every stage. It loads a
//! manifest of either kind, analyses a campaign ([`analyse`]), simulates one
//! ([`run_simulation`], through [`simulate`]), draws the figures ([`figures`]) and writes the outputs
//! (through `report`). It never prints: each entry point returns what it did,
//! or a [`JobError`] that says why nothing was written, for `cli` to report.

pub mod acquire;
mod analyse;
mod compare;
pub mod figures;
mod rig;
pub mod simulate;

use std::path::{Path, PathBuf};

pub use analyse::{Analysis, RunArtifacts, RunError, analyse, analyse_full, any_failed};
pub use rig::{FailedRun, RigError};

use crate::manifest::{self, Campaign, Loaded, ManifestError};
pub use crate::report::FigureFormats;
use crate::report::{self, WriteError};
use crate::results::{self, Results};
use simulate::{SimulateError, Simulated};

/// How a job runs and what it writes.
#[derive(Debug, Clone, Default)]
pub struct Settings {
    /// Output folder (default: `reports/<campaign or simulation name>`).
    pub out: Option<PathBuf>,
    /// Worker threads (default: all cores); the output does not depend on it.
    pub jobs: Option<usize>,
    /// Which figure files to draw.
    pub figures: FigureFormats,
}

/// Why a job wrote nothing (or, for an output, could not finish writing).
#[derive(Debug, thiserror::Error)]
pub enum JobError {
    #[error(transparent)]
    Manifest(#[from] ManifestError),
    #[error("{}: this is a {found} manifest; {hint}", file.display())]
    WrongKind {
        file: PathBuf,
        found: &'static str,
        hint: String,
    },
    #[error("cannot start worker threads: {0}")]
    Workers(#[from] rayon::ThreadPoolBuildError),
    #[error("cannot write the outputs: {0}")]
    Write(#[from] WriteError),
    #[error(transparent)]
    Simulate(#[from] SimulateError),
}

impl JobError {
    /// Whether the job was asked for wrongly (a bad manifest or the wrong
    /// kind of one), as opposed to failing while it ran.
    pub fn is_usage(&self) -> bool {
        matches!(self, JobError::Manifest(_) | JobError::WrongKind { .. })
    }
}

/// What `servoid run` produced.
#[derive(Debug, Clone)]
pub struct CampaignOutcome {
    pub results: Results,
    pub results_path: PathBuf,
    pub page_path: PathBuf,
}

/// What `servoid simulate` produced, and the campaign run after it when one
/// was asked for.
#[derive(Debug)]
pub struct SimulationOutcome {
    pub name: String,
    pub seed: u64,
    pub simulated: Simulated,
    pub campaign: Option<Result<CampaignOutcome, JobError>>,
}

/// A manifest checked without running it.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Checked {
    /// "campaign" or "simulation".
    pub kind: &'static str,
    pub name: String,
    pub runs: usize,
}

impl std::fmt::Display for Checked {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "{} `{}`, {} runs", self.kind, self.name, self.runs)
    }
}

/// Check a manifest of either kind, reporting every problem at once.
pub fn check(path: &Path) -> Result<Checked, ManifestError> {
    Ok(match manifest::load_any(path)? {
        Loaded::Campaign(c) => Checked {
            kind: "campaign",
            name: c.name.clone(),
            runs: c.runs.len(),
        },
        Loaded::Simulation(p) => Checked {
            kind: "simulation",
            name: p.manifest.simulation.name.clone(),
            runs: p.runs.len(),
        },
    })
}

/// Run a campaign manifest: analyse, draw the figures, write results.json
/// and the page into the output folder.
pub fn run_campaign(path: &Path, settings: &Settings) -> Result<CampaignOutcome, JobError> {
    let campaign = match manifest::load_any(path)? {
        Loaded::Campaign(c) => c,
        Loaded::Simulation(_) => {
            return Err(JobError::WrongKind {
                file: path.to_path_buf(),
                found: "simulation",
                hint: format!(
                    "simulate it and run the campaign it writes with `servoid simulate {} --run`",
                    path.display()
                ),
            });
        }
    };
    let out_dir = settings
        .out
        .clone()
        .unwrap_or_else(|| PathBuf::from("reports").join(&campaign.name));
    let workers = pool(settings.jobs)?;
    workers.install(|| write_campaign(&campaign, &out_dir, settings.figures))
}

/// Simulate a campaign from a simulation manifest (logs, truth.json and an
/// analysis manifest), then, with `then_run`, run that campaign into the
/// same folder.
pub fn run_simulation(
    path: &Path,
    settings: &Settings,
    then_run: bool,
) -> Result<SimulationOutcome, JobError> {
    let plan = match manifest::load_any(path)? {
        Loaded::Simulation(p) => p,
        Loaded::Campaign(_) => {
            return Err(JobError::WrongKind {
                file: path.to_path_buf(),
                found: "campaign",
                hint: format!(
                    "a simulation manifest has a [simulation] table; run a campaign with `servoid run {}`",
                    path.display()
                ),
            });
        }
    };
    let out_dir = settings
        .out
        .clone()
        .unwrap_or_else(|| PathBuf::from("reports").join(&plan.manifest.simulation.name));
    let workers = pool(settings.jobs)?;
    let simulated = workers.install(|| simulate::simulate_campaign(&plan, &out_dir))?;
    let campaign = then_run.then(|| {
        let settings = Settings {
            out: Some(out_dir),
            ..settings.clone()
        };
        run_campaign(&simulated.manifest, &settings)
    });
    Ok(SimulationOutcome {
        name: plan.manifest.simulation.name.clone(),
        seed: plan.manifest.simulation.seed,
        simulated,
        campaign,
    })
}

/// Write the JSON Schemas of both manifests and of results.json into `dir`.
pub fn write_schemas(dir: &Path) -> Result<Vec<PathBuf>, WriteError> {
    schemas()
        .into_iter()
        .map(|(name, value)| {
            let path = dir.join(name);
            report::write_atomic(&path, &report::json_bytes(&value))?;
            Ok(path)
        })
        .collect()
}

/// The committed schema files under `schemas/`, with their contents.
pub fn schemas() -> Vec<(&'static str, serde_json::Value)> {
    vec![
        ("manifest.schema.json", manifest::manifest_schema()),
        ("results.schema.json", results::results_schema()),
        ("simulation.schema.json", manifest::simulation_schema()),
    ]
}

fn pool(jobs: Option<usize>) -> Result<rayon::ThreadPool, JobError> {
    Ok(rayon::ThreadPoolBuilder::new()
        .num_threads(jobs.unwrap_or(0))
        .build()?)
}

/// Analyse a checked campaign and write its outputs: the figures first (a
/// figure that cannot be drawn becomes a warning in results.json), then
/// results.json, then the page.
fn write_campaign(
    campaign: &Campaign,
    out_dir: &Path,
    choice: FigureFormats,
) -> Result<CampaignOutcome, JobError> {
    let mut analysis = analyse_full(campaign);
    let specs = match choice {
        FigureFormats::None => Vec::new(),
        _ => figures::build(&analysis, campaign),
    };
    let (page_figures, warnings) = report::write_figures(&specs, out_dir, choice)?;
    analysis.results.warnings.extend(warnings);
    let results = analysis.results;
    let results_path = report::write_results(&results, out_dir)?;
    let page_path = report::write_page(&results, &page_figures, choice, out_dir)?;
    Ok(CampaignOutcome {
        results,
        results_path,
        page_path,
    })
}
