//! What a compiled compute module asks of the device's workgroup limits, read from its
//! SPIR-V with the specialization the host passes: invocations per workgroup and bytes of
//! shared (workgroup) memory. Every pipeline is checked against the device's
//! `maxComputeWorkGroupInvocations` and `maxComputeSharedMemorySize` before it is built
//! ([`check_limits`]), so a kernel chosen for a larger device is an error naming the
//! kernel and the limit, never a driver crash or a silently wrong frame. Under
//! `VERISPLAT_EMULATE=spec-limits` those limits are the specification's minimums (128
//! invocations, 16 KiB), and the tests run every stage there.

use std::collections::HashMap;

const OP_EXECUTION_MODE: u16 = 16;
const OP_TYPE_BOOL: u16 = 20;
const OP_TYPE_INT: u16 = 21;
const OP_TYPE_FLOAT: u16 = 22;
const OP_TYPE_VECTOR: u16 = 23;
const OP_TYPE_MATRIX: u16 = 24;
const OP_TYPE_ARRAY: u16 = 28;
const OP_TYPE_STRUCT: u16 = 30;
const OP_TYPE_POINTER: u16 = 32;
const OP_CONSTANT: u16 = 43;
const OP_CONSTANT_COMPOSITE: u16 = 44;
const OP_SPEC_CONSTANT: u16 = 50;
const OP_SPEC_CONSTANT_COMPOSITE: u16 = 51;
const OP_SPEC_CONSTANT_OP: u16 = 52;
const OP_VARIABLE: u16 = 59;
const OP_DECORATE: u16 = 71;
const OP_EXECUTION_MODE_ID: u16 = 331;

const DECORATION_SPEC_ID: u32 = 1;
const DECORATION_BUILT_IN: u32 = 11;
const BUILT_IN_WORKGROUP_SIZE: u32 = 25;
const MODE_LOCAL_SIZE: u32 = 17;
const MODE_LOCAL_SIZE_ID: u32 = 38;
const STORAGE_WORKGROUP: u32 = 4;

/// A module's workgroup demands.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct WorkgroupDemand {
    /// Workgroup size along x, y and z.
    pub size: [u32; 3],
    /// Invocations per workgroup (x * y * z).
    pub invocations: u32,
    /// Bytes of shared memory its variables take (vec3 counted as 16 bytes).
    pub shared_bytes: u32,
}

#[derive(Clone, Debug)]
enum Ty {
    Scalar(u32),
    Vector(u32, u32),
    Matrix(u32, u32),
    Array(u32, u32),
    Struct(Vec<u32>),
    /// Pointee type.
    Pointer(u32),
}

/// What a module declares that its workgroup demands are read from, with the host's
/// specialization applied, by result id.
#[derive(Default)]
pub(crate) struct Declarations {
    types: HashMap<u32, Ty>,
    /// Scalar constants, specialized and folded where they can be.
    values: HashMap<u32, u32>,
    composites: HashMap<u32, Vec<u32>>,
    spec_ids: HashMap<u32, u32>,
    workgroup_size_builtin: Option<u32>,
    local_size: Option<[u32; 3]>,
    local_size_ids: Option<[u32; 3]>,
    /// Pointer types of the shared (workgroup) variables.
    shared: Vec<u32>,
}

impl Declarations {
    /// Reads the module's execution modes, types, constants and shared variables.
    fn read(words: &[u32], overrides: &HashMap<u32, u32>) -> Result<Self, String> {
        let mut d = Declarations::default();
        for instruction in super::reflect::instructions(words) {
            let (op, w) = instruction?;
            d.visit(op, w, overrides);
        }
        Ok(d)
    }

