//! The campaign's HTML pages, rendered from results.json and the figures'
//! file names by minijinja templates, never by string concatenation: the
//! campaign's page `report.html` (`report.html` template) summarises every
//! run in one table and shows the campaign's figures; each run's page
//! `runs/<id>.html` (`run.html`) holds its details and figures. Figures are
//! the files beside the pages, so a page stays small and opens offline from
//! disk. A failed run still appears with its error.
//!
//! Rendering is linear in the number of runs: the results become a
//! template value once, and nothing in a template searches the runs. The
//! campaign's page takes each run's row (`RunRow`), not its arrays: as a
//! template value a 3,000-log night's whole results would take 0.15 GB.

use crate::units::format_number;
use std::collections::{BTreeMap, HashMap};

use minijinja::value::Serde;
use minijinja::{Environment, Value};

use crate::results::{ComparisonStatus, Results, RunResult, Status};

const CAMPAIGN_TEMPLATE: &str = include_str!("report.html");
const RUN_TEMPLATE: &str = include_str!("run.html");
const STYLE: &str = include_str!("style.html");
const DESIGN_TEMPLATE: &str = include_str!("design.html");

/// A figure as a page shows it.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct PageFigure {
    pub id: String,
    pub title: String,
    pub caption: String,
    /// The PNG, relative to the output folder.
    pub png_file: Option<String>,
    /// The SVG, relative to the output folder.
    pub svg_file: Option<String>,
}

impl PageFigure {
    pub fn new(id: &str, title: &str, caption: &str) -> Self {
        Self {
            id: id.to_string(),
            title: title.to_string(),
            caption: caption.to_string(),
            png_file: None,
            svg_file: None,
        }
    }
}

/// A serialisable value as a template value.
fn ser<T: serde::Serialize>(v: T) -> Value {
    Value::from(Serde(v))
}

/// `servoid design`'s page (design.html): what to run, what it will
/// determine, each run's command and predicted peaks.
pub fn design_page(
    d: &crate::results::DesignResult,
    figures: &[PageFigure],
    notes: &[crate::warning::Warning],
) -> Result<String, HtmlError> {
    let mut env = Environment::new();
    env.add_filter("num", num);
    env.add_filter("specimen", specimen);
    env.add_template("style.html", STYLE)?;
    env.add_template("design.html", DESIGN_TEMPLATE)?;
    Ok(env.get_template("design.html")?.render(
        minijinja::context! { d => ser(d), figures => ser(figures), notes => ser(notes) },
    )?)
}

/// A run's page, relative to the output folder.
pub fn run_page(id: &str) -> String {
    format!("runs/{id}.html")
}

/// Why a page could not be rendered.
#[derive(Debug, thiserror::Error)]
pub enum HtmlError {
    #[error("report template: {0}")]
    Template(#[from] minijinja::Error),
}

impl HtmlError {
    /// The write that failed, where a page rendered into a file could not
    /// be written (a full disk), rather than rendered.
    pub fn write_failure(&self) -> Option<std::io::Error> {
        let HtmlError::Template(t) = self;
        (t.kind() == minijinja::ErrorKind::WriteFailure).then(|| {
            match std::error::Error::source(t).and_then(|s| s.downcast_ref::<std::io::Error>()) {
                Some(e) => std::io::Error::new(e.kind(), e.to_string()),
                None => std::io::Error::other(t.to_string()),
            }
        })
    }
}

/// The results as the campaign's page reads them: all but each run's
/// arrays.
#[derive(serde::Serialize)]
struct PageResults<'a> {
    schema_version: u32,
    servoid_version: &'a str,
    campaign: &'a crate::results::CampaignSummary,
    rig: &'a Option<crate::results::RigResult>,
    rig_error: &'a Option<String>,
    runs: Vec<RunRow<'a>>,
    ccf: &'a [crate::results::CcfResult],
    csi: &'a [crate::validate::csi::Csi],
    comparisons: &'a [crate::results::Comparison],
    sensitivity: &'a Option<crate::results::SensitivityResult>,
    drift: &'a Option<crate::results::DriftResult>,
    warnings: &'a [crate::warning::Warning],
    manifest: &'a crate::manifest::Manifest,
}

/// A run's row on the campaign's page: its summary, and of its tracking
/// the measured.
#[derive(serde::Serialize)]
struct RunRow<'a> {
    id: &'a str,
    role: crate::manifest::Role,
    description: &'a str,
    p_gain: f64,
    status: Status,
    error: &'a Option<String>,
    warnings: &'a [crate::warning::Warning],
    specimen: &'a crate::model::SpecimenModel,
    natural_frequency_hz: Option<f64>,
    tf: &'a Option<crate::results::TfResult>,
    fit: Option<&'a crate::results::FitSummary>,
    validation: &'a Option<crate::validate::timedomain::ValidationMetrics>,
    tracking: Option<RowTracking>,
    log: &'a Option<crate::results::LogInfo>,
}

