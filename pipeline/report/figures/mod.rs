//! The report's figures, drawn from plain data: Bode plots of frequency
//! response functions (the paper's Figs. 8, 11, 13, 15-17), grids of
//! measured-versus-simulated time windows (Figs. 9, 12, 14, 19-22) and
//! generic x-y lines (residuals, sensitivity curves). Each figure renders to
//! whichever of PNG bytes and an SVG string are asked for, one drawing:
//! plotters lays the chart out once into a list of primitives (`canvas`),
//! which `svg` writes and `raster` draws with tiny-skia for the PNG
//! (`encode`).
//!
//! Text uses DejaVu Sans compiled into the binary: the PNG rasterises it and
//! the SVG holds the glyph outlines as paths (no `<text>`), so a figure looks
//! the same on every machine and nothing reads system fonts. Colours are the
//! Okabe-Ito palette; measured data solid, models dashed, references dotted.
//! Output bytes depend only on the input data and size. Pure: the caller
//! writes the files.

mod canvas;
pub mod catalogue;
mod chart;
mod decimate;
mod encode;
mod geometry;
mod raster;
mod svg;
#[cfg(test)]
mod tests;
mod text;

use std::sync::Arc;

use nalgebra::Complex;
use plotters::prelude::IntoDrawingArea;
use rayon::prelude::*;

use canvas::Recorder;
use chart::{Arrangement, Axis, Dash, Metrics, PALETTE, Panel, RawBand, RawCurve, Sheet, Style};

pub use decimate::{decimate_minmax, decimate_minmax_by};

/// A full-width figure: 1200 x 700 px. Shown 90 mm wide, the smallest text
/// (tick labels) is 6 pt to the em.
pub const FULL_WIDTH: (u32, u32) = (1200, 700);

/// Smallest and largest accepted sizes (px).
pub const MIN_SIZE: (u32, u32) = (200, 150);
pub const MAX_SIZE: (u32, u32) = (8192, 8192);

/// Which files a render produces.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Formats {
    /// The full-colour PNG (8-bit RGB).
    pub png: bool,
    /// The SVG document.
    pub svg: bool,
}

/// A figure as PNG bytes and an SVG document, each when asked for.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Rendered {
    pub png: Option<Vec<u8>>,
    pub svg: Option<String>,
}

/// What a series is, which decides its line style.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Trace {
    /// Measured data: solid.
    Measured,
    /// A model or simulation: dashed.
    Model,
    /// A reference (command, published curve): dotted, black unless a
    /// palette slot is given.
    Reference,
}

/// One frequency response function.
#[derive(Clone, Debug)]
pub struct BodeSeries {
    pub label: String,
    pub freq_hz: Vec<f64>,
    /// Complex response at each frequency (same length as `freq_hz`).
    pub h: Vec<Complex<f64>>,
    /// Coherence (0..1) at each frequency, drawn in its own panel.
    pub coherence: Option<Vec<f64>>,
    pub trace: Trace,
    /// Slot in the Okabe-Ito palette (0 blue, 1 vermillion, 2 bluish green,
    /// 3 orange, 4 reddish purple, 5 sky blue, 6 black); `None` takes the
    /// series' position in the figure. Give a run's measured and model
    /// series the same slot to pair them by colour.
    pub palette_index: Option<usize>,
    /// An uncertainty band: +-2 of these standard deviations about the
    /// series, shaded in its colour.
    pub band: Option<BodeBand>,
}

/// Standard deviations of a series' magnitude (dB) and phase (rad), at its
/// frequencies.
#[derive(Clone, Debug, PartialEq)]
pub struct BodeBand {
    pub magnitude_db: Vec<f64>,
    pub phase_rad: Vec<f64>,
}

/// Magnitude (dB), optionally phase (rad) and coherence panels, stacked over
/// a shared frequency axis.
#[derive(Clone, Debug)]
pub struct BodeFigure {
    pub title: String,
    pub series: Vec<BodeSeries>,
    pub freq_range_hz: (f64, f64),
    /// Fixed magnitude limits (dB); `None` fits the data.
    pub mag_range_db: Option<(f64, f64)>,
    pub phase: bool,
    /// Draw a coherence panel (when at least one series has coherence).
    pub coherence: bool,
    pub log_frequency: bool,
    /// Magnitude axis label; empty gives "Magnitude (dB)".
    pub mag_label: String,
}

