//! The split of a backward pass whose per-pair or per-pixel buffers exceed one storage
//! binding (maxStorageBufferRange), as the forward splits its frames: the forward draws a
//! frame, the backward takes it.
//!
//! - **Pair bands**: runs of the sorted pairs whose gradient records fit one binding. Each
//!   band has its own buffer; the blend backward writes a band's records there and the
//!   accumulation reads them with the band's slice of the sorted values.
//! - **Pixel bands**: runs of pixel rows whose per-pixel buffers (the pixels' gradients,
//!   the last contributors) fit one binding, bound at the band's offset.
//!
//! The blend backward runs once per (pixel band, pair band), each bin walked back to front
//! exactly as in one piece, so each pair's sums are the unsplit pass's bit for bit; the
//! fixed-point sums then make the Gaussians' gradients bit-identical too
//! (`glsl/render/backward/blend_bwd.comp`'s band).

use crate::gpu::{limits, BufferSlice, GpuResult};

/// Pixel rows of a pixel band are a multiple of this: a whole number of 8- and 16-pixel
/// bin rows, and with elements of at least 4 bytes a band's offset is a multiple of 256
/// bytes (the largest minStorageBufferOffsetAlignment the spec allows).
const BAND_ROW_ALIGN: u32 = 64;

/// Pairs of a pair band are a multiple of this: the band's slice of the sorted values (4
/// bytes each) starts at a multiple of 256 bytes.
const BAND_PAIR_ALIGN: u64 = 64;

/// How one backward pass is split.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) struct Bands {
    /// Sorted pairs of the frame.
    pairs: u64,
    /// Pairs per pair band (the last may hold fewer).
    pair_band: u64,
    /// Pixel rows of the frame.
    height: u32,
    /// Pixel rows per pixel band (the last may hold fewer).
    row_band: u32,
}

impl Bands {
    /// The split of a frame of `pairs` pairs of `pair_bytes` each and `size` pixels whose
    /// largest per-pixel element is `pixel_bytes`, on a device that binds `max` bytes
    /// ([`limits::storage_binding_bytes`]). A band of the smallest size that still does
    /// not fit is refused with the binding's [`crate::gpu::GpuError::DeviceLimit`], naming
    /// `pixel_what`.
    pub(crate) fn plan(
        max: u64,
        pairs: u64,
        pair_bytes: u64,
        (width, height): (u32, u32),
        (pixel_what, pixel_bytes): (&str, u64),
    ) -> GpuResult<Self> {
        let pair_band = if pairs * pair_bytes <= max {
            pairs.max(1)
        } else {
            let fit = max / pair_bytes.max(1) / BAND_PAIR_ALIGN * BAND_PAIR_ALIGN;
            limits::check_binding_bytes(
                max,
                "pair gradients",
                BAND_PAIR_ALIGN * pair_bytes,
                "no band of pairs fits",
            )?;
            fit
        };
        Ok(Bands {
            pairs,
            pair_band,
            height,
            row_band: rows_per_band(max, (width, height), (pixel_what, pixel_bytes))?,
        })
    }

    /// The pair bands, `[lo, hi)` each (one, empty, for a frame of no pairs).
    pub(crate) fn pair_bands(&self) -> Vec<(u64, u64)> {
        let n = self.pairs.div_ceil(self.pair_band).max(1);
        (0..n)
            .map(|j| {
                let lo = j * self.pair_band;
                (lo, (lo + self.pair_band).min(self.pairs))
            })
            .collect()
    }

    /// The pixel bands, `[y0, y1)` rows each.
    pub(crate) fn row_bands(&self) -> Vec<(u32, u32)> {
        row_runs(self.height, self.row_band)
    }

    /// Whether the per-pixel buffers are split.
    pub(crate) fn pixels_split(&self) -> bool {
        self.row_bands().len() > 1
    }
}

/// The pixel bands of a frame of `size` pixels whose per-pixel buffer (`what`) holds
/// `bytes` a pixel, on a device that binds `max` bytes: `[y0, y1)` rows each, one band
/// when the buffer fits one binding; refused when not even 64 rows do.
pub(crate) fn pixel_bands(
    max: u64,
    size: (u32, u32),
    (what, bytes): (&str, u64),
) -> GpuResult<Vec<(u32, u32)>> {
    Ok(row_runs(size.1, rows_per_band(max, size, (what, bytes))?))
}

