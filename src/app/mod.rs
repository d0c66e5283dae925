//! The application: what the command line (the binary's `src/cli/`) drives. Benchmarks
//! ([`mod@bench`]), the self-check ([`doctor`]), the browser viewer ([`view`]), camera paths
//! to image sequences ([`sequence`]), the `--shard` split ([`shard`]) and scene statistics
//! ([`stats`]).

#[cfg(feature = "cli")]
pub mod bench;
pub mod doctor;
pub mod sequence;
pub mod shard;
pub mod stats;
#[cfg(feature = "viewer")]
pub mod view;
