//! The subcommands of the `verisplat` binary, one file each, and the arguments they share.

pub mod bench;
pub mod common;
pub mod compare;
pub mod convert;
pub mod doctor;
pub mod eval;
pub mod eval_mask;
pub mod eval_photo;
pub mod fit;
pub mod gen;
pub mod info;
pub mod render;
pub mod train;
pub mod transform;
pub mod values;
pub mod view;

/// `1 camera`, `3 cameras`: a count with its noun in the right number (nouns taking `s`).
pub(crate) fn plural(n: usize, noun: &str) -> String {
    if n == 1 {
        format!("1 {noun}")
    } else {
        format!("{n} {noun}s")
    }
}
