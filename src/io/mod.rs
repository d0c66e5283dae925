//! Images in and out: image files and NumPy arrays read ([`image_file`]), rendered frames
//! written as PNG, EXR and the rest ([`output`]), and images compared: metrics
//! ([`metrics`]: PSNR, SSIM, ...; [`color_fit`]: the colour-corrected comparison) and difference images ([`diff_image`], labelled with
//! [`font`]), and videos encoded by the system ffmpeg ([`video`]).

pub mod color_fit;
pub mod diff_image;
pub mod font;
pub mod image_file;
pub mod metrics;
pub mod output;
pub mod video;