impl BodeFigure {
    /// 1200 x 700 px, or 1200 x 900 px with a coherence panel below the
    /// phase (three panels need the height to stay readable).
    pub fn recommended_size(&self) -> (u32, u32) {
        let panels = 1 + usize::from(self.phase) + usize::from(self.shows_coherence());
        if panels >= 3 { (1200, 900) } else { FULL_WIDTH }
    }

    fn shows_coherence(&self) -> bool {
        self.coherence && self.series.iter().any(|s| s.coherence.is_some())
    }
}

/// One signal of a time panel. Samples are shared (`Arc`) because the
/// paper's figures show four windows of the same records.
#[derive(Clone, Debug)]
pub struct TimeSeries {
    pub label: String,
    /// One value per entry of the panel's `t_s`.
    pub y: Arc<[f64]>,
    pub trace: Trace,
    pub palette_index: Option<usize>,
}

/// A time window of one or more signals.
#[derive(Clone, Debug)]
pub struct TimePanel {
    /// Caption above the panel, e.g. "(a) 10-20 s".
    pub title: String,
    pub t_s: Arc<[f64]>,
    pub series: Vec<TimeSeries>,
    /// The window shown (s).
    pub t_range_s: (f64, f64),
    /// Axis label with unit, e.g. "Displacement (cm)".
    pub y_label: String,
    /// Fixed y limits; `None` fits the data inside the window.
    pub y_range: Option<(f64, f64)>,
}

/// Time panels in a grid, filled row by row.
#[derive(Clone, Debug)]
pub struct PanelsFigure {
    pub title: String,
    pub panels: Vec<TimePanel>,
    pub columns: usize,
}

impl PanelsFigure {
    /// 1200 px wide; 150 px for title and legend plus 330 px per row of
    /// panels (780 px for the paper's 2 x 2 grids).
    pub fn recommended_size(&self) -> (u32, u32) {
        let rows = self.panels.len().div_ceil(self.columns.max(1)).max(1) as u32;
        (1200, (150 + 330 * rows).min(MAX_SIZE.1))
    }
}

/// One x-y line.
#[derive(Clone, Debug)]
pub struct XySeries {
    pub label: String,
    pub x: Vec<f64>,
    pub y: Vec<f64>,
    pub trace: Trace,
    pub palette_index: Option<usize>,
}

/// Generic lines (residuals, sensitivity curves).
#[derive(Clone, Debug)]
pub struct LinesFigure {
    pub title: String,
    pub x_label: String,
    pub y_label: String,
    pub series: Vec<XySeries>,
    /// Fixed x limits; `None` spans the data.
    pub x_range: Option<(f64, f64)>,
    /// Fixed y limits; `None` fits the data inside the x range.
    pub y_range: Option<(f64, f64)>,
    pub log_x: bool,
    pub log_y: bool,
    /// A thin black line at y = 0 (for residuals).
    pub zero_line: bool,
}

/// Any figure, for rendering a batch.
#[derive(Clone, Debug)]
pub enum Figure {
    Bode(BodeFigure),
    Panels(PanelsFigure),
    Lines(LinesFigure),
}

