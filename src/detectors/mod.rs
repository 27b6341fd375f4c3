//! What records the light: per-surface tallies and the energy ledger (`tally`), irradiance maps'
//! texel areas (`maps`), the camera with its film (`film`), and the order-free sums a run's totals
//! are kept in (`exact`). The scene describes the detectors; these build their own state and own
//! their accumulators.

pub mod exact;
pub mod film;
pub mod maps;
pub mod tally;
