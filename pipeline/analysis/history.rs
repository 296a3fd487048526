//! A campaign's place in its rig's history, pure: the history table's rows
//! as entries, this campaign's entry, where it goes (in place of its own
//! earlier entry on a rerun, so reruns add nothing and give the same
//! bytes) and its drift checks against the entries before it
//! (`drift::check`). `run` reads and writes the table.

use crate::drift::{self, Entry, OPTIONAL_TABLE_COLUMNS, TABLE_COLUMNS};
use crate::ingest::{self, Table};
use crate::manifest::Campaign;
use crate::results::{DriftResult, Results, RigResult};
use crate::warning::Warning;

/// Columns of a history table that servoid does not write, with each
/// row's cell.
#[derive(Debug, Clone, Default)]
pub struct Extra {
    pub names: Vec<String>,
    pub rows: Vec<Vec<Option<String>>>,
}

/// This campaign's entry and its place among `entries` (its own earlier
/// entry's, or the end); records the drift checks against the entries
/// before that place in `results.drift`, and a warning when the rig starts
/// a new history beside a rig of a close name. None without a rig. `history_file` is the table
/// as results.json names it, `file_name` as the warning does.
/// `replaced` are the audit file's corrections: each entry a night's
/// analysis replaced, with the inputs' hash of the analysis that did, so a
/// rerun of that analysis says what it replaced as the first run did
/// (same inputs, same results).
pub fn place(
    campaign: &Campaign,
    entries: &[Entry],
    replaced: &[(String, Entry)],
    results: &mut Results,
    history_file: &str,
    file_name: &str,
) -> Option<(usize, Entry)> {
    let rig = results.rig.as_ref()?;
    let entry = entry_of(campaign, results, rig);
    let own = entries
        .iter()
        .position(|e| e.rig == entry.rig && e.inputs_sha256 == entry.inputs_sha256);
    // The same night analysed again (same rig, campaign, date and logs)
    // with its manifest corrected or its runs renamed: it takes the earlier
    // entry's place, which the audit file keeps. Another campaign on the
    // same logs is another entry.
    let same_night = |e: &Entry| {
        e.rig == entry.rig
            && e.campaign == entry.campaign
            && e.date == entry.date
            && entry.logs_sha256.is_some()
            && e.logs_sha256 == entry.logs_sha256
    };
    let corrected = match own {
        Some(_) => None,
        None => entries.iter().position(same_night),
    };
    let was_replaced = corrected.map(|k| &entries[k]).or_else(|| {
        own?;
        replaced
            .iter()
            .rev()
            .find(|(by, old)| *by == entry.inputs_sha256 && old.rig == entry.rig)
            .map(|(_, old)| old)
    });
    if let Some(old) = was_replaced {
        results.warnings.push(Warning::new(
            "history: these logs were analysed before; this analysis replaces that entry",
            format!(
                "history: this night's logs were analysed before by this campaign{} (inputs {}): this analysis replaces that entry of {file_name}, and the replaced row is kept in {}",
                old.date.as_ref().map_or(String::new(), |d| format!(", date {d}")),
                &old.inputs_sha256[..old.inputs_sha256.len().min(12)],
                audit_name(file_name),
            ),
        ));
    }
    let slot = own.or(corrected).unwrap_or(entries.len());
    let earlier: Vec<Entry> = entries[..slot]
        .iter()
        .filter(|e| e.rig == entry.rig)
        .cloned()
        .collect();
    if !entries.iter().any(|e| e.rig == entry.rig)
        && let Some((other, n)) = close_rig(entries, &entry.rig)
    {
        results.warnings.push(Warning::new(
            format!(
                "rig `{}` starts a new history beside rig `{other}`: renamed?",
                entry.rig
            ),
            format!(
                "rig `{}` starts a new history in {}, which holds {n} {} of rig `{other}`: if that is this rig renamed, give [rig] name = \"{other}\" to check its drift against {}",
                entry.rig,
                file_name,
                if n == 1 { "entry" } else { "entries" },
                if n == 1 { "it" } else { "them" },
            ),
        ));
    }
    let rule = campaign.history.rule;
    let checks = drift::check(&earlier, &entry, rule);
    let alarms = checks
        .iter()
        .filter(|c| c.alarm)
        .map(|c| alarm(&entry.rig, c, &rule))
        .collect();
    results.drift = Some(DriftResult {
        rig: entry.rig.clone(),
        history_file: history_file.to_string(),
        earlier_entries: earlier.len(),
        window: rule.window,
        threshold: rule.threshold,
        checks,
        alarms,
    });
    Some((slot, entry))
}

