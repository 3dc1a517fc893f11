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

/// Writes `src[i] * scale` into `dst[i]` for every `i` (one IEEE multiplication each, the
/// bits of the plain loop), with non-temporal stores on x86_64 as [`copy_streaming`] copies,
/// and returns whether any product is infinite or NaN (its exponent field all ones).
///
/// # Panics
/// If the slices differ in length (a programming error).
pub(crate) fn scale_streaming(dst: &mut [f32], src: &[f32], scale: f32) -> bool {
    assert_eq!(dst.len(), src.len(), "scale_streaming: lengths differ");
    const EXPONENT: u32 = 0x7f80_0000;
    let mut non_finite = false;
    let mut scalar = |dst: &mut [f32], src: &[f32]| {
        for (d, s) in dst.iter_mut().zip(src) {
            let v = *s * scale;
            *d = v;
            non_finite |= v.to_bits() & EXPONENT == EXPONENT;
        }
    };
    #[cfg(target_arch = "x86_64")]
    if std::mem::size_of_val(src) >= 4096 {
        use std::arch::x86_64::*;
        let head = dst.as_ptr().align_offset(16).min(dst.len());
        let body = (dst.len() - head) / 4 * 4;
        let (dh, rest) = dst.split_at_mut(head);
        let (db, dt) = rest.split_at_mut(body);
        let (sh, rest) = src.split_at(head);
        let (sb, st) = rest.split_at(body);
        scalar(dh, sh);
        scalar(dt, st);
        // SAFETY: SSE2 is part of every x86_64 CPU. Each chunk `s` holds 4 f32 (an
        // unaligned load); each `d` holds 4 f32 and starts on a 16-byte boundary (`head`
        // aligned the body), as the streaming store needs.
        #[allow(unsafe_code)]
        let any = unsafe {
            let (factor, mask) = (_mm_set1_ps(scale), _mm_set1_epi32(EXPONENT as i32));
            let mut any = _mm_setzero_si128();
            for (d, s) in db.chunks_exact_mut(4).zip(sb.chunks_exact(4)) {
                let v = _mm_mul_ps(_mm_loadu_ps(s.as_ptr()), factor);
                _mm_stream_ps(d.as_mut_ptr(), v);
                let e = _mm_and_si128(_mm_castps_si128(v), mask);
                any = _mm_or_si128(any, _mm_cmpeq_epi32(e, mask));
            }
            _mm_sfence();
            _mm_movemask_epi8(any) != 0
        };
        return non_finite || any;
    }
    scalar(dst, src);
    non_finite
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

    /// Every length and misalignment scales bit for bit as the plain loop, and the
    /// non-finite flag is set exactly when a product is infinite or NaN.
    #[test]
    fn scales_every_length_and_offset_exactly() {
        let src: Vec<f32> = (0..6000u32)
            .map(|i| f32::from_bits(i.wrapping_mul(2_654_435_761) & 0xbf7f_ffff))
            .collect();
        for len in [0, 1, 3, 4, 5, 1023, 1024, 1025, 1100, 5000] {
            for offset in 0..5 {
                for (scale, poison) in [
                    (0.25, None),
                    (1.0, Some(f32::NAN)),
                    (0.5, Some(f32::INFINITY)),
                ] {
                    let mut s = src[..len].to_vec();
                    if let (Some(p), true) = (poison, len > 0) {
                        s[len * 2 / 3] = p;
                    }
                    let mut dst = vec![7.0f32; len + 8];
                    let any = super::scale_streaming(&mut dst[offset..offset + len], &s, scale);
                    let want: Vec<u32> = s.iter().map(|v| (v * scale).to_bits()).collect();
                    let got: Vec<u32> = dst[offset..offset + len]
                        .iter()
                        .map(|v| v.to_bits())
                        .collect();
                    assert_eq!(got, want, "{len} at {offset}");
                    assert_eq!(any, poison.is_some() && len > 0, "{len} at {offset}");
                    assert!(
                        dst[..offset]
                            .iter()
                            .chain(&dst[offset + len..])
                            .all(|&v| v == 7.0)
                    );
                }
            }
        }
    }

    #[test]
    #[should_panic(expected = "lengths differ")]
    fn refuses_different_lengths() {
        copy_streaming(&mut [0u8; 3], &[0u8; 4]);
    }
}
