//! Memory the allocator holds free, given back to the system.
//!
//! glibc's malloc keeps freed memory in its free lists and returns it only from the top of a
//! heap: a localizer worker of a 100-reader fleet, whose heap stayed at 54 MiB (heaptrack, at
//! 3 and at 6 minutes), grew in RSS by 20 MiB a minute as short-lived reads were allocated
//! among its long-lived phase series. The series now allocate little ([`crate::localize::series`]),
//! and the live localizer calls [`release_free`] every 10 s (docs/localize.md): the commands
//! hand it over as `localize::live::Settings::release_memory`, as the localizer crate knows
//! no allocator.

/// Returns the allocator's free memory to the system where the allocator allows it (glibc's
/// `malloc_trim`); elsewhere nothing.
pub fn release_free() {
    #[cfg(all(target_os = "linux", target_env = "gnu"))]
    // SAFETY: malloc_trim takes no pointers and only walks the allocator's own free lists
    // under its locks; it is safe to call from any thread at any time.
    unsafe {
        libc::malloc_trim(0);
    }
}
