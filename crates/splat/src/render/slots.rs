//! A parallel rendering's threads, each on buffers of its own ([`Slots`]): every
//! batch of cells is cut into runs of about equal points, each run drawn by pass 1 on
//! plain keys of its own, the keys merged (their minimum) before the next batch's
//! occlusion tests; pass 2 cuts the kept splats into runs the same way, each adding to
//! sums of its own, the sums then added up. Minima and integer sums do not depend on
//! the order, and the batches and their occlusion tests are the single thread's, so
//! the image and the statistics are the same bits whatever the thread count; only the
//! runs' own early rejections in pass 1 (against their own keys) keep a few more
//! splats, which pass 2 rejects. No atomics: on two cores the shared atomic buffers
//! took twice one thread's time.

use rayon::prelude::*;
use ucm::Camera;

use crate::PackedPoint;

use super::culling::DrawCell;
use super::pass_one::widest_pass_one;
use super::pass_two::widest_pass_two;
use super::splat::Splat;
use super::view::View;

/// Most runs a parallel rendering cuts its work into (one set of buffers each).
pub(super) const MAX_RUNS: usize = 8;

/// Pixels merged at a time by one thread.
const MERGE_CHUNK: usize = 8192;

/// The buffers of the runs beyond the first (which draws on the renderer's own), kept
/// between renderings: their keys cleared ([`super::EMPTY`] where valid, 0 where
/// masked) and their sums zero once a rendering ends.
#[derive(Debug, Default)]
pub(super) struct Slots {
    depth: Vec<Vec<u32>>,
    accum: Vec<Vec<[u64; 2]>>,
    /// Whether every buffer is cleared (false while a rendering runs, and after one
    /// that did not end).
    cleared: bool,
}

impl Slots {
    /// Buffers for `runs − 1` more runs over a region whose cleared keys are
    /// `cleared_keys`, cleared (made when first asked for, then kept; cleared again
    /// only if a rendering did not end).
    pub(super) fn prepare(&mut self, runs: usize, cleared_keys: &[u32]) {
        let extra = runs.saturating_sub(1);
        let n = cleared_keys.len();
        if !self.cleared {
            for depth in &mut self.depth {
                depth.copy_from_slice(cleared_keys);
            }
            for accum in &mut self.accum {
                accum.fill([0; 2]);
            }
        }
        while self.depth.len() < extra {
            self.depth.push(cleared_keys.to_vec());
            self.accum.push(vec![[0; 2]; n]);
        }
        self.cleared = true;
    }

    /// Pass 1 of a batch of `cells` in `runs` runs, the first on `depth`; each run's
    /// kept splats moved to the front of `splats`, in run order. Returns their number.
    /// `depth` then holds every run's minimum, and so does each run's buffer.
    #[allow(clippy::too_many_arguments)]
    pub(super) fn draw_depth(
        &mut self,
        runs: usize,
        points: &[PackedPoint],
        cells: &[DrawCell],
        view: &View,
        camera: &Camera,
        depth: &mut [u32],
        splats: &mut [Splat],
    ) -> usize {
        self.cleared = false;
        let bounds = cut(cells, runs);
        let mut jobs: [(&[DrawCell], &mut [Splat], usize); MAX_RUNS] =
            std::array::from_fn(|_| (&[][..], &mut [][..], 0));
        let mut rest = &mut *splats;
        for (job, window) in jobs.iter_mut().zip(bounds.windows(2)) {
            let run = &cells[window[0]..window[1]];
            let n: usize = run.iter().map(|c| c.count as usize).sum();
            let (head, tail) = std::mem::take(&mut rest).split_at_mut(n);
            *job = (run, head, 0);
            rest = tail;
        }
        let (first, others) = jobs[..runs].split_at_mut(1);
        rayon::join(
            || {
                let (run, splats, kept) = &mut first[0];
                *kept = widest_pass_one(points, run, view, camera, depth, splats);
            },
            || {
                others
                    .par_iter_mut()
                    .zip(&mut self.depth[..runs - 1])
                    .for_each(|((run, splats, kept), depth)| {
                        *kept = widest_pass_one(points, run, view, camera, depth, splats);
                    });
            },
        );
        let kept: [usize; MAX_RUNS] = std::array::from_fn(|k| jobs[k].2);
        // The runs' kept splats one after the other.
        let mut total = 0;
        let mut start = 0;
        for (window, &k) in bounds.windows(2).zip(&kept) {
            let n: usize = cells[window[0]..window[1]]
                .iter()
                .map(|c| c.count as usize)
                .sum();
            splats.copy_within(start..start + k, total);
            total += k;
            start += n;
        }
        // Every buffer takes the minimum of all (the occlusion tests and the next
        // batch's early rejections see every run's points).
        let others = &self.depth[..runs - 1];
        depth
            .par_chunks_mut(MERGE_CHUNK)
            .enumerate()
            .for_each(|(index, chunk)| {
                let offset = index * MERGE_CHUNK;
                for other in others {
                    for (key, &o) in chunk.iter_mut().zip(&other[offset..]) {
                        *key = (*key).min(o);
                    }
                }
            });
        for other in &mut self.depth[..runs - 1] {
            other.copy_from_slice(depth);
        }
        total
    }

