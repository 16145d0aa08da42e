//! Counting heap allocations, to check that a hot path (an environment step, a minibatch update)
//! allocates nothing.
//!
//! Install [`CountingAllocator`] as the global allocator of a test, bench or example binary, then
//! wrap the code under test in [`count_allocations`]. Only allocations made **on the calling
//! thread** while it runs are counted (reallocations included, frees not), so test threads
//! running side by side do not disturb each other; work handed to other threads (rayon) is not
//! seen.
//!
//! ```
//! use a2perf_core::alloc_count::{CountingAllocator, count_allocations};
//!
//! #[global_allocator]
//! static ALLOC: CountingAllocator = CountingAllocator;
//!
//! let mut buf = Vec::with_capacity(16);
//! let (n, ()) = count_allocations(|| buf.extend_from_slice(&[1u8, 2, 3]));
//! assert_eq!(n, 0);
//! let (n, v) = count_allocations(|| vec![0u8; 64]);
//! assert_eq!((n, v.len()), (1, 64));
//! ```

use std::alloc::{GlobalAlloc, Layout, System};
use std::cell::Cell;

thread_local! {
    static COUNTING: Cell<bool> = const { Cell::new(false) };
    static COUNT: Cell<usize> = const { Cell::new(0) };
}

fn note() {
    // `try_with`: the allocator may run while the thread's locals are being torn down.
    let _ = COUNTING.try_with(|on| {
        if on.get() {
            let _ = COUNT.try_with(|c| c.set(c.get() + 1));
        }
    });
}

/// The system allocator, counting allocations and reallocations made on a thread while it is
/// inside [`count_allocations`].
#[derive(Clone, Copy, Debug, Default)]
pub struct CountingAllocator;

// SAFETY: every call is forwarded unchanged to `System`; the bookkeeping touches only
// const-initialised thread-locals, which never allocate.
unsafe impl GlobalAlloc for CountingAllocator {
    unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
        note();
        // SAFETY: same contract as the caller's.
        unsafe { System.alloc(layout) }
    }

    unsafe fn alloc_zeroed(&self, layout: Layout) -> *mut u8 {
        note();
        // SAFETY: same contract as the caller's.
        unsafe { System.alloc_zeroed(layout) }
    }

    unsafe fn realloc(&self, ptr: *mut u8, layout: Layout, new_size: usize) -> *mut u8 {
        note();
        // SAFETY: same contract as the caller's.
        unsafe { System.realloc(ptr, layout, new_size) }
    }

    unsafe fn dealloc(&self, ptr: *mut u8, layout: Layout) {
        // SAFETY: same contract as the caller's.
        unsafe { System.dealloc(ptr, layout) }
    }
}

/// Runs `f` and returns the number of heap allocations (and reallocations) it made on this
/// thread, with its result. Counts are meaningful only when [`CountingAllocator`] is the global
/// allocator; otherwise they are 0. A nested call's allocations count towards the enclosing call too.
pub fn count_allocations<R>(f: impl FnOnce() -> R) -> (usize, R) {
    let saved = COUNT.with(|c| c.replace(0));
    let was_on = COUNTING.with(|c| c.replace(true));
    let result = f();
    COUNTING.with(|c| c.set(was_on));
    let n = COUNT.with(|c| {
        let n = c.get();
        c.set(saved + n);
        n
    });
    (n, result)
}
