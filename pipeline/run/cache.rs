//! Incremental reruns: each run's outcome kept under a key made of what
//! decides it (the servoid version and outcome format, the run's checked
//! plan, the identification settings, the figures, its log's SHA-256 and,
//! for a run that needs the rig, the rig to the last bit), so a rerun with
//! nothing changed does no per-log work, and a changed log recomputes its
//! run and what depends on it (a changed identification log changes the
//! rig, and with it every validation run's key).
//!
//! The cache is the orchestrator's own state in `.cache/` inside the output
//! folder: `runs/<key>.json.zst` per run outcome (zstd'd JSON with shortest
//! round-trip floats: a cached outcome gives the same results.json bytes as
//! a fresh one), and `stamps.json`, each log's size and modification time
//! when it was hashed, so an unchanged log is not even read (as make and
//! git do). Entries the campaign no longer uses are removed when it
//! finishes (the cache holds one night). Anything unreadable is a miss.

use std::collections::{BTreeMap, BTreeSet};
use std::path::{Path, PathBuf};
use std::sync::Mutex;

use serde::Serialize;
use serde::de::DeserializeOwned;

use crate::ingest::{FileStamp, LogFile, sha256_hex};
use crate::report::{self, WriteError};

/// A log's stamp when its hash was taken.
#[derive(Debug, Clone, serde::Serialize, serde::Deserialize)]
struct Stamped {
    stamp: FileStamp,
    sha256: String,
}

/// The cache of one output folder.
pub(super) struct Cache {
    dir: PathBuf,
    /// Set by `--force`: nothing is read from the cache, everything is
    /// computed and stored afresh.
    fresh: bool,
    stamps: Mutex<BTreeMap<String, Stamped>>,
    used: Mutex<BTreeSet<String>>,
    /// (work folder, output folder): a log inside the work folder is named
    /// by where it will be once the set is in place.
    names: (PathBuf, PathBuf),
}

/// What a probe found: the stored outcome, or the key to store one under
/// and the log's bytes when they were read on the way.
pub(super) enum Probe<T> {
    Hit(T),
    Miss { key: String, file: Option<LogFile> },
}

impl Cache {
    /// The cache in `out_dir/.cache`, empty when there is none; `fresh`
    /// ignores what it holds. `names` is (work folder, output folder), both
    /// absolute (see `report::OutputFolder`).
    pub(super) fn open(out_dir: &Path, fresh: bool, names: (PathBuf, PathBuf)) -> Self {
        let dir = out_dir.join(".cache");
        let stamps = if fresh {
            BTreeMap::new()
        } else {
            read_json(&dir.join("stamps.json")).unwrap_or_default()
        };
        Self {
            dir,
            fresh,
            stamps: Mutex::new(stamps),
            used: Mutex::new(BTreeSet::new()),
            names,
        }
    }

    /// Look a run up: `key` makes its key from its log's SHA-256. The log
    /// is read only when its stamp changed since it was last hashed.
    pub(super) fn probe<T: DeserializeOwned>(
        &self,
        log: &Path,
        max_bytes: u64,
        key: impl Fn(&str) -> String,
        usable: impl Fn(&T) -> bool,
    ) -> Probe<T> {
        // By absolute path: the same log whichever folder the job ran from.
        let abs = std::path::absolute(log).unwrap_or_else(|_| log.to_path_buf());
        let (work, target) = &self.names;
        let name = match abs.strip_prefix(work) {
            Ok(rest) => target.join(rest),
            Err(_) => abs,
        }
        .to_string_lossy()
        .into_owned();
        let stamp = FileStamp::of(log);
        let known = {
            let stamps = self.stamps.lock().expect("the stamps' lock");
            stamps
                .get(&name)
                .filter(|s| Some(s.stamp) == stamp)
                .map(|s| s.sha256.clone())
        };
        if let Some(sha) = known
            && let Some(hit) = self.load(&key(&sha), &usable)
        {
            return Probe::Hit(hit);
        }
        let Ok(file) = LogFile::read(log, max_bytes) else {
            // The run reads it again and reports why it cannot.
            return Probe::Miss {
                key: String::new(),
                file: None,
            };
        };
        // The stamp the read saw, unchanged from its start to its end.
        if let Some(stamp) = file.stamp {
            self.stamps.lock().expect("the stamps' lock").insert(
                name,
                Stamped {
                    stamp,
                    sha256: file.sha256.clone(),
                },
            );
        }
        let k = key(&file.sha256);
        match self.load(&k, &usable) {
            Some(hit) => Probe::Hit(hit),
            None => Probe::Miss {
                key: k,
                file: Some(file),
            },
        }
    }

