//! The geometry the drawing surface and the text layout share: points and
//! path pieces in device pixels, and the `Outline` that receives them (the
//! SVG writer and the rasteriser each implement it once).

/// Receives path geometry in device pixels. The SVG writer and the
/// rasteriser both implement it, so each primitive's outline is described
/// once for both outputs.
pub(crate) trait Outline {
    fn move_to(&mut self, p: Pt);
    fn line_to(&mut self, p: Pt);
    fn quad_to(&mut self, c: Pt, p: Pt);
    fn cubic_to(&mut self, c1: Pt, c2: Pt, p: Pt);
    fn close(&mut self);
}

/// A point in device pixels (x right, y down).
pub(crate) type Pt = (f32, f32);

/// One piece of a glyph outline in device pixels.
#[derive(Clone, Copy, Debug)]
pub(crate) enum Seg {
    Line(Pt, Pt),
    Quad(Pt, Pt, Pt),
    Cubic(Pt, Pt, Pt, Pt),
}

impl Seg {
    pub(crate) fn start(&self) -> Pt {
        match *self {
            Seg::Line(a, _) | Seg::Quad(a, _, _) | Seg::Cubic(a, _, _, _) => a,
        }
    }
    pub(crate) fn end(&self) -> Pt {
        match *self {
            Seg::Line(_, b) | Seg::Quad(_, _, b) | Seg::Cubic(_, _, _, b) => b,
        }
    }
}