/// Why a figure could not be drawn. `figure` is the figure's title.
#[derive(Debug, thiserror::Error)]
pub enum FigureError {
    #[error(
        "figure \"{figure}\": nothing to draw (no series has a finite point inside the plotted range)"
    )]
    Empty { figure: String },
    #[error(
        "figure \"{figure}\", series \"{series}\": {what} has {found} values but {against} has {expected}"
    )]
    LengthMismatch {
        figure: String,
        series: String,
        what: &'static str,
        found: usize,
        against: &'static str,
        expected: usize,
    },
    #[error("figure \"{figure}\": {what} = ({lo}, {hi}) is not a usable range: {why}")]
    BadRange {
        figure: String,
        what: String,
        lo: f64,
        hi: f64,
        why: &'static str,
    },
    #[error(
        "figure \"{figure}\": size {width} x {height} px is outside {} x {} to {} x {} px",
        MIN_SIZE.0, MIN_SIZE.1, MAX_SIZE.0, MAX_SIZE.1
    )]
    BadSize {
        figure: String,
        width: u32,
        height: u32,
    },
    #[error("figure \"{figure}\": columns = 0; a grid needs at least one column")]
    NoColumns { figure: String },
    #[error("embedded font: {0}")]
    Font(FontProblem),
    #[error("figure \"{figure}\": drawing failed: {source}")]
    Draw {
        figure: String,
        #[source]
        source: chart::DrawError,
    },
    #[error("figure \"{figure}\": drawing failed: tiny-skia could not allocate the canvas")]
    Canvas { figure: String },
    #[error("figure \"{figure}\": PNG encoding failed: {source}")]
    Png {
        figure: String,
        #[source]
        source: png::EncodingError,
    },
}

/// What is wrong with the font compiled into the binary.
#[derive(Debug, Clone, Copy, PartialEq, Eq, thiserror::Error)]
pub enum FontProblem {
    #[error("the embedded DejaVu Sans does not parse")]
    DoesNotParse,
    #[error("plotters rejected the embedded DejaVu Sans")]
    Rejected,
}

/// Render any figure in the formats asked for. Nothing is rasterised unless
/// the PNG is asked for, and no SVG is written unless it is.
/// Bad input (size, ranges, lengths, nothing to draw) is an error whatever
/// the formats.
pub fn render(fig: &Figure, size: (u32, u32), formats: Formats) -> Result<Rendered, FigureError> {
    match fig {
        Figure::Bode(f) => render_bode(f, size, formats),
        Figure::Panels(f) => render_panels(f, size, formats),
        Figure::Lines(f) => render_lines(f, size, formats),
    }
}

/// Render figures in parallel (rayon), a figure per task so that no thread
/// is left with a block of them; results come back in input order and each
/// figure's bytes do not depend on the number of threads.
pub fn render_many(
    figs: &[(&Figure, (u32, u32))],
    formats: Formats,
) -> Vec<Result<Rendered, FigureError>> {
    figs.par_iter()
        .with_max_len(1)
        .map(|(fig, size)| render(fig, *size, formats))
        .collect()
}

/// Bode figure: magnitude 20 log10 |H| (dB); phase arg H (rad), unwrapped
/// along frequency inside the range; coherence (-). Points outside the
/// frequency range or with a non-finite value are left out (a gap in the
/// line). Series without a finite point in range are left out of the legend.
fn render_bode(
    fig: &BodeFigure,
    size: (u32, u32),
    formats: Formats,
) -> Result<Rendered, FigureError> {
    let name = figure_name(&fig.title);
    let (f0, f1) = check_bode(&name, fig, size)?;
    let m = Metrics::new(size);
    let traces = BodeTraces::new(fig, (f0, f1), &m);
    let stack = bode_stack(fig, &traces, (f0, f1), &m);
    let legend = bode_legend(fig, &traces, (f0, f1));
    if !stack.iter().any(|(p, _)| p.has_data()) {
        return Err(FigureError::Empty { figure: name });
    }
    let sheet = Sheet {
        title: fig.title.clone(),
        legend,
        arrangement: Arrangement::Stack(stack),
    };
    render_sheet(&name, size, sheet, &m, formats)
}

/// Check a Bode figure's size, ranges and series lengths; gives its
/// frequency range (Hz).
fn check_bode(name: &str, fig: &BodeFigure, size: (u32, u32)) -> Result<(f64, f64), FigureError> {
    check_size(name, size)?;
    let range = check_range(name, "freq_range_hz", fig.freq_range_hz, fig.log_frequency)?;
    if let Some(r) = fig.mag_range_db {
        check_range(name, "mag_range_db", r, false)?;
    }
    for s in &fig.series {
        check_len(name, &s.label, "h", s.h.len(), "freq_hz", s.freq_hz.len())?;
        if let Some(c) = &s.coherence {
            check_len(
                name,
                &s.label,
                "coherence",
                c.len(),
                "freq_hz",
                s.freq_hz.len(),
            )?;
        }
    }
    Ok(range)
}

