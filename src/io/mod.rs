//! Files in and out: scene files of every format ([`scene`]), camera files ([`camera`]),
//! the built-in demo scene ([`demo`]); image files and NumPy arrays read ([`image_file`]), rendered frames
//! written as PNG, EXR and the rest ([`output`]), and images compared: metrics
//! ([`metrics`]: PSNR, SSIM, ...; [`color_fit`]: the colour-corrected comparison) and difference images ([`diff_image`], labelled with
//! [`font`]), and videos encoded by the system ffmpeg ([`video`]).

pub mod camera;
pub mod color_fit;
pub mod demo;
pub mod diff_image;
pub mod font;
pub mod image_file;
pub mod metrics;
pub mod output;
pub mod scene;
pub mod video;
