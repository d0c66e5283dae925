//! `vksplat view`: an interactive viewer in the browser. The scene is rendered on the
//! machine that holds it; frames go to the page over a WebSocket.
//!
//! * [`source`]: what the server asks of a renderer (one frame for a camera and the
//!   page's settings), and [`source::GpuSource`], the Vulkan pipeline behind it.
//! * [`cpu_source`]: the same from the CPU reference renderer (`view --cpu`).
//! * [`protocol`]: the messages between page and server.
//! * [`server`]: HTTP for the page, the WebSocket per tab, and the render worker.
//! * [`page`]: the page itself (HTML, JS, CSS embedded in the binary).

pub mod cpu_source;
pub mod page;
pub mod protocol;
pub mod server;
pub mod source;
