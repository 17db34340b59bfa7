//! Gives freed heap memory back to the operating system at the few points where a long run
//! knows a large working set has just been released: after the dataset is read (its decoding
//! scratch is several GiB) and after each validation pass.
//!
//! It matters with jemalloc preloaded and its decay turned off (`tools/campaign.sh`,
//! docs/training.md "Memory"): that configuration makes a p training step up to twice
//! as fast as glibc, whose allocations over 32 MiB are fresh mappings faulted in page by page,
//! but it never returns anything by itself, and the campaign's two runs grew to 24 GB. jemalloc
//! is found at run time (`mallctl` in the process), so the binary needs no jemalloc of its own;
//! under glibc the equivalent is `malloc_trim`.

use std::ffi::{c_char, c_int, c_void, CStr};

type Mallctl = unsafe extern "C" fn(*const c_char, *mut c_void, *mut usize, *mut c_void, usize) -> c_int;

/// jemalloc's `MALLCTL_ARENAS_ALL`: the pseudo-arena index that addresses every arena.
const PURGE_ALL_ARENAS: &CStr = c"arena.4096.purge";

/// Which allocator answered.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Released {
    Jemalloc,
    Glibc,
    /// Only off glibc, where neither call exists.
    #[cfg_attr(all(target_os = "linux", target_env = "gnu"), allow(dead_code))]
    Unsupported,
}

fn mallctl() -> Option<Mallctl> {
    // SAFETY: dlsym with RTLD_DEFAULT only looks a symbol up; a non-null result named
    // `mallctl` is jemalloc's, whose signature is the one declared above.
    let sym = unsafe { libc::dlsym(libc::RTLD_DEFAULT, c"mallctl".as_ptr()) };
    (!sym.is_null()).then(|| unsafe { std::mem::transmute::<*mut c_void, Mallctl>(sym) })
}

/// Returns the allocator's free pages to the system.
pub fn release() -> Released {
    if let Some(ctl) = mallctl() {
        // SAFETY: a purge takes no input or output buffers.
        let rc = unsafe { ctl(PURGE_ALL_ARENAS.as_ptr(), std::ptr::null_mut(), std::ptr::null_mut(), std::ptr::null_mut(), 0) };
        if rc == 0 {
            return Released::Jemalloc;
        }
    }
    #[cfg(all(target_os = "linux", target_env = "gnu"))]
    {
        // SAFETY: malloc_trim only walks glibc's own free lists.
        unsafe { libc::malloc_trim(0) };
        Released::Glibc
    }
    #[cfg(not(all(target_os = "linux", target_env = "gnu")))]
    Released::Unsupported
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn release_reaches_the_allocator_this_process_runs_on() {
        // Without a preloaded jemalloc the test binary runs on the system allocator.
        let expected = if mallctl().is_some() {
            Released::Jemalloc
        } else if cfg!(all(target_os = "linux", target_env = "gnu")) {
            Released::Glibc
        } else {
            Released::Unsupported
        };
        let big: Vec<u8> = vec![1; 64 << 20];
        drop(big);
        assert_eq!(release(), expected);
    }
}
