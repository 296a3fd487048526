//! The command line: what the user typed (clap), dispatched to the stages,
//! and the one place the exit code is decided: 2 for usage and manifest
//! errors, 1 when a run failed or an output could not be written, 0 otherwise.

use std::path::{Path, PathBuf};
use std::process::ExitCode;

use clap::{Parser, Subcommand};

use crate::results::{Results, Status};
use crate::{manifest, report, run, schema};

/// Identify servo-hydraulic actuators from lab logs (Maghareh, Silva & Dyke 2018).
#[derive(Debug, Parser)]
#[command(name = "servoid", version, about, long_about = None)]
pub struct Cli {
    #[command(subcommand)]
    pub command: Command,
}

#[derive(Debug, Subcommand)]
pub enum Command {
    /// Run a campaign: identify the rig, predict and validate, write results.json.
    Run {
        /// The campaign manifest (TOML, or JSON with a .json extension).
        manifest: PathBuf,
        /// Output folder (default: `reports/<campaign name>`).
        #[arg(long)]
        out: Option<PathBuf>,
        /// Worker threads (default: all cores); the output does not depend on it.
        #[arg(long, short)]
        jobs: Option<usize>,
        /// Print nothing but errors.
        #[arg(long, short)]
        quiet: bool,
    },
    /// Simulate a campaign: lab logs, truth.json and an analysis manifest.
    Simulate {
        /// The simulation manifest (TOML, or JSON with a .json extension).
        manifest: PathBuf,
        /// Output folder (default: `reports/<simulation name>`).
        #[arg(long)]
        out: Option<PathBuf>,
        /// Then run the generated campaign into the same folder.
        #[arg(long)]
        run: bool,
        /// Worker threads (default: all cores); the output does not depend on it.
        #[arg(long, short)]
        jobs: Option<usize>,
        /// Print nothing but errors.
        #[arg(long, short)]
        quiet: bool,
    },
    /// Check a manifest (campaign or simulation) and report every problem, without running it.
    Check {
        /// The manifest.
        manifest: PathBuf,
    },
    /// Write the JSON Schemas of the manifest and of results.json.
    Schema {
        /// Folder to write them into.
        #[arg(long, default_value = "schemas")]
        out_dir: PathBuf,
    },
}

/// Exit codes.
pub const EXIT_OK: u8 = 0;
pub const EXIT_FAILED: u8 = 1;
pub const EXIT_USAGE: u8 = 2;

pub fn main() -> ExitCode {
    let cli = match Cli::try_parse() {
        Ok(c) => c,
        Err(e) => {
            // --help and --version print to stdout and succeed; usage errors exit 2.
            let _ = e.print();
            return ExitCode::from(if e.use_stderr() { EXIT_USAGE } else { EXIT_OK });
        }
    };
    ExitCode::from(dispatch(cli.command))
}

fn dispatch(command: Command) -> u8 {
    match command {
        Command::Run {
            manifest,
            out,
            jobs,
            quiet,
        } => cmd_run(&manifest, out, jobs, quiet),
        Command::Simulate {
            manifest,
            out,
            run,
            jobs,
            quiet,
        } => cmd_simulate(&manifest, out, run, jobs, quiet),
        Command::Check { manifest } => {
            let checked = if is_simulation(&manifest) {
                manifest::simulation::load_simulation(&manifest).map(|p| {
                    format!(
                        "simulation `{}`, {} runs",
                        p.manifest.simulation.name,
                        p.runs.len()
                    )
                })
            } else {
                manifest::load(&manifest)
                    .map(|c| format!("campaign `{}`, {} runs", c.name, c.runs.len()))
            };
            match checked {
                Ok(what) => {
                    println!("{}: ok ({what})", manifest.display());
                    EXIT_OK
                }
                Err(e) => {
                    eprintln!("error: {e}");
                    EXIT_USAGE
                }
            }
        }
        Command::Schema { out_dir } => {
            for (name, value) in schema::all() {
                let path = out_dir.join(name);
                if let Err(e) = report::write_atomic(&path, schema::render(&value).as_bytes()) {
                    eprintln!("error: {e}");
                    return EXIT_FAILED;
                }
                println!("wrote {}", path.display());
            }
            EXIT_OK
        }
    }
}

/// Whether a manifest is a simulation manifest (it has a `simulation` table).
fn is_simulation(path: &Path) -> bool {
    let Ok(text) = std::fs::read_to_string(path) else {
        return false;
    };
    let is_json = path
        .extension()
        .is_some_and(|e| e.eq_ignore_ascii_case("json"));
    if is_json {
        serde_json::from_str::<serde_json::Value>(&text)
            .ok()
            .is_some_and(|v| v.get("simulation").is_some())
    } else {
        toml::from_str::<toml::Table>(&text)
            .ok()
            .is_some_and(|t| t.contains_key("simulation"))
    }
}

