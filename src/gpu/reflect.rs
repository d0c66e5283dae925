//! A small reflection of compiled SPIR-V: the descriptor bindings a module declares (with
//! their kind), its push-constant block (member offsets and size), and the array strides
//! and member offsets of its buffer blocks. [`check`] compares them with what the host
//! binds, so the GLSL and the Rust side of a stage cannot drift apart unnoticed: every
//! pipeline is checked when it is built, and `shader_interface_matches_the_host` builds
//! every variant.

use std::collections::HashMap;

use crate::core::shader_interface::RecordLayout;

/// What a binding slot holds.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord)]
pub enum BindingKind {
    /// `buffer` block (std430).
    StorageBuffer,
    /// `image2D` with a format qualifier.
    StorageImage,
    /// `samplerBuffer` / `usamplerBuffer` read with `texelFetch`.
    UniformTexelBuffer,
    /// `imageBuffer` / `uimageBuffer` with a format qualifier, written with `imageStore`.
    StorageTexelBuffer,
}

/// What a module declares, as far as the host binds it.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct Interface {
    /// `(binding, kind)` of every descriptor of set 0 the module still uses (the optimiser
    /// removes unused ones), sorted by binding.
    pub bindings: Vec<(u32, BindingKind)>,
    /// Member offsets of the push constants' record, in member order: of the block's one
    /// member when it is a struct (how the shaders declare a record of
    /// [`crate::core::shader_interface`]), else of the block's own members.
    pub push_offsets: Vec<u32>,
    /// The push-constant block is one member of a struct type (a record).
    pub push_is_record: bool,
    /// Bytes of the push-constant block (last member's offset plus its size).
    pub push_size: u32,
    /// `(binding, stride)` of storage buffers whose block is one runtime array of
    /// structs or scalars.
    pub array_strides: Vec<(u32, u32)>,
}

const OP_TYPE_INT: u16 = 21;
const OP_TYPE_FLOAT: u16 = 22;
const OP_TYPE_VECTOR: u16 = 23;
const OP_TYPE_MATRIX: u16 = 24;
const OP_TYPE_IMAGE: u16 = 25;
const OP_TYPE_SAMPLED_IMAGE: u16 = 27;
const OP_TYPE_ARRAY: u16 = 28;
const OP_TYPE_RUNTIME_ARRAY: u16 = 29;
const OP_TYPE_STRUCT: u16 = 30;
const OP_TYPE_POINTER: u16 = 32;
const OP_CONSTANT: u16 = 43;
const OP_VARIABLE: u16 = 59;
const OP_DECORATE: u16 = 71;
const OP_MEMBER_DECORATE: u16 = 72;

const DECORATION_ARRAY_STRIDE: u32 = 6;
const DECORATION_BINDING: u32 = 33;
const DECORATION_DESCRIPTOR_SET: u32 = 34;
const DECORATION_OFFSET: u32 = 35;

const STORAGE_UNIFORM_CONSTANT: u32 = 0;
const STORAGE_PUSH_CONSTANT: u32 = 9;
const STORAGE_STORAGE_BUFFER: u32 = 12;

const DIM_BUFFER: u32 = 5;

#[derive(Clone, Debug)]
enum Type {
    Scalar(u32),
    Vector(u32, u32),
    Matrix(u32, u32),
    Image {
        dim: u32,
        sampled: u32,
    },
    SampledImage(u32),
    /// Length id (element stride from the ArrayStride decoration).
    Array(u32),
    RuntimeArray,
    Struct(Vec<u32>),
    /// Pointee type.
    Pointer(u32),
}

/// The instructions of a SPIR-V module after its header: `(opcode, operands)` each, or
/// an `Err` naming the word where one runs past the end.
pub(crate) fn instructions(words: &[u32]) -> impl Iterator<Item = Result<(u16, &[u32]), String>> {
    let mut i = 5;
    std::iter::from_fn(move || {
        if i >= words.len() {
            return None;
        }
        let count = (words[i] >> 16) as usize;
        let op = (words[i] & 0xffff) as u16;
        if count == 0 || i + count > words.len() {
            let at = i;
            i = words.len();
            return Some(Err(format!("instruction at word {at} runs past the end")));
        }
        let operands = &words[i + 1..i + count];
        i += count;
        Some(Ok((op, operands)))
    })
}

/// The declarations of a module that its interface is read from, by result id.
#[derive(Default)]
pub(crate) struct Declarations {
    types: HashMap<u32, Type>,
    constants: HashMap<u32, u32>,
    bindings: HashMap<u32, u32>,
    sets: HashMap<u32, u32>,
    strides: HashMap<u32, u32>,
    offsets: HashMap<(u32, u32), u32>,
    /// (id, pointer type, storage class) of each variable, in order.
    variables: Vec<(u32, u32, u32)>,
}

