//! Figure-level tests: the files decode, the PNG, its preview and the SVG
//! show the same picture, text is really drawn, data land where the axes
//! say, bytes repeat, only the formats asked for are made, and degenerate
//! inputs behave as documented.

use std::sync::Arc;

use approx::assert_relative_eq;
use nalgebra::Complex;

use super::*;

// ------------------------------------------------------------ builders

fn freqs(n: usize, df: f64) -> Vec<f64> {
    (0..n).map(|k| k as f64 * df).collect()
}

/// First-order lag 1 / (1 + j f / 5) and the same with 5 % more gain.
fn bode_fig(title: &str) -> BodeFigure {
    let f = freqs(161, 0.25);
    let h: Vec<Complex<f64>> = f
        .iter()
        .map(|&fk| Complex::new(1.0, 0.0) / Complex::new(1.0, fk / 5.0))
        .collect();
    let coh: Vec<f64> = f.iter().map(|&fk| 1.0 - 0.5 * (-fk).exp()).collect();
    BodeFigure {
        title: title.into(),
        series: vec![
            BodeSeries {
                label: "Experimental".into(),
                freq_hz: f.clone(),
                h: h.iter().map(|v| v * 1.05).collect(),
                coherence: Some(coh),
                trace: Trace::Measured,
                palette_index: None,
                band: None,
            },
            BodeSeries {
                label: "Identified model".into(),
                freq_hz: f,
                h,
                coherence: None,
                trace: Trace::Model,
                palette_index: None,
                band: None,
            },
        ],
        freq_range_hz: (0.0, 30.0),
        mag_range_db: None,
        phase: true,
        coherence: true,
        log_frequency: false,
        mag_label: String::new(),
    }
}

fn panels_fig(title: &str, n: usize) -> PanelsFigure {
    let fs = 2000.0;
    let t: Arc<[f64]> = (0..n).map(|i| i as f64 / fs).collect();
    let meas: Arc<[f64]> = t.iter().map(|&ti| 0.4 * (2.0 * ti).sin()).collect();
    let sim: Arc<[f64]> = t.iter().map(|&ti| 0.39 * (2.0 * ti - 0.02).sin()).collect();
    let panel = |title: &str, range: (f64, f64)| TimePanel {
        title: title.into(),
        t_s: t.clone(),
        series: vec![
            TimeSeries {
                label: "Experimental".into(),
                y: meas.clone(),
                trace: Trace::Measured,
                palette_index: None,
            },
            TimeSeries {
                label: "Simulated".into(),
                y: sim.clone(),
                trace: Trace::Model,
                palette_index: None,
            },
        ],
        t_range_s: range,
        y_label: "Displacement (cm)".into(),
        y_range: None,
    };
    PanelsFigure {
        title: title.into(),
        panels: vec![
            panel("(a) 1-2 s", (1.0, 2.0)),
            panel("(b) 2-4 s", (2.0, 4.0)),
            panel("(c) 4-5 s", (4.0, 5.0)),
            panel("(d) 5-6 s", (5.0, 6.0)),
        ],
        columns: 2,
    }
}

fn lines_fig(title: &str) -> LinesFigure {
    let x: Vec<f64> = (0..2000).map(|i| i as f64 * 0.01).collect();
    let y: Vec<f64> = x.iter().map(|&v| 0.01 * (3.0 * v).sin()).collect();
    LinesFigure {
        title: title.into(),
        x_label: "Time (s)".into(),
        y_label: "Residual (cm)".into(),
        series: vec![XySeries {
            label: "Residual".into(),
            x,
            y,
            trace: Trace::Measured,
            palette_index: None,
        }],
        x_range: None,
        y_range: None,
        log_x: false,
        log_y: false,
        zero_line: true,
    }
}

// ----------------------------------------------------------- rendering

const ALL: Formats = Formats {
    png: true,
    svg: true,
};

/// Every output of one figure.
#[derive(Debug)]
struct Files {
    png: Vec<u8>,
    svg: String,
}

fn files(fig: Figure, size: (u32, u32)) -> Result<Files, FigureError> {
    let r = render(&fig, size, ALL)?;
    Ok(Files {
        png: r.png.expect("PNG asked for"),
        svg: r.svg.expect("SVG asked for"),
    })
}

fn render_bode(fig: &BodeFigure, size: (u32, u32)) -> Result<Files, FigureError> {
    files(Figure::Bode(fig.clone()), size)
}

fn render_panels(fig: &PanelsFigure, size: (u32, u32)) -> Result<Files, FigureError> {
    files(Figure::Panels(fig.clone()), size)
}

fn render_lines(fig: &LinesFigure, size: (u32, u32)) -> Result<Files, FigureError> {
    files(Figure::Lines(fig.clone()), size)
}

