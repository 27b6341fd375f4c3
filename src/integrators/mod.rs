//! The three ways photon estimates light, all over the same scene, lights and `bsdf` models:
//! the particle tracer (`particle`: flux tallies, and with a camera the light-traced image) and
//! the camera integrators (`camera`: path tracing and BDPT of the same image). `batch` fixes
//! what a batch is, since random streams are per batch.

pub mod batch;
pub mod camera;
pub mod clear_view;
pub mod emitter_view;
pub mod particle;
pub mod passage;
