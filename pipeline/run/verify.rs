//! `servoid verify RESULTS.json`, for a reviewer: rerun the analysis that a
//! results.json records and list every quantity that differs. The manifest
//! is found where results.json says (`campaign.manifest_path`, relative to
//! its folder) and checked by its SHA-256; the logs are found by the
//! manifest and checked by theirs (a changed file is a difference, named).
//! The comparison is of the JSON values, leaf by leaf, exactly: the same
//! inputs give the same bytes, so anything else is a difference. The drift
//! checks (the rig against its history as it stood then) are not rerun.
//!
//! Every other file of the set (pages, figures, tables, the history) is
//! checked against the record the job wrote last, `outputs.sha256`: a
//! figure replaced, a page edited or a table changed after the job is a
//! difference, named. A log whose hash differs from the recorded one is
//! reported first and on its own: every other difference may follow from
//! it.

use std::path::{Path, PathBuf};

use super::JobError;
use super::analyse::analyse;
use crate::manifest;
use crate::results::{Difference, LogDifference, Results};

/// Why a results.json cannot be verified at all.
#[derive(Debug, thiserror::Error)]
pub enum VerifyError {
    #[error("{}: cannot read: {source}", path.display())]
    Read {
        path: PathBuf,
        #[source]
        source: std::io::Error,
    },
    #[error("{}: not a results.json servoid wrote: {source}", path.display())]
    Parse {
        path: PathBuf,
        #[source]
        source: serde_json::Error,
    },
    #[error(
        "{}: results.json does not say where its manifest is (campaign.manifest_path); give it with --manifest",
        path.display()
    )]
    NoManifestPath { path: PathBuf },
    #[error(
        "{}: the manifest results.json names ({recorded}, relative to its folder) is not there ({source}); if the folder moved, give the manifest with --manifest",
        path.display()
    )]
    ManifestGone {
        path: PathBuf,
        recorded: String,
        #[source]
        source: std::io::Error,
    },
}

/// An output file that is not as the set's record says.
#[derive(Debug, Clone, PartialEq)]
pub struct FileDifference {
    /// Relative to the output folder.
    pub file: String,
    pub recorded: String,
    /// None when the file is not there.
    pub now: Option<String>,
}

/// What a verification found.
#[derive(Debug, Clone, PartialEq)]
pub struct Verification {
    pub manifest: PathBuf,
    /// Runs whose log was checked by its hash.
    pub logs: usize,
    /// Logs whose hash differs: first, as everything may follow from them.
    pub log_differences: Vec<LogDifference>,
    /// Output files checked against the record; None when the set has no
    /// record (a set written before servoid wrote one).
    pub files: Option<usize>,
    pub file_differences: Vec<FileDifference>,
    /// The quantities of results.json that differ (the logs' hashes
    /// excepted: they are in `log_differences`).
    pub differences: Vec<Difference>,
}

impl Verification {
    /// Whether everything matches.
    pub fn matches(&self) -> bool {
        self.log_differences.is_empty()
            && self.file_differences.is_empty()
            && self.differences.is_empty()
    }
}

/// A results.json's bytes and what they hold.
pub(super) fn read_results(path: &Path) -> Result<(Vec<u8>, Results), VerifyError> {
    let bytes = std::fs::read(path).map_err(|source| VerifyError::Read {
        path: path.to_path_buf(),
        source,
    })?;
    let results = serde_json::from_slice(&bytes).map_err(|source| VerifyError::Parse {
        path: path.to_path_buf(),
        source,
    })?;
    Ok((bytes, results))
}

/// Rerun the analysis `results_path` records and compare (on the current
/// rayon pool).
pub fn verify(results_path: &Path, manifest: Option<&Path>) -> Result<Verification, JobError> {
    let (_, recorded) = read_results(results_path)?;
    let folder = results_path.parent().unwrap_or(Path::new(""));
    let manifest = match manifest {
        Some(m) => m.to_path_buf(),
        None => {
            let rel = recorded.campaign.manifest_path.as_deref().ok_or_else(|| {
                VerifyError::NoManifestPath {
                    path: results_path.to_path_buf(),
                }
            })?;
            let path = folder.join(rel);
            if let Err(source) = std::fs::metadata(&path) {
                return Err(VerifyError::ManifestGone {
                    path: results_path.to_path_buf(),
                    recorded: rel.to_string(),
                    source,
                }
                .into());
            }
            path
        }
    };
    let campaign = manifest::load(&manifest)?;
    let mut recomputed = analyse(&campaign);
    // Where the manifest is, as recorded: the folder is the same.
    recomputed.campaign.manifest_path = recorded.campaign.manifest_path.clone();
    let logs = recomputed.runs.iter().filter(|r| r.log.is_some()).count();
    // The drift checks compare the rig with its history as it stood when
    // the campaign ran, state the manifest and logs do not hold: not rerun.
    let mut recorded = recorded;
    recorded.drift = None;
    let (differences, log_differences) = recorded.differences(&recomputed);
    let (files, file_differences) = match check_record(folder) {
        Some(found) => (Some(found.0), found.1),
        None => (None, Vec::new()),
    };
    Ok(Verification {
        manifest,
        logs,
        log_differences,
        files,
        file_differences,
        differences,
    })
}

/// The output files of the set in `folder` against its record: how many
/// the record lists, and those that differ. None without a record.
fn check_record(folder: &Path) -> Option<(usize, Vec<FileDifference>)> {
    let text = std::fs::read_to_string(folder.join(crate::report::RECORD)).ok()?;
    let mut differences = Vec::new();
    let mut n = 0;
    for line in text.lines() {
        let Some((sha, file)) = line.split_once("  ") else {
            continue;
        };
        n += 1;
        let now = crate::ingest::file_sha256(&folder.join(file)).ok();
        if now.as_deref() != Some(sha) {
            differences.push(FileDifference {
                file: file.to_string(),
                recorded: sha.to_string(),
                now,
            });
        }
    }
    Some((n, differences))
}
