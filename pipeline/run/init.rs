//! `servoid init LOGS... [--out campaign.toml]`: a campaign manifest
//! proposed from a lab's logs. Finds the logs (files, folders, globs),
//! inspects each (`ingest::inspect`), proposes the channels from the first
//! log's columns (`manifest::scaffold`), reads every log with them to say
//! its rate and length (or why it does not read), and writes the commented
//! manifest, refusing to overwrite one.

use std::collections::BTreeSet;
use std::path::{Path, PathBuf};

use crate::ingest::{
    self, ChannelPlan, Channels, Column, CsvOptions, Inspected, LogFormat, LogPlan, Repair,
    TableFormat, TimePlan,
};
use crate::manifest::scaffold::{self, FoundLog, ProposedChannels, ReadBack, Runs};
use crate::report::{self, WriteError};
use crate::units::{TimeUnit, Unit};

/// Why `servoid init` wrote nothing.
#[derive(Debug, thiserror::Error)]
pub enum InitError {
    #[error("{}: no log there (a file, a folder of logs, or a glob matching them)", path.display())]
    NoLogs { path: PathBuf },
    #[error("{}: not a log servoid reads by its extension ({})", path.display(), LogFormat::EXTENSIONS)]
    NotALog { path: PathBuf },
    #[error("{}: {source}", path.display())]
    Glob {
        path: PathBuf,
        #[source]
        source: glob::PatternError,
    },
    #[error(transparent)]
    Inspect(#[from] ingest::IngestError),
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
    let (files, tables) = collect(logs)?;
    let found_table = match tables.as_slice() {
        [] => None,
        [one] => Some(one.clone()),
        [first, second, ..] => {
            return Err(InitError::TwoTables {
                first: first.clone(),
                second: second.clone(),
            });
        }
    };
    if let (Some(found), Some(_)) = (&found_table, table) {
        return Err(InitError::TableFound {
            found: found.clone(),
        });
    }
    let found: Vec<FoundLog> = files
        .iter()
        .map(|(path, inspected)| FoundLog {
            path: relative(path, &base),
            stem: stem(path),
            inspected: inspected.clone(),
        })
        .collect();
    let channels = scaffold::propose(&found[0].inspected.columns);
    let read: Vec<ReadBack> = files
        .iter()
        .zip(&found)
        .map(|((path, i), log)| read_back(path, i.format, log, &channels))
        .collect();
    let folder = base
        .canonicalize()
        .ok()
        .and_then(|b| b.file_name().map(|n| n.to_string_lossy().into_owned()))
        .unwrap_or_default();
    let name = scaffold::manifest_name(&folder, "campaign");
    let paths: Vec<&Path> = files.iter().map(|(p, _)| p.as_path()).collect();
    let mut table_text = String::new();
    let runs = match (&found_table, table) {
        (Some(t), _) => {
            let mut comments = table_comments(t, &paths);
            comments.extend(read_comments(&found, &read));
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
                comments: read_comments(&found, &read),
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
    })
}

/// The folder a file is in (`.` for a bare name).
fn folder_of(file: &Path) -> PathBuf {
    match file.parent() {
        Some(p) if !p.as_os_str().is_empty() => p.to_path_buf(),
        _ => PathBuf::from("."),
    }
}

fn stem(path: &Path) -> String {
    path.file_stem()
        .map(|s| s.to_string_lossy().into_owned())
        .unwrap_or_default()
}

/// Whether an inspected file is a run table rather than a log: a CSV or
/// Parquet file with columns `id` and `role` (a log's columns are
/// signals).
fn is_run_table(i: &Inspected) -> bool {
    matches!(i.format, LogFormat::Csv | LogFormat::Parquet)
        && ["id", "role"]
            .iter()
            .all(|c| i.columns.iter().any(|x| x.name == *c))
}

/// The logs `args` name, inspected, in order, and the run tables among
/// them: a file as it is, a folder's files with a log extension (sorted;
/// hidden ones left out) or, where these are only a run table, its
/// subfolders' (a night's `specimens.csv` beside its `logs/`), a glob's
/// matches (sorted).
#[allow(clippy::type_complexity)]
fn collect(args: &[PathBuf]) -> Result<(Vec<(PathBuf, Inspected)>, Vec<PathBuf>), InitError> {
    let mut logs = Vec::new();
    let mut tables = Vec::new();
    for arg in args {
        let mut paths: Vec<PathBuf> = if arg.is_dir() {
            folder_files(arg)?
        } else if arg.exists() {
            vec![arg.clone()]
        } else {
            let pattern = arg.to_string_lossy();
            let mut m: Vec<PathBuf> = glob::glob(&pattern)
                .map_err(|source| InitError::Glob {
                    path: arg.clone(),
                    source,
                })?
                .filter_map(Result::ok)
                .filter(|p| p.is_file())
                .collect();
            m.sort();
            m
        };
        let (before, tables_before) = (logs.len(), tables.len());
        sort_out(&paths, &mut logs, &mut tables)?;
        // A folder holding a run table and no logs: a night's table beside
        // its `logs/` folder.
        if arg.is_dir() && logs.len() == before && tables.len() > tables_before {
            paths.clear();
            for sub in subfolders(arg)? {
                paths.extend(folder_files(&sub)?);
            }
            sort_out(&paths, &mut logs, &mut tables)?;
        }
        if logs.len() == before {
            return Err(InitError::NoLogs { path: arg.clone() });
        }
    }
    Ok((logs, tables))
}

/// Inspect each of `paths`: a run table goes to `tables`, a log to `logs`.
fn sort_out(
    paths: &[PathBuf],
    logs: &mut Vec<(PathBuf, Inspected)>,
    tables: &mut Vec<PathBuf>,
) -> Result<(), InitError> {
    for p in paths {
        let format = LogFormat::from_path(p).ok_or(InitError::NotALog { path: p.clone() })?;
        let inspected = ingest::inspect(p, format, ingest::DEFAULT_MAX_LOG_MIB << 20)?;
        if is_run_table(&inspected) {
            tables.push(p.clone());
        } else {
            logs.push((p.clone(), inspected));
        }
    }
    Ok(())
}

fn listing(dir: &Path) -> Result<Vec<PathBuf>, InitError> {
    let mut out: Vec<PathBuf> = std::fs::read_dir(dir)
        .map_err(|e| {
            InitError::Write(WriteError::Io {
                path: dir.to_path_buf(),
                source: e,
            })
        })?
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| {
            !p.file_name()
                .is_some_and(|n| n.to_string_lossy().starts_with('.'))
        })
        .collect();
    out.sort();
    Ok(out)
}

