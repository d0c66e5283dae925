//! Diff heat maps: a per-pixel absolute error, magnified by a stated factor and coloured
//! with turbo, above a colour bar labelled with the error its ends stand for.

use crate::core::frame::Frame;
use crate::io::font::text_width;
use crate::io::output::turbo;

/// Height of the colour bar band below the image, in pixels.
pub const BAR_HEIGHT: u32 = 32;

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
/// left (0) to right (1), and under it the labels `[left, centre, right]`: the centre one
/// between the ends, at the font's single size if its double does not fit there. Returns
/// false when a label did not fit the width and was left out.
pub fn append_colour_bar(color: &mut Vec<[f32; 3]>, w: usize, h: usize, labels: [&str; 3]) -> bool {
    color.resize(w * (h + BAR_HEIGHT as usize), [0.0; 3]);
    let bar = |y: usize, x: usize| (h + y) * w + x;
    for x in 0..w {
        let c = turbo(x as f32 / (w.max(2) - 1) as f32);
        for y in 3..11 {
            color[bar(y, x)] = c;
        }
    }
    // Font pixels twice the size where the labels fit so, else once.
    let fits = |scale: usize| {
        labels
            .iter()
            .map(|t| text_width(t, scale) + 2 * scale)
            .sum::<usize>()
            <= w
    };
    let scale = if fits(2) { 2 } else { 1 };
    let (lw, rw) = (text_width(labels[0], scale), text_width(labels[2], scale));
    let mut all = true;
    for (text, anchor) in labels
        .iter()
        .zip([Anchor::Left, Anchor::Centre, Anchor::Right])
    {
        let mut scale = scale;
        let x0 = match anchor {
            Anchor::Left | Anchor::Right if text_width(text, scale) > w => None,
            Anchor::Left => Some(0),
            Anchor::Right => Some(w - text_width(text, scale)),
            // Centred in the room the end labels leave, so as not to run into them.
            Anchor::Centre => {
                let room = w.saturating_sub(lw + rw + 4 * scale);
                if text_width(text, scale) > room {
                    scale = 1;
                }
                let text_w = text_width(text, scale);
                (text_w <= room).then(|| lw + 2 * scale + (room - text_w) / 2)
            }
        };
        match x0 {
            Some(x0) => crate::io::font::draw(color, w, (x0, h + 13), text, scale),
            None => all = false,
        }
    }
    all
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

/// A number for a label: plain decimals between 1e-3 and 1e5 (as `number`), else
/// scientific notation with three significant digits.
pub fn label_number(v: f64) -> String {
    if v == 0.0 || (1e-3..1e5).contains(&v.abs()) {
        number(v)
    } else {
        format!("{v:.2e}")
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
        // Labels are drawn in white below the bar: "0" at the left edge, "0.1" at the
        // right (its 1 a pixel short of the edge).
        let label_rows = (h as usize + 13)..(h as usize + BAR_HEIGHT as usize);
        assert!(label_rows
            .clone()
            .any(|y| map.color[y * w as usize] == [1.0; 3]));
        assert!(label_rows
            .clone()
            .any(|y| (1..4).any(|dx| map.color[y * w as usize + w as usize - 1 - dx] == [1.0; 3])));
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
