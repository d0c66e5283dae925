"""CPU stand-ins for the CUDA-only helpers that gsplat 1.5.3's torch reference
(`gsplat.rendering._rasterization` and `gsplat.cuda._torch_impl._rasterize_to_pixels`)
calls, written from gsplat's CUDA sources so that gsplat's own test_rasterization.py can
compare verisplat against gsplat's reference on a machine without CUDA:

- `isect_tiles` (IntersectTile.cu): each visible Gaussian's tiles, floor/ceil of
  (mean +- radius) / tile_size clamped to the grid; ids (image << (32 + tile_bits)) |
  (tile << 32) | depth's float bits, stably sorted.
- `isect_offset_encode`: gsplat's own torch version (`_isect_offset_encode`), pure torch.
- `spherical_harmonics` (SphericalHarmonicsCUDA.cu): gsplat's torch `_spherical_harmonics`
  with the kernel's mask (masked-out Gaussians get 0).
- `rasterize_to_indices_in_range` (RasterizeToIndices3DGS.cu): per pixel, the tile's
  Gaussians of batches [range_start, range_end) in depth order; a Gaussian is skipped when
  sigma < 0 or alpha = min(0.999, o exp(-sigma)) < 1/255, and the pixel stops (that
  Gaussian excluded) when T (1 - alpha) <= 1e-4, T starting at `transmittances`.
- `accumulate` (gsplat's torch version without nerfacc): per pixel, weights alpha_i
  prod_{j<i} (1 - alpha_j) over the given pairs in their order.

test_cpu_reference.py checks them against a brute-force per-pixel compositor.
"""

import math

import torch
from gsplat.cuda._torch_impl import _isect_offset_encode, _spherical_harmonics

ALPHA_THRESHOLD = 1.0 / 255.0


@torch.no_grad()
def isect_tiles(means2d, radii, depths, tile_size, tile_width, tile_height, sort=True,
                segmented=False, packed=False, n_images=None, image_ids=None,
                gaussian_ids=None):
    if packed:
        raise NotImplementedError("the CPU stand-in covers gsplat's unpacked reference only")
    image_dims = means2d.shape[:-2]
    n = means2d.shape[-2]
    images = math.prod(image_dims)
    means2d = means2d.reshape(images * n, 2)
    radii = radii.reshape(images * n, 2)
    depths = depths.reshape(images * n).float().contiguous()
    tile_mean = means2d / tile_size
    tile_radius = radii.to(means2d.dtype) / tile_size
    lo = torch.floor(tile_mean - tile_radius).clamp(min=0).long()
    hi = torch.ceil(tile_mean + tile_radius).clamp(min=0).long()
    limit = torch.tensor([tile_width, tile_height])
    lo, hi = torch.minimum(lo, limit), torch.minimum(hi, limit)
    visible = (radii > 0).all(dim=-1)
    tiles_per_gauss = ((hi - lo).prod(dim=-1) * visible).long()
    flat = torch.repeat_interleave(torch.arange(images * n), tiles_per_gauss)
    first = torch.cumsum(tiles_per_gauss, 0) - tiles_per_gauss
    rank = torch.arange(len(flat)) - first[flat]  # which of its tiles, row by row
    span_x = (hi - lo)[flat, 0]
    tx = lo[flat, 0] + rank % span_x.clamp(min=1)
    ty = lo[flat, 1] + rank // span_x.clamp(min=1)
    tile_bits = (tile_width * tile_height).bit_length()
    depth_bits = depths.view(torch.int32).long() & 0xFFFFFFFF
    image = flat // n
    isect_ids = (image << (32 + tile_bits)) | ((ty * tile_width + tx) << 32) | depth_bits[flat]
    flatten_ids = flat.int()
    if sort:
        isect_ids, order = torch.sort(isect_ids, stable=True)
        flatten_ids = flatten_ids[order]
    return tiles_per_gauss.reshape(image_dims + (n,)).int(), isect_ids, flatten_ids


def isect_offset_encode(isect_ids, n_images, tile_width, tile_height):
    return _isect_offset_encode(isect_ids, n_images, tile_width, tile_height)


def spherical_harmonics(degrees_to_use, dirs, coeffs, masks=None):
    colors = _spherical_harmonics(degrees_to_use, dirs, coeffs)
    if masks is not None:
        colors = torch.where(masks[..., None], colors, torch.zeros_like(colors))
    return colors


