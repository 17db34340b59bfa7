//! The BVH's node and leaf arrays, on transparent huge pages where they are large. Traversal
//! of a BVH larger than the caches touches a few scattered nodes and leaves a ray; with 4 KiB
//! pages each is also a walk of the TLB (the displaced sphere's 5.6 MB are ~1,400 pages, past
//! the first-level TLB's reach), with 2 MiB pages four entries cover it all. Linux backs an
//! anonymous range with huge pages where it is aligned to 2 MiB and advised (`MADV_HUGEPAGE`;
//! `/sys/kernel/mm/transparent_hugepage/enabled` is `madvise` on most distributions). Where the
//! advice is refused or huge pages are off, the same memory stays on ordinary pages.

use std::alloc::Layout;
use std::ops::Deref;
use std::ptr::NonNull;

const HUGE_PAGE: usize = 2 << 20;

/// Arrays below this size stay in an ordinary `Vec`: 64 pages of 4 KiB, the reach of the
/// first-level TLB of the CPUs measured. Above it an array takes whole huge pages (up to 2 MiB
/// more memory than it needs).
const HUGE_MIN_BYTES: usize = 256 << 10;

/// An immutable array of `T`, on huge pages if it is at least `HUGE_MIN_BYTES` bytes.
pub(super) struct Pages<T: Copy> {
    /// `len` elements at `ptr`, owned by `owner` (so that reading them takes no branch on
    /// where they live).
    ptr: NonNull<T>,
    len: usize,
    owner: Owner<T>,
}

enum Owner<T> {
    /// Held only to free the buffer when dropped.
    #[allow(dead_code)]
    Vec(Vec<T>),
    /// Allocated with this layout (2 MiB aligned, whole huge pages).
    Huge(Layout),
}

// SAFETY: `Pages` owns its elements exclusively, like a `Vec<T>`, and never mutates them.
unsafe impl<T: Copy + Send> Send for Pages<T> {}
// SAFETY: as above; shared access only reads.
unsafe impl<T: Copy + Sync> Sync for Pages<T> {}

impl<T: Copy> Pages<T> {
    pub(super) fn new(v: Vec<T>) -> Pages<T> {
        let bytes = std::mem::size_of_val(v.as_slice());
        if bytes < HUGE_MIN_BYTES || !cfg!(target_os = "linux") || std::mem::align_of::<T>() > HUGE_PAGE {
            return Pages::in_vec(v);
        }
        let Ok(layout) = Layout::from_size_align(bytes.next_multiple_of(HUGE_PAGE), HUGE_PAGE) else {
            return Pages::in_vec(v);
        };
        // SAFETY: the layout has a non-zero size.
        let raw = unsafe { std::alloc::alloc(layout) };
        let Some(ptr) = NonNull::new(raw as *mut T) else {
            return Pages::in_vec(v);
        };
        // Advise before the copy touches the pages, so that its page faults map huge pages.
        #[cfg(target_os = "linux")]
        // SAFETY: the range is the allocation just made (2 MiB aligned, whole pages). The
        // advice only changes how it is backed; failure (an old kernel, THP off) is harmless.
        unsafe {
            libc::madvise(raw as *mut libc::c_void, layout.size(), libc::MADV_HUGEPAGE);
        }
        // SAFETY: `ptr` has room for `v.len()` elements (the layout is at least `bytes`) and is
        // aligned for `T` (2 MiB is a multiple of its alignment); the ranges do not overlap.
        unsafe { std::ptr::copy_nonoverlapping(v.as_ptr(), ptr.as_ptr(), v.len()) };
        Pages { ptr, len: v.len(), owner: Owner::Huge(layout) }
    }

    /// The elements in an ordinary `Vec` whatever their size (for A/B benchmarks).
    pub(super) fn in_vec(mut v: Vec<T>) -> Pages<T> {
        // The pointer stays valid as the `Vec` moves into `owner`: its buffer does not move.
        let ptr = NonNull::new(v.as_mut_ptr()).expect("a Vec's pointer is never null");
        Pages { ptr, len: v.len(), owner: Owner::Vec(v) }
    }

    /// Whether the elements are in a huge-page allocation (else an ordinary `Vec`).
    #[cfg(test)]
    fn is_huge(&self) -> bool {
        matches!(self.owner, Owner::Huge(_))
    }
}

impl<T: Copy> Deref for Pages<T> {
    type Target = [T];
    #[inline(always)]
    fn deref(&self) -> &[T] {
        // SAFETY: `len` initialised elements at `ptr`, owned by `self.owner` and alive as long
        // as `self`.
        unsafe { std::slice::from_raw_parts(self.ptr.as_ptr(), self.len) }
    }
}

impl<T: Copy> Clone for Pages<T> {
    fn clone(&self) -> Pages<T> {
        Pages::new(self.to_vec())
    }
}

impl<T: Copy> Drop for Pages<T> {
    fn drop(&mut self) {
        if let Owner::Huge(layout) = self.owner {
            // SAFETY: allocated in `new` with exactly this layout; `T: Copy` has no destructor.
            unsafe { std::alloc::dealloc(self.ptr.as_ptr() as *mut u8, layout) };
        }
    }
}

#[cfg(test)]
mod tests {
    use super::{Pages, HUGE_MIN_BYTES, HUGE_PAGE};

    #[test]
    fn small_and_huge_arrays_keep_their_contents() {
        for n in [0usize, 3, HUGE_MIN_BYTES / 8 - 1, HUGE_MIN_BYTES / 8, HUGE_PAGE / 8 + 12_345] {
            let v: Vec<u64> = (0..n as u64).map(|i| i.wrapping_mul(0x9E37_79B9_7F4A_7C15)).collect();
            let p = Pages::new(v.clone());
            assert_eq!(p.is_huge(), cfg!(target_os = "linux") && n * 8 >= HUGE_MIN_BYTES, "{n} elements");
            assert_eq!(&p[..], &v[..]);
            let q = p.clone();
            drop(p);
            assert_eq!(&q[..], &v[..]);
        }
    }
}