/// A folder's files with a log extension, sorted.
fn folder_files(dir: &Path) -> Result<Vec<PathBuf>, InitError> {
    Ok(listing(dir)?
        .into_iter()
        .filter(|p| p.is_file() && LogFormat::from_path(p).is_some())
        .collect())
}

/// A folder's folders, sorted.
fn subfolders(dir: &Path) -> Result<Vec<PathBuf>, InitError> {
    Ok(listing(dir)?.into_iter().filter(|p| p.is_dir()).collect())
}

/// `[run_table] logs` for `logs`: their folder, as the manifest in `base`
/// names it, when they share one; else a placeholder.
fn logs_spec(logs: &[&Path], base: &Path) -> String {
    let folders: BTreeSet<PathBuf> = logs
        .iter()
        .map(|p| std::path::absolute(folder_of(p)).unwrap_or_else(|_| folder_of(p)))
        .collect();
    match folders.into_iter().collect::<Vec<_>>().as_slice() {
        [one] => match relative(one, base) {
            r if r.is_empty() => ".".into(),
            r => r,
        },
        _ => format!(
            "{} a glob or folder matching the logs (they are in several folders)",
            scaffold::PLACEHOLDER
        ),
    }
}

/// How many names a comment lists before it counts the rest.
const LISTED: usize = 10;

fn listed(names: &[String]) -> String {
    let mut s = names
        .iter()
        .take(LISTED)
        .cloned()
        .collect::<Vec<_>>()
        .join(", ");
    if names.len() > LISTED {
        s.push_str(&format!(" and {} more", names.len() - LISTED));
    }
    s
}

/// What a run table found among the logs says about them: its rows, the
/// rows whose log is not among them, the logs no row names.
fn table_comments(table: &Path, logs: &[&Path]) -> Vec<String> {
    let shown = table.display();
    let format = TableFormat::from_path(table).unwrap_or(TableFormat::Csv);
    let t = match ingest::read_table(table, format) {
        Ok(t) => t,
        Err(e) => return vec![format!("the run table does not read: {e}")],
    };
    let (Some(id_col), log_col) = (t.column("id"), t.column("log")) else {
        return vec![];
    };
    let dir = folder_of(table);
    let key = |p: &Path| std::path::absolute(p).unwrap_or_else(|_| p.to_path_buf());
    let have: BTreeSet<PathBuf> = logs.iter().map(|p| key(p)).collect();
    let mut used = BTreeSet::new();
    let mut missing = Vec::new();
    let mut rows = 0;
    for cells in &t.rows {
        let Some(id) = cells.get(id_col).cloned().flatten() else {
            continue;
        };
        rows += 1;
        let cell = log_col.and_then(|c| cells.get(c).cloned().flatten());
        let hit = match cell {
            Some(c) => Some(key(&dir.join(c))).filter(|p| have.contains(p)),
            None => logs
                .iter()
                .find(|p| p.file_stem().is_some_and(|s| s.to_string_lossy() == id))
                .map(|p| key(p)),
        };
        match hit {
            Some(p) => {
                used.insert(p);
            }
            None => missing.push(id),
        }
    }
    let unused: Vec<String> = logs
        .iter()
        .filter(|p| !used.contains(&key(p)))
        .map(|p| p.display().to_string())
        .collect();
    let mut out = vec![format!(
        "{shown}: {rows} row(s); {} find their log among the {} found",
        rows - missing.len(),
        logs.len()
    )];
    if !missing.is_empty() {
        out.push(format!(
            "rows whose log is not there (their runs fail alone until it is): {}",
            listed(&missing)
        ));
    }
    if !unused.is_empty() {
        out.push(format!(
            "logs no row names (`servoid check` warns of them): {}",
            listed(&unused)
        ));
    }
    out
}