    /// Pass 2 of `splats` in `runs` runs, the first adding to `accum`, the others to
    /// their own sums, then added to `accum` (and zeroed); every run reads `depth`.
    /// The runs' keys are cleared (`cleared_keys`) for the next rendering.
    pub(super) fn accumulate(
        &mut self,
        runs: usize,
        splats: &[Splat],
        view: &View,
        depth: &[u32],
        accum: &mut [[u64; 2]],
        cleared_keys: &[u32],
    ) {
        let per_run = splats.len().div_ceil(runs).max(1);
        let (first, rest) = splats.split_at(per_run.min(splats.len()));
        rayon::join(
            || widest_pass_two(first, view, depth, accum),
            || {
                rest.par_chunks(per_run)
                    .zip(self.accum[..runs - 1].par_iter_mut())
                    .for_each(|(splats, sums)| widest_pass_two(splats, view, depth, sums));
            },
        );
        // The runs' sums added up (and zeroed for the next rendering).
        let others = &mut self.accum[..runs - 1];
        accum
            .par_chunks_mut(MERGE_CHUNK)
            .enumerate()
            .for_each(|(index, chunk)| {
                let offset = index * MERGE_CHUNK;
                for other in others.iter() {
                    for (total, s) in chunk.iter_mut().zip(&other[offset..]) {
                        *total = [total[0] + s[0], total[1] + s[1]];
                    }
                }
            });
        for sums in others.iter_mut() {
            sums.fill([0; 2]);
        }
        for keys in &mut self.depth[..runs - 1] {
            keys.copy_from_slice(cleared_keys);
        }
        self.cleared = true;
    }
}

#[cfg(test)]
impl Slots {
    /// Every buffer made nonsense (keys 0, sums 1), as a rendering that stopped
    /// midway could leave them, and marked `cleared` or not.
    pub(super) fn poison(&mut self, cleared: bool) {
        for depth in &mut self.depth {
            depth.fill(0);
        }
        for accum in &mut self.accum {
            accum.fill([1, 1]);
        }
        self.cleared = cleared;
    }
}

/// The first cell of each of `runs` runs of about equal points, and the end
/// (`runs + 1` bounds; runs may be empty).
fn cut(cells: &[DrawCell], runs: usize) -> [usize; MAX_RUNS + 1] {
    let total: usize = cells.iter().map(|c| c.count as usize).sum();
    let mut bounds = [cells.len(); MAX_RUNS + 1];
    bounds[0] = 0;
    let mut run = 1;
    let mut acc = 0;
    for (k, c) in cells.iter().enumerate() {
        if run >= runs {
            break;
        }
        acc += c.count as usize;
        if acc * runs >= total * run {
            bounds[run] = k + 1;
            run += 1;
        }
    }
    bounds
}
