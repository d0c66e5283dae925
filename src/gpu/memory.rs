//! Which memory type each kind of buffer asks for, and what the host must do around a
//! mapping of it: decided here, once, for every buffer and image.
//!
//! - Device buffers prefer device-local memory that is not host-visible (a discrete GPU's
//!   VRAM). They are never mapped where the device's local memory is not host-visible
//!   (or [`Emulation::device_local_not_host_visible`] says so): the host reaches them
//!   through staging buffers ([`super::GpuBuffer::upload`], [`super::GpuBuffer::read`]).
//! - Upload (staging) buffers prefer host-visible, coherent system memory (not the small
//!   device-local BAR heap of a discrete GPU).
//! - Read-back buffers prefer host-cached memory, coherent or not: uncached memory is
//!   write-combined and reads from it are slow. gpu-allocator's `GpuToCpu` insists on
//!   HOST_COHERENT and so picks uncached memory on devices whose cached memory is not
//!   coherent (many mobile and integrated GPUs); this chooser does not.
//!
//! Memory that is not HOST_COHERENT (or all host-visible memory under
//! [`Emulation::non_coherent`]) is flushed after host writes and invalidated before host
//! reads, in ranges rounded out to `nonCoherentAtomSize` ([`atom_range`]). Such buffers
//! are allocated at an offset and with a size that are multiples of the atom, so a
//! rounded range never reaches into a neighbouring sub-allocation (an invalidate there
//! could discard that buffer's unflushed writes).

use ash::vk;

use super::emulate::Emulation;
use super::{DeviceInfo, GpuError, GpuResult, MemoryKind};

type Flags = vk::MemoryPropertyFlags;

/// What a buffer's memory is and how the host may touch it.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct MemoryPlan {
    /// The memory type chosen.
    pub type_index: u32,
    /// Its property flags, as the driver reports them.
    pub flags: vk::MemoryPropertyFlags,
    /// The host may map it: host-visible memory, and not a device buffer on a device
    /// (real or emulated) whose device-local memory is not host-visible.
    pub mappable: bool,
    /// Host writes must be flushed and GPU writes invalidated before host reads (the
    /// memory is not HOST_COHERENT, or [`Emulation::non_coherent`]).
    pub explicit_sync: bool,
    /// The unit of flushes and invalidates, and the allocation's alignment and size
    /// granularity (`nonCoherentAtomSize` with `explicit_sync`, else 1).
    pub atom: u64,
}

/// The property sets `kind` asks for, best first: the first (required, excluded) pair
/// that a permitted memory type satisfies chooses it.
fn preferences(kind: MemoryKind) -> &'static [(Flags, Flags)] {
    const DL: Flags = Flags::DEVICE_LOCAL;
    const HV: Flags = Flags::HOST_VISIBLE;
    const HC: Flags = Flags::HOST_COHERENT;
    const CACHED: Flags = Flags::HOST_CACHED;
    const NONE: Flags = Flags::empty();
    const fn all(f: &[Flags]) -> Flags {
        let mut raw = 0;
        let mut i = 0;
        while i < f.len() {
            raw |= f[i].as_raw();
            i += 1;
        }
        Flags::from_raw(raw)
    }
    match kind {
        MemoryKind::Device => &[(DL, HV), (DL, NONE), (NONE, NONE)],
        MemoryKind::Upload => &[
            (const { all(&[HV, HC]) }, DL),
            (const { all(&[HV, HC]) }, NONE),
            (HV, DL),
            (HV, NONE),
        ],
        MemoryKind::Readback => &[
            (const { all(&[HV, CACHED, HC]) }, DL),
            (const { all(&[HV, CACHED, HC]) }, NONE),
            (const { all(&[HV, CACHED]) }, NONE),
            (const { all(&[HV, HC]) }, NONE),
            (HV, NONE),
        ],
    }
}