fn pool(jobs: Option<usize>) -> Result<rayon::ThreadPool, u8> {
    rayon::ThreadPoolBuilder::new()
        .num_threads(jobs.unwrap_or(0))
        .build()
        .map_err(|e| {
            eprintln!("error: cannot start worker threads: {e}");
            EXIT_FAILED
        })
}

fn cmd_simulate(
    manifest_path: &Path,
    out: Option<PathBuf>,
    then_run: bool,
    jobs: Option<usize>,
    quiet: bool,
) -> u8 {
    let plan = match manifest::simulation::load_simulation(manifest_path) {
        Ok(p) => p,
        Err(e) => {
            eprintln!("error: {e}");
            return EXIT_USAGE;
        }
    };
    let out_dir =
        out.unwrap_or_else(|| PathBuf::from("reports").join(&plan.manifest.simulation.name));
    let workers = match pool(jobs) {
        Ok(p) => p,
        Err(code) => return code,
    };
    let simulated = match workers.install(|| run::simulate::simulate_campaign(&plan, &out_dir)) {
        Ok(s) => s,
        Err(e) => {
            eprintln!("error: {e}");
            return EXIT_FAILED;
        }
    };
    if !quiet {
        println!(
            "simulated {} runs of `{}` (SYNTHETIC logs, seed {})",
            simulated.logs.len(),
            plan.manifest.simulation.name,
            plan.manifest.simulation.seed
        );
        println!("wrote {}", simulated.truth.display());
        println!("wrote {}", simulated.manifest.display());
    }
    if then_run {
        cmd_run(&simulated.manifest, Some(out_dir), jobs, quiet)
    } else {
        EXIT_OK
    }
}

fn cmd_run(manifest_path: &Path, out: Option<PathBuf>, jobs: Option<usize>, quiet: bool) -> u8 {
    let campaign = match manifest::load(manifest_path) {
        Ok(c) => c,
        Err(e) => {
            eprintln!("error: {e}");
            return EXIT_USAGE;
        }
    };
    let out_dir = out.unwrap_or_else(|| PathBuf::from("reports").join(&campaign.name));
    let workers = match pool(jobs) {
        Ok(p) => p,
        Err(code) => return code,
    };
    let (written, results) = workers.install(|| {
        let mut analysis = run::analyse_full(&campaign);
        let specs = run::figures::build(&analysis, &campaign);
        let written = report::write_figures(&specs, &out_dir).and_then(|(figures, warnings)| {
            analysis.results.warnings.extend(warnings);
            let results = &analysis.results;
            let json = report::write_results(results, &out_dir)?;
            let page = report::write_page(
                results,
                &figures,
                results.manifest.campaign.synthetic.as_deref(),
                &out_dir,
            )?;
            Ok((json, page))
        });
        (written, analysis.results)
    });
    let (path, page) = match written {
        Ok(p) => p,
        Err(e) => {
            eprintln!("error: cannot write the outputs: {e}");
            return EXIT_FAILED;
        }
    };
    if !quiet {
        print_summary(&results);
        println!("wrote {}", path.display());
        println!("wrote {}", page.display());
    }
    for r in results.runs.iter().filter(|r| r.status == Status::Failed) {
        eprintln!(
            "error: run {}: {}",
            r.id,
            r.error.as_deref().unwrap_or("failed")
        );
    }
    if run::any_failed(&results) {
        EXIT_FAILED
    } else {
        EXIT_OK
    }
}

fn print_summary(r: &Results) {
    println!("campaign {}", r.campaign.name);
    for run in &r.runs {
        let status = match run.status {
            Status::Ok => "ok",
            Status::Failed => "FAILED",
        };
        println!("  run {:<16} {:<12} {}", run.id, run.role.as_str(), status);
    }
    match &r.rig {
        Some(rig) => {
            let pm = |e: &crate::identify::Estimate| match e.std {
                Some(s) => format!("{:.5e} +/- {:.2e}", e.value, s),
                None => format!("{:.5e}", e.value),
            };
            println!("  rig ({:?}, a1b0 at P = {}):", rig.source, rig.p_gain);
            println!("    beta1 = {} 1/s", pm(&rig.beta1));
            println!("    a1b0  = {} N/(m s^2)", pm(&rig.a1b0));
            println!("    a2    = {} N/m", pm(&rig.a2));
            println!("    a3    = {} 1/s", pm(&rig.a3));
        }
        None => {
            if let Some(e) = &r.rig_error {
                println!("  rig: unavailable ({e})");
            }
        }
    }
    let flagged = r.comparisons.iter().filter(|c| c.flag).count();
    if !r.comparisons.is_empty() {
        println!(
            "  comparisons: {} with published values, {flagged} flagged",
            r.comparisons.len()
        );
    }
    for w in &r.warnings {
        println!("  warning: {w}");
    }
}
