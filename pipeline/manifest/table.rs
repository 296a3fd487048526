//! The run table (`[run_table]`): one run per row of a CSV or Parquet side
//! table (read by [`ingest::read_table`]), its cells checked as a `[[runs]]`
//! table's keys are (the same slug, sign and specimen checks), and each
//! row's log found: its `log` cell, else the file `logs` matched whose stem
//! is the run's id. Every problem names the table file, the 1-based data
//! row, the run (when its id was read) and the column.
//!
//! A nightly batch runs over logs that are not all there yet: a row whose
//! log is missing is no problem here (its run is planned with the path
//! expected and fails alone when it is read), and a matched log that no run
//! uses is a warning, not an error.

use crate::warning::Warning;
use std::collections::{BTreeMap, BTreeSet};
use std::path::{Path, PathBuf};

use super::checks::{check_slug, check_specimen, normalise_date, positive};
use super::document::{closest, suggest};
use super::keypath::{KeyPath, Seg};
use super::problem::{Problem, TablePlace};
use super::raw::{Role, RunTable, Specimen};
use super::scaffold::PLACEHOLDER;
use crate::ingest::{self, LogFormat, TableFormat};
use crate::model::SpecimenModel;

/// The run table's provenance: which file, its hash and its rows.
#[derive(
    Debug, Clone, PartialEq, Eq, serde::Serialize, serde::Deserialize, schemars::JsonSchema,
)]
pub struct RunTableInfo {
    /// The table file as the manifest names it.
    pub file: String,
    /// SHA-256 of the table's bytes (lowercase hexadecimal).
    pub sha256: String,
    /// Data rows that name a run (a blank line is no run).
    pub rows: usize,
}

/// The table's columns, and whether each is required.
const COLUMNS: [(&str, bool); 9] = [
    ("id", true),
    ("role", true),
    ("p_gain", true),
    ("mass_kg", false),
    ("damping_ns_per_m", false),
    ("stiffness_n_per_m", false),
    ("date", false),
    ("log", false),
    ("description", false),
];

/// A row that passed its checks.
#[derive(Debug, Clone)]
pub(super) struct TableRun {
    pub id: String,
    pub role: Role,
    pub p_gain: f64,
    pub specimen: SpecimenModel,
    pub date: Option<String>,
    /// Its log (which may not exist yet) and the log's format; None for a
    /// validation run without one, a prediction as in `[[runs]]`.
    pub log: Option<(PathBuf, LogFormat)>,
    /// The `description` cell, or empty.
    pub description: String,
    /// The row's cells in the lab's own columns (a `notes`, an
    /// `operator`), by column, empty cells left out.
    pub annotations: BTreeMap<String, String>,
}

/// What a non-blank row says about its run, read leniently (whatever its
/// other cells' problems), for the campaign's checks across runs: unique
/// ids, where the rig comes from, what references may name.
#[derive(Debug, Clone)]
pub(super) struct RowKey {
    /// 1-based data row.
    pub row: usize,
    pub id: Option<String>,
    pub role: Option<Role>,
    pub has_mass: bool,
}

/// The run table, checked.
#[derive(Debug, Default)]
pub(super) struct CheckedTable {
    /// The runs of the rows that passed every check, in table order.
    pub runs: Vec<TableRun>,
    /// Every non-blank row's key, in table order.
    pub keys: Vec<RowKey>,
    /// None when the table could not be read (the problem is recorded).
    pub info: Option<RunTableInfo>,
    pub warnings: Vec<Warning>,
}

/// The logs `[run_table] logs` names.
struct Matched {
    /// As the manifest gives it, for messages.
    spec: String,
    /// `logs` joined to the manifest's folder, unescaped: where a missing
    /// log is expected.
    target: PathBuf,
    /// The manifest's folder, which messages name files relative to.
    base_dir: PathBuf,
    glob: bool,
    /// Every matched file, sorted, so that nothing depends on the order the
    /// file system lists them in.
    files: Vec<PathBuf>,
    /// Folder links the walk did not follow, each with the ancestor it
    /// leads back to (a loop), sorted.
    loops: Vec<(PathBuf, PathBuf)>,
}

/// How deep a `**` glob walks below its literal folder: deeper than any
/// lab's log tree (date/rig/run is three), shallow enough that a walk
/// through links that fan out without looping still ends.
pub const GLOB_MAX_DEPTH: usize = 32;

