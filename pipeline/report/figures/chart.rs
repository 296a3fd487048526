//! Chart layout shared by every figure: a sheet is a title, a legend band and
//! panels (stacked with a shared x axis, or a grid); each panel is a boxed
//! plotters chart with grid lines, ticks chosen here, axis labels and curves
//! already clipped to the panel and decimated to the pixel width.

use std::convert::Infallible;

use plotters::coord::Shift;
use plotters::coord::ranged1d::{DefaultFormatting, KeyPointHint};
use plotters::coord::types::RangedCoordf64;
use plotters::element::DashedPathElement;
use plotters::prelude::*;
use plotters::style::text_anchor::{HPos, Pos, VPos};

use super::canvas::Recorder;
use super::decimate::decimate_minmax;
use super::text;

pub(crate) type Area<'a> = DrawingArea<Recorder<'a>, Shift>;
pub(crate) type DrawError = DrawingAreaErrorKind<Infallible>;

/// Okabe & Ito (2008) colour-blind-safe palette, in the order series take
/// it; yellow is left out (too faint on white).
pub(crate) const PALETTE: [(u8, u8, u8); 7] = [
    (0, 114, 178),   // blue
    (213, 94, 0),    // vermillion
    (0, 158, 115),   // bluish green
    (230, 159, 0),   // orange
    (204, 121, 167), // reddish purple
    (86, 180, 233),  // sky blue
    (0, 0, 0),       // black
];

const GRID: RGBColor = RGBColor(217, 217, 217);

/// Sizes in pixels, proportional to the figure width so that text keeps its
/// printed size when a figure is shown at a fixed width. A text size here is
/// ab_glyph's pixel scale, ascender to descender, 1.164 em for DejaVu Sans.
/// Shown 90 mm wide, a 1200 px figure has 0.075 mm per pixel: 33 px tick
/// labels are 28.4 px = 2.13 mm = 6.0 pt to the em, axis labels 6.4 pt, the
/// title 6.9 pt. Lines of 3 px are 0.23 mm.
#[derive(Clone, Copy, Debug)]
pub(crate) struct Metrics {
    pub title_px: f64,
    pub caption_px: f64,
    pub desc_px: f64,
    pub tick_px: f64,
    pub legend_px: f64,
    pub line_w: u32,
    pub thin_w: u32,
    pub axis_w: u32,
    pub tick_len: i32,
    pub pad: i32,
}

impl Metrics {
    pub(crate) fn new(size: (u32, u32)) -> Self {
        let s = f64::from(size.0) / 1200.0;
        let px = |v: f64| (v * s).round().max(1.0);
        Metrics {
            title_px: px(38.0),
            caption_px: px(35.0),
            desc_px: px(35.0),
            tick_px: px(33.0),
            legend_px: px(33.0),
            line_w: px(3.0) as u32,
            thin_w: px(2.0) as u32,
            axis_w: px(2.0) as u32,
            tick_len: px(8.0) as i32,
            pad: px(12.0) as i32,
        }
    }

    fn font(&self, size_px: f64) -> TextStyle<'static> {
        (text::FAMILY, size_px).into_font().color(&BLACK)
    }

    /// Room below a plot for tick labels and the axis label; the glyphs of
    /// the tick labels reach a little below their layout box.
    fn x_area(&self) -> i32 {
        2 * self.tick_len
            + text::line_height(self.tick_px)
            + (0.5 * self.tick_px) as i32
            + text::line_height(self.desc_px)
            + self.pad / 2
    }
}

/// How a curve is stroked.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum Dash {
    Solid,
    Dashed,
    Dotted,
}

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) struct Style {
    pub rgb: (u8, u8, u8),
    pub dash: Dash,
    pub width: u32,
}

impl Style {
    fn shape(&self) -> ShapeStyle {
        RGBColor(self.rgb.0, self.rgb.1, self.rgb.2).stroke_width(self.width)
    }

    /// Dash and gap lengths in pixels; round caps eat `width` of each gap.
    fn dash_gap(&self) -> (i32, i32) {
        let w = self.width as i32;
        match self.dash {
            Dash::Solid => (0, 0),
            Dash::Dashed => (5 * w, 4 * w),
            Dash::Dotted => (1, 3 * w),
        }
    }
}

/// One axis of a panel.
#[derive(Clone, Debug)]
pub(crate) struct Axis {
    pub lo: f64,
    pub hi: f64,
    pub log: bool,
    pub desc: String,
    /// Whether tick labels and the axis label are drawn (false for the upper
    /// panels of a stack that share the bottom panel's x axis).
    pub labelled: bool,
    pub ticks: Vec<f64>,
}

impl Axis {
    pub(crate) fn new(lo: f64, hi: f64, log: bool, desc: &str, labelled: bool) -> Self {
        Axis {
            lo,
            hi,
            log,
            desc: desc.to_string(),
            labelled,
            ticks: Vec::new(),
        }
    }
}

/// A curve ready to draw: finite runs inside the panel.
#[derive(Clone, Debug)]
struct Curve {
    pub runs: Vec<Vec<(f64, f64)>>,
    pub style: Style,
}

/// A curve before its panel's ranges are known: raw data and a style.
#[derive(Clone, Debug)]
pub(crate) struct RawCurve<'a> {
    x: &'a [f64],
    y: &'a [f64],
    style: Style,
    /// x is non-decreasing (checked once; enables binary search).
    sorted: bool,
}