    /// Takes in one instruction (`op`, operands `w`), specialized by `overrides`
    /// (specialization constant id to value).
    pub(crate) fn visit(&mut self, op: u16, w: &[u32], overrides: &HashMap<u32, u32>) {
        let arg = |k: usize| w.get(k).copied().unwrap_or(0);
        match op {
            OP_EXECUTION_MODE if arg(1) == MODE_LOCAL_SIZE => {
                self.local_size = Some([arg(2), arg(3), arg(4)]);
            }
            OP_EXECUTION_MODE_ID if arg(1) == MODE_LOCAL_SIZE_ID => {
                self.local_size_ids = Some([arg(2), arg(3), arg(4)]);
            }
            OP_DECORATE if arg(1) == DECORATION_SPEC_ID => {
                self.spec_ids.insert(arg(0), arg(2));
            }
            OP_DECORATE if arg(1) == DECORATION_BUILT_IN && arg(2) == BUILT_IN_WORKGROUP_SIZE => {
                self.workgroup_size_builtin = Some(arg(0));
            }
            OP_TYPE_BOOL => {
                self.types.insert(arg(0), Ty::Scalar(4));
            }
            OP_TYPE_INT | OP_TYPE_FLOAT => {
                self.types.insert(arg(0), Ty::Scalar(arg(1) / 8));
            }
            OP_TYPE_VECTOR => {
                self.types.insert(arg(0), Ty::Vector(arg(1), arg(2)));
            }
            OP_TYPE_MATRIX => {
                self.types.insert(arg(0), Ty::Matrix(arg(1), arg(2)));
            }
            OP_TYPE_ARRAY => {
                self.types.insert(arg(0), Ty::Array(arg(1), arg(2)));
            }
            OP_TYPE_STRUCT => {
                self.types.insert(arg(0), Ty::Struct(w[1..].to_vec()));
            }
            OP_TYPE_POINTER => {
                self.types.insert(arg(0), Ty::Pointer(arg(2)));
            }
            OP_CONSTANT => {
                self.values.insert(arg(1), arg(2));
            }
            OP_SPEC_CONSTANT => {
                let id = arg(1);
                let value = self
                    .spec_ids
                    .get(&id)
                    .and_then(|s| overrides.get(s))
                    .copied()
                    .unwrap_or(arg(2));
                self.values.insert(id, value);
            }
            OP_CONSTANT_COMPOSITE | OP_SPEC_CONSTANT_COMPOSITE => {
                self.composites.insert(arg(1), w[2..].to_vec());
            }
            OP_SPEC_CONSTANT_OP => {
                if let Some(v) = fold_spec_constant_op(&self.values, w) {
                    self.values.insert(arg(1), v);
                }
            }
            OP_VARIABLE if arg(2) == STORAGE_WORKGROUP => self.shared.push(arg(0)),
            _ => {}
        }
    }

    /// The workgroup size: the WorkgroupSize built-in's, else the LocalSizeId or the
    /// LocalSize execution mode's.
    fn workgroup_size(&self) -> Result<[u32; 3], String> {
        let value = |id: u32| {
            self.values
                .get(&id)
                .copied()
                .ok_or_else(|| format!("constant %{id} cannot be evaluated"))
        };
        Ok(if let Some(builtin) = self.workgroup_size_builtin {
            let parts = self
                .composites
                .get(&builtin)
                .ok_or("the WorkgroupSize built-in is not a constant composite")?;
            [value(parts[0])?, value(parts[1])?, value(parts[2])?]
        } else if let Some(ids) = self.local_size_ids {
            [value(ids[0])?, value(ids[1])?, value(ids[2])?]
        } else {
            self.local_size.ok_or("no LocalSize execution mode")?
        })
    }

    /// Bytes of type `t` in shared memory; `None` for what has no size here or nests
    /// deeper than 16.
    fn size(&self, t: u32, depth: u32) -> Option<u64> {
        if depth > 16 {
            return None;
        }
        Some(match self.types.get(&t)? {
            Ty::Scalar(bytes) => u64::from(*bytes),
            // A vec3 takes a vec4's slot in the layouts drivers use for shared memory.
            Ty::Vector(c, n) => {
                self.size(*c, depth + 1)? * u64::from((*n).max(2).next_power_of_two())
            }
            Ty::Matrix(c, n) => self.size(*c, depth + 1)? * u64::from(*n),
            Ty::Array(e, len) => self.size(*e, depth + 1)? * u64::from(*self.values.get(len)?),
            Ty::Struct(members) => {
                let mut total = 0;
                for &m in members {
                    total += self.size(m, depth + 1)?;
                }
                total
            }
            Ty::Pointer(_) => return None,
        })
    }

    /// Bytes of shared memory all the shared variables take.
    fn shared_bytes(&self) -> Result<u64, String> {
        let mut shared_bytes = 0u64;
        for &variable_type in &self.shared {
            let Some(Ty::Pointer(pointee)) = self.types.get(&variable_type) else {
                return Err(format!(
                    "shared variable of type %{variable_type} is no pointer"
                ));
            };
            shared_bytes += self
                .size(*pointee, 0)
                .ok_or_else(|| format!("the size of shared type %{pointee} cannot be evaluated"))?;
        }
        Ok(shared_bytes)
    }

    /// The workgroup demand the declarations make up.
    pub(crate) fn demand(&self) -> Result<WorkgroupDemand, String> {
        let size3 = self.workgroup_size()?;
        let invocations = size3
            .iter()
            .try_fold(1u32, |acc, &n| acc.checked_mul(n))
            .ok_or("the workgroup size overflows")?;
        let shared_bytes = self.shared_bytes()?;
        Ok(WorkgroupDemand {
            size: size3,
            invocations,
            shared_bytes: u32::try_from(shared_bytes).unwrap_or(u32::MAX),
        })
    }
}

