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
    /// Check a manifest and report every problem, without running it.
    Check {
        /// The campaign manifest.
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
        Command::Check { manifest } => match manifest::load(&manifest) {
            Ok(c) => {
                println!(
                    "{}: ok (campaign `{}`, {} runs)",
                    manifest.display(),
                    c.name,
                    c.runs.len()
                );
                EXIT_OK
            }
            Err(e) => {
                eprintln!("error: {e}");
                EXIT_USAGE
            }
        },
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

fn cmd_run(manifest_path: &Path, out: Option<PathBuf>, jobs: Option<usize>, quiet: bool) -> u8 {
    let campaign = match manifest::load(manifest_path) {
        Ok(c) => c,
        Err(e) => {
            eprintln!("error: {e}");
            return EXIT_USAGE;
        }
    };
    let out_dir = out.unwrap_or_else(|| PathBuf::from("reports").join(&campaign.name));
    let pool = match rayon::ThreadPoolBuilder::new()
        .num_threads(jobs.unwrap_or(0))
        .build()
    {
        Ok(p) => p,
        Err(e) => {
            eprintln!("error: cannot start worker threads: {e}");
            return EXIT_FAILED;
        }
    };
    let results = pool.install(|| run::analyse(&campaign));
    let written = report::write_results(&results, &out_dir).and_then(|r| {
        Ok((
            r,
            report::write_page(
                &results,
                &[],
                results.manifest.campaign.synthetic.as_deref(),
                &out_dir,
            )?,
        ))
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
