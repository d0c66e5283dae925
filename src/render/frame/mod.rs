//! The frame machinery around the stages: the per-frame [`buffers`] (and the growth of
//! the key buffers), the [`schedule`] (submit, finish, the decision to record a frame
//! again), the [`record`]ing of a frame's stages into one command buffer, the
//! [`readback`] of what a consumer asked for, the stage [`timings`] and [`traffic`], the scene and
//! feature [`upload`], the [`pipelines`] built on first use and the pipelined camera
//! [`path`].

pub(crate) mod bands;
pub mod buffers;
pub mod path;
pub mod pipelines;
pub mod readback;
pub mod record;
pub mod schedule;
pub mod timings;
pub mod traffic;
pub mod upload;
