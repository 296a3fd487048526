//! Writes a recorded drawing as a standalone SVG 1.1 document: no `<text>`,
//! no external references, glyphs as filled paths. Numbers are printed with
//! fixed rounding, so the same drawing gives the same string.

use std::fmt::Write;

use plotters_backend::BackendCoord;

use super::canvas::{self, Op, Rgba};
use super::geometry::{Outline, Pt, Seg};
use super::text;

/// The SVG document for `ops` on a `size` canvas; `title` becomes `<title>`.
pub(crate) fn write(ops: &[Op], size: (u32, u32), title: &str) -> String {
    let (w, h) = size;
    let mut s = String::with_capacity(64 * 1024);
    s.push_str("<?xml version=\"1.0\" encoding=\"UTF-8\"?>\n");
    let _ = writeln!(
        s,
        "<svg xmlns=\"http://www.w3.org/2000/svg\" version=\"1.1\" width=\"{w}\" height=\"{h}\" viewBox=\"0 0 {w} {h}\">"
    );
    if !title.is_empty() {
        let _ = writeln!(s, "<title>{}</title>", escape(title));
    }
    let mut i = 0;
    while i < ops.len() {
        match &ops[i] {
            Op::Stroke { width, colour, .. } => {
                i += write_strokes(&mut s, &ops[i..], *width, colour);
                continue;
            }
            Op::FillRect {
                x0,
                y0,
                x1,
                y1,
                colour,
            } => write_rect(&mut s, (*x0, *y0), (*x1, *y1), colour),
            Op::Polygon { points, colour } => write_polygon(&mut s, points, colour),
            Op::Circle {
                centre,
                radius,
                colour,
                fill,
            } => write_circle(&mut s, *centre, *radius, colour, *fill),
            Op::Text {
                text,
                glyphs,
                colour,
            } => write_text(&mut s, text, glyphs, colour),
        }
        i += 1;
    }
    s.push_str("</svg>\n");
    s
}

/// The strokes at the start of `ops` of one style (`width`, `colour`) as
/// one `<path>` element ([`canvas::stroke_run`]); returns how many ops it
/// took.
fn write_strokes(s: &mut String, ops: &[Op], width: u32, colour: &Rgba) -> usize {
    let run = canvas::stroke_run(ops);
    let mut d = PathData::default();
    for points in &run {
        canvas::polyline(points, &mut d);
    }
    let _ = writeln!(
        s,
        "<path d=\"{}\" fill=\"none\" stroke=\"{}\"{} stroke-width=\"{width}\" stroke-linecap=\"round\" stroke-linejoin=\"round\"/>",
        d.0,
        hex(colour),
        opacity("stroke-opacity", colour)
    );
    run.len()
}

/// Pixels x0..x1, y0..y1 filled, as a `<rect>`.
fn write_rect(s: &mut String, (x0, y0): (i32, i32), (x1, y1): (i32, i32), colour: &Rgba) {
    let _ = writeln!(
        s,
        "<rect x=\"{x0}\" y=\"{y0}\" width=\"{}\" height=\"{}\" fill=\"{}\"{}/>",
        x1 - x0,
        y1 - y0,
        hex(colour),
        opacity("fill-opacity", colour)
    );
}

/// A filled polygon as a closed `<path>`.
fn write_polygon(s: &mut String, points: &[BackendCoord], colour: &Rgba) {
    let mut d = PathData::default();
    canvas::polyline(points, &mut d);
    d.close();
    let _ = writeln!(
        s,
        "<path d=\"{}\" fill=\"{}\"{}/>",
        d.0,
        hex(colour),
        opacity("fill-opacity", colour)
    );
}

/// A circle, filled or stroked, as a `<circle>`.
fn write_circle(s: &mut String, centre: BackendCoord, radius: u32, colour: &Rgba, fill: bool) {
    let paint = if fill {
        format!(
            "fill=\"{}\"{}",
            hex(colour),
            opacity("fill-opacity", colour)
        )
    } else {
        format!(
            "fill=\"none\" stroke=\"{}\"{}",
            hex(colour),
            opacity("stroke-opacity", colour)
        )
    };
    let (cx, cy) = canvas::centre(centre);
    let _ = writeln!(
        s,
        "<circle cx=\"{}\" cy=\"{}\" r=\"{radius}\" {paint}/>",
        num(cx),
        num(cy)
    );
}

/// Text as a group of filled glyph paths, the string kept as its
/// aria-label.
fn write_text(s: &mut String, text: &str, glyphs: &[Vec<Seg>], colour: &Rgba) {
    let _ = writeln!(
        s,
        "<g aria-label=\"{}\" fill=\"{}\"{}>",
        escape(text),
        hex(colour),
        opacity("fill-opacity", colour)
    );
    for glyph in glyphs {
        let mut d = PathData::default();
        text::trace_glyph(glyph, &mut d);
        let _ = writeln!(s, "<path d=\"{}\"/>", d.0);
    }
    s.push_str("</g>\n");
}