/// The files `spec` (a glob relative to `base_dir`) matches, and the
/// folder links that loop back to an ancestor (not followed). The walk
/// starts at the glob's literal folders, follows folder links (labs link
/// log folders in) unless one leads back to its own ancestor, and goes
/// [`GLOB_MAX_DEPTH`] deep for a `**`, else as deep as the glob has
/// components. `*` and `?` do not cross a `/`; a file or folder whose name
/// starts with `.` matches only a pattern that starts it with a literal dot.
#[allow(clippy::type_complexity)]
fn walk_glob(
    spec: &str,
    base_dir: &Path,
) -> Result<(Vec<PathBuf>, Vec<(PathBuf, PathBuf)>), glob::PatternError> {
    let mut root = base_dir.to_path_buf();
    let mut rest: Vec<String> = Vec::new();
    for c in Path::new(spec).components() {
        let part = c.as_os_str().to_string_lossy().into_owned();
        if rest.is_empty() && !part.contains(['*', '?', '[']) {
            root.push(c);
        } else {
            rest.push(part);
        }
    }
    let pattern = glob::Pattern::new(&rest.join("/"))?;
    let options = glob::MatchOptions {
        require_literal_separator: true,
        require_literal_leading_dot: true,
        ..glob::MatchOptions::new()
    };
    let depth = if rest.iter().any(|p| p.contains("**")) {
        GLOB_MAX_DEPTH
    } else {
        rest.len()
    };
    let (mut files, mut loops) = (Vec::new(), Vec::new());
    let walk = walkdir::WalkDir::new(&root)
        .follow_links(true)
        .min_depth(1)
        .max_depth(depth);
    for entry in walk {
        match entry {
            Ok(e) if e.file_type().is_file() => {
                let rel = e.path().strip_prefix(&root).unwrap_or(e.path());
                if pattern.matches_path_with(rel, options) {
                    files.push(e.into_path());
                }
            }
            Ok(_) => {}
            // A loop is named; a folder that cannot be read is skipped, as
            // the glob crate's walk skipped it.
            Err(err) => {
                if let (Some(ancestor), Some(link)) = (err.loop_ancestor(), err.path()) {
                    loops.push((link.to_path_buf(), ancestor.to_path_buf()));
                }
            }
        }
    }
    loops.sort();
    Ok((files, loops))
}

/// Where the rows without a `log` cell find theirs.
#[derive(Clone, Copy)]
enum LogSource<'a> {
    /// `[run_table]` gives no `logs`.
    None,
    /// `logs` is wrong (its problem is reported), so rows are not judged by
    /// it.
    Broken,
    Matched(&'a Matched),
}

/// Read and check the run table `spec` names; `base_dir` is the manifest's
/// folder and `run_logs` the logs `[[runs]]` name (those are used, so not
/// reported as unused when the table's `logs` also match them).
pub(super) fn check_table(
    spec: &RunTable,
    base_dir: &Path,
    run_logs: &[PathBuf],
    problems: &mut Vec<Problem>,
) -> CheckedTable {
    let at_file = |message: String| {
        let place = TablePlace {
            file: spec.file.clone(),
            row: None,
            column: None,
        };
        Problem::in_table(place, None, message)
    };
    let path = base_dir.join(&spec.file);
    let Some(format) = spec.format.or_else(|| TableFormat::from_path(&path)) else {
        problems.push(at_file(
            "cannot tell the table's format from its extension; give [run_table] format = \"csv\" or \"parquet\"".into(),
        ));
        return CheckedTable::default();
    };
    let Some(text) = table_text(spec, format, &mut |m| problems.push(at_file(m))) else {
        return CheckedTable::default();
    };
    let table = match ingest::read_table_as(&path, format, text) {
        Ok(t) => t,
        Err(e) => {
            problems.push(at_file(e.problem.to_string()));
            return CheckedTable::default();
        }
    };
    let (columns, annotations) = check_columns(&spec.file, &table.columns, problems);
    let mut matched = spec
        .logs
        .as_ref()
        .map(|l| match_logs(l, base_dir, problems));
    // The table is not one of its own logs (it may sit among them, a CSV
    // in a folder of CSV logs).
    if let Some(Some(m)) = &mut matched {
        let own = same_file(&path);
        m.files.retain(|f| same_file(f) != own);
    }
    let source = match &matched {
        None => LogSource::None,
        Some(None) => LogSource::Broken,
        Some(Some(m)) => LogSource::Matched(m),
    };
    let table_dir = path.parent().unwrap_or(Path::new(""));
    let mut out = CheckedTable::default();
    let mut used: BTreeSet<PathBuf> = run_logs.iter().map(|p| same_file(p)).collect();
    for (i, cells) in table.rows.iter().enumerate() {
        if cells.iter().all(Option::is_none) {
            continue;
        }
        let row = Row {
            file: &spec.file,
            number: i + 1,
            cells,
            columns: &columns,
            annotations: &annotations,
            decimal_comma: table.decimal_comma,
        };
        let (key, run) = check_row(&row, table_dir, source, spec.predict, problems);
        if let Some(run) = run {
            if let Some((log, _)) = &run.log {
                used.insert(same_file(log));
            }
            out.runs.push(run);
        }
        out.keys.push(key);
    }
    if let LogSource::Matched(m) = source {
        out.warnings = unused_logs(m, &used);
    }
    out.info = Some(RunTableInfo {
        file: spec.file.clone(),
        sha256: table.sha256,
        rows: out.keys.len(),
    });
    out
}

