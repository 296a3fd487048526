//! The orchestrator: the one module that knows every stage. It loads a
//! manifest of either kind, analyses a campaign ([`analyse`]: each run's
//! work in `step`, pure, its output written by `sink` as it arrives),
//! simulates one ([`run_simulation`], through [`simulate`]) and writes the
//! outputs (through `report`, which also decides what each figure shows). It never prints: each entry point returns what it did,
//! or a [`JobError`] that says why nothing was written, for `cli` to report.

pub mod allocator;
mod analyse;
mod cache;
pub mod design;
pub mod history;
pub mod init;
mod scratch;
mod sensitivity;
mod shard;
pub mod simulate;
mod sink;
mod step;
mod verify;

use crate::warning::Warning;
use std::path::{Path, PathBuf};

pub use crate::analysis::{FailedRun, RigError};
pub use crate::results::{Difference, LogDifference};
pub use analyse::{Event, Observer, RunError, Unobserved, analyse};
pub use shard::{MergeError, Shard, ShardInfo};
pub use verify::{FileDifference, Verification, VerifyError};

use crate::manifest::{self, Campaign, Loaded, ManifestError};
use crate::report::{self, FigureFiles, OutputFolder, WriteError};
pub use crate::report::{FigureFormats, RECORD};
use crate::results::{Results, Status};
use cache::Cache;
use simulate::{SimulateError, Simulated};
use sink::Sink;

/// How a job runs and what it writes.
#[derive(Debug, Clone, Default)]
pub struct Settings {
    /// Output folder (default: `reports/<campaign or simulation name>`).
    pub out: Option<PathBuf>,
    /// Worker threads (default: two per core); the output does not depend on it.
    pub jobs: Option<usize>,
    /// Which figures to draw, and as which files (None: as the manifest
    /// says, [`Campaign::figures`]).
    pub figures: Option<FigureFormats>,
    /// Ignore the cache of earlier runs (it is refreshed).
    pub force: bool,
    /// How long to wait for another job writing the same output folder
    /// (None: [`crate::report::output_folder::DEFAULT_WAIT`]).
    pub wait: Option<std::time::Duration>,
    /// The date of the night the job records, given to every run the
    /// manifest leaves undated (ISO 8601, normalised): the history's
    /// `date`.
    pub date: Option<String>,
}

/// How shards are merged: the job's settings (its `figures` unused), the
/// figure files to draw (None: the shards' own) and the manifest when it
/// is no longer where the shards recorded it.
#[derive(Debug, Clone, Default)]
pub struct MergeSettings {
    pub job: Settings,
    pub figures: Option<FigureFormats>,
    pub manifest: Option<PathBuf>,
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
    #[error(transparent)]
    Verify(#[from] VerifyError),
    #[error(transparent)]
    Merge(#[from] MergeError),
    #[error(transparent)]
    Design(#[from] design::DesignJobError),
    /// A share of the campaign cannot give the rig the whole campaign
    /// gives: with the validation runs in the joint fit, every shard would
    /// need every validation log.
    #[error("{}: identification.joint.include_validation fits every validation run's log into the rig, which a shard reading only its share cannot give; run the campaign without --shard, or set the key to false to share it out", file.display())]
    NotShardable { file: PathBuf },
    /// A shard's `--out` holds another shard of the same campaign, which
    /// this one would replace (the merge would then miss it).
    #[error(
        "{}: holds shard {}/{} of campaign `{campaign}`, which this run of shard {}/{} would replace, and the merge would miss it: give each shard its own --out",
        out.display(), held.index, held.count, asked.index, asked.count
    )]
    ShardFolderTaken {
        out: PathBuf,
        campaign: String,
        held: Shard,
        asked: Shard,
    },
}

impl JobError {
    /// This error as the user should read it: an output error's paths under
    /// the output folder, not under `set`'s work folder (see
    /// [`OutputFolder::relocate`]).
    pub fn relocated(self, set: &OutputFolder) -> Self {
        let f = |p: &Path| set.final_path(p);
        match self {
            JobError::Write(e) => JobError::Write(e.map_paths(&f)),
            JobError::Simulate(e) => JobError::Simulate(e.map_paths(&f)),
            e => e,
        }
    }

