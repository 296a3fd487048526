//! `servoid init`: a campaign manifest proposed from a folder of logs. The
//! channels are found from the columns' names and units (`disp_mm`,
//! `Displacement (mm)`, `x1 [m]`, a unit the file states), each run's role
//! from its file name (`no-specimen`, `bare`, `spring`, `k2`, `exp3`,
//! `val`), and every value only the lab knows (the specimen's stiffness,
//! mass and damping, the P gain, a unit no column gives, a role no name
//! gives) is written as a [`PLACEHOLDER`] string that `servoid check`
//! reports by key until it is filled. Pure: the logs come inspected
//! (`ingest::inspect`) and the run table read (`ingest::read_table`); the
//! plans to read the logs back with ([`log_plan`]) go to `run` to read,
//! and the text goes back to `run` to write.

use std::collections::BTreeSet;
use std::fmt::Write as _;
use std::path::{Path, PathBuf};

pub use crate::ingest::naming::{Proposed, ProposedChannels, propose};
use crate::ingest::{
    ChannelPlan, Channels, Column, CsvOptions, DEFAULT_MAX_LOG_MIB, Inspected, LogColumn,
    LogFormat, LogPlan, Repair, Table, TimePlan,
};
use crate::units::{TimeUnit, Unit};

/// The prefix of a value the lab must fill in: `servoid check` names every
/// key that still holds one.
pub const PLACEHOLDER: &str = "FILL:";

/// One log as `servoid init` found it.
#[derive(Debug, Clone)]
pub struct FoundLog {
    /// The path as the manifest will name it (relative to the manifest).
    pub path: String,
    /// The file name without its extension: the run's role comes from it.
    pub stem: String,
    /// The run's id: the stem as an id, made unique among the logs.
    pub id: String,
    pub inspected: Inspected,
    /// Its own channels, where its columns are not the campaign's
    /// (`[[runs]]` block's `channels`).
    pub channels: Option<ProposedChannels>,
}

/// What a log's reading with the proposed channels gave (or why it failed):
/// `run` reads each log once the channels are proposed.
#[derive(Debug, Clone)]
pub enum ReadBack {
    Read {
        sample_rate_hz: f64,
        n_samples: usize,
    },
    Failed(String),
    /// Not read: a channel is a placeholder.
    NotRead,
}

/// A run's role from its log's name, and the word that said it.
pub fn role_of(stem: &str) -> Option<(&'static str, String)> {
    let lower = stem.to_ascii_lowercase();
    let words: Vec<&str> = lower
        .split(|c: char| !c.is_ascii_alphanumeric())
        .filter(|w| !w.is_empty())
        .collect();
    let joined: String = words.concat();
    let has = |w: &str| words.contains(&w);
    if joined.contains("nospecimen") || has("bare") || has("empty") || has("ns") {
        return Some(("no_specimen", stem.to_string()));
    }
    let spring_k = words
        .iter()
        .find(|w| w.len() > 1 && w.starts_with('k') && w[1..].chars().all(|c| c.is_ascii_digit()));
    if has("spring") || spring_k.is_some() {
        return Some(("spring", stem.to_string()));
    }
    let validation = words.iter().any(|w| {
        let letters = w.trim_end_matches(|c: char| c.is_ascii_digit());
        matches!(
            letters,
            "exp" | "val" | "validation" | "specimen" | "sdof" | "test"
        )
    });
    validation.then(|| ("validation", stem.to_string()))
}

/// A name a manifest accepts (a run id, a campaign name) from a file's or
/// folder's: letters, digits, `.`, `_` and `-`, not starting with `.` (a
/// folder such as `.tmpXYZ`); `fallback` when nothing is left.
pub fn manifest_name(text: &str, fallback: &str) -> String {
    let cleaned: String = text
        .chars()
        .map(|c| {
            if c.is_ascii_alphanumeric() || matches!(c, '.' | '_' | '-') {
                c
            } else {
                '-'
            }
        })
        .collect();
    match cleaned.trim_start_matches('.') {
        "" => fallback.to_string(),
        name => name.to_string(),
    }
}

fn quoted(s: &str) -> String {
    toml::Value::String(s.to_string()).to_string()
}

fn fill(what: &str) -> String {
    quoted(&format!("{PLACEHOLDER} {what}"))
}