impl<'a> RawCurve<'a> {
    /// Uses the common length of `x` and `y`.
    pub(crate) fn new(x: &'a [f64], y: &'a [f64], style: Style) -> Self {
        let n = x.len().min(y.len());
        let (x, y) = (&x[..n], &y[..n]);
        let sorted = x.windows(2).all(|w| w[0] <= w[1]);
        RawCurve {
            x,
            y,
            style,
            sorted,
        }
    }

    /// Whether some finite point lies inside the x range (positive values
    /// on log axes).
    pub(crate) fn has_points_in(&self, x_range: (f64, f64), x_log: bool, y_log: bool) -> bool {
        y_extent(self, x_range, x_log, y_log).is_some()
    }
}

/// A shaded band between two curves over x (an uncertainty band), drawn
/// under the panel's curves in a light tint of `rgb`.
#[derive(Clone, Debug)]
pub(crate) struct RawBand<'a> {
    x: &'a [f64],
    lo: Vec<f64>,
    hi: Vec<f64>,
    rgb: (u8, u8, u8),
}

impl<'a> RawBand<'a> {
    pub(crate) fn new(x: &'a [f64], lo: Vec<f64>, hi: Vec<f64>, rgb: (u8, u8, u8)) -> Self {
        RawBand { x, lo, hi, rgb }
    }
}

/// A band's opacity: the curves stay legible through it.
const BAND_ALPHA: f64 = 0.25;
/// At most this many points along a band's edges (it is smooth: a model's
/// uncertainty), so that its SVG path stays small.
const BAND_POINTS: usize = 400;

/// The band's outline in data coordinates, inside the x range and clamped
/// to the y range: its upper edge forward, its lower edge back.
fn band_outline(b: &RawBand<'_>, (x0, x1, y0, y1): (f64, f64, f64, f64)) -> Vec<(f64, f64)> {
    let keep: Vec<usize> = (0..b.x.len().min(b.lo.len()).min(b.hi.len()))
        .filter(|&i| (x0..=x1).contains(&b.x[i]) && b.lo[i].is_finite() && b.hi[i].is_finite())
        .collect();
    let stride = keep.len().div_ceil(BAND_POINTS).max(1);
    let mut picked: Vec<usize> = keep.iter().copied().step_by(stride).collect();
    if let (Some(&last), Some(&end)) = (keep.last(), picked.last())
        && last != end
    {
        picked.push(last);
    }
    let clamp = |v: f64| v.clamp(y0, y1);
    let upper = picked.iter().map(|&i| (b.x[i], clamp(b.hi[i])));
    let lower = picked.iter().rev().map(|&i| (b.x[i], clamp(b.lo[i])));
    upper.chain(lower).collect()
}

/// One chart of a sheet. The y range is fixed, or (`y_auto`) chosen from
/// the data inside the x range once the plot height is known; the curves are
/// clipped and decimated once the plot width is known.
#[derive(Clone, Debug)]
pub(crate) struct Panel<'a> {
    pub title: Option<String>,
    pub x: Axis,
    pub y: Axis,
    pub y_auto: bool,
    pub raw: Vec<RawCurve<'a>>,
    /// Shaded bands, under the curves; they do not widen an automatic y
    /// range.
    pub bands: Vec<RawBand<'a>>,
    pub zero_line: bool,
    curves: Vec<Curve>,
}

impl<'a> Panel<'a> {
    pub(crate) fn new(
        title: Option<String>,
        x: Axis,
        y: Axis,
        y_auto: bool,
        raw: Vec<RawCurve<'a>>,
    ) -> Self {
        Panel {
            title,
            x,
            y,
            y_auto,
            raw,
            bands: Vec::new(),
            zero_line: false,
            curves: Vec::new(),
        }
    }

    /// Whether any curve has a finite point inside the x range.
    pub(crate) fn has_data(&self) -> bool {
        self.extent().is_some()
    }

    fn extent(&self) -> Option<(f64, f64)> {
        self.raw
            .iter()
            .filter_map(|r| y_extent(r, (self.x.lo, self.x.hi), self.x.log, self.y.log))
            .reduce(|a, b| (a.0.min(b.0), a.1.max(b.1)))
    }

    /// Fix the y range and ticks for a plot `plot_h` tall.
    fn settle_y(&mut self, m: &Metrics, plot_h: i32) {
        let budget = y_tick_budget(m, plot_h);
        if self.y_auto {
            let (lo, hi, step) = nice_range_step(self.extent(), self.y.log, budget);
            self.y.lo = lo;
            self.y.hi = hi;
            if !self.y.log {
                self.y.ticks = linear_ticks(lo, hi, step);
                return;
            }
        }
        self.y.ticks = ticks_for(&self.y, budget);
    }

    /// Fix the x ticks and prepare the curves for a plot `plot_w` wide.
    fn settle_x(&mut self, m: &Metrics, plot_w: i32) {
        choose_x_ticks(m, &mut self.x, plot_w);
        let columns = plot_w.max(1) as usize;
        self.curves = self
            .raw
            .iter()
            .map(|r| Curve {
                runs: prepare(r, &self.x, &self.y, columns),
                style: r.style,
            })
            .collect();
    }
}

pub(crate) enum Arrangement<'a> {
    /// Panels one above the other sharing the x axis; plot heights in
    /// proportion to the weights.
    Stack(Vec<(Panel<'a>, f64)>),
    Grid {
        panels: Vec<Panel<'a>>,
        columns: usize,
    },
}

pub(crate) struct Sheet<'a> {
    pub title: String,
    pub legend: Vec<(String, Style)>,
    pub arrangement: Arrangement<'a>,
}

