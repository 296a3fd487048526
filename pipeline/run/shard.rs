//! Scale-out on a lab's scheduler: `servoid run --shard i/n` does a
//! deterministic share of a campaign's per-log work into its own folder,
//! and `servoid merge DIR...` combines the shards into the results and pages
//! a single machine would have written, byte for byte.
//!
//! A shard does every identification run (no-specimen and springs: few, and
//! each shard needs the rig they give) and every n-th of the others (fit
//! and validation runs, counted in manifest order, starting at the i-th);
//! the first shard also does the campaign's Monte Carlo.
//! It writes its runs' cache entries, figures and tables, and `shard.json`
//! (campaign, servoid, share, date). The merge checks the shards belong
//! together, gathers their files and runs the campaign there: every run
//! comes from the cache, so it writes exactly what one run would.

use std::path::{Path, PathBuf};

use serde::{Deserialize, Serialize};

use crate::manifest::{Campaign, Role};
use crate::report::{self, FigureFormats, WriteError};

/// One share of a campaign: the `index`-th (0-based) of `count`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub struct Shard {
    pub index: usize,
    pub count: usize,
}

/// A `--shard` that is not `i/n` with 0 <= i < n.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum BadShard {
    #[error("`{0}` is not i/n (e.g. 0/4)")]
    NotIOverN(String),
    #[error("shard {index}/{count}: needs 0 <= i < n, counting from 0")]
    OutOfRange { index: usize, count: usize },
}

impl std::str::FromStr for Shard {
    type Err = BadShard;

    /// `i/n` with 0 <= i < n.
    fn from_str(s: &str) -> Result<Self, BadShard> {
        let syntax = || BadShard::NotIOverN(s.to_string());
        let (i, n) = s.split_once('/').ok_or_else(syntax)?;
        let parse = |v: &str| v.trim().parse::<usize>().map_err(|_| syntax());
        let (index, count) = (parse(i)?, parse(n)?);
        if count == 0 || index >= count {
            return Err(BadShard::OutOfRange { index, count });
        }
        Ok(Self { index, count })
    }
}

impl Shard {
    /// The campaign with this shard's runs: every identification run, and
    /// every `count`-th of the others from the `index`-th. Runs keep their
    /// places in the manifest (and so their cache keys).
    pub fn of(&self, campaign: &Campaign) -> Campaign {
        let mut share = campaign.clone();
        let mut k = 0;
        share.runs.retain(|r| {
            if matches!(r.role, Role::NoSpecimen | Role::Spring) {
                return true;
            }
            k += 1;
            (k - 1) % self.count == self.index
        });
        // The campaign's Monte Carlo is the first shard's alone: the others
        // would repeat it, and the merge finds it in that shard's cache.
        if self.index > 0 {
            share.sensitivity.monte_carlo = None;
        }
        share
    }
}

/// `shard.json`: what a shard folder holds.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ShardInfo {
    pub servoid_version: String,
    pub campaign: String,
    pub manifest_sha256: String,
    /// The manifest, as an absolute path, for the merge.
    pub manifest: PathBuf,
    pub shard: Shard,
    /// The runs the shard did, in manifest order.
    pub runs: Vec<String>,
    /// The figure files it drew (`--figures`): part of each run's cache
    /// key, so the merge draws the same or redoes every run.
    pub figures: FigureFormats,
    /// The night's date the shard was run with (`--date`): part of each
    /// run's plan, so the merge records the same.
    #[serde(default)]
    pub date: Option<String>,
}

/// Why shards cannot be merged; each names the folder.
#[derive(Debug, thiserror::Error)]
pub enum MergeError {
    #[error("{}: not a shard folder (no shard.json): {source}", dir.display())]
    NotAShard {
        dir: PathBuf,
        #[source]
        source: std::io::Error,
    },
    #[error("{}: shard.json does not read: {source}", dir.display())]
    BadInfo {
        dir: PathBuf,
        #[source]
        source: serde_json::Error,
    },
    #[error(
        "{}: a shard of another {what} ({found}; the first shard, {}, has {expected}): shards of one campaign and one servoid merge",
        dir.display(), first.display()
    )]
    Mismatch {
        dir: PathBuf,
        first: PathBuf,
        what: &'static str,
        found: String,
        expected: String,
    },
    #[error("{}: shard {index}/{count} is given twice (also {})", dir.display(), other.display())]
    Twice {
        dir: PathBuf,
        other: PathBuf,
        index: usize,
        count: usize,
    },
    #[error("shards {missing:?} of {count} are missing: every share must be merged")]
    Missing { missing: Vec<usize>, count: usize },
    #[error("no shard folders to merge")]
    None,
    #[error(
        "{}: the manifest changed since the shards ran (SHA-256 {now}, the shards' {recorded}); run the shards again",
        manifest.display()
    )]
    ManifestChanged {
        manifest: PathBuf,
        recorded: String,
        now: String,
    },
    #[error(
        "{}: the manifest the shards ran is not there ({source}); if it moved, give it with --manifest",
        manifest.display()
    )]
    ManifestGone {
        manifest: PathBuf,
        #[source]
        source: std::io::Error,
    },
    #[error(
        "the shards drew their figures with --figures {}, and each run's cached outcome is for those: merge with --figures {} (the default), or run the shards again with --figures {}",
        shards.as_str(), shards.as_str(), asked.as_str()
    )]
    OtherFigures {
        shards: FigureFormats,
        asked: FigureFormats,
    },
    #[error(
        "the shards were run with {}, and each run's cached outcome is for that date: merge without --date, or run the shards again with --date {asked}",
        shards.as_ref().map_or("no --date".to_string(), |d| format!("--date {d}"))
    )]
    OtherDate {
        shards: Option<String>,
        asked: String,
    },
}

