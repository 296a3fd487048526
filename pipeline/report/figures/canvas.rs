//! The drawing surface plotters draws on: a recorder that keeps every
//! primitive (strokes, fills, text as glyph outlines) in device pixels. The
//! chart is laid out once; `svg.rs` writes the list as SVG and `raster.rs`
//! rasterises the same list into pixels, so both files show one drawing.
//! The geometry both of them trace (pixel centres, glyph contours) is
//! produced here and in `text.rs` through the `Outline` trait (`geometry.rs`),
//! once.
//!
//! Coordinates: plotters' integer coordinate (x, y) names the pixel whose
//! centre is (x + 0.5, y + 0.5); strokes and polygons are drawn through pixel
//! centres, filled rectangles cover whole pixels (end exclusive, as plotters'
//! bitmap backend does).

use std::convert::Infallible;

use plotters_backend::{
    BackendColor, BackendCoord, BackendStyle, BackendTextStyle, DrawingBackend, DrawingErrorKind,
};

use super::geometry::{Outline, Pt, Seg};
use super::text::{self, Placement};

/// An sRGB colour with opacity in 0..=1.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) struct Rgba {
    pub rgb: (u8, u8, u8),
    pub alpha: f64,
}

impl From<BackendColor> for Rgba {
    fn from(c: BackendColor) -> Self {
        Rgba {
            rgb: c.rgb,
            alpha: c.alpha.clamp(0.0, 1.0),
        }
    }
}

/// The centre of pixel `p`.
pub(crate) fn centre(p: BackendCoord) -> Pt {
    (p.0 as f32 + 0.5, p.1 as f32 + 0.5)
}

/// An open polyline through the centres of `points`. A lone point becomes a
/// zero-length segment, which round caps draw as a dot (a bare move-to would
/// draw nothing).
pub(crate) fn polyline(points: &[BackendCoord], out: &mut impl Outline) {
    let Some((&first, rest)) = points.split_first() else {
        return;
    };
    out.move_to(centre(first));
    if rest.is_empty() {
        out.line_to(centre(first));
    }
    for &p in rest {
        out.line_to(centre(p));
    }
}

/// The polylines of the strokes at the start of `ops` that share the first
/// one's width and colour: one path for both outputs (the SVG's one
/// `<path>`, the PNG's one coverage), so a dashed line's dashes, or pieces
/// that touch, are a union and not ink laid twice. Empty when `ops` does not
/// start with a stroke.
pub(crate) fn stroke_run(ops: &[Op]) -> Vec<&[BackendCoord]> {
    let Some(Op::Stroke { width, colour, .. }) = ops.first() else {
        return Vec::new();
    };
    ops.iter()
        .map_while(|op| match op {
            Op::Stroke {
                points,
                width: w,
                colour: c,
            } if w == width && c == colour => Some(points.as_slice()),
            _ => None,
        })
        .collect()
}

/// One recorded primitive.
#[derive(Clone, Debug)]
pub(crate) enum Op {
    /// An open polyline through pixel centres, round joins and caps.
    Stroke {
        points: Vec<BackendCoord>,
        width: u32,
        colour: Rgba,
    },
    /// Pixels x0..x1, y0..y1 (end exclusive).
    FillRect {
        x0: i32,
        y0: i32,
        x1: i32,
        y1: i32,
        colour: Rgba,
    },
    /// A filled polygon through pixel centres (non-zero rule).
    Polygon {
        points: Vec<BackendCoord>,
        colour: Rgba,
    },
    /// A circle about a pixel centre, filled or stroked one pixel wide.
    Circle {
        centre: BackendCoord,
        radius: u32,
        colour: Rgba,
        fill: bool,
    },
    /// Text: the string (kept for the SVG's aria-label) and its glyph
    /// outlines in device pixels.
    Text {
        text: String,
        glyphs: Vec<Vec<Seg>>,
        colour: Rgba,
    },
}

/// A plotters backend that records into `ops`.
pub(crate) struct Recorder<'a> {
    ops: &'a mut Vec<Op>,
    size: (u32, u32),
}

impl<'a> Recorder<'a> {
    pub(crate) fn new(ops: &'a mut Vec<Op>, size: (u32, u32)) -> Self {
        Recorder { ops, size }
    }
}

type DrawResult = Result<(), DrawingErrorKind<Infallible>>;

