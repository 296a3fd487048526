//! Rasterises a recorded drawing with tiny-skia into 8-bit RGB pixels on a
//! white background: strokes with round caps and joins, polygons and glyphs
//! filled by the non-zero rule, all anti-aliased; filled rectangles cover
//! whole pixels without anti-aliasing, so axes and backgrounds stay crisp.
//! tiny-skia's arithmetic does not depend on the thread count, so neither do
//! the pixels.

use tiny_skia::{FillRule, LineCap, LineJoin, Paint, PathBuilder, Pixmap, Rect, Stroke, Transform};

use plotters_backend::BackendCoord;

use super::canvas::{self, Op, Rgba};
use super::geometry::{Outline, Pt};
use super::text;

impl Outline for PathBuilder {
    fn move_to(&mut self, p: Pt) {
        PathBuilder::move_to(self, p.0, p.1);
    }
    fn line_to(&mut self, p: Pt) {
        PathBuilder::line_to(self, p.0, p.1);
    }
    fn quad_to(&mut self, c: Pt, p: Pt) {
        PathBuilder::quad_to(self, c.0, c.1, p.0, p.1);
    }
    fn cubic_to(&mut self, c1: Pt, c2: Pt, p: Pt) {
        PathBuilder::cubic_to(self, c1.0, c1.1, c2.0, c2.1, p.0, p.1);
    }
    fn close(&mut self) {
        PathBuilder::close(self);
    }
}

/// Draw `ops` on a white `size` canvas and return its RGB rows (3 bytes a
/// pixel, no padding); None when tiny-skia cannot allocate the canvas.
pub(crate) fn rgb(ops: &[Op], size: (u32, u32)) -> Option<Vec<u8>> {
    let mut pixmap = Pixmap::new(size.0, size.1)?;
    pixmap.fill(tiny_skia::Color::WHITE);
    let mut rest = ops;
    while let [op, ..] = rest {
        if let Op::Stroke { width, colour, .. } = op {
            let run = canvas::stroke_run(rest);
            stroke(&mut pixmap, &run, *width, *colour);
            rest = &rest[run.len()..];
        } else {
            draw(&mut pixmap, op);
            rest = &rest[1..];
        }
    }
    // Every pixel is opaque (white below, source-over on top), so the
    // premultiplied RGBA that tiny-skia keeps is plain RGB plus 255.
    Some(
        pixmap
            .data()
            .chunks_exact(4)
            .flat_map(|px| [px[0], px[1], px[2]])
            .collect(),
    )
}

fn paint(colour: Rgba, anti_alias: bool) -> Paint<'static> {
    let (r, g, b) = colour.rgb;
    let mut paint = Paint::default();
    paint.set_color_rgba8(r, g, b, (colour.alpha * 255.0).round() as u8);
    paint.anti_alias = anti_alias;
    paint
}

fn draw(pixmap: &mut Pixmap, op: &Op) {
    let id = Transform::identity();
    match op {
        Op::FillRect {
            x0,
            y0,
            x1,
            y1,
            colour,
        } => {
            // Cut to the canvas first: plotters may hand over rectangles
            // reaching far outside it.
            let (w, h) = (pixmap.width() as i32, pixmap.height() as i32);
            let (xa, xb) = ((*x0).clamp(0, w), (*x1).clamp(0, w));
            let (ya, yb) = ((*y0).clamp(0, h), (*y1).clamp(0, h));
            if xa < xb && ya < yb {
                let rect = Rect::from_ltrb(xa as f32, ya as f32, xb as f32, yb as f32);
                if let Some(rect) = rect {
                    pixmap.fill_rect(rect, &paint(*colour, false), id, None);
                }
            }
        }
        Op::Stroke {
            points,
            width,
            colour,
        } => stroke(pixmap, &[points], *width, *colour),
        Op::Polygon { points, colour } => {
            let mut pb = PathBuilder::new();
            canvas::polyline(points, &mut pb);
            pb.close();
            if let Some(path) = pb.finish() {
                pixmap.fill_path(&path, &paint(*colour, true), FillRule::Winding, id, None);
            }
        }
        Op::Circle {
            centre,
            radius,
            colour,
            fill,
        } => {
            let (cx, cy) = canvas::centre(*centre);
            let Some(path) = PathBuilder::from_circle(cx, cy, *radius as f32) else {
                return;
            };
            let paint = paint(*colour, true);
            if *fill {
                pixmap.fill_path(&path, &paint, FillRule::Winding, id, None);
            } else {
                // One pixel wide, as the SVG's default stroke width.
                let stroke = Stroke::default();
                pixmap.stroke_path(&path, &paint, &stroke, id, None);
            }
        }
        Op::Text { glyphs, colour, .. } => {
            let paint = paint(*colour, true);
            // Glyph by glyph, as the SVG has one path per glyph.
            for glyph in glyphs {
                let mut pb = PathBuilder::new();
                text::trace_glyph(glyph, &mut pb);
                if let Some(path) = pb.finish() {
                    pixmap.fill_path(&path, &paint, FillRule::Winding, id, None);
                }
            }
        }
    }
}

