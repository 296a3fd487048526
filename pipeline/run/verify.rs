//! `servoid verify RESULTS.json`, for a reviewer: rerun the analysis that a
//! results.json records and list every quantity that differs. The manifest
//! is found where results.json says (`campaign.manifest_path`, relative to
//! its folder) and checked by its SHA-256; the logs are found by the
//! manifest and checked by theirs (a changed file is a difference, named).
//! The comparison is of the JSON values, leaf by leaf, exactly: the same
//! inputs give the same bytes, so anything else is a difference. The drift
//! checks (the rig against its history as it stood then) are not rerun.

use std::path::{Path, PathBuf};

use serde_json::Value;

use super::JobError;
use super::analyse::analyse;
use crate::manifest;
use crate::results::Results;

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
}

/// One quantity that differs: where in results.json, and both values.
#[derive(Debug, Clone, PartialEq)]
pub struct Difference {
    /// A path into results.json, e.g. `runs[3].validation.nrmse_pct`.
    pub key: String,
    pub recorded: String,
    pub recomputed: String,
}

/// What a verification found.
#[derive(Debug, Clone, PartialEq)]
pub struct Verification {
    pub manifest: PathBuf,
    /// Runs whose log was checked by its hash.
    pub logs: usize,
    pub differences: Vec<Difference>,
}

/// Rerun the analysis `results_path` records and compare (on the current
/// rayon pool).
pub fn verify(results_path: &Path, manifest: Option<&Path>) -> Result<Verification, JobError> {
    let bytes = std::fs::read(results_path).map_err(|source| VerifyError::Read {
        path: results_path.to_path_buf(),
        source,
    })?;
    let recorded: Results =
        serde_json::from_slice(&bytes).map_err(|source| VerifyError::Parse {
            path: results_path.to_path_buf(),
            source,
        })?;
    let manifest = match manifest {
        Some(m) => m.to_path_buf(),
        None => {
            let rel = recorded.campaign.manifest_path.as_deref().ok_or_else(|| {
                VerifyError::NoManifestPath {
                    path: results_path.to_path_buf(),
                }
            })?;
            results_path.parent().unwrap_or(Path::new("")).join(rel)
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
    let mut differences = Vec::new();
    let a = serde_json::to_value(&recorded).expect("results serialise");
    let b = serde_json::to_value(&recomputed).expect("results serialise");
    diff("", &a, &b, &mut differences);
    Ok(Verification {
        manifest,
        logs,
        differences,
    })
}

/// Every leaf where `a` and `b` differ, with its path.
fn diff(key: &str, a: &Value, b: &Value, out: &mut Vec<Difference>) {
    match (a, b) {
        (Value::Object(x), Value::Object(y)) => {
            let keys: std::collections::BTreeSet<&String> = x.keys().chain(y.keys()).collect();
            for k in keys {
                let sub = if key.is_empty() {
                    k.clone()
                } else {
                    format!("{key}.{k}")
                };
                let none = Value::Null;
                diff(
                    &sub,
                    x.get(k).unwrap_or(&none),
                    y.get(k).unwrap_or(&none),
                    out,
                );
            }
        }
        (Value::Array(x), Value::Array(y)) if x.len() == y.len() => {
            for (i, (p, q)) in x.iter().zip(y).enumerate() {
                diff(&format!("{key}[{i}]"), p, q, out);
            }
        }
        _ if a != b => out.push(Difference {
            key: key.to_string(),
            recorded: a.to_string(),
            recomputed: b.to_string(),
        }),
        _ => {}
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn differences_are_named_by_their_path() {
        let a = serde_json::json!({"rig": {"a2": 1.0, "a3": [1, 2]}, "runs": [{"id": "x"}]});
        let b = serde_json::json!({"rig": {"a2": 1.5, "a3": [1, 3]}, "runs": [{"id": "x"}, {"id": "y"}]});
        let mut out = Vec::new();
        diff("", &a, &b, &mut out);
        let keys: Vec<&str> = out.iter().map(|d| d.key.as_str()).collect();
        assert_eq!(keys, ["rig.a2", "rig.a3[1]", "runs"]);
        assert_eq!(out[0].recorded, "1.0");
        assert_eq!(out[0].recomputed, "1.5");
    }
}
