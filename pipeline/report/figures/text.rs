//! The embedded font and the one text layout that both outputs use: a string
//! at a plotters anchor, size and rotation becomes glyph outlines in device
//! pixels, traced into contours by `trace_glyph`. The PNG fills those
//! contours and the SVG writes them as paths, so the two files show the same
//! letters in the same places.
//!
//! Why outlines rather than an SVG `@font-face`: an SVG shown through `<img>`
//! may not load external fonts, and an embedded subset would need a font
//! subsetter (a TrueType writer) we would have to trust; outlines are plain
//! path data that every SVG renderer draws the same way.

use std::sync::OnceLock;

use ab_glyph::{Font, FontRef, OutlineCurve, ScaleFont};
use plotters::style::FontStyle;
use plotters_backend::FontTransform;
use plotters_backend::text_anchor::{HPos, Pos, VPos};

use super::geometry::{Outline, Pt, Seg};
use super::{FigureError, FontProblem};

/// The family name the charts ask plotters for.
pub(crate) const FAMILY: &str = "sans-serif";

/// DejaVu Sans 2.37, compiled into the binary by the `dejavu` crate.
fn font_bytes() -> &'static [u8] {
    dejavu::sans::regular()
}

/// The parsed embedded font.
pub(crate) fn font() -> Result<&'static FontRef<'static>, FigureError> {
    static FONT: OnceLock<Option<FontRef<'static>>> = OnceLock::new();
    FONT.get_or_init(|| FontRef::try_from_slice(font_bytes()).ok())
        .as_ref()
        .ok_or(FigureError::Font(FontProblem::DoesNotParse))
}

/// Register the embedded font with plotters (once per process). Without a
/// registered font plotters cannot measure text and every chart fails with
/// `FontUnavailable`, the SVG included.
pub(crate) fn ensure_registered() -> Result<(), FigureError> {
    static DONE: OnceLock<bool> = OnceLock::new();
    let ok = *DONE.get_or_init(|| {
        // `InvalidFont` has no Debug or Display: keep only the fact.
        plotters::style::register_font(FAMILY, FontStyle::Normal, font_bytes()).is_ok()
    });
    if ok {
        font().map(|_| ())
    } else {
        Err(FigureError::Font(FontProblem::Rejected))
    }
}

/// Width and height of the box plotters reserves for `text` at `size_px`.
/// This repeats plotters' own ab_glyph estimate (sum of advances and kerning;
/// height size / 1.24) so that our placement agrees with the room plotters
/// made for the label.
pub(crate) fn box_size(font: &FontRef<'static>, size_px: f64, text: &str) -> (i32, i32) {
    let scaled = font.as_scaled(size_px as f32);
    let mut width = 0f32;
    let mut prev = None;
    for c in text.chars() {
        let id = scaled.glyph_id(c);
        width += scaled.h_advance(id);
        if let Some(p) = prev {
            width += scaled.kern(p, id);
        }
        prev = Some(id);
    }
    (width as i32, line_height(size_px))
}

/// Height of the layout box of one line of text at `size_px`, as plotters
/// reckons it.
pub(crate) fn line_height(size_px: f64) -> i32 {
    (size_px / 1.24) as i32
}

/// Trace one glyph's outline: a new contour starts wherever a segment does
/// not continue the previous one, and every contour is closed (a last line
/// back to the contour's start is what closing draws, so it is left out).
pub(crate) fn trace_glyph(glyph: &[Seg], out: &mut impl Outline) {
    let mut last: Option<Pt> = None;
    let mut contour_start: Pt = (0.0, 0.0);
    for (k, seg) in glyph.iter().enumerate() {
        let start = seg.start();
        if last.is_none_or(|l| !same(l, start)) {
            if last.is_some() {
                out.close();
            }
            out.move_to(start);
            contour_start = start;
        }
        let closes = glyph
            .get(k + 1)
            .is_none_or(|next| !same(seg.end(), next.start()));
        match *seg {
            Seg::Line(_, b) if closes && same(b, contour_start) => {}
            Seg::Line(_, b) => out.line_to(b),
            Seg::Quad(_, c, b) => out.quad_to(c, b),
            Seg::Cubic(_, c1, c2, b) => out.cubic_to(c1, c2, b),
        }
        last = Some(seg.end());
    }
    if last.is_some() {
        out.close();
    }
}

/// Whether two outline points coincide (to a ten-thousandth of a pixel).
fn same(a: Pt, b: Pt) -> bool {
    (a.0 - b.0).abs() < 1e-4 && (a.1 - b.1).abs() < 1e-4
}

/// Where plotters asked for a text to go.
pub(crate) struct Placement {
    pub pos: (i32, i32),
    pub size_px: f64,
    pub anchor: Pos,
    pub transform: FontTransform,
}

