//! The core: what every other wing builds on. The splat model the renderers share
//! ([`model`]), the reference's rules ([`rules`]), cameras ([`camera`]) with their lenses
//! and scenes ([`scene`]) (their files are read and written in [`crate::io`]), the
//! rendered [`frame`], NumPy arrays
//! ([`npy`]), quaternions
//! ([`quat`]), synthetic scenes ([`gen`]), the records and flags shared with the shaders
//! ([`shader_interface`]), arithmetic with the same bits on every device ([`math`]), and
//! the small utilities below them all: file errors
//! ([`file_error`]), atomic writes ([`fsutil`]), console output ([`console`]) and the
//! former name's environment variables ([`former_name`]).

pub mod camera;
pub mod console;
pub mod file_error;
pub mod former_name;
pub mod frame;
pub mod fsutil;
pub mod gen;
pub mod math;
pub mod model;
pub mod npy;
pub mod quat;
pub mod rules;
pub mod scene;
pub mod shader_interface;
