//! Copying a slice without the C library's slow case.
//!
//! glibc's `memcpy` moves copies from about 2 KiB up to its non-temporal threshold (about
//! 1 MiB) with `rep movsb`. Measured on this project's AMD EPYC VM (glibc 2.36), `rep movsb`
//! runs about 15 times slower (0.7 instead of 10–20 bytes a cycle) when the destination
//! lies 1 to 31 bytes past the source modulo 4 KiB. Two buffers of the same page-multiple
//! size allocated one after the other are exactly that far apart (the allocator's 16-byte
//! chunk header), so a hot copy between them can cost more than the work around it: the
//! analytical placer's density map, rebuilt from its fixed charge at every evaluation, spent
//! 18% of a toy placement run there. [`copy_slice`] copies such a pair in pieces of at most
//! 2 KiB, which the library moves with vector loads and stores; every other copy is one
//! `copy_from_slice`. The result is the same either way: a copy.
//!
//! ```
//! use a2perf_core::copy::copy_slice;
//! let src: Vec<f32> = (0..10_000).map(|i| i as f32).collect();
//! let mut dst = vec![0.0f32; 10_000];
//! copy_slice(&mut dst, &src);
//! assert_eq!(dst, src);
//! ```

/// The largest piece [`copy_slice`] hands to `copy_from_slice` when it splits a copy.
pub const PIECE_BYTES: usize = 2048;

/// How far past the source, modulo 4 KiB, a destination may lie and still be split (the slow
/// window measured is 1–31 bytes; the margin costs nothing).
const SLOW_WINDOW: usize = 64;

/// Copies `src` into `dst`, as `dst.copy_from_slice(src)`, in pieces of at most
/// [`PIECE_BYTES`] when the destination lies just past the source modulo 4 KiB and the copy is
/// longer than a piece (see the [module documentation](self)).
///
/// # Panics
///
/// If the lengths differ, as `copy_from_slice`.
///
/// ```
/// use a2perf_core::copy::copy_slice;
/// let mut dst = [0u8; 4];
/// copy_slice(&mut dst, &[1, 2, 3, 4]);
/// assert_eq!(dst, [1, 2, 3, 4]);
/// ```
#[inline]
pub fn copy_slice<T: Copy>(dst: &mut [T], src: &[T]) {
    assert_eq!(
        dst.len(),
        src.len(),
        "copy_slice: destination and source lengths differ"
    );
    let bytes = std::mem::size_of_val(src);
    let gap = (dst.as_ptr() as usize).wrapping_sub(src.as_ptr() as usize) % 4096;
    if bytes <= PIECE_BYTES || gap == 0 || gap >= SLOW_WINDOW {
        dst.copy_from_slice(src);
        return;
    }
    // `T` is not zero-sized here (the copy has more than a piece's bytes); an element larger
    // than a piece goes alone.
    let step = (PIECE_BYTES / std::mem::size_of::<T>()).max(1);
    for (d, s) in dst.chunks_mut(step).zip(src.chunks(step)) {
        d.copy_from_slice(s);
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    proptest! {
        /// Whatever the length and the distance between the buffers (the slow window
        /// included), the destination ends up equal to the source and nothing around it moves.
        #[test]
        fn copies_every_element_and_nothing_else(
            len in 0usize..6_000,
            gap in prop_oneof![1usize..64, 0usize..4_200],
            src_at in 0usize..64,
        ) {
            // One buffer holding both, so the gap between them is the one chosen.
            let total = src_at + len + gap + len + 64;
            let mut buf: Vec<u32> = (0..total as u32).map(|i| i.wrapping_mul(2_654_435_761)).collect();
            let before = buf.clone();
            let dst_at = src_at + len + gap;
            let (head, tail) = buf.split_at_mut(dst_at);
            copy_slice(&mut tail[..len], &head[src_at..src_at + len]);
            prop_assert_eq!(&buf[dst_at..dst_at + len], &before[src_at..src_at + len]);
            prop_assert_eq!(&buf[..dst_at], &before[..dst_at]);
            prop_assert_eq!(&buf[dst_at + len..], &before[dst_at + len..]);
        }
    }

    #[test]
    #[should_panic(expected = "lengths differ")]
    fn different_lengths_panic_as_copy_from_slice_does() {
        let mut dst = [0u8; 3];
        copy_slice(&mut dst, &[1, 2]);
    }
}
