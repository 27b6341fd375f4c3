//! What records the light: per-surface tallies and the energy ledger (`tally`), irradiance maps'
//! texel areas (`maps`), and the camera with its film (`film`). The scene describes the
//! detectors; these build their own state and own their accumulators.

pub mod film;
pub mod maps;
pub mod tally;
