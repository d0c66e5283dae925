//! Training: the backward pass against finite differences and on the device, the loss,
//! `verisplat train` on data sets made here and from real captures, distorted photos, and
//! training under gsplat's rules, and the per-photo appearance.

mod appearance;
mod banded_backward;
mod captures;
mod gradients;
mod gsplat_rules;
mod lens_gradients;
mod loss;
mod masks;
mod mip_filter;
mod photos;
mod training;
mod undistort;
mod widths;