// ------------------------------------------------------------- readers

/// Decoded 8-bit PNG, a palette expanded: (width, height, RGB bytes).
fn decode_png(bytes: &[u8]) -> (u32, u32, Vec<u8>) {
    let mut decoder = png::Decoder::new(std::io::Cursor::new(bytes));
    decoder.set_transformations(png::Transformations::EXPAND);
    let mut reader = decoder.read_info().expect("PNG header");
    let mut buf = vec![0; reader.output_buffer_size().expect("PNG size")];
    let info = reader.next_frame(&mut buf).expect("PNG data");
    buf.truncate(info.buffer_size());
    assert_eq!(info.color_type, png::ColorType::Rgb);
    assert_eq!(info.bit_depth, png::BitDepth::Eight);
    let raw = reader.info().color_type;
    assert!(
        matches!(raw, png::ColorType::Rgb | png::ColorType::Indexed),
        "{raw:?}"
    );
    (info.width, info.height, buf)
}

/// Per-channel absolute differences of two RGB images: (mean, share of
/// pixels where some channel differs by more than `far`).
fn difference(a: &[u8], b: &[u8], far: u8) -> (f64, f64) {
    assert_eq!(a.len(), b.len());
    let total: u64 = a
        .iter()
        .zip(b)
        .map(|(x, y)| u64::from(x.abs_diff(*y)))
        .sum();
    let far_px = a
        .chunks(3)
        .zip(b.chunks(3))
        .filter(|(p, q)| p.iter().zip(*q).any(|(x, y)| x.abs_diff(*y) > far))
        .count();
    (
        total as f64 / a.len() as f64,
        far_px as f64 / (a.len() / 3) as f64,
    )
}

/// Subpaths of an SVG path made of M and L commands only.
fn polylines(d: &str) -> Vec<Vec<(f64, f64)>> {
    let mut out: Vec<Vec<(f64, f64)>> = Vec::new();
    let mut rest = d;
    while !rest.is_empty() {
        let cmd = rest.as_bytes()[0] as char;
        let end = rest[1..]
            .find(|c: char| c.is_ascii_alphabetic())
            .map_or(rest.len(), |i| i + 1);
        let nums: Vec<f64> = rest[1..end]
            .split_whitespace()
            .map(|v| v.parse().expect("number"))
            .collect();
        match cmd {
            'M' => out.push(vec![(nums[0], nums[1])]),
            'L' => out.last_mut().expect("M first").push((nums[0], nums[1])),
            other => panic!("unexpected command {other}"),
        }
        rest = &rest[end..];
    }
    out
}

/// Keep the polylines that lie within box `b` (grown by `slack`), which
/// drops legend samples.
fn within(
    lines: Vec<Vec<(f64, f64)>>,
    b: (f64, f64, f64, f64),
    slack: f64,
) -> Vec<Vec<(f64, f64)>> {
    lines
        .into_iter()
        .filter(|l| {
            l.iter().all(|p| {
                p.0 >= b.0 - slack && p.0 <= b.2 + slack && p.1 >= b.1 - slack && p.1 <= b.3 + slack
            })
        })
        .collect()
}

/// All stroke polylines of one colour in the SVG.
fn strokes_of(doc: &roxmltree::Document<'_>, colour: &str) -> Vec<Vec<(f64, f64)>> {
    doc.descendants()
        .filter(|n| n.has_tag_name("path") && n.attribute("stroke") == Some(colour))
        .flat_map(|n| polylines(n.attribute("d").unwrap()))
        .collect()
}

/// Plot boxes: closed axis-aligned black rectangles drawn as one subpath,
/// as (left, top, right, bottom), largest first.
fn plot_boxes(doc: &roxmltree::Document<'_>) -> Vec<(f64, f64, f64, f64)> {
    let mut boxes: Vec<(f64, f64, f64, f64)> = strokes_of(doc, "#000000")
        .into_iter()
        .filter(|p| p.len() == 5 && p[0] == p[4])
        .map(|p| {
            let xs = p.iter().map(|q| q.0);
            let ys = p.iter().map(|q| q.1);
            (
                xs.clone().fold(f64::MAX, f64::min),
                ys.clone().fold(f64::MAX, f64::min),
                xs.fold(f64::MIN, f64::max),
                ys.fold(f64::MIN, f64::max),
            )
        })
        .filter(|b| b.2 - b.0 > 50.0 && b.3 - b.1 > 30.0)
        .collect();
    boxes.sort_by(|a, b| ((b.2 - b.0) * (b.3 - b.1)).total_cmp(&((a.2 - a.0) * (a.3 - a.1))));
    boxes
}

