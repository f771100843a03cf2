//! The global allocator: the system's, with every large block (at least [`MIN_ADVISED`]) marked
//! for transparent huge pages (`madvise(MADV_HUGEPAGE)`), as glibc's `glibc.malloc.hugetlb=1`
//! tunable would do for the whole heap.
//!
//! A paper-scale solve touches about 130 MB in a few large arrays (element matrices, factors,
//! gather indices) read in scattered order: with 2 MiB pages it takes fewer TLB misses and page
//! faults, and the kernel frees it faster at exit. Measured side by side on the contention
//! deck (14 interleaved runs, a slow phase of the host): `femu solve` 0.471 → 0.414 s best,
//! 0.534 → 0.461 s median; assembly 0.082 → 0.071 s median; peak memory 126 → 131 MB (the
//! glibc tunable: 0.412 s best, 0.492 s median). Where the kernel has transparent huge pages
//! off (`never`) or refuses the advice, the blocks stay on normal pages: it is only an advice.
//!
//! Tried and not kept (2026-11-24): advising the whole heap (256 MiB grown at start, one arena,
//! blocks up to 32 MiB from the heap, no trimming; `glibc.malloc.hugetlb=1` in effect). In runs
//! back to back it was the fastest (page faults 19 000 → 2 000, median 0.229 s against 0.243 s
//! for the advice of large blocks only), but right after another process had freed a lot of
//! memory (ccx, 0.9 GB, as in `femu bench`) it was the slowest: median 0.329 s against 0.258 s,
//! with the setup phase at 0.16–0.30 s instead of 0.04 s. This machine's host takes back the
//! guest's free 2 MiB blocks, and every huge-page fault then waits for the host to back its
//! block again. The heap options without the whole-heap advice gained nothing measurable.

use std::alloc::{GlobalAlloc, Layout, System};

/// Blocks at least this large are advised.
pub const MIN_ADVISED: usize = 4 << 20;

const HUGE_PAGE: usize = 2 << 20;

/// The system allocator, advising huge pages for large blocks.
pub struct HugePageAlloc;

/// Advises huge pages for the whole 2 MiB pages inside `[ptr, ptr + size)`; whether the kernel
/// accepted the advice (`false` for small or null blocks and off Linux).
fn advise(ptr: *mut u8, size: usize) -> bool {
    if ptr.is_null() || size < MIN_ADVISED {
        return false;
    }
    let start = (ptr as usize).next_multiple_of(HUGE_PAGE);
    let end = (ptr as usize + size) / HUGE_PAGE * HUGE_PAGE;
    if end <= start {
        return false;
    }
    #[cfg(target_os = "linux")]
    {
        // SAFETY: `[start, end)` lies inside the block just allocated, which this process owns;
        // MADV_HUGEPAGE changes only how the kernel backs the range, never its contents.
        unsafe { libc::madvise(start as *mut libc::c_void, end - start, libc::MADV_HUGEPAGE) == 0 }
    }
    #[cfg(not(target_os = "linux"))]
    {
        false
    }
}

// SAFETY: every call is forwarded to `System` with the same arguments; `advise` only adds
// advice on memory `System` just returned.
unsafe impl GlobalAlloc for HugePageAlloc {
    unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
        // SAFETY: the caller's contract for `alloc`, passed on.
        let ptr = unsafe { System.alloc(layout) };
        advise(ptr, layout.size());
        ptr
    }

    unsafe fn alloc_zeroed(&self, layout: Layout) -> *mut u8 {
        // SAFETY: the caller's contract for `alloc_zeroed`, passed on.
        let ptr = unsafe { System.alloc_zeroed(layout) };
        advise(ptr, layout.size());
        ptr
    }

    unsafe fn dealloc(&self, ptr: *mut u8, layout: Layout) {
        // SAFETY: the caller's contract for `dealloc`, passed on.
        unsafe { System.dealloc(ptr, layout) }
    }

    unsafe fn realloc(&self, ptr: *mut u8, layout: Layout, new_size: usize) -> *mut u8 {
        // SAFETY: the caller's contract for `realloc`, passed on.
        let ptr = unsafe { System.realloc(ptr, layout, new_size) };
        advise(ptr, new_size);
        ptr
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Large blocks are advised (on Linux) and hold what is written into them, through
    /// allocation, zeroed allocation and growth; small ones are left alone.
    #[test]
    fn large_blocks_are_advised_and_usable() {
        let alloc = HugePageAlloc;
        assert!(!advise(std::ptr::null_mut(), 64 << 20));
        let small = Layout::from_size_align(4096, 8).unwrap();
        let large = Layout::from_size_align(8 << 20, 8).unwrap();
        // SAFETY: layouts of non-zero size; every block is freed with the layout it has.
        unsafe {
            let p = alloc.alloc(small);
            assert!(!advise(p, small.size()));
            alloc.dealloc(p, small);

            let p = alloc.alloc_zeroed(large);
            assert!(!p.is_null());
            let words = std::slice::from_raw_parts_mut(p as *mut u64, large.size() / 8);
            assert!(words.iter().all(|&w| w == 0));
            for (k, w) in words.iter_mut().enumerate() {
                *w = k as u64;
            }
            if cfg!(target_os = "linux") {
                assert!(advise(p, large.size()), "madvise(MADV_HUGEPAGE) refused");
            }
            let grown = alloc.realloc(p, large, 2 * large.size());
            let words = std::slice::from_raw_parts(grown as *const u64, large.size() / 8);
            assert!(words.iter().enumerate().all(|(k, &w)| w == k as u64));
            alloc.dealloc(grown, Layout::from_size_align(2 * large.size(), 8).unwrap());
        }
    }
}
