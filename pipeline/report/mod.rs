//! Writing outputs: results.json, the figures, the campaign's page
//! (`html`), named columns as CSV or Parquet (`columns`: the simulator's
//! logs, the runs' tables, the history). Every file is written to a
//! temporary sibling and renamed into place, so a reader never sees a
//! half-written file; the files of one job are written as a set into a work
//! folder that replaces the output folder at the end ([`OutputFolder`]), so a
//! reader never sees a mix of two jobs' files and a failure never destroys
//! the previous output.

pub mod html;

pub mod figures;

pub mod columns;

pub mod matlab;

pub mod models;

pub mod tables;

pub mod history;

pub mod output_folder;

pub use html::{PageFigure, design_page};
pub use output_folder::OutputFolder;

use crate::warning::Warning;
use std::io::Write;
use std::path::{Path, PathBuf};

use crate::results::Results;

/// Why an output could not be written.
#[derive(Debug, thiserror::Error)]
pub enum WriteError {
    #[error(transparent)]
    Html(#[from] html::HtmlError),
    #[error(transparent)]
    Table(Box<columns::ColumnWriteError>),
    #[error("{}: {source}", path.display())]
    Io {
        path: PathBuf,
        #[source]
        source: std::io::Error,
    },
    /// The output folder cannot take the outputs; found before computing.
    #[error("{}: {why}", path.display())]
    OutFolder { path: PathBuf, why: String },
    /// What a run was writing (a figure, a table, its cache entry) when
    /// the write failed.
    #[error("run {run}: {source}")]
    Run {
        run: String,
        #[source]
        source: Box<WriteError>,
    },
}

impl WriteError {
    /// This error, said of run `id`.
    pub fn in_run(self, id: &str) -> Self {
        Self::Run {
            run: id.to_string(),
            source: Box::new(self),
        }
    }

    /// This error with every path it names passed through `f` (a work
    /// folder's paths named as the output folder's, see [`OutputFolder`]).
    pub fn map_paths(self, f: &dyn Fn(&Path) -> PathBuf) -> Self {
        match self {
            Self::Io { path, source } => Self::Io {
                path: f(&path),
                source,
            },
            Self::OutFolder { path, why } => Self::OutFolder {
                path: f(&path),
                why,
            },
            Self::Run { run, source } => Self::Run {
                run,
                source: Box::new(source.map_paths(f)),
            },
            Self::Table(e) => Self::Table(Box::new(e.map_paths(f))),
            e @ Self::Html(_) => e,
        }
    }
}

/// One figure to draw, with what the page says of it.
#[derive(Debug, Clone)]
pub struct FigureSpec {
    /// File stem under `figures/` and the anchor on the page.
    pub id: String,
    pub title: String,
    pub caption: String,
    pub figure: figures::Figure,
    pub size: (u32, u32),
}

/// What a run's log gave, as its figures and tables show it: borrowed from
/// the run's analysis while its log is in memory.
#[derive(Debug, Clone, Copy)]
pub struct Measured<'a> {
    pub sample_rate_hz: f64,
    /// Command to displacement.
    pub frf: &'a crate::frf::Frf,
    /// Command to force, when the log has a force channel.
    pub force_frf: Option<&'a crate::frf::Frf>,
    /// The bins the run's fit used (band and coherence).
    pub mask: &'a [bool],
    /// The run's own fit, when it has one.
    pub fit: Option<&'a crate::fit::TfFit>,
}

impl<'a> Measured<'a> {
    /// A log stage as its figures and tables show it.
    pub fn of(stage: &'a crate::analysis::log_stage::LogStage) -> Self {
        Self {
            sample_rate_hz: stage.log.sample_rate_hz,
            frf: &stage.frf,
            force_frf: stage.force_frf.as_ref(),
            mask: &stage.mask,
            fit: stage.fit.as_ref(),
        }
    }
}

pub use crate::manifest::FigureFormats;

