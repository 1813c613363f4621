//! Which candidates a global search keeps: the screening's selection on each score and
//! the bound that spares comparing the candidates it could never select, and the
//! descents that go on to a refinement.

use ucm::Isometry3;

use super::GlobalConfig;

/// A candidate: its score, its node and its orientation (indices).
pub(super) type Candidate = (f64, usize, usize);

/// Which orientations `Servo::search_cost` compares.
#[derive(Clone, Copy, Debug)]
pub(super) enum Compared {
    /// Every one whose scores could be at most this (on the common support; the others'
    /// stay infinite).
    Bounded(f64),
    /// This one alone.
    Only(usize),
}

impl Compared {
    pub(super) fn wants(self, orientation: usize) -> bool {
        match self {
            Self::Bounded(_) => true,
            Self::Only(o) => o == orientation,
        }
    }

    /// Whether a lower bound of a candidate's scores puts it beyond the bound: it
    /// would not be among the best of either list.
    pub(super) fn beyond_bound(self, lower: f64) -> bool {
        matches!(self, Self::Bounded(bound) if lower > bound)
    }
}

/// The bound of the screening on the common support, from the scores so far: a
/// candidate with a score above it in both lists is not among the `count` best that
/// `select` takes from each (it may take up to `2 count` from one list, when the other's
/// are taken already).
pub(super) fn screening_bound(
    screened: &[Candidate],
    squared: &[Candidate],
    count: usize,
    ranks: &mut Vec<f64>,
) -> f64 {
    let depth = 2 * count;
    worst_kept(screened, depth, ranks).max(worst_kept(squared, depth, ranks))
}

/// The `depth`-th best score of `list` (infinite while it holds fewer): a candidate
/// scoring above it cannot be among `list`'s `depth` best, whatever comes after.
fn worst_kept(list: &[Candidate], depth: usize, ranks: &mut Vec<f64>) -> f64 {
    if depth == 0 || list.len() < depth {
        return f64::INFINITY;
    }
    ranks.clear();
    ranks.extend(list.iter().map(|c| c.0));
    *ranks.select_nth_unstable_by(depth - 1, f64::total_cmp).1
}

/// The candidates that descend: the `screened` best by cost; on the common support
/// the `screened` best by each score, in turn (the correlation finds a photograph's
/// pose where small smooth supports fool the squared difference, which tells apart
/// renderings whose PGMs differ in contrast alone: either list alone loses poses the
/// other finds).
pub(super) fn select(
    mut screened: Vec<Candidate>,
    mut squared: Vec<Candidate>,
    common: bool,
    count: usize,
) -> Vec<Candidate> {
    let order =
        |a: &Candidate, b: &Candidate| a.0.total_cmp(&b.0).then(a.1.cmp(&b.1)).then(a.2.cmp(&b.2));
    screened.sort_by(order);
    if !common {
        screened.truncate(count);
        return screened;
    }
    squared.sort_by(order);
    let target = 2 * count;
    let mut merged: Vec<Candidate> = Vec::with_capacity(target);
    let mut lists = [screened.iter(), squared.iter()];
    'merge: while merged.len() < target {
        let mut any = false;
        for list in &mut lists {
            for &(score, index, orientation) in list.by_ref() {
                any = true;
                if !merged.iter().any(|m| (m.1, m.2) == (index, orientation)) {
                    merged.push((score, index, orientation));
                    break;
                }
            }
            if merged.len() == target {
                break 'merge;
            }
        }
        if !any {
            break;
        }
    }
    merged
}

/// The descents refined: the best by rank, and up to [`GlobalConfig::refined`] in all
/// ranked within [`GlobalConfig::refine_within`] of it, each farther than the merge
/// distance ([`GlobalConfig::merge_distance_m`], at most a quarter of the smallest grid
/// spacing) from every better one kept; the initial pose itself when every descent
/// diverged (its refinement says how).
pub(super) fn distinct_best(
    mut descended: Vec<(f64, (usize, usize), Isometry3)>,
    settings: &GlobalConfig,
    initial: Isometry3,
) -> Vec<((usize, usize), Isometry3)> {
    descended.sort_by(|a, b| a.0.total_cmp(&b.0).then(a.1.cmp(&b.1)));
    let merge_m = settings
        .grid_spacing_m
        .iter()
        .fold(settings.merge_distance_m, |m, &s| m.min(0.25 * s));
    let within = descended.first().map_or(f64::INFINITY, |best| {
        best.0 * (1.0 + settings.refine_within)
    });
    let mut kept: Vec<((usize, usize), Isometry3)> = Vec::with_capacity(settings.refined);
    for &(rank, index, pose) in &descended {
        if kept.len() == settings.refined || (!kept.is_empty() && rank > within) {
            break;
        }
        let duplicate = kept
            .iter()
            .any(|(_, other)| (pose.translation - other.translation).length() < merge_m);
        if !duplicate {
            kept.push((index, pose));
        }
    }
    if kept.is_empty() {
        kept.push(((usize::MAX, 0), initial));
    }
    kept
}

