//! `servoid init LOGS... [--out campaign.toml]`: a campaign manifest
//! proposed from a lab's logs. Finds the logs (files, folders, globs),
//! inspects each (`ingest::inspect`), proposes the channels from the first
//! log's columns (`manifest::scaffold`), reads every log with them to say
//! its rate and length (or why it does not read), and writes the commented
//! manifest, refusing to overwrite one.

use std::path::{Path, PathBuf};

use crate::ingest::{
    self, ChannelPlan, Channels, Column, CsvOptions, LogFormat, LogPlan, TimePlan,
};
use crate::manifest::scaffold::{self, FoundLog, ProposedChannels, ReadBack};
use crate::report::{self, WriteError};
use crate::units::{TimeUnit, Unit};

/// Why `servoid init` wrote nothing.
#[derive(Debug, thiserror::Error)]
pub enum InitError {
    #[error("{}: no log there (a file, a folder of logs, or a glob matching them)", path.display())]
    NoLogs { path: PathBuf },
    #[error("{}: not a log servoid reads by its extension (.csv, .tsv, .parquet, .pq, .mat, .txt, .h5, .hdf5, .tdms)", path.display())]
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
    #[error(transparent)]
    Write(#[from] WriteError),
}

/// What `init` wrote.
#[derive(Debug)]
pub struct Initialised {
    pub manifest: PathBuf,
    pub logs: usize,
    /// How many placeholders are left to fill.
    pub placeholders: usize,
}

/// Propose a manifest for `logs` and write it to `out`.
pub fn init(logs: &[PathBuf], out: &Path) -> Result<Initialised, InitError> {
    if out.exists() {
        return Err(InitError::Exists {
            path: out.to_path_buf(),
        });
    }
    let files = log_files(logs)?;
    let base = match out.parent() {
        Some(p) if !p.as_os_str().is_empty() => p.to_path_buf(),
        _ => PathBuf::from("."),
    };
    let mut found = Vec::with_capacity(files.len());
    for (path, format) in &files {
        let inspected = ingest::inspect(path, *format, ingest::DEFAULT_MAX_LOG_MIB << 20)?;
        found.push(FoundLog {
            path: relative(path, &base),
            stem: path
                .file_stem()
                .map(|s| s.to_string_lossy().into_owned())
                .unwrap_or_default(),
            inspected,
        });
    }
    let channels = scaffold::propose(&found[0].inspected.columns);
    let read: Vec<ReadBack> = files
        .iter()
        .zip(&found)
        .map(|((path, format), log)| read_back(path, *format, log, &channels))
        .collect();
    let folder = base
        .canonicalize()
        .ok()
        .and_then(|b| b.file_name().map(|n| n.to_string_lossy().into_owned()))
        .unwrap_or_default();
    let name = scaffold::manifest_name(&folder, "campaign");
    let text = scaffold::manifest_text(&name, &found, &channels, &read);
    report::write_atomic(out, text.as_bytes())?;
    Ok(Initialised {
        manifest: out.to_path_buf(),
        logs: found.len(),
        placeholders: text
            .matches(&format!("\"{} ", scaffold::PLACEHOLDER))
            .count(),
    })
}

/// The logs `args` name, in order: a file as it is, a folder's files with
/// a log extension (sorted), a glob's matches (sorted).
fn log_files(args: &[PathBuf]) -> Result<Vec<(PathBuf, LogFormat)>, InitError> {
    let mut out = Vec::new();
    for arg in args {
        let mut paths: Vec<PathBuf> = if arg.is_dir() {
            std::fs::read_dir(arg)
                .map_err(|e| {
                    InitError::Write(WriteError::Io {
                        path: arg.clone(),
                        source: e,
                    })
                })?
                .filter_map(|e| e.ok().map(|e| e.path()))
                .filter(|p| p.is_file() && LogFormat::from_path(p).is_some())
                .collect()
        } else if arg.exists() {
            vec![arg.clone()]
        } else {
            let pattern = arg.to_string_lossy();
            glob::glob(&pattern)
                .map_err(|source| InitError::Glob {
                    path: arg.clone(),
                    source,
                })?
                .filter_map(Result::ok)
                .filter(|p| p.is_file())
                .collect()
        };
        paths.sort();
        if paths.is_empty() {
            return Err(InitError::NoLogs { path: arg.clone() });
        }
        for p in paths {
            let format = LogFormat::from_path(&p).ok_or(InitError::NotALog { path: p.clone() })?;
            out.push((p, format));
        }
    }
    Ok(out)
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