/// Each series' magnitude (dB), unwrapped phase (rad; none without a
/// phase panel) and line style, in the figure's order.
struct BodeTraces {
    mag: Vec<Vec<f64>>,
    phase: Vec<Vec<f64>>,
    styles: Vec<Style>,
}

impl BodeTraces {
    fn new(fig: &BodeFigure, (f0, f1): (f64, f64), m: &Metrics) -> Self {
        let mag = fig
            .series
            .iter()
            .map(|s| s.h.iter().map(|h| 20.0 * h.norm().log10()).collect())
            .collect();
        // Only a phase panel reads the phase.
        let phase = if fig.phase {
            fig.series
                .iter()
                .map(|s| unwrap_phase(&s.freq_hz, &s.h, f0, f1))
                .collect()
        } else {
            Vec::new()
        };
        let styles = fig
            .series
            .iter()
            .enumerate()
            .map(|(i, s)| style_for(s.trace, i, s.palette_index, m))
            .collect();
        BodeTraces { mag, phase, styles }
    }
}

/// The panels from the top, each with its share of the height: magnitude,
/// then phase and coherence when shown. Only the bottom panel labels the
/// frequency axis.
fn bode_stack<'a>(
    fig: &'a BodeFigure,
    traces: &'a BodeTraces,
    (f0, f1): (f64, f64),
    m: &Metrics,
) -> Vec<(Panel<'a>, f64)> {
    let show_phase = fig.phase;
    let show_coh = fig.shows_coherence();
    let n_panels = 1 + usize::from(show_phase) + usize::from(show_coh);
    let x_axis = |k: usize| {
        Axis::new(
            f0,
            f1,
            fig.log_frequency,
            "Frequency (Hz)",
            k + 1 == n_panels,
        )
    };
    let mut stack = vec![(
        magnitude_panel(fig, traces, x_axis(0)),
        if show_coh { 1.0 } else { 1.2 },
    )];
    if show_phase {
        stack.push((phase_panel(fig, traces, x_axis(1)), 1.0));
    }
    if show_coh {
        let p = coherence_panel(fig, &traces.styles, m, x_axis(n_panels - 1));
        stack.push((p, 0.55));
    }
    stack
}

/// The magnitude panel: fixed limits when the figure gives them, else
/// fitted to the data; bands where the series have them.
fn magnitude_panel<'a>(fig: &'a BodeFigure, traces: &'a BodeTraces, x: Axis) -> Panel<'a> {
    let mag_label = if fig.mag_label.is_empty() {
        "Magnitude (dB)"
    } else {
        fig.mag_label.as_str()
    };
    let (m0, m1) = fig.mag_range_db.unwrap_or((0.0, 1.0));
    let mut p = Panel::new(
        None,
        x,
        Axis::new(m0, m1, false, mag_label, true),
        fig.mag_range_db.is_none(),
        raw_curves(&fig.series, &traces.mag, &traces.styles),
    );
    p.bands = bode_bands(fig, &traces.mag, &traces.styles, &|b| &b.magnitude_db);
    p
}

/// The phase panel, its limits fitted to the data; bands where the series
/// have them.
fn phase_panel<'a>(fig: &'a BodeFigure, traces: &'a BodeTraces, x: Axis) -> Panel<'a> {
    let mut p = Panel::new(
        None,
        x,
        Axis::new(0.0, 1.0, false, "Phase (rad)", true),
        true,
        raw_curves(&fig.series, &traces.phase, &traces.styles),
    );
    p.bands = bode_bands(fig, &traces.phase, &traces.styles, &|b| &b.phase_rad);
    p
}

