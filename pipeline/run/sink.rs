//! Where each run's output goes as it arrives: its figures drawn into their
//! files, its tables written, and its outcome stored in the cache; and, before
//! a run is done, the cache's stored outcome of it, when there is one. The
//! analysis (`step`) computes; everything it produces is written here, so a
//! write error is the sink's to report, and a run's log is long dropped when
//! its files are written.

use crate::warning::Warning;
use std::path::Path;

use super::cache::{self, Cache, Probe};
use super::step::{Kept, Output, Wants};
use crate::fit::Intersample;
use crate::ingest::LogFile;
use crate::manifest::{Campaign, RunPlan, RunSource};
use crate::report::{FigureFiles, FigureFormats, FigureSpec, PageFigure, WriteError};

/// The output of a campaign's runs: where figures and tables go (nowhere when
/// the job writes none) and the cache, if any.
pub(super) struct Sink<'a> {
    /// The output folder, for the runs' tables; None writes none.
    pub out_dir: Option<&'a Path>,
    pub files: Option<&'a FigureFiles<'a>>,
    pub choice: FigureFormats,
    pub intersample: Intersample,
    pub cache: Option<&'a Cache>,
}

/// A run's outcome as the cache keeps it: what the campaign keeps of it,
/// and the files it wrote.
#[derive(Debug, Clone, serde::Serialize, serde::Deserialize)]
pub(super) struct Stored {
    kept: Kept,
    figures: Vec<PageFigure>,
    figure_warnings: Vec<Warning>,
    /// The figure and table files with their sizes, to tell they are still
    /// there.
    files: Vec<(String, u64)>,
}

/// What the cache knows of a run before it is done.
pub(super) enum Probed {
    /// Its stored outcome, the files it wrote still in place.
    Hit(Box<Stored>),
    /// The key to store its outcome under (None: not cached) and its log's
    /// bytes when they were read on the way.
    Miss {
        key: Option<String>,
        file: Option<LogFile>,
    },
}

/// A run done: what the campaign keeps of it and what was written for it.
pub(super) struct Done {
    pub kept: Kept,
    pub figures: Vec<PageFigure>,
    pub figure_warnings: Vec<Warning>,
    /// The run's tables as written (relative to the output folder).
    pub tables: Vec<String>,
    /// Why its log could not be read or analysed (never from the cache).
    pub log_error: Option<std::sync::Arc<crate::analysis::log_stage::LogStageError>>,
    pub seconds: f64,
    pub cached: bool,
}

impl Done {
    /// A run's outcome from the cache.
    pub(super) fn from_stored(s: Stored) -> Self {
        Self {
            tables: table_files(&s.files),
            kept: s.kept,
            figures: s.figures,
            figure_warnings: s.figure_warnings,
            log_error: None,
            seconds: 0.0,
            cached: true,
        }
    }
}