/// The CSV options `[run_table]` gives (`delimiter`, `decimal`), checked:
/// None, with each problem reported, when they cannot be used.
fn table_text(
    spec: &RunTable,
    format: TableFormat,
    bad: &mut impl FnMut(String),
) -> Option<ingest::TableText> {
    let mut ok = true;
    if format == TableFormat::Parquet && (spec.delimiter.is_some() || spec.decimal.is_some()) {
        bad("delimiter and decimal are for a CSV table; a Parquet table has neither".into());
        return None;
    }
    let delimiter = match spec.delimiter.as_deref() {
        None => None,
        Some(d) if d.len() == 1 && d.is_ascii() && d != "\"" && d != "\n" && d != "\r" => {
            Some(d.as_bytes()[0])
        }
        Some(d) => {
            bad(format!(
                "delimiter: must be one character other than a quote or a line break (got {d:?})"
            ));
            ok = false;
            None
        }
    };
    let decimal_comma = match spec.decimal.as_deref() {
        None => None,
        Some(".") => Some(false),
        Some(",") => Some(true),
        Some(d) => {
            bad(format!("decimal: must be \".\" or \",\" (got {d:?})"));
            ok = false;
            None
        }
    };
    if delimiter == Some(b',') && decimal_comma == Some(true) {
        bad("decimal = \",\" needs another delimiter than a comma (a European export uses delimiter = \";\")".into());
        ok = false;
    }
    ok.then_some(ingest::TableText {
        delimiter,
        decimal_comma,
    })
}

/// Each column of the header known, or the lab's own, and each required
/// column there. Returns the known columns' indices by name and the lab's
/// columns (name, index). A column whose name is close to a known one
/// (`stifness_n_per_m`, `mass`) is a problem with a suggestion, not an
/// annotation: a typo must not silently drop a specimen's value. A column
/// without a name (a spreadsheet's index column) is neither, and is left
/// out.
#[allow(clippy::type_complexity)]
fn check_columns(
    file: &str,
    header: &[String],
    problems: &mut Vec<Problem>,
) -> (BTreeMap<&'static str, usize>, Vec<(String, usize)>) {
    let at = |column: &str, message: String| {
        let place = TablePlace {
            file: file.to_string(),
            row: None,
            column: Some(column.to_string()),
        };
        Problem::in_table(place, None, message)
    };
    let known: Vec<&str> = COLUMNS.iter().map(|(name, _)| *name).collect();
    let mut found = BTreeMap::new();
    let mut own = Vec::new();
    for (i, name) in header.iter().enumerate() {
        match COLUMNS.iter().find(|(c, _)| c == name) {
            Some((c, _)) => {
                found.insert(*c, i);
            }
            None if name.trim().is_empty() => {}
            None if closest(&known, name).is_some() => problems.push(at(
                name,
                format!("unknown column `{name}`{}", suggest(&known, name)),
            )),
            None => own.push((name.clone(), i)),
        }
    }
    for (name, required) in COLUMNS {
        if required && !found.contains_key(name) {
            problems.push(at(name, "required column is missing".into()));
        }
    }
    (found, own)
}

/// One data row and how to address its cells.
struct Row<'a> {
    /// The table file as the manifest names it.
    file: &'a str,
    /// 1-based.
    number: usize,
    cells: &'a [Option<String>],
    columns: &'a BTreeMap<&'static str, usize>,
    /// The lab's own columns (name, index).
    annotations: &'a [(String, usize)],
    /// Whether numbers are written with a decimal comma.
    decimal_comma: bool,
}

impl Row<'_> {
    /// The text of the row's cell in `column`; None when empty or when the
    /// table has no such column.
    fn cell(&self, column: &str) -> Option<&str> {
        let i = *self.columns.get(column)?;
        self.cells.get(i)?.as_deref()
    }

    /// A problem in this row (in `column`, when it is in one).
    fn problem(&self, id: Option<&str>, column: Option<&str>, message: String) -> Problem {
        let place = TablePlace {
            file: self.file.to_string(),
            row: Some(self.number),
            column: column.map(str::to_string),
        };
        Problem::in_table(place, id.map(str::to_string), message)
    }
}

/// One row's checks: every cell, the specimen its role needs, its date and
/// its log. Returns the row's key and, when every check passed, its run.
fn check_row(
    row: &Row<'_>,
    table_dir: &Path,
    source: LogSource<'_>,
    predict: bool,
    problems: &mut Vec<Problem>,
) -> (RowKey, Option<TableRun>) {
    let id = row.cell("id").filter(|c| !c.starts_with(PLACEHOLDER));
    // A cell `servoid init --table` left to fill: that is the row's problem
    // until it is filled (its other checks would only repeat it).
    if report_placeholders(row, id, problems) {
        let role = row
            .cell("role")
            .and_then(|r| Role::ALL.into_iter().find(|x| x.as_str() == r));
        let key = RowKey {
            row: row.number,
            id: id.map(str::to_string),
            role,
            has_mass: false,
        };
        return (key, None);
    }
    let before = problems.len();
    let cells = read_cells(row, id, problems);
    let key = RowKey {
        row: row.number,
        id: id.map(str::to_string),
        role: cells.role,
        has_mass: cells.mass.flatten().is_some(),
    };
    let specimen = row_specimen(row, id, &cells, problems);
    let log = cells
        .role
        .and_then(|role| row_log(row, id, role, table_dir, source, predict, problems));
    let run = match (cells.id, cells.role, cells.p_gain, specimen, log) {
        (Some(id), Some(role), Some(p_gain), Some(specimen), Some(log))
            if problems.len() == before =>
        {
            Some(TableRun {
                id: id.to_string(),
                role,
                p_gain,
                specimen,
                date: cells.date,
                log,
                description: row.cell("description").unwrap_or_default().to_string(),
                annotations: row_annotations(row),
            })
        }
        _ => None,
    };
    (key, run)
}