/// The audit file beside history file `file_name`: `<name>.audit.jsonl`.
pub fn audit_name(file_name: &str) -> String {
    format!("{file_name}.audit.jsonl")
}

/// This campaign's entry: its rig's parameters with their stds.
fn entry_of(campaign: &Campaign, results: &Results, rig: &RigResult) -> Entry {
    Entry {
        rig: campaign.rig_name.clone(),
        campaign: campaign.name.clone(),
        date: campaign.runs.iter().filter_map(|r| r.date.clone()).max(),
        inputs_sha256: inputs_sha256(results),
        results_sha256: String::new(),
        servoid_version: env!("CARGO_PKG_VERSION").to_string(),
        p_gain: rig.p_gain,
        beta1: rig.beta1.value,
        beta1_std: rig.beta1.std,
        a1b0: rig.a1b0.value,
        a1b0_std: rig.a1b0.std,
        a2: rig.a2.value,
        a2_std: rig.a2.std,
        a3: rig.a3.value,
        a3_std: rig.a3.std,
        delay_s: night_delay(results),
        logs_sha256: logs_sha256(results),
    }
}

/// The night's actuator delay: the median of its no-specimen runs'
/// measured delays (the actuator alone), or of all its runs' when it has
/// none; None when no run measured one.
fn night_delay(results: &Results) -> Option<f64> {
    let delays = |bare: bool| -> Vec<f64> {
        results
            .runs
            .iter()
            .filter(|r| !bare || r.role == crate::manifest::Role::NoSpecimen)
            .filter_map(|r| r.tracking.as_ref()?.get().measured.delay_xcorr_s)
            .collect()
    };
    let mut d = delays(true);
    if d.is_empty() {
        d = delays(false);
    }
    d.sort_by(f64::total_cmp);
    match d.len() {
        0 => None,
        n if n % 2 == 1 => Some(d[n / 2]),
        n => Some(0.5 * (d[n / 2 - 1] + d[n / 2])),
    }
}

/// The alarm's text: which parameter of `rig` moved, from what, by how much,
/// beyond which limit.
fn alarm(rig: &str, c: &drift::Check, rule: &drift::Rule) -> String {
    format!(
        "rig `{}`: {} = {:.6e} moved {:+.3e} from the median {:.6e} of its last {} entries, beyond {} x {:.3e} = {:.3e}",
        rig,
        c.parameter,
        c.value,
        c.deviation.unwrap_or(0.0),
        c.median.unwrap_or(0.0),
        c.entries,
        rule.threshold,
        c.limit.unwrap_or(0.0) / rule.threshold,
        c.limit.unwrap_or(0.0)
    )
}

/// The rig of the history whose name is closest to `rig` (the same but
/// for case, spaces and punctuation, or close to it: `frame B` for
/// `Frame B`, `frame-b`), with its entry count: a renamed rig would start
/// a new history silently and its drift would go unchecked.
fn close_rig(entries: &[Entry], rig: &str) -> Option<(String, usize)> {
    let fold = |s: &str| -> String {
        s.chars()
            .filter(|c| c.is_alphanumeric())
            .flat_map(char::to_lowercase)
            .collect()
    };
    let mine = fold(rig);
    let mut counts: std::collections::BTreeMap<&str, usize> = Default::default();
    for e in entries {
        *counts.entry(e.rig.as_str()).or_default() += 1;
    }
    counts
        .into_iter()
        .map(|(name, n)| (strsim::jaro_winkler(&fold(name), &mine), name, n))
        .filter(|(score, _, _)| *score >= 0.9)
        .max_by(|a, b| a.0.total_cmp(&b.0))
        .map(|(_, name, n)| (name.to_string(), n))
}

/// What a campaign's results come from: the servoid version, the manifest
/// and every log, by their hashes.
fn inputs_sha256(results: &Results) -> String {
    let mut text = format!(
        "servoid {}\n{}\n",
        results.servoid_version, results.campaign.manifest_sha256
    );
    if let Some(t) = &results.campaign.run_table {
        text.push_str(&format!("table {}\n", t.sha256));
    }
    for r in &results.runs {
        let log = r.log.as_ref().map_or("-", |l| l.sha256.as_str());
        text.push_str(&format!("{} {log}\n", r.id));
    }
    ingest::sha256_hex(text.as_bytes())
}