// ---------------------------------------------------------------- ranges

/// A 1-2-5 step giving at most `max_ticks` ticks over `span` (steps of 2.5
/// would cost every label a decimal).
pub(crate) fn nice_step(span: f64, max_ticks: usize) -> f64 {
    let max_ticks = max_ticks.max(2);
    let span = if span.is_finite() && span > 0.0 {
        span
    } else {
        1.0
    };
    let raw = span / (max_ticks - 1) as f64;
    let mag = 10f64.powf(raw.log10().floor());
    for m in [1.0, 2.0, 5.0, 10.0] {
        let step = m * mag;
        if ((span / step).floor() as usize) < max_ticks {
            return step;
        }
    }
    10.0 * mag
}

/// Ticks k * step inside [lo, hi] (a hair of slack for rounding).
pub(crate) fn linear_ticks(lo: f64, hi: f64, step: f64) -> Vec<f64> {
    let eps = step * 1e-9;
    let k0 = ((lo - eps) / step).ceil() as i64;
    let k1 = ((hi + eps) / step).floor() as i64;
    (k0..=k1)
        .map(|k| {
            let v = k as f64 * step;
            if v.abs() < eps { 0.0 } else { v }
        })
        .collect()
}

/// Decades inside [lo, hi]; with fewer than three, also 2x and 5x; with too
/// many, every m-th decade.
pub(crate) fn log_ticks(lo: f64, hi: f64, max_ticks: usize) -> Vec<f64> {
    let (a, b) = (lo.log10(), hi.log10());
    let (k0, k1) = ((a - 1e-9).ceil() as i32, (b + 1e-9).floor() as i32);
    let decades = (k1 - k0 + 1).max(0) as usize;
    let inside = |v: f64| v >= lo * (1.0 - 1e-9) && v <= hi * (1.0 + 1e-9);
    if decades >= 3 {
        let every = decades.div_ceil(max_ticks.max(2)).max(1) as i32;
        return (k0..=k1)
            .filter(|k| (k - k0) % every == 0)
            .map(|k| 10f64.powi(k))
            .collect();
    }
    let mut v = Vec::new();
    for k in (a.floor() as i32)..=(b.ceil() as i32) {
        for m in [1.0, 2.0, 5.0] {
            let t = m * 10f64.powi(k);
            if inside(t) {
                v.push(t);
            }
        }
    }
    v
}

/// Axis limits around data [min, max]: padded, snapped to the tick step,
/// never degenerate. `None` (no data) gives 0..1 (1..10 on a log axis).
/// Also returns the linear tick step snapped to (NaN on a log axis), so
/// that the ticks use the same step as the limits.
pub(crate) fn nice_range_step(
    extent: Option<(f64, f64)>,
    log: bool,
    max_ticks: usize,
) -> (f64, f64, f64) {
    if log {
        let Some((min, max)) = extent else {
            return (1.0, 10.0, f64::NAN);
        };
        let lo = 10f64.powf(min.log10().floor());
        let mut hi = 10f64.powf(max.log10().ceil());
        if hi <= lo {
            hi = lo * 10.0;
        }
        return (lo, hi, f64::NAN);
    }
    let Some((min, max)) = extent else {
        return (0.0, 1.0, nice_step(1.0, max_ticks));
    };
    let (min, max) = if max - min > 1e-12 * max.abs().max(min.abs()) {
        (min, max)
    } else {
        // Constant data: a band around the value.
        let d = if min.abs() > 0.0 {
            0.1 * min.abs()
        } else {
            1.0
        };
        (min - d, max + d)
    };
    // A hair of padding so a maximum exactly on a tick does not touch the box
    // (more would push the limits out a whole step for little gain).
    let pad = 0.005 * (max - min);
    let (min, max) = (min - pad, max + pad);
    // Snapping outwards can add a step at each end; choose the step for
    // the snapped span so the tick count stays within the budget.
    let mut step = nice_step(max - min, max_ticks);
    let snap = |step: f64| ((min / step).floor() * step, (max / step).ceil() * step);
    for _ in 0..8 {
        let (lo, hi) = snap(step);
        let next = nice_step(hi - lo, max_ticks);
        if next <= step {
            return (lo, hi, step);
        }
        step = next;
    }
    let (lo, hi) = snap(step);
    (lo, hi, step)
}

/// Smallest and largest finite y whose x lies in [x_lo, x_hi] (positive
/// values only on a log axis).
fn y_extent(
    c: &RawCurve<'_>,
    (x_lo, x_hi): (f64, f64),
    x_log: bool,
    y_log: bool,
) -> Option<(f64, f64)> {
    let (x, y) = (c.x, c.y);
    let (i0, i1) = window(x, x_lo, x_hi, c.sorted);
    let mut e: Option<(f64, f64)> = None;
    for i in i0..i1 {
        let (xv, yv) = (x[i], y[i]);
        let x_ok = xv >= x_lo && xv <= x_hi && (!x_log || xv > 0.0);
        if x_ok && yv.is_finite() && (!y_log || yv > 0.0) {
            e = Some(match e {
                None => (yv, yv),
                Some((a, b)) => (a.min(yv), b.max(yv)),
            });
        }
    }
    e
}

/// Index range worth looking at for x in [lo, hi]: for non-decreasing x a
/// binary search (plus one point either side, for lines entering the
/// panel); otherwise everything.
fn window(x: &[f64], lo: f64, hi: f64, sorted: bool) -> (usize, usize) {
    if !sorted {
        return (0, x.len());
    }
    let i0 = x.partition_point(|&v| v < lo).saturating_sub(1);
    let i1 = (x.partition_point(|&v| v <= hi) + 1).min(x.len());
    (i0, i1.max(i0))
}

