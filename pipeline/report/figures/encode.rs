//! The PNG file of a rasterised figure (8-bit RGB pixels): a pure function
//! of the pixels, so the bytes repeat. A figure of at most 256 colours (an
//! FRF's: about a hundred with the anti-aliasing's blends) is written with
//! a palette, exactly: a third of the bytes to deflate, and a file 40 %
//! smaller; one of more colours (the time windows' dense traces) as RGB.

use std::collections::HashMap;

/// zlib level 4 with no row filter: figures are large areas of flat colour,
/// which deflate's matching handles better unfiltered. Measured on the
/// figures benchmark's 22 figures: 1.38 MB at level 4 against 3.06 MB with
/// png's `Fast` setting, for 2.6 ms a figure instead of 1.8.
const PALETTE_LEVEL: u8 = 4;

/// The RGB figures are the time windows, a night's largest files: level 6
/// packs a validation run's 15 % smaller than 4 (128 kB to 109 kB; 9 gives
/// 100 kB at several times the time).
const RGB_LEVEL: u8 = 6;

/// The figure as an 8-bit PNG. `rgb` holds `size.0 * size.1` pixels.
pub(crate) fn rgb_png(rgb: &[u8], size: (u32, u32)) -> Result<Vec<u8>, png::EncodingError> {
    let mut out = Vec::with_capacity(rgb.len() / 8);
    let mut enc = png::Encoder::new(&mut out, size.0, size.1);
    enc.set_depth(png::BitDepth::Eight);
    enc.set_filter(png::Filter::NoFilter);
    let indexed = palette(rgb);
    let data = match &indexed {
        Some((colours, index)) => {
            enc.set_color(png::ColorType::Indexed);
            enc.set_palette(colours.clone());
            enc.set_deflate_compression(png::DeflateCompression::Level(PALETTE_LEVEL));
            index.as_slice()
        }
        None => {
            enc.set_color(png::ColorType::Rgb);
            enc.set_deflate_compression(png::DeflateCompression::Level(RGB_LEVEL));
            rgb
        }
    };
    let mut writer = enc.write_header()?;
    writer.write_image_data(data)?;
    writer.finish()?;
    Ok(out)
}

/// The pixels' colours in the order they first appear (flattened RGB) and
/// each pixel's index among them; None past 256 colours.
fn palette(rgb: &[u8]) -> Option<(Vec<u8>, Vec<u8>)> {
    let mut seen: HashMap<[u8; 3], u8> = HashMap::new();
    let mut colours = Vec::new();
    let mut index = Vec::with_capacity(rgb.len() / 3);
    let mut last: Option<([u8; 3], u8)> = None;
    for px in rgb.chunks_exact(3) {
        let c = [px[0], px[1], px[2]];
        // Runs of one colour are most of a figure: skip the lookup.
        if let Some((lc, li)) = last
            && lc == c
        {
            index.push(li);
            continue;
        }
        let i = match seen.get(&c) {
            Some(&i) => i,
            None => {
                let i = u8::try_from(seen.len()).ok()?;
                seen.insert(c, i);
                colours.extend_from_slice(&c);
                i
            }
        };
        last = Some((c, i));
        index.push(i);
    }
    Some((colours, index))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Decode a PNG to 8-bit RGB with the png crate's own expansion of a
    /// palette.
    fn decoded(bytes: &[u8]) -> (png::ColorType, Vec<u8>) {
        let mut dec = png::Decoder::new(std::io::Cursor::new(bytes));
        dec.set_transformations(png::Transformations::EXPAND);
        let mut reader = dec.read_info().unwrap();
        let raw = reader.info().color_type;
        let mut buf = vec![0; reader.output_buffer_size().unwrap()];
        let frame = reader.next_frame(&mut buf).unwrap();
        buf.truncate(frame.buffer_size());
        (raw, buf)
    }

    /// Every pixel comes back, through a palette up to 256 colours and as
    /// RGB past them.
    #[test]
    fn the_pixels_come_back_with_or_without_a_palette() {
        let (w, h) = (31u32, 17u32);
        let image = |colours: u32| -> Vec<u8> {
            (0..w * h)
                .flat_map(|i| {
                    let c = (i * 7919) % colours;
                    [(c % 256) as u8, (c / 256) as u8, 200]
                })
                .collect()
        };
        for (colours, kind) in [
            (1, png::ColorType::Indexed),
            (256, png::ColorType::Indexed),
            (257, png::ColorType::Rgb),
        ] {
            let rgb = image(colours);
            let (raw, back) = decoded(&rgb_png(&rgb, (w, h)).unwrap());
            assert_eq!(raw, kind, "{colours} colours");
            assert_eq!(back, rgb, "{colours} colours");
        }
    }
}