impl FigureFormats {
    /// As `--figures` names it.
    pub fn as_str(self) -> &'static str {
        match self {
            FigureFormats::All => "all",
            FigureFormats::Png => "png",
            FigureFormats::Svg => "svg",
            FigureFormats::Summary => "summary",
            FigureFormats::None => "none",
        }
    }

    /// Whether every figure is drawn, not only the summary's.
    pub fn every(self) -> bool {
        self != FigureFormats::Summary
    }

    /// What to render, or None when nothing is drawn.
    fn formats(self) -> Option<figures::Formats> {
        let (png, svg) = match self {
            FigureFormats::All => (true, true),
            FigureFormats::Png | FigureFormats::Summary => (true, false),
            FigureFormats::Svg => (false, true),
            FigureFormats::None => return None,
        };
        Some(figures::Formats { png, svg })
    }

    /// What a page says in place of its figures when none were drawn.
    fn note(self) -> Option<&'static str> {
        (self == FigureFormats::None)
            .then_some("No figures were drawn for this report (--figures none).")
    }

    /// What a page says below its figures when only the summary's were
    /// drawn.
    fn more(self) -> Option<&'static str> {
        (self == FigureFormats::Summary).then_some(
            "The summary's figures (--figures summary, the default of a campaign that numbers no publication's figures). \
             `--figures all`, or report.figures = \"all\" in the manifest, also draws each run's residual, \
             state trajectory and force path, a validation run's compensator, and SVG files.",
        )
    }
}

/// Where figures go: `figures/<id>.png` and `.svg` under an output folder,
/// in the formats asked for.
#[derive(Debug, Clone, Copy)]
pub struct FigureFiles<'a> {
    out_dir: &'a Path,
    formats: figures::Formats,
}

impl<'a> FigureFiles<'a> {
    /// None when `choice` draws no figure.
    pub fn new(out_dir: &'a Path, choice: FigureFormats) -> Option<Self> {
        Some(Self {
            out_dir,
            formats: choice.formats()?,
        })
    }

    /// The size of a figure file (named relative to the output folder),
    /// None when it is not there.
    pub fn size_of(&self, name: &str) -> Option<u64> {
        std::fs::metadata(self.out_dir.join(name))
            .ok()
            .map(|m| m.len())
    }

    /// Render the figures (in parallel; bytes do not depend on the thread
    /// count) and write their files. A figure that cannot be drawn is
    /// reported in the returned warnings and left out; it never stops the
    /// report.
    pub fn write(
        &self,
        specs: &[FigureSpec],
    ) -> Result<(Vec<PageFigure>, Vec<Warning>), WriteError> {
        let jobs: Vec<(&figures::Figure, (u32, u32))> =
            specs.iter().map(|s| (&s.figure, s.size)).collect();
        let rendered = figures::render_many(&jobs, self.formats);
        let mut page = Vec::new();
        let mut warnings = Vec::new();
        for (spec, r) in specs.iter().zip(rendered) {
            let r = match r {
                Ok(r) => r,
                Err(e) => {
                    warnings.push(Warning::new(
                        format!("figure {} not drawn", spec.id),
                        format!("figure {}: {e}", spec.id),
                    ));
                    continue;
                }
            };
            let mut fig = PageFigure::new(&spec.id, &spec.title, &spec.caption);
            if let Some(png) = &r.png {
                let name = format!("figures/{}.png", spec.id);
                write_artifact(&self.out_dir.join(&name), png)?;
                fig.png_file = Some(name);
            }
            if let Some(svg) = &r.svg {
                let name = format!("figures/{}.svg", spec.id);
                write_artifact(&self.out_dir.join(&name), svg.as_bytes())?;
                fig.svg_file = Some(name);
            }
            page.push(fig);
        }
        Ok((page, warnings))
    }
}

