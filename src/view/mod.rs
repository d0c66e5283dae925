//! `vksplat view`: an interactive viewer in the browser. The scene is rendered by the
//! Vulkan pipeline on the machine that holds it; frames go to the page over a WebSocket.
//!
//! * [`source`]: what the server asks of a renderer (one frame for a camera and the
//!   page's settings), and [`source::GpuSource`], the Vulkan pipeline behind it.

pub mod source;