/// (left, top, right, bottom) in pixels.
type Bbox = (f64, f64, f64, f64);

/// Text groups: (aria-label, number of glyph paths, bounding box of the
/// glyph path coordinates).
fn text_groups(doc: &roxmltree::Document<'_>) -> Vec<(String, usize, Bbox)> {
    doc.descendants()
        .filter(|n| n.has_tag_name("g"))
        .filter_map(|g| {
            let label = g.attribute("aria-label")?.to_string();
            let paths: Vec<_> = g.children().filter(|c| c.has_tag_name("path")).collect();
            let mut b = (f64::MAX, f64::MAX, f64::MIN, f64::MIN);
            for p in &paths {
                let d = p.attribute("d").unwrap();
                let nums: Vec<f64> = d
                    .split(|c: char| c.is_ascii_alphabetic() || c == ' ')
                    .filter(|s| !s.is_empty())
                    .map(|s| s.parse().unwrap())
                    .collect();
                for xy in nums.chunks(2) {
                    b = (
                        b.0.min(xy[0]),
                        b.1.min(xy[1]),
                        b.2.max(xy[0]),
                        b.3.max(xy[1]),
                    );
                }
            }
            Some((label, paths.len(), b))
        })
        .collect()
}

fn all_kinds() -> Vec<(Figure, (u32, u32))> {
    vec![
        (Figure::Bode(bode_fig("Bode")), (1000, 800)),
        (Figure::Panels(panels_fig("Panels", 12_000)), (1200, 700)),
        (Figure::Lines(lines_fig("Lines")), (640, 400)),
    ]
}

// --------------------------------------------------------------- tests

#[test]
fn png_decodes_at_the_requested_size() {
    for (fig, size) in all_kinds() {
        let r = files(fig, size).unwrap();
        assert_eq!(&r.png[..8], b"\x89PNG\r\n\x1a\n");
        let (w, h, px) = decode_png(&r.png);
        assert_eq!((w, h), size);
        assert_eq!(px.len(), (w * h * 3) as usize);
    }
}

#[test]
fn svg_is_well_formed_sized_and_has_no_text_elements() {
    for (fig, size) in all_kinds() {
        let r = files(fig, size).unwrap();
        let doc = roxmltree::Document::parse(&r.svg).expect("well-formed XML");
        let root = doc.root_element();
        assert_eq!(root.tag_name().name(), "svg");
        assert_eq!(
            root.tag_name().namespace(),
            Some("http://www.w3.org/2000/svg")
        );
        assert_eq!(root.attribute("width"), Some(size.0.to_string().as_str()));
        assert_eq!(root.attribute("height"), Some(size.1.to_string().as_str()));
        let vb = format!("0 0 {} {}", size.0, size.1);
        assert_eq!(root.attribute("viewBox"), Some(vb.as_str()));
        assert!(!doc.descendants().any(|n| n.has_tag_name("text")));
        assert!(!r.svg.contains("<text"));
        // Nothing external: no images, fonts or links.
        assert!(!r.svg.contains("href") && !r.svg.contains("@font-face"));
    }
}

#[test]
fn every_label_is_drawn_as_one_path_per_glyph() {
    // The independent count: every non-space character of these strings has
    // an outline in DejaVu Sans (letters, digits, punctuation, U+2212).
    let fig = bode_fig("Plant with no specimen: command to displacement");
    let r = render_bode(&fig, (1200, 900)).unwrap();
    let doc = roxmltree::Document::parse(&r.svg).unwrap();
    let groups = text_groups(&doc);
    for want in [
        "Plant with no specimen: command to displacement",
        "Experimental",
        "Identified model",
        "Magnitude (dB)",
        "Phase (rad)",
        "Coherence (-)",
        "Frequency (Hz)",
    ] {
        let (_, paths, _) = groups
            .iter()
            .find(|(l, _, _)| l == want)
            .unwrap_or_else(|| panic!("no text \"{want}\""));
        let glyphs = want.chars().filter(|c| !c.is_whitespace()).count();
        assert_eq!(*paths, glyphs, "{want}");
    }
    // Tick labels too: the frequency axis 0..30 Hz carries "0" and "30".
    assert!(groups.iter().any(|(l, _, _)| l == "30"));
}