/// Glyph outlines of `text` in device pixels, one entry per glyph that has an
/// outline (spaces have none).
///
/// The anchor arithmetic is plotters' default `draw_text`: the layout box is
/// shifted by the anchor, then rotated about `pos`. Inside the box the
/// baseline is set so capital letters sit centred in it (plotters' own
/// rasteriser puts the baseline at half the size, which pushes capitals above
/// the box); glyphs keep their side bearings.
pub(crate) fn layout(font: &FontRef<'static>, text: &str, at: &Placement) -> Vec<Vec<Seg>> {
    let (box_w, box_h) = box_size(font, at.size_px, text);
    let (box_w, box_h) = (box_w as f32, box_h as f32);
    let dx = match at.anchor.h_pos {
        HPos::Left => 0.0,
        HPos::Right => -box_w,
        HPos::Center => -(box_w / 2.0).floor(),
    };
    let dy = match at.anchor.v_pos {
        VPos::Top => 0.0,
        VPos::Center => -(box_h / 2.0).floor(),
        VPos::Bottom => -box_h,
    };
    let size = at.size_px as f32;
    let scaled = font.as_scaled(size);
    // ab_glyph's pixel scale: `size` pixels from descender to ascender.
    let per_unit = size / font.height_unscaled();
    let cap_px = cap_height_unscaled(font) * per_unit;
    let baseline = dy + 0.5 * (box_h + cap_px);
    let (ox, oy) = (at.pos.0 as f32, at.pos.1 as f32);
    let rotate = |u: f32, v: f32| -> Pt {
        let (x, y) = match at.transform {
            FontTransform::None => (u, v),
            FontTransform::Rotate90 => (-v, u),
            FontTransform::Rotate180 => (-u, -v),
            FontTransform::Rotate270 => (v, -u),
        };
        (ox + x, oy + y)
    };

    let mut glyphs = Vec::new();
    let mut pen = dx;
    let mut prev = None;
    for c in text.chars() {
        let id = scaled.glyph_id(c);
        if let Some(p) = prev {
            pen += scaled.kern(p, id);
        }
        prev = Some(id);
        if let Some(outline) = font.outline(id) {
            // Font units have y up; device pixels have y down.
            let map = |p: ab_glyph::Point| rotate(pen + p.x * per_unit, baseline - p.y * per_unit);
            let segs: Vec<Seg> = outline
                .curves
                .iter()
                .map(|curve| match *curve {
                    OutlineCurve::Line(a, b) => Seg::Line(map(a), map(b)),
                    OutlineCurve::Quad(a, b, c) => Seg::Quad(map(a), map(b), map(c)),
                    OutlineCurve::Cubic(a, b, c, d) => Seg::Cubic(map(a), map(b), map(c), map(d)),
                })
                .collect();
            if !segs.is_empty() {
                glyphs.push(segs);
            }
        }
        pen += scaled.h_advance(id);
    }
    glyphs
}

/// Height of a capital H in font units (1493 of 2048 in DejaVu Sans).
fn cap_height_unscaled(font: &FontRef<'static>) -> f32 {
    // ab_glyph stores the font's y_max in `bounds.min.y` (y-down naming).
    font.outline(font.glyph_id('H'))
        .map(|o| o.bounds.min.y.max(o.bounds.max.y))
        .unwrap_or_else(|| 0.7 * font.ascent_unscaled())
}

#[cfg(test)]
mod tests {
    use super::*;
    use approx::assert_relative_eq;

    fn at(pos: (i32, i32), transform: FontTransform) -> Placement {
        Placement {
            pos,
            size_px: 40.0,
            anchor: Pos::new(HPos::Left, VPos::Top),
            transform,
        }
    }

    fn bounds(glyphs: &[Vec<Seg>]) -> (f32, f32, f32, f32) {
        let mut b = (f32::MAX, f32::MAX, f32::MIN, f32::MIN);
        for seg in glyphs.iter().flatten() {
            let points: &[Pt] = match seg {
                Seg::Line(a, c) => &[*a, *c],
                Seg::Quad(a, c, d) => &[*a, *c, *d],
                Seg::Cubic(a, c, d, e) => &[*a, *c, *d, *e],
            };
            for p in points {
                b = (b.0.min(p.0), b.1.min(p.1), b.2.max(p.0), b.3.max(p.1));
            }
        }
        b
    }

    #[test]
    fn dejavu_metrics_are_the_published_ones() {
        // DejaVu Sans 2.37 as read from the TTF with a separate 40-line
        // Python parser of the head/hhea/glyf tables: 2048 units per em,
        // ascent 1901, descent -483, glyph 'H' bounding box yMax 1493.
        let f = font().unwrap();
        assert_relative_eq!(f.units_per_em().unwrap(), 2048.0);
        assert_relative_eq!(f.ascent_unscaled(), 1901.0);
        assert_relative_eq!(f.descent_unscaled(), -483.0);
        assert_relative_eq!(cap_height_unscaled(f), 1493.0);
    }

    #[test]
    fn capital_sits_inside_its_box_and_rotation_swaps_axes() {
        let f = font().unwrap();
        // 'H' at 40 px: the font spans 2384 units over 40 px, so the cap
        // height is 1493 / 2384 * 40 = 25.05 px, centred in a 32 px box.
        let g = layout(f, "H", &at((100, 200), FontTransform::None));
        assert_eq!(g.len(), 1);
        let (_, y0, _, y1) = bounds(&g);
        let cap = 1493.0 / 2384.0 * 40.0;
        assert_relative_eq!(y1 - y0, cap, epsilon = 0.01);
        let box_h = (40.0f32 / 1.24).floor();
        assert_relative_eq!(y0 - 200.0, (box_h - cap) / 2.0, epsilon = 0.01);

        // Rotate270 maps (u, v) to (v, -u): the glyph becomes wide in x by
        // the cap height and extends upwards from the anchor.
        let r = layout(f, "H", &at((100, 200), FontTransform::Rotate270));
        let (x0, _, x1, y1r) = bounds(&r);
        assert_relative_eq!(x1 - x0, cap, epsilon = 0.01);
        assert!(y1r <= 200.0);
    }

    #[test]
    fn spaces_have_no_outline_and_box_matches_advances() {
        let f = font().unwrap();
        let g = layout(f, "a b", &at((0, 0), FontTransform::None));
        assert_eq!(g.len(), 2);
        // Advance widths from the same Python parser (cmap + hmtx): a 1255,
        // space 651, b 1300. At 2384 px one font unit is one pixel.
        let (w, h) = box_size(f, 2384.0, "a b");
        assert_eq!(w, 1255 + 651 + 1300);
        assert_eq!(h, (2384.0f64 / 1.24) as i32);
    }
}