    /// A stored outcome under `key` that is not a log's (the campaign's
    /// Monte Carlo).
    pub(super) fn lookup<T: DeserializeOwned>(&self, key: &str) -> Option<T> {
        self.load(key, &|_: &T| true)
    }

    fn load<T: DeserializeOwned>(&self, key: &str, usable: &impl Fn(&T) -> bool) -> Option<T> {
        if self.fresh {
            return None;
        }
        let bytes = zstd::decode_all(std::fs::read(self.entry(key)).ok()?.as_slice()).ok()?;
        let entry: T = serde_json::from_slice(&bytes).ok()?;
        if !usable(&entry) {
            return None;
        }
        self.used
            .lock()
            .expect("the used keys' lock")
            .insert(key.to_string());
        Some(entry)
    }

    /// Keep a run's outcome under `key` (from a miss).
    pub(super) fn store(&self, key: &str, value: &impl Serialize) -> Result<(), WriteError> {
        if key.is_empty() {
            return Ok(());
        }
        let json = serde_json::to_vec(value).expect("servoid's outcomes serialise to JSON");
        let packed =
            zstd::encode_all(json.as_slice(), ENTRY_LEVEL).expect("zstd compresses in memory");
        report::write_artifact(&self.entry(key), &packed)?;
        self.used
            .lock()
            .expect("the used keys' lock")
            .insert(key.to_string());
        Ok(())
    }

    /// Write the stamps and remove the entries this campaign did not use.
    pub(super) fn finish(&self) -> Result<(), WriteError> {
        let stamps = self.stamps.lock().expect("the stamps' lock");
        report::write_atomic(&self.dir.join("stamps.json"), &report::json_bytes(&*stamps))?;
        let used = self.used.lock().expect("the used keys' lock");
        if let Ok(entries) = std::fs::read_dir(self.dir.join("runs")) {
            for e in entries.flatten() {
                let name = e.file_name().to_string_lossy().into_owned();
                let key = name.trim_end_matches(ENTRY_EXTENSION);
                if !used.contains(key) {
                    let _ = std::fs::remove_file(e.path());
                }
            }
        }
        Ok(())
    }

    fn entry(&self, key: &str) -> PathBuf {
        self.dir
            .join("runs")
            .join(format!("{key}{ENTRY_EXTENSION}"))
    }
}

/// The place of the cache in `out_dir` taken by something that is not a
/// folder (`.cache`, or `.cache/runs`), as a path relative to `out_dir`.
pub(super) fn taken_place(out_dir: &Path) -> Option<PathBuf> {
    [Path::new(".cache"), Path::new(".cache/runs")]
        .into_iter()
        .find(|p| std::fs::metadata(out_dir.join(p)).is_ok_and(|m| !m.is_dir()))
        .map(Path::to_path_buf)
}

/// Fold the log stamps other caches (a merge's shards, in `dirs`) hold into
/// `out_dir`'s, so that the logs they hashed are not read again.
pub(super) fn merge_stamps(out_dir: &Path, dirs: &[PathBuf]) -> Result<(), WriteError> {
    let path = out_dir.join(".cache").join("stamps.json");
    let mut stamps: BTreeMap<String, Stamped> = read_json(&path).unwrap_or_default();
    for d in dirs {
        let theirs: BTreeMap<String, Stamped> =
            read_json(&d.join(".cache").join("stamps.json")).unwrap_or_default();
        stamps.extend(theirs);
    }
    report::write_atomic(&path, &report::json_bytes(&stamps))
}

/// A stored outcome's file name after its key.
const ENTRY_EXTENSION: &str = ".json.zst";

/// zstd's level for the entries: level 3, its default, packs an
/// identification run's entry 3.9 times (compact JSON 0.95 MB, 0.24 MB);
/// level 19 packs it 5.2 times at many times the CPU.
const ENTRY_LEVEL: i32 = 3;

/// What a run's outcome holds, counted up whenever a change between
/// releases adds to it or computes it differently: the version alone
/// would let an older build's entries stand in for outcomes this build
/// computes otherwise.
const OUTCOME_FORMAT: u32 = 11;

/// A key from the text of what decides a run's outcome. The plan's Debug
/// text holds every setting with its floats to the last bit; a rebuild that
/// printed them differently could only change the key (a miss), never make
/// two different plans share one.
pub(super) fn key(parts: &[&dyn std::fmt::Debug]) -> String {
    let mut text = format!(
        "servoid {} outcome {OUTCOME_FORMAT}\n",
        env!("CARGO_PKG_VERSION")
    );
    for p in parts {
        text.push_str(&format!("{p:?}\n"));
    }
    sha256_hex(text.as_bytes())
}

fn read_json<T: DeserializeOwned>(path: &Path) -> Option<T> {
    serde_json::from_slice(&std::fs::read(path).ok()?).ok()
}