#[derive(serde::Serialize)]
struct RowTracking {
    measured: crate::tracking::Tracking,
}

impl<'a> PageResults<'a> {
    fn of(r: &'a Results) -> Self {
        let row = |run: &'a RunResult| RunRow {
            id: &run.id,
            role: run.role,
            description: &run.description,
            p_gain: run.p_gain,
            status: run.status,
            error: &run.error,
            warnings: &run.warnings,
            specimen: &run.specimen,
            natural_frequency_hz: run.natural_frequency_hz,
            tf: &run.tf,
            fit: run.fit.as_deref(),
            validation: &run.validation,
            tracking: run.tracking.as_ref().map(|t| RowTracking {
                measured: t.get().measured.clone(),
            }),
            log: &run.log,
        };
        Self {
            schema_version: r.schema_version,
            servoid_version: &r.servoid_version,
            campaign: &r.campaign,
            rig: &r.rig,
            rig_error: &r.rig_error,
            runs: r.runs.iter().map(row).collect(),
            ccf: &r.ccf,
            csi: &r.csi,
            comparisons: &r.comparisons,
            sensitivity: &r.sensitivity,
            drift: &r.drift,
            warnings: &r.warnings,
            manifest: &r.manifest,
        }
    }
}

/// The pages of one campaign: the templates and the results, made ready once.
pub struct Pages<'a> {
    env: Environment<'static>,
    results: &'a Results,
    /// The results as the campaign's page reads them, a template value
    /// (built once: it is large).
    r: Value,
    /// Each run's canonical form, by run id.
    ccf_of: HashMap<&'a str, usize>,
    figures_note: Option<&'static str>,
    figures_more: Option<&'static str>,
}

impl<'a> Pages<'a> {
    /// `choice` is what the figures were drawn as: a page without figures
    /// says why, and one with the summary's says how to draw the others.
    pub fn new(results: &'a Results, choice: super::FigureFormats) -> Result<Self, HtmlError> {
        let mut env = Environment::new();
        env.add_filter("num", num);
        env.add_filter("pm", pm);
        env.add_filter("pct", pct);
        env.add_filter("ms", ms);
        env.add_filter("specimen", specimen);
        env.add_filter("poles", poles);
        env.add_template("style.html", STYLE)?;
        env.add_template("report.html", CAMPAIGN_TEMPLATE)?;
        env.add_template("run.html", RUN_TEMPLATE)?;
        Ok(Self {
            env,
            results,
            r: ser(PageResults::of(results)),
            ccf_of: (results.ccf.iter().enumerate())
                .map(|(i, c)| (c.run.as_str(), i))
                .collect(),
            figures_note: choice.note(),
            figures_more: choice.more(),
        })
    }

    /// The campaign's page, with the campaign's own figures, rendered into
    /// `out` as it goes: a night of 3,000 runs is 8.5 MB of page, which
    /// would otherwise be held, and grown by doubling, as one string.
    pub fn campaign(
        &self,
        figures: &[PageFigure],
        out: impl std::io::Write,
    ) -> Result<(), HtmlError> {
        let results = self.results;
        let failed = results
            .runs
            .iter()
            .filter(|r| r.status == Status::Failed)
            .count();
        let flagged = results.comparisons.iter().filter(|c| c.flag).count();
        let not_computed = results
            .comparisons
            .iter()
            .filter(|c| c.status == ComparisonStatus::NotComputed)
            .count();
        let manifest_json =
            serde_json::to_string_pretty(&results.manifest).unwrap_or_else(|e| e.to_string());
        // Table 3 heads each run's column with its a1b0; looked up here once.
        let a1b0: BTreeMap<&str, Option<f64>> = results
            .runs
            .iter()
            .map(|r| (r.id.as_str(), r.a1b0))
            .collect();
        // A publication's figures by number apart from the campaign's own,
        // in the manifest's order, with those it cannot draw.
        let numbered = &results.manifest.numbered_figures;
        let stems: Vec<String> = numbered.iter().map(|n| n.stem()).collect();
        let (by_number, own): (Vec<&PageFigure>, Vec<&PageFigure>) =
            figures.iter().partition(|f| stems.contains(&f.id));
        let not_drawn: Vec<&crate::manifest::NumberedFigure> =
            numbered.iter().filter(|n| n.not_drawn.is_some()).collect();
        let ctx = minijinja::context! {
            r => self.r.clone(),
            numbered_figures => ser(by_number),
            not_drawn => ser(not_drawn),
            run_warnings => ser(shared_warnings(
                results.runs.iter().map(|r| (r.id.as_str(), r.warnings.as_slice()))
            )),
            figures => ser(own),
            notice => results.manifest.campaign.synthetic.as_deref(),
            figures_note => self.figures_note,
            figures_more => self.figures_more,
            failed => failed,
            flagged => flagged,
            not_computed => not_computed,
            a1b0_of => ser(&a1b0),
            manifest_json => manifest_json,
        };
        self.env
            .get_template("report.html")?
            .render_captured_to(ctx, out)?;
        Ok(())
    }