/// The shard a folder holds (its `shard.json`), when it holds one.
pub fn held(dir: &Path) -> Option<ShardInfo> {
    serde_json::from_slice(&std::fs::read(dir.join("shard.json")).ok()?).ok()
}

/// Write `shard.json` into a shard's folder.
pub fn write_info(out_dir: &Path, info: &ShardInfo) -> Result<(), WriteError> {
    report::write_atomic(&out_dir.join("shard.json"), &report::json_bytes(info))
}

/// Read and check the shards' `shard.json`: one campaign, one servoid, each
/// share once. Returns the infos in shard order.
pub fn check(dirs: &[PathBuf]) -> Result<Vec<(PathBuf, ShardInfo)>, MergeError> {
    let mut infos = Vec::new();
    for dir in dirs {
        let text =
            std::fs::read(dir.join("shard.json")).map_err(|source| MergeError::NotAShard {
                dir: dir.clone(),
                source,
            })?;
        let info: ShardInfo =
            serde_json::from_slice(&text).map_err(|source| MergeError::BadInfo {
                dir: dir.clone(),
                source,
            })?;
        infos.push((dir.clone(), info));
    }
    let Some((first_dir, first)) = infos.first().cloned() else {
        return Err(MergeError::None);
    };
    let mut seen: Vec<Option<PathBuf>> = vec![None; first.shard.count];
    for (dir, info) in &infos {
        let mismatch = |what, found: String, expected: String| MergeError::Mismatch {
            dir: dir.clone(),
            first: first_dir.clone(),
            what,
            found,
            expected,
        };
        if info.servoid_version != first.servoid_version {
            return Err(mismatch(
                "servoid version",
                info.servoid_version.clone(),
                first.servoid_version.clone(),
            ));
        }
        if info.manifest_sha256 != first.manifest_sha256 {
            return Err(mismatch(
                "campaign",
                format!("`{}`, manifest {}", info.campaign, info.manifest_sha256),
                format!("`{}`, manifest {}", first.campaign, first.manifest_sha256),
            ));
        }
        if info.figures != first.figures {
            return Err(mismatch(
                "--figures",
                info.figures.as_str().to_string(),
                first.figures.as_str().to_string(),
            ));
        }
        if info.date != first.date {
            return Err(mismatch(
                "--date",
                info.date.clone().unwrap_or_else(|| "none".into()),
                first.date.clone().unwrap_or_else(|| "none".into()),
            ));
        }
        if info.shard.count != first.shard.count {
            return Err(mismatch(
                "sharding",
                format!("{} shards", info.shard.count),
                format!("{} shards", first.shard.count),
            ));
        }
        let slot = &mut seen[info.shard.index];
        if let Some(other) = slot {
            return Err(MergeError::Twice {
                dir: dir.clone(),
                other: other.clone(),
                index: info.shard.index,
                count: info.shard.count,
            });
        }
        *slot = Some(dir.clone());
    }
    let missing: Vec<usize> = (0..first.shard.count)
        .filter(|i| seen[*i].is_none())
        .collect();
    if !missing.is_empty() {
        return Err(MergeError::Missing {
            missing,
            count: first.shard.count,
        });
    }
    infos.sort_by_key(|(_, i)| i.shard.index);
    Ok(infos)
}

/// Copy what a shard wrote (its cache entries, figures and tables) into the
/// merge's folder. The run stamps are merged by the cache itself.
pub fn gather(shard: &Path, out_dir: &Path) -> Result<(), WriteError> {
    for sub in [".cache/runs", "figures", "tables"] {
        let Ok(entries) = std::fs::read_dir(shard.join(sub)) else {
            continue;
        };
        let mut names: Vec<PathBuf> = entries.flatten().map(|e| e.path()).collect();
        names.sort();
        for from in names {
            let Some(name) = from.file_name() else {
                continue;
            };
            if name.to_string_lossy().starts_with('.') {
                continue;
            }
            let to = out_dir.join(sub).join(name);
            let bytes = std::fs::read(&from).map_err(|source| WriteError::Io {
                path: from.clone(),
                source,
            })?;
            report::write_artifact(&to, &bytes)?;
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn shards_parse_and_refuse_what_is_not_a_share() {
        assert_eq!("2/4".parse::<Shard>(), Ok(Shard { index: 2, count: 4 }));
        assert!(
            "4/4"
                .parse::<Shard>()
                .unwrap_err()
                .to_string()
                .contains("0 <= i < n")
        );
        assert!("1/0".parse::<Shard>().is_err());
        assert!(
            "x".parse::<Shard>()
                .unwrap_err()
                .to_string()
                .contains("not i/n")
        );
    }
}
