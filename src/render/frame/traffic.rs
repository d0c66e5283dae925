//! The device memory each stage of a frame reads and writes ([`frame_traffic`]), counted
//! from the frame's counts and the records its shaders load and store: every element once
//! per dispatch that touches it (a pair's splat once per bin that lists it), caches not
//! modelled. A stage's bytes over its time is the bandwidth it reached at least; `bench`
//! reports both.

use crate::core::camera::Camera;
use crate::core::model::RenderOptions;
use crate::gpu::sort::{RadixSort, SORT_CONFIG_32};
use crate::gpu::{Scan, Traffic};
use crate::render::forward::order::DEPTH_BITS;
use crate::render::forward::types::{Counters, GpuGaussian, GpuGaussianCompact, Splat};
use crate::render::{bin_grid, tile_bits, FrameStats, GpuScene, Readback, Stage};
use std::mem::size_of;

/// Bytes of one `T`.
const fn bytes<T>() -> u64 {
    size_of::<T>() as u64
}

/// Per Gaussian, what preprocess writes besides its splat: the tile rectangle (2 words),
/// the depth key and index, the bin mask and tiles touched.
const PREPROCESS_WORDS: u64 = 6;

/// Per pixel, the blend's colour (RGBA32F) and depth (R32F) images.
const PIXEL_STATE: u64 = 16 + 4;

/// The traffic of each stage of a frame drawn with `stats` (the last frame's counts, as
/// [`crate::render::GpuRenderer::stats`] gives them) of `scene` seen by `cam` under
/// `opts`, read back as `readback`, its pixels' last contributors saved when `save_last`.
/// Stages without a model (the feature blend, the shader) are absent.
pub fn frame_traffic(
    scene: &GpuScene,
    cam: &Camera,
    opts: &RenderOptions,
    stats: &FrameStats,
    readback: Readback,
    save_last: bool,
) -> Vec<(Stage, Traffic)> {
    let n = u64::from(scene.count);
    let keyed = u64::from(stats.visible);
    let pairs = stats.pairs;
    let pixels = u64::from(cam.width) * u64::from(cam.height);
    let (bx, by) = bin_grid(stats.bin_size.max(1), cam.width, cam.height);
    let bins = u64::from(bx) * u64::from(by);
    let chunks = u64::from(stats.chunks.max(1));
    let record = if scene.compact {
        bytes::<GpuGaussianCompact>()
    } else {
        bytes::<GpuGaussian>()
    };
    // The texels the active degree's coefficients span (3 floats each, 4 to a texel).
    let degree = opts.active_sh_degree(scene.sh_degree);
    let sh = u64::from((3 * (degree + 1) * (degree + 1)).div_ceil(4)) * 16;
    let preprocess = Traffic::new(
        n * record + keyed * sh,
        n * (bytes::<Splat>() + PREPROCESS_WORDS * 4) + bytes::<Counters>(),
    );
    let count = u32::try_from(n).unwrap_or(u32::MAX);
    let order = RadixSort::traffic(&SORT_CONFIG_32, count, count, DEPTH_BITS)
        // The gather: the depth order and tiles touched read, tiles touched written.
        + Traffic::new(n * 8, n * 4);
    let scan = Scan::traffic(count);
    // Every Gaussian's depth order and rectangle; a keyed one's mean, conic and bound (two
    // texels), bin mask and two offsets; each pair written.
    let keys = Traffic::new(n * 12 + keyed * (32 + 4 + 8), pairs * 8);
    let sort_pairs = u32::try_from(pairs).unwrap_or(u32::MAX);
    let capacity = stats.key_capacity.max(sort_pairs);
    let bits = tile_bits(bx * by);
    // Each chunk sorts its own pairs with digit tables laid out for the capacity.
    let sort = RadixSort::traffic(&SORT_CONFIG_32, sort_pairs, capacity, bits)
        + RadixSort::traffic(&SORT_CONFIG_32, 1, capacity, bits).times(chunks - 1);
    // The sorted keys read; every bin's range written.
    let ranges = Traffic::new(pairs * 4, bins * 8 * chunks);
    // A bin's range, each pair's index and splat; the pixels' state loaded by each chunk
    // after the first and written by every chunk.
    let blend = Traffic::new(
        bins * 8 * chunks + pairs * (4 + bytes::<Splat>()) + (chunks - 1) * pixels * PIXEL_STATE,
        chunks * pixels * PIXEL_STATE + if save_last { pixels * 8 } else { 0 },
    );
    let counters = bytes::<Counters>();
    let copied = match readback {
        // The images. A feature frame's planes and an Intermediates readback's buffers
        // are read after the frame, through staging copies of their own, outside the
        // stage.
        Readback::Float | Readback::Intermediates => copy(pixels * PIXEL_STATE),
        // The pack reads the colour image and writes 4 bytes a pixel, which are copied.
        Readback::Rgba8 => Traffic::new(pixels * 16, pixels * 4) + copy(pixels * 4),
        Readback::Counters => Traffic::default(),
    };
    let readback = copied + copy(counters);
    vec![
        (Stage::Preprocess, preprocess),
        (Stage::Order, order),
        (Stage::Scan, scan),
        (Stage::Keys, keys),
        (Stage::Sort, sort),
        (Stage::Ranges, ranges),
        (Stage::Blend, blend),
        (Stage::Readback, readback),
    ]
}

/// A copy of `bytes` bytes: read once, written once.
fn copy(bytes: u64) -> Traffic {
    Traffic::new(bytes, bytes)
}