/// Report each cell `servoid init --table` left to fill, in column order;
/// whether there was one.
fn report_placeholders(row: &Row<'_>, id: Option<&str>, problems: &mut Vec<Problem>) -> bool {
    let mut left = false;
    let mut in_order: Vec<(&&str, &usize)> = row.columns.iter().collect();
    in_order.sort_by_key(|(_, i)| **i);
    for (name, i) in in_order {
        if let Some(what) = row
            .cells
            .get(*i)
            .and_then(|c| c.as_deref()?.strip_prefix(PLACEHOLDER))
        {
            problems.push(Problem {
                placeholder: true,
                ..row.problem(
                    id,
                    Some(name),
                    format!("a placeholder to fill: {}", what.trim_start()),
                )
            });
            left = true;
        }
    }
    left
}

/// A row's cells as values, each None where it is empty or did not read;
/// the numbers `Some(None)` when empty, None when they did not read (as
/// [`number`] gives them).
struct Cells<'a> {
    id: Option<&'a str>,
    role: Option<Role>,
    p_gain: Option<f64>,
    mass: Option<Option<f64>>,
    damping: Option<Option<f64>>,
    stiffness: Option<Option<f64>>,
    date: Option<String>,
}

/// Read and check each cell of the row on its own: the required ones
/// there, the id a slug, the role known, the numbers numbers, the date a
/// date.
fn read_cells<'a>(row: &'a Row<'_>, id: Option<&str>, problems: &mut Vec<Problem>) -> Cells<'a> {
    let mut bad = |column: &str, message: String| {
        problems.push(row.problem(id, Some(column), message));
    };
    let mut required = |column: &str| {
        let cell = row.cell(column);
        // A missing column is one problem of the header, not one per row.
        if cell.is_none() && row.columns.contains_key(column) {
            bad(column, "required: the cell is empty".into());
        }
        cell
    };
    let (id_cell, role_cell, p_cell) = (required("id"), required("role"), required("p_gain"));
    if let Some(id) = id_cell {
        check_slug(id, &KeyPath::root(), &mut |_, m| bad("id", m));
    }
    let role = role_cell.and_then(|r| {
        let role = Role::ALL.into_iter().find(|x| x.as_str() == r);
        if role.is_none() {
            let names = Role::ALL.map(Role::as_str);
            bad(
                "role",
                format!("unknown role `{r}`{}", suggest(&names[..], r)),
            );
        }
        role
    });
    let comma = row.decimal_comma;
    let p_gain = number(p_cell, "p_gain", comma, &mut bad)
        .flatten()
        .filter(|&p| positive(p, &KeyPath::root(), &mut |_, m| bad("p_gain", m)));
    let mut parsed = |c: &str| number(row.cell(c), c, comma, &mut bad);
    let (mass, damping, stiffness) = (
        parsed("mass_kg"),
        parsed("damping_ns_per_m"),
        parsed("stiffness_n_per_m"),
    );
    let date = row.cell("date").and_then(|d| {
        normalise_date(d)
            .map_err(|e| bad("date", e.to_string()))
            .ok()
    });
    Cells {
        id: id_cell,
        role,
        p_gain,
        mass,
        damping,
        stiffness,
        date,
    }
}

/// The specimen the row's role needs, checked. It is judged only from
/// cells that read as numbers: an unreadable stiffness is one problem, not
/// also a missing one.
fn row_specimen(
    row: &Row<'_>,
    id: Option<&str>,
    cells: &Cells<'_>,
    problems: &mut Vec<Problem>,
) -> Option<SpecimenModel> {
    let (Some(role), Some(mass_kg), Some(damping_ns_per_m), Some(stiffness_n_per_m)) =
        (cells.role, cells.mass, cells.damping, cells.stiffness)
    else {
        return None;
    };
    let s = Specimen {
        mass_kg,
        damping_ns_per_m,
        stiffness_n_per_m,
        ..Specimen::default()
    };
    check_specimen(role, Some(&s), &KeyPath::root(), &mut |p, m| {
        problems.push(row.problem(id, specimen_column(&p), m));
    })
}

/// The row's cells in the lab's own columns, by column, empty cells left
/// out.
fn row_annotations(row: &Row<'_>) -> BTreeMap<String, String> {
    row.annotations
        .iter()
        .filter_map(|(name, i)| {
            let cell = row.cells.get(*i)?.as_deref()?;
            Some((name.clone(), cell.to_string()))
        })
        .collect()
}