impl Declarations {
    /// Collects the types, constants, variables and decorations of the module.
    fn read(words: &[u32]) -> Result<Self, String> {
        let mut d = Declarations::default();
        for instruction in instructions(words) {
            let (op, w) = instruction?;
            d.visit(op, w);
        }
        Ok(d)
    }

    /// Takes in one instruction (`op`, operands `w`).
    pub(crate) fn visit(&mut self, op: u16, w: &[u32]) {
        let arg = |k: usize| w.get(k).copied().unwrap_or(0);
        match op {
            OP_TYPE_INT | OP_TYPE_FLOAT => {
                self.types.insert(arg(0), Type::Scalar(arg(1) / 8));
            }
            OP_TYPE_VECTOR => {
                self.types.insert(arg(0), Type::Vector(arg(1), arg(2)));
            }
            OP_TYPE_MATRIX => {
                self.types.insert(arg(0), Type::Matrix(arg(1), arg(2)));
            }
            OP_TYPE_IMAGE => {
                self.types.insert(
                    arg(0),
                    Type::Image {
                        dim: arg(2),
                        sampled: arg(6),
                    },
                );
            }
            OP_TYPE_SAMPLED_IMAGE => {
                self.types.insert(arg(0), Type::SampledImage(arg(1)));
            }
            OP_TYPE_ARRAY => {
                self.types.insert(arg(0), Type::Array(arg(2)));
            }
            OP_TYPE_RUNTIME_ARRAY => {
                self.types.insert(arg(0), Type::RuntimeArray);
            }
            OP_TYPE_STRUCT => {
                self.types.insert(arg(0), Type::Struct(w[1..].to_vec()));
            }
            OP_TYPE_POINTER => {
                self.types.insert(arg(0), Type::Pointer(arg(2)));
            }
            OP_CONSTANT => {
                self.constants.insert(arg(1), arg(2));
            }
            OP_VARIABLE => self.variables.push((arg(1), arg(0), arg(2))),
            OP_DECORATE => match arg(1) {
                DECORATION_BINDING => {
                    self.bindings.insert(arg(0), arg(2));
                }
                DECORATION_DESCRIPTOR_SET => {
                    self.sets.insert(arg(0), arg(2));
                }
                DECORATION_ARRAY_STRIDE => {
                    self.strides.insert(arg(0), arg(2));
                }
                _ => {}
            },
            OP_MEMBER_DECORATE if arg(2) == DECORATION_OFFSET => {
                self.offsets.insert((arg(0), arg(1)), arg(3));
            }
            _ => {}
        }
    }

    /// Bytes of type `t` (a block: its last member's offset plus that member's size);
    /// `None` for what has no size here or nests deeper than 16.
    fn size_of(&self, t: u32) -> Option<u32> {
        self.size(t, 0)
    }

    fn size(&self, t: u32, depth: u32) -> Option<u32> {
        if depth > 16 {
            return None;
        }
        match self.types.get(&t)? {
            Type::Scalar(bytes) => Some(*bytes),
            Type::Vector(c, n) => Some(self.size(*c, depth + 1)? * n),
            Type::Matrix(c, n) => Some(self.size(*c, depth + 1)? * n),
            Type::Array(len) => Some(self.strides.get(&t)? * self.constants.get(len)?),
            Type::Struct(members) => {
                let last = members.len().checked_sub(1)? as u32;
                let off = self.offsets.get(&(t, last))?;
                Some(off + self.size(members[last as usize], depth + 1)?)
            }
            _ => None,
        }
    }

    /// The kind of descriptor `binding` is: a variable of `storage` class pointing at
    /// `pointee`.
    fn binding_kind(
        &self,
        binding: u32,
        storage: u32,
        pointee: u32,
    ) -> Result<BindingKind, String> {
        let types = &self.types;
        Ok(match (storage, types.get(&pointee)) {
            (STORAGE_STORAGE_BUFFER, _) => BindingKind::StorageBuffer,
            (_, Some(Type::SampledImage(image))) => match types.get(image) {
                Some(Type::Image {
                    dim: DIM_BUFFER, ..
                }) => BindingKind::UniformTexelBuffer,
                _ => {
                    return Err(format!(
                        "binding {binding}: a sampled image other than a texel buffer"
                    ))
                }
            },
            (
                _,
                Some(Type::Image {
                    dim: DIM_BUFFER,
                    sampled: 2,
                }),
            ) => BindingKind::StorageTexelBuffer,
            // SPIR-V 1.6 declares a samplerBuffer as a sampled (1) buffer image.
            (
                _,
                Some(Type::Image {
                    dim: DIM_BUFFER,
                    sampled: 1,
                }),
            ) => BindingKind::UniformTexelBuffer,
            (_, Some(Type::Image { sampled: 2, .. })) => BindingKind::StorageImage,
            _ => {
                return Err(format!(
                    "binding {binding}: a descriptor kind verisplat does not bind"
                ))
            }
        })
    }