/// A channel's line of the manifest, with the guess's comment above it.
fn channel_line(out: &mut String, key: &str, p: &Proposed, units_hint: &str, optional: bool) {
    let _ = writeln!(out, "# {}", p.how);
    let column = match &p.column {
        Some(c) => quoted(c),
        None if optional => {
            let _ = writeln!(
                out,
                "# {key} = {{ column = \"...\", unit = \"{units_hint}\" }}   # optional: no force column found"
            );
            return;
        }
        None => fill(&format!("the {key} column (see the columns listed above)")),
    };
    let unit = match p.unit {
        Some(u) => quoted(u),
        None => fill(units_hint),
    };
    let _ = writeln!(out, "{key} = {{ column = {column}, unit = {unit} }}");
}

/// Where a proposed manifest's runs are.
#[derive(Debug, Clone)]
pub enum Runs<'a> {
    /// One `[[runs]]` table per log, each with what reading it with the
    /// proposed channels gave (same order as the logs).
    Blocks(&'a [ReadBack]),
    /// A `[run_table]`: its file and the logs' folder as the manifest
    /// names them (relative to it), with lines of comment on what `init`
    /// found (rows matched to logs, logs read).
    Table {
        file: String,
        logs: String,
        comments: Vec<String>,
    },
}

/// The manifest text for `logs`, with the channels proposed for the first
/// and the runs as `runs` says.
pub fn manifest_text(
    name: &str,
    logs: &[FoundLog],
    channels: &ProposedChannels,
    runs: &Runs<'_>,
) -> String {
    let mut out = String::new();
    write_preamble(&mut out, name, logs);
    write_channels(&mut out, logs, channels);
    out.push_str(
        "\n# The band fitted. The FRF settings are left to servoid, which chooses\n\
         # them for each log from its length, its ends and the band (the\n\
         # default, estimator = \"auto\"; each run's choice is in results.json\n\
         # and on its page); see docs/manifest.md.\n\
         [identification]\nband_hz = [0.5, 30.0]\ncoherence_min = 0.8\n",
    );
    write_runs(&mut out, logs, runs);
    out
}

/// The manifest's opening comment, `[campaign]` and `[rig]`, and the first
/// log's columns listed for the channels below.
fn write_preamble(out: &mut String, name: &str, logs: &[FoundLog]) {
    let _ = writeln!(
        out,
        "# A campaign manifest proposed by `servoid init` from {} log(s).\n\
         # Every value only the lab knows is a string starting {PLACEHOLDER}, which\n\
         # `servoid check` names until it is filled. Check the channels and roles below:\n\
         # they are guesses from the columns' and the files' names.\n",
        logs.len()
    );
    let _ = writeln!(
        out,
        "schema_version = 1\n\n[campaign]\nname = {}\n",
        quoted(name)
    );
    let _ = writeln!(
        out,
        "[rig]\nname = {}\n",
        fill("the actuator and frame, as the history names the rig")
    );
    if let Some(first) = logs.first() {
        let _ = writeln!(out, "# The columns of {}:", first.path);
        for c in &first.inspected.columns {
            let unit = c
                .unit
                .as_deref()
                .map(|u| format!(" (the file says {u:?})"))
                .unwrap_or_default();
            let _ = writeln!(out, "#   {}{unit}", quoted(&c.name));
        }
    }
}

/// `[channels]`: the time base (a column, the rate the file states, or a
/// rate to fill), then the command, displacement and force.
fn write_channels(out: &mut String, logs: &[FoundLog], channels: &ProposedChannels) {
    out.push_str("[channels]\n");
    let rate = logs.first().and_then(|l| l.inspected.rate_hz);
    channel_lines(out, "", channels, rate);
}

/// The time base and the three channels' lines, each key after `prefix`
/// (`""` for `[channels]`, `"channels."` for a run's own). Where the file
/// states its rate and has no time column, `[channels]` leaves the time
/// out (servoid reads the rate itself), while a run's own channels must
/// give it, to replace `[channels]`' time column.
fn channel_lines(out: &mut String, prefix: &str, p: &ProposedChannels, rate: Option<f64>) {
    let key = |k: &str| format!("{prefix}{k}");
    match (&p.time.column, rate) {
        (Some(_), _) => channel_line(out, &key("time"), &p.time, "s or ms", false),
        (None, Some(hz)) if prefix.is_empty() => {
            let _ = writeln!(
                out,
                "# time: no time column; the file states its rate, {hz} Hz, which servoid reads itself"
            );
        }
        (None, Some(hz)) => {
            let _ = writeln!(
                out,
                "{} = {{ sample_rate_hz = {hz} }}   # the file's own rate",
                key("time")
            );
        }
        (None, None) => {
            let _ = writeln!(out, "# {}", p.time.how);
            let _ = writeln!(
                out,
                "{} = {{ sample_rate_hz = {} }}",
                key("time"),
                fill("the sampling rate in Hz")
            );
        }
    }
    channel_line(out, &key("command"), &p.command, "m, cm, mm or in", false);
    channel_line(
        out,
        &key("displacement"),
        &p.displacement,
        "m, cm, mm or in",
        false,
    );
    channel_line(out, &key("force"), &p.force, "N, kN or lbf", true);
}