/// The column a specimen check names (its key path's last key); None for a
/// problem of the specimen as a whole.
fn specimen_column(path: &KeyPath) -> Option<&str> {
    match path.0.last() {
        Some(Seg::Key(k)) => Some(k.as_str()),
        _ => None,
    }
}

/// A cell as a number: `Some(None)` when empty, `Some(Some(v))` when it
/// reads, None (with the problem reported) when it does not.
fn number(
    cell: Option<&str>,
    column: &str,
    decimal_comma: bool,
    bad: &mut impl FnMut(&str, String),
) -> Option<Option<f64>> {
    match cell {
        None => Some(None),
        Some(text) => match if decimal_comma {
            text.replacen(',', ".", 1).parse::<f64>()
        } else {
            text.parse::<f64>()
        } {
            Ok(v) => Some(Some(v)),
            Err(_) => {
                bad(column, format!("must be a number (got {text:?})"));
                None
            }
        },
    }
}

/// A row's log: its `log` cell (relative to the table's folder), else the
/// matched file whose stem is the run's id, else, when `logs` is given, the
/// path where that file is expected. `Some(None)` for a validation run
/// without a log (a prediction); None, with the problem reported, when the
/// log's format is unknown, the id names several matched files, or a run
/// that needs a log has none (and silently when the id, whose problem is
/// reported, is needed and missing).
#[allow(clippy::too_many_arguments)]
fn row_log(
    row: &Row<'_>,
    id: Option<&str>,
    role: Role,
    table_dir: &Path,
    source: LogSource<'_>,
    predict: bool,
    problems: &mut Vec<Problem>,
) -> Option<Option<(PathBuf, LogFormat)>> {
    let mut bad = |message: String| problems.push(row.problem(id, Some("log"), message));
    // The path, and how a message names it.
    let (path, shown) = match (row.cell("log"), source) {
        (Some(cell), _) => (table_dir.join(cell), cell.to_string()),
        (None, LogSource::Broken) => return None,
        (None, LogSource::Matched(m)) => {
            let id = id?;
            let hits: Vec<&PathBuf> = m
                .files
                .iter()
                .filter(|f| f.file_stem().is_some_and(|s| s == id))
                .collect();
            match hits.as_slice() {
                [one] => ((*one).clone(), m.shown(one)),
                [] => {
                    // Not there (yet): the run fails alone when read, naming
                    // this path; its format then does not matter.
                    let expected = expected_log(m, id);
                    let format = LogFormat::from_path(&expected).unwrap_or(LogFormat::Csv);
                    return Some(Some((expected, format)));
                }
                several => {
                    let names: Vec<String> = several.iter().map(|p| m.shown(p)).collect();
                    bad(format!(
                        "{} matched logs have the stem `{id}` ({}); name one in the `log` cell",
                        several.len(),
                        names.join(", ")
                    ));
                    return None;
                }
            }
        }
        (None, LogSource::None) if role == Role::Validation && predict => return Some(None),
        (None, LogSource::None) if role == Role::Validation => {
            bad("a validation run needs a log to be validated: give its `log` cell or [run_table] logs (or predict = true under [run_table] for a table of specimens to predict from the rig model)".into());
            return None;
        }
        (None, LogSource::None) => {
            bad(format!(
                "a {} run needs a log: give its `log` cell or [run_table] logs",
                role.as_str()
            ));
            return None;
        }
    };
    match LogFormat::from_path(&path) {
        Some(format) => Some(Some((path, format))),
        None => {
            bad(format!(
                "cannot tell the format of `{shown}` from its extension; use {}",
                LogFormat::EXTENSIONS
            ));
            None
        }
    }
}

/// The logs `spec` names, relative to `base_dir`: a glob, or a folder's files
/// with a log extension. Hidden files (a name starting with `.`, as editors'
/// lock and swap files have) are not logs. None, with the problem reported,
/// when the glob does not parse or the folder is not one.
fn match_logs(spec: &str, base_dir: &Path, problems: &mut Vec<Problem>) -> Option<Matched> {
    let key = KeyPath::root().key("run_table").key("logs");
    let target = base_dir.join(spec);
    let glob = spec.contains(['*', '?', '[']);
    let mut loops = Vec::new();
    let mut files = if glob {
        // The manifest's folder is literal text, whatever characters it
        // holds: the walk starts there and matches only below it.
        match walk_glob(spec, base_dir) {
            Ok((files, l)) => {
                loops = l;
                files
            }
            Err(e) => {
                problems.push(Problem::new(key, format!("not a valid glob: {e}")));
                return None;
            }
        }
    } else {
        let Ok(entries) = std::fs::read_dir(&target) else {
            problems.push(Problem::new(
                key,
                format!(
                    "{} is neither a folder nor a glob pattern (`*`, `?`, `[...]`)",
                    target.display()
                ),
            ));
            return None;
        };
        entries
            .filter_map(|e| e.ok().map(|e| e.path()))
            .filter(|p| p.is_file() && LogFormat::from_path(p).is_some())
            .filter(|p| {
                !p.file_name()
                    .is_some_and(|n| n.to_string_lossy().starts_with('.'))
            })
            .collect::<Vec<PathBuf>>()
    };
    files.sort();
    Some(Matched {
        spec: spec.to_string(),
        target,
        base_dir: base_dir.to_path_buf(),
        glob,
        files,
        loops,
    })
}

