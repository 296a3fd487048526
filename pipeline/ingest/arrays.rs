//! Logs saved as named numeric arrays (MATLAB MAT-files, level 5 and v7.3;
//! HDF5; TDMS channels): how a plan's channels are found among them, so
//! that every such format addresses channels, names what is missing and
//! checks units the same way.
//!
//! - `Column::Name("x1")`: the numeric vector `x1` (1 x N or N x 1); inside
//!   a struct or group, its path: `log.x1` (MATLAB), `run1/x1` (HDF5),
//!   `Group/x1` (TDMS).
//! - `Column::Name("data:2")`: channel 2 (0-based) of the 2-D variable
//!   `data`, when no variable is literally named `data:2`.
//! - `Column::Index(2)`: channel 2 of the only 2-D numeric variable.
//!
//! A 2-D variable's channels are its columns (N x channels), or its rows
//! when it is wide (Simulink's To File writes `[t; u; y]`). Places are
//! 1-based sample numbers. For users: docs/manifest.md, "Log formats".

use crate::warning::Warning;
use std::path::Path;

use super::plan::{Column, LogPlan, TimePlan};
use super::{
    At, FormatProblem, IngestError, MatVariable, Raw, RawTime, Wanted, dims, list, wanted,
};
use crate::units::Unit;

/// A file of named numeric arrays.
pub(super) trait Arrays {
    /// Every numeric variable with its size (rows x cols as MATLAB shows
    /// it), in the order messages list them.
    fn variables(&self) -> &[MatVariable];

    /// Variable `name`'s values, real, as f64, column-major over its size.
    fn values(&self, name: &str, channel: &'static str) -> Result<Vec<f64>, IngestError>;

    /// The time base the file gives itself, when the plan asks for it: by
    /// default the vector variable `t`, else `time`.
    fn own_time(&self, path: &Path) -> Result<RawTime, IngestError> {
        let v = ["t", "time"]
            .into_iter()
            .find_map(|n| self.variables().iter().find(|v| v.name == n))
            .ok_or_else(|| {
                IngestError::format(
                    path,
                    FormatProblem::NoTimeBase {
                        variables: self.variables().to_vec(),
                    },
                )
            })?;
        Ok(RawTime::Column {
            raw: vector(path, self, &v.name, "time")?,
            to_s: 1.0,
            column: format!("`{}`", v.name),
        })
    }

    /// The unit the file states for variable `name`, when it states one.
    fn stated_unit(&self, _name: &str) -> Option<String> {
        None
    }

    /// The variables the file holds that no channel can take (text,
    /// booleans, links servoid does not follow), each with what it is, so a
    /// plan that names one is told what it named rather than that it is
    /// not there.
    fn unusable(&self) -> &[Unusable] {
        &[]
    }

    /// What the reader passed over that a plan might have meant, in words.
    fn skipped(&self) -> Option<String> {
        None
    }

    /// What `name`, not a variable, is when it is a link the reader does
    /// not follow, in words.
    fn link(&self, _name: &str) -> Option<String> {
        None
    }

    /// What a reader that read the file has to say of it (a recording cut
    /// short), each naming the file.
    fn warnings(&self) -> Vec<Warning> {
        Vec::new()
    }
}

/// A variable in the file that is not a numeric array, and what it is
/// (`a string dataset`, `a soft link`).
#[derive(Debug, Clone, PartialEq)]
pub(super) struct Unusable {
    pub name: String,
    pub what: String,
}

/// The last component of a grouped name: `x1` of `log/x1`.
fn leaf(name: &str) -> &str {
    name.rsplit_once('/').map_or(name, |(_, l)| l)
}

/// The vector variables and each 2-D variable's channels (`name:j`), with
/// the units the file states, as `servoid init` lists them.
pub(super) fn columns(arrays: &dyn Arrays) -> Vec<super::LogColumn> {
    let mut out = Vec::new();
    for v in arrays.variables() {
        let unit = arrays.stated_unit(&v.name);
        if is_vector(&v.size) {
            out.push(super::LogColumn {
                name: v.name.clone(),
                unit,
            });
        } else if v.size.len() == 2 {
            let n = v.size[0].min(v.size[1]);
            out.extend((0..n).map(|j| super::LogColumn {
                name: format!("{}:{j}", v.name),
                unit: unit.clone(),
            }));
        }
    }
    out
}

/// Read a plan's channels from `arrays`.
pub(super) fn read<'a>(
    path: &Path,
    arrays: &dyn Arrays,
    plan: &'a LogPlan,
) -> Result<Raw<'a>, IngestError> {
    let format = |problem| IngestError::format(path, problem);
    let want = wanted(plan);
    let mut warnings = arrays.warnings();
    let mut columns = Vec::with_capacity(want.len());
    for w in &want {
        let (variable, values) = column(path, arrays, w)?;
        if let Some(unit) = plan_unit(plan, w.channel) {
            check_unit(path, arrays, &variable, w.channel, unit, &mut warnings)?;
        }
        columns.push((w.channel, values));
    }
    let mut it = columns.into_iter();
    let time = match &plan.channels.time {
        TimePlan::Column { column, to_s } => RawTime::Column {
            raw: it.next().expect("time wanted").1,
            to_s: *to_s,
            column: column.to_string(),
        },
        TimePlan::SampleRate { hz } => RawTime::Rate {
            hz: *hz,
            from: "manifest",
        },
        TimePlan::FromLog => arrays.own_time(path)?,
    };
    let rest: Vec<(&'static str, Vec<f64>)> = it.collect();
    let mut lengths = rest.iter().map(|(c, v)| (*c, v.len())).collect::<Vec<_>>();
    if let RawTime::Column { raw, .. } = &time {
        lengths.insert(0, ("time", raw.len()));
    }
    if lengths.iter().any(|(_, n)| *n != lengths[0].1) {
        return Err(format(FormatProblem::Lengths { lengths }));
    }
    let mut rest = rest.into_iter().map(|(_, v)| v);
    let command = rest.next().expect("command wanted");
    let displacement = rest.next().expect("displacement wanted");
    let force = rest.next();
    Ok(Raw {
        time,
        command,
        displacement,
        force,
        locate: Box::new(|i| At::Element(i + 1)),
        warnings,
    })
}

