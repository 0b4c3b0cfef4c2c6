//! Arrays on 2 MiB pages where the kernel offers them (Linux transparent huge pages in
//! `madvise` mode, the common default). The plane table is read at random: on 4 KiB pages
//! nearly every fetch from its 12 MiB also missed the TLB and waited for a page walk, which
//! its prefetches cannot hide. Elsewhere, or when the kernel declines, this is plain memory.
//!
//! Written by hand because it is a dozen lines over `std::alloc`: the allocation must be
//! aligned to 2 MiB and advised before its first touch, which neither `Vec` nor the mapping
//! crates offer together.

use std::alloc::{alloc, dealloc, handle_alloc_error, Layout};
use std::mem::MaybeUninit;
use std::ops::{Deref, DerefMut};
use std::ptr::NonNull;

use rayon::prelude::*;

const LARGE_PAGE: usize = 2 << 20;

/// `len` values in one allocation that starts on a 2 MiB boundary when it is that large.
pub struct LargePageVec<T: Copy> {
    ptr: NonNull<T>,
    len: usize,
    layout: Layout,
}

// SAFETY: it owns its values as a Vec would.
unsafe impl<T: Copy + Send> Send for LargePageVec<T> {}
unsafe impl<T: Copy + Sync> Sync for LargePageVec<T> {}

impl<T: Copy + Send + Sync> LargePageVec<T> {
    /// Written in parallel, a large page at a time: the first write to a fresh page is where
    /// the kernel clears it, about as long as building the plane table itself on one thread.
    pub fn filled(value: T, len: usize) -> Self {
        let bytes = len.checked_mul(std::mem::size_of::<T>()).expect("array size overflows");
        let align = if bytes >= LARGE_PAGE { LARGE_PAGE } else { std::mem::align_of::<T>() };
        let layout = Layout::from_size_align(bytes, align).expect("array layout");
        if bytes == 0 {
            return LargePageVec { ptr: NonNull::dangling(), len, layout };
        }
        // SAFETY: the layout has a non-zero size; every value is written before any is read.
        let ptr = unsafe {
            let raw = alloc(layout) as *mut T;
            let Some(ptr) = NonNull::new(raw) else { handle_alloc_error(layout) };
            advise_large_pages(raw as usize, bytes);
            let slots = std::slice::from_raw_parts_mut(raw as *mut MaybeUninit<T>, len);
            let per_page = (LARGE_PAGE / std::mem::size_of::<T>().max(1)).max(1);
            slots.par_chunks_mut(per_page).for_each(|page| page.iter_mut().for_each(|slot| {
                slot.write(value);
            }));
            ptr
        };
        LargePageVec { ptr, len, layout }
    }
}

#[cfg(target_os = "linux")]
fn advise_large_pages(address: usize, bytes: usize) {
    if bytes >= LARGE_PAGE {
        // SAFETY: the range lies inside one live allocation; the advice only changes how the
        // kernel backs it, and a refusal leaves ordinary pages.
        unsafe {
            libc::madvise(address as *mut libc::c_void, bytes - bytes % LARGE_PAGE, libc::MADV_HUGEPAGE);
        }
    }
}

#[cfg(not(target_os = "linux"))]
fn advise_large_pages(_: usize, _: usize) {}

impl<T: Copy> Drop for LargePageVec<T> {
    fn drop(&mut self) {
        if self.layout.size() != 0 {
            // SAFETY: allocated in `filled` with this layout; the values need no drop (Copy).
            unsafe { dealloc(self.ptr.as_ptr() as *mut u8, self.layout) }
        }
    }
}

impl<T: Copy> Deref for LargePageVec<T> {
    type Target = [T];
    #[inline(always)]
    fn deref(&self) -> &[T] {
        // SAFETY: `len` initialised values live at `ptr` while self does.
        unsafe { std::slice::from_raw_parts(self.ptr.as_ptr(), self.len) }
    }
}

impl<T: Copy> DerefMut for LargePageVec<T> {
    #[inline(always)]
    fn deref_mut(&mut self) -> &mut [T] {
        // SAFETY: as for deref, and self is borrowed mutably.
        unsafe { std::slice::from_raw_parts_mut(self.ptr.as_ptr(), self.len) }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn large_arrays_start_on_a_page_boundary_and_hold_their_values() {
        let mut v = LargePageVec::filled([7u64; 16], 3 * LARGE_PAGE / 128 + 5);
        assert_eq!(v.as_ptr() as usize % LARGE_PAGE, 0);
        assert_eq!(v.len(), 3 * LARGE_PAGE / 128 + 5);
        assert!(v.iter().all(|m| *m == [7u64; 16]));
        v[4] = [1; 16];
        assert_eq!(v[4], [1; 16]);
    }

    #[test]
    fn small_and_empty_arrays_are_plain() {
        let v = LargePageVec::filled(1u8, 10);
        assert_eq!(&v[..], &[1u8; 10]);
        assert!(LargePageVec::filled(0u32, 0).is_empty());
    }
}
