//! The process's allocator: the system's, with every allocation of 4 MB or more advised as
//! transparent huge pages (2 MB) before it is first written. Linux backs such ranges with huge
//! pages where its THP mode is `madvise` (as on this project's hosts) or `always`; elsewhere the
//! advice does nothing. With 4 kB pages almost every node and triangle a ray reads in a large
//! mesh's 100 MB, and every splat into a 512² film's 32 MB of exact sums, also missed the TLB;
//! Embree asks for huge pages for its trees the same way. raybench on the 1.3 M-triangle sphere:
//! closest hit 0.90×, shadow ray 0.91×.
//!
//! The advice must come before the pages are touched: pages already written stay 4 kB (until the
//! kernel's background merging, if ever). A vector grown by pushing is advised as each
//! reallocation passes 4 MB, so only its new part is backed by huge pages; arrays read at random
//! (the tree's nodes) are allocated once at their size (`geometry::bvh::Bvh8::from_nodes`).

use std::alloc::{GlobalAlloc, Layout, System};

/// Allocations smaller than this are left alone (a couple of huge pages at most).
const LEAST_BYTES: usize = 4 << 20;

pub struct HugePages;

// SAFETY: every call is passed to `System` unchanged; the advice only changes how the pages of
// a range inside the returned block are backed, never their contents.
unsafe impl GlobalAlloc for HugePages {
    unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
        // SAFETY: the caller's contract, passed on.
        let p = unsafe { System.alloc(layout) };
        advise(p, layout.size());
        p
    }

    unsafe fn alloc_zeroed(&self, layout: Layout) -> *mut u8 {
        // SAFETY: as `alloc`.
        let p = unsafe { System.alloc_zeroed(layout) };
        advise(p, layout.size());
        p
    }

    unsafe fn dealloc(&self, p: *mut u8, layout: Layout) {
        // SAFETY: as `alloc`.
        unsafe { System.dealloc(p, layout) }
    }

    unsafe fn realloc(&self, p: *mut u8, layout: Layout, new_size: usize) -> *mut u8 {
        // SAFETY: as `alloc`.
        let q = unsafe { System.realloc(p, layout, new_size) };
        advise(q, new_size);
        q
    }
}

/// The size of a transparent huge page on x86-64 and most Linux targets.
const HUGE: usize = 2 << 20;

/// Advises the whole 2 MB pages inside [start, start + bytes) as huge, for a block of at least
/// LEAST_BYTES (a null `start` is a failed allocation: nothing to advise).
#[inline]
fn advise(start: *mut u8, bytes: usize) {
    if bytes < LEAST_BYTES || start.is_null() {
        return;
    }
    #[cfg(target_os = "linux")]
    if let Some((first, len)) = whole_huge_pages(start as usize, bytes) {
        // SAFETY: the range lies inside the block just allocated; a refusal (no THP) is
        // harmless and ignored.
        unsafe { libc::madvise(first as *mut libc::c_void, len, libc::MADV_HUGEPAGE) };
    }
}

/// The start and length of the whole huge pages inside [start, start + bytes), if any.
#[cfg_attr(not(target_os = "linux"), allow(dead_code))]
fn whole_huge_pages(start: usize, bytes: usize) -> Option<(usize, usize)> {
    let first = start.checked_next_multiple_of(HUGE)?;
    let end = start.checked_add(bytes)? / HUGE * HUGE;
    (end > first).then(|| (first, end - first))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn only_whole_huge_pages_inside_the_block_are_advised() {
        // Aligned at both ends: all of it.
        assert_eq!(whole_huge_pages(4 * HUGE, 3 * HUGE), Some((4 * HUGE, 3 * HUGE)));
        // Page-aligned (as mmap gives) but not huge-aligned: the huge pages strictly inside.
        assert_eq!(whole_huge_pages(4 * HUGE + 4096, 3 * HUGE), Some((5 * HUGE, 2 * HUGE)));
        // Less than one whole huge page inside: nothing.
        assert_eq!(whole_huge_pages(HUGE + 1, HUGE + 100), None);
        // A block ending at the top of the address space: no overflow.
        assert_eq!(whole_huge_pages(usize::MAX - HUGE, HUGE), None);
    }

    /// A block allocated through the global allocator is usable whole, before and after growing
    /// past the advised size (the advice never changes contents).
    #[test]
    fn large_blocks_keep_their_contents() {
        let mut v: Vec<u64> = (0..(LEAST_BYTES as u64 / 4)).collect();
        v.extend(0..LEAST_BYTES as u64 / 4);
        let n = LEAST_BYTES as u64 / 4;
        assert!(v.iter().enumerate().all(|(i, &x)| x == i as u64 % n));
    }
}