    /// The array stride of a storage buffer whose block (`pointee`) is one runtime array.
    fn runtime_array_stride(&self, pointee: u32) -> Option<u32> {
        let Some(Type::Struct(members)) = self.types.get(&pointee) else {
            return None;
        };
        let [array] = members[..] else {
            return None;
        };
        match (self.types.get(&array), self.strides.get(&array)) {
            (Some(Type::RuntimeArray), Some(&stride)) => Some(stride),
            _ => None,
        }
    }

    /// The interface the declarations make up.
    pub(crate) fn interface(&self) -> Result<Interface, String> {
        let d = self;
        let mut interface = Interface::default();
        for &(id, pointer, storage) in &d.variables {
            let pointee = match d.types.get(&pointer) {
                Some(Type::Pointer(pointee)) => *pointee,
                _ => continue,
            };
            match storage {
                STORAGE_PUSH_CONSTANT => {
                    let Some(Type::Struct(members)) = d.types.get(&pointee) else {
                        return Err("the push constants are not a block".into());
                    };
                    // A block of one struct member: the record's members.
                    let (record, members) = match members[..] {
                        [member] => match d.types.get(&member) {
                            Some(Type::Struct(inner)) => (member, inner),
                            _ => (pointee, members),
                        },
                        _ => (pointee, members),
                    };
                    interface.push_is_record = record != pointee;
                    interface.push_offsets = (0..members.len() as u32)
                        .map(|m| d.offsets.get(&(record, m)).copied().unwrap_or(u32::MAX))
                        .collect();
                    interface.push_size = d
                        .size_of(pointee)
                        .ok_or("the push-constant block's size cannot be computed")?;
                }
                STORAGE_STORAGE_BUFFER | STORAGE_UNIFORM_CONSTANT => {
                    let Some(&binding) = d.bindings.get(&id) else {
                        continue;
                    };
                    if d.sets.get(&id).copied().unwrap_or(0) != 0 {
                        return Err(format!("binding {binding} is not in descriptor set 0"));
                    }
                    let kind = d.binding_kind(binding, storage, pointee)?;
                    interface.bindings.push((binding, kind));
                    if kind == BindingKind::StorageBuffer {
                        if let Some(stride) = d.runtime_array_stride(pointee) {
                            interface.array_strides.push((binding, stride));
                        }
                    }
                }
                _ => {}
            }
        }
        interface.bindings.sort_by_key(|&(b, _)| b);
        interface.array_strides.sort();
        Ok(interface)
    }
}

/// Reads the interface of a SPIR-V module; `Err` names what is malformed.
pub fn reflect(words: &[u32]) -> Result<Interface, String> {
    if words.len() < 5 || words[0] != super::shader_set::SPIRV_MAGIC {
        return Err("not a SPIR-V module".into());
    }
    Declarations::read(words)?.interface()
}

/// Checks that a module binds what the host passes: every binding the module uses is in
/// `bindings` with the same kind, and its push-constant block is the record `push`, member
/// by member.
pub fn check(
    name: &str,
    words: &[u32],
    bindings: &[BindingKind],
    push: &RecordLayout,
) -> Result<Interface, String> {
    check_interface(name, reflect(words), bindings, push)
}

/// [`check`] of a module's interface as read (`Err`: what is malformed).
pub(crate) fn check_interface(
    name: &str,
    interface: Result<Interface, String>,
    bindings: &[BindingKind],
    push: &RecordLayout,
) -> Result<Interface, String> {
    let interface = interface.map_err(|e| format!("shader {name}: {e}"))?;
    let push_size = push.size as u32;
    for &(binding, kind) in &interface.bindings {
        match bindings.get(binding as usize) {
            Some(&host) if host == kind => {}
            Some(&host) => {
                return Err(format!(
                    "shader {name} declares binding {binding} as {kind:?}, the host binds {host:?}"
                ))
            }
            None => {
                return Err(format!(
                    "shader {name} declares binding {binding} ({kind:?}), the host binds only {}",
                    bindings.len()
                ))
            }
        }
    }
    // A block the optimiser removed (no member used) has no size; any other must match.
    if interface.push_size != push_size && !interface.push_offsets.is_empty() {
        return Err(format!(
            "shader {name} has {} bytes of push constants, the host pushes {push_size}",
            interface.push_size
        ));
    }
    if !interface.push_offsets.is_empty() {
        if !interface.push_is_record {
            return Err(format!(
                "shader {name} declares its push constants member by member: declare them as \
                 one member of type {} (interface.glsl, from src/core/shader_interface.rs)",
                push.glsl
            ));
        }
        let host: Vec<u32> = push.fields.iter().map(|f| f.offset as u32).collect();
        if interface.push_offsets != host {
            return Err(format!(
                "shader {name}: the push constants' members are at bytes {:?}, {} has them \
                 at {host:?}",
                interface.push_offsets, push.rust
            ));
        }
    }
    Ok(interface)
}