/// Rows of a pixel band: the whole frame when it fits one binding, else as many multiples
/// of [`BAND_ROW_ALIGN`] as fit.
fn rows_per_band(
    max: u64,
    (width, height): (u32, u32),
    (what, bytes): (&str, u64),
) -> GpuResult<u32> {
    let row_bytes = u64::from(width) * bytes;
    if u64::from(height) * row_bytes <= max {
        return Ok(height.max(1));
    }
    limits::check_binding_bytes(
        max,
        &format!("{what} ({BAND_ROW_ALIGN} rows of {width} pixels)"),
        u64::from(BAND_ROW_ALIGN) * row_bytes,
        "use a narrower frame",
    )?;
    Ok((max / row_bytes.max(1)) as u32 / BAND_ROW_ALIGN * BAND_ROW_ALIGN)
}

/// `[y0, y1)` runs of `band` rows over `height` rows (one, possibly empty, at least).
fn row_runs(height: u32, band: u32) -> Vec<(u32, u32)> {
    let n = height.div_ceil(band).max(1);
    (0..n)
        .map(|b| {
            let y0 = b * band;
            (y0, (y0 + band).min(height))
        })
        .collect()
}

/// Rows `[y0, y1)` of a per-pixel buffer of `row_bytes` a row, as a band binds them (the
/// whole slice for an element of no bytes: a buffer the pass does not read).
pub(crate) fn band_rows(
    s: BufferSlice<'_>,
    (y0, y1): (u32, u32),
    row_bytes: u64,
) -> BufferSlice<'_> {
    if row_bytes == 0 {
        return s;
    }
    BufferSlice {
        offset: s.offset + u64::from(y0) * row_bytes,
        size: u64::from(y1 - y0) * row_bytes,
        ..s
    }
}

/// The rows `[first, end)` of `bin`-pixel bins (tiles) that cover pixel rows `[y0, y1)` of
/// a frame `height` rows tall with `bins_y` rows of bins (a band's rows are whole bin
/// rows but at the frame's foot).
pub(crate) fn bin_rows((y0, y1): (u32, u32), height: u32, bin: u32, bins_y: u32) -> (u32, u32) {
    (y0 / bin, if y1 >= height { bins_y } else { y1 / bin })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_frame_that_fits_is_one_band() {
        let b = Bands::plan(1 << 27, 1000, 48, (640, 480), ("x", 16)).unwrap();
        assert_eq!(b.pair_bands(), vec![(0, 1000)]);
        assert_eq!(b.row_bands(), vec![(0, 480)]);
        assert!(!b.pixels_split());
        let none = Bands::plan(1 << 27, 0, 48, (1, 1), ("x", 16)).unwrap();
        assert_eq!(none.pair_bands(), vec![(0, 0)]);
    }

    #[test]
    fn bands_cover_everything_once_at_aligned_starts() {
        // 1 MiB bindings: 21,845 pairs of 48 bytes fit, rounded down to 21,824.
        let b = Bands::plan(1 << 20, 50_000, 48, (1920, 1080), ("x", 4)).unwrap();
        assert_eq!(
            b.pair_bands(),
            vec![(0, 21_824), (21_824, 43_648), (43_648, 50_000)]
        );
        // 1920 pixels of 16 bytes a row: 34 rows fit, fewer than 64: refused.
        let e = Bands::plan(1 << 20, 10, 48, (1920, 1080), ("colour", 16)).unwrap_err();
        assert!(
            e.to_string()
                .contains("colour (64 rows of 1920 pixels) needs 1966080 bytes"),
            "{e}"
        );
        // 4 MiB: 136 rows fit, 128 taken.
        let b = Bands::plan(4 << 20, 10, 48, (1920, 1080), ("x", 16)).unwrap();
        let rows = b.row_bands();
        assert_eq!(rows.len(), 9);
        assert_eq!(rows[0], (0, 128));
        assert_eq!(rows[8], (1024, 1080));
        assert!(rows.windows(2).all(|w| w[0].1 == w[1].0));
        assert_eq!(pixel_bands(4 << 20, (1920, 1080), ("x", 16)).unwrap(), rows);
        // Bin rows of 8- and 16-pixel bins: whole rows, and the foot's partial one.
        assert_eq!(bin_rows((128, 256), 1080, 8, 135), (16, 32));
        assert_eq!(bin_rows((1024, 1080), 1080, 16, 68), (64, 68));
        assert!(b.pixels_split());
    }
}