/// The runs: a `[[runs]]` block per log, or the `[run_table]`.
fn write_runs(out: &mut String, logs: &[FoundLog], runs: &Runs<'_>) {
    match runs {
        Runs::Blocks(read) => {
            for (log, back) in logs.iter().zip(*read) {
                run_block(out, log, back);
            }
        }
        Runs::Table {
            file,
            logs,
            comments,
        } => {
            out.push_str(
                "\n# The runs are the table's rows (id, role, p_gain, the specimen's cells):\n\
                 # see docs/manifest.md, \"Runs from a table\". A row's log is its `log`\n\
                 # cell, else the log in `logs` whose stem is its id.\n",
            );
            for c in comments {
                let _ = writeln!(out, "# {c}");
            }
            let _ = writeln!(
                out,
                "[run_table]\nfile = {}\nlogs = {}",
                quoted(file),
                quoted(logs)
            );
        }
    }
}

/// The run table's columns as `servoid init --table` writes them.
pub const TABLE_HEADER: [&str; 7] = [
    "id",
    "role",
    "p_gain",
    "mass_kg",
    "damping_ns_per_m",
    "stiffness_n_per_m",
    "log",
];

/// A CSV cell: quoted (RFC 4180) where it holds a delimiter, a quote or a
/// line break, or starts or ends with white space.
fn csv_cell(text: &str) -> String {
    let plain = !text.contains([',', '"', '\n', '\r']) && text.trim() == text;
    if plain {
        text.to_string()
    } else {
        format!("\"{}\"", text.replace('"', "\"\""))
    }
}

/// A run table (CSV) with one row per log, for a lab to fill in a
/// spreadsheet: the id from the file's name, the role where the name says
/// it, every other cell the lab must give as a [`PLACEHOLDER`] (`servoid
/// check` names each by row and column), and the `log` cell, `log_cells`,
/// as the table's folder names it (same order as `logs`).
pub fn run_table_text(logs: &[FoundLog], log_cells: &[String]) -> String {
    let mut out = TABLE_HEADER.join(",");
    out.push('\n');
    for (log, cell) in logs.iter().zip(log_cells) {
        let role = role_of(&log.stem).map(|(r, _)| r);
        let filled = |what: &str| format!("{PLACEHOLDER} {what}");
        let (mass, damping, stiffness) = match role {
            Some("spring") => (
                String::new(),
                String::new(),
                filled("the spring's stiffness in N/m"),
            ),
            Some("validation") => (
                filled("the specimen's mass in kg"),
                filled("its damping in N s/m"),
                filled("its stiffness in N/m"),
            ),
            Some(_) => (String::new(), String::new(), String::new()),
            None => (
                filled("the specimen's mass in kg (empty unless a validation run)"),
                filled("its damping in N s/m (empty unless a validation run)"),
                filled("its stiffness in N/m (empty for a no_specimen or fit run)"),
            ),
        };
        let row = [
            log.id.clone(),
            role.map(str::to_string).unwrap_or_else(|| {
                filled("no_specimen, spring, validation or fit; the file's name does not say")
            }),
            filled("the controller's P gain in this run"),
            mass,
            damping,
            stiffness,
            cell.clone(),
        ];
        let cells: Vec<String> = row.iter().map(|c| csv_cell(c)).collect();
        out.push_str(&cells.join(","));
        out.push('\n');
    }
    out
}

