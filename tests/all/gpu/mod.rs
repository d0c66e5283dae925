//! The Vulkan layer under the renderer: the context, shader compiler, prefix sum and radix
//! sort; the shader interface; device limits, discrete-GPU semantics and memory over long
//! runs.

mod discrete_emulation;
mod limits;
mod memory;
mod primitives;
mod shader_interface;
