//! PNG files of a rasterised figure: the full-colour file (8-bit RGB) and
//! the compact preview the report page inlines as a data URI (8-bit indexed:
//! the same pixels in at most 256 colours). Both are pure functions of the
//! pixels, so the bytes repeat.

use std::collections::HashMap;

use color_quant::NeuQuant;

/// zlib levels, with no row filter: figures are large areas of flat colour,
/// which deflate's matching handles better unfiltered. Measured on the
/// figures benchmark's 22 figures: the RGB files total 1.38 MB at level 4
/// (3.06 MB with png's `Fast` setting, 2.6 ms a figure instead of 1.8); the
/// previews 0.80 MB at level 5 (0.86 MB at level 4), the size that counts
/// for a page they are inlined in.
const RGB_LEVEL: u8 = 4;
const PREVIEW_LEVEL: u8 = 5;

/// The figure as an 8-bit RGB PNG. `rgb` holds `size.0 * size.1` pixels.
pub(crate) fn rgb_png(rgb: &[u8], size: (u32, u32)) -> Result<Vec<u8>, png::EncodingError> {
    encode(rgb, size, None, RGB_LEVEL)
}

/// The figure as an 8-bit indexed PNG of the same size: exact when it has
/// at most 256 colours, otherwise quantised by NeuQuant.
pub(crate) fn preview_png(rgb: &[u8], size: (u32, u32)) -> Result<Vec<u8>, png::EncodingError> {
    let (palette, indices) = quantise(rgb);
    encode(&indices, size, Some(palette), PREVIEW_LEVEL)
}

/// An 8-bit PNG of `data`: RGB triples, or palette indices when a palette
/// (RGB triples) is given.
fn encode(
    data: &[u8],
    size: (u32, u32),
    palette: Option<Vec<u8>>,
    level: u8,
) -> Result<Vec<u8>, png::EncodingError> {
    let mut out = Vec::with_capacity(data.len() / 8);
    let mut enc = png::Encoder::new(&mut out, size.0, size.1);
    enc.set_depth(png::BitDepth::Eight);
    match palette {
        Some(p) => {
            enc.set_color(png::ColorType::Indexed);
            enc.set_palette(p);
        }
        None => enc.set_color(png::ColorType::Rgb),
    }
    enc.set_deflate_compression(png::DeflateCompression::Level(level));
    enc.set_filter(png::Filter::NoFilter);
    let mut writer = enc.write_header()?;
    writer.write_image_data(data)?;
    writer.finish()?;
    Ok(out)
}

/// NeuQuant's sampling factor: it learns from every 30th pixel, the fastest
/// it allows (1 is best and slowest; 10 is its authors' compromise). On the
/// benchmark's figures learning takes 15-19 ms instead of ~50 ms, and the
/// preview still differs from the PNG by under 0.08 levels on average.
const SAMPLE_FACTOR: i32 = 30;

/// A palette (RGB triples, at most 256) and one palette index per pixel.
fn quantise(rgb: &[u8]) -> (Vec<u8>, Vec<u8>) {
    if let Some(exact) = exact_palette(rgb) {
        return exact;
    }
    let rgba: Vec<u8> = rgb
        .chunks_exact(3)
        .flat_map(|p| [p[0], p[1], p[2], 255])
        .collect();
    let nq = NeuQuant::new(SAMPLE_FACTOR, 256, &rgba);
    // Each distinct colour is looked up once; figures are mostly runs of a
    // few colours (white above all), so most pixels repeat the last one.
    let mut seen: HashMap<[u8; 3], u8> = HashMap::new();
    let mut last: Option<([u8; 3], u8)> = None;
    let indices = rgba
        .chunks_exact(4)
        .map(|p| {
            let c = [p[0], p[1], p[2]];
            match last {
                Some((lc, li)) if lc == c => li,
                _ => {
                    let i = *seen.entry(c).or_insert_with(|| nq.index_of(p) as u8);
                    last = Some((c, i));
                    i
                }
            }
        })
        .collect();
    (nq.color_map_rgb(), indices)
}

/// The figure's own colours as the palette (in first-seen order), when
/// there are no more than 256 of them.
fn exact_palette(rgb: &[u8]) -> Option<(Vec<u8>, Vec<u8>)> {
    let mut index: HashMap<[u8; 3], u8> = HashMap::new();
    let mut palette = Vec::new();
    let mut indices = Vec::with_capacity(rgb.len() / 3);
    let mut last: Option<([u8; 3], u8)> = None;
    for p in rgb.chunks_exact(3) {
        let c = [p[0], p[1], p[2]];
        let i = match last {
            Some((lc, li)) if lc == c => li,
            _ => {
                let i = match index.get(&c) {
                    Some(&i) => i,
                    None => {
                        let i = u8::try_from(index.len()).ok()?;
                        index.insert(c, i);
                        palette.extend_from_slice(&c);
                        i
                    }
                };
                last = Some((c, i));
                i
            }
        };
        indices.push(i);
    }
    Some((palette, indices))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn few_colours_are_kept_exactly() {
        // Three colours: the palette holds exactly them, in first-seen order.
        let rgb = [255, 255, 255, 0, 114, 178, 255, 255, 255, 213, 94, 0];
        let (palette, indices) = quantise(&rgb);
        assert_eq!(palette, [255, 255, 255, 0, 114, 178, 213, 94, 0]);
        assert_eq!(indices, [0, 1, 0, 2]);
    }

    #[test]
    fn many_colours_are_quantised_to_256() {
        // A 512 x 512 gradient in red and green (65,536 colours): an even
        // 16 x 16 grid of palette entries would be within 8 levels of every
        // pixel.
        let rgb: Vec<u8> = (0..512 * 512u32)
            .flat_map(|i| [(i % 512 / 2) as u8, (i / 512 / 2) as u8, 128])
            .collect();
        let (palette, indices) = quantise(&rgb);
        assert_eq!(palette.len(), 256 * 3);
        let (mut worst, mut total) = (0, 0);
        for (p, &i) in rgb.chunks(3).zip(&indices) {
            let q = &palette[3 * i as usize..3 * i as usize + 3];
            let d = (0..3).map(|k| p[k].abs_diff(q[k])).max().unwrap();
            worst = worst.max(d);
            total += u64::from(d);
        }
        let mean = total as f64 / indices.len() as f64;
        // NeuQuant's map is not that even grid (and learns from one pixel
        // in 30), so allow four times its worst error; a pixel given a wrong
        // index would typically be off by a hundred levels.
        assert!(worst <= 32, "worst channel error {worst}");
        assert!(mean <= 12.0, "mean channel error {mean}");
    }
}
