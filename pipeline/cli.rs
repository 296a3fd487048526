//! The command line: what the user typed (clap), handed to the orchestrator
//! (`run`), what it did printed, and the one place the exit code is decided:
//! 2 for usage and manifest errors, 1 when a run failed or an output could
//! not be written, 0 otherwise.

use std::path::PathBuf;
use std::process::ExitCode;

use clap::{Parser, Subcommand, ValueEnum};

use crate::identify::Estimate;
use crate::results::{Results, Status};
use crate::run::{self, CampaignOutcome, FigureFormats, JobError, Settings};

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
        /// Which figure files to draw (the page inlines PNG previews).
        #[arg(long, value_enum, default_value_t = Figures::All)]
        figures: Figures,
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
        /// With --run: which figure files to draw (the page inlines PNG previews).
        #[arg(long, value_enum, default_value_t = Figures::All, requires = "run")]
        figures: Figures,
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

/// `--figures`: which figure files a run draws.
#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum Figures {
    /// PNG and SVG files.
    All,
    /// PNG files only.
    Png,
    /// SVG files only.
    Svg,
    /// No figure at all.
    None,
}

impl From<Figures> for FigureFormats {
    fn from(f: Figures) -> Self {
        match f {
            Figures::All => FigureFormats::All,
            Figures::Png => FigureFormats::Png,
            Figures::Svg => FigureFormats::Svg,
            Figures::None => FigureFormats::None,
        }
    }
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
            figures,
            quiet,
        } => {
            let settings = Settings {
                out,
                jobs,
                figures: figures.into(),
            };
            match run::run_campaign(&manifest, &settings) {
                Ok(outcome) => report_campaign(&outcome, quiet),
                Err(e) => job_failed(&e),
            }
        }
        Command::Simulate {
            manifest,
            out,
            run,
            jobs,
            figures,
            quiet,
        } => {
            let settings = Settings {
                out,
                jobs,
                figures: figures.into(),
            };
            cmd_simulate(&manifest, &settings, run, quiet)
        }
        Command::Check { manifest } => match run::check(&manifest) {
            Ok(checked) => {
                println!("{}: ok ({checked})", manifest.display());
                EXIT_OK
            }
            Err(e) => {
                eprintln!("error: {e}");
                EXIT_USAGE
            }
        },
        Command::Schema { out_dir } => match run::write_schemas(&out_dir) {
            Ok(paths) => {
                for p in paths {
                    println!("wrote {}", p.display());
                }
                EXIT_OK
            }
            Err(e) => {
                eprintln!("error: {e}");
                EXIT_FAILED
            }
        },
    }
}

/// Report a job that wrote nothing (or could not finish writing).
fn job_failed(e: &JobError) -> u8 {
    eprintln!("error: {e}");
    if e.is_usage() {
        EXIT_USAGE
    } else {
        EXIT_FAILED
    }
}

fn cmd_simulate(
    manifest: &std::path::Path,
    settings: &Settings,
    then_run: bool,
    quiet: bool,
) -> u8 {
    let outcome = match run::run_simulation(manifest, settings, then_run) {
        Ok(o) => o,
        Err(e) => return job_failed(&e),
    };
    if !quiet {
        println!(
            "simulated {} runs of `{}` (SYNTHETIC logs, seed {})",
            outcome.simulated.logs.len(),
            outcome.name,
            outcome.seed
        );
        println!("wrote {}", outcome.simulated.truth.display());
        println!("wrote {}", outcome.simulated.manifest.display());
    }
    match &outcome.campaign {
        None => EXIT_OK,
        Some(Ok(c)) => report_campaign(c, quiet),
        Some(Err(e)) => job_failed(e),
    }
}

/// Print what a campaign run wrote and decide its exit code: 1 when any run
/// failed (its error is in results.json too).
fn report_campaign(outcome: &CampaignOutcome, quiet: bool) -> u8 {
    let results = &outcome.results;
    if !quiet {
        print_summary(results);
        println!("wrote {}", outcome.results_path.display());
        println!("wrote {}", outcome.page_path.display());
    }
    for r in results.runs.iter().filter(|r| r.status == Status::Failed) {
        eprintln!(
            "error: run {}: {}",
            r.id,
            r.error.as_deref().unwrap_or("failed")
        );
    }
    if run::any_failed(results) {
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
            let pm = |e: &Estimate| match e.std {
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