/// The unit the plan gives a channel (none for time, whose unit is the
/// plan's `to_s`).
fn plan_unit(plan: &LogPlan, channel: &str) -> Option<Unit> {
    let ch = &plan.channels;
    match channel {
        "command" => Some(ch.command.unit),
        "displacement" => Some(ch.displacement.unit),
        "force" => ch.force.as_ref().map(|f| f.unit),
        _ => None,
    }
}

/// A unit as files state it (`mm`, `Millimeters`, `kN`, ...), when servoid
/// knows it.
fn parse_unit(text: &str) -> Option<Unit> {
    let t = text.trim();
    let lower = t.to_ascii_lowercase();
    Some(match lower.as_str() {
        "m" | "meter" | "meters" | "metre" | "metres" => Unit::Meter,
        "cm" | "centimeter" | "centimeters" | "centimetre" | "centimetres" => Unit::Centimeter,
        "mm" | "millimeter" | "millimeters" | "millimetre" | "millimetres" => Unit::Millimeter,
        "in" | "inch" | "inches" => Unit::Inch,
        "n" | "newton" | "newtons" => Unit::Newton,
        "kn" | "kilonewton" | "kilonewtons" => Unit::Kilonewton,
        "lbf" | "lb" | "lbs" => Unit::PoundForce,
        _ => return None,
    })
}

