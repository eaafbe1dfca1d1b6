//! A counting allocator, so a fuzz case's memory is its own: the bytes
//! each thread has live and its peak since a mark. A reader that believes
//! a size in its input ("element face 4294967296") allocates on the thread
//! that runs the case, where this sees it whatever other workers do. The
//! fuzz binaries install it (`#[global_allocator]`); without it the
//! memory check is off (`installed()`).

use std::alloc::{GlobalAlloc, Layout, System};
use std::cell::Cell;
use std::sync::atomic::{AtomicBool, Ordering};

/// The system allocator, counting per thread.
pub struct CountingAlloc;

static INSTALLED: AtomicBool = AtomicBool::new(false);

thread_local! {
    static LIVE: Cell<i64> = const { Cell::new(0) };
    static PEAK: Cell<i64> = const { Cell::new(0) };
}

fn count(delta: i64) {
    if !INSTALLED.load(Ordering::Relaxed) {
        INSTALLED.store(true, Ordering::Relaxed);
    }
    // try_with: the thread's locals may be gone while it exits.
    let _ = LIVE.try_with(|live| {
        let v = live.get() + delta;
        live.set(v);
        let _ = PEAK.try_with(|p| {
            if v > p.get() {
                p.set(v)
            }
        });
    });
}

// SAFETY: every call is passed to the system allocator unchanged; the
// bookkeeping touches only const-initialised thread locals (no allocation).
unsafe impl GlobalAlloc for CountingAlloc {
    unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
        let p = System.alloc(layout);
        if !p.is_null() {
            count(layout.size() as i64);
        }
        p
    }

    unsafe fn alloc_zeroed(&self, layout: Layout) -> *mut u8 {
        let p = System.alloc_zeroed(layout);
        if !p.is_null() {
            count(layout.size() as i64);
        }
        p
    }

    unsafe fn dealloc(&self, ptr: *mut u8, layout: Layout) {
        System.dealloc(ptr, layout);
        count(-(layout.size() as i64));
    }

    unsafe fn realloc(&self, ptr: *mut u8, layout: Layout, new_size: usize) -> *mut u8 {
        let p = System.realloc(ptr, layout, new_size);
        if !p.is_null() {
            count(new_size as i64 - layout.size() as i64);
        }
        p
    }
}

impl CountingAlloc {
    /// For `#[global_allocator]`: also marks the counts as meaningful.
    pub const fn new() -> Self {
        CountingAlloc
    }
}

/// Whether the counting allocator is this program's (it has counted).
pub fn installed() -> bool {
    INSTALLED.load(Ordering::Relaxed)
}

/// Start measuring this thread's peak: returns its live bytes now.
pub fn mark() -> i64 {
    let live = LIVE.with(|l| l.get());
    PEAK.with(|p| p.set(live));
    live
}

/// This thread's peak live bytes since `mark`.
pub fn peak() -> i64 {
    PEAK.with(|p| p.get())
}

#[cfg(test)]
mod tests {
    #[test]
    fn without_the_allocator_nothing_is_counted() {
        // The unit-test binary runs on the system allocator.
        assert_eq!(super::mark(), 0);
        let v = vec![0u8; 1 << 20];
        assert_eq!(super::peak(), 0);
        drop(v);
        assert!(!super::installed());
    }
}
