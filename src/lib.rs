//! photon: a forward Monte Carlo particle tracer. A scene (surfaces, materials, lights) goes in;
//! per-surface flux tallies with standard errors and an exact energy ledger come out.
//!
//! Data path: `scene` (TOML → SI triangles) → `emitter` (photon births) → `transport` (the photon
//! loop over the `geometry` BVH, `bsdf` scattering, `media` absorption) → `tally` (per-history moments, ledger) →
//! `run` (batches, ordered reduction, stopping) → `output` (staged files). Modules are layered
//! one way down (see `tests/layers.rs` for the order): none names a module above it.

pub mod batch;
pub mod bsdf;
pub mod camera_paths;
pub mod color;
pub mod converge;
pub mod emitter;
pub mod error;
pub mod film;
pub mod geometry;
pub mod ies;
pub mod media;
pub mod output;
pub mod photometry;
pub mod run;
pub mod sampling;
pub mod scene;
pub mod spectrum;
pub mod tally;
pub mod transport;
pub mod validate;