@torch.no_grad()
def rasterize_to_indices_in_range(range_start, range_end, transmittances, means2d, conics,
                                  opacities, image_width, image_height, tile_size,
                                  isect_offsets, flatten_ids):
    """All tiles at once: step by step, the next `step` Gaussians of each tile's list for
    its 16x16 pixels, until every pixel has stopped or its list's range is used up."""
    n = means2d.shape[-2]
    images = math.prod(means2d.shape[:-2])
    tile_height, tile_width = isect_offsets.shape[-2:]
    n_isects = len(flatten_ids)
    means2d = means2d.reshape(images * n, 2)
    conics = conics.reshape(images * n, 3)
    opacities = opacities.reshape(images * n)
    trans = transmittances.reshape(images * image_height * image_width)
    starts = isect_offsets.reshape(-1).long()
    ends = torch.cat([starts[1:], torch.tensor([n_isects])])
    block = tile_size * tile_size
    n_batches = (ends - starts + block - 1) // block
    pos = starts + block * range_start
    stop_at = torch.minimum(ends, starts + block * range_end)
    tile = torch.arange(len(starts))
    image, rest = tile // (tile_width * tile_height), tile % (tile_width * tile_height)
    ly, lx = torch.meshgrid(torch.arange(tile_size), torch.arange(tile_size), indexing="ij")
    i = (rest // tile_width)[:, None] * tile_size + ly.flatten()  # [tiles, block]
    j = (rest % tile_width)[:, None] * tile_size + lx.flatten()
    inside = (i < image_height) & (j < image_width)
    pixel = image[:, None] * image_height * image_width + i * image_width + j
    pixel = torch.where(inside, pixel, 0)
    px = torch.stack([j, i], -1).to(means2d.dtype) + 0.5
    t_now = torch.where(inside, trans[pixel], 0)
    done = ~inside | (range_start >= n_batches)[:, None]
    out_pixel, out_key, out_gauss = [], [], []
    step = 16
    while True:
        live = ((pos < stop_at) & ~done.all(1)).nonzero(as_tuple=True)[0]
        if len(live) == 0:
            break
        step = max(16, min(step, (1 << 23) // (len(live) * block)))
        at = pos[live, None] + torch.arange(step)  # [A, S] positions in the sorted list
        in_range = at < stop_at[live, None]
        ids = flatten_ids[at.clamp(max=n_isects - 1)].long()
        d = means2d[ids][:, None] - px[live][:, :, None]  # [A, P, S, 2]
        q = conics[ids][:, None]
        sigma = 0.5 * (q[..., 0] * d[..., 0] ** 2 + q[..., 2] * d[..., 1] ** 2) \
            + q[..., 1] * d[..., 0] * d[..., 1]
        alpha = torch.clamp_max(opacities[ids][:, None] * torch.exp(-sigma), 0.999)
        valid = (in_range[:, None] & (sigma >= 0) & (alpha >= ALPHA_THRESHOLD)
                 & ~done[live][..., None])
        factor = torch.where(valid, 1.0 - alpha, 1.0)
        # T after each Gaussian, multiplied in the kernel's order.
        t_after = torch.cumprod(torch.cat([t_now[live][..., None], factor], -1), -1)[..., 1:]
        stopped = torch.cumsum((valid & (t_after <= 1e-4)).int(), -1) > 0
        keep = valid & ~stopped
        a, p, k = keep.nonzero(as_tuple=True)
        out_gauss.append(ids[a, k] % n)
        out_pixel.append(pixel[live[a], p])
        out_key.append(at[a, k])
        t_now[live] = torch.where(keep, factor, 1.0).prod(-1) * t_now[live]
        done[live] |= stopped[..., -1]
        pos[live] += step
        step *= 2
    if not out_gauss:
        empty = torch.zeros(0, dtype=torch.long)
        return empty, empty, empty
    gauss, pixel, key = torch.cat(out_gauss), torch.cat(out_pixel), torch.cat(out_key)
    # Pixel by pixel (as the kernel's outputs), each pixel's Gaussians in list order.
    order = torch.argsort(pixel * (n_isects + 1) + key)
    gauss, pixel = gauss[order], pixel[order]
    return gauss, pixel % (image_width * image_height), pixel // (image_width * image_height)


def accumulate(means2d, conics, opacities, colors, gaussian_ids, pixel_ids, image_ids,
               image_width, image_height):
    image_dims = means2d.shape[:-2]
    images = math.prod(image_dims)
    n = means2d.shape[-2]
    channels = colors.shape[-1]
    means2d = means2d.reshape(images, n, 2)
    conics = conics.reshape(images, n, 3)
    opacities = opacities.reshape(images, n)
    colors = colors.reshape(images, n, channels)
    pixel = torch.stack([pixel_ids % image_width, pixel_ids // image_width], -1) + 0.5
    d = pixel - means2d[image_ids, gaussian_ids]
    c = conics[image_ids, gaussian_ids]
    sigma = 0.5 * (c[:, 0] * d[:, 0] ** 2 + c[:, 2] * d[:, 1] ** 2) + c[:, 1] * d[:, 0] * d[:, 1]
    alphas = torch.clamp_max(opacities[image_ids, gaussian_ids] * torch.exp(-sigma), 0.999)
    rays = image_ids * image_height * image_width + pixel_ids
    total = images * image_height * image_width
    # Exclusive product of (1 - alpha) within each ray (the pairs come ray by ray).
    log_keep = torch.log1p(-alphas.double())  # float64: the sums run over all the pairs
    inclusive = torch.cumsum(log_keep, 0)
    ray_start = torch.ones_like(rays, dtype=torch.bool)
    ray_start[1:] = rays[1:] != rays[:-1]
    start_index = torch.cummax(torch.where(ray_start, torch.arange(len(rays)), 0), 0).values
    before_ray = (inclusive - log_keep)[start_index]
    weights = alphas * torch.exp(inclusive - log_keep - before_ray).to(alphas.dtype)
    renders = torch.zeros(total, channels, dtype=colors.dtype).index_add_(
        0, rays, weights[:, None] * colors[image_ids, gaussian_ids])
    acc = torch.zeros(total, 1, dtype=weights.dtype).index_add_(0, rays, weights[:, None])
    return (renders.reshape(image_dims + (image_height, image_width, channels)),
            acc.reshape(image_dims + (image_height, image_width, 1)))
