//! `servoid init`: a campaign manifest proposed from a folder of logs. The
//! channels are found from the columns' names and units (`disp_mm`,
//! `Displacement (mm)`, `x1 [m]`, a unit the file states), each run's role
//! from its file name (`no-specimen`, `bare`, `spring`, `k2`, `exp3`,
//! `val`), and every value only the lab knows (the specimen's stiffness,
//! mass and damping, the P gain, a unit no column gives, a role no name
//! gives) is written as a [`PLACEHOLDER`] string that `servoid check`
//! reports by key until it is filled. Pure: the logs come inspected
//! (`ingest::inspect`), the text goes back to `run` to write.

use std::fmt::Write as _;

use crate::ingest::{Inspected, LogColumn};

/// The prefix of a value the lab must fill in: `servoid check` names every
/// key that still holds one.
pub const PLACEHOLDER: &str = "FILL:";

/// One log as `servoid init` found it.
#[derive(Debug, Clone)]
pub struct FoundLog {
    /// The path as the manifest will name it (relative to the manifest).
    pub path: String,
    /// The file name without its extension: the run's id and role come
    /// from it.
    pub stem: String,
    pub inspected: Inspected,
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

/// A channel's column and unit as proposed, with how sure the guess is.
#[derive(Debug, Clone, PartialEq)]
pub struct Proposed {
    /// The column's name; None when no column looks like this channel.
    pub column: Option<String>,
    /// The unit's symbol as the manifest writes it; None when neither the
    /// name nor the file gives one.
    pub unit: Option<&'static str>,
    /// How the guess was made, for the comment beside it.
    pub how: String,
}

/// The four channels proposed for one log.
#[derive(Debug, Clone, PartialEq)]
pub struct ProposedChannels {
    pub time: Proposed,
    pub command: Proposed,
    pub displacement: Proposed,
    pub force: Proposed,
}

/// The channel kinds, and the words that name each in a column (lowercase,
/// whole words after splitting at non-letters and at a unit suffix).
const TIME_WORDS: [&str; 6] = ["t", "time", "times", "timestamp", "seconds", "sec"];
const COMMAND_WORDS: [&str; 9] = [
    "cmd",
    "command",
    "u",
    "ref",
    "reference",
    "setpoint",
    "sp",
    "demand",
    "drive",
];
const DISPLACEMENT_WORDS: [&str; 10] = [
    "x",
    "x1",
    "disp",
    "displacement",
    "lvdt",
    "pos",
    "position",
    "stroke",
    "y",
    "feedback",
];
const FORCE_WORDS: [&str; 6] = ["f", "force", "load", "lc", "loadcell", "fa"];

/// Units as columns write them, with the manifest's symbol.
fn unit_symbol(word: &str) -> Option<&'static str> {
    Some(match word.to_ascii_lowercase().as_str() {
        "s" | "sec" | "secs" | "seconds" => "s",
        "ms" | "msec" => "ms",
        "m" | "meter" | "meters" | "metre" | "metres" => "m",
        "cm" => "cm",
        "mm" | "millimeter" | "millimeters" | "millimetre" | "millimetres" => "mm",
        "in" | "inch" | "inches" => "in",
        "n" | "newton" | "newtons" => "N",
        "kn" => "kN",
        "lbf" | "lb" | "lbs" => "lbf",
        _ => return None,
    })
}

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Kind {
    Time,
    Length,
    Force,
}

fn kind_of(symbol: &str) -> Kind {
    match symbol {
        "s" | "ms" => Kind::Time,
        "N" | "kN" | "lbf" => Kind::Force,
        _ => Kind::Length,
    }
}