impl Matched {
    /// A file as the manifest's folder sees it.
    fn shown(&self, path: &Path) -> String {
        path.strip_prefix(&self.base_dir)
            .unwrap_or(path)
            .display()
            .to_string()
    }
}

/// Where the log of run `id` is expected when `logs` matched none: the glob
/// with the id in place of the first `*` of its file name (keeping the
/// pattern's extension if it has no `*`), or in the folder under the id with
/// the extension its logs share (none when they differ).
fn expected_log(m: &Matched, id: &str) -> PathBuf {
    if m.glob {
        let name = m
            .target
            .file_name()
            .map(|n| n.to_string_lossy().into_owned())
            .unwrap_or_default();
        let file = match name.split_once('*') {
            Some((before, after)) => format!("{before}{id}{after}"),
            None => match Path::new(&name).extension() {
                Some(ext) => format!("{id}.{}", ext.to_string_lossy()),
                None => id.to_string(),
            },
        };
        return m.target.with_file_name(file);
    }
    let extensions: BTreeSet<_> = m.files.iter().filter_map(|f| f.extension()).collect();
    // Not `set_extension`: an id may hold a `.` itself.
    match extensions.into_iter().collect::<Vec<_>>().as_slice() {
        [ext] => m.target.join(format!("{id}.{}", ext.to_string_lossy())),
        _ => m.target.join(id),
    }
}

/// The unused logs a warning names one by one; past them, one line says
/// how many more (a folder of old logs matched 20,000).
pub const UNUSED_LOGS_LISTED: usize = 10;

/// A warning for each folder link the walk did not follow (a loop); for
/// each matched log that no run uses, naming it as the manifest's folder
/// sees it, the first [`UNUSED_LOGS_LISTED`] of them and then their count;
/// and one when `logs` matched nothing.
fn unused_logs(m: &Matched, used: &BTreeSet<PathBuf>) -> Vec<Warning> {
    let name = |p: &Path| {
        p.file_name()
            .map_or_else(|| m.shown(p), |n| n.to_string_lossy().into_owned())
    };
    let mut out: Vec<Warning> = m
        .loops
        .iter()
        .map(|(link, ancestor)| {
            Warning::new(
                format!("[run_table] logs: the folder link {} loops; not followed", name(link)),
                format!(
                    "{}: a folder link back to {} (a loop): [run_table] logs = {:?} does not follow it",
                    m.shown(link),
                    m.shown(ancestor),
                    m.spec
                ),
            )
        })
        .collect();
    if m.files.is_empty() {
        out.push(Warning::new(
            "[run_table] logs matches no log file",
            format!("[run_table] logs = {:?} matches no log file", m.spec),
        ));
        return out;
    }
    let unused: Vec<&PathBuf> = m
        .files
        .iter()
        .filter(|f| !used.contains(&same_file(f)))
        .collect();
    out.extend(unused.iter().take(UNUSED_LOGS_LISTED).map(|f| {
        Warning::new(
            format!("[run_table] logs matches {}, which no run uses", name(f)),
            format!(
                "{}: matched by [run_table] logs = {:?}, but no run uses it",
                m.shown(f),
                m.spec
            ),
        )
    }));
    if unused.len() > UNUSED_LOGS_LISTED {
        let more = unused.len() - UNUSED_LOGS_LISTED;
        out.push(Warning::new(
            format!("[run_table] logs matches {more} more logs no run uses"),
            format!(
                "and {more} more logs matched by [run_table] logs = {:?} that no run uses (narrow the glob, or move old logs out)",
                m.spec
            ),
        ));
    }
    out
}

/// A path to compare files by: canonical where the file exists (the same
/// log named through `..` or a symbolic link is the same log), else as given.
fn same_file(path: &Path) -> PathBuf {
    std::fs::canonicalize(path).unwrap_or_else(|_| path.to_path_buf())
}

#[cfg(test)]
mod tests {
    use std::path::{Path, PathBuf};

    use crate::ingest::{LogFormat, sha256_hex};
    use crate::manifest::{Campaign, RunSource, load};
    use crate::warning::Warning;

    fn details(warnings: &[Warning]) -> Vec<&str> {
        warnings.iter().map(|w| w.detail.as_str()).collect()
    }

