//! What is wrong with a manifest: each [`Problem`] with its key path, run and
//! line, and the [`ManifestError`] that carries every one of them at once.

use std::path::{Path, PathBuf};

use super::keypath::KeyPath;

/// One problem in a manifest.
#[derive(Debug, Clone, PartialEq)]
pub struct Problem {
    /// Where: the key path inside the manifest.
    pub path: KeyPath,
    /// The run's id when the problem is inside a run.
    pub run: Option<String>,
    /// Line and column (1-based) in a TOML manifest.
    pub line_col: Option<(usize, usize)>,
    pub message: String,
}

impl Problem {
    pub fn new(path: KeyPath, message: impl Into<String>) -> Self {
        Self {
            path,
            run: None,
            line_col: None,
            message: message.into(),
        }
    }
}

/// Why a manifest cannot be used.
#[derive(Debug, thiserror::Error)]
pub enum ManifestError {
    #[error("{}: cannot read the manifest: {source}", file.display())]
    Read {
        file: PathBuf,
        #[source]
        source: std::io::Error,
    },
    #[error("{}:{line}:{column}: {format} syntax error: {message}", file.display())]
    Syntax {
        file: PathBuf,
        format: &'static str,
        line: usize,
        column: usize,
        message: String,
    },
    #[error("{}", render(file, problems))]
    Invalid {
        file: PathBuf,
        problems: Vec<Problem>,
    },
}

fn render(file: &Path, problems: &[Problem]) -> String {
    let n = problems.len();
    let mut out = format!(
        "{}: {n} problem{} in the manifest:",
        file.display(),
        if n == 1 { "" } else { "s" }
    );
    for p in problems {
        out.push_str("\n  ");
        out.push_str(&file.display().to_string());
        if let Some((l, c)) = p.line_col {
            out.push_str(&format!(":{l}:{c}"));
        }
        out.push_str(&format!(": {}", p.path));
        if let Some(run) = &p.run {
            out.push_str(&format!(" (run \"{run}\")"));
        }
        out.push_str(&format!(": {}", p.message));
    }
    out
}
