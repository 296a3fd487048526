//! The declarative manifests: a campaign on one rig (`raw`, checked by
//! `campaign` into a [`Campaign`]) and a simulated campaign (`simulation`).
//!
//! The manifests' types are as the user writes them (TOML, or the same
//! structure in JSON); the stages' own setting types (`frf::Window`,
//! `ingest::Column`, ...) appear in them where the user names a stage's
//! option. Loading reads a file, checks form and meaning, reports every
//! problem at once with its key path, run and (TOML) line and column, and
//! builds each stage's settings. `schemas/*.schema.json` are generated from
//! these types (`servoid schema`).
//!
//! Inside: `keypath` and `problem` say where and what; `document` parses and
//! reads sections against a schema; `checks` holds what both kinds check;
//! `table` reads and checks a campaign's run table; `campaign` and
//! `simulation` build the plans.

mod campaign;
mod checks;
mod document;
mod identification;
mod keypath;
pub mod keys;
mod problem;
mod raw;
pub mod scaffold;
pub mod simulation;
mod table;

use std::path::Path;

pub use crate::identify::IdentificationPlan;
pub use campaign::{
    Campaign, Quantity, ReferencePlan, RunPlan, RunSource, StiffnessRange, load, load_str,
};
pub use checks::{BadDate, normalise_date};
pub use keypath::{KeyPath, Seg};
pub use problem::{ManifestError, Problem, TablePlace};
pub use raw::{
    BoucWenParams, CampaignInfo, Channel, Channels, CompareMode, CompensatorSettings, DelayMode,
    DelaySettings, DesignSettings, FigureFormats, FrfSettings, Identification, JointRig,
    JointSettings, Manifest, ModelOrders, MonteCarloSettings, NumberedFigure, PublishedTf,
    Reference, ReportSettings, Rig, Role, Run, RunData, RunTable, SCHEMA_VERSION,
    SensitivitySettings, Specimen, SpecimenKind, TimeChannel, manifest_schema,
};
pub use simulation::{SimulationPlan, load_simulation, simulation_schema};
pub use table::RunTableInfo;

/// A manifest of either kind, checked.
#[derive(Debug, Clone)]
pub enum Loaded {
    Campaign(Box<Campaign>),
    Simulation(Box<SimulationPlan>),
}

/// Read and check a manifest of either kind: a simulation manifest has a
/// `simulation` table, anything else is read as a campaign (so a file that
/// cannot be parsed reports the campaign manifest's problems).
pub fn load_any(path: &Path) -> Result<Loaded, ManifestError> {
    let text = document::read(path)?;
    if document::has_top_level_key(&text, path, "simulation") {
        simulation::load_simulation_str(&text, path).map(|p| Loaded::Simulation(Box::new(p)))
    } else {
        campaign::load_str(&text, path).map(|c| Loaded::Campaign(Box::new(c)))
    }
}

/// A manifest checked without running it.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Checked {
    /// "campaign" or "simulation".
    pub kind: &'static str,
    pub name: String,
    pub runs: usize,
    /// Runs whose log is not there (yet): each will fail alone when run.
    pub missing_logs: Vec<(String, std::path::PathBuf)>,
    /// The manifest's warnings (a run table's logs no row uses, ...), as
    /// results.json would carry them.
    pub warnings: Vec<crate::warning::Warning>,
}

impl std::fmt::Display for Checked {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "{} `{}`, {} runs", self.kind, self.name, self.runs)
    }
}

/// Check a manifest of either kind, reporting every problem at once.
pub fn check(path: &Path) -> Result<Checked, ManifestError> {
    Ok(match load_any(path)? {
        Loaded::Campaign(c) => Checked {
            kind: "campaign",
            name: c.name.clone(),
            runs: c.runs.len(),
            missing_logs: c
                .runs
                .iter()
                .filter_map(|r| match &r.source {
                    RunSource::Log(plan) if !plan.path.exists() => {
                        Some((r.id.clone(), plan.path.clone()))
                    }
                    _ => None,
                })
                .collect(),
            warnings: c.warnings.clone(),
        },
        Loaded::Simulation(p) => Checked {
            kind: "simulation",
            name: p.manifest.simulation.name.clone(),
            runs: p.runs.len(),
            missing_logs: Vec::new(),
            warnings: Vec::new(),
        },
    })
}
