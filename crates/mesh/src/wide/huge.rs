//! Fixed-length arrays for the wide BVH's nodes and triangle blocks, on transparent huge
//! pages when they are large.

/// Arrays at least this large go to transparent huge pages ([`HugeBuf`]).
const HUGE_MIN_BYTES: usize = 1 << 20;
/// The x86_64 / aarch64-4k transparent huge page size.
const HUGE_PAGE: usize = 2 << 20;

/// A fixed-length array of `Copy` elements (nodes, triangle blocks). At least
/// [`HUGE_MIN_BYTES`] long it is allocated 2 MiB-aligned, rounded up to whole 2 MiB pages,
/// and on Linux advised `MADV_HUGEPAGE` before it is written, so the kernel backs it with
/// transparent huge pages (when `/sys/kernel/mm/transparent_hugepage/enabled` is `always`
/// or `madvise`; with `never`, or if the advice fails, it is plain memory and works the same).
/// A random walk over the full dragon's ~80 MB of nodes and blocks misses the TLB on most
/// node visits with 4 KiB pages; Embree allocates its BVH on huge pages for the same reason.
pub(crate) struct HugeBuf<T: Copy> {
    ptr: std::ptr::NonNull<T>,
    len: usize,
    /// `None` for an empty buffer (dangling pointer, nothing allocated).
    layout: Option<std::alloc::Layout>,
}

// SAFETY: `HugeBuf` owns its elements like a `Box<[T]>`.
unsafe impl<T: Copy + Send> Send for HugeBuf<T> {}
// SAFETY: shared access only reads, like `&[T]`.
unsafe impl<T: Copy + Sync> Sync for HugeBuf<T> {}

impl<T: Copy> HugeBuf<T> {
    /// A copy of `items`. Aborts through [`std::alloc::handle_alloc_error`] when the memory
    /// cannot be allocated, as `Vec` does.
    pub(crate) fn from_slice(items: &[T]) -> Self {
        let bytes = size_of_val(items);
        if bytes == 0 {
            return Self {
                ptr: std::ptr::NonNull::dangling(),
                len: items.len(),
                layout: None,
            };
        }
        let huge = bytes >= HUGE_MIN_BYTES;
        let layout = if huge {
            std::alloc::Layout::from_size_align(
                bytes.next_multiple_of(HUGE_PAGE),
                HUGE_PAGE.max(align_of::<T>()),
            )
        } else {
            std::alloc::Layout::array::<T>(items.len())
        };
        // A slice's size always fits a layout, short of an address-space-sized slice.
        let layout = layout.unwrap_or_else(|_| panic!("{bytes} bytes do not fit a layout"));
        // SAFETY: `layout` has a non-zero size.
        let raw = unsafe { std::alloc::alloc(layout) };
        let Some(ptr) = std::ptr::NonNull::new(raw.cast::<T>()) else {
            std::alloc::handle_alloc_error(layout)
        };
        #[cfg(target_os = "linux")]
        if huge {
            // SAFETY: the range is the allocation just made, page-aligned (2 MiB) and a whole
            // number of pages long; the advice changes no contents. Failure is harmless.
            unsafe {
                libc::madvise(raw.cast(), layout.size(), libc::MADV_HUGEPAGE);
            }
        }
        // SAFETY: the allocation holds `items.len()` elements of `T`, suitably aligned, and
        // does not overlap `items`.
        unsafe { std::ptr::copy_nonoverlapping(items.as_ptr(), ptr.as_ptr(), items.len()) };
        Self {
            ptr,
            len: items.len(),
            layout: Some(layout),
        }
    }
}

impl<T: Copy> std::ops::Deref for HugeBuf<T> {
    type Target = [T];
    #[inline(always)]
    fn deref(&self) -> &[T] {
        // SAFETY: `ptr` holds `len` initialised elements (or is dangling with `len` zero-sized
        // elements / `len == 0`).
        unsafe { std::slice::from_raw_parts(self.ptr.as_ptr(), self.len) }
    }
}

impl<T: Copy> Clone for HugeBuf<T> {
    fn clone(&self) -> Self {
        Self::from_slice(self)
    }
}

impl<T: Copy> Drop for HugeBuf<T> {
    fn drop(&mut self) {
        if let Some(layout) = self.layout {
            // SAFETY: allocated in `from_slice` with exactly this layout.
            unsafe { std::alloc::dealloc(self.ptr.as_ptr().cast(), layout) };
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::wide::layout::{EMPTY_BLOCK, TriBlock};

    #[test]
    fn huge_buffers_hold_their_copy_on_both_paths() {
        // Below and above `HUGE_MIN_BYTES` (the second goes to 2 MiB-aligned huge pages),
        // and empty; clones are independent copies.
        for n in [0usize, 1, 1000, HUGE_MIN_BYTES / 4 + 17] {
            let items: Vec<u32> = (0..n as u32).map(|i| i.wrapping_mul(2654435761)).collect();
            let buf = HugeBuf::from_slice(&items);
            assert_eq!(&buf[..], &items[..], "{n} items");
            if size_of_val(&items[..]) >= HUGE_MIN_BYTES {
                assert_eq!(
                    buf.as_ptr() as usize % HUGE_PAGE,
                    0,
                    "huge buffer alignment"
                );
            }
            let copy = buf.clone();
            drop(buf);
            assert_eq!(&copy[..], &items[..], "{n} items, clone");
        }
        let blocks = HugeBuf::from_slice(&[EMPTY_BLOCK; 3]);
        assert_eq!(blocks.len(), 3);
        assert_eq!(blocks.as_ptr() as usize % align_of::<TriBlock>(), 0);
    }
}