// --------------------------------------------------------------- curves

/// Decimate `c` to `columns` pixel columns over the x axis, split it at
/// non-finite points and clip it to the panel. Decimating first keeps the
/// work on a long record to one pass over the window; clipping the
/// per-column extremes afterwards draws the same envelope.
fn prepare(c: &RawCurve<'_>, xa: &Axis, ya: &Axis, columns: usize) -> Vec<Vec<(f64, f64)>> {
    use std::borrow::Cow;
    let (x, y) = (c.x, c.y);
    let (i0, i1) = window(x, xa.lo, xa.hi, c.sorted);
    let tx = |v: f64| fwd(v, xa.log);
    let ty = |v: f64| fwd(v, ya.log);
    let bounds = (tx(xa.lo), ty(ya.lo), tx(xa.hi), ty(ya.hi));
    let span = bounds.2 - bounds.0;

    // Runs of consecutive drawable samples, as index ranges.
    let mut runs: Vec<std::ops::Range<usize>> = Vec::new();
    let mut start: Option<usize> = None;
    for i in i0..i1 {
        let ok = tx(x[i]).is_finite() && ty(y[i]).is_finite();
        match (ok, start) {
            (true, None) => start = Some(i),
            (false, Some(s0)) => {
                runs.push(s0..i);
                start = None;
            }
            _ => {}
        }
    }
    if let Some(s0) = start {
        runs.push(s0..i1);
    }

    let mut out = Vec::new();
    for r in runs {
        let (rx, ry): (Cow<'_, [f64]>, Cow<'_, [f64]>) = if xa.log || ya.log {
            (
                x[r.clone()].iter().map(|&v| tx(v)).collect(),
                y[r.clone()].iter().map(|&v| ty(v)).collect(),
            )
        } else {
            (Cow::Borrowed(&x[r.clone()]), Cow::Borrowed(&y[r.clone()]))
        };
        let (lo, hi) = rx
            .iter()
            .fold((f64::MAX, f64::MIN), |(a, b), &v| (a.min(v), b.max(v)));
        let buckets = ((columns as f64 * (hi - lo) / span).ceil() as usize).clamp(1, rx.len());
        let (dx, dy) = decimate_minmax(&rx, &ry, buckets);
        let pts: Vec<(f64, f64)> = dx.into_iter().zip(dy).collect();
        for clipped in clip_run(&pts, bounds) {
            out.push(
                clipped
                    .into_iter()
                    .map(|(a, b)| (inv(a, xa.log), inv(b, ya.log)))
                    .collect(),
            );
        }
    }
    out
}

fn fwd(v: f64, log: bool) -> f64 {
    if !log {
        v
    } else if v > 0.0 {
        v.log10()
    } else {
        f64::NAN
    }
}

fn inv(v: f64, log: bool) -> f64 {
    if log { 10f64.powf(v) } else { v }
}

/// Clip a polyline to the box (x0, y0, x1, y1); pieces outside are cut out
/// and the polyline splits where it leaves the box.
fn clip_run(run: &[(f64, f64)], b: (f64, f64, f64, f64)) -> Vec<Vec<(f64, f64)>> {
    let inside = |p: (f64, f64)| p.0 >= b.0 && p.0 <= b.2 && p.1 >= b.1 && p.1 <= b.3;
    let mut out: Vec<Vec<(f64, f64)>> = Vec::new();
    let mut cur: Vec<(f64, f64)> = Vec::new();
    if run.len() == 1 {
        if inside(run[0]) {
            out.push(vec![run[0]]);
        }
        return out;
    }
    for w in run.windows(2) {
        match clip_segment(w[0], w[1], b) {
            Some((a, c)) => {
                if cur.last() != Some(&a) {
                    if cur.len() > 1 {
                        out.push(std::mem::take(&mut cur));
                    } else {
                        cur.clear();
                    }
                    cur.push(a);
                }
                cur.push(c);
            }
            None => {
                if cur.len() > 1 {
                    out.push(std::mem::take(&mut cur));
                } else {
                    cur.clear();
                }
            }
        }
    }
    if cur.len() > 1 {
        out.push(cur);
    }
    out
}

/// Liang-Barsky in data coordinates.
fn clip_segment(
    a: (f64, f64),
    b: (f64, f64),
    bx: (f64, f64, f64, f64),
) -> Option<((f64, f64), (f64, f64))> {
    let (dx, dy) = (b.0 - a.0, b.1 - a.1);
    let (mut t0, mut t1) = (0f64, 1f64);
    for (p, q) in [
        (-dx, a.0 - bx.0),
        (dx, bx.2 - a.0),
        (-dy, a.1 - bx.1),
        (dy, bx.3 - a.1),
    ] {
        if p == 0.0 {
            if q < 0.0 {
                return None;
            }
        } else {
            let t = q / p;
            if p < 0.0 {
                t0 = t0.max(t);
            } else {
                t1 = t1.min(t);
            }
        }
    }
    if t0 > t1 {
        return None;
    }
    let at = |t: f64| (a.0 + t * dx, a.1 + t * dy);
    Some((
        if t0 > 0.0 { at(t0) } else { a },
        if t1 < 1.0 { at(t1) } else { b },
    ))
}

// ----------------------------------------------------------- tick labels

