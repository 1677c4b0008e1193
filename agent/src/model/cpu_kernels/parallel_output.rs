//! New kernel outputs, written in parallel chunks.
//!
//! An output made by `vec![0.0; n]` is zeroed by the calling thread alone before the parallel
//! pass overwrites it; over a batch-8 training step those serial fills were about a sixth of
//! the main thread's own work. Here each chunk is zeroed by the thread that fills it, just
//! before, while its cache lines are being written anyway.

use std::mem::MaybeUninit;

use rayon::prelude::*;

/// A new vector of `len` values, in chunks of `chunk` values (the last one shorter if need
/// be): `fill(k, values)` writes the `k`-th, handed over zeroed. Chunks run in parallel unless
/// there is only one; `fill`'s results come back in chunk order.
///
/// Panics if `chunk` is 0.
pub fn filled_in_chunks_with<R: Send>(
    len: usize,
    chunk: usize,
    fill: impl Fn(usize, &mut [f32]) -> R + Sync,
) -> (Vec<f32>, Vec<R>) {
    assert!(chunk > 0, "chunk length 0");
    let mut output = Vec::with_capacity(len);
    let slots = &mut output.spare_capacity_mut()[..len];
    let results = if len <= chunk {
        vec![fill(0, zeroed(slots))]
    } else {
        slots
            .par_chunks_mut(chunk)
            .enumerate()
            .map(|(k, slots)| fill(k, zeroed(slots)))
            .collect()
    };
    // SAFETY: `zeroed` initialised every one of the first `len` slots above (a panic in
    // `fill` unwinds past this line, leaving `output` empty).
    unsafe { output.set_len(len) };
    (output, results)
}

/// [`filled_in_chunks_with`] for a `fill` with no result.
pub fn filled_in_chunks(
    len: usize,
    chunk: usize,
    fill: impl Fn(usize, &mut [f32]) + Sync,
) -> Vec<f32> {
    filled_in_chunks_with(len, chunk, fill).0
}

/// `len` zeros, written in parallel (for outputs that a parallel `gemm` writes over).
pub fn zeros(len: usize) -> Vec<f32> {
    filled_in_chunks(len, ZERO_CHUNK, |_, _| {})
}

/// Chunk length for [`zeros`]: 256 KiB per task.
const ZERO_CHUNK: usize = 64 * 1024;

fn zeroed(slots: &mut [MaybeUninit<f32>]) -> &mut [f32] {
    slots.fill(MaybeUninit::new(0.0));
    // SAFETY: every slot was initialised just above, and `MaybeUninit<f32>` has the layout of
    // `f32`.
    unsafe { &mut *(slots as *mut [MaybeUninit<f32>] as *mut [f32]) }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_chunk_is_zeroed_filled_once_and_in_order() {
        for (len, chunk) in [(0, 4), (3, 4), (4, 4), (10, 4), (100_000, 1000)] {
            let (output, firsts) = filled_in_chunks_with(len, chunk, |k, values| {
                assert!(values.iter().all(|&v| v == 0.0), "chunk {k} not zeroed");
                for (i, v) in values.iter_mut().enumerate() {
                    *v += (k * chunk + i) as f32;
                }
                k * chunk
            });
            let expected: Vec<f32> = (0..len).map(|i| i as f32).collect();
            assert_eq!(output, expected, "len {len}, chunk {chunk}");
            let chunks = len.div_ceil(chunk).max(1);
            assert_eq!(firsts, (0..chunks).map(|k| k * chunk).collect::<Vec<_>>());
        }
        assert_eq!(zeros(200_000), vec![0.0; 200_000]);
    }
}
