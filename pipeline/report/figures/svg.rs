//! Writes a recorded drawing as a standalone SVG 1.1 document: no `<text>`,
//! no external references, glyphs as filled paths. Numbers are printed with
//! fixed rounding, so the same drawing gives the same string.

use std::fmt::Write;

use super::canvas::{Op, Rgba};
use super::text::{Pt, Seg};

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
                // Consecutive strokes of one style (a dashed line is one
                // stroke per dash) share a <path> element.
                let mut d = String::new();
                while let Some(Op::Stroke {
                    points,
                    width: w2,
                    colour: c2,
                }) = ops.get(i)
                {
                    if w2 != width || c2 != colour {
                        break;
                    }
                    stroke_data(&mut d, points);
                    i += 1;
                }
                let _ = writeln!(
                    s,
                    "<path d=\"{d}\" fill=\"none\" stroke=\"{}\"{} stroke-width=\"{width}\" stroke-linecap=\"round\" stroke-linejoin=\"round\"/>",
                    hex(colour),
                    opacity("stroke-opacity", colour)
                );
                continue;
            }
            Op::FillRect {
                x0,
                y0,
                x1,
                y1,
                colour,
            } => {
                let _ = writeln!(
                    s,
                    "<rect x=\"{x0}\" y=\"{y0}\" width=\"{}\" height=\"{}\" fill=\"{}\"{}/>",
                    x1 - x0,
                    y1 - y0,
                    hex(colour),
                    opacity("fill-opacity", colour)
                );
            }
            Op::Polygon { points, colour } => {
                let mut d = String::new();
                stroke_data(&mut d, points);
                d.push('Z');
                let _ = writeln!(
                    s,
                    "<path d=\"{d}\" fill=\"{}\"{}/>",
                    hex(colour),
                    opacity("fill-opacity", colour)
                );
            }
            Op::Circle {
                centre,
                radius,
                colour,
                fill,
            } => {
                let paint = if *fill {
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
                let _ = writeln!(
                    s,
                    "<circle cx=\"{}.5\" cy=\"{}.5\" r=\"{radius}\" {paint}/>",
                    centre.0, centre.1
                );
            }
            Op::Text {
                text,
                glyphs,
                colour,
            } => {
                let _ = writeln!(
                    s,
                    "<g aria-label=\"{}\" fill=\"{}\"{}>",
                    escape(text),
                    hex(colour),
                    opacity("fill-opacity", colour)
                );
                for glyph in glyphs {
                    let _ = writeln!(s, "<path d=\"{}\"/>", glyph_data(glyph));
                }
                s.push_str("</g>\n");
            }
        }
        i += 1;
    }
    s.push_str("</svg>\n");
    s
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

/// "M x y L x y ..." through pixel centres.
fn stroke_data(d: &mut String, points: &[(i32, i32)]) {
    for (k, p) in points.iter().enumerate() {
        let _ = write!(d, "{}{}.5 {}.5", if k == 0 { 'M' } else { 'L' }, p.0, p.1);
    }
}

/// Path data of one glyph; a new subpath starts wherever a segment does not
/// continue the previous one (the contours of the outline).
fn glyph_data(glyph: &[Seg]) -> String {
    let mut d = String::with_capacity(glyph.len() * 24);
    let mut last: Option<Pt> = None;
    let mut contour_start: Pt = (0.0, 0.0);
    for (k, seg) in glyph.iter().enumerate() {
        let start = seg.start();
        if last.is_none_or(|l| !same(l, start)) {
            if last.is_some() {
                d.push('Z');
            }
            let _ = write!(d, "M{} {}", num(start.0), num(start.1));
            contour_start = start;
        }
        // A closing line back to the contour's start is what Z does.
        let closes = glyph
            .get(k + 1)
            .is_none_or(|next| !same(seg.end(), next.start()));
        match *seg {
            Seg::Line(_, b) if closes && same(b, contour_start) => {}
            Seg::Line(_, b) => {
                let _ = write!(d, "L{} {}", num(b.0), num(b.1));
            }
            Seg::Quad(_, c, b) => {
                let _ = write!(d, "Q{} {} {} {}", num(c.0), num(c.1), num(b.0), num(b.1));
            }
            Seg::Cubic(_, c1, c2, b) => {
                let _ = write!(
                    d,
                    "C{} {} {} {} {} {}",
                    num(c1.0),
                    num(c1.1),
                    num(c2.0),
                    num(c2.1),
                    num(b.0),
                    num(b.1)
                );
            }
        }
        last = Some(seg.end());
    }
    if last.is_some() {
        d.push('Z');
    }
    d
}

fn same(a: Pt, b: Pt) -> bool {
    (a.0 - b.0).abs() < 1e-4 && (a.1 - b.1).abs() < 1e-4
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
}
