//! Diff heat maps: a per-pixel absolute error, magnified by a stated factor and coloured
//! with turbo, above a colour bar labelled with the error its ends stand for.

use crate::frame::Frame;
use crate::output::turbo;

/// Height of the colour bar band below the image, in pixels.
pub const BAR_HEIGHT: u32 = 24;

/// The largest absolute difference over the channels of each pixel of two `H x W x C`
/// sample slices.
pub fn per_pixel_max_abs(reference: &[f32], test: &[f32], channels: usize) -> Vec<f32> {
    reference
        .chunks(channels.max(1))
        .zip(test.chunks(channels.max(1)))
        .map(|(r, t)| {
            r.iter()
                .zip(t)
                .map(|(a, b)| (a - b).abs())
                .fold(0.0f32, f32::max)
        })
        .collect()
}

/// A heat map of `error` (one value per pixel of a `width x height` image): `error *
/// magnify` through turbo (0 dark blue, 1 and above dark red), with a colour bar of
/// [`BAR_HEIGHT`] rows below it whose left end is labelled 0, its right end
/// `1 / magnify` (the error that saturates), and its middle `x<magnify>`. The frame holds
/// the colours; its alpha and depth planes are empty.
pub fn heatmap(width: u32, height: u32, error: &[f32], magnify: f32) -> Frame {
    let (w, h) = (width as usize, height as usize);
    let mut color: Vec<[f32; 3]> = error
        .iter()
        .map(|&e| turbo(if e.is_nan() { 1.0 } else { e * magnify }))
        .collect();
    append_colour_bar(
        &mut color,
        w,
        h,
        [
            "0",
            &format!("x{}", number(magnify as f64)),
            &number(1.0 / magnify as f64),
        ],
    );
    Frame {
        width,
        height: height + BAR_HEIGHT,
        color,
        alpha: Vec::new(),
        depth: Vec::new(),
        feature_count: 0,
        features: Vec::new(),
    }
}

/// Appends [`BAR_HEIGHT`] rows below the `w x h` image `color`: the turbo colour map from
/// left (0) to right (1), and under it the labels `[left, centre, right]` (a label wider
/// than the image is left out).
pub fn append_colour_bar(color: &mut Vec<[f32; 3]>, w: usize, h: usize, labels: [&str; 3]) {
    color.resize(w * (h + BAR_HEIGHT as usize), [0.0; 3]);
    let bar = |y: usize, x: usize| (h + y) * w + x;
    for x in 0..w {
        let c = turbo(x as f32 / (w.max(2) - 1) as f32);
        for y in 3..11 {
            color[bar(y, x)] = c;
        }
    }
    let text_width = |text: &str| (text.chars().count() * (GLYPH_W + 1)).saturating_sub(1) * SCALE;
    let (lw, rw) = (text_width(labels[0]), text_width(labels[2]));
    for (text, anchor) in labels
        .iter()
        .zip([Anchor::Left, Anchor::Centre, Anchor::Right])
    {
        let text_w = text_width(text);
        if text_w > w {
            continue;
        }
        let x0 = match anchor {
            Anchor::Left => 0,
            Anchor::Centre => {
                let x = (w - text_w) / 2;
                // Only where it does not run into the end labels.
                if x < lw + SCALE * 2 || x + text_w + rw + SCALE * 2 > w {
                    continue;
                }
                x
            }
            Anchor::Right => w - text_w,
        };
        draw_text(color, w, x0, h + 13, text);
    }
}

enum Anchor {
    Left,
    Centre,
    Right,
}

/// A number in plain decimal notation with at most four decimals, trailing zeros dropped.
fn number(v: f64) -> String {
    let s = format!("{v:.4}");
    let s = s.trim_end_matches('0').trim_end_matches('.');
    if s.is_empty() || s == "-0" {
        "0".into()
    } else {
        s.to_string()
    }
}

/// A number for a label: plain decimals between 1e-3 and 1e5 (as [`number`]), else
/// scientific notation with three significant digits.
pub fn label_number(v: f64) -> String {
    if v == 0.0 || (1e-3..1e5).contains(&v.abs()) {
        number(v)
    } else {
        format!("{v:.2e}")
    }
}

const GLYPH_W: usize = 3;
const SCALE: usize = 2;