/// SHA-256 over the night's log hashes, sorted: the same logs whatever the
/// runs are called or the manifest says. None without logs.
fn logs_sha256(results: &Results) -> Option<String> {
    let mut hashes: Vec<&str> = results
        .runs
        .iter()
        .filter_map(|r| r.log.as_ref().map(|l| l.sha256.as_str()))
        .collect();
    if hashes.is_empty() {
        return None;
    }
    hashes.sort_unstable();
    Some(ingest::sha256_hex(hashes.join("\n").as_bytes()))
}

/// Why a history table's rows do not read as entries.
#[derive(Debug, thiserror::Error)]
pub enum HistoryError {
    #[error("column `{0}` is missing: not a servoid history table")]
    MissingColumn(&'static str),
    #[error("row {row}: `{column}` is {value:?}, not a number")]
    NotANumber {
        row: usize,
        column: &'static str,
        value: String,
    },
    #[error("row {row}: `{column}` is empty")]
    Empty { row: usize, column: &'static str },
}

/// The table's rows as entries (its floats come back bit for bit: Parquet
/// holds them as doubles, the reader prints them shortest round-trip), and
/// its other columns.
pub fn entries(t: &Table) -> Result<(Vec<Entry>, Extra), HistoryError> {
    let others: Vec<usize> = (0..t.columns.len())
        .filter(|&i| {
            let c = t.columns[i].as_str();
            !TABLE_COLUMNS.contains(&c) && !OPTIONAL_TABLE_COLUMNS.contains(&c)
        })
        .collect();
    let extra = Extra {
        names: others.iter().map(|&i| t.columns[i].clone()).collect(),
        rows: t
            .rows
            .iter()
            .map(|r| others.iter().map(|&i| r[i].clone()).collect())
            .collect(),
    };
    Ok((servoid_entries(t)?, extra))
}

fn servoid_entries(t: &Table) -> Result<Vec<Entry>, HistoryError> {
    let col = |name: &'static str| t.column(name).ok_or(HistoryError::MissingColumn(name));
    let idx: Vec<usize> = TABLE_COLUMNS
        .iter()
        .map(|c| col(c))
        .collect::<Result<_, _>>()?;
    let at = |k: usize| TABLE_COLUMNS[k];
    // Written since servoid measured the delay; an older table has none.
    let delay = t.column("delay_s");
    let logs = t.column("logs_sha256");
    t.rows
        .iter()
        .enumerate()
        .map(|(i, row)| {
            let row_no = i + 1;
            let cell = |k: usize| row[idx[k]].clone();
            let text = |k: usize| {
                cell(k).ok_or(HistoryError::Empty {
                    row: row_no,
                    column: at(k),
                })
            };
            let opt = |k: usize| -> Result<Option<f64>, HistoryError> {
                cell(k)
                    .map(|v| {
                        v.parse::<f64>().map_err(|_| HistoryError::NotANumber {
                            row: row_no,
                            column: at(k),
                            value: v.clone(),
                        })
                    })
                    .transpose()
            };
            let num = |k: usize| {
                opt(k)?.ok_or(HistoryError::Empty {
                    row: row_no,
                    column: at(k),
                })
            };
            Ok(Entry {
                rig: text(0)?,
                campaign: text(1)?,
                date: cell(2),
                inputs_sha256: text(3)?,
                results_sha256: text(4)?,
                p_gain: num(5)?,
                beta1: num(6)?,
                beta1_std: opt(7)?,
                a1b0: num(8)?,
                a1b0_std: opt(9)?,
                a2: num(10)?,
                a2_std: opt(11)?,
                a3: num(12)?,
                a3_std: opt(13)?,
                servoid_version: text(14)?,
                delay_s: match delay.and_then(|c| row[c].clone()) {
                    None => None,
                    Some(v) => Some(v.parse::<f64>().map_err(|_| HistoryError::NotANumber {
                        row: row_no,
                        column: "delay_s",
                        value: v.clone(),
                    })?),
                },
                logs_sha256: logs.and_then(|c| row[c].clone()),
            })
        })
        .collect()
}
