//! Buffers read into the caches, in order, before a pass reads them out of order.

/// Read one element of each 64-byte line of `buffer`, in order. Between two renderings
/// the work of their caller (a PGM's planes, several megabytes) pushes the renderer's
/// buffers out of the caches, and the passes read them at scattered pixels: pass 1 its
/// depth keys, pass 2 its sums (16 bytes a pixel of the valid pixels' box: 3.5 MB for
/// the benchmarks' 640×480 catadioptric camera), each access then waiting on memory.
/// Read in order first, the hardware prefetchers stream them in at the memory's
/// bandwidth (`docs/RESULTS.md`, "Speed"). Only the time depends on it.
#[inline(always)]
pub(super) fn read_in<T: Copy>(buffer: &[T]) {
    let per_line = (64 / size_of::<T>().max(1)).max(1);
    for line in buffer.iter().step_by(per_line) {
        std::hint::black_box(*line);
    }
}