#[test]
fn png_has_ink_where_the_axis_labels_are() {
    let fig = bode_fig("Ink");
    let size = (1200, 900);
    let r = render_bode(&fig, size).unwrap();
    let (w, _, px) = decode_png(&r.png);
    let doc = roxmltree::Document::parse(&r.svg).unwrap();
    let groups = text_groups(&doc);
    let dark = |b: (f64, f64, f64, f64)| {
        let mut n = 0;
        let mut all = 0;
        for y in b.1.floor() as usize..b.3.ceil() as usize {
            for x in b.0.floor() as usize..b.2.ceil() as usize {
                let i = (y * w as usize + x) * 3;
                all += 1;
                if px[i] < 96 && px[i + 1] < 96 && px[i + 2] < 96 {
                    n += 1;
                }
            }
        }
        n as f64 / all as f64
    };
    for label in ["Frequency (Hz)", "Magnitude (dB)", "Ink"] {
        let (_, _, b) = groups.iter().find(|(l, _, _)| l == label).unwrap();
        // Text ink covers a good part of its box but not all of it.
        let f = dark(*b);
        assert!((0.08..0.7).contains(&f), "{label}: {f}");
    }
    // The rotated y label sits in the left margin, tall and narrow.
    let (_, _, b) = groups
        .iter()
        .find(|(l, _, _)| l == "Magnitude (dB)")
        .unwrap();
    assert!(b.3 - b.1 > 3.0 * (b.2 - b.0));
    assert!(b.0 < 60.0);
    // A blank strip (right of the last plot, between panels) has no ink.
    assert!(dark((1190.0, 300.0, 1199.0, 320.0)) < 1e-9);
}

#[test]
fn magnitude_lands_where_the_axis_says_and_is_clipped_to_the_plot() {
    // |H| = 0.1 is -20 dB, the middle of a -40..0 dB axis. The second series
    // ramps from -60 to +20 dB and must stay inside the plot box.
    let f = freqs(121, 0.25);
    let flat = vec![Complex::new(0.1, 0.0); f.len()];
    let ramp: Vec<Complex<f64>> = f
        .iter()
        .map(|&fk| Complex::new(10f64.powf((-60.0 + 80.0 * fk / 30.0) / 20.0), 0.0))
        .collect();
    let series = |label: &str, h: Vec<Complex<f64>>, trace| BodeSeries {
        label: label.into(),
        freq_hz: f.clone(),
        h,
        coherence: None,
        trace,
        palette_index: None,
        band: None,
    };
    let fig = BodeFigure {
        title: "Placement".into(),
        series: vec![
            series("flat", flat, Trace::Measured),
            series("ramp", ramp, Trace::Measured),
        ],
        freq_range_hz: (0.0, 30.0),
        mag_range_db: Some((-40.0, 0.0)),
        phase: false,
        coherence: false,
        log_frequency: false,
        mag_label: String::new(),
    };
    let r = render_bode(&fig, (1200, 700)).unwrap();
    let doc = roxmltree::Document::parse(&r.svg).unwrap();
    let b = plot_boxes(&doc)[0];
    // Okabe-Ito blue (#0072B2) and vermillion (#D55E00), the published values.
    let flat = within(strokes_of(&doc, "#0072b2"), b, 0.5);
    assert_eq!(flat.len(), 1);
    let mid = 0.5 * (b.1 + b.3);
    for p in &flat[0] {
        assert_relative_eq!(p.1, mid, epsilon = 1.0);
    }
    assert_relative_eq!(flat[0][0].0, b.0, epsilon = 1.0);
    assert_relative_eq!(flat[0].last().unwrap().0, b.2, epsilon = 1.0);
    // Everything vermillion except the legend sample (above the box) lies
    // inside the box.
    let all_ramp = strokes_of(&doc, "#d55e00");
    let ramp = within(all_ramp.clone(), b, 0.5);
    assert_eq!(ramp.len(), all_ramp.len() - 1);
    assert!(all_ramp.iter().any(|l| l.iter().all(|p| p.1 < b.1)));
    // The ramp enters at the bottom (-40 dB at 7.5 Hz) and leaves at the
    // top (0 dB at 22.5 Hz): x = 1/4 and 3/4 of the box.
    let xs: Vec<f64> = ramp.iter().flatten().map(|p| p.0).collect();
    let x_at = |frac: f64| b.0 + frac * (b.2 - b.0);
    assert_relative_eq!(
        xs.iter().cloned().fold(f64::MAX, f64::min),
        x_at(0.25),
        epsilon = 1.5
    );
    assert_relative_eq!(
        xs.iter().cloned().fold(f64::MIN, f64::max),
        x_at(0.75),
        epsilon = 1.5
    );
}

#[test]
fn model_is_dashed_and_measured_solid() {
    let r = render_bode(&bode_fig("Styles"), (1200, 900)).unwrap();
    let doc = roxmltree::Document::parse(&r.svg).unwrap();
    let measured = strokes_of(&doc, "#0072b2");
    let model = strokes_of(&doc, "#d55e00");
    // Measured: legend sample, magnitude, phase, coherence; one piece each.
    assert_eq!(measured.len(), 4);
    // Model: many short dashes (legend sample included).
    assert!(model.len() > 30, "{} dashes", model.len());
}

