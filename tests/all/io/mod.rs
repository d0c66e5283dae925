//! Files in and out: scene formats, the PLY loader, camera sources, malformed input and
//! the fuzzers' finds, the real scenes, and the image and compositing outputs.

mod camera_sources;
mod formats;
mod fuzz_regressions;
mod gltf;
mod malformed;
mod output;
mod output_compositing;
mod ply_loader;
mod real_scenes;
mod spz_axes;
mod writers;
