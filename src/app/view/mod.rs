//! `verisplat view`: an interactive viewer in the browser. The scene is rendered on the
//! machine that holds it; frames go to the page over a WebSocket.
//!
//! * [`source`]: what the server asks of a renderer (one frame for a camera and the
//!   page's settings), and [`source::GpuSource`], the Vulkan pipeline behind it.
//! * [`cpu_source`]: the same from the CPU reference renderer (`view --cpu`).
//! * [`protocol`]: the messages between page and server.
//! * [`server`]: the listener, the page's files, the WebSocket upgrade and the render
//!   worker; `session` is one tab's connection, `http` the little HTTP it needs, `queue`
//!   what they share (the tunables, each tab's pending work and its channel).
//! * [`paths`]: keyframe paths from the page (exports and the preview's frames).
//! * [`preview`]: how many Gaussians and pixels a tab's next preview draws, from the
//!   measured stage times.
//! * [`page`]: the page itself (HTML, JS, CSS embedded in the binary).

pub mod cpu_source;
mod http;
pub mod page;
pub mod paths;
pub mod preview;
pub mod protocol;
mod queue;
pub mod server;
mod session;
pub mod source;