fn hex(c: &Rgba) -> String {
    format!("#{:02x}{:02x}{:02x}", c.rgb.0, c.rgb.1, c.rgb.2)
}

fn opacity(attr: &str, c: &Rgba) -> String {
    if c.alpha >= 1.0 {
        String::new()
    } else {
        format!(" {attr}=\"{}\"", num(c.alpha as f32))
    }
}

/// SVG path data ("M x y L x y ... Z"), coordinates rounded by `num`.
#[derive(Default)]
struct PathData(String);

impl PathData {
    fn command(&mut self, c: char, points: &[Pt]) {
        self.0.push(c);
        for (k, p) in points.iter().enumerate() {
            if k > 0 {
                self.0.push(' ');
            }
            let _ = write!(self.0, "{} {}", num(p.0), num(p.1));
        }
    }
}

impl Outline for PathData {
    fn move_to(&mut self, p: Pt) {
        self.command('M', &[p]);
    }
    fn line_to(&mut self, p: Pt) {
        self.command('L', &[p]);
    }
    fn quad_to(&mut self, c: Pt, p: Pt) {
        self.command('Q', &[c, p]);
    }
    fn cubic_to(&mut self, c1: Pt, c2: Pt, p: Pt) {
        self.command('C', &[c1, c2, p]);
    }
    fn close(&mut self) {
        self.0.push('Z');
    }
}

/// A coordinate rounded to 1/100 px, without trailing zeros or "-0".
fn num(v: f32) -> String {
    let hundredths = (f64::from(v) * 100.0).round() as i64;
    let sign = if hundredths < 0 { "-" } else { "" };
    let a = hundredths.unsigned_abs();
    let (int, frac) = (a / 100, a % 100);
    match frac {
        0 => format!("{sign}{int}"),
        f if f % 10 == 0 => format!("{sign}{int}.{}", f / 10),
        f => format!("{sign}{int}.{f:02}"),
    }
}

/// Escape for XML text and attribute values.
pub(crate) fn escape(s: &str) -> String {
    let mut out = String::with_capacity(s.len());
    for c in s.chars() {
        match c {
            '&' => out.push_str("&amp;"),
            '<' => out.push_str("&lt;"),
            '>' => out.push_str("&gt;"),
            '"' => out.push_str("&quot;"),
            '\'' => out.push_str("&apos;"),
            // Control characters are not allowed in XML 1.0.
            c if (c as u32) < 0x20 && c != '\t' && c != '\n' && c != '\r' => out.push(' '),
            c => out.push(c),
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn numbers_round_to_hundredths() {
        assert_eq!(num(0.0), "0");
        assert_eq!(num(-0.001), "0");
        assert_eq!(num(12.5), "12.5");
        assert_eq!(num(-4.236), "-4.24");
        assert_eq!(num(7.05), "7.05");
        assert_eq!(num(1199.999), "1200");
    }

    #[test]
    fn escape_covers_markup_and_controls() {
        assert_eq!(
            escape("a<b & \"c\" 'd'>\u{1}"),
            "a&lt;b &amp; &quot;c&quot; &apos;d&apos;&gt; "
        );
    }

    #[test]
    fn strokes_of_one_style_share_a_path() {
        let c = Rgba {
            rgb: (0, 114, 178),
            alpha: 1.0,
        };
        let ops = vec![
            Op::Stroke {
                points: vec![(0, 0), (10, 0)],
                width: 3,
                colour: c,
            },
            Op::Stroke {
                points: vec![(20, 0), (30, 0)],
                width: 3,
                colour: c,
            },
        ];
        let s = write(&ops, (40, 10), "t");
        assert_eq!(s.matches("<path").count(), 1);
        assert!(s.contains("d=\"M0.5 0.5L10.5 0.5M20.5 0.5L30.5 0.5\""));
        assert!(s.contains("stroke=\"#0072b2\""));
    }

    #[test]
    fn pixel_centres_left_of_zero_and_lone_points() {
        // Pixel -3 has its centre at -2.5; a lone point is a zero-length
        // segment, which round caps draw as a dot (a bare M draws nothing).
        let ops = vec![Op::Stroke {
            points: vec![(-3, 2)],
            width: 2,
            colour: Rgba {
                rgb: (0, 0, 0),
                alpha: 1.0,
            },
        }];
        let s = write(&ops, (10, 10), "");
        assert!(s.contains("d=\"M-2.5 2.5L-2.5 2.5\""), "{s}");
    }
}