/// The unit a file states for a channel's variable against the manifest's:
/// a different known unit is refused (a log in m read as mm is a factor of
/// 1000 in every parameter); one servoid does not know is a warning.
fn check_unit(
    path: &Path,
    arrays: &dyn Arrays,
    variable: &str,
    channel: &'static str,
    unit: Unit,
    warnings: &mut Vec<Warning>,
) -> Result<(), IngestError> {
    let Some(stated) = arrays
        .stated_unit(variable)
        .filter(|s| !s.trim().is_empty())
    else {
        return Ok(());
    };
    match parse_unit(&stated) {
        Some(u) if u == unit => Ok(()),
        Some(_) => Err(IngestError::format(
            path,
            FormatProblem::UnitDisagrees {
                variable: variable.to_string(),
                channel,
                stated,
                manifest: unit.symbol(),
            },
        )),
        None => {
            warnings.push(Warning::new(
                format!(
                    "the {channel}'s unit {stated:?} is unknown; the manifest's `{}` is used",
                    unit.symbol()
                ),
                format!(
                    "{}: variable `{variable}` ({channel} channel) states its unit as {stated:?}, which servoid does not know; the manifest's `{}` is used",
                    path.display(),
                    unit.symbol()
                ),
            ));
            Ok(())
        }
    }
}

/// One wanted column's variable and values: a vector variable by name, one
/// channel of a 2-D variable as `name:index`, or by index the one 2-D
/// table's channel.
fn column(
    path: &Path,
    arrays: &dyn Arrays,
    w: &Wanted<'_>,
) -> Result<(String, Vec<f64>), IngestError> {
    let missing = || missing_column(path, arrays, w);
    let find = |name: &str| find_variable(path, arrays, name, w.channel);
    match w.column {
        Column::Name(n) => match find(n)? {
            Some(v) => Ok((v.name.clone(), vector(path, arrays, &v.name, w.channel)?)),
            None => {
                let (var, ch) = n
                    .rsplit_once(':')
                    .and_then(|(v, c)| Some((v, c.trim().parse::<usize>().ok()?)))
                    .ok_or_else(missing)?;
                let v = find(var)?.ok_or_else(missing)?;
                Ok((v.name.clone(), channel(path, arrays, v, ch, w.channel)?))
            }
        },
        Column::Index(i) => {
            let tables: Vec<&MatVariable> = arrays
                .variables()
                .iter()
                .filter(|v| !is_vector(&v.size))
                .collect();
            match tables.as_slice() {
                [v] => Ok((v.name.clone(), channel(path, arrays, v, *i, w.channel)?)),
                [] => Err(IngestError::format(
                    path,
                    FormatProblem::NoTable {
                        channel: w.channel,
                        index: *i,
                        variables: arrays.variables().to_vec(),
                    },
                )),
                _ => Err(IngestError::format(
                    path,
                    FormatProblem::SeveralTables {
                        channel: w.channel,
                        index: *i,
                        tables: tables.iter().map(|v| v.name.clone()).collect(),
                    },
                )),
            }
        }
    }
}

/// The variable a plan names `name`: by its name, else, for a bare name,
/// the grouped variable of that name where only one group holds it (as a
/// manifest carried over from CSV logs names it). None when there is none;
/// an error naming what the file holds when it is not numeric, or when
/// several groups hold the bare name.
fn find_variable<'a>(
    path: &Path,
    arrays: &'a dyn Arrays,
    name: &str,
    channel: &'static str,
) -> Result<Option<&'a MatVariable>, IngestError> {
    let not_numeric = |u: &Unusable| {
        IngestError::format(
            path,
            FormatProblem::NotNumericVariable {
                variable: u.name.clone(),
                channel,
                what: u.what.clone(),
            },
        )
    };
    if let Some(v) = arrays.variables().iter().find(|v| v.name == name) {
        return Ok(Some(v));
    }
    // Not found: a link the reader does not follow is named as one.
    let absent = || match arrays.link(name) {
        Some(what) => Err(not_numeric(&Unusable {
            name: name.to_string(),
            what,
        })),
        None => Ok(None),
    };
    if let Some(u) = arrays.unusable().iter().find(|u| u.name == name) {
        return Err(not_numeric(u));
    }
    if name.contains('/') {
        return absent();
    }
    let grouped: Vec<&MatVariable> = arrays
        .variables()
        .iter()
        .filter(|v| leaf(&v.name) == name)
        .collect();
    let others: Vec<&Unusable> = arrays
        .unusable()
        .iter()
        .filter(|u| leaf(&u.name) == name)
        .collect();
    match (grouped.as_slice(), others.as_slice()) {
        ([v], []) => Ok(Some(v)),
        ([], [u]) => Err(not_numeric(u)),
        ([], []) => absent(),
        _ => Err(IngestError::format(
            path,
            FormatProblem::AmbiguousName {
                name: name.to_string(),
                channel,
                found: grouped
                    .iter()
                    .map(|v| v.name.clone())
                    .chain(others.iter().map(|u| u.name.clone()))
                    .collect(),
            },
        )),
    }
}

