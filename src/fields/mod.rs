//! Fields: Gaussian fits to sampled fields ([`fit`]), the RF field model ([`rf`]), and the
//! small MLP that shades feature splats ([`mlp`]).

pub mod fit;
pub mod mlp;
pub mod rf;
