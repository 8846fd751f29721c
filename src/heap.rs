//! The process heap across frames.
//!
//! A frame allocates the same buffers as the last one (tile outputs, the
//! film, the PRSS images) and frees them at its end. glibc's defaults hand
//! the freed top of the heap back to the kernel (above 128 KiB) and serve
//! large buffers by fresh mappings, so the kernel faults in and zeroes the
//! same pages again every frame: 3–6% of a glass-sphere frame on 2 threads
//! (BENCHMARKS.md, steady-state frames). Programs that render frame after
//! frame — `cargo bench --bench frame`, an interactive embedder — call
//! [`retain_freed_memory`] once at start. The CLI does not: its renders are
//! single frames, and `snell bench` reports each configuration's peak
//! resident memory, which memory kept from the one before would inflate.

/// Heap memory a process may keep after freeing it, for the next frame.
pub const RETAINED_BYTES: i32 = 1 << 30;

/// Largest buffer served from the heap rather than its own mapping (glibc's
/// ceiling for this setting); volumes and coefficient arrays stay mapped
/// separately and go back to the kernel when dropped.
pub const HEAP_BUFFER_BYTES: i32 = 32 << 20;

/// Keeps freed memory in the process for reuse (glibc on Linux; elsewhere
/// nothing to do). Returns whether the allocator took the settings.
pub fn retain_freed_memory() -> bool {
    #[cfg(all(target_os = "linux", target_env = "gnu"))]
    {
        // SAFETY: mallopt only changes allocator parameters; any value is
        // accepted or refused with a 0 return.
        unsafe {
            libc::mallopt(libc::M_TRIM_THRESHOLD, RETAINED_BYTES) == 1
                && libc::mallopt(libc::M_MMAP_THRESHOLD, HEAP_BUFFER_BYTES) == 1
        }
    }
    #[cfg(not(all(target_os = "linux", target_env = "gnu")))]
    {
        false
    }
}

/// Hands the free memory inside the heap back to the kernel (glibc's
/// `malloc_trim`; elsewhere nothing to do). Preparation frees large
/// transients in the worker threads' arenas (such as the classification's
/// per-slab results) which would otherwise stay resident: in `snell bench`'s scaling suite they raised the image-size
/// rows' peak from 139 to 522 MiB after the 1024³ rows.
pub fn release_free_memory() {
    #[cfg(all(target_os = "linux", target_env = "gnu"))]
    // SAFETY: malloc_trim only returns free pages to the kernel.
    unsafe {
        libc::malloc_trim(0);
    }
}

#[cfg(test)]
mod tests {
    #[test]
    #[cfg(all(target_os = "linux", target_env = "gnu"))]
    fn glibc_takes_the_settings() {
        assert!(super::retain_freed_memory());
    }
}