    /// Whether the job was asked for wrongly (a bad manifest or the wrong
    /// kind of one), as opposed to failing while it ran.
    pub fn is_usage(&self) -> bool {
        matches!(
            self,
            JobError::Manifest(_)
                | JobError::WrongKind { .. }
                | JobError::Write(WriteError::OutFolder { .. })
                | JobError::Verify(_)
                | JobError::Merge(_)
                | JobError::Design(design::DesignJobError::Flag { .. })
                | JobError::NotShardable { .. }
                | JobError::ShardFolderTaken { .. }
        )
    }
}

/// What `servoid run` produced.
#[derive(Debug, Clone)]
pub struct CampaignOutcome {
    pub results: Results,
    pub results_path: PathBuf,
    pub page_path: PathBuf,
    /// Where each run's timing went (run.jsonl).
    pub log_path: PathBuf,
    /// Wall-clock time of the analysis and its outputs (s).
    pub seconds: f64,
    /// Runs whose outcome came from the cache.
    pub cached: usize,
    /// The rig history exists and cannot be read: what is wrong and how to
    /// recover. The night's failure (exit 1): its drift alarm is off.
    pub history_error: Option<String>,
}

impl CampaignOutcome {
    /// Runs that failed.
    pub fn failed(&self) -> usize {
        self.results
            .runs
            .iter()
            .filter(|r| r.status == Status::Failed)
            .count()
    }
}

/// What `servoid simulate` produced, and the campaign run after it when one
/// was asked for.
#[derive(Debug)]
pub struct SimulationOutcome {
    pub name: String,
    pub seed: u64,
    pub simulated: Simulated,
    /// The campaign run on the logs (`--run`); a campaign that fails to
    /// write fails the whole job, which then replaces nothing.
    pub campaign: Option<CampaignOutcome>,
}

/// Run a campaign manifest: analyse, draw the figures, write results.json
/// and the page into the output folder.
pub fn run_campaign(
    path: &Path,
    settings: &Settings,
    observer: &dyn Observer,
) -> Result<CampaignOutcome, JobError> {
    let campaign = load_campaign(path, settings.date.as_deref())?;
    let out_dir = settings
        .out
        .clone()
        .unwrap_or_else(|| PathBuf::from("reports").join(&campaign.name));
    let set = begin(&out_dir, settings.wait)?;
    let workers = pool(settings.jobs)?;
    let outcome = workers
        .install(|| write_campaign(&campaign, &set, settings, observer))
        .map_err(|e| e.relocated(&set))?;
    set.commit()?;
    Ok(outcome)
}

/// Simulate a campaign from a simulation manifest (logs, truth.json and an
/// analysis manifest), then, with `then_run`, run that campaign into the
/// same folder.
pub fn run_simulation(
    path: &Path,
    settings: &Settings,
    then_run: bool,
    observer: &dyn Observer,
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
    // The logs and the campaign run on them are one set: a rerun never
    // leaves new logs beside the previous campaign's results.
    let set = begin(&out_dir, settings.wait)?;
    let workers = pool(settings.jobs)?;
    let relocate = |e: JobError| e.relocated(&set);
    let simulated = workers
        .install(|| simulate::simulate_campaign(&plan, set.dir()))
        .map_err(|e| relocate(e.into()))?;
    let campaign = if then_run {
        let campaign =
            load_campaign(&simulated.manifest, settings.date.as_deref()).map_err(relocate)?;
        Some(
            workers
                .install(|| write_campaign(&campaign, &set, settings, observer))
                .map_err(relocate)?,
        )
    } else {
        None
    };
    let simulated = Simulated {
        out_dir: set.final_path(&simulated.out_dir),
        manifest: set.final_path(&simulated.manifest),
        truth: set.final_path(&simulated.truth),
        logs: simulated.logs.iter().map(|l| set.final_path(l)).collect(),
    };
    set.commit()?;
    Ok(SimulationOutcome {
        name: plan.manifest.simulation.name.clone(),
        seed: plan.manifest.simulation.seed,
        simulated,
        campaign,
    })
}

/// What `servoid run --shard i/n` did.
#[derive(Debug, Clone)]
pub struct ShardOutcome {
    pub info: ShardInfo,
    pub out_dir: PathBuf,
    /// Runs of the share that failed, and that came from the cache.
    pub failed: usize,
    pub cached: usize,
    pub seconds: f64,
}

/// Do one share of a campaign's per-log work into its own folder (see
/// `run/shard.rs`); default folder `reports/<campaign>-shard-<i>-of-<n>`.
pub fn run_shard(
    path: &Path,
    settings: &Settings,
    shard: Shard,
    observer: &dyn Observer,
) -> Result<ShardOutcome, JobError> {
    let campaign = load_campaign(path, settings.date.as_deref())?;
    if campaign.joint.include_validation {
        return Err(JobError::NotShardable {
            file: path.to_path_buf(),
        });
    }
    let out_dir = settings.out.clone().unwrap_or_else(|| {
        PathBuf::from("reports").join(format!(
            "{}-shard-{}-of-{}",
            campaign.name, shard.index, shard.count
        ))
    });
    let set = begin(&out_dir, settings.wait)?;
    // Under the folder's lock: the set in place is the one this run would
    // replace.
    if let Some(held) = shard::held(set.resolved())
        .filter(|h| h.campaign == campaign.name && h.shard.count == shard.count)
        .filter(|h| h.shard.index != shard.index)
    {
        return Err(JobError::ShardFolderTaken {
            out: out_dir,
            campaign: held.campaign,
            held: held.shard,
            asked: shard,
        });
    }
    let share = shard.of(&campaign);
    let clock = std::time::Instant::now();
    let workers = pool(settings.jobs)?;
    let work = set.dir();
    let figures = settings.figures.unwrap_or(campaign.figures());
    let files = FigureFiles::new(work, figures);
    let cache = Cache::open(work, settings.force, cache_names(&set));
    let sink = Sink {
        out_dir: Some(work),
        files: files.as_ref(),
        choice: figures,
        intersample: share.identification.intersample,
        cache: Some(&cache),
    };
    let relocate = |e: JobError| e.relocated(&set);
    let analysed = workers
        .install(|| analyse::analyse_with(&share, &sink, observer))
        .map_err(|e| relocate(e.into()))?;
    let info = ShardInfo {
        servoid_version: env!("CARGO_PKG_VERSION").to_string(),
        campaign: campaign.name.clone(),
        manifest_sha256: campaign.manifest_sha256.clone(),
        manifest: std::path::absolute(&campaign.file).unwrap_or_else(|_| campaign.file.clone()),
        shard,
        runs: share.runs.iter().map(|r| r.id.clone()).collect(),
        figures,
        date: settings.date.clone(),
    };
    shard::write_info(work, &info).map_err(|e| relocate(e.into()))?;
    let out_dir = set.commit()?;
    Ok(ShardOutcome {
        failed: (analysed.results.runs.iter())
            .filter(|r| r.status == Status::Failed)
            .count(),
        cached: analysed.cached.iter().filter(|c| **c).count(),
        seconds: clock.elapsed().as_secs_f64(),
        info,
        out_dir,
    })
}

/// Merge the shards of one campaign into `settings.out` (default
/// `reports/<campaign>`): their runs from their caches, then the campaign's
/// results and pages as one run would write them.
pub fn merge(
    dirs: &[PathBuf],
    merge: &MergeSettings,
    observer: &dyn Observer,
) -> Result<CampaignOutcome, JobError> {
    let shards = shard::check(dirs)?;
    let first = &shards[0].1;
    // The shards' figures are in each run's cache key: another choice
    // would redo every run's log work here, silently.
    if let Some(asked) = merge.figures
        && asked != first.figures
    {
        return Err(MergeError::OtherFigures {
            shards: first.figures,
            asked,
        }
        .into());
    }
    // The shards' date is the night's: another would key every run anew.
    if let Some(asked) = &merge.job.date
        && first.date.as_ref() != Some(asked)
    {
        return Err(MergeError::OtherDate {
            shards: first.date.clone(),
            asked: asked.clone(),
        }
        .into());
    }
    let settings = &Settings {
        figures: Some(first.figures),
        date: first.date.clone(),
        ..merge.job.clone()
    };
    let manifest = merge
        .manifest
        .clone()
        .unwrap_or_else(|| first.manifest.clone());
    if let Err(source) = std::fs::metadata(&manifest)
        && merge.manifest.is_none()
    {
        return Err(MergeError::ManifestGone { manifest, source }.into());
    }
    let out_dir = settings
        .out
        .clone()
        .unwrap_or_else(|| PathBuf::from("reports").join(&first.campaign));
    let set = begin(&out_dir, settings.wait)?;
    let relocate = |e: JobError| e.relocated(&set);
    let shard_dirs: Vec<PathBuf> = shards.iter().map(|(d, _)| d.clone()).collect();
    let gathered = (|| {
        for dir in &shard_dirs {
            shard::gather(dir, set.dir())?;
        }
        cache::merge_stamps(set.dir(), &shard_dirs)
    })();
    gathered.map_err(|e| relocate(e.into()))?;
    let campaign = load_campaign(&manifest, settings.date.as_deref())?;
    if campaign.manifest_sha256 != first.manifest_sha256 {
        return Err(MergeError::ManifestChanged {
            manifest: manifest.clone(),
            recorded: first.manifest_sha256.clone(),
            now: campaign.manifest_sha256.clone(),
        }
        .into());
    }
    let workers = pool(settings.jobs)?;
    let outcome = workers
        .install(|| write_campaign(&campaign, &set, settings, observer))
        .map_err(relocate)?;
    set.commit()?;
    Ok(outcome)
}

/// A campaign manifest, refusing a simulation manifest with a hint; its
/// undated runs given the job's `date`.
fn load_campaign(path: &Path, date: Option<&str>) -> Result<Box<Campaign>, JobError> {
    match manifest::load_any(path)? {
        Loaded::Campaign(mut c) => {
            if let Some(date) = date {
                c.date_undated_runs(date);
            }
            Ok(c)
        }
        Loaded::Simulation(_) => Err(JobError::WrongKind {
            file: path.to_path_buf(),
            found: "simulation",
            hint: format!(
                "simulate it and run the campaign it writes with `servoid simulate {} --run`",
                path.display()
            ),
        }),
    }
}

/// Rerun the analysis a results.json records and list what differs (see
/// `run/verify.rs`); `manifest` overrides where results.json says it is.
pub fn verify_results(
    results: &Path,
    manifest: Option<&Path>,
    jobs: Option<usize>,
) -> Result<Verification, JobError> {
    // An output folder stands for the results.json it holds.
    let results = if results.is_dir() {
        &results.join("results.json")
    } else {
        results
    };
    pool(jobs)?.install(|| verify::verify(results, manifest))
}

fn pool(jobs: Option<usize>) -> Result<rayon::ThreadPool, JobError> {
    Ok(rayon::ThreadPoolBuilder::new()
        .num_threads(jobs.unwrap_or_else(default_jobs))
        .build()?)
}

/// Two workers per core: a run waits while polars reads and writes its
/// Parquet on polars' own pool, and a second worker keeps the core busy
/// meanwhile (on two cores, 100 Parquet logs of 120 s: 1.44 s using 1.5
/// cores with one worker per core, 1.2-1.3 s using 1.8 with two; 500 logs
/// in `cargo bench --bench night`: 6.4 s and 6.2 s). Each worker still
/// holds one log at a time.
fn default_jobs() -> usize {
    2 * cores()
}

/// The cores this process may use, as the default worker count and the
/// cap on `--jobs` count them.
pub fn cores() -> usize {
    std::thread::available_parallelism().map_or(1, |n| n.get())
}

/// Analyse a checked campaign and write its outputs: each run's figures as
/// it finishes (a figure that cannot be drawn becomes a warning in
/// results.json), then results.json, the pages and run.jsonl.
fn write_campaign(
    campaign: &Campaign,
    set: &OutputFolder,
    settings: &Settings,
    observer: &dyn Observer,
) -> Result<CampaignOutcome, JobError> {
    let started = std::time::SystemTime::now();
    let clock = std::time::Instant::now();
    let out_dir = set.dir();
    let figures = settings.figures.unwrap_or(campaign.figures());
    let files = FigureFiles::new(out_dir, figures);
    let cache = Cache::open(out_dir, settings.force, cache_names(set));
    let sink = Sink {
        out_dir: Some(out_dir),
        files: files.as_ref(),
        choice: figures,
        intersample: campaign.identification.intersample,
        cache: Some(&cache),
    };
    let mut analysed = analyse::analyse_with(campaign, &sink, observer)?;
    let results = &mut analysed.results;
    // Where the manifest is from where results.json will be, once the set
    // is in place (a simulated campaign's manifest is inside the set).
    results.campaign.manifest_path = relative_to(&set.final_path(&campaign.file), set.target());
    let (history, history_error) = match history::check(campaign, out_dir, results) {
        Ok(h) => (h, None),
        Err(u) => {
            // Named as the user knows the file, not under the work folder.
            let said = u.message(&set.final_path(&u.path));
            results.warnings.push(Warning::new(
                "the history could not be updated",
                said.clone(),
            ));
            (None, Some(said))
        }
    };
    if let (Some(h), Some(files)) = (&history, &files)
        && let Some(spec) = crate::report::figures::catalogue::history_figure(&h.rig_entries())
    {
        let (figures, warnings) = files.write(std::slice::from_ref(&spec))?;
        analysed.campaign_figures.extend(figures);
        results.warnings.extend(warnings);
    }
    let written = write_set(campaign, set, figures, &analysed, history)?;
    let seconds = clock.elapsed().as_secs_f64();
    let log = report::RunLog {
        started,
        seconds,
        jobs: rayon::current_num_threads(),
        runs: &analysed.results.runs,
        run_seconds: &analysed.seconds,
        cached: &analysed.cached,
    };
    let log_path = out_dir.join("run.jsonl");
    report::write_atomic(&log_path, &log.jsonl())?;
    // The record of the set, last: every output file by its hash, for
    // `verify` (and `sha256sum -c`). Not run.jsonl, whose wall-clock times
    // differ between two runs of the same inputs: the record is the same
    // bytes for the same inputs, as every other output is.
    report::write_record(out_dir, &written.recorded)?;
    Ok(CampaignOutcome {
        cached: analysed.cached.iter().filter(|c| **c).count(),
        results: analysed.results,
        results_path: set.final_path(&written.results),
        page_path: set.final_path(&written.page),
        log_path: set.final_path(&log_path),
        seconds,
        history_error,
    })
}

/// What `write_set` wrote: results.json, the campaign's page, and every
/// file the set's record lists.
struct Written {
    results: PathBuf,
    page: PathBuf,
    recorded: std::collections::BTreeSet<String>,
}

/// Write the analysed campaign's set: results.json, the history's new
/// entry, the pages, and the set pruned to this job's files.
fn write_set(
    campaign: &Campaign,
    set: &OutputFolder,
    figures: FigureFormats,
    analysed: &analyse::Analysed,
    history: Option<history::History>,
) -> Result<Written, JobError> {
    let out_dir = set.dir();
    let results = &analysed.results;
    let results_path = out_dir.join("results.json");
    report::settle(out_dir)?;
    let results_sha256 = report::write_json(&results_path, results)?;
    report::output_folder::fault("results");
    report::write_streamed(&out_dir.join("models.mat"), |w| {
        report::models::write_models_mat(w, results)
    })?;
    report::tables::write_tracking(&out_dir.join(report::tables::TRACKING_TABLE), &results.runs)
        .map_err(WriteError::from)?;
    if let Some(h) = history {
        h.write(results_sha256)?;
    }
    let page = report::write_pages(
        results,
        &analysed.run_figures,
        &analysed.campaign_figures,
        figures,
        out_dir,
    )?;
    let kept = report::set_files(
        results,
        &analysed.run_figures,
        &analysed.run_tables,
        &analysed.campaign_figures,
    );
    report::prune(out_dir, &kept)?;
    let mut recorded = kept;
    recorded.extend(["results.json", "models.mat", "report.html"].map(String::from));
    if let Some(h) = relative_to(&history::path(campaign, out_dir), out_dir)
        .filter(|h| !h.starts_with("..") && out_dir.join(h).is_file())
    {
        recorded.insert(h);
    }
    Ok(Written {
        results: results_path,
        page,
        recorded,
    })
}

/// Start the output set in `out_dir`, refusing, before any computing, a
/// folder whose cache place is taken by a file: the job would compute for
/// nothing and fail writing its first cache entry.
fn begin(out_dir: &Path, wait: Option<std::time::Duration>) -> Result<OutputFolder, WriteError> {
    if let Some(taken) = cache::taken_place(out_dir) {
        return Err(WriteError::OutFolder {
            path: out_dir.to_path_buf(),
            why: format!(
                "{} in the output folder (--out) is not a folder, and servoid keeps its cache there; remove it, or give another folder",
                taken.display()
            ),
        });
    }
    OutputFolder::begin(
        out_dir,
        wait.unwrap_or(crate::report::output_folder::DEFAULT_WAIT),
    )
}

/// How the cache names a log inside the work folder (a simulated
/// campaign's): by where it will be, so a rerun finds its stamp.
fn cache_names(set: &OutputFolder) -> (PathBuf, PathBuf) {
    (set.dir().to_path_buf(), set.resolved().to_path_buf())
}

/// `path` relative to the folder `dir` (`/`-separated), as `servoid verify`
/// finds the manifest from results.json; None when there is no relative
/// path (another drive).
fn relative_to(path: &Path, dir: &Path) -> Option<String> {
    let abs = |p: &Path| std::path::absolute(p).ok();
    let rel = pathdiff::diff_paths(abs(path)?, abs(dir)?)?;
    Some(
        rel.components()
            .map(|c| c.as_os_str().to_string_lossy())
            .collect::<Vec<_>>()
            .join("/"),
    )
}