#[test]
fn long_record_keeps_its_spike_after_decimation() {
    // 348,160 samples of a small ripple with one spike; auto y range. The
    // spike must reach the upper part of the plot, and the drawn line has at
    // most two points per pixel column (plus the ends).
    let n = 348_160;
    let t: Arc<[f64]> = (0..n).map(|i| i as f64 / 2000.0).collect();
    let mut y: Vec<f64> = (0..n).map(|i| 1e-3 * (i as f64 * 0.37).sin()).collect();
    y[25_000] = 1.0; // t = 12.5 s
    let fig = PanelsFigure {
        title: "Spike".into(),
        panels: vec![TimePanel {
            title: "(a) 10-20 s".into(),
            t_s: t,
            series: vec![TimeSeries {
                label: "Experimental".into(),
                y: y.into(),
                trace: Trace::Measured,
                palette_index: None,
            }],
            t_range_s: (10.0, 20.0),
            y_label: "Displacement (cm)".into(),
            y_range: None,
        }],
        columns: 1,
    };
    let r = render_panels(&fig, (1200, 700)).unwrap();
    let doc = roxmltree::Document::parse(&r.svg).unwrap();
    let b = plot_boxes(&doc)[0];
    let lines = strokes_of(&doc, "#0072b2");
    let line = lines.iter().max_by_key(|l| l.len()).unwrap();
    let top = line.iter().map(|p| p.1).fold(f64::MAX, f64::min);
    assert!(
        top < b.1 + 0.2 * (b.3 - b.1),
        "spike top at {top}, box {b:?}"
    );
    // Where the spike is: 12.5 s is a quarter of 10..20 s.
    let at = line.iter().find(|p| p.1 == top).unwrap();
    assert_relative_eq!(at.0, b.0 + 0.25 * (b.2 - b.0), epsilon = 1.5);
    assert!(
        line.len() <= 2 * (b.2 - b.0) as usize + 4,
        "{} points",
        line.len()
    );
}

#[test]
fn same_data_same_bytes_whatever_the_thread_count() {
    let figs = all_kinds();
    let once: Vec<Rendered> = figs
        .iter()
        .map(|(f, s)| render(f, *s, ALL).unwrap())
        .collect();
    let twice: Vec<Rendered> = figs
        .iter()
        .map(|(f, s)| render(f, *s, ALL).unwrap())
        .collect();
    assert_eq!(once, twice);
    let pool = |n| {
        rayon::ThreadPoolBuilder::new()
            .num_threads(n)
            .build()
            .unwrap()
    };
    let refs: Vec<(&Figure, (u32, u32))> = figs.iter().map(|(f, s)| (f, *s)).collect();
    let one = pool(1).install(|| render_many(&refs, ALL));
    let two = pool(2).install(|| render_many(&refs, ALL));
    for ((a, b), c) in one.into_iter().zip(two).zip(&once) {
        let (a, b) = (a.unwrap(), b.unwrap());
        assert_eq!(&a, c);
        assert_eq!(a, b);
    }
}

#[test]
fn phase_is_unwrapped_along_frequency() {
    // A pure delay of 50 ms: arg H = -2 pi f tau, down to -3 pi at 30 Hz;
    // steps of 0.25 Hz change the phase by 0.079 rad, far below pi.
    let tau = 0.05;
    let f = freqs(121, 0.25);
    let h: Vec<Complex<f64>> = f
        .iter()
        .map(|&fk| Complex::from_polar(1.0, -2.0 * std::f64::consts::PI * fk * tau))
        .collect();
    let p = unwrap_phase(&f, &h, 0.0, 30.0);
    for (fk, pk) in f.iter().zip(&p) {
        assert_relative_eq!(*pk, -2.0 * std::f64::consts::PI * fk * tau, epsilon = 1e-9);
    }
    // Outside the range and at H = 0: no value.
    let p = unwrap_phase(
        &[1.0, 2.0, 3.0],
        &[Complex::new(1.0, 0.0), Complex::new(0.0, 0.0), h[4]],
        0.0,
        2.5,
    );
    assert!(p[1].is_nan() && p[2].is_nan());
}

// ---------------------------------------------------- degenerate inputs

