//! Returning freed memory to the system between frames.
//!
//! glibc's allocator keeps freed memory in its arenas. When a method holds a large transient
//! state while the others allocate beside it (the incremental Delaunay's certificates, a few
//! hundred MB on the LAM head, on the frames it probes its update path), the holes it leaves
//! are fragmented by the others' live blocks and stay resident: the process's peak then grows
//! with the number of such frames, not with what it holds. `malloc_trim(0)` gives every free
//! page of every arena back (glibc ≥ 2.8 also inside the heap, not only at its top).

/// Gives the allocator's free pages back to the system (glibc's `malloc_trim(0)`; nothing
/// elsewhere). Costs about a millisecond per call; the run calls it once per frame.
#[cfg(all(target_os = "linux", target_env = "gnu"))]
#[allow(unsafe_code, reason = "one call into glibc, see the SAFETY note")]
pub fn release_free_memory() {
    // SAFETY: malloc_trim takes no pointers; it only walks glibc's own free lists under the
    // allocator's locks and is safe to call from any thread at any time.
    unsafe {
        libc::malloc_trim(0);
    }
}

/// Gives the allocator's free pages back to the system (glibc's `malloc_trim(0)`; nothing
/// elsewhere).
#[cfg(not(all(target_os = "linux", target_env = "gnu")))]
pub fn release_free_memory() {}