/// How tick values are printed: fixed decimals, or scientific for very
/// large or small numbers.
#[derive(Clone, Copy, Debug)]
pub(crate) enum TickFormat {
    Fixed(usize),
    Sci(usize),
    Log,
}

pub(crate) fn tick_format(ticks: &[f64], log: bool) -> TickFormat {
    if log {
        return TickFormat::Log;
    }
    let step = ticks
        .windows(2)
        .map(|w| (w[1] - w[0]).abs())
        .fold(f64::INFINITY, f64::min);
    let big = ticks.iter().fold(0f64, |m, v| m.max(v.abs()));
    if !step.is_finite() || step <= 0.0 {
        return TickFormat::Fixed(if big >= 1.0 || big == 0.0 { 0 } else { 3 });
    }
    if big >= 1e6 || step < 1e-4 {
        // Significant digits needed to tell neighbours apart.
        let digits = ((big / step).log10().ceil().max(0.0) as usize).min(8);
        return TickFormat::Sci(digits);
    }
    // Decimals of the step: 2.5 needs one, 0.25 two, 5 none.
    let mut d = 0usize;
    while d < 8
        && ((step * 10f64.powi(d as i32)).round() - step * 10f64.powi(d as i32)).abs() > 1e-6
    {
        d += 1;
    }
    TickFormat::Fixed(d)
}

/// A tick label, with a true minus sign (U+2212) and never "-0".
pub(crate) fn format_tick(v: f64, f: TickFormat) -> String {
    let s = match f {
        TickFormat::Fixed(d) => format!("{:.*}", d, v),
        TickFormat::Sci(d) => format!("{:.*e}", d, v),
        TickFormat::Log => {
            // Powers of ten and 2x, 5x: print the shortest exact form.
            let p = v.log10().round() as i32;
            if (-4..=5).contains(&p) {
                let d = (-v.log10().floor()).max(0.0) as usize;
                format!("{:.*}", d, v)
            } else {
                format!("1e{p}")
            }
        }
    };
    let negative_zero = s.starts_with('-') && s[1..].chars().all(|c| c == '0' || c == '.');
    let s = if negative_zero { s[1..].to_string() } else { s };
    s.replace('-', "\u{2212}")
}

// ---------------------------------------------------------------- layout

/// Pixel geometry of one panel, computed before plotters builds it.
struct PanelBox {
    /// Height of the whole panel area (plot + caption + labels + margins).
    area_h: i32,
    plot_h: i32,
}

fn caption_h(m: &Metrics, title: &Option<String>) -> i32 {
    match title {
        Some(t) if !t.is_empty() => text::line_height(m.caption_px) + m.pad / 2,
        _ => 0,
    }
}

fn chrome_h(m: &Metrics, p: &Panel<'_>) -> i32 {
    let x_area = if p.x.labelled { m.x_area() } else { 0 };
    caption_h(m, &p.title) + x_area + margin_top(m) + m.pad / 2
}

/// Room above a plot: half a tick label pokes out above the top tick.
fn margin_top(m: &Metrics) -> i32 {
    m.pad.max((0.7 * m.tick_px) as i32)
}

/// Maximum number of y ticks for a plot `plot_h` pixels tall.
fn y_tick_budget(m: &Metrics, plot_h: i32) -> usize {
    ((f64::from(plot_h) / (1.7 * m.tick_px)) as usize + 1).clamp(2, 11)
}

/// Maximum number of x ticks for a plot `plot_w` pixels wide.
fn x_tick_budget(m: &Metrics, plot_w: i32, widest_label: i32) -> usize {
    let per = f64::from(widest_label) + 1.5 * m.tick_px;
    ((f64::from(plot_w) / per) as usize + 1).clamp(2, 13)
}

fn text_w(size_px: f64, s: &str) -> i32 {
    text::font()
        .map(|f| text::box_size(f, size_px, s).0)
        .unwrap_or(0)
}

/// Room left of a plot: tick labels, gap, rotated axis label.
fn y_area_w(m: &Metrics, p: &Panel<'_>) -> i32 {
    let f = tick_format(&p.y.ticks, p.y.log);
    let widest =
        p.y.ticks
            .iter()
            .map(|&v| text_w(m.tick_px, &format_tick(v, f)))
            .max()
            .unwrap_or(0);
    2 * m.tick_len + widest + (0.5 * m.tick_px) as i32 + text::line_height(m.desc_px) + m.pad / 2
}

fn choose_x_ticks(m: &Metrics, axis: &mut Axis, plot_w: i32) {
    // Widest label of a first guess, then the budget that fits it.
    let guess = ticks_for(axis, 8);
    let f = tick_format(&guess, axis.log);
    let widest = guess
        .iter()
        .map(|&v| text_w(m.tick_px, &format_tick(v, f)))
        .max()
        .unwrap_or(0);
    axis.ticks = ticks_for(axis, x_tick_budget(m, plot_w, widest));
}

fn ticks_for(axis: &Axis, budget: usize) -> Vec<f64> {
    if axis.log {
        log_ticks(axis.lo, axis.hi, budget)
    } else {
        linear_ticks(axis.lo, axis.hi, nice_step(axis.hi - axis.lo, budget))
    }
}

/// Heights of the title and legend bands and the legend rows.
struct Bands {
    title_h: i32,
    legend_h: i32,
    rows: Vec<Vec<(usize, i32)>>,
}

/// Legend geometry: each entry is a line sample, a gap and the label;
/// entries are `spacing` apart in rows `row_h` tall.
struct LegendLayout {
    sample: i32,
    gap: i32,
    spacing: i32,
    row_h: i32,
}

