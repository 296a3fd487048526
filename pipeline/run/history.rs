//! The rig's history on disk around one campaign: the table read (through
//! ingest) before the campaign's drift is checked (`analysis::history`),
//! and its entry written in once results.json is.

use std::path::{Path, PathBuf};

use crate::analysis::history::{self, Extra};
use crate::drift::Entry;
use crate::ingest::{self, TableFormat};
use crate::manifest::Campaign;
use crate::report::{self, WriteError};
use crate::results::Results;

/// A campaign's place in its rig's history.
pub(super) struct History {
    path: PathBuf,
    /// Every entry of the table, every rig, in table order.
    entries: Vec<Entry>,
    /// The table's columns that are not servoid's (a lab's notes, an
    /// operator): kept through every update, as text.
    extra: Extra,
    /// Where this campaign's entry goes: its own earlier entry's place, or
    /// the end.
    slot: usize,
    entry: Entry,
}

/// The history file: the manifest's, else `history.parquet` in `out_dir`.
pub(super) fn path(campaign: &Campaign, out_dir: &Path) -> PathBuf {
    campaign
        .history
        .file
        .clone()
        .unwrap_or_else(|| out_dir.join("history.parquet"))
}

/// A history table that exists and cannot be read (damaged, or not a
/// servoid history): the night's failure, not a warning, for the drift
/// alarm is off until someone looks.
#[derive(Debug)]
pub struct Unreadable {
    pub path: PathBuf,
    pub what: String,
}

impl Unreadable {
    /// What the night says, with `shown` the file as the user knows it:
    /// what is wrong and how to recover.
    pub fn message(&self, shown: &Path) -> String {
        let prev = previous_copy(&self.path);
        let recover = if prev.is_file() {
            let shown_prev = previous_copy(shown);
            format!(
                "its previous good copy is {}: restore it (cp {} {}), or move the damaged file aside to start a new history, then rerun",
                shown_prev.display(),
                shown_prev.display(),
                shown.display()
            )
        } else {
            "restore it from a backup, or move it aside to start a new history, then rerun".into()
        };
        format!(
            "the rig history {} cannot be read ({}): the rig was not checked for drift and the history was not updated; {recover}",
            shown.display(),
            self.what
        )
    }
}

/// Where the previous good copy of the history at `path` is kept:
/// `<file>.prev` beside it, written before each update replaces it.
pub(super) fn previous_copy(path: &Path) -> PathBuf {
    let mut name = path.file_name().unwrap_or_default().to_os_string();
    name.push(".prev");
    path.with_file_name(name)
}

/// The history's entries and what else its table holds, or why the table
/// that exists cannot be read. None there yet: empty.
fn read(path: &Path) -> Result<(Vec<Entry>, Extra), Unreadable> {
    if std::fs::symlink_metadata(path).is_err() {
        return Ok((Vec::new(), Extra::default()));
    }
    ingest::read_table(path, TableFormat::Parquet)
        .map_err(|e| e.problem.to_string())
        .and_then(|t| history::entries(&t).map_err(|e| e.to_string()))
        .map_err(|what| Unreadable {
            path: path.to_path_buf(),
            what,
        })
}

/// Check `results`' rig against its history and record the checks in
/// `results.drift`. Returns the history to update once results.json is
/// written (None without a rig), or why the table that exists cannot be
/// read: it is then left as it is for someone to look at.
pub(super) fn check(
    campaign: &Campaign,
    out_dir: &Path,
    results: &mut Results,
) -> Result<Option<History>, Unreadable> {
    if results.rig.is_none() {
        return Ok(None);
    }
    let path = path(campaign, out_dir);
    let (entries, extra) = read(&path)?;
    // As the output folder sees it, so results.json does not depend on
    // where the folder is.
    let shown = super::relative_to(&path, out_dir).unwrap_or_else(|| path.display().to_string());
    let file_name = path.file_name().unwrap_or_default().to_string_lossy();
    let replaced = corrections(&audit_path(&path));
    let Some((slot, entry)) =
        history::place(campaign, &entries, &replaced, results, &shown, &file_name)
    else {
        return Ok(None);
    };
    Ok(Some(History {
        path,
        entries,
        extra,
        slot,
        entry,
    }))
}

