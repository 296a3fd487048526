//! Rasterises a recorded drawing into an 8-bit RGB image and encodes it as
//! PNG. Every shape becomes polygons whose coverage ab_glyph's rasteriser
//! computes (anti-aliased, the same geometry the SVG holds); strokes are a
//! quadrilateral per segment plus a disc at every vertex (round joins and
//! caps, as the SVG asks for). All arithmetic is in a fixed order, so the
//! bytes do not depend on the machine's thread count.

use ab_glyph_rasterizer::{Rasterizer, point};

use super::canvas::{Op, Rgba};
use super::text::Seg;

type P = (f32, f32);

/// An RGB image, white to start with.
pub(crate) struct Image {
    width: usize,
    height: usize,
    rgb: Vec<u8>,
}

impl Image {
    fn new(width: u32, height: u32) -> Self {
        let (width, height) = (width as usize, height as usize);
        Image {
            width,
            height,
            rgb: vec![255; width * height * 3],
        }
    }

    #[inline]
    fn blend(&mut self, x: usize, y: usize, colour: Rgba, coverage: f32) {
        let a = (coverage.min(1.0) * colour.alpha as f32).clamp(0.0, 1.0);
        if a < 1.0 / 512.0 {
            return;
        }
        let i = (y * self.width + x) * 3;
        let src = [colour.rgb.0, colour.rgb.1, colour.rgb.2];
        if a >= 1.0 {
            self.rgb[i..i + 3].copy_from_slice(&src);
            return;
        }
        for (k, s) in src.iter().enumerate() {
            let d = f32::from(self.rgb[i + k]);
            // Values stay within 0..=255, so adding 0.5 and truncating
            // rounds half up (cheaper than `round`, same on every machine).
            self.rgb[i + k] = (d + (f32::from(*s) - d) * a + 0.5) as u8;
        }
    }
}

/// Draw `ops` and encode the PNG.
pub(crate) fn render(ops: &[Op], size: (u32, u32)) -> Result<Vec<u8>, png::EncodingError> {
    let mut img = Image::new(size.0, size.1);
    for op in ops {
        draw(&mut img, op);
    }
    encode(&img)
}

/// Draw `ops` and return the raw RGB rows (for tests).
#[cfg(test)]
pub(crate) fn pixels(ops: &[Op], size: (u32, u32)) -> Vec<u8> {
    let mut img = Image::new(size.0, size.1);
    for op in ops {
        draw(&mut img, op);
    }
    img.rgb
}

fn encode(img: &Image) -> Result<Vec<u8>, png::EncodingError> {
    let mut out = Vec::with_capacity(img.rgb.len() / 8);
    {
        let mut enc = png::Encoder::new(&mut out, img.width as u32, img.height as u32);
        enc.set_color(png::ColorType::Rgb);
        enc.set_depth(png::BitDepth::Eight);
        enc.set_compression(png::Compression::Fast);
        let mut writer = enc.write_header()?;
        writer.write_image_data(&img.rgb)?;
        writer.finish()?;
    }
    Ok(out)
}

fn centre(p: (i32, i32)) -> P {
    (p.0 as f32 + 0.5, p.1 as f32 + 0.5)
}