/// The coherence panel, 0 to 1: a thin solid line in each series' colour
/// for the series that have coherence.
fn coherence_panel<'a>(fig: &'a BodeFigure, styles: &[Style], m: &Metrics, x: Axis) -> Panel<'a> {
    let raw: Vec<RawCurve<'_>> = fig
        .series
        .iter()
        .zip(styles)
        .filter_map(|(s, st)| {
            s.coherence.as_ref().map(|c| {
                let style = Style {
                    dash: Dash::Solid,
                    width: m.thin_w,
                    ..*st
                };
                RawCurve::new(&s.freq_hz, c, style)
            })
        })
        .collect();
    Panel::new(
        None,
        x,
        Axis::new(0.0, 1.0, false, "Coherence (-)", true),
        false,
        raw,
    )
}

/// +-2 std about each series that has a band: `values` are the series'
/// (magnitude or phase) and `std_of` picks the matching std from a band.
fn bode_bands<'a>(
    fig: &'a BodeFigure,
    values: &[Vec<f64>],
    styles: &[Style],
    std_of: &dyn Fn(&BodeBand) -> &[f64],
) -> Vec<RawBand<'a>> {
    fig.series
        .iter()
        .zip(values)
        .zip(styles)
        .filter_map(|((s, v), st)| {
            let sd = std_of(s.band.as_ref()?);
            let at = |sign: f64| v.iter().zip(sd).map(|(v, d)| v + sign * 2.0 * d).collect();
            Some(RawBand::new(&s.freq_hz, at(-1.0), at(1.0), st.rgb))
        })
        .collect()
}

/// The legend: the series with a magnitude or phase point inside the
/// frequency range, each (label, style) once.
fn bode_legend(
    fig: &BodeFigure,
    traces: &BodeTraces,
    (f0, f1): (f64, f64),
) -> Vec<(String, Style)> {
    let mut legend = Vec::new();
    for (i, s) in fig.series.iter().enumerate() {
        let in_range = |y: &[f64]| {
            RawCurve::new(&s.freq_hz, y, traces.styles[i]).has_points_in(
                (f0, f1),
                fig.log_frequency,
                false,
            )
        };
        if in_range(&traces.mag[i]) || (fig.phase && in_range(&traces.phase[i])) {
            push_legend(&mut legend, &s.label, traces.styles[i]);
        }
    }
    legend
}

/// Time panels in a grid. Each panel shows its window of the records
/// (min/max-decimated to the plot's pixel columns, so peaks survive);
/// non-finite samples leave gaps. The legend lists each (label, style) once.
fn render_panels(
    fig: &PanelsFigure,
    size: (u32, u32),
    formats: Formats,
) -> Result<Rendered, FigureError> {
    let name = figure_name(&fig.title);
    check_size(&name, size)?;
    if fig.columns == 0 {
        return Err(FigureError::NoColumns { figure: name });
    }
    for (k, p) in fig.panels.iter().enumerate() {
        let what = |w: &str| format!("panels[{k}] (\"{}\").{w}", p.title);
        check_range(&name, &what("t_range_s"), p.t_range_s, false)?;
        if let Some(r) = p.y_range {
            check_range(&name, &what("y_range"), r, false)?;
        }
        for s in &p.series {
            check_len(&name, &s.label, "y", s.y.len(), "t_s", p.t_s.len())?;
        }
    }
    let m = Metrics::new(size);
    let mut legend = Vec::new();
    let mut panels = Vec::with_capacity(fig.panels.len());
    for p in &fig.panels {
        let (t0, t1) = p.t_range_s;
        let mut raw = Vec::new();
        for (i, s) in p.series.iter().enumerate() {
            let style = style_for(s.trace, i, s.palette_index, &m);
            let curve = RawCurve::new(&p.t_s, &s.y, style);
            if curve.has_points_in((t0, t1), false, false) {
                push_legend(&mut legend, &s.label, style);
            }
            raw.push(curve);
        }
        let (y0, y1) = p.y_range.unwrap_or((0.0, 1.0));
        panels.push(Panel::new(
            Some(p.title.clone()),
            Axis::new(t0, t1, false, "Time (s)", true),
            Axis::new(y0, y1, false, &p.y_label, true),
            p.y_range.is_none(),
            raw,
        ));
    }
    if !panels.iter().any(Panel::has_data) {
        return Err(FigureError::Empty { figure: name });
    }
    let sheet = Sheet {
        title: fig.title.clone(),
        legend,
        arrangement: Arrangement::Grid {
            panels,
            columns: fig.columns,
        },
    };
    render_sheet(&name, size, sheet, &m, formats)
}