impl LegendLayout {
    fn new(m: &Metrics) -> Self {
        LegendLayout {
            sample: (2.2 * m.legend_px) as i32,
            gap: (0.4 * m.legend_px) as i32,
            spacing: (1.5 * m.legend_px) as i32,
            row_h: text::line_height(m.legend_px) + (0.5 * m.legend_px) as i32,
        }
    }
}

fn bands(sheet: &Sheet, m: &Metrics, width: i32) -> Bands {
    let title_h = if sheet.title.is_empty() {
        m.pad
    } else {
        text::line_height(m.title_px) + 2 * m.pad
    };
    let LegendLayout {
        sample,
        gap,
        spacing,
        row_h,
    } = LegendLayout::new(m);
    let avail = width - 2 * m.pad;
    let mut rows: Vec<Vec<(usize, i32)>> = Vec::new();
    let mut used = 0;
    for (i, (label, _)) in sheet.legend.iter().enumerate() {
        let w = sample + gap + text_w(m.legend_px, label);
        let need = if used == 0 { w } else { used + spacing + w };
        if used > 0 && need > avail {
            rows.push(Vec::new());
            used = w;
        } else {
            used = need;
        }
        if rows.is_empty() {
            rows.push(Vec::new());
        }
        rows.last_mut().expect("a row exists").push((i, w));
    }
    let legend_h = if rows.is_empty() {
        0
    } else {
        rows.len() as i32 * row_h + m.pad / 2
    };
    Bands {
        title_h,
        legend_h,
        rows,
    }
}

/// Lay out and draw a whole sheet on `root`.
pub(crate) fn draw_sheet(
    root: &Area<'_>,
    sheet: &mut Sheet<'_>,
    m: &Metrics,
) -> Result<(), DrawError> {
    root.fill(&WHITE)?;
    let (w, h) = root.dim_in_pixel();
    let (w, h) = (w as i32, h as i32);
    let b = bands(sheet, m, w);

    if !sheet.title.is_empty() {
        root.draw_text(
            &sheet.title,
            &m.font(m.title_px).pos(Pos::new(HPos::Center, VPos::Top)),
            (w / 2, m.pad),
        )?;
    }
    let (_, rest) = root.split_vertically(b.title_h);
    let (legend_area, panels_area) = rest.split_vertically(b.legend_h);
    draw_legend(&legend_area, &sheet.legend, &b.rows, m)?;
    let panels_h = h - b.title_h - b.legend_h;

    match &mut sheet.arrangement {
        Arrangement::Stack(panels) => {
            let chrome: i32 = panels.iter().map(|(p, _)| chrome_h(m, p)).sum();
            let weights: f64 = panels.iter().map(|(_, wt)| wt).sum();
            let plot_total = (panels_h - chrome).max(10 * panels.len() as i32);
            let boxes: Vec<PanelBox> = panels
                .iter()
                .map(|(p, wt)| {
                    let plot_h = (f64::from(plot_total) * wt / weights) as i32;
                    PanelBox {
                        area_h: plot_h + chrome_h(m, p),
                        plot_h,
                    }
                })
                .collect();
            for ((p, _), bx) in panels.iter_mut().zip(&boxes) {
                p.settle_y(m, bx.plot_h);
            }
            let y_area = panels
                .iter()
                .map(|(p, _)| y_area_w(m, p))
                .max()
                .unwrap_or(0);
            let plot_w = w - y_area - margin_right(m) - m.pad;
            for (p, _) in panels.iter_mut() {
                p.settle_x(m, plot_w);
            }
            let mut area = panels_area;
            for ((p, _), bx) in panels.iter().zip(&boxes) {
                let (top, below) = area.split_vertically(bx.area_h);
                draw_panel(&top, p, m, y_area)?;
                area = below;
            }
        }
        Arrangement::Grid { panels, columns } => {
            let cols = (*columns).max(1);
            let rows = panels.len().div_ceil(cols).max(1);
            let cells = panels_area.split_evenly((rows, cols));
            let cell_w = w / cols as i32;
            let cell_h = panels_h / rows as i32;
            for p in panels.iter_mut() {
                let plot_h = cell_h - chrome_h(m, p);
                p.settle_y(m, plot_h);
            }
            // One label width for all panels keeps the plots aligned.
            let y_area = panels.iter().map(|p| y_area_w(m, p)).max().unwrap_or(0);
            let plot_w = cell_w - y_area - margin_right(m) - m.pad;
            for p in panels.iter_mut() {
                p.settle_x(m, plot_w);
            }
            for (p, cell) in panels.iter().zip(cells.iter()) {
                draw_panel(cell, p, m, y_area)?;
            }
        }
    }
    Ok(())
}

/// Room right of a plot: half of a last x tick label like "171.0".
fn margin_right(m: &Metrics) -> i32 {
    (1.6 * m.tick_px) as i32
}

fn draw_legend(
    area: &Area<'_>,
    entries: &[(String, Style)],
    rows: &[Vec<(usize, i32)>],
    m: &Metrics,
) -> Result<(), DrawError> {
    if rows.is_empty() {
        return Ok(());
    }
    let (w, _) = area.dim_in_pixel();
    let LegendLayout {
        sample,
        gap,
        spacing,
        row_h,
    } = LegendLayout::new(m);
    for (r, row) in rows.iter().enumerate() {
        let total: i32 =
            row.iter().map(|(_, ew)| ew).sum::<i32>() + spacing * (row.len() as i32 - 1);
        let mut x = (w as i32 - total) / 2;
        let y = r as i32 * row_h + row_h / 2;
        for &(i, ew) in row {
            let (label, style) = &entries[i];
            let pts = vec![(x, y), (x + sample, y)];
            match style.dash {
                Dash::Solid => area.draw(&PathElement::new(pts, style.shape()))?,
                _ => {
                    let (d, g) = style.dash_gap();
                    area.draw(&DashedPathElement::new(pts, d, g, style.shape()))?
                }
            }
            area.draw_text(
                label,
                &m.font(m.legend_px).pos(Pos::new(HPos::Left, VPos::Center)),
                (x + sample + gap, y),
            )?;
            x += ew + spacing;
        }
    }
    Ok(())
}

