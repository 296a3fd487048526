//! The rig's history on disk around one campaign: the table read (through
//! ingest) before the campaign's drift is checked (`analysis::history`),
//! and its entry written in once results.json is.

use std::path::{Path, PathBuf};

use crate::analysis::history::{self, Extra};
use crate::drift::Entry;
use crate::ingest::{self, TableFormat};
use crate::manifest::Campaign;
use crate::report::{self, WriteError, columns::ColumnWriteError};
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
pub(super) struct Unreadable {
    pub path: PathBuf,
    pub what: String,
}

impl Unreadable {
    /// What the night says, with `shown` the file as the user knows it:
    /// what is wrong and how to recover.
    pub(super) fn message(&self, shown: &Path) -> String {
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
    let Some((slot, entry)) = history::place(campaign, &entries, results, &shown, &file_name)
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
    pub(super) fn write(mut self, results_json: &[u8]) -> Result<(), WriteError> {
        self.entry.results_sha256 = ingest::sha256_hex(results_json);
        if self.slot == self.entries.len() {
            self.extra.rows.push(vec![None; self.extra.names.len()]);
        }
        put(&mut self.entries, self.slot, self.entry);
        let before = std::fs::read(&self.path).ok();
        let columns: Vec<(String, Vec<Option<String>>)> = self
            .extra
            .names
            .iter()
            .enumerate()
            .map(|(k, name)| {
                (
                    name.clone(),
                    self.extra.rows.iter().map(|r| r[k].clone()).collect(),
                )
            })
            .collect();
        report::history::write(
            &self.path,
            &previous_copy(&self.path),
            before.as_deref(),
            &self.entries,
            &columns,
        )
        .map_err(|e| match e {
            ColumnWriteError::Write(w) => w,
            other => WriteError::Table(Box::new(other)),
        })
    }
}

fn put(entries: &mut Vec<Entry>, slot: usize, entry: Entry) {
    if slot < entries.len() {
        entries[slot] = entry;
    } else {
        entries.push(entry);
    }
}