impl FigureFiles<'_> {
    /// A publication's figures by their numbers (`numbered`), each a copy
    /// of the drawn figure it names (`drawn`: run and campaign figures
    /// alike), written beside it as `figures/fig-<number>.<ext>`: their
    /// page entries, titled by their numbers, and a warning for each that
    /// names a figure not drawn.
    pub fn numbered(
        &self,
        numbered: &[crate::manifest::NumberedFigure],
        drawn: &[&PageFigure],
    ) -> Result<(Vec<PageFigure>, Vec<Warning>), WriteError> {
        let mut page = Vec::new();
        let mut warnings = Vec::new();
        for n in numbered {
            let Some(id) = &n.figure else { continue };
            let Some(source) = drawn.iter().find(|f| &f.id == id) else {
                warnings.push(Warning::new(
                    format!("numbered_figures: Fig. {}: no figure {id}", n.number),
                    format!(
                        "numbered_figures: Fig. {} names the figure {id}, which this campaign did not draw; its figures are {}",
                        n.number,
                        drawn.iter().map(|f| f.id.as_str()).collect::<Vec<_>>().join(", ")
                    ),
                ));
                continue;
            };
            let stem = n.stem();
            let mut fig = PageFigure::new(&stem, &format!("Fig. {}", n.number), &n.caption);
            let copy = |file: &str, ext: &str| -> Result<String, WriteError> {
                let from = self.out_dir.join(file);
                let bytes = std::fs::read(&from).map_err(|source| WriteError::Io {
                    path: from.clone(),
                    source,
                })?;
                let name = format!("figures/{stem}.{ext}");
                write_artifact(&self.out_dir.join(&name), &bytes)?;
                Ok(name)
            };
            if let Some(png) = &source.png_file {
                fig.png_file = Some(copy(png, "png")?);
            }
            if let Some(svg) = &source.svg_file {
                fig.svg_file = Some(copy(svg, "svg")?);
            }
            page.push(fig);
        }
        Ok((page, warnings))
    }
}

/// Write a document to `path` atomically and durably (temporary file,
/// fsync, rename): results.json, the campaign page, the history, what a
/// later run or a reviewer trusts as the record. Call [`settle`] first so
/// that what the document refers to is on disk before it is.
pub fn write_atomic(path: &Path, bytes: &[u8]) -> Result<(), WriteError> {
    replace(path, bytes, true)
}

/// Write a run's artifact to `path` atomically (temporary file, rename),
/// without waiting for the disk: figures, tables, run pages, cache entries,
/// simulated logs. A reader never sees half a file; after a crash an
/// artifact may be lost or empty, which the cache treats as a miss and a
/// rerun writes again. One [`settle`] before the campaign's documents makes
/// them durable together: an fsync per file cost a night of 100 Parquet
/// logs 12 % of its wall time.
pub fn write_artifact(path: &Path, bytes: &[u8]) -> Result<(), WriteError> {
    replace(path, bytes, false)
}

fn replace(path: &Path, bytes: &[u8], sync: bool) -> Result<(), WriteError> {
    replace_with(path, sync, |f| f.write_all(bytes))
}

/// Write `value` as indented JSON (as [`json_bytes`] gives it) to `path`
/// atomically and durably, streamed: a night's results.json of 3,000 runs
/// is 130 MB, which the job need not hold as text besides the results.
/// Returns the file's SHA-256, taken on the way.
pub fn write_json(path: &Path, value: &impl serde::Serialize) -> Result<String, WriteError> {
    use sha2::Digest;
    struct Hashing<W> {
        inner: W,
        hash: sha2::Sha256,
    }
    impl<W: Write> Write for Hashing<W> {
        fn write(&mut self, buf: &[u8]) -> std::io::Result<usize> {
            let n = self.inner.write(buf)?;
            self.hash.update(&buf[..n]);
            Ok(n)
        }
        fn flush(&mut self) -> std::io::Result<()> {
            self.inner.flush()
        }
    }
    let mut sha = String::new();
    write_streamed(path, |w| {
        let mut w = Hashing {
            inner: w,
            hash: sha2::Sha256::new(),
        };
        serde_json::to_writer_pretty(&mut w, value).map_err(std::io::Error::from)?;
        w.write_all(b"\n")?;
        sha = format!("{:x}", w.hash.finalize());
        Ok(())
    })?;
    Ok(sha)
}

/// Write `path` atomically and durably, as [`write_atomic`] does, its
/// bytes streamed by `write` through a buffer that may seek (models.mat
/// writes its runs' size once they are written).
pub fn write_streamed(
    path: &Path,
    write: impl FnOnce(&mut std::io::BufWriter<&mut std::fs::File>) -> std::io::Result<()>,
) -> Result<(), WriteError> {
    replace_with(path, true, |f| {
        let mut w = std::io::BufWriter::with_capacity(1 << 16, f);
        write(&mut w)?;
        w.flush()
    })
}