    /// A run's page, with its figures.
    pub fn run(&self, run: &RunResult, figures: &[PageFigure]) -> Result<String, HtmlError> {
        let ccf = self
            .ccf_of
            .get(run.id.as_str())
            .map(|&i| &self.results.ccf[i]);
        let ctx = minijinja::context! {
            campaign => ser(&self.results.campaign),
            servoid_version => self.results.servoid_version.as_str(),
            notice => self.results.manifest.campaign.synthetic.as_deref(),
            run => ser(run),
            ccf => ser(ccf),
            figures => ser(figures),
            figures_note => self.figures_note,
            figures_more => self.figures_more,
        };
        Ok(self.env.get_template("run.html")?.render(ctx)?)
    }
}

/// The runs' warnings by headline, each once with the runs that give it
/// (in manifest order), in the order they first appear: a night whose
/// runs share a warning reads it once. Headlines that differ only in
/// their numbers are one warning, each number given as the range the runs
/// span ("in 8.1–9.4 % of its samples").
#[derive(Debug, serde::Serialize)]
struct SharedWarning<'a> {
    headline: String,
    runs: Vec<&'a str>,
}

/// A headline cut at its numbers: the text around them, and each number
/// as written with its value. A digit inside a word (x1/u, H2) is text.
fn split_numbers(h: &str) -> (Vec<&str>, Vec<(&str, f64)>) {
    let b = h.as_bytes();
    let digit = |i: usize| b.get(i).is_some_and(u8::is_ascii_digit);
    let (mut text, mut numbers) = (Vec::new(), Vec::new());
    let (mut start, mut i) = (0, 0);
    while i < b.len() {
        let sign = matches!(b[i], b'-' | b'+') && digit(i + 1);
        let in_word =
            i > 0 && (b[i - 1].is_ascii_alphanumeric() || matches!(b[i - 1], b'_' | b'.'));
        if !(digit(i) || sign) || in_word {
            i += 1;
            continue;
        }
        let mut j = i + usize::from(sign);
        while digit(j) || (b.get(j) == Some(&b'.') && digit(j + 1)) {
            j += 1;
        }
        if b.get(j) == Some(&b'e') {
            let k = j + 1 + usize::from(matches!(b.get(j + 1), Some(b'-' | b'+')));
            if digit(k) {
                j = k;
                while digit(j) {
                    j += 1;
                }
            }
        }
        if let Ok(v) = h[i..j].parse::<f64>() {
            text.push(&h[start..i]);
            numbers.push((&h[i..j], v));
            start = j;
        }
        i = j;
    }
    text.push(&h[start..]);
    (text, numbers)
}

/// A shared warning's text and, number by number, what its runs give
/// there, and the runs.
type Group<'a> = (Vec<&'a str>, Vec<Vec<(&'a str, f64)>>, Vec<&'a str>);

fn shared_warnings<'a>(
    runs: impl IntoIterator<Item = (&'a str, &'a [crate::warning::Warning])>,
) -> Vec<SharedWarning<'a>> {
    let mut groups: Vec<Group<'a>> = Vec::new();
    for (id, warnings) in runs {
        for w in warnings {
            let (text, numbers) = split_numbers(&w.headline);
            match groups.iter_mut().find(|g| g.0 == text) {
                Some((_, slots, ids)) => {
                    if ids.last() != Some(&id) {
                        ids.push(id);
                    }
                    for (slot, n) in slots.iter_mut().zip(numbers) {
                        slot.push(n);
                    }
                }
                None => {
                    let slots = numbers.into_iter().map(|n| vec![n]).collect();
                    groups.push((text, slots, vec![id]));
                }
            }
        }
    }
    groups
        .into_iter()
        .map(|(text, slots, runs)| SharedWarning {
            headline: with_ranges(&text, &slots),
            runs,
        })
        .collect()
}