impl History {
    /// This rig's entries with this campaign's in its place, oldest first
    /// (for the trend figure).
    pub(super) fn rig_entries(&self) -> Vec<Entry> {
        let mut all = self.entries.clone();
        put(&mut all, self.slot, self.entry.clone());
        all.into_iter()
            .filter(|e| e.rig == self.entry.rig)
            .collect()
    }

    /// Put this campaign's entry in, with the hash of its results.json;
    /// the table it replaces (read cleanly: this history came from it) is
    /// kept as `<file>.prev` first when the update changes it, the good
    /// copy an unreadable table's message points to.
    pub(super) fn write(mut self, results_sha256: String) -> Result<(), WriteError> {
        self.entry.results_sha256 = results_sha256;
        // The entry of the same night this one corrects, when it replaces
        // one it is not a rerun of (its inputs differ): for the audit.
        let audit: Vec<serde_json::Value> = self
            .entries
            .get(self.slot)
            .filter(|old| old.inputs_sha256 != self.entry.inputs_sha256)
            .map(|old| {
                serde_json::json!({
                    "action": "replaced",
                    "by_campaign": self.entry.campaign,
                    "by_inputs_sha256": self.entry.inputs_sha256,
                    "by_results_sha256": self.entry.results_sha256,
                    "entry": old,
                })
            })
            .into_iter()
            .collect();
        if self.slot == self.entries.len() {
            self.extra.rows.push(vec![None; self.extra.names.len()]);
        }
        put(&mut self.entries, self.slot, self.entry);
        write_table(&self.path, &self.entries, &self.extra, &audit)
    }
}

/// Write `entries` with the lab's columns `extra` as the history at
/// `path`, the table it replaces kept as `<file>.prev` when the update
/// changes it, then append `audit` to its audit file.
fn write_table(
    path: &Path,
    entries: &[Entry],
    extra: &Extra,
    audit: &[serde_json::Value],
) -> Result<(), WriteError> {
    let before = std::fs::read(path).ok();
    let columns: Vec<(String, Vec<Option<String>>)> = extra
        .names
        .iter()
        .enumerate()
        .map(|(k, name)| {
            (
                name.clone(),
                extra.rows.iter().map(|r| r[k].clone()).collect(),
            )
        })
        .collect();
    report::history::write(
        path,
        &previous_copy(path),
        before.as_deref(),
        entries,
        &columns,
    )
    .and_then(|()| report::history::append_audit(&audit_path(path), audit))
    .map_err(WriteError::from)
}

/// The corrections the audit file at `path` records: each replaced entry
/// with the inputs' hash of the analysis that replaced it. A line that does
/// not read as one is passed over: the audit is a record, not an input the
/// night depends on.
fn corrections(path: &Path) -> Vec<(String, Entry)> {
    let Ok(text) = std::fs::read_to_string(path) else {
        return Vec::new();
    };
    text.lines()
        .filter_map(|l| serde_json::from_str::<serde_json::Value>(l).ok())
        .filter(|v| v["action"] == "replaced")
        .filter_map(|v| {
            let by = v["by_inputs_sha256"].as_str()?.to_string();
            let entry = serde_json::from_value(v["entry"].clone()).ok()?;
            Some((by, entry))
        })
        .collect()
}

/// The audit file beside the history at `path`.
pub(super) fn audit_path(path: &Path) -> PathBuf {
    let name = path.file_name().unwrap_or_default().to_string_lossy();
    path.with_file_name(history::audit_name(&name))
}

