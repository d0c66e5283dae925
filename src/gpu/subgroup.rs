//! The subgroup size the device really runs, measured once per context
//! (`glsl/gpu/subgroup_probe.comp`), and what follows when the driver reports another.
//!
//! Every kernel is generic over the subgroup size, but it must be the size the lanes
//! really run at: the sort lays a block out as `subgroup * size + lane`, the scans stride
//! by it, and shared arrays are sized by the smallest size the device may pick. Mesa's
//! llvmpipe (22.3, LLVM 15) configured wider than 512 bits (`LP_NATIVE_VECTOR_WIDTH=1024`
//! or `2048`) reports 32 or 64 lanes in `subgroupSize`, `minSubgroupSize` and
//! `gl_SubgroupSize`, but runs compute shaders 16 lanes wide (its `LP_MAX_VECTOR_WIDTH` is
//! 512 bits): ballots hold 16 bits, `gl_NumSubgroups` is 8 for 128 invocations. Kernels
//! that trusted the reported size read and wrote the wrong elements (a black frame, a
//! wrong sort) or wrote past their shared arrays (the 2048-bit process died in `malloc`).
//!
//! The probe runs one 128-invocation workgroup and compares what each invocation is told
//! (`gl_SubgroupSize`) with the lanes that run together (a ballot of every lane and a
//! subgroup sum of ones). When they disagree consistently, the measured size is used:
//! [`DeviceInfo`](super::DeviceInfo)'s subgroup sizes become it and every pipeline gets it
//! as the `SUBGROUP_SIZE_SPEC` specialization constant, which `glsl/gpu/subgroup.glsl`'s
//! `SUBGROUP_SIZE` uses in place of `gl_SubgroupSize`. When the readings are inconsistent
//! in any other way the device is refused: no kernel could be trusted on it.

use super::buffer::GpuBuffer;
use super::shader::{BindingKind, ComputePipeline};
use super::sync::{barrier, Access};
use super::{GpuContext, GpuError, GpuResult};

/// Invocations of the probe's one workgroup (the spec's guaranteed minimum of
/// `maxComputeWorkGroupInvocations`).
pub const PROBE_INVOCATIONS: u32 = 128;

/// What the probe read on the device.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct SubgroupProbe {
    /// Largest and smallest `gl_SubgroupSize` an invocation was told.
    pub told: (u32, u32),
    /// Largest and smallest number of lanes in a ballot of every active lane.
    pub ballot: (u32, u32),
    /// Largest and smallest subgroup sum of ones.
    pub summed: (u32, u32),
    /// One more than the largest `gl_SubgroupInvocationID`.
    pub lane_ids: u32,
    /// Largest `gl_NumSubgroups`.
    pub num_subgroups: u32,
    /// One more than the largest `gl_SubgroupID`.
    pub subgroup_ids: u32,
}

/// The verdict on a probe.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum SubgroupVerdict {
    /// The lanes that run agree with `gl_SubgroupSize` (which may vary between
    /// pipelines within the device's range on some GPUs).
    Consistent,
    /// The driver says `reported` lanes but `runs` lanes run together, consistently:
    /// kernels use `runs`.
    Misreported {
        /// `gl_SubgroupSize` as told.
        reported: u32,
        /// Lanes that really run together.
        runs: u32,
    },
}

impl SubgroupProbe {
    /// Judges the readings: consistent, misreported in a way the kernels can follow, or
    /// (`Err`, a sentence) broken.
    pub fn verdict(&self) -> Result<SubgroupVerdict, String> {
        let runs = self.ballot.0;
        let uniform = self.ballot.0 == self.ballot.1
            && self.summed == self.ballot
            && self.lane_ids == runs
            && self.told.0 == self.told.1;
        let layout_fits = runs.is_power_of_two()
            && runs <= PROBE_INVOCATIONS
            && self.num_subgroups == PROBE_INVOCATIONS / runs
            && self.subgroup_ids == self.num_subgroups;
        if !uniform || !layout_fits {
            return Err(format!(
                "its subgroups are inconsistent: gl_SubgroupSize {}..{}, a ballot of every \
                 lane counts {}..{}, a subgroup sum of ones {}..{}, lane ids up to {}, \
                 {} subgroups ({} ids) in {PROBE_INVOCATIONS} invocations",
                self.told.1,
                self.told.0,
                self.ballot.1,
                self.ballot.0,
                self.summed.1,
                self.summed.0,
                self.lane_ids,
                self.num_subgroups,
                self.subgroup_ids
            ));
        }
        if self.told.0 == runs {
            Ok(SubgroupVerdict::Consistent)
        } else {
            Ok(SubgroupVerdict::Misreported {
                reported: self.told.0,
                runs,
            })
        }
    }
}