/// What reading each log with the proposed channels gave, in a few lines.
fn read_comments(logs: &[FoundLog], read: &[ReadBack]) -> Vec<String> {
    let mut rates = Vec::new();
    let mut seconds = Vec::new();
    let mut failed = Vec::new();
    for (log, back) in logs.iter().zip(read) {
        match back {
            ReadBack::Read {
                sample_rate_hz,
                n_samples,
            } => {
                rates.push(*sample_rate_hz);
                seconds.push(*n_samples as f64 / sample_rate_hz);
            }
            ReadBack::Failed(why) => failed.push(format!("{} ({why})", log.path)),
            ReadBack::NotRead => {}
        }
    }
    let range = |v: &[f64], digits: usize| {
        let (lo, hi) = v
            .iter()
            .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), &x| {
                (a.min(x), b.max(x))
            });
        if format!("{lo:.digits$}") == format!("{hi:.digits$}") {
            format!("{lo:.digits$}")
        } else {
            format!("{lo:.digits$} to {hi:.digits$}")
        }
    };
    let mut out = Vec::new();
    if !rates.is_empty() {
        out.push(format!(
            "{} log(s) read with these channels: {} Hz, {} s long",
            rates.len(),
            range(&rates, 6),
            range(&seconds, 1)
        ));
    }
    if !failed.is_empty() {
        out.push(format!(
            "{} log(s) do not read with these channels: {}",
            failed.len(),
            listed(&failed)
        ));
    }
    if logs
        .iter()
        .any(|l| l.inspected.csv_delimiter.is_some_and(|d| d != ','))
    {
        out.push(
            "some CSV logs are split on another delimiter than a comma, which a run table's rows cannot say: give them [[runs]] tables with data.csv.delimiter".into(),
        );
    }
    out
}

/// `path` as the manifest in `base` names it.
fn relative(path: &Path, base: &Path) -> String {
    let abs = |p: &Path| std::path::absolute(p).unwrap_or_else(|_| p.to_path_buf());
    pathdiff::diff_paths(abs(path), abs(base))
        .unwrap_or_else(|| path.to_path_buf())
        .to_string_lossy()
        .replace('\\', "/")
}

/// Read a log with the proposed channels: its rate and length, or why not.
fn read_back(path: &Path, format: LogFormat, log: &FoundLog, p: &ProposedChannels) -> ReadBack {
    let length = |c: &scaffold::Proposed| -> Option<ChannelPlan> {
        let unit: Unit = serde_json::from_value(serde_json::json!(c.unit?)).ok()?;
        Some(ChannelPlan {
            column: Column::Name(c.column.clone()?),
            unit,
            gain: unit.to_si(),
            offset: 0.0,
            range: None,
            repair: Repair::None,
        })
    };
    let time = match (&p.time.column, p.time.unit, log.inspected.rate_hz) {
        (Some(c), Some(u), _) => {
            let Ok(unit) = serde_json::from_value::<TimeUnit>(serde_json::json!(u)) else {
                return ReadBack::NotRead;
            };
            TimePlan::Column {
                column: Column::Name(c.clone()),
                to_s: unit.to_si(),
            }
        }
        (None, _, Some(_)) => TimePlan::FromLog,
        _ => return ReadBack::NotRead,
    };
    let (Some(command), Some(displacement)) = (length(&p.command), length(&p.displacement)) else {
        return ReadBack::NotRead;
    };
    let csv = CsvOptions {
        delimiter: log.inspected.csv_delimiter.unwrap_or(',').to_string(),
        ..CsvOptions::default()
    };
    let plan = LogPlan {
        path: path.to_path_buf(),
        format,
        csv,
        sha256: None,
        channels: Channels {
            time,
            command,
            displacement,
            force: length(&p.force),
        },
        max_bytes: ingest::DEFAULT_MAX_LOG_MIB << 20,
    };
    match ingest::read_log(&plan) {
        Ok(l) => ReadBack::Read {
            sample_rate_hz: l.sample_rate_hz,
            n_samples: l.n_rows,
        },
        Err(e) => ReadBack::Failed(e.to_string()),
    }
}