fn put(entries: &mut Vec<Entry>, slot: usize, entry: Entry) {
    if slot < entries.len() {
        entries[slot] = entry;
    } else {
        entries.push(entry);
    }
}

/// What `servoid history remove` took out of a history.
#[derive(Debug)]
pub struct Removed {
    pub entries: Vec<Entry>,
    /// Where they are recorded.
    pub audit: PathBuf,
}

/// Why `servoid history remove` removed nothing.
#[derive(Debug, thiserror::Error)]
pub enum RemoveError {
    #[error("{}", .0.message(&.0.path))]
    Unreadable(Unreadable),
    #[error("{}: no entry of date {date}{} (its dates: {})", path.display(), rig.as_ref().map_or(String::new(), |r| format!(" for rig `{r}`")), if dates.is_empty() { "none".to_string() } else { dates.join(", ") })]
    NoEntry {
        path: PathBuf,
        date: String,
        rig: Option<String>,
        dates: Vec<String>,
    },
    #[error("{}: the entries of date {date} are of several rigs ({}): give --rig", path.display(), rigs.join(", "))]
    SeveralRigs {
        path: PathBuf,
        date: String,
        rigs: Vec<String>,
    },
    #[error("{}: cannot lock the output folder it is in: {source}", path.display())]
    Lock {
        path: PathBuf,
        source: std::io::Error,
    },
    #[error("{}: no such history file", path.display())]
    Missing { path: PathBuf },
    #[error(transparent)]
    Write(#[from] WriteError),
}

/// Remove the entries of `date` (of `rig`, or of the one rig that has
/// entries that day) from the history at `path`, recording each in its
/// audit file and keeping the table as it was in `<file>.prev`. Where the
/// history is in an output folder, that folder's lock is held meanwhile
/// (waiting at most `wait` for a job writing it).
pub fn remove(
    path: &Path,
    date: &str,
    rig: Option<&str>,
    wait: std::time::Duration,
) -> Result<Removed, RemoveError> {
    let _lock =
        report::output_folder::lock_if_output(path, wait).map_err(|source| RemoveError::Lock {
            path: path.to_path_buf(),
            source,
        })?;
    if !path.is_file() {
        return Err(RemoveError::Missing {
            path: path.to_path_buf(),
        });
    }
    let (entries, mut extra) = read(path).map_err(RemoveError::Unreadable)?;
    let that_day = |e: &Entry| e.date.as_deref() == Some(date) && rig.is_none_or(|r| e.rig == r);
    let mut rigs: Vec<String> = entries
        .iter()
        .filter(|e| that_day(e))
        .map(|e| e.rig.clone())
        .collect();
    rigs.sort();
    rigs.dedup();
    if rigs.is_empty() {
        let mut dates: Vec<String> = entries.iter().filter_map(|e| e.date.clone()).collect();
        dates.sort();
        dates.dedup();
        return Err(RemoveError::NoEntry {
            path: path.to_path_buf(),
            date: date.to_string(),
            rig: rig.map(str::to_string),
            dates,
        });
    }
    if rigs.len() > 1 {
        return Err(RemoveError::SeveralRigs {
            path: path.to_path_buf(),
            date: date.to_string(),
            rigs,
        });
    }
    let (mut kept, mut removed) = (Vec::new(), Vec::new());
    let mut rows = Vec::new();
    for (e, row) in entries.into_iter().zip(std::mem::take(&mut extra.rows)) {
        if that_day(&e) {
            removed.push(e);
        } else {
            kept.push(e);
            rows.push(row);
        }
    }
    extra.rows = rows;
    let records: Vec<serde_json::Value> = removed
        .iter()
        .map(|e| serde_json::json!({"action": "removed", "date": date, "entry": e}))
        .collect();
    write_table(path, &kept, &extra, &records)?;
    let audit = audit_path(path);
    Ok(Removed {
        entries: removed,
        audit,
    })
}
