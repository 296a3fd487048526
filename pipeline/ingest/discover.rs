//! Finding the logs `servoid init` is given as files, folders and globs:
//! each file is inspected ([`inspect`]) to tell a log from a run table, so
//! that `run` proposes a manifest from what the files hold, not from their
//! names alone.

use std::path::{Path, PathBuf};

use super::inspect::{Inspected, inspect};
use super::{DEFAULT_MAX_LOG_MIB, IngestError, LogFormat};

/// Why the logs named cannot be found; the message names the path at
/// fault.
#[derive(Debug, thiserror::Error)]
pub enum DiscoverError {
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
    Inspect(#[from] IngestError),
    /// A folder named (or one of its subfolders) cannot be listed.
    #[error("{}: {source}", path.display())]
    ReadDir {
        path: PathBuf,
        #[source]
        source: std::io::Error,
    },
}

/// The files [`collect`] found, in the order it found them.
#[derive(Debug, Default)]
pub struct Found {
    /// The logs, each with what [`inspect`] saw in it.
    pub logs: Vec<(PathBuf, Inspected)>,
    /// The run tables among the files (columns `id` and `role`).
    pub tables: Vec<PathBuf>,
    /// The files of a folder or glob left out, each with why: a name that
    /// is not UTF-8 (a manifest could not name it), a symbolic link to
    /// nothing, a file that cannot be read or inspected.
    pub skipped: Vec<String>,
}

/// The logs `args` name, inspected, in order, and the run tables among
/// them: a file as it is, a folder's files with a log extension (sorted;
/// hidden ones left out) or, where these are only a run table, its
/// subfolders' (a night's `specimens.csv` beside its `logs/`), a glob's
/// matches (sorted). Each argument must give at least one log. A file
/// named by itself that cannot be inspected is an error; one a folder or
/// glob gives is skipped with a line in `skipped`, as are names that are
/// not UTF-8 and links to nothing.
pub fn collect(args: &[PathBuf]) -> Result<Found, DiscoverError> {
    let mut found = Found::default();
    for arg in args {
        let one_file = !arg.is_dir() && arg.exists();
        let mut paths: Vec<PathBuf> = if arg.is_dir() {
            folder_files(arg, &mut found.skipped)?
        } else if one_file {
            vec![arg.clone()]
        } else {
            let pattern = arg.to_string_lossy();
            let mut m: Vec<PathBuf> = glob::glob(&pattern)
                .map_err(|source| DiscoverError::Glob {
                    path: arg.clone(),
                    source,
                })?
                .filter_map(Result::ok)
                .filter(|p| usable(p, &mut found.skipped))
                .collect();
            m.sort();
            m
        };
        let (before, tables_before) = (found.logs.len(), found.tables.len());
        sort_out(&paths, one_file, &mut found)?;
        // A folder holding a run table and no logs: a night's table beside
        // its `logs/` folder.
        if arg.is_dir() && found.logs.len() == before && found.tables.len() > tables_before {
            paths.clear();
            for sub in subfolders(arg)? {
                paths.extend(folder_files(&sub, &mut found.skipped)?);
            }
            sort_out(&paths, false, &mut found)?;
        }
        if found.logs.len() == before {
            return Err(DiscoverError::NoLogs { path: arg.clone() });
        }
    }
    Ok(found)
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

/// Inspect each of `paths`: a run table goes to `found.tables`, a log to
/// `found.logs`; one that cannot be inspected is an error where it was
/// `named` by itself, else skipped with why.
fn sort_out(paths: &[PathBuf], named: bool, found: &mut Found) -> Result<(), DiscoverError> {
    for p in paths {
        let format = LogFormat::from_path(p).ok_or(DiscoverError::NotALog { path: p.clone() })?;
        let inspected = match inspect(p, format, DEFAULT_MAX_LOG_MIB << 20) {
            Ok(i) => i,
            Err(e) if !named => {
                found.skipped.push(format!("skipped {e}"));
                continue;
            }
            Err(e) => return Err(e.into()),
        };
        if is_run_table(&inspected) {
            found.tables.push(p.clone());
        } else {
            found.logs.push((p.clone(), inspected));
        }
    }
    Ok(())
}

/// A folder's entries, sorted, hidden ones (a leading `.`) left out.
fn listing(dir: &Path) -> Result<Vec<PathBuf>, DiscoverError> {
    let mut out: Vec<PathBuf> = std::fs::read_dir(dir)
        .map_err(|source| DiscoverError::ReadDir {
            path: dir.to_path_buf(),
            source,
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

/// A folder's files with a log extension, sorted, those [`usable`] does
/// not take noted in `skipped`.
fn folder_files(dir: &Path, skipped: &mut Vec<String>) -> Result<Vec<PathBuf>, DiscoverError> {
    Ok(listing(dir)?
        .into_iter()
        .filter(|p| LogFormat::from_path(p).is_some() && usable(p, skipped))
        .collect())
}

/// Whether a found path can be a run's log: a file (a symbolic link to
/// nothing, a folder or a device is not) whose name a manifest can write
/// (UTF-8). A link to nothing and a name that is not UTF-8 are noted in
/// `skipped`; the rest are not files a lab meant.
fn usable(p: &Path, skipped: &mut Vec<String>) -> bool {
    if p.is_symlink() && !p.exists() {
        let target = std::fs::read_link(p).unwrap_or_default();
        skipped.push(format!(
            "skipped {}: a symbolic link to {}, which is not there",
            p.display(),
            target.display()
        ));
        return false;
    }
    if !p.is_file() {
        return false;
    }
    if p.to_str().is_none() {
        let name = p.file_name().unwrap_or_default().as_encoded_bytes();
        skipped.push(format!(
            "skipped {}: its name is not UTF-8 (bytes \"{}\"), so a manifest cannot name it; rename it in UTF-8",
            p.display(),
            name.escape_ascii()
        ));
        return false;
    }
    true
}

/// A folder's folders, sorted.
fn subfolders(dir: &Path) -> Result<Vec<PathBuf>, DiscoverError> {
    Ok(listing(dir)?.into_iter().filter(|p| p.is_dir()).collect())
}