/// Chooses the memory for a buffer of `kind` among `types` (property flags by index)
/// permitted by `type_bits` (VkMemoryRequirements::memoryTypeBits); None when none fits
/// (a host-visible kind with no host-visible type permitted).
pub fn choose(
    kind: MemoryKind,
    types: &[vk::MemoryPropertyFlags],
    type_bits: u32,
    atom_size: u64,
    emulation: &Emulation,
) -> Option<MemoryPlan> {
    let permitted = |i: usize| i < 32 && type_bits & (1 << i) != 0;
    let (type_index, flags) = preferences(kind).iter().find_map(|&(required, excluded)| {
        types
            .iter()
            .enumerate()
            .find(|&(i, f)| permitted(i) && f.contains(required) && !f.intersects(excluded))
            .map(|(i, &f)| (i as u32, f))
    })?;
    let host_visible = flags.contains(Flags::HOST_VISIBLE);
    let mappable =
        host_visible && !(kind == MemoryKind::Device && emulation.device_local_not_host_visible);
    let explicit_sync =
        mappable && (!flags.contains(Flags::HOST_COHERENT) || emulation.non_coherent);
    Some(MemoryPlan {
        type_index,
        flags,
        mappable,
        explicit_sync,
        atom: if explicit_sync { atom_size.max(1) } else { 1 },
    })
}

/// [`choose`] for a device, with its memory types, atom size and emulation; an error
/// naming the buffer when no memory type fits.
pub fn plan(
    info: &DeviceInfo,
    kind: MemoryKind,
    type_bits: u32,
    name: &str,
) -> GpuResult<MemoryPlan> {
    choose(
        kind,
        &info.memory_types,
        type_bits,
        info.non_coherent_atom_size,
        &info.emulation,
    )
    .ok_or_else(|| {
        GpuError::Missing(format!(
            "no memory type of {} suits buffer '{name}' ({kind:?}: permitted types {type_bits:#b}, \
             types {:?})",
            info.name, info.memory_types
        ))
    })
}

impl MemoryPlan {
    /// The requirements to allocate with: only the chosen type, and for memory flushed
    /// and invalidated by hand, offset and size in whole atoms.
    pub fn requirements(&self, mut r: vk::MemoryRequirements) -> vk::MemoryRequirements {
        r.memory_type_bits = 1 << self.type_index;
        r.alignment = r.alignment.max(self.atom);
        r.size = r.size.div_ceil(self.atom) * self.atom;
        r
    }
}

/// The `VkMappedMemoryRange` (offset and size in the memory object) that covers bytes
/// `start..start + len` of an allocation at `alloc_offset` of `alloc_size` bytes in that
/// object, rounded out to whole `atom`s and clamped to the allocation's end. With an
/// allocation aligned and sized to the atom ([`MemoryPlan::requirements`]) both ends are
/// multiples of the atom, as vkFlushMappedMemoryRanges and vkInvalidateMappedMemoryRanges
/// require, and the range never leaves the allocation.
pub fn atom_range(
    alloc_offset: u64,
    alloc_size: u64,
    start: u64,
    len: u64,
    atom: u64,
) -> (u64, u64) {
    let atom = atom.max(1);
    let alloc_end = alloc_offset + alloc_size;
    let begin = (alloc_offset + start).min(alloc_end);
    let end = begin.saturating_add(len).min(alloc_end);
    let lo = (begin / atom * atom).max(alloc_offset);
    let hi = (end.div_ceil(atom) * atom).min(alloc_end);
    (lo, hi - lo)
}

#[cfg(test)]
mod tests {
    use super::*;

    const DL: Flags = Flags::DEVICE_LOCAL;
    const HV: Flags = Flags::HOST_VISIBLE;
    const HC: Flags = Flags::HOST_COHERENT;
    const CACHED: Flags = Flags::HOST_CACHED;

    fn pick(kind: MemoryKind, types: &[Flags], e: &Emulation) -> MemoryPlan {
        choose(kind, types, u32::MAX, 64, e).expect("a type fits")
    }