impl DrawingBackend for Recorder<'_> {
    type ErrorType = Infallible;

    fn get_size(&self) -> (u32, u32) {
        self.size
    }

    fn ensure_prepared(&mut self) -> DrawResult {
        Ok(())
    }

    fn present(&mut self) -> DrawResult {
        Ok(())
    }

    fn draw_pixel(&mut self, point: BackendCoord, color: BackendColor) -> DrawResult {
        if color.alpha > 0.0 {
            self.ops.push(Op::FillRect {
                x0: point.0,
                y0: point.1,
                x1: point.0 + 1,
                y1: point.1 + 1,
                colour: color.into(),
            });
        }
        Ok(())
    }

    fn draw_line<S: BackendStyle>(
        &mut self,
        from: BackendCoord,
        to: BackendCoord,
        style: &S,
    ) -> DrawResult {
        self.draw_path([from, to], style)
    }

    fn draw_rect<S: BackendStyle>(
        &mut self,
        upper_left: BackendCoord,
        bottom_right: BackendCoord,
        style: &S,
        fill: bool,
    ) -> DrawResult {
        let colour: Rgba = style.color().into();
        if colour.alpha <= 0.0 {
            return Ok(());
        }
        let (x0, x1) = (
            upper_left.0.min(bottom_right.0),
            upper_left.0.max(bottom_right.0),
        );
        let (y0, y1) = (
            upper_left.1.min(bottom_right.1),
            upper_left.1.max(bottom_right.1),
        );
        if fill {
            self.ops.push(Op::FillRect {
                x0,
                y0,
                x1,
                y1,
                colour,
            });
        } else {
            self.ops.push(Op::Stroke {
                points: vec![(x0, y0), (x1, y0), (x1, y1), (x0, y1), (x0, y0)],
                width: style.stroke_width().max(1),
                colour,
            });
        }
        Ok(())
    }

    fn draw_path<S: BackendStyle, I: IntoIterator<Item = BackendCoord>>(
        &mut self,
        path: I,
        style: &S,
    ) -> DrawResult {
        let colour: Rgba = style.color().into();
        if colour.alpha <= 0.0 || style.stroke_width() == 0 {
            return Ok(());
        }
        let mut points: Vec<BackendCoord> = Vec::new();
        for p in path {
            if points.last() != Some(&p) {
                points.push(p);
            }
        }
        if !points.is_empty() {
            self.ops.push(Op::Stroke {
                points,
                width: style.stroke_width(),
                colour,
            });
        }
        Ok(())
    }

    fn draw_circle<S: BackendStyle>(
        &mut self,
        center: BackendCoord,
        radius: u32,
        style: &S,
        fill: bool,
    ) -> DrawResult {
        let colour: Rgba = style.color().into();
        if colour.alpha > 0.0 {
            self.ops.push(Op::Circle {
                centre: center,
                radius,
                colour,
                fill,
            });
        }
        Ok(())
    }

    fn fill_polygon<S: BackendStyle, I: IntoIterator<Item = BackendCoord>>(
        &mut self,
        vert: I,
        style: &S,
    ) -> DrawResult {
        let colour: Rgba = style.color().into();
        let points: Vec<BackendCoord> = vert.into_iter().collect();
        if colour.alpha > 0.0 && points.len() >= 3 {
            self.ops.push(Op::Polygon { points, colour });
        }
        Ok(())
    }

    fn draw_text<TStyle: BackendTextStyle>(
        &mut self,
        text: &str,
        style: &TStyle,
        pos: BackendCoord,
    ) -> DrawResult {
        let colour: Rgba = style.color().into();
        if colour.alpha <= 0.0 || text.is_empty() {
            return Ok(());
        }
        // `ensure_registered` ran before any chart was built, so the font is
        // there; a failure here would be a bug, reported as a font error.
        let font = text::font().map_err(|e| DrawingErrorKind::FontError(Box::new(e)))?;
        let glyphs = text::layout(
            font,
            text,
            &Placement {
                pos,
                size_px: style.size(),
                anchor: style.anchor(),
                transform: style.transform(),
            },
        );
        self.ops.push(Op::Text {
            text: text.to_string(),
            glyphs,
            colour,
        });
        Ok(())
    }

    fn estimate_text_size<TStyle: BackendTextStyle>(
        &self,
        text: &str,
        style: &TStyle,
    ) -> Result<(u32, u32), DrawingErrorKind<Infallible>> {
        let font = text::font().map_err(|e| DrawingErrorKind::FontError(Box::new(e)))?;
        let (w, h) = text::box_size(font, style.size(), text);
        Ok((w.max(0) as u32, h.max(0) as u32))
    }
}