/// Write `path` through a temporary file beside it, renamed into place
/// (`sync`: fsync'd first), the temporary file removed on failure.
fn replace_with(
    path: &Path,
    sync: bool,
    write: impl FnOnce(&mut std::fs::File) -> std::io::Result<()>,
) -> Result<(), WriteError> {
    let io = |source| WriteError::Io {
        path: path.to_path_buf(),
        source,
    };
    let dir = path.parent().unwrap_or(Path::new("."));
    std::fs::create_dir_all(dir).map_err(io)?;
    let name = path
        .file_name()
        .map(|n| n.to_string_lossy().into_owned())
        .unwrap_or_default();
    let tmp = dir.join(format!(".{name}.tmp-{}", std::process::id()));
    let result = (|| {
        let mut f = std::fs::File::create(&tmp)?;
        write(&mut f)?;
        if sync {
            f.sync_all()?;
        }
        std::fs::rename(&tmp, path)
    })();
    if result.is_err() {
        let _ = std::fs::remove_file(&tmp);
    }
    result.map_err(io)
}

/// Put every artifact written so far under `dir` on disk: one syncfs(2) of
/// its file system on Linux (elsewhere the documents' own fsync is all).
pub fn settle(dir: &Path) -> Result<(), WriteError> {
    #[cfg(target_os = "linux")]
    {
        use std::os::fd::AsRawFd;
        let io = |source| WriteError::Io {
            path: dir.to_path_buf(),
            source,
        };
        let handle = std::fs::File::open(dir).map_err(io)?;
        // SAFETY: syncfs takes an open descriptor, which `handle` owns for
        // the length of the call.
        if unsafe { libc::syncfs(handle.as_raw_fd()) } != 0 {
            return Err(io(std::io::Error::last_os_error()));
        }
    }
    #[cfg(not(target_os = "linux"))]
    let _ = dir;
    Ok(())
}

/// A JSON document as servoid writes it (results.json, truth.json, the
/// schemas): pretty, with a trailing newline. Floats are printed
/// shortest-round-trip, so equal values give equal bytes.
pub fn json_bytes(value: &impl serde::Serialize) -> Vec<u8> {
    let mut s = serde_json::to_string_pretty(value).expect("servoid's outputs serialise to JSON");
    s.push('\n');
    s.into_bytes()
}

/// The folders of an output folder that hold only what servoid writes.
pub const OWN_FOLDERS: [&str; 3] = ["figures", "runs", "tables"];

/// Remove from servoid's own folders of `out_dir` ([`OWN_FOLDERS`]) every
/// file this job did not write or keep: `keep` names the set's files
/// relative to `out_dir`, `/`-separated. The set starts as a copy of the
/// previous one, so without this a run dropped from the campaign, a figure
/// format no longer drawn (`--figures none`) or a table a run no longer
/// writes would stay beside the new outputs.
pub fn prune(out_dir: &Path, keep: &std::collections::BTreeSet<String>) -> Result<(), WriteError> {
    for folder in OWN_FOLDERS {
        let dir = out_dir.join(folder);
        let Ok(entries) = std::fs::read_dir(&dir) else {
            continue;
        };
        let mut names: Vec<String> = entries
            .flatten()
            .filter(|e| e.file_type().is_ok_and(|t| !t.is_dir()))
            .map(|e| e.file_name().to_string_lossy().into_owned())
            .collect();
        names.sort();
        for name in names {
            let rel = format!("{folder}/{name}");
            if keep.contains(&rel) {
                continue;
            }
            let path = dir.join(&name);
            std::fs::remove_file(&path).map_err(|source| WriteError::Io { path, source })?;
        }
    }
    Ok(())
}

/// The record of an output set: `<sha256>  <file>` per output file,
/// sorted by file, as `sha256sum` writes and checks it.
pub const RECORD: &str = "outputs.sha256";

/// Write [`RECORD`] into `out_dir` for `files` (relative to it,
/// `/`-separated), each hashed as it is now on disk.
pub fn write_record(
    out_dir: &Path,
    files: &std::collections::BTreeSet<String>,
) -> Result<(), WriteError> {
    let mut text = String::new();
    for name in files {
        let path = out_dir.join(name);
        let sha =
            crate::ingest::file_sha256(&path).map_err(|source| WriteError::Io { path, source })?;
        text.push_str(&format!("{sha}  {name}\n"));
    }
    write_atomic(&out_dir.join(RECORD), text.as_bytes())
}

