//! Process start-up tuning of the C allocator, so frame-sized stage buffers are reused instead of mapped and unmapped for every stage.
//!
//! glibc serves allocations above its mmap threshold (128 KiB, raised on the fly up to 32 MiB)
//! with fresh mappings and returns them to the kernel when freed. Every stage of every group
//! allocates and frees buffers of 5–50 MB, so without this each buffer costs page faults on
//! first touch and a TLB shoot-down across the cores when it is unmapped: about a fifth of a
//! depth-path group's time went to the kernel. Raising the mmap and trim thresholds keeps freed
//! buffers in the heap for the next group; the peak resident size stays the same (it is set by
//! the largest group in flight), but the process no longer hands memory back after a long run.
//!
//! With the thresholds raised, every thread's arena would keep its own freed buffers, and the
//! small long-lived allocations a run keeps per group (signals, report rows) would pin pages
//! in each arena between them: the peak resident size grew by about a fifth from 20 to 2,000
//! small groups. One arena shares the freed buffers between the threads (README.md, "Whole sides",
//! has the figures).

/// Thresholds that keep every buffer of a 1280×1024 group in the heap.
#[cfg(all(target_os = "linux", target_env = "gnu"))]
const KEEP_BELOW_BYTES: i32 = 1 << 30;

/// Asks the allocator to keep freed buffers for reuse (glibc on Linux; elsewhere a no-op).
/// Call once at start-up, before the worker threads exist. Returns whether the allocator took
/// the setting.
pub fn keep_freed_buffers() -> bool {
    #[cfg(all(target_os = "linux", target_env = "gnu"))]
    {
        // glibc's <malloc.h>: M_TRIM_THRESHOLD = -1, M_MMAP_THRESHOLD = -3, M_ARENA_MAX = -8.
        const M_TRIM_THRESHOLD: i32 = -1;
        const M_MMAP_THRESHOLD: i32 = -3;
        const M_ARENA_MAX: i32 = -8;
        unsafe extern "C" {
            fn mallopt(param: i32, value: i32) -> i32;
        }
        // SAFETY: mallopt only changes allocator parameters; glibc documents both settings
        // and accepts any value in range, reporting failure through its return value.
        let (mmap, trim, arenas) = unsafe {
            (
                mallopt(M_MMAP_THRESHOLD, KEEP_BELOW_BYTES),
                mallopt(M_TRIM_THRESHOLD, KEEP_BELOW_BYTES),
                mallopt(M_ARENA_MAX, 1),
            )
        };
        mmap == 1 && trim == 1 && arenas == 1
    }
    #[cfg(not(all(target_os = "linux", target_env = "gnu")))]
    {
        false
    }
}

#[cfg(test)]
mod tests {
    #[test]
    #[cfg(all(target_os = "linux", target_env = "gnu"))]
    fn glibc_takes_the_thresholds() {
        assert!(super::keep_freed_buffers());
    }
}
