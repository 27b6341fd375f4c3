//! photon: a forward Monte Carlo particle tracer. A scene (surfaces, materials, lights) goes in;
//! per-surface flux tallies with standard errors and an exact energy ledger come out.
//!
//! Data path: `scene` (TOML → SI triangles) → `lights` (photon births) → `integrators` (the
//! photon loop over the `geometry` BVH, `bsdf` scattering, `media` absorption) → `detectors`
//! (per-history moments, ledger, film) → `run` (batches, ordered reduction, stopping) → `output`
//! (staged files). Modules are layered one way down (see `tests/layers.rs` for the order): none
//! names a module above it.

pub mod bsdf;
pub mod detectors;
pub mod error;
pub mod geometry;
pub mod integrators;
pub mod lights;
pub mod media;
pub mod output;
pub mod pages;
pub mod run;
pub mod sampling;
pub mod scene;
pub mod spectrum;
pub mod validate;

/// Large allocations in huge pages (`pages`).
#[global_allocator]
static ALLOCATOR: pages::HugePages = pages::HugePages;