#[test]
fn an_empty_figure_is_an_error_naming_it() {
    let mut fig = bode_fig("Fig. 8 (no data)");
    fig.series.clear();
    let e = render_bode(&fig, FULL_WIDTH).unwrap_err();
    assert!(matches!(e, FigureError::Empty { .. }));
    assert_eq!(
        e.to_string(),
        "figure \"Fig. 8 (no data)\": nothing to draw (no series has a finite point inside the plotted range)"
    );

    // All NaN is empty too.
    let mut fig = bode_fig("All NaN");
    for s in &mut fig.series {
        s.h.iter_mut()
            .for_each(|v| *v = Complex::new(f64::NAN, 0.0));
        s.coherence = None;
    }
    assert!(matches!(
        render_bode(&fig, FULL_WIDTH),
        Err(FigureError::Empty { .. })
    ));

    let mut fig = panels_fig("No panels", 10);
    fig.panels.clear();
    assert!(matches!(
        render_panels(&fig, FULL_WIDTH),
        Err(FigureError::Empty { .. })
    ));

    // Data only outside the window is empty as well.
    let mut fig = panels_fig("Outside", 1000); // 0..0.5 s of data
    for p in &mut fig.panels {
        p.t_range_s = (10.0, 11.0);
    }
    assert!(matches!(
        render_panels(&fig, FULL_WIDTH),
        Err(FigureError::Empty { .. })
    ));

    let mut fig = lines_fig("Empty lines");
    fig.series[0].y.iter_mut().for_each(|v| *v = f64::NAN);
    let e = render_lines(&fig, FULL_WIDTH).unwrap_err();
    assert!(e.to_string().contains("\"Empty lines\""));
}

#[test]
fn nan_points_are_skipped_and_empty_series_leave_the_legend() {
    let mut fig = lines_fig("Gaps");
    for v in fig.series[0].y.iter_mut().skip(500).take(100) {
        *v = f64::NAN;
    }
    fig.series.push(XySeries {
        label: "Nothing here".into(),
        x: vec![],
        y: vec![],
        trace: Trace::Model,
        palette_index: None,
    });
    let r = render_lines(&fig, FULL_WIDTH).unwrap();
    let doc = roxmltree::Document::parse(&r.svg).unwrap();
    // The gap splits the residual into two pieces (plus the legend sample).
    assert_eq!(strokes_of(&doc, "#0072b2").len(), 3);
    let labels: Vec<String> = text_groups(&doc).into_iter().map(|g| g.0).collect();
    assert!(labels.contains(&"Residual".to_string()));
    assert!(!labels.contains(&"Nothing here".to_string()));
}

#[test]
fn single_points_and_constant_data_draw() {
    // One point: drawn as a dot; the axes do not collapse.
    let fig = LinesFigure {
        series: vec![XySeries {
            label: "one".into(),
            x: vec![2.0],
            y: vec![5.0],
            trace: Trace::Measured,
            palette_index: None,
        }],
        ..lines_fig("Single point")
    };
    let r = render_lines(&fig, FULL_WIDTH).unwrap();
    assert!(r.svg.contains("<circle"));
    decode_png(&r.png);

    // Constant signal in a time panel: a flat line strictly inside the box.
    let mut fig = panels_fig("Constant", 4000);
    let flat: Arc<[f64]> = vec![0.3; 4000].into();
    for p in &mut fig.panels {
        p.t_range_s = (0.0, 1.0);
        p.series.truncate(1);
        p.series[0].y = flat.clone();
    }
    fig.panels.truncate(1);
    fig.columns = 1;
    let r = render_panels(&fig, FULL_WIDTH).unwrap();
    let doc = roxmltree::Document::parse(&r.svg).unwrap();
    let b = plot_boxes(&doc)[0];
    let lines = strokes_of(&doc, "#0072b2");
    let line = lines.iter().max_by_key(|l| l.len()).unwrap();
    let y0 = line[0].1;
    assert!(line.iter().all(|p| (p.1 - y0).abs() < 1e-9));
    assert!(y0 > b.1 + 10.0 && y0 < b.3 - 10.0);
}