#[cfg(test)]
mod tests {
    use glam::DVec3;

    use super::*;

    /// The screening's bound leaves `select`'s choice as it is: candidates (each with
    /// both scores, as on the common support) come in batches, and those whose lower
    /// bound exceeds the bound computed before their batch are dropped.
    #[test]
    fn candidates_beyond_the_bound_are_never_selected() {
        let mut state = 0x9e37_79b9_7f4a_7c15u64;
        let mut next = move || {
            state ^= state << 13;
            state ^= state >> 7;
            state ^= state << 17;
            (state >> 11) as f64 / (1u64 << 53) as f64
        };
        let mut dropped_any = false;
        for case in 0..300 {
            let count = 1 + case % 7;
            let per_node = 1 + case % 5;
            let nodes = 5 + (next() * 60.0) as usize;
            let (mut all, mut all_squared) = (Vec::new(), Vec::new());
            let (mut kept, mut kept_squared) = (Vec::new(), Vec::new());
            let mut ranks = Vec::new();
            for batch in (0..nodes).collect::<Vec<_>>().chunks(1 + case % 4) {
                let bound = screening_bound(&kept, &kept_squared, count, &mut ranks);
                for &index in batch {
                    for orientation in 0..per_node {
                        // Coarse scores, so that ties occur.
                        let cost = (next() * 20.0).floor() / 20.0;
                        let squared = (next() * 20.0).floor() / 20.0;
                        let lower = cost.min(squared) - next() * 0.1;
                        all.push((cost, index, orientation));
                        all_squared.push((squared, index, orientation));
                        if Compared::Bounded(bound).beyond_bound(lower) {
                            dropped_any = true;
                            continue;
                        }
                        kept.push((cost, index, orientation));
                        kept_squared.push((squared, index, orientation));
                    }
                }
            }
            assert_eq!(
                select(all, all_squared, true, count),
                select(kept, kept_squared, true, count),
                "case {case}"
            );
        }
        assert!(dropped_any, "the bound never dropped a candidate");
    }

    /// The descents refined: the best, then those ranked within `refine_within` of it
    /// (at most `refined`), duplicates within the merge distance (at most a quarter of
    /// the grid spacing) left out.
    #[test]
    fn descents_ranked_alike_are_refined_and_duplicates_are_not() {
        let at = |x: f64| Isometry3::from_translation(DVec3::new(x, 0.0, 0.0));
        let descended = vec![
            (0.20, (2, 0), at(1.0)),
            (0.12, (1, 0), at(0.3)),
            (0.10, (0, 0), at(0.0)),
            (0.11, (3, 0), at(0.02)),
        ];
        let kept = |grid: f64, refined: usize| -> Vec<usize> {
            let settings = GlobalConfig {
                grid_spacing_m: [grid; 3],
                refined,
                ..GlobalConfig::default()
            };
            distinct_best(descended.clone(), &settings, at(9.0))
                .iter()
                .map(|(c, _)| c.0)
                .collect()
        };
        // A small box (0.2 m between nodes): 0.3 m apart are two basins.
        assert_eq!(kept(0.2, 3), vec![0, 1]);
        assert_eq!(kept(0.2, 1), vec![0]);
        // The city's grid (2 m): within the default 0.5 m they are one.
        assert_eq!(kept(2.0, 3), vec![0]);
        // Nothing ranked: the initial pose.
        let settings = GlobalConfig::default();
        let initial = distinct_best(Vec::new(), &settings, at(9.0));
        assert_eq!(initial[0].0.0, usize::MAX);
    }
}