/// A group's headline: its text with each number, or the range its runs
/// span there (the lowest and the highest as written).
fn with_ranges(text: &[&str], slots: &[Vec<(&str, f64)>]) -> String {
    let mut headline = String::from(text[0]);
    for (slot, after) in slots.iter().zip(&text[1..]) {
        if slot.iter().all(|n| n.0 == slot[0].0) {
            headline.push_str(slot[0].0);
        } else {
            let low = slot.iter().min_by(|a, b| a.1.total_cmp(&b.1));
            let high = slot.iter().max_by(|a, b| a.1.total_cmp(&b.1));
            if let (Some(low), Some(high)) = (low, high) {
                headline.push_str(&format!("{}\u{2013}{}", low.0, high.0));
            }
        }
        headline.push_str(after);
    }
    headline
}

fn as_f64(v: &Value) -> Option<f64> {
    if v.is_undefined() || v.is_none() {
        return None;
    }
    f64::try_from(v.clone()).ok().filter(|x| x.is_finite())
}

fn num(v: Value, sig: Option<usize>) -> String {
    as_f64(&v).map_or_else(|| "\u{2013}".into(), |x| format_number(x, sig.unwrap_or(4)))
}

/// Seconds as milliseconds, to `sig` significant digits (4).
fn ms(v: Value, sig: Option<usize>) -> String {
    as_f64(&v).map_or_else(
        || "\u{2013}".into(),
        |x| format_number(x * 1e3, sig.unwrap_or(4)),
    )
}

fn pm(v: Value) -> String {
    let value = v.get_attr("value").ok().and_then(|x| as_f64(&x));
    let std = v.get_attr("std").ok().and_then(|x| as_f64(&x));
    match (value, std) {
        (Some(x), Some(s)) => format!("{} \u{b1} {}", format_number(x, 4), format_number(s, 2)),
        (Some(x), None) => format_number(x, 4),
        _ => "\u{2013}".into(),
    }
}

fn pct(v: Value) -> String {
    as_f64(&v).map_or_else(|| "\u{2013}".into(), |x| format!("{:+.2} %", 100.0 * x))
}

fn specimen(v: Value) -> String {
    let kind = v
        .get_attr("kind")
        .ok()
        .and_then(|k| k.as_str().map(str::to_string))
        .unwrap_or_default();
    let get = |k: &str| v.get_attr(k).ok().and_then(|x| as_f64(&x));
    match kind.as_str() {
        "spring" => format!(
            "spring, k = {} N/m",
            get("stiffness_n_per_m").map_or("?".into(), |x| format_number(x, 6))
        ),
        "none" => "none".into(),
        other => {
            let f = |k: &str, sig: usize| get(k).map_or("?".into(), |x| format_number(x, sig));
            let mck = format!(
                "m = {} kg, c = {} N s/m, k = {} N/m",
                f("mass_kg", 4),
                f("damping_ns_per_m", 4),
                f("stiffness_n_per_m", 6)
            );
            match other {
                "linear_sdof" => mck,
                "duffing" => format!(
                    "Duffing: {mck}, k3 = {} N/m\u{b3}",
                    f("cubic_stiffness_n_per_m3", 4)
                ),
                "friction" => format!(
                    "friction: {mck}, f_c = {} N, v_s = {} m/s",
                    f("coulomb_force_n", 4),
                    f("smoothing_velocity_m_per_s", 3)
                ),
                "bouc_wen" => format!(
                    "Bouc-Wen: {mck}, \u{3b1} = {}, A = {}, \u{3b2} = {}, \u{3b3} = {}, n = {}",
                    f("alpha", 3),
                    f("a", 3),
                    f("beta_per_m_pow_n", 3),
                    f("gamma_per_m_pow_n", 3),
                    f("n", 3)
                ),
                _ => other.to_string(),
            }
        }
    }
}