fn run_block(out: &mut String, log: &FoundLog, back: &ReadBack) {
    let _ = writeln!(out, "\n[[runs]]\nid = {}", quoted(&log.id));
    match back {
        ReadBack::Read {
            sample_rate_hz,
            n_samples,
        } => {
            let _ = writeln!(
                out,
                "# {}: {n_samples} samples at {sample_rate_hz:.6} Hz ({:.1} s)",
                log.path,
                *n_samples as f64 / sample_rate_hz
            );
        }
        ReadBack::Failed(why) => {
            let _ = writeln!(
                out,
                "# {} does not read with these channels: {why}",
                log.path
            );
        }
        ReadBack::NotRead => {}
    }
    let role = role_of(&log.stem);
    match role {
        Some((r, _)) => {
            let _ = writeln!(out, "role = {}   # from the file's name", quoted(r));
        }
        None => {
            let _ = writeln!(
                out,
                "role = {}",
                fill("no_specimen, spring, validation or fit; the file's name does not say")
            );
        }
    }
    let _ = writeln!(
        out,
        "p_gain = {}",
        fill("the controller's P gain in this run")
    );
    match role.map(|(r, _)| r) {
        Some("spring") => {
            let _ = writeln!(
                out,
                "specimen = {{ stiffness_n_per_m = {} }}",
                fill("the spring's stiffness in N/m")
            );
        }
        Some("validation") => {
            let _ = writeln!(
                out,
                "specimen = {{ mass_kg = {}, damping_ns_per_m = {}, stiffness_n_per_m = {} }}",
                fill("the specimen's mass in kg"),
                fill("its damping in N s/m"),
                fill("its stiffness in N/m")
            );
        }
        Some(_) => {}
        None => {
            let _ = writeln!(
                out,
                "# A spring or validation run also needs its specimen:\n\
                 # specimen = {{ mass_kg = ..., damping_ns_per_m = ..., stiffness_n_per_m = ... }}"
            );
        }
    }
    if let Some(own) = &log.channels {
        run_channels(out, log, own);
    }
    match log.inspected.csv_delimiter.filter(|d| *d != ',') {
        Some(d) => {
            let decimal = if log.inspected.csv_decimal_comma {
                ", decimal = \",\""
            } else {
                ""
            };
            let _ = writeln!(
                out,
                "data = {{ log = {}, csv = {{ delimiter = {}{decimal} }} }}",
                quoted(&log.path),
                quoted(&d.to_string())
            );
        }
        None => {
            let _ = writeln!(out, "data = {{ log = {} }}", quoted(&log.path));
        }
    }
}

/// A run's own channels, where its log's columns are not the campaign's:
/// each as `channels.<key>`, which replaces `[channels]`' for this run.
fn run_channels(out: &mut String, log: &FoundLog, own: &ProposedChannels) {
    let _ = writeln!(
        out,
        "# {}'s columns are not those [channels] names; its own:",
        log.path
    );
    for c in &log.inspected.columns {
        let _ = writeln!(out, "#   {}", quoted(&c.name));
    }
    channel_lines(out, "channels.", own, log.inspected.rate_hz);
}

/// The folder a file is in (`.` for a bare name): where the paths a
/// manifest or run table names start from.
pub fn folder_of(file: &Path) -> PathBuf {
    match file.parent() {
        Some(p) if !p.as_os_str().is_empty() => p.to_path_buf(),
        _ => PathBuf::from("."),
    }
}

/// How many names a comment lists before it counts the rest.
const LISTED: usize = 10;

/// The first [`LISTED`] of `names`, comma-separated, and how many more
/// there are: a comment stays a line however many logs there are.
fn listed(names: &[String]) -> String {
    let mut s = names
        .iter()
        .take(LISTED)
        .cloned()
        .collect::<Vec<_>>()
        .join(", ");
    if names.len() > LISTED {
        s.push_str(&format!(" and {} more", names.len() - LISTED));
    }
    s
}