fn draw(img: &mut Image, op: &Op) {
    match op {
        Op::FillRect {
            x0,
            y0,
            x1,
            y1,
            colour,
        } => {
            let (w, h) = (img.width as i32, img.height as i32);
            let cx = |v: i32| v.clamp(0, w) as usize;
            let cy = |v: i32| v.clamp(0, h) as usize;
            let (xa, xb) = (cx(*x0), cx(*x1));
            for y in cy(*y0)..cy(*y1) {
                if colour.alpha >= 1.0 {
                    let row = &mut img.rgb[(y * img.width + xa) * 3..(y * img.width + xb) * 3];
                    for px in row.chunks_exact_mut(3) {
                        px.copy_from_slice(&[colour.rgb.0, colour.rgb.1, colour.rgb.2]);
                    }
                } else {
                    for x in xa..xb {
                        img.blend(x, y, *colour, 1.0);
                    }
                }
            }
        }
        Op::Stroke {
            points,
            width,
            colour,
        } => {
            let r = (*width).max(1) as f32 / 2.0;
            let pts: Vec<P> = points.iter().map(|&p| centre(p)).collect();
            let mut polys = Vec::with_capacity(2 * pts.len());
            let lim = limits(img, r + 2.0);
            for w in pts.windows(2) {
                if let Some((a, b)) = clip_segment(w[0], w[1], lim) {
                    polys.push(segment_quad(a, b, r));
                    polys.push(disc(b, r));
                    if a != w[0] {
                        polys.push(disc(a, r));
                    }
                }
            }
            if let Some(&first) = pts.first().filter(|&&p| inside(p, lim)) {
                polys.push(disc(first, r));
            }
            fill_polygons(img, &polys, *colour);
        }
        Op::Polygon { points, colour } => {
            let pts: Vec<P> = points.iter().map(|&p| centre(p)).collect();
            fill_polygons(img, &[pts], *colour);
        }
        Op::Circle {
            centre: c,
            radius,
            colour,
            fill,
        } => {
            let c = centre(*c);
            let r = *radius as f32;
            if *fill {
                fill_polygons(img, &[disc(c, r + 0.5)], *colour);
            } else {
                let mut inner = disc(c, (r - 0.5).max(0.0));
                inner.reverse();
                let outer = disc(c, r + 0.5);
                fill_raw(img, &[outer, inner], *colour);
            }
        }
        Op::Text { glyphs, colour, .. } => {
            for glyph in glyphs {
                fill_glyph(img, glyph, *colour);
            }
        }
    }
}

/// (x_min, y_min, x_max, y_max) of the image grown by `pad`.
fn limits(img: &Image, pad: f32) -> (f32, f32, f32, f32) {
    (-pad, -pad, img.width as f32 + pad, img.height as f32 + pad)
}

fn inside(p: P, lim: (f32, f32, f32, f32)) -> bool {
    p.0 >= lim.0 && p.0 <= lim.2 && p.1 >= lim.1 && p.1 <= lim.3
}

