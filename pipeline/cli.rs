//! The command line: what the user typed (clap), handed to the orchestrator
//! (`run`), what it did printed, and the one place the exit code is decided:
//! 3 when the rig drifted (an alarm), 2 for usage and manifest errors, 1
//! when a run failed or an output could not be written, 0 otherwise.
//!
//! What a run does as it goes is shown as a progress bar on a terminal, or
//! as JSON lines (`--log-format json`) for a cron job; either way a summary
//! line ends the run. Output to a closed pipe is dropped, not a panic.

use std::io::{IsTerminal, Write};
use std::path::{Path, PathBuf};
use std::process::ExitCode;

use clap::{Parser, Subcommand, ValueEnum};
use indicatif::{ProgressBar, ProgressStyle};

use crate::identify::Estimate;
use crate::results::{Results, RigSource, Status, Warning};
use crate::run::{self, CampaignOutcome, Event, FigureFormats, JobError, Observer, Settings};

/// `servoid --version`: the release and the commit it was built from
/// (`build.rs`; "+modified" when the sources differed from it, "unknown
/// commit" outside a git checkout).
const VERSION: &str = concat!(
    env!("CARGO_PKG_VERSION"),
    " (commit ",
    env!("SERVOID_COMMIT"),
    ")"
);

/// Identify servo-hydraulic actuators from lab logs (Maghareh, Silva & Dyke 2018).
#[derive(Debug, Parser)]
#[command(name = "servoid", version = VERSION, about, long_about = None)]
pub struct Cli {
    #[command(subcommand)]
    pub command: Command,
}

/// How a job is run and reported: what `run`, `simulate` and `merge`
/// share.
#[derive(Debug, clap::Args)]
pub struct JobArgs {
    /// Output folder (default: `reports/<name>`).
    #[arg(long)]
    out: Option<PathBuf>,
    /// Worker threads (default: two per core, at most four per core); the
    /// output does not depend on it.
    #[arg(long, short, value_parser = clap::value_parser!(u64).range(1..))]
    jobs: Option<u64>,
    /// `text`: a progress bar on a terminal and a summary; `json`: one JSON
    /// object per line (each run started, finished or failed, with its
    /// duration, then a summary) on stdout, for cron.
    #[arg(long, value_enum, default_value_t = ProgressFormat::Text)]
    log_format: ProgressFormat,
    /// Ignore the cache of earlier runs into the same folder: every run is
    /// done again (and the cache refreshed).
    #[arg(long)]
    force: bool,
    /// Print nothing but errors.
    #[arg(long, short)]
    quiet: bool,
    /// Print each warning's detail (the evidence, the remedy, the keys)
    /// under its headline.
    #[arg(long, short)]
    verbose: bool,
    /// Seconds to wait for another job writing the same output folder
    /// before giving up (exit 2); the message names that job. Default:
    /// 1800.
    #[arg(long, value_name = "SECONDS")]
    wait: Option<u64>,
    /// The night's date (ISO 8601, YYYY-MM-DD), given to every run the
    /// manifest and its run table leave undated: the date of the rig
    /// history's entry, which `servoid history remove --date` names. A
    /// nightly job passes the night it records, e.g. `--date "$(date
    /// +%F)"`.
    #[arg(long, value_name = "YYYY-MM-DD", value_parser = night_date)]
    date: Option<String>,
}

/// `--date`, checked against the calendar and normalised.
fn night_date(text: &str) -> Result<String, String> {
    crate::manifest::normalise_date(text).map_err(|e| e.to_string())
}

/// How a campaign is run: a job, its figures, and its share.
#[derive(Debug, clap::Args)]
pub struct RunArgs {
    #[command(flatten)]
    job: JobArgs,
    /// Which figures to draw, and as which files. Default: the manifest's
    /// `report.figures`, else `summary`, or `all` for a campaign that
    /// numbers a publication's figures.
    #[arg(long, value_enum)]
    figures: Option<FigureFormats>,
    /// Do the i-th of n shares of the per-log work (0 <= i < n) into its
    /// own folder, for `servoid merge` (e.g. one Slurm array task each).
    #[arg(long, value_name = "I/N")]
    shard: Option<run::Shard>,
}

