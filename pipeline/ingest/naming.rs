//! What a log's column names and the units a file states say about which
//! column is which channel: `disp_mm`, `Displacement (mm)`, `x1 [m]`, a
//! unit the file gives. `servoid init` proposes its channels with it, and
//! ingest finds with it a time column a manifest that states a rate did
//! not name.

use super::LogColumn;

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
/// whole words after splitting at what is not a letter or digit and at a
/// unit suffix), in English and in the languages of the labs' exports
/// seen (German `Zeit`, `Soll`, `Weg`, `Kraft`; French, Spanish, Italian).
const TIME_WORDS: [&str; 10] = [
    "t",
    "time",
    "times",
    "timestamp",
    "seconds",
    "sec",
    "zeit",
    "temps",
    "tiempo",
    "tempo",
];
const COMMAND_WORDS: [&str; 18] = [
    "cmd",
    "command",
    "u",
    "ref",
    "reference",
    "setpoint",
    "sp",
    "demand",
    "drive",
    "soll",
    "sollwert",
    "sollweg",
    "vorgabe",
    "consigne",
    "consigna",
    "comando",
    "referencia",
    "riferimento",
];
const DISPLACEMENT_WORDS: [&str; 22] = [
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
    "weg",
    "ist",
    "istwert",
    "istweg",
    "hub",
    "verschiebung",
    "déplacement",
    "deplacement",
    "desplazamiento",
    "posición",
    "spostamento",
    "posizione",
];
const FORCE_WORDS: [&str; 11] = [
    "f", "force", "load", "lc", "loadcell", "fa", "kraft", "last", "fuerza", "carga", "forza",
];

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
    // Letters beyond ASCII are letters (`Führung`, `déplacement`), not
    // places to split.
    let mut words: Vec<String> = base
        .split(|c: char| !c.is_alphanumeric())
        .filter(|w| !w.is_empty())
        .map(str::to_lowercase)
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

/// A time column among `columns`, found as [`propose`] finds one, with the
/// factor its unit (stated or in its name; seconds when none) takes to
/// seconds, and whether a unit was found.
pub fn time_column(columns: &[LogColumn]) -> Option<(String, f64, bool)> {
    let time = find(columns, &TIME_WORDS, Kind::Time, &[], "time");
    let to_s = match time.unit {
        Some("ms") => 1e-3,
        _ => 1.0,
    };
    time.column.map(|c| (c, to_s, time.unit.is_some()))
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

        // A German export: words and units in other forms.
        let p = propose(&cols(&["Zeit [s]", "Soll [mm]", "Weg [mm]", "Kraft/kN"]));
        assert_eq!(
            (p.time.column.as_deref(), p.time.unit),
            (Some("Zeit [s]"), Some("s"))
        );
        assert_eq!(
            (p.command.column.as_deref(), p.command.unit),
            (Some("Soll [mm]"), Some("mm"))
        );
        assert_eq!(
            (p.displacement.column.as_deref(), p.displacement.unit),
            (Some("Weg [mm]"), Some("mm"))
        );
        assert_eq!(
            (p.force.column.as_deref(), p.force.unit),
            (Some("Kraft/kN"), Some("kN"))
        );
        // A letter beyond ASCII does not split a word (`Führung` is not
        // `f` and `hrung`, a force).
        let p = propose(&cols(&["Zeit_s", "Führungsgröße_mm", "Déplacement (mm)"]));
        assert_eq!(p.force.column, None);
        assert_eq!(p.displacement.column.as_deref(), Some("Déplacement (mm)"));

        // The DAQ's anonymous channels: nothing to go on.
        let p = propose(&cols(&["CHANNEL0", "CHANNEL1", "CHANNEL2"]));
        assert!(
            [p.command.column, p.displacement.column, p.force.column]
                .iter()
                .all(Option::is_none)
        );
    }
}