/// Generic lines. With no `x_range` the axis spans the finite data exactly
/// (positive data on a log axis); long monotone records are min/max
/// decimated like time panels.
fn render_lines(
    fig: &LinesFigure,
    size: (u32, u32),
    formats: Formats,
) -> Result<Rendered, FigureError> {
    let name = figure_name(&fig.title);
    check_size(&name, size)?;
    for s in &fig.series {
        check_len(&name, &s.label, "y", s.y.len(), "x", s.x.len())?;
    }
    if let Some(r) = fig.y_range {
        check_range(&name, "y_range", r, fig.log_y)?;
    }
    let (x0, x1) = match fig.x_range {
        Some(r) => check_range(&name, "x_range", r, fig.log_x)?,
        None => {
            let ok = |v: f64| v.is_finite() && (!fig.log_x || v > 0.0);
            let mut e: Option<(f64, f64)> = None;
            for s in &fig.series {
                for (&x, &y) in s.x.iter().zip(&s.y) {
                    if ok(x) && y.is_finite() && (!fig.log_y || y > 0.0) {
                        e = Some(e.map_or((x, x), |(a, b)| (a.min(x), b.max(x))));
                    }
                }
            }
            match e {
                None => return Err(FigureError::Empty { figure: name }),
                Some((a, b)) if b > a => (a, b),
                Some((a, _)) if fig.log_x => (a / 2.0, a * 2.0),
                Some((a, _)) => {
                    let d = if a != 0.0 { 0.1 * a.abs() } else { 1.0 };
                    (a - d, a + d)
                }
            }
        }
    };
    let m = Metrics::new(size);
    let mut legend = Vec::new();
    let mut raw = Vec::new();
    for (i, s) in fig.series.iter().enumerate() {
        let style = style_for(s.trace, i, s.palette_index, &m);
        let curve = RawCurve::new(&s.x, &s.y, style);
        if curve.has_points_in((x0, x1), fig.log_x, fig.log_y) {
            push_legend(&mut legend, &s.label, style);
        }
        raw.push(curve);
    }
    let (y0, y1) = fig.y_range.unwrap_or((0.0, 1.0));
    let mut panel = Panel::new(
        None,
        Axis::new(x0, x1, fig.log_x, &fig.x_label, true),
        Axis::new(y0, y1, fig.log_y, &fig.y_label, true),
        fig.y_range.is_none(),
        raw,
    );
    panel.zero_line = fig.zero_line;
    if !panel.has_data() {
        return Err(FigureError::Empty { figure: name });
    }
    let sheet = Sheet {
        title: fig.title.clone(),
        legend,
        arrangement: Arrangement::Stack(vec![(panel, 1.0)]),
    };
    render_sheet(&name, size, sheet, &m, formats)
}

/// Phase (rad) inside [f_lo, f_hi], unwrapped in frequency order: each step
/// is taken as the equivalent in [-pi, pi). NaN outside the range or where H
/// is not finite or zero.
fn unwrap_phase(f: &[f64], h: &[Complex<f64>], f_lo: f64, f_hi: f64) -> Vec<f64> {
    use std::f64::consts::{PI, TAU};
    let mut out = vec![f64::NAN; h.len()];
    let mut prev: Option<f64> = None;
    for (i, (fi, hi)) in f.iter().zip(h).enumerate() {
        let usable =
            *fi >= f_lo && *fi <= f_hi && hi.re.is_finite() && hi.im.is_finite() && hi.norm() > 0.0;
        if !usable {
            continue;
        }
        let a = hi.arg();
        let u = match prev {
            None => a,
            Some(p) => {
                let d = a - p;
                p + (d - TAU * ((d + PI) / TAU).floor())
            }
        };
        out[i] = u;
        prev = Some(u);
    }
    out
}

fn raw_curves<'a>(
    series: &'a [BodeSeries],
    ys: &'a [Vec<f64>],
    styles: &[Style],
) -> Vec<RawCurve<'a>> {
    series
        .iter()
        .zip(ys)
        .zip(styles)
        .map(|((s, y), st)| RawCurve::new(&s.freq_hz, y, *st))
        .collect()
}