/// What `servoid history` does.
#[derive(Debug, Subcommand)]
pub enum HistoryAction {
    /// Remove the entries of one date from a history (history.parquet in
    /// an output folder, or the manifest's history.file): each is recorded
    /// in `<file>.audit.jsonl` beside it, and the table as it was is kept
    /// in `<file>.prev`.
    Remove {
        /// The history table.
        history: PathBuf,
        /// The night's date, as the history's `date` column has it.
        #[arg(long)]
        date: String,
        /// The rig, where entries of that date are of several rigs.
        #[arg(long)]
        rig: Option<String>,
        /// Seconds to wait for a job writing the output folder the history
        /// is in. Default: 1800.
        #[arg(long, value_name = "SECONDS")]
        wait: Option<u64>,
    },
}

#[derive(Debug, Subcommand)]
pub enum Command {
    /// Run a campaign: identify the rig, predict and validate, write results.json.
    Run {
        /// The campaign manifest (TOML, or JSON with a .json extension).
        manifest: PathBuf,
        #[command(flatten)]
        args: RunArgs,
    },
    /// Simulate a campaign: lab logs, truth.json and an analysis manifest.
    Simulate {
        /// The simulation manifest (TOML, or JSON with a .json extension).
        manifest: PathBuf,
        /// Then run the generated campaign into the same folder.
        #[arg(long)]
        run: bool,
        #[command(flatten)]
        args: JobArgs,
        /// Which figures the campaign's run draws, and as which files (with
        /// --run). Default: as `servoid run` chooses for the generated
        /// manifest.
        #[arg(long, value_enum)]
        figures: Option<FigureFormats>,
    },
    /// Merge the folders of `servoid run --shard i/n` into the campaign's
    /// results and pages, as one run over all the logs writes them.
    Merge {
        /// The shard folders, one per share.
        #[arg(required = true)]
        shards: Vec<PathBuf>,
        #[command(flatten)]
        args: JobArgs,
        /// Which figure files to draw (default: the shards' own, so the
        /// merge does no per-log work; another choice is refused).
        #[arg(long, value_enum)]
        figures: Option<FigureFormats>,
        /// The campaign manifest, when it is no longer where the shards
        /// recorded it (it must be the same file, by its SHA-256).
        #[arg(long)]
        manifest: Option<PathBuf>,
    },
    /// Design tomorrow night's identification runs from a campaign's
    /// results: each run's command (odd multisines shaped for the rig,
    /// within its limits) as CSV and MAT, the next night's manifest, a
    /// simulation manifest that checks them, design.json and a page.
    Design(DesignArgs),
    /// Rerun the analysis a results.json records (its manifest and logs
    /// checked by their hashes) and list every quantity that differs.
    Verify {
        /// The results.json to verify, or the output folder that holds it.
        results: PathBuf,
        /// The manifest, when it is no longer where results.json says.
        #[arg(long)]
        manifest: Option<PathBuf>,
        /// Worker threads (default: two per core, at most four per core).
        #[arg(long, short, value_parser = clap::value_parser!(u64).range(1..))]
        jobs: Option<u64>,
    },
    /// Edit a rig history: remove a night's entry (a night run with a
    /// wrong manifest), recorded in the history's audit file.
    History {
        #[command(subcommand)]
        action: HistoryAction,
    },
    /// Propose a campaign manifest from a lab's logs: channels from the
    /// columns' names and units, roles from the files' names, and every
    /// value only the lab knows as a placeholder `servoid check` names.
    Init {
        /// Logs: files, folders of logs, or globs.
        #[arg(required = true)]
        logs: Vec<PathBuf>,
        /// Where to write the manifest (never overwritten).
        #[arg(long, default_value = "campaign.toml")]
        out: PathBuf,
        /// Also write a run table (CSV) here, a row per log for the lab to
        /// fill, which the manifest names as its `[run_table]` (a night's
        /// hundreds of logs). Logs that already have a run table (a CSV or
        /// Parquet file with columns id and role among them) get it
        /// without this.
        #[arg(long)]
        table: Option<PathBuf>,
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
    /// Print a shell's completion script for servoid (e.g. `servoid
    /// completions bash > ~/.local/share/bash-completion/completions/servoid`).
    Completions {
        /// The shell.
        #[arg(value_enum)]
        shell: clap_complete::Shell,
    },
    /// Print servoid's man page (roff), e.g. `servoid man > servoid.1;
    /// man -l servoid.1`.
    Man,
    /// Print the manifests' key reference (markdown): every key with its
    /// value, default and meaning, from the JSON Schemas (docs/keys.md).
    Keys,
}

/// `--log-format`: how a job reports its progress (not a data log's format,
/// which is `ingest::LogFormat`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum ProgressFormat {
    Text,
    Json,
}

/// Exit codes.
pub const EXIT_OK: u8 = 0;
pub const EXIT_FAILED: u8 = 1;
pub const EXIT_USAGE: u8 = 2;
/// The rig drifted: a parameter moved beyond its history's limit. Before 1:
/// the outputs are written, and a nightly job pages on it.
pub const EXIT_ALARM: u8 = 3;

