//! The loss's target, staged by the host or kept on the device: the training photos stay
//! on the device ([`GpuLoss::keep_photos`], [`GpuLoss::stage_photo`]) when they fit, each
//! uploaded once as the loss reads it, and each loss submission copies its target from
//! where it is ([`GpuLoss::record_target_copy`]).

use super::GpuLoss;
use crate::gpu::sync::{barrier, Access};
use crate::gpu::{GpuBuffer, GpuContext, GpuResult};

/// The target a loss submission copies to the device: staged by the host (and, for a photo
/// kept on the device the first time, copied into its place too), or a kept photo.
#[derive(Clone, Copy)]
pub(super) enum PendingTarget {
    Staged { bytes: u64, keep_at: Option<u64> },
    Kept { offset: u64, bytes: u64 },
}

/// The training photos on the device ([`GpuLoss::keep_photos`]): one buffer, a slot each.
pub(super) struct PhotoStore {
    buffer: GpuBuffer,
    slots: Vec<PhotoSlot>,
}

/// One photo's place in the store, and its kept pixels once it has been staged there.
pub(super) struct PhotoSlot {
    offset: u64,
    bytes: u64,
    kept: Option<u64>,
}

impl GpuLoss {
    /// Keeps the training photos on the device, `pixels[i]` for photo `i`, when together
    /// they take at most `max_bytes` (as the loss reads them: a vec4 per pixel, the mask
    /// in `w`, so the targets are the same bits): each is staged once, the first time it is
    /// the target ([`Self::stage_photo`]), and copied on the device from then on, so an
    /// iteration's host writes no pixel. Returns whether they are kept; otherwise every
    /// photo is staged each time, as [`Self::stage_target_masked`] does.
    pub fn keep_photos(
        &mut self,
        ctx: &GpuContext,
        pixels: &[u64],
        max_bytes: u64,
    ) -> GpuResult<bool> {
        self.photos = None;
        let total: u64 = pixels.iter().map(|p| p * 16).sum();
        if pixels.is_empty() || total > max_bytes {
            return Ok(false);
        }
        let mut offset = 0;
        let slots = pixels
            .iter()
            .map(|p| {
                let slot = PhotoSlot {
                    offset,
                    bytes: p * 16,
                    kept: None,
                };
                offset += p * 16;
                slot
            })
            .collect();
        let buffer = GpuBuffer::new(
            ctx,
            "training photos",
            total.max(16),
            crate::gpu::MemoryKind::Device,
        )?;
        self.photos = Some(PhotoStore { buffer, slots });
        Ok(true)
    }

    /// [`Self::stage_target_masked`] of training photo `index`: from the photos kept on the
    /// device when it was staged before ([`Self::keep_photos`]), else staged (and, when
    /// the photos are kept, copied into its place too).
    pub fn stage_photo(
        &mut self,
        ctx: &GpuContext,
        index: usize,
        target: &[[f32; 3]],
        keep: Option<&[bool]>,
    ) -> GpuResult<()> {
        let pixels = target.len() as u64;
        let slot = self
            .photos
            .as_ref()
            .and_then(|p| p.slots.get(index))
            .filter(|s| s.bytes == pixels * 16)
            .map(|s| (s.offset, s.bytes, s.kept));
        match slot {
            Some((offset, bytes, Some(kept))) => {
                self.ensure_io(ctx, pixels)?;
                self.target_pending = Some(PendingTarget::Kept { offset, bytes });
                self.target_kept = kept;
            }
            Some((offset, bytes, None)) => {
                self.stage_target_masked(ctx, target, keep)?;
                self.target_pending = Some(PendingTarget::Staged {
                    bytes,
                    keep_at: Some(offset),
                });
                let kept = self.target_kept;
                if let Some(p) = self.photos.as_mut() {
                    p.slots[index].kept = Some(kept);
                }
            }
            None => self.stage_target_masked(ctx, target, keep)?,
        }
        Ok(())
    }

    /// Records the copy of the staged target into the device's target buffer `tgt` (if
    /// one is pending); the caller's barrier makes it visible to the loss's passes.
    pub(super) fn record_target_copy(
        &mut self,
        ctx: &GpuContext,
        cmd: ash::vk::CommandBuffer,
        tgt: &GpuBuffer,
    ) {
        let Some(pending) = self.target_pending.take() else {
            return;
        };
        let copy = |src: &GpuBuffer, dst: &GpuBuffer, (from, to, bytes): (u64, u64, u64)| {
            let region = [ash::vk::BufferCopy::default()
                .src_offset(from)
                .dst_offset(to)
                .size(bytes)];
            // SAFETY: both buffers are alive and hold `bytes` from their offsets (the
            // photo store's slots and the staged target were sized together); the host's
            // writes to the staging buffer are visible to the device from the submission
            // on, and a copy out of the store follows the barrier recorded before it.
            unsafe {
                ctx.device()
                    .cmd_copy_buffer(cmd, src.handle(), dst.handle(), &region)
            };
        };
        match (pending, &self.target_staging, &self.photos) {
            (PendingTarget::Staged { bytes, keep_at }, Some(staging), photos) => {
                copy(staging, tgt, (0, 0, bytes));
                if let (Some(at), Some(p)) = (keep_at, photos) {
                    copy(staging, &p.buffer, (0, at, bytes));
                }
            }
            (PendingTarget::Kept { offset, bytes }, _, Some(p)) => {
                // The photo was copied into the store by an earlier submission.
                barrier(ctx, cmd, Access::TransferWrite, Access::TransferRead);
                copy(&p.buffer, tgt, (offset, 0, bytes));
            }
            _ => {}
        }
    }
}