/// What a run table found among the logs says about them: its rows, the
/// rows whose log is not among them, the logs no row names. A row's `log`
/// cell is relative to the table's folder; a row without one names its log
/// by its id, as the file's stem.
pub fn table_comments(table: &Table, logs: &[&Path]) -> Vec<String> {
    let (Some(id_col), log_col) = (table.column("id"), table.column("log")) else {
        return vec![];
    };
    let dir = folder_of(&table.path);
    let key = |p: &Path| std::path::absolute(p).unwrap_or_else(|_| p.to_path_buf());
    let have: BTreeSet<PathBuf> = logs.iter().map(|p| key(p)).collect();
    let mut used = BTreeSet::new();
    let mut missing = Vec::new();
    let mut no_id = Vec::new();
    let mut rows = 0;
    for (n, cells) in table.rows.iter().enumerate() {
        let Some(id) = cells.get(id_col).cloned().flatten() else {
            no_id.push((n + 1).to_string());
            continue;
        };
        rows += 1;
        let cell = log_col.and_then(|c| cells.get(c).cloned().flatten());
        let hit = match cell {
            Some(c) => Some(key(&dir.join(c))).filter(|p| have.contains(p)),
            None => logs
                .iter()
                .find(|p| p.file_stem().is_some_and(|s| s.to_string_lossy() == id))
                .map(|p| key(p)),
        };
        match hit {
            Some(p) => {
                used.insert(p);
            }
            None => missing.push(id),
        }
    }
    let unused: Vec<String> = logs
        .iter()
        .filter(|p| !used.contains(&key(p)))
        .map(|p| p.display().to_string())
        .collect();
    let mut out = vec![format!(
        "{}: {} row(s); {} of the {rows} with an id find their log among the {} found",
        table.path.display(),
        table.rows.len(),
        rows - missing.len(),
        logs.len()
    )];
    if !no_id.is_empty() {
        out.push(format!(
            "row(s) {} have no id, and are no run until they have one (`servoid check` names them)",
            listed(&no_id)
        ));
    }
    if !missing.is_empty() {
        out.push(format!(
            "rows whose log is not there (their runs fail alone until it is): {}",
            listed(&missing)
        ));
    }
    if !unused.is_empty() {
        out.push(format!(
            "logs no row names (`servoid check` warns of them): {}",
            listed(&unused)
        ));
    }
    out
}

/// What reading each log with the proposed channels gave, in a few lines.
pub fn read_comments(logs: &[FoundLog], read: &[ReadBack]) -> Vec<String> {
    let mut rates = Vec::new();
    let mut seconds = Vec::new();
    let mut failed = Vec::new();
    for (log, back) in logs.iter().zip(read) {
        match back {
            ReadBack::Read {
                sample_rate_hz,
                n_samples,
            } => {
                rates.push(*sample_rate_hz);
                seconds.push(*n_samples as f64 / sample_rate_hz);
            }
            ReadBack::Failed(why) => failed.push(format!("{} ({why})", log.path)),
            ReadBack::NotRead => {}
        }
    }
    let range = |v: &[f64], digits: usize| {
        let (lo, hi) = v
            .iter()
            .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), &x| {
                (a.min(x), b.max(x))
            });
        if format!("{lo:.digits$}") == format!("{hi:.digits$}") {
            format!("{lo:.digits$}")
        } else {
            format!("{lo:.digits$} to {hi:.digits$}")
        }
    };
    let mut out = Vec::new();
    if !rates.is_empty() {
        out.push(format!(
            "{} log(s) read with these channels: {} Hz, {} s long",
            rates.len(),
            range(&rates, 6),
            range(&seconds, 1)
        ));
    }
    if !failed.is_empty() {
        out.push(format!(
            "{} log(s) do not read with these channels: {}",
            failed.len(),
            listed(&failed)
        ));
    }
    if logs
        .iter()
        .any(|l| l.inspected.csv_delimiter.is_some_and(|d| d != ','))
    {
        out.push(
            "some CSV logs are split on another delimiter than a comma, which a run table's rows cannot say: give them [[runs]] tables with data.csv.delimiter".into(),
        );
    }
    out
}