    /// A campaign whose rig comes from published transfer functions, one
    /// `[[runs]]` fit run on `logs/c.csv`, and a run table of fit runs.
    const MANIFEST: &str = r#"schema_version = 1

[campaign]
name = "t"

[rig]
name = "r"

[channels]
time = { column = "t", unit = "s" }
command = { column = "u", unit = "mm" }
displacement = { column = "x", unit = "mm" }

[[runs]]
id = "ns"
role = "no_specimen"
p_gain = 1.0
[runs.data.transfer_function]
num = [3060.0]
den = [1.0, 267.0, 3060.0]

[[runs]]
id = "k1"
role = "spring"
p_gain = 1.0
specimen = { stiffness_n_per_m = 116640.0 }
[runs.data.transfer_function]
num = [2703.0]
den = [1.0, 263.4, 3337.0]

[[runs]]
id = "c"
role = "fit"
p_gain = 1.0
data = { log = "logs/c.csv" }

[run_table]
file = "night/runs.csv"
logs = "LOGS"
"#;

    /// Write the manifest (with `logs`), the table and the (empty) log
    /// files, in the order given; load the campaign.
    fn campaign(dir: &Path, logs: &str, table: &str, files: &[&str]) -> Campaign {
        for f in files {
            let p = dir.join(f);
            std::fs::create_dir_all(p.parent().unwrap()).unwrap();
            std::fs::write(&p, "t,u,x\n").unwrap();
        }
        std::fs::create_dir_all(dir.join("night")).unwrap();
        std::fs::write(dir.join("night/runs.csv"), table).unwrap();
        let manifest = dir.join("campaign.toml");
        std::fs::write(&manifest, MANIFEST.replace("LOGS", logs)).unwrap();
        load(&manifest).unwrap_or_else(|e| panic!("{e}"))
    }

    fn log_of(c: &Campaign, id: &str) -> (PathBuf, LogFormat) {
        let run = c.runs.iter().find(|r| r.id == id).unwrap();
        match &run.source {
            RunSource::Log(plan) => (plan.path.clone(), plan.format),
            other => panic!("{id}: {other:?}"),
        }
    }

    #[test]
    fn a_matched_log_no_run_uses_is_a_warning_in_sorted_order() {
        let dir = tempfile::tempdir().unwrap();
        let d = dir.path();
        // Created out of order, so that a listing in creation order would
        // differ from the sorted one.
        let files = [
            "logs/z-spare.csv",
            "logs/b.csv",
            "logs/m-spare.csv",
            "logs/a.csv",
            "logs/c.csv",
            "logs/.hidden.csv",
        ];
        // `a` by its stem, `b` through its `log` cell (by another path to
        // the same file), `c` by the `[[runs]]` run.
        let table = "id,role,p_gain,log\na,fit,1,\nb,fit,2,../logs/./b.csv\n";
        let c = campaign(d, "logs/*.csv", table, &files);
        assert_eq!(
            details(&c.warnings),
            [
                "logs/m-spare.csv: matched by [run_table] logs = \"logs/*.csv\", but no run uses it",
                "logs/z-spare.csv: matched by [run_table] logs = \"logs/*.csv\", but no run uses it",
            ]
        );
        let ids: Vec<(&str, usize)> = c.runs.iter().map(|r| (r.id.as_str(), r.index)).collect();
        assert_eq!(ids, [("ns", 0), ("k1", 1), ("c", 2), ("a", 3), ("b", 4)]);
        assert_eq!(log_of(&c, "a"), (d.join("logs/a.csv"), LogFormat::Csv));
        assert_eq!(
            log_of(&c, "b"),
            (d.join("night/../logs/./b.csv"), LogFormat::Csv)
        );
        let info = c.run_table.as_ref().unwrap();
        assert_eq!(info.file, "night/runs.csv");
        assert_eq!(info.sha256, sha256_hex(table.as_bytes()));
        assert_eq!(info.rows, 2);
        // Exact: the table's cells parsed as written.
        assert_eq!(c.runs[3].p_gain, 1.0);
        assert_eq!(c.runs[4].p_gain, 2.0);
    }

    #[test]
    fn a_recursive_glob_through_two_folder_loops_ends_and_names_them() {
        // `logs/**/*.csv` through two links back to ancestors ran
        // until memory ran out (3 GB in 2 minutes).
        let dir = tempfile::tempdir().unwrap();
        let d = dir.path();
        let files = ["logs/a.csv", "logs/day1/b.csv", "logs/day1/deep/c2.csv"];
        for f in files {
            let p = d.join(f);
            std::fs::create_dir_all(p.parent().unwrap()).unwrap();
            std::fs::write(&p, "t,u,x\n").unwrap();
        }
        std::os::unix::fs::symlink(d.join("logs"), d.join("logs/day1/up")).unwrap();
        std::os::unix::fs::symlink(d.join("logs/day1"), d.join("logs/day1/deep/back")).unwrap();
        // A linked-in folder that does not loop is followed.
        std::fs::create_dir_all(d.join("elsewhere")).unwrap();
        std::fs::write(d.join("elsewhere/e.csv"), "t,u,x\n").unwrap();
        std::os::unix::fs::symlink(d.join("elsewhere"), d.join("logs/linked")).unwrap();
        let table = "id,role,p_gain\na,fit,1\nb,fit,1\n";
        let c = campaign(d, "logs/**/*.csv", table, &[]);
        assert_eq!(
            details(&c.warnings),
            [
                "logs/day1/deep/back: a folder link back to logs/day1 (a loop): [run_table] logs = \"logs/**/*.csv\" does not follow it",
                "logs/day1/up: a folder link back to logs (a loop): [run_table] logs = \"logs/**/*.csv\" does not follow it",
                "logs/day1/deep/c2.csv: matched by [run_table] logs = \"logs/**/*.csv\", but no run uses it",
                "logs/linked/e.csv: matched by [run_table] logs = \"logs/**/*.csv\", but no run uses it",
            ]
        );
        // `**` matches no folder too: a.csv sits right under logs/.
        assert_eq!(log_of(&c, "a"), (d.join("logs/a.csv"), LogFormat::Csv));
        assert_eq!(log_of(&c, "b"), (d.join("logs/day1/b.csv"), LogFormat::Csv));
    }