pub fn main() -> ExitCode {
    crate::run::allocator::tune();
    // A panic inside a log reader (polars, hdf5-pure, matfile) on a damaged
    // log is caught and reported as the run's error; its raw panic message
    // would only confuse the log.
    let default_hook = std::panic::take_hook();
    std::panic::set_hook(Box::new(move |info| {
        if !crate::ingest::caught_reader_panic(info) {
            default_hook(info);
        }
    }));
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

/// A line on stdout; a closed pipe (`servoid run ... | head -1`) drops it
/// instead of panicking, and the exit code stays the run's own.
fn say(line: &str) {
    let mut out = std::io::stdout().lock();
    let _ = writeln!(out, "{line}");
}

/// A line on stderr, dropped when stderr is closed.
fn warn(line: &str) {
    let _ = writeln!(std::io::stderr().lock(), "{line}");
}

fn dispatch(command: Command) -> u8 {
    match command {
        Command::Run { manifest, args } => cmd_run(&manifest, &args),
        Command::Merge {
            shards,
            args,
            figures,
            manifest,
        } => cmd_merge(&shards, &args, figures, manifest),
        Command::Simulate {
            manifest,
            run,
            args,
            figures,
        } => cmd_simulate(&manifest, run, &args, figures),
        Command::Verify {
            results,
            manifest,
            jobs,
        } => cmd_verify(&results, manifest.as_deref(), capped(jobs)),
        Command::Check { manifest } => cmd_check(&manifest),
        Command::Design(args) => cmd_design(&args),
        Command::Init { logs, out, table } => cmd_init(&logs, &out, table.as_deref()),
        Command::History {
            action:
                HistoryAction::Remove {
                    history,
                    date,
                    rig,
                    wait,
                },
        } => cmd_history_remove(&history, &date, rig.as_deref(), wait),
        Command::Completions { shell } => cmd_completions(shell),
        Command::Keys => print_bytes(
            crate::manifest::keys::key_reference().as_bytes(),
            "the key reference",
        ),
        Command::Man => cmd_man(),
        Command::Schema { out_dir } => cmd_schema(&out_dir),
    }
}

/// `servoid design`'s arguments: the limits and times absent are taken
/// from the results (or not applied: stroke, velocity, force).
#[derive(Debug, clap::Args)]
pub struct DesignArgs {
    /// The results.json of the campaign to design from, the output folder
    /// that holds it, or a campaign manifest (.toml) whose
    /// [rig.parameters] give the rig's nominal values.
    from: PathBuf,
    /// The output folder (default: `reports/<campaign>-design`).
    #[arg(long, short)]
    out: Option<PathBuf>,
    /// The command's largest magnitude (mm); default: the largest command
    /// of last night's identification logs.
    #[arg(long)]
    command_mm: Option<f64>,
    /// The actuator's stroke (mm): the predicted displacement stays within
    /// +-this.
    #[arg(long)]
    stroke_mm: Option<f64>,
    /// The peak velocity (mm/s), the valve's rated flow over the piston
    /// area.
    #[arg(long)]
    velocity_mm_s: Option<f64>,
    /// The peak force on the specimen (N).
    #[arg(long)]
    force_n: Option<f64>,
    /// The band of interest, LO,HI (Hz); default: the campaign's
    /// identification band.
    #[arg(long, value_delimiter = ',', num_args = 1)]
    band_hz: Option<Vec<f64>>,
    /// The DAQ's rate (Hz); default: last night's logs'.
    #[arg(long)]
    rate_hz: Option<f64>,
    /// The displacement's noise (mm RMS at the rate), taken as white;
    /// default: the noise last night's logs measured.
    #[arg(long)]
    noise_mm: Option<f64>,
    /// The time per run, rest included (s); default: the longest of last
    /// night's identification logs.
    #[arg(long)]
    run_s: Option<f64>,
    /// The time for the night's identification runs together (s), shared
    /// equally.
    #[arg(long)]
    night_s: Option<f64>,
    /// Rest before and after each command (s).
    #[arg(long, default_value_t = 1.0)]
    rest_s: f64,
    /// The worst relative std to reach (0.001 for 0.1 %): the runs are
    /// then as long as it needs, or the design names the limit that stops
    /// it.
    #[arg(long)]
    target_std: Option<f64>,
    /// The seed of the lines left empty for detection.
    #[arg(long, default_value_t = 1)]
    seed: u64,
}

/// `servoid design`: tomorrow night's runs, written; says where and what
/// they are predicted to determine.
fn cmd_design(args: &DesignArgs) -> u8 {
    let band_hz = match args.band_hz.as_deref() {
        None => None,
        Some(&[lo, hi]) => Some([lo, hi]),
        Some(other) => {
            warn(&format!(
                "error: --band-hz takes two frequencies, LO,HI (got {other:?})"
            ));
            return EXIT_USAGE;
        }
    };
    let ask = run::design::DesignAsk {
        out: args.out.clone(),
        limits: crate::manifest::DesignSettings {
            command_m: args.command_mm.map(|v| v * 1e-3),
            stroke_m: args.stroke_mm.map(|v| v * 1e-3),
            velocity_m_per_s: args.velocity_mm_s.map(|v| v * 1e-3),
            force_n: args.force_n,
            band_hz,
            run_s: args.run_s,
            night_s: args.night_s,
            target_relative_std: args.target_std,
            sample_rate_hz: args.rate_hz,
            displacement_noise_m: args.noise_mm.map(|v| v * 1e-3),
        },
        rest_s: args.rest_s,
        seed: args.seed,
        wait: None,
    };
    match run::design::design_night(&args.from, &ask) {
        Ok(d) => {
            let r = &d.result;
            say(&format!(
                "designed {} runs of {:.1} s: odd multisines of {} s x {} periods, {} lines over {}-{} Hz, crest factors {}",
                r.runs.len(),
                r.record_s,
                r.period_s,
                r.periods,
                r.lines_excited,
                r.band_hz[0],
                r.band_hz[1],
                r.runs
                    .iter()
                    .map(|x| format!("{:.2}", x.crest_factor))
                    .collect::<Vec<_>>()
                    .join(", ")
            ));
            for p in &r.parameters {
                say(&format!(
                    "  {}: predicted std {:.3e} ({:.3} %)",
                    p.name,
                    p.std,
                    100.0 * p.relative_std
                ));
            }
            if let Some(b) = &r.baseline {
                say(&format!(
                    "  against the paper's chirps at the same record and peak: worst std {:.2} times smaller, sum of squared relative stds {:.2} times",
                    b.worst_ratio, b.squares_ratio
                ));
            }
            say(&format!(
                "wrote {} (design.html first)",
                d.out_dir.display()
            ));
            EXIT_OK
        }
        Err(e) => job_failed(&e, false),
    }
}

/// `servoid run`: the whole campaign, or one shard of it.
fn cmd_run(manifest: &Path, args: &RunArgs) -> u8 {
    let watch = Watch::new(&args.job);
    let settings = settings(&args.job, args.figures);
    let code = match args.shard {
        Some(shard) => match run::run_shard(manifest, &settings, shard, &watch) {
            Ok(outcome) => watch.shard(&outcome),
            Err(e) => job_failed(&e, watch.json),
        },
        None => match run::run_campaign(manifest, &settings, &watch) {
            Ok(outcome) => watch.campaign(&outcome),
            Err(e) => job_failed(&e, watch.json),
        },
    };
    watch.done();
    code
}

/// `servoid merge`: the shards' folders into the campaign's results.
fn cmd_merge(
    shards: &[PathBuf],
    args: &JobArgs,
    figures: Option<FigureFormats>,
    manifest: Option<PathBuf>,
) -> u8 {
    let watch = Watch::new(args);
    let merge = run::MergeSettings {
        job: settings(args, None),
        figures,
        manifest,
    };
    let code = match run::merge(shards, &merge, &watch) {
        Ok(outcome) => watch.campaign(&outcome),
        Err(e) => job_failed(&e, watch.json),
    };
    watch.done();
    code
}

/// `servoid check`: the manifest's problems, or ok with its warnings.
fn cmd_check(manifest: &Path) -> u8 {
    match crate::manifest::check(manifest) {
        Ok(checked) => {
            say(&format!("{}: ok ({checked})", manifest.display()));
            for (run, log) in &checked.missing_logs {
                warn(&format!(
                    "warning: run {run}: log file not found: {}{}; the run will fail alone when the campaign runs",
                    log.display(),
                    crate::ingest::backslash_hint(log)
                ));
            }
            for w in &checked.warnings {
                warn(&format!("warning: {w:#}"));
            }
            EXIT_OK
        }
        Err(e) => {
            warn(&format!("error: {e}"));
            EXIT_USAGE
        }
    }
}

/// `servoid history remove`: a night's entries out of a history, recorded.
fn cmd_history_remove(history: &Path, date: &str, rig: Option<&str>, wait: Option<u64>) -> u8 {
    let wait = wait.map_or(
        crate::report::output_folder::DEFAULT_WAIT,
        std::time::Duration::from_secs,
    );
    match run::history::remove(history, date, rig, wait) {
        Ok(done) => {
            for e in &done.entries {
                say(&format!(
                    "removed the entry of rig `{}`, campaign `{}`, date {date} (inputs {}) from {}",
                    e.rig,
                    e.campaign,
                    &e.inputs_sha256[..e.inputs_sha256.len().min(12)],
                    history.display()
                ));
            }
            say(&format!("recorded in {}", done.audit.display()));
            EXIT_OK
        }
        Err(e) => {
            warn(&format!("error: {e}"));
            EXIT_USAGE
        }
    }
}

/// `servoid init`: a manifest proposed from the logs.
fn cmd_init(logs: &[PathBuf], out: &Path, table: Option<&Path>) -> u8 {
    match run::init::init(logs, out, table) {
        Ok(done) => {
            for w in &done.warnings {
                warn(&format!("warning: {w}"));
            }
            let table = done
                .table
                .map(|t| format!(" (runs from the table {})", t.display()))
                .unwrap_or_default();
            say(&format!(
                "wrote {} for {} log(s){table}: {} placeholder(s) to fill; `servoid check {}` names them",
                done.manifest.display(),
                done.logs,
                done.placeholders,
                done.manifest.display()
            ));
            EXIT_OK
        }
        Err(e) => {
            warn(&format!("error: {e}"));
            EXIT_USAGE
        }
    }
}

/// `servoid completions`: the shell's completion script.
fn cmd_completions(shell: clap_complete::Shell) -> u8 {
    let mut cmd = <Cli as clap::CommandFactory>::command();
    let mut script = Vec::new();
    clap_complete::generate(shell, &mut cmd, "servoid", &mut script);
    print_bytes(&script, "the completion script")
}

/// `servoid man`: the man page.
fn cmd_man() -> u8 {
    let cmd = <Cli as clap::CommandFactory>::command();
    let mut page = Vec::new();
    match clap_mangen::Man::new(cmd).render(&mut page) {
        Ok(()) => print_bytes(&page, "the man page"),
        Err(e) => {
            warn(&format!("error: the man page could not be made: {e}"));
            EXIT_FAILED
        }
    }
}

/// `servoid schema`: the JSON Schemas, written into `out_dir`.
fn cmd_schema(out_dir: &Path) -> u8 {
    match crate::report::write_schemas(out_dir) {
        Ok(paths) => {
            for p in paths {
                say(&format!("wrote {}", p.display()));
            }
            EXIT_OK
        }
        Err(e) => {
            warn(&format!("error: {e}"));
            EXIT_FAILED
        }
    }
}

/// Write `bytes` (`what`) to stdout. A reader that stops early (`| head`)
/// is not an error: the rest is not wanted.
fn print_bytes(bytes: &[u8], what: &str) -> u8 {
    use std::io::Write;
    let mut out = std::io::stdout().lock();
    match out.write_all(bytes).and_then(|()| out.flush()) {
        Ok(()) => EXIT_OK,
        Err(e) if e.kind() == std::io::ErrorKind::BrokenPipe => EXIT_OK,
        Err(e) => {
            warn(&format!("error: {what} could not be written: {e}"));
            EXIT_FAILED
        }
    }
}

/// Exit 0 when every recomputed quantity equals the recorded one, 1
/// otherwise, each difference on its own line.
fn cmd_verify(results: &Path, manifest: Option<&Path>, jobs: Option<usize>) -> u8 {
    let v = match run::verify_results(results, manifest, jobs) {
        Ok(v) => v,
        Err(e) => return job_failed(&e, false),
    };
    // The logs first: every other difference may follow from them.
    for d in &v.log_differences {
        say(&format!(
            "log differs: run {}: {}: recorded sha256 {}, {}",
            d.run,
            d.file,
            d.recorded,
            d.now
                .as_ref()
                .map_or("cannot be read now".to_string(), |n| format!("now {n}"))
        ));
    }
    for d in &v.file_differences {
        match &d.now {
            Some(now) => say(&format!(
                "file differs: {}: recorded sha256 {}, now {now}",
                d.file, d.recorded
            )),
            None => say(&format!("file missing: {}", d.file)),
        }
    }
    for d in &v.differences {
        say(&format!(
            "differs: {}: recorded {}, recomputed {}",
            d.key, d.recorded, d.recomputed
        ));
    }
    let files = match v.files {
        Some(n) => format!("{n} output files by the set's record"),
        None => format!(
            "no record of the output files ({}): results.json alone",
            run::RECORD
        ),
    };
    let what = format!(
        "{}: rerun from {} ({} logs checked by their hashes, {files})",
        results.display(),
        v.manifest.display(),
        v.logs,
    );
    if v.matches() {
        say(&format!("{what}: everything matches"));
        EXIT_OK
    } else {
        say(&format!(
            "{what}: {} logs, {} files and {} quantities differ",
            v.log_differences.len(),
            v.file_differences.len(),
            v.differences.len()
        ));
        EXIT_FAILED
    }
}

fn settings(args: &JobArgs, figures: Option<FigureFormats>) -> Settings {
    Settings {
        out: args.out.clone(),
        jobs: capped(args.jobs),
        figures,
        force: args.force,
        wait: args.wait.map(std::time::Duration::from_secs),
        date: args.date.clone(),
    }
}

/// Workers beyond four per core only cost memory and switching (`--jobs
/// 1000` ran six times slower than the default on two cores, and `--jobs
/// 100000` stalled the machine starting threads): a larger `--jobs` is
/// lowered to that, with a warning.
pub const MAX_JOBS_PER_CORE: usize = 4;

fn capped(jobs: Option<u64>) -> Option<usize> {
    let cores = run::cores();
    let max = MAX_JOBS_PER_CORE * cores;
    let jobs = jobs?;
    if jobs > max as u64 {
        warn(&format!(
            "warning: --jobs {jobs} is more than {MAX_JOBS_PER_CORE} per core ({cores} cores): using {max}"
        ));
        return Some(max);
    }
    Some(jobs as usize)
}

/// Report a job that wrote nothing (or could not finish writing): on
/// stderr, and with `--log-format json` as an `error` event on stdout too,
/// so a nightly job's log parser sees why the night wrote nothing.
fn job_failed(e: &JobError, json: bool) -> u8 {
    let text = e.to_string();
    warn(&format!("error: {text}"));
    let code = if e.is_usage() {
        EXIT_USAGE
    } else {
        EXIT_FAILED
    };
    if json {
        say(&serde_json::json!({"event": "error", "error": text, "exit": code}).to_string());
    }
    code
}

fn cmd_simulate(
    manifest: &Path,
    then_run: bool,
    args: &JobArgs,
    figures: Option<FigureFormats>,
) -> u8 {
    if figures.is_some() && !then_run {
        warn("error: --figures draws a campaign's figures; it needs --run");
        return EXIT_USAGE;
    }
    let watch = Watch::new(args);
    let outcome = match run::run_simulation(manifest, &settings(args, figures), then_run, &watch) {
        Ok(o) => o,
        Err(e) => return job_failed(&e, watch.json),
    };
    if watch.text() {
        say(&format!(
            "simulated {} runs of `{}` (SYNTHETIC logs, seed {})",
            outcome.simulated.logs.len(),
            outcome.name,
            outcome.seed
        ));
        say(&format!("wrote {}", outcome.simulated.truth.display()));
        say(&format!("wrote {}", outcome.simulated.manifest.display()));
    }
    let code = match &outcome.campaign {
        None => EXIT_OK,
        Some(c) => watch.campaign(c),
    };
    watch.done();
    code
}

/// What the user sees of a run as it goes: a progress bar on a terminal (a
/// text log whose stdout is a terminal), JSON lines, or nothing.
struct Watch {
    json: bool,
    quiet: bool,
    verbose: bool,
    bar: Option<ProgressBar>,
}

impl Watch {
    fn new(args: &JobArgs) -> Self {
        let json = args.log_format == ProgressFormat::Json;
        let bar = (!json && !args.quiet && std::io::stdout().is_terminal()).then(|| {
            let bar = ProgressBar::new(0);
            bar.set_style(
                ProgressStyle::with_template("{bar:40} {pos}/{len} runs, {elapsed} ({per_sec})")
                    .expect("the progress template is valid"),
            );
            bar
        });
        Self {
            json,
            quiet: args.quiet,
            verbose: args.verbose,
            bar,
        }
    }

    /// Whether text output is wanted.
    fn text(&self) -> bool {
        !self.json && !self.quiet
    }

    fn done(&self) {
        if let Some(bar) = &self.bar {
            bar.finish_and_clear();
        }
    }

    /// Print what a campaign run wrote, with its summary line, and decide
    /// its exit code: 1 when any run failed (its error is in results.json
    /// too) or the rig history cannot be read.
    fn campaign(&self, outcome: &CampaignOutcome) -> u8 {
        self.done();
        let results = &outcome.results;
        let n = results.runs.len();
        let failed = outcome.failed();
        let per_s = n as f64 / outcome.seconds.max(1e-9);
        // Springs that disagree are a warning to act on before the rig is
        // trusted, even with every run ok: said on stderr, as alarms are.
        let inconsistent = results
            .rig
            .as_ref()
            .and_then(|r| r.consistency.as_ref())
            .filter(|c| c.consistent == Some(false))
            .map(|c| {
                format!(
                    "rig: {}; likely causes: {}",
                    c.note,
                    c.likely_causes.join("; ")
                )
            });
        let alarms = results.drift.as_ref().map_or(&[][..], |d| &d.alarms[..]);
        if self.json {
            // Every warning the text summary prints, as an event, then the
            // errors and alarms, then the summary: the last line.
            for run in &results.runs {
                for w in &run.warnings {
                    say(
                        &serde_json::json!({"event": "warning", "run": run.id, "warning": w})
                            .to_string(),
                    );
                }
            }
            // The springs' disagreement is among them (stderr says it
            // again, as it does alarms).
            for w in &results.warnings {
                say(&serde_json::json!({"event": "warning", "warning": w}).to_string());
            }
            if let Some(h) = &outcome.history_error {
                say(&serde_json::json!({"event": "history_unreadable", "error": h}).to_string());
            }
            for a in alarms {
                say(&serde_json::json!({"event": "alarm", "alarm": a}).to_string());
            }
            say(&serde_json::json!({
                "event": "summary",
                "campaign": results.campaign.name,
                "ok": n - failed,
                "failed": failed,
                "cached": outcome.cached,
                "warnings": results.warnings.len()
                    + results.runs.iter().map(|r| r.warnings.len()).sum::<usize>(),
                "alarms": alarms.len(),
                "seconds": outcome.seconds,
                "logs_per_s": per_s,
                "results": outcome.results_path,
            })
            .to_string());
        } else if !self.quiet {
            print_summary(results, self.verbose);
            say(&format!("wrote {}", outcome.results_path.display()));
            say(&format!("wrote {}", outcome.page_path.display()));
            say(&format!(
                "summary: {} ok, {failed} failed, {} cached in {:.2} s ({per_s:.1} logs/s)",
                n - failed,
                outcome.cached,
                outcome.seconds
            ));
        }
        for r in results.runs.iter().filter(|r| r.status == Status::Failed) {
            warn(&format!(
                "error: run {}: {}",
                r.id,
                r.error.as_deref().unwrap_or("failed")
            ));
        }
        if let Some(w) = &inconsistent {
            warn(&format!("warning: {w}"));
        }
        if let Some(h) = &outcome.history_error {
            warn(&format!("error: {h}"));
        }
        for a in alarms {
            warn(&format!("ALARM: {a}"));
        }
        if !alarms.is_empty() {
            EXIT_ALARM
        } else if failed > 0 || outcome.history_error.is_some() {
            EXIT_FAILED
        } else {
            EXIT_OK
        }
    }
}

impl Watch {
    /// Print what a shard did; exit 1 when a run of its share failed.
    fn shard(&self, outcome: &run::ShardOutcome) -> u8 {
        self.done();
        let info = &outcome.info;
        let n = info.runs.len();
        if self.json {
            say(&serde_json::json!({
                "event": "summary",
                "campaign": info.campaign,
                "shard": format!("{}/{}", info.shard.index, info.shard.count),
                "ok": n - outcome.failed,
                "failed": outcome.failed,
                "cached": outcome.cached,
                "seconds": outcome.seconds,
                "logs_per_s": n as f64 / outcome.seconds.max(1e-9),
            })
            .to_string());
        } else if !self.quiet {
            say(&format!(
                "shard {}/{} of `{}`: {} runs into {} ({} failed, {} cached in {:.2} s); merge the shards with `servoid merge`",
                info.shard.index,
                info.shard.count,
                info.campaign,
                n,
                outcome.out_dir.display(),
                outcome.failed,
                outcome.cached,
                outcome.seconds
            ));
        }
        if outcome.failed > 0 {
            EXIT_FAILED
        } else {
            EXIT_OK
        }
    }
}

impl Observer for Watch {
    fn event(&self, event: &Event<'_>) {
        match *event {
            Event::Started { runs } => {
                if let Some(bar) = &self.bar {
                    bar.set_length(runs as u64);
                }
            }
            Event::RunStarted { id } => {
                if self.json {
                    say(&serde_json::json!({"event": "run_started", "run": id}).to_string());
                }
            }
            Event::RunFinished {
                id,
                status,
                error,
                seconds,
            } => {
                if let Some(bar) = &self.bar {
                    bar.inc(1);
                }
                if self.json {
                    let line = match status {
                        Status::Ok => {
                            serde_json::json!({"event": "run_finished", "run": id, "seconds": seconds})
                        }
                        Status::Failed => serde_json::json!({
                            "event": "run_failed",
                            "run": id,
                            "seconds": seconds,
                            "error": error.unwrap_or("failed"),
                        }),
                    };
                    say(&line.to_string());
                }
            }
            Event::RunCached { id, seconds } => {
                if let Some(bar) = &self.bar {
                    bar.inc(1);
                }
                if self.json {
                    say(
                        &serde_json::json!({"event": "run_cached", "run": id, "seconds": seconds})
                            .to_string(),
                    );
                }
            }
        }
    }
}

fn print_summary(r: &Results, verbose: bool) {
    let shown = |w: &Warning| {
        if verbose {
            format!("{w:#}")
        } else {
            w.to_string()
        }
    };
    say(&format!("campaign {}", r.campaign.name));
    for run in &r.runs {
        let status = match (
            run.status,
            run.validation.as_ref().is_some_and(|v| v.outlier),
        ) {
            (Status::Failed, _) => "FAILED",
            (Status::Ok, true) => "ok (OUTLIER)",
            (Status::Ok, false) => "ok",
        };
        say(&format!(
            "  run {:<16} {:<12} {}",
            run.id,
            run.role.as_str(),
            status
        ));
        // Why a run is an outlier, under its line: "OUTLIER" alone does
        // not say what to look at.
        if let Some(frf) = &run.frf {
            say(&format!("      FRF: {}", frf.reason));
        }
        if let Some(note) = run
            .validation
            .as_ref()
            .filter(|v| v.outlier)
            .and_then(|v| v.note.as_ref())
        {
            say(&format!("      outlier: {note}"));
        }
        for w in &run.warnings {
            say(&format!("      warning: {}", shown(w)));
        }
    }
    match &r.rig {
        Some(rig) => {
            let pm = |e: &Estimate| match e.std {
                Some(s) => format!("{:.5e} +/- {:.2e}", e.value, s),
                None => format!("{:.5e}", e.value),
            };
            let source = match (rig.source, &rig.joint) {
                (RigSource::Joint, Some(j)) => format!(
                    "joint grey-box fit, structure {}",
                    j.structure.map_or("none", |s| s.as_str())
                ),
                (RigSource::Joint, None) => "joint grey-box fit".into(),
                (RigSource::Identified, _) => "sequential, Eqs. 18-20".into(),
                (RigSource::Given, _) => "given".into(),
            };
            say(&format!("  rig ({source}; a1b0 at P = {}):", rig.p_gain));
            // The sequential estimate beside the joint one when that is used.
            let seq = rig
                .sequential
                .as_ref()
                .filter(|_| rig.source == RigSource::Joint);
            let line = |name: &str, e: &Estimate, s: Option<&Estimate>, unit: &str| {
                let side = s.map_or(String::new(), |s| format!("   (sequential {})", pm(s)));
                format!("    {name} = {} {unit}{side}", pm(e))
            };
            say(&line("beta1", &rig.beta1, seq.map(|s| &s.beta1), "1/s"));
            say(&line("a1b0 ", &rig.a1b0, seq.map(|s| &s.a1b0), "N/(m s^2)"));
            say(&line("a2   ", &rig.a2, seq.map(|s| &s.a2), "N/m"));
            say(&line("a3   ", &rig.a3, seq.map(|s| &s.a3), "1/s"));
        }
        None => {
            if let Some(e) = &r.rig_error {
                say(&format!("  rig: unavailable ({e})"));
            }
        }
    }
    let flagged = r.comparisons.iter().filter(|c| c.flag).count();
    // A comparison the campaign could not compute is neither agreeing nor
    // flagged: "0 flagged" alone read as all agreeing when every run failed.
    let not_computed = r
        .comparisons
        .iter()
        .filter(|c| c.status == crate::results::ComparisonStatus::NotComputed)
        .count();
    if !r.comparisons.is_empty() {
        let missing = if not_computed > 0 {
            format!(", {not_computed} not computed")
        } else {
            String::new()
        };
        say(&format!(
            "  comparisons: {} with published values, {flagged} flagged{missing}",
            r.comparisons.len()
        ));
    }
    for w in &r.warnings {
        say(&format!("  warning: {}", shown(w)));
    }
}