/// The plan that reads the log at `path` with the proposed channels (each
/// in its proposed unit, no offset, range or repair), so that `init` can
/// say the log's rate and length before the lab fills anything in; `None`
/// ([`ReadBack::NotRead`]) while the time, command or displacement channel,
/// or its unit, is still a placeholder.
pub fn log_plan(
    path: &Path,
    format: LogFormat,
    log: &FoundLog,
    p: &ProposedChannels,
) -> Option<LogPlan> {
    let length = |c: &Proposed| -> Option<ChannelPlan> {
        let unit: Unit = serde_json::from_value(serde_json::json!(c.unit?)).ok()?;
        Some(ChannelPlan {
            column: Column::Name(c.column.clone()?),
            unit,
            gain: unit.to_si(),
            offset: 0.0,
            range: None,
            repair: Repair::None,
        })
    };
    let time = match (&p.time.column, p.time.unit, log.inspected.rate_hz) {
        (Some(c), Some(u), _) => {
            let unit = serde_json::from_value::<TimeUnit>(serde_json::json!(u)).ok()?;
            TimePlan::Column {
                column: Column::Name(c.clone()),
                to_s: unit.to_si(),
            }
        }
        (None, _, Some(_)) => TimePlan::FromLog,
        _ => return None,
    };
    let (Some(command), Some(displacement)) = (length(&p.command), length(&p.displacement)) else {
        return None;
    };
    let csv = CsvOptions {
        delimiter: log.inspected.csv_delimiter.unwrap_or(',').to_string(),
        decimal: if log.inspected.csv_decimal_comma {
            ",".into()
        } else {
            ".".into()
        },
        ..CsvOptions::default()
    };
    Some(LogPlan {
        path: path.to_path_buf(),
        format,
        csv,
        sha256: None,
        channels: Channels {
            time,
            command,
            displacement,
            force: length(&p.force),
        },
        max_bytes: DEFAULT_MAX_LOG_MIB << 20,
    })
}

/// The logs as the manifest in `base` names them, each with its run id
/// and, where its columns are not the campaign's, its own channels; and
/// the campaign's channels (those most logs are proposed).
pub fn proposed_logs(
    files: &[(PathBuf, Inspected)],
    base: &Path,
    warnings: &mut Vec<String>,
) -> (Vec<FoundLog>, ProposedChannels) {
    let ids = unique_ids(files, warnings);
    let proposed: Vec<ProposedChannels> = files.iter().map(|(_, i)| propose(&i.columns)).collect();
    let channels = most_common(&proposed).clone();
    let found = files
        .iter()
        .zip(ids)
        .zip(proposed)
        .map(|(((path, inspected), id), own)| FoundLog {
            path: relative(path, base),
            stem: stem(path),
            id,
            channels: (!reads_with(&channels, &inspected.columns)).then_some(own),
            inspected: inspected.clone(),
        })
        .collect();
    (found, channels)
}

/// Each log's run id: its stem as an id ([`manifest_name`]);
/// where several logs would share one (`bare.csv` beside `bare.mat`, the
/// same name in two folders), each gets its extension and, if that is not
/// enough, its folder, with a warning: they may be one run twice.
fn unique_ids(files: &[(PathBuf, Inspected)], warnings: &mut Vec<String>) -> Vec<String> {
    let id_of = |p: &Path| manifest_name(&stem(p), "run");
    let mut ids: Vec<String> = files.iter().map(|(p, _)| id_of(p)).collect();
    let shared = |ids: &[String], i: usize| ids.iter().filter(|x| **x == ids[i]).count() > 1;
    let clashes: Vec<usize> = (0..ids.len()).filter(|&i| shared(&ids, i)).collect();
    if clashes.is_empty() {
        return ids;
    }
    let part = |p: &Path, what: fn(&Path) -> Option<&std::ffi::OsStr>| {
        what(p)
            .map(|s| s.to_string_lossy().into_owned())
            .unwrap_or_default()
    };
    for &i in &clashes {
        let p = &files[i].0;
        ids[i] = manifest_name(&format!("{}_{}", stem(p), part(p, Path::extension)), "run");
    }
    for &i in &clashes {
        if shared(&ids, i) {
            let p = &files[i].0;
            let folder = folder_of(p);
            ids[i] = manifest_name(
                &format!("{}_{}", part(&folder, Path::file_name), ids[i]),
                "run",
            );
        }
    }
    let mut seen = BTreeSet::new();
    for id in &mut ids {
        if !seen.insert(id.clone()) {
            let k = (2..)
                .find(|k| !seen.contains(&format!("{id}_{k}")))
                .expect("a free number");
            *id = format!("{id}_{k}");
            seen.insert(id.clone());
        }
    }
    let named: Vec<String> = clashes
        .iter()
        .map(|&i| format!("{} as `{}`", files[i].0.display(), ids[i]))
        .collect();
    warnings.push(format!(
        "logs whose names give the same run id are told apart by their extension or folder: {}; check they are different runs (one may be the other exported again)",
        named.join(", ")
    ));
    ids
}

/// The channels most logs are proposed (the first of the most common).
fn most_common(proposed: &[ProposedChannels]) -> &ProposedChannels {
    proposed
        .iter()
        .max_by_key(|p| {
            (
                proposed.iter().filter(|q| q == p).count(),
                std::cmp::Reverse(proposed.iter().position(|q| q == *p)),
            )
        })
        .expect("at least one log")
}