/// The polylines `run`, stroked `width` pixels wide with round joins and
/// caps as one path, as the SVG's one `<path>` is
/// ([`canvas::stroke_run`]).
fn stroke(pixmap: &mut Pixmap, run: &[&[BackendCoord]], width: u32, colour: Rgba) {
    let mut pb = PathBuilder::new();
    for points in run {
        canvas::polyline(points, &mut pb);
    }
    if let Some(path) = pb.finish() {
        let stroke = Stroke {
            width: width.max(1) as f32,
            line_cap: LineCap::Round,
            line_join: LineJoin::Round,
            ..Stroke::default()
        };
        let id = Transform::identity();
        pixmap.stroke_path(&path, &paint(colour, true), &stroke, id, None);
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use approx::assert_relative_eq;

    const INK: Rgba = Rgba {
        rgb: (0, 0, 0),
        alpha: 1.0,
    };

    fn grey(px: &[u8], w: usize, x: usize, y: usize) -> u8 {
        px[(y * w + x) * 3]
    }

    /// Total ink in pixels (a black pixel counts 1).
    fn ink(px: &[u8]) -> f64 {
        px.chunks(3)
            .map(|p| (255.0 - f64::from(p[0])) / 255.0)
            .sum()
    }

    #[test]
    fn one_pixel_horizontal_line_is_crisp() {
        // A width-1 line through pixel centres covers its row exactly.
        let ops = [Op::Stroke {
            points: vec![(2, 5), (17, 5)],
            width: 1,
            colour: INK,
        }];
        let px = rgb(&ops, (20, 10)).unwrap();
        for x in 3..17 {
            assert_eq!(grey(&px, 20, x, 5), 0);
            assert_eq!(grey(&px, 20, x, 4), 255);
            assert_eq!(grey(&px, 20, x, 6), 255);
        }
    }

    #[test]
    fn filled_rect_covers_whole_pixels_only() {
        let ops = [Op::FillRect {
            x0: 3,
            y0: 2,
            x1: 8,
            y1: 6,
            colour: INK,
        }];
        let px = rgb(&ops, (12, 10)).unwrap();
        for y in 0..10 {
            for x in 0..12 {
                let inside = (3..8).contains(&x) && (2..6).contains(&y);
                assert_eq!(grey(&px, 12, x, y), if inside { 0 } else { 255 });
            }
        }
    }

    #[test]
    fn a_sharp_zigzag_has_no_holes() {
        // A thick polyline turning back on itself: the overlapping pieces must
        // add up, never cancel. Every pixel whose centre lies within r of the
        // path (computed here by point-segment distance) must be fully inked.
        let pts = vec![(5, 30), (25, 5), (45, 30), (65, 5), (85, 30)];
        let ops = [Op::Stroke {
            points: pts.clone(),
            width: 6,
            colour: INK,
        }];
        let px = rgb(&ops, (90, 40)).unwrap();
        let c: Vec<Pt> = pts.iter().map(|&p| canvas::centre(p)).collect();
        let dist = |q: Pt| {
            c.windows(2)
                .map(|w| {
                    let (a, b) = (w[0], w[1]);
                    let (vx, vy) = (b.0 - a.0, b.1 - a.1);
                    let t = (((q.0 - a.0) * vx + (q.1 - a.1) * vy) / (vx * vx + vy * vy))
                        .clamp(0.0, 1.0);
                    ((q.0 - a.0 - t * vx).powi(2) + (q.1 - a.1 - t * vy).powi(2)).sqrt()
                })
                .fold(f32::MAX, f32::min)
        };
        let mut checked = 0;
        for y in 0..40 {
            for x in 0..90 {
                let d = dist((x as f32 + 0.5, y as f32 + 0.5));
                if d < 2.0 {
                    assert_eq!(grey(&px, 90, x, y), 0, "hole at ({x}, {y})");
                    checked += 1;
                } else if d > 4.5 {
                    assert_eq!(grey(&px, 90, x, y), 255, "ink at ({x}, {y})");
                }
            }
        }
        assert!(checked > 300);
    }

    #[test]
    fn filled_disc_has_the_area_of_a_circle() {
        // Total ink of a filled disc of radius 10 px is pi r^2, give or take
        // the anti-aliasing of its rim.
        let ops = [Op::Circle {
            centre: (20, 20),
            radius: 10,
            colour: INK,
            fill: true,
        }];
        let px = rgb(&ops, (40, 40)).unwrap();
        assert_relative_eq!(
            ink(&px),
            std::f64::consts::PI * 10.0 * 10.0,
            max_relative = 0.02
        );
    }

    #[test]
    fn a_lone_point_is_a_round_dot() {
        // A one-point stroke of width 6 is a disc of radius 3: pi 3^2 ink.
        let ops = [Op::Stroke {
            points: vec![(10, 10)],
            width: 6,
            colour: INK,
        }];
        let px = rgb(&ops, (20, 20)).unwrap();
        assert_relative_eq!(ink(&px), std::f64::consts::PI * 9.0, max_relative = 0.05);
        assert_eq!(grey(&px, 20, 10, 10), 0);
    }

    #[test]
    fn translucent_colour_blends_with_white() {
        // Black at half opacity over white is mid grey (127 or 128).
        let ops = [Op::FillRect {
            x0: 0,
            y0: 0,
            x1: 4,
            y1: 4,
            colour: Rgba {
                rgb: (0, 0, 0),
                alpha: 0.5,
            },
        }];
        let px = rgb(&ops, (4, 4)).unwrap();
        assert!((127..=128).contains(&grey(&px, 4, 1, 1)));
    }

    #[test]
    fn far_away_points_are_drawn_without_allocating_the_world() {
        // chart.rs clips curves in data space; anything else reaching far
        // off the canvas is still drawn where it crosses it.
        let ops = [
            Op::Stroke {
                points: vec![(5, 5), (i32::MAX / 2, 5)],
                width: 3,
                colour: INK,
            },
            Op::FillRect {
                x0: i32::MIN,
                y0: 8,
                x1: i32::MAX,
                y1: 9,
                colour: INK,
            },
        ];
        let px = rgb(&ops, (20, 10)).unwrap();
        assert_eq!(grey(&px, 20, 15, 5), 0);
        assert_eq!(grey(&px, 20, 0, 8), 0);
        assert_eq!(grey(&px, 20, 19, 8), 0);
    }
}