/// Write the campaign's page `report.html` and each run's page
/// `runs/<id>.html` into `out_dir`; returns the campaign page's path.
/// `run_figures` follow `results.runs`; `choice` is what the figures were
/// drawn as (a page without figures says why).
pub fn write_pages(
    results: &Results,
    run_figures: &[Vec<PageFigure>],
    campaign_figures: &[PageFigure],
    choice: FigureFormats,
    out_dir: &Path,
) -> Result<PathBuf, WriteError> {
    let pages = html::Pages::new(results, choice)?;
    for (run, figures) in results.runs.iter().zip(run_figures) {
        let page = pages.run(run, figures)?;
        write_artifact(&out_dir.join(html::run_page(&run.id)), page.as_bytes())?;
    }
    let path = out_dir.join("report.html");
    settle(out_dir)?;
    // A failed write is the file's error; any other, the template's.
    let mut template = None;
    let written = write_streamed(&path, |w| {
        pages
            .campaign(campaign_figures, w)
            .map_err(|e| match e.write_failure() {
                Some(io) => io,
                None => {
                    template = Some(e);
                    std::io::Error::other("the page's template failed")
                }
            })
    });
    if let Some(e) = template {
        return Err(e.into());
    }
    written?;
    Ok(path)
}

/// run.jsonl: when the campaign ran and how long each run's log took. Wall
/// clocks and durations live here, never in results.json, whose bytes
/// depend on the inputs alone.
pub struct RunLog<'a> {
    pub started: std::time::SystemTime,
    pub seconds: f64,
    pub jobs: usize,
    pub runs: &'a [crate::results::RunResult],
    pub run_seconds: &'a [f64],
    pub cached: &'a [bool],
}

impl RunLog<'_> {
    pub fn jsonl(&self) -> Vec<u8> {
        let mut out = Vec::new();
        let mut line = |v: serde_json::Value| {
            out.extend_from_slice(v.to_string().as_bytes());
            out.push(b'\n');
        };
        let n = self.runs.len();
        line(serde_json::json!({
            "event": "campaign",
            "started": humantime::format_rfc3339_millis(self.started).to_string(),
            "seconds": self.seconds,
            "runs": n,
            "logs_per_s": n as f64 / self.seconds.max(1e-9),
            "jobs": self.jobs,
            "servoid_version": env!("CARGO_PKG_VERSION"),
        }));
        for ((run, seconds), cached) in self.runs.iter().zip(self.run_seconds).zip(self.cached) {
            line(serde_json::json!({
                "event": "run",
                "run": run.id,
                "status": run.status,
                "cached": cached,
                "seconds": seconds,
            }));
        }
        out
    }
}

/// The files this job's set holds in servoid's own folders (figures, run
/// pages, tables), relative to the output folder.
pub fn set_files(
    results: &crate::results::Results,
    run_figures: &[Vec<html::PageFigure>],
    run_tables: &[Vec<String>],
    campaign_figures: &[html::PageFigure],
) -> std::collections::BTreeSet<String> {
    let figures = run_figures
        .iter()
        .flatten()
        .chain(campaign_figures)
        .flat_map(|f| [&f.png_file, &f.svg_file])
        .flatten()
        .cloned();
    let pages = results.runs.iter().map(|r| html::run_page(&r.id));
    let tables = run_tables
        .iter()
        .flatten()
        .cloned()
        .chain([tables::TRACKING_TABLE.to_string()]);
    figures.chain(pages).chain(tables).collect()
}

/// Write the JSON Schemas of both manifests and of results.json into `dir`.
pub fn write_schemas(dir: &Path) -> Result<Vec<PathBuf>, WriteError> {
    schemas()
        .into_iter()
        .map(|(name, value)| {
            let path = dir.join(name);
            write_atomic(&path, &json_bytes(&value))?;
            Ok(path)
        })
        .collect()
}

/// The committed schema files under `schemas/`, with their contents.
pub fn schemas() -> Vec<(&'static str, serde_json::Value)> {
    vec![
        ("manifest.schema.json", crate::manifest::manifest_schema()),
        ("results.schema.json", crate::results::results_schema()),
        (
            "simulation.schema.json",
            crate::manifest::simulation_schema(),
        ),
    ]
}
