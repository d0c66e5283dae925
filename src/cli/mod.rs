//! The subcommands of the `vksplat` binary, one file each, and the arguments they share.

pub mod bench;
pub mod common;
pub mod compare;
pub mod convert;
pub mod eval;
pub mod gen;
pub mod info;
pub mod render;
