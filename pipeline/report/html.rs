//! The campaign's HTML report: one page rendered from results.json and the
//! figures by a minijinja template (`report.html`), never by string
//! concatenation. It opens offline from disk: each figure is inlined as a
//! compact PNG preview (a data URI), with links to the full PNG and the SVG
//! beside the page; with SVG files alone the page shows those. A failed run
//! still appears with its error.

use base64::Engine;
use minijinja::value::Serde;
use minijinja::{Environment, Value};

use crate::results::{Results, Status};

const TEMPLATE: &str = include_str!("report.html");

/// A figure as the page shows it.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct PageFigure {
    pub id: String,
    pub title: String,
    pub caption: String,
    /// The compact preview inlined in the page, `data:image/png;base64,...`
    /// (only characters that need no HTML escaping).
    pub preview_data_uri: Option<String>,
    /// The full PNG beside the page, relative to it.
    pub png_file: Option<String>,
    /// The SVG beside the page, relative to it.
    pub svg_file: Option<String>,
}

impl PageFigure {
    pub fn new(id: &str, title: &str, caption: &str) -> Self {
        Self {
            id: id.to_string(),
            title: title.to_string(),
            caption: caption.to_string(),
            preview_data_uri: None,
            png_file: None,
            svg_file: None,
        }
    }

    /// Inline `png` as the page's preview of the figure.
    pub fn with_preview(mut self, png: &[u8]) -> Self {
        self.preview_data_uri = Some(format!(
            "data:image/png;base64,{}",
            base64::engine::general_purpose::STANDARD.encode(png)
        ));
        self
    }
}

/// Why the page could not be rendered.
#[derive(Debug, thiserror::Error)]
pub enum HtmlError {
    #[error("report template: {0}")]
    Template(#[from] minijinja::Error),
}

/// Render the page. `notice` is shown in a banner (e.g. that the logs are
/// synthetic); `figures_note` says why there are no figures when there are
/// none.
pub fn render(
    results: &Results,
    figures: &[PageFigure],
    notice: Option<&str>,
    figures_note: &str,
) -> Result<String, HtmlError> {
    let mut env = Environment::new();
    env.add_filter("num", num);
    env.add_filter("pm", pm);
    env.add_filter("pct", pct);
    env.add_filter("specimen", specimen);
    env.add_filter("poles", poles);
    env.add_template("report.html", TEMPLATE)?;
    let failed = results
        .runs
        .iter()
        .filter(|r| r.status == Status::Failed)
        .count();
    let flagged = results.comparisons.iter().filter(|c| c.flag).count();
    let manifest_json =
        serde_json::to_string_pretty(&results.manifest).unwrap_or_else(|e| e.to_string());
    let ctx = minijinja::context! {
        r => Value::from(Serde(results)),
        figures => Value::from(Serde(figures)),
        notice => notice,
        figures_note => figures_note,
        failed => failed,
        flagged => flagged,
        manifest_json => manifest_json,
    };
    Ok(env.get_template("report.html")?.render(ctx)?)
}

fn as_f64(v: &Value) -> Option<f64> {
    if v.is_undefined() || v.is_none() {
        return None;
    }
    f64::try_from(v.clone()).ok().filter(|x| x.is_finite())
}

/// A number with `sig` significant digits: plain between 1e-3 and 1e6,
/// scientific outside; a dash for none.
pub fn format_number(x: f64, sig: usize) -> String {
    let sig = sig.max(1);
    if x == 0.0 {
        return "0".into();
    }
    let e = x.abs().log10().floor() as i32;
    if (-3..6).contains(&e) {
        let decimals = (sig as i32 - 1 - e).max(0) as usize;
        let s = format!("{x:.decimals$}");
        if s.contains('.') {
            s.trim_end_matches('0').trim_end_matches('.').to_string()
        } else {
            s
        }
    } else {
        format!("{:.*e}", sig - 1, x)
    }
}

fn num(v: Value, sig: Option<usize>) -> String {
    as_f64(&v).map_or_else(|| "\u{2013}".into(), |x| format_number(x, sig.unwrap_or(4)))
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
}