/// 3x5 pixel glyphs, one row per 3-bit number (most significant bit on the left).
fn glyph(c: char) -> [u8; 5] {
    match c {
        '0' => [7, 5, 5, 5, 7],
        '1' => [2, 6, 2, 2, 7],
        '2' => [7, 1, 7, 4, 7],
        '3' => [7, 1, 7, 1, 7],
        '4' => [5, 5, 7, 1, 1],
        '5' => [7, 4, 7, 1, 7],
        '6' => [7, 4, 7, 5, 7],
        '7' => [7, 1, 1, 1, 1],
        '8' => [7, 5, 7, 5, 7],
        '9' => [7, 5, 7, 1, 7],
        '.' => [0, 0, 0, 0, 2],
        '-' => [0, 0, 7, 0, 0],
        '+' => [0, 2, 7, 2, 0],
        '_' => [0, 0, 0, 0, 7],
        '/' => [1, 1, 2, 4, 4],
        '(' => [1, 2, 2, 2, 1],
        ')' => [4, 2, 2, 2, 4],
        ':' => [0, 2, 0, 2, 0],
        '%' => [5, 1, 2, 4, 5],
        'x' | 'X' => [0, 5, 2, 5, 0],
        c if c.is_ascii_alphabetic() => letter(c.to_ascii_lowercase()),
        _ => [0; 5],
    }
}

/// 3x5 letters (upper case drawn as lower case).
fn letter(c: char) -> [u8; 5] {
    match c {
        'a' => [2, 5, 7, 5, 5],
        'b' => [6, 5, 6, 5, 6],
        'c' => [3, 4, 4, 4, 3],
        'd' => [6, 5, 5, 5, 6],
        'e' => [7, 4, 6, 4, 7],
        'f' => [7, 4, 6, 4, 4],
        'g' => [3, 4, 5, 5, 3],
        'h' => [5, 5, 7, 5, 5],
        'i' => [7, 2, 2, 2, 7],
        'j' => [1, 1, 1, 5, 2],
        'k' => [5, 5, 6, 5, 5],
        'l' => [4, 4, 4, 4, 7],
        'm' => [5, 7, 7, 5, 5],
        'n' => [6, 5, 5, 5, 5],
        'o' => [2, 5, 5, 5, 2],
        'p' => [6, 5, 6, 4, 4],
        'q' => [2, 5, 5, 6, 3],
        'r' => [6, 5, 6, 5, 5],
        's' => [3, 4, 2, 1, 6],
        't' => [7, 2, 2, 2, 2],
        'u' => [5, 5, 5, 5, 7],
        'v' => [5, 5, 5, 5, 2],
        'w' => [5, 5, 7, 7, 5],
        'y' => [5, 5, 2, 2, 2],
        'z' => [7, 1, 2, 4, 7],
        _ => [0; 5],
    }
}

/// Draws `text` in white, its top-left corner at pixel `(x0, y0)`.
fn draw_text(color: &mut [[f32; 3]], width: usize, x0: usize, y0: usize, text: &str) {
    for (k, c) in text.chars().enumerate() {
        let rows = glyph(c);
        let gx = x0 + k * (GLYPH_W + 1) * SCALE;
        for (ry, bits) in rows.iter().enumerate() {
            for rx in 0..GLYPH_W {
                if bits & (4 >> rx) == 0 {
                    continue;
                }
                for dy in 0..SCALE {
                    for dx in 0..SCALE {
                        let (x, y) = (gx + rx * SCALE + dx, y0 + ry * SCALE + dy);
                        if let Some(p) = color.get_mut(y * width + x).filter(|_| x < width) {
                            *p = [1.0; 3];
                        }
                    }
                }
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn heatmap_maps_magnified_error_through_turbo_and_adds_a_labelled_bar() {
        let (w, h) = (64u32, 8u32);
        let mut err = vec![0.0f32; (w * h) as usize];
        err[1] = 0.05; // half of the saturating 0.1 at x10
        err[2] = 0.5; // saturated
        let map = heatmap(w, h, &err, 10.0);
        assert_eq!((map.width, map.height), (w, h + BAR_HEIGHT));
        assert_eq!(map.color[0], turbo(0.0));
        assert_eq!(map.color[1], turbo(0.5));
        assert_eq!(map.color[2], turbo(1.0));
        // The bar runs from turbo(0) on the left to turbo(1) on the right.
        let row = (h as usize + 5) * w as usize;
        assert_eq!(map.color[row], turbo(0.0));
        assert_eq!(map.color[row + w as usize - 1], turbo(1.0));
        // Labels are drawn in white below the bar: "0" at the left edge.
        let label_rows = (h as usize + 13)..(h as usize + 23);
        assert!(label_rows
            .clone()
            .any(|y| map.color[y * w as usize] == [1.0; 3]));
        assert!(label_rows
            .clone()
            .any(|y| map.color[y * w as usize + w as usize - 1] == [1.0; 3]));
        assert_eq!(number(0.1), "0.1");
        assert_eq!(number(10.0), "10");
        assert_eq!(number(1.0 / 3.0), "0.3333");
    }

    #[test]
    fn per_pixel_error_is_the_largest_channel_difference() {
        let a = [0.0, 0.5, 1.0, 0.2, 0.2, 0.2];
        let b = [0.1, 0.5, 0.7, 0.2, 0.2, 0.2];
        let e = per_pixel_max_abs(&a, &b, 3);
        assert!((e[0] - 0.3).abs() < 1e-6 && e[1] == 0.0);
    }
}
