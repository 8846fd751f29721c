//! The process heap: memory kept across frames, and huge pages for the
//! large grids read at random.
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

/// Bytes of a transparent huge page on x86-64 Linux.
const HUGE_PAGE: usize = 2 << 20;

/// Asks the kernel to back `buf` with transparent huge pages (Linux's
/// `madvise(MADV_HUGEPAGE)` on the 2 MiB pages that lie wholly inside it;
/// elsewhere, or when the kernel declines, nothing changes). Call it before
/// the buffer is first written: pages already faulted in stay small.
///
/// Why: the solve reads each cell's 4³ coefficients from anywhere in a
/// grid of tens of megabytes (the teapot's is 93 MB of `f64`), where 4 KiB
/// pages make nearly every neighbourhood a TLB miss; one huge page covers
/// 512 small ones (teapot solve stage −6%, prefilter −12%: BENCHMARKS.md).
/// The walk's skip and distance maps are read the same way, a byte per
/// step (teapot traverse stage 8–10% less single thread).
pub fn advise_huge_pages<T>(buf: &mut [T]) {
    let bytes = std::mem::size_of_val(buf);
    if bytes < 2 * HUGE_PAGE {
        return;
    }
    #[cfg(target_os = "linux")]
    {
        let start = buf.as_mut_ptr() as usize;
        let lo = start.next_multiple_of(HUGE_PAGE);
        let hi = (start + bytes) / HUGE_PAGE * HUGE_PAGE;
        if lo < hi {
            // SAFETY: `[lo, hi)` lies inside `buf`, which this process owns;
            // MADV_HUGEPAGE changes only how its pages are backed, never
            // their contents, and an error leaves them as they were.
            unsafe {
                libc::madvise(lo as *mut libc::c_void, hi - lo, libc::MADV_HUGEPAGE);
            }
        }
    }
}

#[cfg(test)]
mod tests {
    #[test]
    #[cfg(all(target_os = "linux", target_env = "gnu"))]
    fn glibc_takes_the_settings() {
        assert!(super::retain_freed_memory());
    }

    /// Where the kernel offers transparent huge pages on request, an
    /// advised buffer gets them (else the advice was lost, e.g. on a wrong
    /// range), and its contents are what was written.
    #[test]
    #[cfg(target_os = "linux")]
    fn advised_buffers_get_huge_pages() {
        let mode = std::fs::read_to_string("/sys/kernel/mm/transparent_hugepage/enabled")
            .unwrap_or_default();
        // 64 MiB: above any mmap threshold glibc takes, so a fresh mapping.
        let mut buf = vec![0.0f64; 8 << 20];
        super::advise_huge_pages(&mut buf);
        for (i, v) in buf.iter_mut().enumerate() {
            *v = i as f64;
        }
        assert!(buf.iter().enumerate().all(|(i, &v)| v == i as f64));
        if !(mode.contains("[madvise]") || mode.contains("[always]")) {
            return;
        }
        // The advice splits the mapping: the advised part starts at the
        // buffer's first huge-page boundary.
        let at = (buf.as_ptr() as usize).next_multiple_of(super::HUGE_PAGE);
        let smaps = std::fs::read_to_string("/proc/self/smaps").unwrap();
        let mut inside = false;
        let mut huge_kb = None;
        for line in smaps.lines() {
            if let Some((range, _)) = line.split_once(' ')
                && let Some((lo, hi)) = range.split_once('-')
                && let (Ok(lo), Ok(hi)) =
                    (usize::from_str_radix(lo, 16), usize::from_str_radix(hi, 16))
            {
                inside = (lo..hi).contains(&at);
            } else if inside && let Some(kb) = line.strip_prefix("AnonHugePages:") {
                huge_kb = kb.trim().trim_end_matches(" kB").parse::<usize>().ok();
            }
        }
        let huge_kb = huge_kb.expect("the buffer's mapping in /proc/self/smaps");
        assert!(huge_kb >= 2048, "{huge_kb} kB in huge pages");
    }
}