#[test]
fn bad_inputs_are_errors_that_say_where() {
    let mut fig = bode_fig("Lengths");
    fig.series[1].h.pop();
    let e = render_bode(&fig, FULL_WIDTH).unwrap_err();
    assert_eq!(
        e.to_string(),
        "figure \"Lengths\", series \"Identified model\": h has 160 values but freq_hz has 161"
    );

    let mut fig = bode_fig("Range");
    fig.freq_range_hz = (30.0, 0.0);
    let e = render_bode(&fig, FULL_WIDTH).unwrap_err();
    assert_eq!(
        e.to_string(),
        "figure \"Range\": freq_range_hz = (30, 0) is not a usable range: the lower limit must be below the upper"
    );
    let mut fig = bode_fig("Log");
    fig.log_frequency = true;
    assert!(matches!(
        render_bode(&fig, FULL_WIDTH),
        Err(FigureError::BadRange { .. })
    ));
    fig.freq_range_hz = (0.1, 30.0);
    assert!(render_bode(&fig, FULL_WIDTH).is_ok());

    let mut fig = panels_fig("Window", 100);
    fig.panels[2].t_range_s = (1.0, f64::NAN);
    let e = render_panels(&fig, FULL_WIDTH).unwrap_err();
    assert!(
        e.to_string()
            .contains("panels[2] (\"(c) 4-5 s\").t_range_s"),
        "{e}"
    );

    let mut fig = panels_fig("Columns", 100);
    fig.columns = 0;
    assert!(matches!(
        render_panels(&fig, FULL_WIDTH),
        Err(FigureError::NoColumns { .. })
    ));

    let e = render_lines(&lines_fig("Tiny"), (100, 50)).unwrap_err();
    assert_eq!(
        e.to_string(),
        "figure \"Tiny\": size 100 x 50 px is outside 200 x 150 to 8192 x 8192 px"
    );

    let mut fig = lines_fig("Log y");
    fig.log_y = true;
    fig.y_range = Some((0.0, 1.0));
    assert!(matches!(
        render_lines(&fig, FULL_WIDTH),
        Err(FigureError::BadRange { .. })
    ));
}

#[test]
fn log_axes_draw() {
    // Sensitivity-style curve over three decades on log-log axes.
    let x: Vec<f64> = (0..200)
        .map(|i| 10f64.powf(3.0 + 3.0 * i as f64 / 199.0))
        .collect();
    let y: Vec<f64> = x.iter().map(|&k| 1.0 + 1e5 / k).collect();
    let fig = LinesFigure {
        title: "Sensitivity".into(),
        x_label: "Stiffness (N/m)".into(),
        y_label: "Error amplification (-)".into(),
        series: vec![XySeries {
            label: "R3".into(),
            x,
            y,
            trace: Trace::Model,
            palette_index: Some(2),
        }],
        x_range: None,
        y_range: None,
        log_x: true,
        log_y: true,
        zero_line: false,
    };
    let r = render_lines(&fig, FULL_WIDTH).unwrap();
    let doc = roxmltree::Document::parse(&r.svg).unwrap();
    let labels: Vec<String> = text_groups(&doc).into_iter().map(|g| g.0).collect();
    // Decade ticks 1000 ... 1000000 on x, printed in full or as 1e6.
    assert!(labels.contains(&"1000".to_string()));
    assert!(labels.contains(&"1e6".to_string()));
    // Bluish green (#009E73) from palette slot 2.
    assert!(!strokes_of(&doc, "#009e73").is_empty());
}

// ------------------------------------------------------------- formats

#[test]
fn only_the_formats_asked_for_are_made() {
    let fig = Figure::Lines(lines_fig("Formats"));
    let all = render(&fig, FULL_WIDTH, ALL).unwrap();
    for png in [false, true] {
        for svg in [false, true] {
            let r = render(&fig, FULL_WIDTH, Formats { png, svg }).unwrap();
            // Each file is there exactly when asked for, and the same bytes
            // as when everything is asked for.
            assert_eq!(r.png.is_some(), png);
            assert_eq!(r.svg.is_some(), svg);
            assert!(r.png.is_none_or(|b| Some(b) == all.png));
            assert!(r.svg.is_none_or(|s| Some(s) == all.svg));
        }
    }
    // Bad input is an error whatever the formats, even none.
    let none = Formats {
        png: false,
        svg: false,
    };
    assert!(matches!(
        render(&fig, (100, 50), none),
        Err(FigureError::BadSize { .. })
    ));
}

// ------------------------------------------------------ PNG against SVG

/// `svg` drawn on white by resvg, an SVG renderer that shares nothing with
/// `svg.rs` or `raster.rs` but the rasteriser underneath: it parses the
/// document and builds its own geometry from the path data, circles and
/// rectangles written there.
fn resvg_rgb(svg: &str, size: (u32, u32)) -> Vec<u8> {
    use resvg::tiny_skia::{Color, Pixmap, Transform};
    let tree = resvg::usvg::Tree::from_str(svg, &resvg::usvg::Options::default())
        .expect("resvg parses the SVG");
    let mut pixmap = Pixmap::new(size.0, size.1).unwrap();
    pixmap.fill(Color::WHITE);
    resvg::render(&tree, Transform::identity(), &mut pixmap.as_mut());
    pixmap
        .data()
        .chunks_exact(4)
        .flat_map(|p| [p[0], p[1], p[2]])
        .collect()
}

