//! Batches, the unit of work, statistics and parallelism: their fixed size, and how a batch in
//! progress learns that the run is stopping. Shared by every integrator and the driver.

use std::sync::atomic::{AtomicBool, Ordering};

/// Photons per batch. Fixed, so a batch's photons and its random stream never depend on threads.
pub const BATCH_PHOTONS: u64 = 16_384;

/// Photons between two looks at `Kernel::cancel`.
pub const CANCEL_CHECK_PHOTONS: u64 = 256;

/// Whether `cancel` is set; checked every `CANCEL_CHECK_PHOTONS` photons of a batch.
#[inline]
pub fn cancelled(cancel: Option<&AtomicBool>, photon: u64) -> bool {
    photon.is_multiple_of(CANCEL_CHECK_PHOTONS) && cancel.is_some_and(|c| c.load(Ordering::Relaxed))
}