/// A plotters axis with the ticks chosen here (plotters' own choice is
/// not what a paper figure wants, and `WithKeyPoints` loses the value
/// formatter for f64).
struct TickedAxis {
    scale: Scale,
    keys: Vec<f64>,
}

enum Scale {
    Lin(RangedCoordf64),
    Log(LogCoord<f64>),
}

impl TickedAxis {
    fn new(a: &Axis) -> Self {
        let scale = if a.log {
            Scale::Log((a.lo..a.hi).log_scale().into())
        } else {
            Scale::Lin((a.lo..a.hi).into())
        };
        TickedAxis {
            scale,
            keys: a.ticks.clone(),
        }
    }
}

impl Ranged for TickedAxis {
    type FormatOption = DefaultFormatting;
    type ValueType = f64;

    fn map(&self, value: &f64, limit: (i32, i32)) -> i32 {
        match &self.scale {
            Scale::Lin(r) => r.map(value, limit),
            Scale::Log(r) => r.map(value, limit),
        }
    }

    fn key_points<Hint: KeyPointHint>(&self, hint: Hint) -> Vec<f64> {
        // Light (minor) grid lines are not drawn.
        if hint.weight().allow_light_points() {
            Vec::new()
        } else {
            self.keys.clone()
        }
    }

    fn range(&self) -> std::ops::Range<f64> {
        match &self.scale {
            Scale::Lin(r) => r.range(),
            Scale::Log(r) => r.range(),
        }
    }
}