fn style_for(trace: Trace, index: usize, palette_index: Option<usize>, m: &Metrics) -> Style {
    let rgb = match (palette_index, trace) {
        (Some(k), _) => PALETTE[k % PALETTE.len()],
        (None, Trace::Reference) => PALETTE[6],
        (None, _) => PALETTE[index % PALETTE.len()],
    };
    let (dash, width) = match trace {
        Trace::Measured => (Dash::Solid, m.line_w),
        Trace::Model => (Dash::Dashed, m.line_w),
        Trace::Reference => (Dash::Dotted, m.line_w),
    };
    Style { rgb, dash, width }
}

fn push_legend(legend: &mut Vec<(String, Style)>, label: &str, style: Style) {
    if !label.is_empty() && !legend.iter().any(|(l, s)| l == label && *s == style) {
        legend.push((label.to_string(), style));
    }
}

fn figure_name(title: &str) -> String {
    if title.is_empty() {
        "(untitled)".to_string()
    } else {
        title.to_string()
    }
}

fn check_size(name: &str, size: (u32, u32)) -> Result<(), FigureError> {
    let ok =
        (MIN_SIZE.0..=MAX_SIZE.0).contains(&size.0) && (MIN_SIZE.1..=MAX_SIZE.1).contains(&size.1);
    if ok {
        Ok(())
    } else {
        Err(FigureError::BadSize {
            figure: name.to_string(),
            width: size.0,
            height: size.1,
        })
    }
}

fn check_range(
    name: &str,
    what: &str,
    r: (f64, f64),
    log: bool,
) -> Result<(f64, f64), FigureError> {
    let why = if !(r.0.is_finite() && r.1.is_finite()) {
        Some("limits must be finite")
    } else if r.0 >= r.1 {
        Some("the lower limit must be below the upper")
    } else if log && r.0 <= 0.0 {
        Some("a logarithmic axis needs positive limits")
    } else {
        None
    };
    match why {
        None => Ok(r),
        Some(why) => Err(FigureError::BadRange {
            figure: name.to_string(),
            what: what.to_string(),
            lo: r.0,
            hi: r.1,
            why,
        }),
    }
}

fn check_len(
    name: &str,
    series: &str,
    what: &'static str,
    found: usize,
    against: &'static str,
    expected: usize,
) -> Result<(), FigureError> {
    if found == expected {
        Ok(())
    } else {
        Err(FigureError::LengthMismatch {
            figure: name.to_string(),
            series: series.to_string(),
            what,
            found,
            against,
            expected,
        })
    }
}

/// Draw a sheet once into the recorder, then write the SVG and rasterise the
/// PNG from the same primitives, each only when asked for (in parallel;
/// neither depends on the other).
fn render_sheet(
    name: &str,
    size: (u32, u32),
    mut sheet: Sheet<'_>,
    m: &Metrics,
    formats: Formats,
) -> Result<Rendered, FigureError> {
    text::ensure_registered()?;
    let draw_err = |source| FigureError::Draw {
        figure: name.to_string(),
        source,
    };
    let mut ops = Vec::new();
    {
        let root = Recorder::new(&mut ops, size).into_drawing_area();
        chart::draw_sheet(&root, &mut sheet, m).map_err(draw_err)?;
        root.present().map_err(draw_err)?;
    }
    let png_err = |source| FigureError::Png {
        figure: name.to_string(),
        source,
    };
    let png = || -> Result<Option<Vec<u8>>, FigureError> {
        if !formats.png {
            return Ok(None);
        }
        let rgb = raster::rgb(&ops, size).ok_or_else(|| FigureError::Canvas {
            figure: name.to_string(),
        })?;
        encode::rgb_png(&rgb, size).map(Some).map_err(png_err)
    };
    let svg = || formats.svg.then(|| svg::write(&ops, size, &sheet.title));
    let (png, svg) = rayon::join(png, svg);
    Ok(Rendered { png: png?, svg })
}
