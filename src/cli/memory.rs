//! How freed memory goes back to the system. The pipelines allocate and
//! free buffers of a few megabytes per chunk or window (parsed statements,
//! plans, compensation jobs and results). With glibc's adaptive defaults
//! such a block is often handed back to the kernel when freed (mapped and
//! unmapped on its own, or trimmed off the top of the heap), and the next
//! window's buffers start on fresh pages, each a page fault and a page
//! cleared by the kernel. Fixed thresholds keep freed blocks for the next
//! window: `check` of the 100 000-target module of `scripts/bench` takes
//! about 7 000 page faults instead of 39 000, for the same peak memory.

/// Sets the allocator's thresholds (glibc on Linux; elsewhere nothing):
/// blocks of [`MMAP_THRESHOLD_BYTES`] and more are mapped on their own,
/// and free memory at the top of the heap is given back from
/// [`TRIM_THRESHOLD_BYTES`] on. Called once, before any thread starts.
pub fn keep_freed_memory() {
    #[cfg(all(target_os = "linux", target_env = "gnu"))]
    // SAFETY: mallopt only sets two parameters of the allocator; it is
    // called before any other thread exists.
    unsafe {
        libc::mallopt(libc::M_MMAP_THRESHOLD, MMAP_THRESHOLD_BYTES);
        libc::mallopt(libc::M_TRIM_THRESHOLD, TRIM_THRESHOLD_BYTES);
    }
}

/// Size from which a block is mapped on its own (glibc's largest: 32 MiB
/// on 64-bit systems).
pub const MMAP_THRESHOLD_BYTES: i32 = 32 << 20;

/// Free memory at the top of the heap beyond which it is given back.
pub const TRIM_THRESHOLD_BYTES: i32 = 64 << 20;