fn draw_panel(area: &Area<'_>, p: &Panel<'_>, m: &Metrics, y_area: i32) -> Result<(), DrawError> {
    let mut cb = ChartBuilder::on(area);
    cb.margin_top(margin_top(m) + caption_h(m, &p.title))
        .margin_bottom(m.pad / 2)
        .margin_left(m.pad)
        .margin_right(margin_right(m))
        .x_label_area_size(if p.x.labelled { m.x_area() } else { 0 })
        .y_label_area_size(y_area);
    let mut chart = cb.build_cartesian_2d(TickedAxis::new(&p.x), TickedAxis::new(&p.y))?;
    // The panel caption is centred over the plot itself (plotters' caption
    // is centred over the whole cell, labels included).
    if let Some(t) = p.title.as_ref().filter(|t| !t.is_empty()) {
        let (xs, ys) = chart.plotting_area().get_pixel_range();
        let (bx, by) = area.get_base_pixel();
        area.draw_text(
            t,
            &m.font(m.caption_px)
                .pos(Pos::new(HPos::Center, VPos::Bottom)),
            ((xs.start + xs.end) / 2 - bx, ys.start - by - margin_top(m)),
        )?;
    }

    let fx = tick_format(&p.x.ticks, p.x.log);
    let fy = tick_format(&p.y.ticks, p.y.log);
    let fmt_x = move |v: &f64| format_tick(*v, fx);
    let fmt_y = move |v: &f64| format_tick(*v, fy);
    let mut mesh = chart.configure_mesh();
    mesh.x_labels(p.x.ticks.len().max(1))
        .y_labels(p.y.ticks.len().max(1))
        .x_label_formatter(&fmt_x)
        .y_label_formatter(&fmt_y)
        .label_style(m.font(m.tick_px))
        .axis_desc_style(m.font(m.desc_px))
        .bold_line_style(GRID.stroke_width(1))
        .light_line_style(TRANSPARENT)
        .axis_style(BLACK.stroke_width(m.axis_w))
        .set_all_tick_mark_size(m.tick_len)
        .y_desc(p.y.desc.as_str());
    if p.x.labelled {
        mesh.x_desc(p.x.desc.as_str());
    }
    mesh.draw()?;

    let (x0, x1, y0, y1) = (p.x.lo, p.x.hi, p.y.lo, p.y.hi);
    for b in &p.bands {
        let outline = band_outline(b, (x0, x1, y0, y1));
        if outline.len() >= 3 {
            let (r, g, bl) = b.rgb;
            chart.draw_series(std::iter::once(Polygon::new(
                outline,
                RGBColor(r, g, bl).mix(BAND_ALPHA).filled(),
            )))?;
        }
    }
    for c in &p.curves {
        for run in &c.runs {
            if run.len() == 1 {
                chart.draw_series(std::iter::once(Circle::new(
                    run[0],
                    c.style.width.max(2),
                    c.style.shape().filled(),
                )))?;
                continue;
            }
            match c.style.dash {
                Dash::Solid => {
                    chart.draw_series(std::iter::once(PathElement::new(
                        run.clone(),
                        c.style.shape(),
                    )))?;
                }
                _ => {
                    let (d, g) = c.style.dash_gap();
                    chart.draw_series(DashedLineSeries::new(
                        run.iter().copied(),
                        d,
                        g,
                        c.style.shape(),
                    ))?;
                }
            }
        }
    }
    // The zero line goes over the data so that it stays visible.
    if p.zero_line && y0 < 0.0 && y1 > 0.0 {
        chart.draw_series(std::iter::once(PathElement::new(
            vec![(x0, 0.0), (x1, 0.0)],
            BLACK.stroke_width(1),
        )))?;
    }
    chart.draw_series(std::iter::once(Rectangle::new(
        [(x0, y0), (x1, y1)],
        BLACK.stroke_width(m.axis_w),
    )))?;
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use approx::assert_relative_eq;

    #[test]
    fn nice_steps_follow_1_2_5() {
        // 0..30 Hz with room for 7 ticks: step 5 (0, 5, ..., 30), as in the
        // paper's Figs. 8, 11, 13.
        assert_relative_eq!(nice_step(30.0, 7), 5.0);
        // Room for 13 would fit steps of 2.5; 1-2-5 takes 5.
        assert_relative_eq!(nice_step(30.0, 13), 5.0);
        // 10..20 s with 6 ticks: step 2 (Fig. 9a).
        assert_relative_eq!(nice_step(10.0, 6), 2.0);
        // 120..122 s with 5 ticks: step 0.5 (Fig. 9c).
        assert_relative_eq!(nice_step(2.0, 5), 0.5);
        // 170..171 s with 6 ticks: step 0.2 (Fig. 9d).
        assert_relative_eq!(nice_step(1.0, 6), 0.2);
        let t = linear_ticks(170.0, 171.0, 0.2);
        assert_eq!(t.len(), 6);
        assert_relative_eq!(t[5], 171.0);
    }

    #[test]
    fn ranges_are_never_degenerate() {
        let (lo, hi, _) = nice_range_step(Some((2.0, 2.0)), false, 5);
        assert!(lo < 2.0 && hi > 2.0);
        let (lo, hi, _) = nice_range_step(Some((0.0, 0.0)), false, 5);
        assert!(lo < 0.0 && hi > 0.0);
        let (lo, hi, _) = nice_range_step(None, false, 5);
        assert!(lo < hi);
        let (lo, hi, _) = nice_range_step(Some((3.0, 3.0)), true, 5);
        assert_relative_eq!(lo, 1.0);
        assert_relative_eq!(hi, 10.0);
        // -27.3..3.1 dB, 5 ticks: padded to -27.45..3.25, step 10 gives
        // -30..10, five ticks.
        let (lo, hi, step) = nice_range_step(Some((-27.3, 3.1)), false, 5);
        assert_relative_eq!(lo, -30.0);
        assert_relative_eq!(hi, 10.0);
        assert_eq!(linear_ticks(lo, hi, step).len(), 5);
        // 0..0.95 with 3 ticks: step 0.5 would snap to 0..1 (3 ticks).
        let (lo, hi, step) = nice_range_step(Some((0.0, 0.95)), false, 3);
        assert!(linear_ticks(lo, hi, step).len() <= 3);
    }

    #[test]
    fn log_ticks_are_decades_or_1_2_5() {
        // Exact: decades from 1 are integers.
        assert_eq!(log_ticks(1.0, 1000.0, 8), vec![1.0, 10.0, 100.0, 1000.0]);
        let t = log_ticks(1.0, 10.0, 8);
        assert_eq!(t.len(), 4);
        assert_relative_eq!(t[1], 2.0);
        assert_relative_eq!(t[2], 5.0);
    }

    #[test]
    fn tick_labels() {
        let f = tick_format(&[-0.4, -0.2, 0.0, 0.2], false);
        assert_eq!(format_tick(-0.2, f), "\u{2212}0.2");
        assert_eq!(format_tick(-0.0, f), "0.0");
        let f = tick_format(&[120.0, 120.5, 121.0], false);
        assert_eq!(format_tick(121.0, f), "121.0");
        let f = tick_format(&[0.0, 2.5, 5.0], false);
        assert_eq!(format_tick(5.0, f), "5.0");
        let f = tick_format(&[0.0, 5.0, 10.0], false);
        assert_eq!(format_tick(10.0, f), "10");
        assert_eq!(format_tick(0.01, TickFormat::Log), "0.01");
        assert_eq!(format_tick(200.0, TickFormat::Log), "200");
    }

    #[test]
    fn clipping_splits_and_interpolates() {
        let xa = Axis::new(0.0, 10.0, false, "", true);
        let ya = Axis::new(-1.0, 1.0, false, "", true);
        // Goes out of the top between x = 2 and 4 and comes back.
        let x = [0.0, 2.0, 4.0, 6.0];
        let y = [0.0, 0.0, 3.0, 0.0];
        let style = Style {
            rgb: (0, 0, 0),
            dash: Dash::Solid,
            width: 1,
        };
        let runs = prepare(&RawCurve::new(&x, &y, style), &xa, &ya, 100);
        assert_eq!(runs.len(), 2);
        // Leaves at y = 1: x = 2 + 2 * (1/3).
        assert_relative_eq!(runs[0].last().unwrap().0, 2.0 + 2.0 / 3.0, epsilon = 1e-12);
        assert_relative_eq!(runs[1][0].0, 6.0 - 2.0 / 3.0, epsilon = 1e-12);
        // NaN splits a run; a lone finite point is kept as a single point.
        let (x, y) = ([1.0, 2.0, 3.0], [0.5, f64::NAN, 0.5]);
        let runs = prepare(&RawCurve::new(&x, &y, style), &xa, &ya, 100);
        assert_eq!(runs.len(), 2);
        assert_eq!(runs[0].len(), 1);
    }
}
