//! Copies into memory that will not be read again soon, without pulling it into the cache.
//!
//! A finished band of pixels goes from a worker's cached planes into the framebuffer, which
//! is larger than the caches and is not read again during the render. Ordinary stores first
//! read each destination cache line from memory ("read for ownership") and then evict lines
//! the worker still needs; non-temporal stores (`movntdq`, SSE2, part of every x86_64 CPU)
//! write whole lines straight to memory, halving the copy's memory traffic.

/// Copies `src` into `dst`, bit for bit, as [`slice::copy_from_slice`] does, with
/// non-temporal stores on x86_64 (ordinary copies elsewhere and for the unaligned head and
/// tail). The stores are fenced before returning, so the copy is visible to any thread that
/// later synchronises with this one, as after an ordinary copy.
///
/// # Panics
/// If the slices differ in length (a programming error).
pub(crate) fn copy_streaming<T: Copy>(dst: &mut [T], src: &[T]) {
    assert_eq!(dst.len(), src.len(), "copy_streaming: lengths differ");
    #[cfg(target_arch = "x86_64")]
    {
        let bytes = std::mem::size_of_val(src);
        // Small copies gain nothing and stay in the cache.
        if bytes >= 4096 {
            // SAFETY: `dst` and `src` are distinct live slices (one borrowed mutably) of the
            // same `bytes`; `T: Copy` values may be copied byte for byte; every access stays
            // within `bytes`, and the 16-byte stores are at 16-byte aligned addresses.
            #[allow(unsafe_code)]
            unsafe {
                stream_bytes(
                    dst.as_mut_ptr().cast::<u8>(),
                    src.as_ptr().cast::<u8>(),
                    bytes,
                )
            };
            return;
        }
    }
    dst.copy_from_slice(src);
}

/// Copies `bytes` bytes from `src` to `dst` with 16-byte non-temporal stores, then fences.
///
/// # Safety
/// `src` must be valid for reads and `dst` for writes of `bytes` bytes, without overlap.
#[cfg(target_arch = "x86_64")]
#[allow(unsafe_code)]
unsafe fn stream_bytes(dst: *mut u8, src: *const u8, bytes: usize) {
    use std::arch::x86_64::{__m128i, _mm_loadu_si128, _mm_sfence, _mm_stream_si128};
    let head = dst.align_offset(16).min(bytes);
    // SAFETY: the caller's contract; offsets stay below `bytes`, and `dst + i` is 16-byte
    // aligned for every streamed chunk because `i` starts at `head`.
    unsafe {
        std::ptr::copy_nonoverlapping(src, dst, head);
        let mut i = head;
        while i + 64 <= bytes {
            let a = _mm_loadu_si128(src.add(i).cast::<__m128i>());
            let b = _mm_loadu_si128(src.add(i + 16).cast::<__m128i>());
            let c = _mm_loadu_si128(src.add(i + 32).cast::<__m128i>());
            let d = _mm_loadu_si128(src.add(i + 48).cast::<__m128i>());
            _mm_stream_si128(dst.add(i).cast::<__m128i>(), a);
            _mm_stream_si128(dst.add(i + 16).cast::<__m128i>(), b);
            _mm_stream_si128(dst.add(i + 32).cast::<__m128i>(), c);
            _mm_stream_si128(dst.add(i + 48).cast::<__m128i>(), d);
            i += 64;
        }
        while i + 16 <= bytes {
            let a = _mm_loadu_si128(src.add(i).cast::<__m128i>());
            _mm_stream_si128(dst.add(i).cast::<__m128i>(), a);
            i += 16;
        }
        std::ptr::copy_nonoverlapping(src.add(i), dst.add(i), bytes - i);
        _mm_sfence();
    }
}

#[cfg(test)]
mod tests {
    use super::copy_streaming;
    use glam::Vec3;

    /// Every length and misalignment of the destination around the streaming threshold and
    /// the 16/64-byte chunking copies exactly.
    #[test]
    fn copies_every_length_and_offset_exactly() {
        let src: Vec<u8> = (0..20_000u32).map(|i| (i * 7 + 3) as u8).collect();
        for len in [
            0, 1, 15, 16, 17, 63, 64, 65, 4095, 4096, 4097, 5000, 8191, 19_000,
        ] {
            for offset in 0..17 {
                let mut dst = vec![0xAAu8; len + 40];
                copy_streaming(&mut dst[offset..offset + len], &src[3..3 + len]);
                assert_eq!(
                    &dst[offset..offset + len],
                    &src[3..3 + len],
                    "{len} at {offset}"
                );
                assert!(
                    dst[..offset].iter().all(|&b| b == 0xAA),
                    "{len} at {offset}: head"
                );
                assert!(
                    dst[offset + len..].iter().all(|&b| b == 0xAA),
                    "{len} at {offset}: tail"
                );
            }
        }
    }

    #[test]
    fn copies_typed_values() {
        let src: Vec<Vec3> = (0..3000)
            .map(|i| Vec3::new(i as f32, -0.5, f32::NAN))
            .collect();
        let mut dst = vec![Vec3::ZERO; 3000];
        copy_streaming(&mut dst, &src);
        for (d, s) in dst.iter().zip(&src) {
            assert_eq!(
                d.to_array().map(f32::to_bits),
                s.to_array().map(f32::to_bits)
            );
        }
    }

    #[test]
    #[should_panic(expected = "lengths differ")]
    fn refuses_different_lengths() {
        copy_streaming(&mut [0u8; 3], &[0u8; 4]);
    }
}