/// Liang-Barsky clipping of segment a-b to the box `lim`.
pub(crate) fn clip_segment(a: P, b: P, lim: (f32, f32, f32, f32)) -> Option<(P, P)> {
    let (dx, dy) = (b.0 - a.0, b.1 - a.1);
    let mut t0 = 0f32;
    let mut t1 = 1f32;
    for (p, q) in [
        (-dx, a.0 - lim.0),
        (dx, lim.2 - a.0),
        (-dy, a.1 - lim.1),
        (dy, lim.3 - a.1),
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
    let at = |t: f32| (a.0 + t * dx, a.1 + t * dy);
    Some((
        if t0 > 0.0 { at(t0) } else { a },
        if t1 < 1.0 { at(t1) } else { b },
    ))
}

fn segment_quad(a: P, b: P, r: f32) -> Vec<P> {
    let (dx, dy) = (b.0 - a.0, b.1 - a.1);
    let len = (dx * dx + dy * dy).sqrt();
    if len < 1e-6 {
        return Vec::new();
    }
    let (nx, ny) = (-dy / len * r, dx / len * r);
    vec![
        (a.0 + nx, a.1 + ny),
        (b.0 + nx, b.1 + ny),
        (b.0 - nx, b.1 - ny),
        (a.0 - nx, a.1 - ny),
    ]
}

/// A regular polygon standing in for a disc; enough sides that the error is
/// under a tenth of a pixel.
fn disc(c: P, r: f32) -> Vec<P> {
    if r <= 0.0 {
        return Vec::new();
    }
    // Sagitta r (1 - cos(pi/n)) < 0.1 px.
    let n = ((std::f32::consts::PI / (1.0 - 0.1 / r.max(0.1)).clamp(-1.0, 1.0).acos()).ceil()
        as usize)
        .clamp(8, 64);
    unit_circle(n)
        .into_iter()
        .map(|(x, y)| (c.0 + r * x as f32, c.1 + r * y as f32))
        .collect()
}

/// n points on the unit circle using only IEEE-exact arithmetic (+, *, /):
/// the step's cosine and sine from their Taylor series, then rotation by
/// that step. Platform `sin`/`cos` may differ in the last bit, which would
/// change PNG bytes between machines.
fn unit_circle(n: usize) -> Vec<(f64, f64)> {
    let d = std::f64::consts::TAU / n as f64; // at most pi/4
    let (mut cd, mut sd) = (0.0, 0.0);
    let (mut term_c, mut term_s) = (1.0, d);
    for k in 0..12 {
        cd += term_c;
        sd += term_s;
        let (a, b) = ((2 * k + 1) as f64, (2 * k + 2) as f64);
        term_c *= -d * d / (a * b);
        term_s *= -d * d / (b * (b + 1.0));
    }
    let (mut x, mut y) = (1.0f64, 0.0f64);
    (0..n)
        .map(|_| {
            let p = (x, y);
            (x, y) = (x * cd - y * sd, x * sd + y * cd);
            p
        })
        .collect()
}

/// Twice the signed area (shoelace).
fn signed_area2(poly: &[P]) -> f32 {
    let n = poly.len();
    (0..n)
        .map(|i| {
            let (a, b) = (poly[i], poly[(i + 1) % n]);
            a.0 * b.1 - b.0 * a.1
        })
        .sum()
}

/// Fill the union of `polys`: all are turned the same way round so that
/// overlaps add up (and are clamped) instead of cancelling.
fn fill_polygons(img: &mut Image, polys: &[Vec<P>], colour: Rgba) {
    let oriented: Vec<Vec<P>> = polys
        .iter()
        .filter(|p| p.len() >= 3)
        .map(|p| {
            let mut p = p.clone();
            if signed_area2(&p) < 0.0 {
                p.reverse();
            }
            p
        })
        .collect();
    fill_raw(img, &oriented, colour);
}

/// Fill polygons as given (orientation decides holes).
fn fill_raw(img: &mut Image, polys: &[Vec<P>], colour: Rgba) {
    let Some(bb) = bounds(polys.iter().flatten().copied(), img) else {
        return;
    };
    let mut r = Rasterizer::new(bb.w, bb.h);
    let (ox, oy) = (bb.x0 as f32, bb.y0 as f32);
    for poly in polys.iter().filter(|p| p.len() >= 3) {
        for i in 0..poly.len() {
            let (a, b) = (poly[i], poly[(i + 1) % poly.len()]);
            r.draw_line(point(a.0 - ox, a.1 - oy), point(b.0 - ox, b.1 - oy));
        }
    }
    composite(img, &r, &bb, colour);
}

fn fill_glyph(img: &mut Image, glyph: &[Seg], colour: Rgba) {
    let Some(bb) = bounds(glyph.iter().flat_map(|s| s.points()), img) else {
        return;
    };
    let mut r = Rasterizer::new(bb.w, bb.h);
    let (ox, oy) = (bb.x0 as f32, bb.y0 as f32);
    let p = |q: P| point(q.0 - ox, q.1 - oy);
    for seg in glyph {
        match *seg {
            Seg::Line(a, b) => r.draw_line(p(a), p(b)),
            Seg::Quad(a, b, c) => r.draw_quad(p(a), p(b), p(c)),
            Seg::Cubic(a, b, c, d) => r.draw_cubic(p(a), p(b), p(c), p(d)),
        }
    }
    composite(img, &r, &bb, colour);
}

/// The pixel box a shape is rasterised in.
struct Bounds {
    x0: i64,
    y0: i64,
    w: usize,
    h: usize,
}

/// Integer box around `points` with a one-pixel margin, or None when the
/// shape is empty, not finite, or lies wholly off the image. The rasteriser
/// needs every point inside its grid (coverage left of column 0 would wrap
/// into the row above), so the box is not cut to the image; shapes are kept
/// near the image by clipping before this point.
fn bounds(points: impl Iterator<Item = P>, img: &Image) -> Option<Bounds> {
    let mut b = (f32::MAX, f32::MAX, f32::MIN, f32::MIN);
    let mut any = false;
    for q in points {
        if !(q.0.is_finite() && q.1.is_finite()) {
            return None;
        }
        any = true;
        b = (b.0.min(q.0), b.1.min(q.1), b.2.max(q.0), b.3.max(q.1));
    }
    if !any {
        return None;
    }
    let x0 = b.0.floor() as i64 - 1;
    let y0 = b.1.floor() as i64 - 1;
    let x1 = b.2.ceil() as i64 + 2;
    let y1 = b.3.ceil() as i64 + 2;
    if x1 <= 0 || y1 <= 0 || x0 >= img.width as i64 || y0 >= img.height as i64 {
        return None;
    }
    let (w, h) = ((x1 - x0) as usize, (y1 - y0) as usize);
    // A shape several times larger than the image means unclipped input;
    // refuse it rather than allocate without bound.
    if w * h > 16 * img.width * img.height + 4096 {
        return None;
    }
    Some(Bounds { x0, y0, w, h })
}

fn composite(img: &mut Image, r: &Rasterizer, bb: &Bounds, colour: Rgba) {
    let (iw, ih) = (img.width as i64, img.height as i64);
    r.for_each_pixel_2d(|gx, gy, cov| {
        if cov <= 0.0 {
            return;
        }
        let (x, y) = (bb.x0 + i64::from(gx), bb.y0 + i64::from(gy));
        if x >= 0 && y >= 0 && x < iw && y < ih {
            img.blend(x as usize, y as usize, colour, cov);
        }
    });
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

    #[test]
    fn one_pixel_horizontal_line_is_crisp() {
        // A width-1 line through pixel centres covers its row exactly.
        let ops = [Op::Stroke {
            points: vec![(2, 5), (17, 5)],
            width: 1,
            colour: INK,
        }];
        let px = pixels(&ops, (20, 10));
        for x in 3..17 {
            assert_eq!(grey(&px, 20, x, 5), 0);
            assert_eq!(grey(&px, 20, x, 4), 255);
            assert_eq!(grey(&px, 20, x, 6), 255);
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
        let px = pixels(&ops, (90, 40));
        let c: Vec<P> = pts.iter().map(|&p| centre(p)).collect();
        let dist = |q: P| {
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
        // Total ink of a filled disc of radius 10.5 px is pi r^2 within the
        // polygon approximation (sagitta under 0.1 px) and anti-aliasing.
        let ops = [Op::Circle {
            centre: (20, 20),
            radius: 10,
            colour: INK,
            fill: true,
        }];
        let px = pixels(&ops, (40, 40));
        let ink: f64 = px
            .chunks(3)
            .map(|p| (255.0 - f64::from(p[0])) / 255.0)
            .sum();
        assert_relative_eq!(ink, std::f64::consts::PI * 10.5 * 10.5, max_relative = 0.02);
    }

    #[test]
    fn unit_circle_matches_sin_cos() {
        // Against the platform's sin/cos (an independent implementation).
        for n in [8, 23, 64] {
            for (k, (x, y)) in unit_circle(n).into_iter().enumerate() {
                let t = k as f64 * std::f64::consts::TAU / n as f64;
                assert_relative_eq!(x, t.cos(), epsilon = 1e-12);
                assert_relative_eq!(y, t.sin(), epsilon = 1e-12);
            }
        }
    }

    #[test]
    fn clipping_keeps_the_inside_part() {
        let lim = (0.0, 0.0, 10.0, 10.0);
        let (a, b) = clip_segment((-10.0, 5.0), (20.0, 5.0), lim).unwrap();
        assert_relative_eq!(a.0, 0.0);
        assert_relative_eq!(b.0, 10.0);
        assert!(clip_segment((-10.0, -5.0), (20.0, -5.0), lim).is_none());
        // A far-away point does not make the rasteriser allocate the world.
        let ops = [Op::Stroke {
            points: vec![(5, 5), (i32::MAX / 2, 5)],
            width: 3,
            colour: INK,
        }];
        let px = pixels(&ops, (20, 10));
        assert_eq!(grey(&px, 20, 15, 5), 0);
    }
}