/// A column's name split into its words and the unit it names, if any:
/// `disp_mm` -> (["disp"], mm), `Displacement (mm)` -> (["displacement"],
/// mm), `x1 [m]` -> (["x1"], m), `g/u` -> (["g", "u"], none).
fn words_and_unit(name: &str) -> (Vec<String>, Option<&'static str>) {
    let mut unit = None;
    let mut base = name.to_string();
    for (open, close) in [('(', ')'), ('[', ']')] {
        if let (Some(a), Some(b)) = (name.rfind(open), name.rfind(close))
            && a < b
        {
            unit = unit.or(unit_symbol(name[a + 1..b].trim()));
            base = format!("{}{}", &name[..a], &name[b + 1..]);
        }
    }
    let mut words: Vec<String> = base
        .split(|c: char| !c.is_ascii_alphanumeric())
        .filter(|w| !w.is_empty())
        .map(str::to_ascii_lowercase)
        .collect();
    // A trailing unit word (`disp_mm`, `force kN`), unless it is the only
    // word (a column named `m` or `s` is not a unit).
    if words.len() > 1
        && let Some(u) = words.last().and_then(|w| unit_symbol(w))
    {
        unit = unit.or(Some(u));
        words.pop();
    }
    (words, unit)
}

/// The best column for a channel: one whose words include the channel's
/// (the last words first: `g/u` is channel `u` of group `g`) and whose
/// unit, when it has one, is of the right kind.
fn find(
    columns: &[LogColumn],
    words: &[&str],
    kind: Kind,
    taken: &[String],
    what: &str,
) -> Proposed {
    let mut best: Option<(usize, &LogColumn, Option<&'static str>, bool)> = None;
    for c in columns {
        if taken.contains(&c.name) {
            continue;
        }
        let (w, named_unit) = words_and_unit(&c.name);
        let stated = c.unit.as_deref().and_then(unit_symbol);
        let unit = stated.or(named_unit);
        if unit.is_some_and(|u| kind_of(u) != kind) {
            continue;
        }
        // A later word counts more: in `disp_cmd` the command wins.
        let score = w
            .iter()
            .enumerate()
            .filter(|(_, x)| words.contains(&x.as_str()))
            .map(|(i, _)| 10 + i)
            .max();
        if let Some(s) = score {
            let s = s + usize::from(unit.is_some()) * 5;
            if best.is_none_or(|(b, ..)| s > b) {
                best = Some((s, c, unit, stated.is_some()));
            }
        }
    }
    match best {
        Some((_, c, unit, stated)) => Proposed {
            column: Some(c.name.clone()),
            unit,
            how: match (unit, stated) {
                (Some(_), true) => format!("{what}: by its name and the unit the file states"),
                (Some(_), false) => format!("{what}: by its name and the unit in it"),
                (None, _) => format!("{what}: by its name; no unit in it or in the file"),
            },
        },
        None => Proposed {
            column: None,
            unit: None,
            how: format!("{what}: no column's name says it"),
        },
    }
}

/// The channels proposed for a log's columns. Command and force are
/// looked for first (their words are the more specific), then the
/// displacement and time among the rest.
pub fn propose(columns: &[LogColumn]) -> ProposedChannels {
    let mut taken = Vec::new();
    let command = find(columns, &COMMAND_WORDS, Kind::Length, &taken, "command");
    taken.extend(command.column.clone());
    let force = find(columns, &FORCE_WORDS, Kind::Force, &taken, "force");
    taken.extend(force.column.clone());
    let displacement = find(
        columns,
        &DISPLACEMENT_WORDS,
        Kind::Length,
        &taken,
        "displacement",
    );
    taken.extend(displacement.column.clone());
    let time = find(columns, &TIME_WORDS, Kind::Time, &taken, "time");
    ProposedChannels {
        time,
        command,
        displacement,
        force,
    }
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
    out.push_str("[channels]\n");
    let rate = logs.first().and_then(|l| l.inspected.rate_hz);
    match (&channels.time.column, rate) {
        (Some(_), _) => channel_line(&mut out, "time", &channels.time, "s or ms", false),
        (None, Some(hz)) => {
            let _ = writeln!(
                out,
                "# time: no time column; the file states its rate, {hz} Hz, which servoid reads itself"
            );
        }
        (None, None) => {
            let _ = writeln!(out, "# {}", channels.time.how);
            let _ = writeln!(
                out,
                "time = {{ sample_rate_hz = {} }}",
                fill("the sampling rate in Hz")
            );
        }
    }
    channel_line(
        &mut out,
        "command",
        &channels.command,
        "m, cm, mm or in",
        false,
    );
    channel_line(
        &mut out,
        "displacement",
        &channels.displacement,
        "m, cm, mm or in",
        false,
    );
    channel_line(&mut out, "force", &channels.force, "N, kN or lbf", true);
    out.push_str(
        "\n# The band fitted and the FRF settings: the defaults, which suit a sweep\n\
         # of a few minutes at 1-2 kHz; see docs/manifest.md.\n\
         [identification]\nband_hz = [0.5, 30.0]\ncoherence_min = 0.8\n",
    );
    match runs {
        Runs::Blocks(read) => {
            for (log, back) in logs.iter().zip(*read) {
                run_block(&mut out, log, back);
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
    out
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
            manifest_name(&log.stem, "run"),
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
    let _ = writeln!(
        out,
        "\n[[runs]]\nid = {}",
        quoted(&manifest_name(&log.stem, "run"))
    );
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
    match log.inspected.csv_delimiter.filter(|d| *d != ',') {
        Some(d) => {
            let _ = writeln!(
                out,
                "data = {{ log = {}, csv = {{ delimiter = {} }} }}",
                quoted(&log.path),
                quoted(&d.to_string())
            );
        }
        None => {
            let _ = writeln!(out, "data = {{ log = {} }}", quoted(&log.path));
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn cols(names: &[&str]) -> Vec<LogColumn> {
        names
            .iter()
            .map(|n| LogColumn {
                name: n.to_string(),
                unit: None,
            })
            .collect()
    }

    /// Columns as labs name them, each with the channel and unit a reader
    /// of the name would take.
    #[test]
    fn channels_are_found_by_name_and_unit() {
        let p = propose(&cols(&[
            "time_s",
            "command_mm",
            "displacement_mm",
            "force_kn",
        ]));
        assert_eq!(p.time.column.as_deref(), Some("time_s"));
        assert_eq!(
            (p.command.column.as_deref(), p.command.unit),
            (Some("command_mm"), Some("mm"))
        );
        assert_eq!(p.displacement.unit, Some("mm"));
        assert_eq!(
            (p.force.column.as_deref(), p.force.unit),
            (Some("force_kn"), Some("kN"))
        );

        let p = propose(&cols(&[
            "Time (s)",
            "Displacement (mm)",
            "Disp Cmd (mm)",
            "Load [kN]",
        ]));
        assert_eq!(p.command.column.as_deref(), Some("Disp Cmd (mm)"));
        assert_eq!(p.displacement.column.as_deref(), Some("Displacement (mm)"));
        assert_eq!(
            (p.force.column.as_deref(), p.force.unit),
            (Some("Load [kN]"), Some("kN"))
        );
        assert_eq!(
            (p.time.column.as_deref(), p.time.unit),
            (Some("Time (s)"), Some("s"))
        );

        let p = propose(&cols(&["t", "u", "x1 [m]", "f"]));
        assert_eq!(
            (p.displacement.column.as_deref(), p.displacement.unit),
            (Some("x1 [m]"), Some("m"))
        );
        assert_eq!(
            (p.command.column.as_deref(), p.command.unit),
            (Some("u"), None)
        );
        assert_eq!(p.force.column.as_deref(), Some("f"));

        // TDMS and HDF5 paths; a unit the file states beats none.
        let mut c = cols(&["g/u", "g/x", "g/f"]);
        c[1].unit = Some("mm".into());
        let p = propose(&c);
        assert_eq!(
            (p.displacement.column.as_deref(), p.displacement.unit),
            (Some("g/x"), Some("mm"))
        );
        assert!(p.displacement.how.contains("the unit the file states"));
        assert_eq!(p.time.column, None);

        // The DAQ's anonymous channels: nothing to go on.
        let p = propose(&cols(&["CHANNEL0", "CHANNEL1", "CHANNEL2"]));
        assert!(
            [p.command.column, p.displacement.column, p.force.column]
                .iter()
                .all(Option::is_none)
        );
    }

    /// The table `init --table` writes reads back, through the run table's
    /// reader, to the cells it meant: a placeholder with commas in it is
    /// one cell, a role the name gives is the role.
    #[test]
    fn a_proposed_run_table_reads_back_cell_for_cell() {
        let log = |stem: &str| FoundLog {
            path: format!("logs/{stem}.csv"),
            stem: stem.into(),
            inspected: Inspected {
                format: crate::ingest::LogFormat::Csv,
                columns: cols(&["t", "u", "x"]),
                rate_hz: None,
                csv_delimiter: Some(','),
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