    #[test]
    fn lavapipe_has_one_type_for_everything() {
        let types = [DL | HV | HC | CACHED];
        let plain = Emulation::default();
        for kind in [MemoryKind::Device, MemoryKind::Upload, MemoryKind::Readback] {
            let p = pick(kind, &types, &plain);
            assert_eq!(p.type_index, 0);
            assert!(
                p.mappable && !p.explicit_sync && p.atom == 1,
                "{kind:?}: {p:?}"
            );
        }
        // Emulated discrete: device buffers are not mappable, host buffers are flushed
        // and invalidated in 64-byte atoms.
        let discrete = Emulation::parse("discrete").unwrap();
        let d = pick(MemoryKind::Device, &types, &discrete);
        assert!(!d.mappable && !d.explicit_sync);
        for kind in [MemoryKind::Upload, MemoryKind::Readback] {
            let p = pick(kind, &types, &discrete);
            assert!(
                p.mappable && p.explicit_sync && p.atom == 64,
                "{kind:?}: {p:?}"
            );
        }
    }

    #[test]
    fn a_discrete_gpu_keeps_staging_out_of_vram_and_reads_back_from_cached_memory() {
        // An NVIDIA-like table: VRAM, system memory (uncached and cached), the BAR.
        let types = [DL, HV | HC, HV | HC | CACHED, DL | HV | HC];
        let e = Emulation::default();
        assert_eq!(pick(MemoryKind::Device, &types, &e).type_index, 0);
        assert!(!pick(MemoryKind::Device, &types, &e).mappable);
        assert_eq!(pick(MemoryKind::Upload, &types, &e).type_index, 1);
        assert_eq!(pick(MemoryKind::Readback, &types, &e).type_index, 2);
        // A buffer that may only live in the BAR still gets it.
        let only_bar = choose(MemoryKind::Upload, &types, 1 << 3, 64, &e).unwrap();
        assert_eq!(only_bar.type_index, 3);
        // No host-visible type permitted: no plan for a staging buffer.
        assert!(choose(MemoryKind::Readback, &types, 1, 64, &e).is_none());
    }

    #[test]
    fn cached_memory_that_is_not_coherent_is_chosen_for_read_back_and_synced_by_hand() {
        // A mobile-like table: coherent memory is uncached, cached memory is not coherent.
        let types = [DL | HV | HC, DL | HV | CACHED];
        let e = Emulation::default();
        let r = pick(MemoryKind::Readback, &types, &e);
        assert_eq!(r.type_index, 1);
        assert!(r.mappable && r.explicit_sync && r.atom == 64);
        let u = pick(MemoryKind::Upload, &types, &e);
        assert_eq!(u.type_index, 0);
        assert!(!u.explicit_sync);
        // Device buffers on a unified-memory device are host-visible (and so mappable).
        assert!(pick(MemoryKind::Device, &types, &e).mappable);
    }

    #[test]
    fn requirements_round_to_whole_atoms() {
        let p = MemoryPlan {
            type_index: 3,
            flags: HV,
            mappable: true,
            explicit_sync: true,
            atom: 64,
        };
        let r = p.requirements(vk::MemoryRequirements {
            size: 100,
            alignment: 16,
            memory_type_bits: 0b1111,
        });
        assert_eq!((r.size, r.alignment, r.memory_type_bits), (128, 64, 0b1000));
        let big = p.requirements(vk::MemoryRequirements {
            size: 256,
            alignment: 256,
            memory_type_bits: 0b1000,
        });
        assert_eq!((big.size, big.alignment), (256, 256));
    }

    #[test]
    fn ranges_round_out_to_atoms_inside_the_allocation() {
        // An allocation of 256 bytes at 1024 in its memory object.
        assert_eq!(atom_range(1024, 256, 0, 256, 64), (1024, 256));
        assert_eq!(atom_range(1024, 256, 5, 7, 64), (1024, 64));
        assert_eq!(atom_range(1024, 256, 60, 8, 64), (1024, 128));
        assert_eq!(atom_range(1024, 256, 200, 56, 64), (1216, 64));
        // Past the end: clamped to it.
        assert_eq!(atom_range(1024, 256, 250, 100, 64), (1216, 64));
        // Coherent memory (atom 1): exactly the bytes.
        assert_eq!(atom_range(1000, 100, 3, 5, 1), (1003, 5));
        for start in 0..256 {
            for len in [1, 3, 64, 65, 200] {
                let (o, s) = atom_range(1024, 256, start, len, 64);
                assert!(o % 64 == 0 && s % 64 == 0 && o >= 1024 && o + s <= 1280);
                assert!(o <= 1024 + start && o + s >= (1024 + start + len).min(1280));
            }
        }
    }
}
