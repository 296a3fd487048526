//! `servoid init LOGS... [--out campaign.toml]`: a campaign manifest
//! proposed from a lab's logs. Finds and inspects the logs (files,
//! folders, globs: `ingest::collect`), proposes the channels from the first
//! log's columns (`manifest::scaffold`), reads every log with them to say
//! its rate and length (or why it does not read), and writes the commented
//! manifest, refusing to overwrite one. The text is `manifest::scaffold`'s
//! and the reading `ingest`'s; this module calls them in turn and writes
//! what they give.

use std::path::{Path, PathBuf};

use crate::ingest::{self, DiscoverError, LogFormat, TableFormat};
use crate::manifest::scaffold::{
    self, FoundLog, ProposedChannels, ReadBack, Runs, folder_of, logs_spec, proposed_logs, relative,
};
use crate::report::{self, WriteError};

/// Why `servoid init` wrote nothing.
#[derive(Debug, thiserror::Error)]
pub enum InitError {
    /// The logs named cannot be found or inspected (`ingest::collect`).
    #[error(transparent)]
    Discover(#[from] DiscoverError),
    #[error("{}: already exists; give another --out, or remove it", path.display())]
    Exists { path: PathBuf },
    #[error("{} and {} are both run tables (columns id and role); give init one", first.display(), second.display())]
    TwoTables { first: PathBuf, second: PathBuf },
    #[error("{}: the logs already have this run table; --table writes a new one, for logs without", found.display())]
    TableFound { found: PathBuf },
    #[error(transparent)]
    Write(#[from] WriteError),
}

/// What `init` wrote.
#[derive(Debug)]
pub struct Initialised {
    pub manifest: PathBuf,
    pub logs: usize,
    /// The run table the manifest names: one found among the logs, or the
    /// one `--table` wrote.
    pub table: Option<PathBuf>,
    /// How many placeholders are left to fill (in the manifest and in a
    /// table `--table` wrote).
    pub placeholders: usize,
    /// What the lab should know of what `init` did: files skipped, runs
    /// renamed to keep their ids apart, logs given their own channels.
    pub warnings: Vec<String>,
}

/// Propose a manifest for `logs` and write it to `out`. Where the logs
/// hold a run table (a CSV or Parquet file with columns `id` and `role`),
/// the manifest names it as its `[run_table]`; with `table`, `init` writes
/// one there, a row per log, for the lab to fill; else each log is a
/// `[[runs]]` table.
pub fn init(logs: &[PathBuf], out: &Path, table: Option<&Path>) -> Result<Initialised, InitError> {
    for path in std::iter::once(out).chain(table) {
        if path.exists() {
            return Err(InitError::Exists {
                path: path.to_path_buf(),
            });
        }
    }
    let base = folder_of(out);
    let ingest::Found {
        logs: files,
        tables,
        skipped: mut warnings,
    } = ingest::collect(logs)?;
    let found_table = the_table(&tables, table)?;
    let (found, channels) = proposed_logs(&files, &base, &mut warnings);
    let read: Vec<ReadBack> = files
        .iter()
        .zip(&found)
        .map(|((path, i), log)| {
            read_back(
                path,
                i.format,
                log,
                log.channels.as_ref().unwrap_or(&channels),
            )
        })
        .collect();
    let own: Vec<&str> = found
        .iter()
        .filter(|l| l.channels.is_some())
        .map(|l| l.path.as_str())
        .collect();
    if !own.is_empty() {
        warnings.push(format!(
            "{} log(s) have other columns than the campaign's [channels]: {}; {}",
            own.len(),
            own.join(", "),
            match (&found_table, table) {
                (None, None) => "each run is given its own `channels`; check them",
                _ => "a run table cannot give a run its own channels: give these runs [[runs]] tables with `channels`, or export the logs with the same columns",
            }
        ));
    }
    // The folder may not exist yet (`--out new/campaign.toml`): then its
    // name as written, made absolute.
    let folder = base
        .canonicalize()
        .or_else(|_| std::path::absolute(&base))
        .ok()
        .and_then(|b| b.file_name().map(|n| n.to_string_lossy().into_owned()))
        .unwrap_or_default();
    let name = scaffold::manifest_name(&folder, "campaign");
    let paths: Vec<&Path> = files.iter().map(|(p, _)| p.as_path()).collect();
    let mut table_text = String::new();
    let runs = match (&found_table, table) {
        (Some(t), _) => {
            let mut comments = table_comments(t, &paths);
            comments.extend(scaffold::read_comments(&found, &read));
            Runs::Table {
                file: relative(t, &base),
                logs: logs_spec(&paths, &base),
                comments,
            }
        }
        (None, Some(t)) => {
            let dir = folder_of(t);
            let cells: Vec<String> = paths.iter().map(|p| relative(p, &dir)).collect();
            table_text = scaffold::run_table_text(&found, &cells);
            Runs::Table {
                file: relative(t, &base),
                logs: logs_spec(&paths, &base),
                comments: scaffold::read_comments(&found, &read),
            }
        }
        (None, None) => Runs::Blocks(&read),
    };
    let text = scaffold::manifest_text(&name, &found, &channels, &runs);
    if let Some(t) = table {
        report::write_atomic(t, table_text.as_bytes())?;
    }
    report::write_atomic(out, text.as_bytes())?;
    let quoted_fill = format!("\"{} ", scaffold::PLACEHOLDER);
    Ok(Initialised {
        manifest: out.to_path_buf(),
        logs: found.len(),
        table: found_table.or(table.map(Path::to_path_buf)),
        placeholders: text.matches(&quoted_fill).count()
            + table_text.matches(scaffold::PLACEHOLDER).count(),
        warnings,
    })
}

/// The run table the manifest names: the one found among the logs, if
/// any. Two found, or one found beside `--table` (which writes one for logs
/// without), are refused.
fn the_table(tables: &[PathBuf], table: Option<&Path>) -> Result<Option<PathBuf>, InitError> {
    let found = match tables {
        [] => None,
        [one] => Some(one.clone()),
        [first, second, ..] => {
            return Err(InitError::TwoTables {
                first: first.clone(),
                second: second.clone(),
            });
        }
    };
    if let (Some(found), Some(_)) = (&found, table) {
        return Err(InitError::TableFound {
            found: found.clone(),
        });
    }
    Ok(found)
}

/// What a run table found among the logs says about them
/// ([`scaffold::table_comments`]), or that it does not read.
fn table_comments(table: &Path, logs: &[&Path]) -> Vec<String> {
    let format = TableFormat::from_path(table).unwrap_or(TableFormat::Csv);
    match ingest::read_table(table, format) {
        Ok(t) => scaffold::table_comments(&t, logs),
        Err(e) => vec![format!("the run table does not read: {e}")],
    }
}

/// Read a log with the proposed channels: its rate and length, or why not.
fn read_back(path: &Path, format: LogFormat, log: &FoundLog, p: &ProposedChannels) -> ReadBack {
    let Some(plan) = scaffold::log_plan(path, format, log, p) else {
        return ReadBack::NotRead;
    };
    match ingest::read_log(&plan) {
        Ok(l) => ReadBack::Read {
            sample_rate_hz: l.sample_rate_hz,
            n_samples: l.n_rows,
        },
        Err(e) => ReadBack::Failed(e.to_string()),
    }
}