    #[test]
    fn many_unused_logs_are_listed_up_to_ten_then_counted() {
        let dir = tempfile::tempdir().unwrap();
        let d = dir.path();
        let files: Vec<String> = (0..25).map(|i| format!("logs/old{i:02}.csv")).collect();
        let files: Vec<&str> = files.iter().map(String::as_str).collect();
        let c = campaign(d, "logs/*.csv", "id,role,p_gain\nold00,fit,1\n", &files);
        assert_eq!(c.warnings.len(), super::UNUSED_LOGS_LISTED + 1);
        assert!(c.warnings[0].detail.starts_with("logs/old01.csv: matched"));
        assert_eq!(
            c.warnings[10].detail,
            "and 14 more logs matched by [run_table] logs = \"logs/*.csv\" that no run uses (narrow the glob, or move old logs out)"
        );
    }

    #[test]
    fn a_folder_matches_its_logs_only_and_a_missing_log_keeps_its_expected_path() {
        let dir = tempfile::tempdir().unwrap();
        let d = dir.path();
        let files = [
            "logs/z-spare.csv",
            "logs/a.csv",
            "logs/m-spare.csv",
            "logs/c.csv",
            "logs/notes.md",
            "logs/.a.csv",
        ];
        // A blank line is no run, and `k2.v1` (an id with a dot) has no log.
        let table = "id,role,p_gain\na,fit,1\n\nk2.v1,fit,1\n";
        let c = campaign(d, "logs", table, &files);
        assert_eq!(
            details(&c.warnings),
            [
                "logs/m-spare.csv: matched by [run_table] logs = \"logs\", but no run uses it",
                "logs/z-spare.csv: matched by [run_table] logs = \"logs\", but no run uses it",
            ]
        );
        assert_eq!(log_of(&c, "a"), (d.join("logs/a.csv"), LogFormat::Csv));
        assert_eq!(
            log_of(&c, "k2.v1"),
            (d.join("logs/k2.v1.csv"), LogFormat::Csv)
        );
        assert_eq!(c.run_table.as_ref().unwrap().rows, 2);
    }

    #[test]
    fn a_glob_puts_the_id_in_place_of_its_star_for_a_missing_log() {
        let dir = tempfile::tempdir().unwrap();
        let d = dir.path();
        let table = "id,role,p_gain\nk2,fit,1\n";
        let c = campaign(d, "logs/run-*.parquet", table, &["logs/c.csv"]);
        assert_eq!(
            log_of(&c, "k2"),
            (d.join("logs/run-k2.parquet"), LogFormat::Parquet)
        );
        assert_eq!(
            details(&c.warnings),
            ["[run_table] logs = \"logs/run-*.parquet\" matches no log file"]
        );
    }

    #[test]
    fn an_id_whose_stem_several_logs_share_is_a_problem_listing_them_sorted() {
        let dir = tempfile::tempdir().unwrap();
        let d = dir.path();
        for f in ["logs/a.parquet", "logs/a.csv", "logs/c.csv"] {
            std::fs::create_dir_all(d.join("logs")).unwrap();
            std::fs::write(d.join(f), "").unwrap();
        }
        std::fs::create_dir_all(d.join("night")).unwrap();
        std::fs::write(d.join("night/runs.csv"), "id,role,p_gain\na,fit,1\n").unwrap();
        let manifest = d.join("campaign.toml");
        std::fs::write(&manifest, MANIFEST.replace("LOGS", "logs/*")).unwrap();
        let e = load(&manifest).unwrap_err().to_string();
        assert!(
            e.ends_with(
                "\n  night/runs.csv: row 1 (run \"a\"), column log: 2 matched logs have the stem `a` (logs/a.csv, logs/a.parquet); name one in the `log` cell"
            ),
            "{e}"
        );
    }

    #[test]
    fn a_manifest_without_a_run_table_has_no_table_and_no_warnings() {
        let text = MANIFEST[..MANIFEST.find("[[runs]]\nid = \"c\"").unwrap()].to_string();
        let c = crate::manifest::load_str(&text, Path::new("campaign.toml")).unwrap();
        assert!(c.run_table.is_none());
        assert!(c.warnings.is_empty());
        assert!(c.manifest.run_table.is_none());
        assert_eq!(c.runs.len(), 2);
    }
}