fn poles(v: Value) -> String {
    let Ok(iter) = v.try_iter() else {
        return String::new();
    };
    let mut out = Vec::new();
    for p in iter {
        let re = p
            .get_attr("re")
            .ok()
            .and_then(|x| as_f64(&x))
            .unwrap_or(f64::NAN);
        let im = p
            .get_attr("im")
            .ok()
            .and_then(|x| as_f64(&x))
            .unwrap_or(0.0);
        // Conjugate pairs are printed once.
        if im < 0.0 {
            continue;
        }
        if im == 0.0 {
            out.push(format_number(re, 5));
        } else {
            out.push(format!(
                "{} \u{b1} {}j",
                format_number(re, 5),
                format_number(im, 5)
            ));
        }
    }
    out.join(", ")
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The campaign's page from each run's row is the page from the whole
    /// results, on a small simulated campaign with a spring and a
    /// validation run (its tracking, compensator and windows).
    #[test]
    fn the_campaign_page_from_the_rows_is_the_page_from_the_whole_results() {
        let dir = tempfile::tempdir().unwrap();
        let text = include_str!("../../tests/fixtures/small-simulation.toml");
        let results = crate::run::analyse(&crate::run::simulate::simulated(text, dir.path()));
        let v = results.runs.iter().find(|r| r.id == "v1").unwrap();
        assert!(
            v.tracking
                .as_ref()
                .is_some_and(|t| t.get().compensator.is_some())
        );
        let mut pages = Pages::new(&results, super::super::FigureFormats::Summary).unwrap();
        let page = |pages: &Pages| {
            let mut out = Vec::new();
            pages.campaign(&[], &mut out).unwrap();
            out
        };
        let rows = page(&pages);
        pages.r = ser(&results);
        assert_eq!(rows, page(&pages));
    }

    #[test]
    fn numbers_are_readable() {
        assert_eq!(format_number(129_400.0, 4), "129400");
        assert_eq!(format_number(3.8, 4), "3.8");
        assert_eq!(format_number(2.413_778e9, 4), "2.414e9");
        assert_eq!(format_number(-283.122_204, 6), "-283.122");
        assert_eq!(format_number(1.6e-5, 3), "1.60e-5");
        assert_eq!(format_number(0.0, 3), "0");
        assert_eq!(num(Value::from(()), None), "\u{2013}");
        assert_eq!(pct(Value::from(0.000_74)), "+0.07 %");
    }

    /// Each shared warning's headline and runs.
    fn headlines_and_runs<'a>(shared: &'a [SharedWarning<'a>]) -> Vec<(&'a str, Vec<&'a str>)> {
        shared
            .iter()
            .map(|s| (s.headline.as_str(), s.runs.clone()))
            .collect()
    }

    /// Three runs, two of which share a headline (one of them twice): the
    /// shared one is listed once with both runs, the other alone.
    #[test]
    fn a_warning_runs_share_is_listed_once_with_their_ids() {
        use crate::warning::Warning;
        let limit = Warning::new("the command is limited", "a.csv: ...");
        let misfit = Warning::new("the run's own fit: misfit", "...");
        let a = [limit.clone(), limit.clone()];
        let b: [Warning; 0] = [];
        let c = [
            misfit.clone(),
            Warning::new("the command is limited", "c.csv: ..."),
        ];
        let shared = shared_warnings([("a", &a[..]), ("b", &b[..]), ("c", &c[..])]);
        let got = headlines_and_runs(&shared);
        assert_eq!(
            got,
            [
                ("the command is limited", vec!["a", "c"]),
                ("the run's own fit: misfit", vec!["c"]),
            ]
        );
    }

    /// Headlines that differ in their numbers alone are one, each number
    /// the range the runs give; a digit in a word (x1/u) is text, and a
    /// headline whose words differ is another warning.
    #[test]
    fn headlines_that_differ_in_their_numbers_are_one_with_their_ranges() {
        use crate::warning::Warning;
        let at = |pct: &str| {
            [Warning::new(
                format!("the command holds its maximum 3 mm in {pct} % of its samples"),
                "...",
            )]
        };
        let (a, b, c) = (at("8.1"), at("9.4"), at("10.2"));
        let fit = |z: &str| {
            [Warning::new(
                format!("x1/u misses: chi-square 1.25, {z} std above noise"),
                "...",
            )]
        };
        let (d, e) = (fit("11"), fit("-2.5e1"));
        let other = [Warning::new(
            "the command holds its minimum 3 mm in 9.4 % of its samples",
            "...",
        )];
        let shared = shared_warnings([
            ("a", &a[..]),
            ("b", &b[..]),
            ("c", &c[..]),
            ("d", &d[..]),
            ("e", &e[..]),
            ("f", &other[..]),
        ]);
        let got = headlines_and_runs(&shared);
        assert_eq!(
            got,
            [
                (
                    "the command holds its maximum 3 mm in 8.1\u{2013}10.2 % of its samples",
                    vec!["a", "b", "c"]
                ),
                (
                    "x1/u misses: chi-square 1.25, -2.5e1\u{2013}11 std above noise",
                    vec!["d", "e"]
                ),
                (
                    "the command holds its minimum 3 mm in 9.4 % of its samples",
                    vec!["f"]
                ),
            ]
        );
    }
}
