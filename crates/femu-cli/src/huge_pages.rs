//! The global allocator: the system's, with every large block (at least [`MIN_ADVISED`]) marked
//! for transparent huge pages (`madvise(MADV_HUGEPAGE)`), as glibc's `glibc.malloc.hugetlb=1`
//! tunable would do for the whole heap; and [`configure_heap`], called first thing in `main`,
//! which sets glibc's heap up so that freed blocks are reused instead of unmapped, by every
//! thread, on huge pages.
//!
//! A paper-scale solve touches about 130 MB in a few large arrays (element matrices, factors,
//! gather indices) read in scattered order: with 2 MiB pages it takes fewer TLB misses and page
//! faults, and the kernel frees it faster at exit. Measured side by side on the contention
//! deck (14 interleaved runs, a slow phase of the host): `femu solve` 0.471 → 0.414 s best,
//! 0.534 → 0.461 s median; assembly 0.082 → 0.071 s median; peak memory 126 → 131 MB (the
//! glibc tunable: 0.412 s best, 0.492 s median). With [`configure_heap`] as well (2026-11-24,
//! `perf stat -r 12`, interleaved): page faults 19 000 → 2 000, CPU time 0.41–0.48 → 0.36–0.39
//! s, reading the deck 27 → 19 ms; peak memory 129 → 136 MB. Where the kernel has transparent
//! huge pages off (`never`) or refuses the advice, the blocks stay on normal pages: it is only
//! an advice.

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

/// Largest block glibc's `malloc` serves from its heap rather than from a mapping of its own
/// (glibc caps `M_MMAP_THRESHOLD` at 32 MiB on 64-bit targets).
#[cfg(all(target_os = "linux", target_env = "gnu"))]
const HEAP_BLOCK_MAX: usize = 32 << 20;

/// Heap grown (virtually) and advised for huge pages at start.
#[cfg(all(target_os = "linux", target_env = "gnu"))]
const HEAP_RESERVE: usize = 256 << 20;

/// Sets up glibc's heap for femu's allocation pattern, before anything is allocated: one arena
/// for all threads, blocks up to 32 MiB from the heap instead of fresh mappings, nothing
/// returned to the kernel, and the first [`HEAP_RESERVE`] of the heap advised for huge pages
/// (as `GLIBC_TUNABLES=glibc.malloc.hugetlb=1:glibc.malloc.arena_max=1:...` would).
///
/// A solve allocates and frees many short-lived buffers of 0.1–30 MB (the deck's lines, the
/// node graph, the symbolic analyses, the output's rows), each of which glibc would otherwise
/// map fresh and unmap, so that every one costs page faults and the kernel's zeroing of its
/// pages again; and rayon's worker threads would each get an arena of their own, on small pages.
/// Here a freed block's pages are reused as they are. Returns whether the heap was set up
/// (`false` off glibc, or if an option was refused).
pub fn configure_heap() -> bool {
    #[cfg(all(target_os = "linux", target_env = "gnu"))]
    {
        // SAFETY: mallopt only changes glibc's allocation parameters; the blocks below are
        // allocated, advised and freed here, and nothing else holds them.
        unsafe {
            let options = [
                (libc::M_ARENA_MAX, 1),
                (libc::M_MMAP_THRESHOLD, HEAP_BLOCK_MAX as libc::c_int),
                (libc::M_TRIM_THRESHOLD, libc::c_int::MAX),
            ];
            if options.iter().any(|&(k, v)| libc::mallopt(k, v) != 1) {
                return false;
            }
            // Grow the heap by blocks just under the mapping threshold, advise the whole span
            // (they are contiguous), and free them: the heap keeps the span, and later blocks
            // are carved from it.
            const BLOCK: usize = HEAP_BLOCK_MAX - (1 << 20);
            let mut blocks = [std::ptr::null_mut::<libc::c_void>(); HEAP_RESERVE / BLOCK];
            for b in blocks.iter_mut() {
                *b = libc::malloc(BLOCK);
            }
            let (lo, hi) = blocks
                .iter()
                .filter(|b| !b.is_null())
                .fold((usize::MAX, 0usize), |(lo, hi), &b| {
                    (lo.min(b as usize), hi.max(b as usize + BLOCK))
                });
            if lo < hi {
                advise(lo as *mut u8, hi - lo);
            }
            for &b in blocks.iter().rev() {
                libc::free(b);
            }
        }
        true
    }
    #[cfg(not(all(target_os = "linux", target_env = "gnu")))]
    {
        false
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// glibc accepts the heap options (on Linux with glibc), and blocks up to the mapping
    /// threshold then come from the heap and hold what is written into them.
    #[test]
    fn heap_is_configured() {
        let configured = configure_heap();
        assert_eq!(
            configured,
            cfg!(all(target_os = "linux", target_env = "gnu")),
            "mallopt refused an option"
        );
        let mut v = vec![0u64; (24 << 20) / 8];
        for (k, w) in v.iter_mut().enumerate() {
            *w = k as u64;
        }
        assert!(v.iter().enumerate().all(|(k, &w)| w == k as u64));
    }

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