impl Sink<'_> {
    /// What the runs' steps are asked to build.
    pub(super) fn wants(&self) -> Wants {
        Wants {
            figures: self.files.is_some(),
            every_figure: self.files.is_some() && self.choice.every(),
            tables: self.out_dir.is_some(),
            intersample: self.intersample,
        }
    }

    /// The cache's verdict on a run; `parts` are what decide its outcome
    /// besides its plan and log (None: the run is not cached).
    pub(super) fn probe(
        &self,
        campaign: &Campaign,
        plan: &RunPlan,
        parts: Option<&[&dyn std::fmt::Debug]>,
    ) -> Probed {
        let (Some(cache), RunSource::Log(lp), Some(parts)) = (self.cache, &plan.source, parts)
        else {
            return Probed::Miss {
                key: None,
                file: None,
            };
        };
        // The plan as the manifest states it: its log relative to the
        // manifest's folder, so the key does not depend on the folder the job
        // ran from (shards on other machines find each other's runs).
        // A run's description and the lab's notes do not change what it
        // computes: they are left out of the key and put in a stored outcome
        // as the manifest says them now, so editing a note redoes no work.
        let mut keyed = plan.clone();
        keyed.description.clear();
        keyed.annotations.clear();
        if let (RunSource::Log(kp), Some(base)) = (&mut keyed.source, campaign.file.parent()) {
            kp.path = kp.path.strip_prefix(base).unwrap_or(&kp.path).to_path_buf();
        }
        let key = |sha: &str| {
            let mut all: Vec<&dyn std::fmt::Debug> = parts.to_vec();
            all.extend([&keyed as &dyn std::fmt::Debug, &self.choice, &sha]);
            cache::key(&all)
        };
        match cache.probe(&lp.path, lp.max_bytes, key, |s: &Stored| {
            self.still_there(s)
        }) {
            Probe::Hit(mut stored) => {
                stored.kept.result.description = plan.description.clone();
                stored.kept.result.annotations = plan.annotations.clone();
                Probed::Hit(Box::new(stored))
            }
            Probe::Miss { key, file } => Probed::Miss {
                key: Some(key),
                file,
            },
        }
    }

    /// Write a run's output as it arrives: its figures and tables, then its
    /// outcome into the cache under `key` when it may be cached.
    pub(super) fn keep(&self, key: Option<&str>, output: Output) -> Result<Done, WriteError> {
        let (figures, figure_warnings) = self.figures(&output.figures)?;
        let tables = match (&output.tables, self.out_dir) {
            (Some(t), Some(dir)) => t.write(dir)?,
            _ => Vec::new(),
        };
        if let (true, Some(cache), Some(key)) = (output.cacheable, self.cache, key) {
            let stored = Stored {
                kept: output.kept.clone(),
                files: self.sizes(&figures, &tables),
                figures: figures.clone(),
                figure_warnings: figure_warnings.clone(),
            };
            cache.store(key, &stored)?;
        }
        Ok(Done {
            kept: output.kept,
            figures,
            figure_warnings,
            tables,
            log_error: output.log_error,
            seconds: 0.0,
            cached: false,
        })
    }

    /// Draw figures into their files (none when the job draws none): each
    /// one's page entry, and a warning for each that could not be drawn.
    pub(super) fn figures(
        &self,
        specs: &[FigureSpec],
    ) -> Result<(Vec<PageFigure>, Vec<Warning>), WriteError> {
        match self.files {
            Some(files) if !specs.is_empty() => files.write(specs),
            _ => Ok((Vec::new(), Vec::new())),
        }
    }

    /// A publication's figures by their numbers, copied from the figures
    /// drawn (none when the job draws none).
    pub(super) fn numbered(
        &self,
        numbered: &[crate::manifest::NumberedFigure],
        drawn: &[&PageFigure],
    ) -> Result<(Vec<PageFigure>, Vec<Warning>), WriteError> {
        match self.files {
            Some(files) if !numbered.is_empty() => files.numbered(numbered, drawn),
            _ => Ok((Vec::new(), Vec::new())),
        }
    }

    /// Write what the cache keeps of the whole campaign (the log stamps) and
    /// forget what it no longer uses.
    pub(super) fn finish(&self) -> Result<(), WriteError> {
        match self.cache {
            Some(cache) => cache.finish(),
            None => Ok(()),
        }
    }

    /// The size of a file under the output folder, None when it is not
    /// there.
    fn size_of(&self, name: &str) -> Option<u64> {
        let dir = self.out_dir?;
        std::fs::metadata(dir.join(name)).ok().map(|m| m.len())
    }

    /// Whether every file `stored` wrote (figures, tables) is still there,
    /// as it was written.
    fn still_there(&self, stored: &Stored) -> bool {
        stored
            .files
            .iter()
            .all(|(name, size)| self.size_of(name) == Some(*size))
    }

    /// Each file a run wrote (its figures and tables), with its size.
    fn sizes(&self, figures: &[PageFigure], tables: &[String]) -> Vec<(String, u64)> {
        figures
            .iter()
            .flat_map(|f| [&f.png_file, &f.svg_file])
            .flatten()
            .chain(tables)
            .filter_map(|name| self.size_of(name).map(|size| (name.clone(), size)))
            .collect()
    }
}

/// The tables among the files a stored run wrote.
fn table_files(files: &[(String, u64)]) -> Vec<String> {
    files
        .iter()
        .map(|(name, _)| name)
        .filter(|name| name.starts_with("tables/"))
        .cloned()
        .collect()
}
