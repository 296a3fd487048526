//! What is wrong with a manifest: each [`Problem`] with its key path, run and
//! line (or, in a run table, its file, row and column), and the
//! [`ManifestError`] that carries every one of them at once.

use std::path::{Path, PathBuf};

use super::keypath::KeyPath;

/// One problem in a manifest or in the run table it names.
#[derive(Debug, Clone, PartialEq)]
pub struct Problem {
    /// Where: the key path inside the manifest. A run-table problem points
    /// at `run_table.file`, which orders it among the manifest's problems.
    pub path: KeyPath,
    /// The run's id when the problem is inside a run (and the id was read).
    pub run: Option<String>,
    /// Line and column (1-based) in a TOML manifest.
    pub line_col: Option<(usize, usize)>,
    /// Where in the run table, for a problem of the table: it is named by
    /// this instead of by `path` and `line_col`.
    pub table: Option<TablePlace>,
    pub message: String,
    /// For an unknown key, the known key its suggestion names: that key's
    /// own "missing" problem is then left out (it says the same thing).
    pub meant: Option<KeyPath>,
    /// A value `servoid init` left for the lab to fill (a manifest's key or
    /// a run table's cell): while any is left, only these are reported.
    pub placeholder: bool,
}

/// A place in a run table.
#[derive(Debug, Clone, PartialEq, Eq, PartialOrd, Ord)]
pub struct TablePlace {
    /// The table file as the manifest names it.
    pub file: String,
    /// The 1-based data row (the header is not a row), for a problem of one
    /// row.
    pub row: Option<usize>,
    /// The column, for a problem of one column.
    pub column: Option<String>,
}

impl Problem {
    pub fn new(path: KeyPath, message: impl Into<String>) -> Self {
        Self {
            path,
            run: None,
            line_col: None,
            table: None,
            message: message.into(),
            meant: None,
            placeholder: false,
        }
    }

    /// A problem of a run table, at `place`, in the run `run` when its id
    /// was read.
    pub fn in_table(place: TablePlace, run: Option<String>, message: impl Into<String>) -> Self {
        Self {
            path: KeyPath::root().key("run_table").key("file"),
            run,
            line_col: None,
            table: Some(place),
            message: message.into(),
            meant: None,
            placeholder: false,
        }
    }
}

/// The largest manifest servoid reads (16 MiB: some 100,000 runs written
/// out in full). Anything larger is not a manifest (`/dev/zero` was read
/// until memory ran out).
pub const MAX_MANIFEST_BYTES: u64 = 16 << 20;

/// Why a manifest cannot be used.
#[derive(Debug, thiserror::Error)]
pub enum ManifestError {
    #[error("{}: cannot read the manifest: {source}", file.display())]
    Read {
        file: PathBuf,
        #[source]
        source: std::io::Error,
    },
    #[error(
        "{}: the manifest is larger than {} MiB; reading stopped there. A manifest describes runs, not their data: give long run lists as a run table (`run_table`) and data as log files",
        file.display(),
        MAX_MANIFEST_BYTES >> 20
    )]
    TooLarge { file: PathBuf },
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
        match &p.table {
            Some(t) => out.push_str(&table_place(t, p.run.as_deref())),
            None => out.push_str(&key_place(file, p)),
        }
        out.push_str(&format!(": {}", p.message));
    }
    out
}

/// `campaign.toml:12:3: runs[2].p_gain (run "k2")`
fn key_place(file: &Path, p: &Problem) -> String {
    let mut out = file.display().to_string();
    if let Some((l, c)) = p.line_col {
        out.push_str(&format!(":{l}:{c}"));
    }
    out.push_str(&format!(": {}", p.path));
    if let Some(run) = &p.run {
        out.push_str(&format!(" (run \"{run}\")"));
    }
    out
}

/// `night/specimens.csv: row 7 (run "k2"), column stiffness_n_per_m`, or
/// without the row or the column where the problem is not in one.
fn table_place(t: &TablePlace, run: Option<&str>) -> String {
    let mut out = t.file.clone();
    if let Some(row) = t.row {
        out.push_str(&format!(": row {row}"));
        if let Some(run) = run {
            out.push_str(&format!(" (run \"{run}\")"));
        }
    }
    match (&t.column, t.row) {
        (Some(c), Some(_)) => out.push_str(&format!(", column {c}")),
        (Some(c), None) => out.push_str(&format!(": column {c}")),
        (None, _) => {}
    }
    out
}