/// The value of an OpSpecConstantOp (operands `w`) over the constants known so far, for
/// the integer operations glslang emits for sizes; `None` for any other.
fn fold_spec_constant_op(values: &HashMap<u32, u32>, w: &[u32]) -> Option<u32> {
    let arg = |k: usize| w.get(k).copied().unwrap_or(0);
    let operand = |k: usize| values.get(&arg(k)).copied();
    let (a, b) = (operand(3), operand(4));
    let both = |f: fn(u32, u32) -> Option<u32>| a.zip(b).and_then(|(a, b)| f(a, b));
    match arg(2) {
        128 => both(|a, b| Some(a.wrapping_add(b))),
        130 => both(|a, b| Some(a.wrapping_sub(b))),
        132 => both(|a, b| Some(a.wrapping_mul(b))),
        134 => both(|a, b| a.checked_div(b)),
        137 => both(|a, b| a.checked_rem(b)),
        194 => both(|a, b| Some(a.checked_shr(b).unwrap_or(0))),
        196 => both(|a, b| Some(a.checked_shl(b).unwrap_or(0))),
        197 => both(|a, b| Some(a | b)),
        199 => both(|a, b| Some(a & b)),
        // Select(condition, a, b) and the comparisons glslang folds into it.
        169 => values
            .get(&arg(3))
            .and_then(|&c| if c != 0 { operand(4) } else { operand(5) }),
        170 => both(|a, b| Some(u32::from(a == b))),
        171 => both(|a, b| Some(u32::from(a != b))),
        172 => both(|a, b| Some(u32::from(a > b))),
        174 => both(|a, b| Some(u32::from(a >= b))),
        176 => both(|a, b| Some(u32::from(a < b))),
        178 => both(|a, b| Some(u32::from(a <= b))),
        _ => None,
    }
}

/// Reads `words`' workgroup size and shared memory with `specialization` (`(id, value)`
/// pairs) applied. `Err` names what cannot be evaluated.
pub fn demand(words: &[u32], specialization: &[(u32, u32)]) -> Result<WorkgroupDemand, String> {
    if words.len() < 5 || words[0] != super::shader_set::SPIRV_MAGIC {
        return Err("not a SPIR-V module".into());
    }
    let overrides: HashMap<u32, u32> = specialization.iter().copied().collect();
    Declarations::read(words, &overrides)?.demand()
}

/// Refuses a module whose workgroup needs more invocations or shared memory than the
/// device (or the emulated limits) allow: one sentence naming the kernel and the limit.
pub fn check_limits(
    name: &str,
    words: &[u32],
    specialization: &[(u32, u32)],
    info: &super::DeviceInfo,
) -> Result<WorkgroupDemand, super::GpuError> {
    check_demand(name, demand(words, specialization), info)
}

/// [`check_limits`] of a module's demand as read (`Err`: what cannot be evaluated).
pub(crate) fn check_demand(
    name: &str,
    demand: Result<WorkgroupDemand, String>,
    info: &super::DeviceInfo,
) -> Result<WorkgroupDemand, super::GpuError> {
    let d = demand.map_err(|e| super::GpuError::Internal(format!("shader {name}: {e}")))?;
    let over = |limit: &'static str, needed: u32, max: u32| super::GpuError::DeviceLimit {
        limit,
        needed: u64::from(needed),
        max: u64::from(max),
        message: format!(
            "the {name} kernel needs {needed} of {limit} and {} allows {max} (a bug: every \
             stage must choose a variant within the device's limits; please report it)",
            info.name
        ),
    };
    if d.invocations > info.max_workgroup_invocations {
        return Err(over(
            "maxComputeWorkGroupInvocations",
            d.invocations,
            info.max_workgroup_invocations,
        ));
    }
    if d.shared_bytes > info.max_shared_memory {
        return Err(over(
            "maxComputeSharedMemorySize",
            d.shared_bytes,
            info.max_shared_memory,
        ));
    }
    Ok(d)
}

/// Invocations of the kernels built with `WIDE_WG_SPEC`: [`WIDE_WG`](super::shader_set::WIDE_WG)
/// where the device allows that many, else [`LINEAR_WG`](super::shader_set::LINEAR_WG).
pub fn wide_linear_workgroup(info: &super::DeviceInfo) -> u32 {
    use super::shader_set::{LINEAR_WG, WIDE_WG};
    if info.max_workgroup_invocations >= WIDE_WG {
        WIDE_WG
    } else {
        LINEAR_WG
    }
}
