//! Writing outputs. Every file is written to a temporary sibling and renamed
//! into place, so a reader never sees a half-written file and a failure never
//! destroys the previous output. `html` renders the campaign's page.

pub mod html;

pub mod figures;

pub mod logs;

use std::io::Write;
use std::path::{Path, PathBuf};

use crate::results::Results;

/// Why an output could not be written.
#[derive(Debug, thiserror::Error)]
pub enum WriteError {
    #[error(transparent)]
    Html(#[from] html::HtmlError),
    #[error("{}: {source}", path.display())]
    Io {
        path: PathBuf,
        #[source]
        source: std::io::Error,
    },
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

/// Render every figure (in parallel; bytes do not depend on the thread
/// count) and write `figures/<id>.png` and `.svg` into `out_dir`. A figure
/// that cannot be drawn is reported in the returned warnings and left out;
/// it never stops the report.
pub fn write_figures(
    specs: &[FigureSpec],
    out_dir: &Path,
) -> Result<(Vec<html::PageFigure>, Vec<String>), WriteError> {
    let jobs: Vec<(figures::Figure, (u32, u32))> =
        specs.iter().map(|s| (s.figure.clone(), s.size)).collect();
    let rendered = figures::render_many(&jobs);
    let mut page = Vec::new();
    let mut warnings = Vec::new();
    for (spec, r) in specs.iter().zip(rendered) {
        match r {
            Ok(r) => {
                let png = out_dir.join("figures").join(format!("{}.png", spec.id));
                let svg_name = format!("figures/{}.svg", spec.id);
                write_atomic(&png, &r.png)?;
                write_atomic(&out_dir.join(&svg_name), r.svg.as_bytes())?;
                page.push(html::PageFigure::new(
                    &spec.id,
                    &spec.title,
                    &spec.caption,
                    &r.png,
                    Some(svg_name),
                ));
            }
            Err(e) => warnings.push(format!("figure {}: {e}", spec.id)),
        }
    }
    Ok((page, warnings))
}

/// Write `bytes` to `path` atomically (temporary file, fsync, rename).
pub fn write_atomic(path: &Path, bytes: &[u8]) -> Result<(), WriteError> {
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
        f.write_all(bytes)?;
        f.sync_all()?;
        std::fs::rename(&tmp, path)
    })();
    if result.is_err() {
        let _ = std::fs::remove_file(&tmp);
    }
    result.map_err(io)
}

/// results.json as bytes: pretty JSON with a trailing newline. Floats are
/// printed shortest-round-trip, so equal results give equal bytes.
pub fn results_json(results: &Results) -> Vec<u8> {
    let mut s = serde_json::to_string_pretty(results).expect("results serialise");
    s.push('\n');
    s.into_bytes()
}

/// Write the HTML report `report.html` into `out_dir`; returns its path.
pub fn write_page(
    results: &Results,
    figures: &[html::PageFigure],
    notice: Option<&str>,
    out_dir: &Path,
) -> Result<PathBuf, WriteError> {
    let page = html::render(results, figures, notice)?;
    let path = out_dir.join("report.html");
    write_atomic(&path, page.as_bytes())?;
    Ok(path)
}

/// Write `results.json` into `out_dir`; returns its path.
pub fn write_results(results: &Results, out_dir: &Path) -> Result<PathBuf, WriteError> {
    let path = out_dir.join("results.json");
    write_atomic(&path, &results_json(results))?;
    Ok(path)
}