/// A wanted column that is not there, with what the file holds: its
/// variables, those that are not numeric, and what the reader skipped.
fn missing_column(path: &Path, arrays: &dyn Arrays, w: &Wanted<'_>) -> IngestError {
    let mut available = format!("variables: {}", list(arrays.variables()));
    if !arrays.unusable().is_empty() {
        let unusable = arrays
            .unusable()
            .iter()
            .map(|u| format!("`{}` ({})", u.name, u.what));
        available.push_str(&format!("; not numeric: {}", list(unusable)));
    }
    if let Some(skipped) = arrays.skipped() {
        available.push_str(&format!("; skipped: {skipped}"));
    }
    IngestError::MissingColumn {
        path: path.to_path_buf(),
        channel: w.channel,
        column: w.column.to_string(),
        available,
    }
}

/// A 1 x N or N x 1 size (an empty or scalar one counts too).
pub(super) fn is_vector(size: &[usize]) -> bool {
    size.len() == 2 && size.iter().filter(|&&d| d > 1).count() <= 1
}

/// Variable `name`'s values, checked against its declared size: a damaged
/// file can declare more elements than it holds (found by the MAT fuzz
/// target), and indexing by the declared size would run off the end.
fn sized_values(
    path: &Path,
    arrays: &(impl Arrays + ?Sized),
    v: &MatVariable,
    channel: &'static str,
) -> Result<Vec<f64>, IngestError> {
    let values = arrays.values(&v.name, channel)?;
    let declared: usize = v.size.iter().product();
    if values.len() != declared {
        return Err(IngestError::format(
            path,
            FormatProblem::SizeMismatch {
                variable: v.name.clone(),
                channel,
                size: v.size.clone(),
                held: values.len(),
            },
        ));
    }
    Ok(values)
}

/// A vector variable's values.
fn vector(
    path: &Path,
    arrays: &(impl Arrays + ?Sized),
    name: &str,
    channel: &'static str,
) -> Result<Vec<f64>, IngestError> {
    let v = arrays
        .variables()
        .iter()
        .find(|v| v.name == name)
        .expect("a listed variable");
    if !is_vector(&v.size) {
        return Err(IngestError::format(
            path,
            FormatProblem::NotVector {
                variable: v.name.clone(),
                channel,
                size: v.size.clone(),
            },
        ));
    }
    sized_values(path, arrays, v, channel)
}

/// Channel `j` of a 2-D variable: its column `j`, or its row `j` when the
/// variable is wide (fewer rows than columns).
fn channel(
    path: &Path,
    arrays: &dyn Arrays,
    v: &MatVariable,
    j: usize,
    channel: &'static str,
) -> Result<Vec<f64>, IngestError> {
    let size = &v.size;
    if size.len() != 2 {
        return Err(IngestError::format(
            path,
            FormatProblem::NotTable {
                variable: v.name.clone(),
                channel,
                size: size.clone(),
            },
        ));
    }
    let (rows, cols) = (size[0], size[1]);
    let wide = rows < cols;
    let n_channels = if wide { rows } else { cols };
    if j >= n_channels {
        return Err(IngestError::MissingColumn {
            path: path.to_path_buf(),
            channel,
            column: format!("`{}:{j}`", v.name),
            available: format!(
                "`{}` is {} and holds channels 0 to {} in its {}",
                v.name,
                dims(size),
                n_channels.saturating_sub(1),
                if wide { "rows" } else { "columns" }
            ),
        });
    }
    let all = sized_values(path, arrays, v, channel)?;
    // Column-major storage: element (r, c) sits at r + c * rows.
    Ok(if wide {
        (0..cols).map(|c| all[j + c * rows]).collect()
    } else {
        all[j * rows..(j + 1) * rows].to_vec()
    })
}