#[test]
fn png_and_svg_are_the_same_picture() {
    let mut kinds = all_kinds();
    let single = LinesFigure {
        series: vec![XySeries {
            label: "one".into(),
            x: vec![2.0],
            y: vec![5.0],
            trace: Trace::Measured,
            palette_index: None,
        }],
        ..lines_fig("Single point")
    };
    kinds.push((Figure::Lines(single), FULL_WIDTH));
    // Dotted references: dots one pixel long, some of them a single point.
    let mut dotted = lines_fig("Dotted");
    dotted.series[0].trace = Trace::Reference;
    kinds.push((Figure::Lines(dotted), FULL_WIDTH));
    // A residual of a long record: noise min/max-decimated to two points a
    // pixel column, whose stroke overlaps itself over most of its band;
    // solid, and dashed as a model's trace is, where dashes overlap: the
    // SVG's one path is their union, so the PNG must not lay ink twice
    // there (dash by dash it differed by 3 levels on average).
    let mut seed = 11u64;
    let mut noise = || {
        seed = seed
            .wrapping_mul(6_364_136_223_846_793_005)
            .wrapping_add(1_442_695_040_888_963_407);
        (seed >> 11) as f64 / (1u64 << 53) as f64 - 0.5
    };
    let mut dense = lines_fig("Dense");
    let n = 120_000;
    dense.series[0].x = (0..n).map(|i| i as f64 * 1e-3).collect();
    dense.series[0].y = (0..n)
        .map(|i| 0.01 * (0.2 * i as f64 * 1e-3).sin() + 0.004 * noise())
        .collect();
    kinds.push((Figure::Lines(dense.clone()), (1200, 450)));
    dense.series[0].trace = Trace::Model;
    kinds.push((Figure::Lines(dense), (1200, 450)));
    for (fig, size) in kinds {
        let r = files(fig, size).unwrap();
        let (_, _, png) = decode_png(&r.png);
        let svg = resvg_rgb(&r.svg, size);
        // Both are anti-aliased renderings of the same geometry, so they
        // differ only where rounding of coverage does: a tenth of a level on
        // average, no pixel by more than a quarter of the range.
        let (mean, far) = difference(&png, &svg, 64);
        assert!(mean < 0.1, "mean difference {mean}");
        // Exact: a count of pixels, as a fraction.
        assert_eq!(far, 0.0, "pixels differ by more than 64 levels");
        // And the ink lands in the same places: of the pixels dark in
        // either picture (a quarter of the way to black), 99.5 % are dark
        // in both.
        let ink = |px: &[u8]| -> Vec<bool> {
            px.chunks(3)
                .map(|p| p.iter().map(|&v| u32::from(v)).sum::<u32>() < 3 * 192)
                .collect()
        };
        let (a, b) = (ink(&png), ink(&svg));
        let both = a.iter().zip(&b).filter(|(x, y)| **x && **y).count();
        let either = a.iter().zip(&b).filter(|(x, y)| **x || **y).count();
        let overlap = both as f64 / either as f64;
        assert!(either > 5000, "only {either} dark pixels");
        assert!(overlap > 0.995, "ink overlap {overlap}");
    }
}

/// A series' uncertainty band is shaded in a quarter-strength tint of its
/// colour under the curves, in both panels, in the PNG and the SVG; without
/// a band there is no such tint.
#[test]
fn a_band_is_shaded_in_a_tint_of_its_series() {
    let plain = bode_fig("band");
    let mut banded = plain.clone();
    let n = banded.series[1].freq_hz.len();
    banded.series[1].band = Some(BodeBand {
        magnitude_db: vec![1.5; n],
        phase_rad: vec![0.1; n],
    });
    // Series 1 takes palette slot 1, vermillion (213, 94, 0); a quarter of
    // it over white is (244, 215, 191).
    let tint = |png: &[u8]| {
        let (_, _, rgb) = decode_png(png);
        rgb.chunks(3)
            .filter(|p| {
                (p[0] as i32 - 244).abs() <= 3
                    && (p[1] as i32 - 215).abs() <= 3
                    && (p[2] as i32 - 191).abs() <= 3
            })
            .count()
    };
    let size = (1200, 900);
    let a = render_bode(&plain, size).unwrap();
    let b = render_bode(&banded, size).unwrap();
    // Without a band only the anti-aliased edges of the dashed line come
    // near that tint.
    assert!(tint(&a.png) < 500, "{}", tint(&a.png));
    // Two bands of +-2 std, each tens of pixels tall over ~1000 px wide.
    assert!(tint(&b.png) > 20_000, "{}", tint(&b.png));
    assert_eq!(
        b.svg.matches("fill-opacity=\"0.25\"").count(),
        2,
        "one band a panel"
    );
    assert!(!a.svg.contains("fill-opacity=\"0.25\""));
}