/// Whether every column `channels` names is among `columns`.
fn reads_with(channels: &ProposedChannels, columns: &[LogColumn]) -> bool {
    [
        &channels.time,
        &channels.command,
        &channels.displacement,
        &channels.force,
    ]
    .iter()
    .filter_map(|p| p.column.as_deref())
    .all(|c| columns.iter().any(|x| x.name == c))
}

fn stem(path: &Path) -> String {
    path.file_stem()
        .map(|s| s.to_string_lossy().into_owned())
        .unwrap_or_default()
}

/// `[run_table] logs` for `logs`: their folder, as the manifest in `base`
/// names it, when they share one; else a placeholder.
pub fn logs_spec(logs: &[&Path], base: &Path) -> String {
    let folders: BTreeSet<PathBuf> = logs
        .iter()
        .map(|p| std::path::absolute(folder_of(p)).unwrap_or_else(|_| folder_of(p)))
        .collect();
    match folders.into_iter().collect::<Vec<_>>().as_slice() {
        [one] => match relative(one, base) {
            r if r.is_empty() => ".".into(),
            r => r,
        },
        _ => format!(
            "{} a glob or folder matching the logs (they are in several folders)",
            PLACEHOLDER
        ),
    }
}

/// `path` as the manifest in `base` names it.
pub fn relative(path: &Path, base: &Path) -> String {
    let abs = |p: &Path| std::path::absolute(p).unwrap_or_else(|_| p.to_path_buf());
    pathdiff::diff_paths(abs(path), abs(base))
        .unwrap_or_else(|| path.to_path_buf())
        .to_string_lossy()
        .replace('\\', "/")
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::ingest::LogColumn;

    fn cols(names: &[&str]) -> Vec<LogColumn> {
        names
            .iter()
            .map(|n| LogColumn {
                name: n.to_string(),
                unit: None,
            })
            .collect()
    }

    /// The table `init --table` writes reads back, through the run table's
    /// reader, to the cells it meant: a placeholder with commas in it is
    /// one cell, a role the name gives is the role.
    #[test]
    fn a_proposed_run_table_reads_back_cell_for_cell() {
        let log = |stem: &str| FoundLog {
            path: format!("logs/{stem}.csv"),
            stem: stem.into(),
            id: manifest_name(stem, "run"),
            channels: None,
            inspected: Inspected {
                format: crate::ingest::LogFormat::Csv,
                columns: cols(&["t", "u", "x"]),
                rate_hz: None,
                csv_delimiter: Some(','),
                csv_decimal_comma: false,
            },
        };
        let logs = [log("log 1"), log("k2")];
        let cells = ["logs/log 1.csv".to_string(), "logs/k2.csv".to_string()];
        let text = run_table_text(&logs, &cells);
        let t = crate::ingest::table_from_bytes(
            std::path::Path::new("runs.csv"),
            text.into_bytes(),
            crate::ingest::TableFormat::Csv,
        )
        .unwrap();
        assert_eq!(t.columns, TABLE_HEADER);
        let cell = |row: usize, c: &str| t.rows[row][t.column(c).unwrap()].clone();
        assert_eq!(cell(0, "id").as_deref(), Some("log-1"));
        assert_eq!(
            cell(0, "role").as_deref(),
            Some("FILL: no_specimen, spring, validation or fit; the file's name does not say")
        );
        assert_eq!(cell(0, "log").as_deref(), Some("logs/log 1.csv"));
        assert_eq!(cell(1, "role").as_deref(), Some("spring"));
        assert_eq!(cell(1, "mass_kg"), None);
        assert!(
            cell(1, "stiffness_n_per_m")
                .unwrap()
                .starts_with(PLACEHOLDER)
        );
    }

    #[test]
    fn roles_come_from_file_names() {
        for (stem, role) in [
            ("no-specimen", Some("no_specimen")),
            ("bare_2024-05-01", Some("no_specimen")),
            ("empty", Some("no_specimen")),
            ("spring-k1", Some("spring")),
            ("k2", Some("spring")),
            ("exp3", Some("validation")),
            ("val_mass", Some("validation")),
            ("log1", None),
            ("0A", None),
        ] {
            assert_eq!(role_of(stem).map(|(r, _)| r), role, "{stem}");
        }
    }
}
