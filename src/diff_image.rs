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
    color.resize(w * (h + BAR_HEIGHT as usize), [0.0; 3]);
    let bar = |y: usize, x: usize| (h + y) * w + x;
    for x in 0..w {
        let c = turbo(x as f32 / (w.max(2) - 1) as f32);
        for y in 3..11 {
            color[bar(y, x)] = c;
        }
    }
    let mut label = |text: &str, anchor: Anchor| {
        let text_w = (text.len() * (GLYPH_W + 1) - 1) * SCALE;
        if text_w > w {
            return;
        }
        let x0 = match anchor {
            Anchor::Left => 0,
            Anchor::Centre => (w - text_w) / 2,
            Anchor::Right => w - text_w,
        };
        draw_text(&mut color, w, x0, h + 13, text);
    };
    label("0", Anchor::Left);
    label(&number(1.0 / magnify as f64), Anchor::Right);
    label(&format!("x{}", number(magnify as f64)), Anchor::Centre);
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
        'x' => [0, 5, 2, 5, 0],
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
