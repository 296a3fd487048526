//! `servoid simulate`: from a checked simulation manifest to lab logs, a truth
//! file and an analysis manifest ready for `servoid run` (a closed loop).
//! Everything is computed first and written only when every run succeeded,
//! each file atomically, so a failure leaves no half-written campaign.

use std::path::{Path, PathBuf};

use rayon::prelude::*;

use crate::analysis::simulated::{self, RunSignals, SimRunError};
use crate::ingest::command::{CommandFileError, read_command};
use crate::ingest::{DEFAULT_MAX_LOG_MIB, sha256_hex};
use crate::manifest::simulation::{Command, SimulationPlan};
use crate::report::columns::{self, ColumnWriteError};
use crate::report::{self, WriteError};

/// Why a simulation failed.
#[derive(Debug, thiserror::Error)]
pub enum SimulateError {
    #[error(transparent)]
    Run(#[from] SimRunError),
    #[error("run {run}: its command file: {source}")]
    Command {
        run: String,
        #[source]
        source: Box<CommandFileError>,
    },
    #[error(transparent)]
    Log(#[from] ColumnWriteError),
    #[error(transparent)]
    Write(#[from] WriteError),
}

impl SimulateError {
    /// This error with every path an output error names passed through `f`.
    pub fn map_paths(self, f: &dyn Fn(&Path) -> PathBuf) -> Self {
        match self {
            SimulateError::Log(e) => SimulateError::Log(e.map_paths(f)),
            SimulateError::Write(e) => SimulateError::Write(e.map_paths(f)),
            e => e,
        }
    }
}

/// What `servoid simulate` wrote.
#[derive(Debug, Clone)]
pub struct Simulated {
    pub out_dir: PathBuf,
    pub manifest: PathBuf,
    pub truth: PathBuf,
    pub logs: Vec<PathBuf>,
}

/// The campaign a simulation manifest's `text` describes, simulated into
/// `dir` and loaded: the unit tests' campaigns from their fixtures.
#[cfg(test)]
pub(crate) fn simulated(text: &str, dir: &Path) -> crate::manifest::Campaign {
    let sim = crate::manifest::simulation::load_simulation_str(text, &dir.join("sim.toml"))
        .expect("a simulation");
    let out = simulate_campaign(&sim, dir).expect("simulates");
    crate::manifest::load(&out.manifest).expect("the manifest loads")
}

/// Simulate every run and write the campaign into `out_dir`.
pub fn simulate_campaign(
    plan: &SimulationPlan,
    out_dir: &Path,
) -> Result<Simulated, SimulateError> {
    let m = &plan.manifest;
    let ext = m.simulation.log_format.extension();
    // A log's path relative to the output folder, as truth.json names it.
    let log_rel = |s: &RunSignals| format!("logs/{}.{ext}", s.truth.id);
    // Each run is simulated, and its log's bytes made (the shortest
    // round-trip text of every sample is most of a CSV log's cost) and
    // hashed, side by side; the files are written after, in the manifest's
    // order, so a run that cannot be simulated leaves no log behind.
    let logs: Vec<(RunSignals, Vec<u8>, String)> = plan
        .runs
        .par_iter()
        .with_max_len(1)
        .map(|run| {
            let played = match &run.excitation {
                Command::File(path) => Some(
                    read_command(path, DEFAULT_MAX_LOG_MIB << 20).map_err(|source| {
                        SimulateError::Command {
                            run: run.id.clone(),
                            source: Box::new(source),
                        }
                    })?,
                ),
                Command::Generated(_) => None,
            };
            let s = simulated::simulate_run(plan, run, played.as_ref())?;
            let path = out_dir.join(log_rel(&s));
            let bytes = columns::log_bytes(
                m.simulation.log_format,
                &path,
                &s,
                1.0 / m.simulation.sample_rate_hz,
            )?;
            let sha256 = sha256_hex(&bytes);
            Ok((s, bytes, sha256))
        })
        .collect::<Vec<Result<_, SimulateError>>>()
        .into_iter()
        // The first failure in the manifest's order, whichever thread
        // met it first.
        .collect::<Result<_, _>>()?;

    let mut log_paths = Vec::new();
    let mut truth_runs = Vec::new();
    for (s, bytes, sha256) in logs {
        let rel = log_rel(&s);
        let path = out_dir.join(&rel);
        report::write_artifact(&path, &bytes)?;
        let mut t = s.truth;
        t.log = rel;
        t.log_sha256 = sha256;
        truth_runs.push(t);
        log_paths.push(path);
    }

    let truth = simulated::truth(plan, truth_runs);
    let truth_path = out_dir.join("truth.json");
    report::settle(out_dir)?;
    report::write_atomic(&truth_path, &report::json_bytes(&truth))?;

    let text = simulated::manifest_text(plan, &truth);
    let manifest_path = out_dir.join("campaign.toml");
    report::write_atomic(&manifest_path, text.as_bytes())?;
    Ok(Simulated {
        out_dir: out_dir.to_path_buf(),
        manifest: manifest_path,
        truth: truth_path,
        logs: log_paths,
    })
}
