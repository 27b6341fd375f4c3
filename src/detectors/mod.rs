//! What records the light: per-surface tallies and the energy ledger (`tally`), and the camera
//! with its film (`film`). The scene describes the detectors; these own their accumulators.

pub mod film;
pub mod tally;