/// Runs the probe on `ctx` (one dispatch; a few milliseconds).
pub fn probe(ctx: &GpuContext) -> GpuResult<SubgroupProbe> {
    use super::shader_set::bindings::subgroup_probe as slot;
    let pipeline = ComputePipeline::from_embedded(
        ctx,
        "subgroup_probe",
        &[],
        &[BindingKind::StorageBuffer],
        &crate::core::shader_interface::NO_PUSH_CONSTANTS,
    )?;
    debug_assert_eq!(slot::OUT, 0);
    let init = [0, u32::MAX, 0, u32::MAX, 0, u32::MAX, 0, 0, 0];
    let out = GpuBuffer::from_slice(ctx, "subgroup probe", &init)?;
    ctx.submit_and_wait("subgroup probe", |cmd| {
        pipeline.dispatch(ctx, cmd, &[out.whole()], &[], [1, 1, 1])?;
        barrier(ctx, cmd, Access::ComputeWrite, Access::TransferRead);
        Ok(())
    })?;
    let o: Vec<u32> = out.read(ctx, init.len())?;
    Ok(SubgroupProbe {
        told: (o[0], o[1]),
        ballot: (o[2], o[3]),
        summed: (o[4], o[5]),
        lane_ids: o[6],
        num_subgroups: o[7],
        subgroup_ids: o[8],
    })
}

/// The subgroup size kernels must use on a device with `probe`'s readings, or the
/// sentence that refuses it.
pub fn size_to_use(device: &str, probe: &SubgroupProbe) -> GpuResult<SubgroupVerdict> {
    probe.verdict().map_err(|why| {
        GpuError::Missing(format!(
            "{device} fails verisplat's subgroup self-check: {why}; no kernel can be trusted \
             on it (a driver bug: try another driver or, on llvmpipe, \
             LP_NATIVE_VECTOR_WIDTH of 512 or less)"
        ))
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn reading(told: u32, runs: u32) -> SubgroupProbe {
        SubgroupProbe {
            told: (told, told),
            ballot: (runs, runs),
            summed: (runs, runs),
            lane_ids: runs,
            num_subgroups: PROBE_INVOCATIONS / runs,
            subgroup_ids: PROBE_INVOCATIONS / runs,
        }
    }

    #[test]
    fn agreeing_readings_are_consistent() {
        for size in [4, 8, 16, 32, 64] {
            assert_eq!(
                reading(size, size).verdict(),
                Ok(SubgroupVerdict::Consistent)
            );
        }
    }

    #[test]
    fn llvmpipe_wider_than_512_bits_is_misreported_and_followed() {
        assert_eq!(
            reading(32, 16).verdict(),
            Ok(SubgroupVerdict::Misreported {
                reported: 32,
                runs: 16
            })
        );
        assert_eq!(
            reading(64, 16).verdict(),
            Ok(SubgroupVerdict::Misreported {
                reported: 64,
                runs: 16
            })
        );
    }

    #[test]
    fn inconsistent_readings_are_refused() {
        let mut r = reading(32, 32);
        r.summed = (31, 31);
        assert!(r.verdict().is_err());
        let mut r = reading(32, 32);
        r.num_subgroups = 8;
        assert!(r.verdict().is_err());
        let mut r = reading(32, 32);
        r.ballot = (32, 16);
        assert!(r.verdict().unwrap_err().contains("ballot"));
        assert!(reading(32, 24).verdict().is_err());
    }
}
