//! Sweeps: the first and largest part of the global collapse order, run piece by piece.
//!
//! The engine collapses in one global order of cost (Garland and Heckbert 1997; Azim et al.
//! 2014, section 6.2, step 3), kept by one queue. On a mesh that falls into many separate
//! pieces, such as the QEM baseline's expanded maple (a copy of every leaf), that queue visits
//! memory at random and the loop waits on cache misses. But pieces share no edge: a collapse
//! in one never changes a cost in another. So:
//! - the single queue, watched on one piece, pops exactly what the piece's own queue pops;
//! - for any key θ, the single queue's state when it first pops a key above θ is every piece
//!   run on its own queue until its next key is above θ.
//!
//! A sweep builds that state piece after piece, in memory order, so that each piece stays in
//! cache while it runs. The first sweep is the largest, and most of the work: there a pilot
//! group in [`PILOT_STRIDE`] sweeps alone, in small steps, until its removals, scaled up,
//! promise [`MAIN_SHARE`] of the excess; then every other group runs straight to the pilots'
//! key, each visited once while its piece is in cache. Any schedule of keys reaches the single
//! queue's state, so long as every group ends at the same key. The ordinary sweeps that follow
//! each aim to remove [`SHARE`] of the triangles still over the target, choosing θ from a
//! sample of the queued keys. Once little is left, the pieces' queues pour into the single
//! queue, which finishes the run in strict order.
//!
//! Pieces are also independent in memory, so on a large mesh the sweeps run in parallel, one
//! part of the workspace (whole pieces, see [`super::workspace`]) per thread. A group's sweep
//! does not depend on where it runs, so the result is the same with any number of threads.
//!
//! The one case the argument does not cover: a sweep that reaches the target. The single queue
//! would have stopped somewhere inside it, so the state is not one the strict order passes
//! through. The sweep reports it, and the caller starts again in one queue.

use std::sync::atomic::{AtomicBool, AtomicI64, Ordering};

use rayon::prelude::*;

use super::{Candidate, Part, RadixHeap, RunStats, Step};

/// Share of the remaining excess (triangles over the target) a sweep aims to remove. Sweeps
/// remove less than they aim at (candidates fail their checks, and a collapse spoils its
/// neighbours' candidates), so half keeps a sweep well clear of the target.
const SHARE: f64 = 0.5;
/// The sweeps stop once the excess falls below this fraction of the first one: the single
/// queue does the rest.
const TAIL: f64 = 1.0 / 64.0;
/// At most this many sweeps.
const MAX_SWEEPS: usize = 16;
/// Pieces join consecutive pieces into groups of at least this many position vertices, so
/// that a mesh of many tiny pieces does not pay for a queue per piece.
const GROUP_VERTICES: usize = 256;
/// One group in this many is a pilot of the first sweep (see [`pilot_then_main`]).
const PILOT_STRIDE: usize = 16;
/// Fewest pilot groups worth the estimate: with fewer, the first sweep is an ordinary one.
const MIN_PILOTS: usize = 32;
/// Share of the excess the first sweep aims at from the pilots' estimate; the margin is for
/// the estimate's error (the ordinary sweeps that follow take the rest in smaller steps).
const MAIN_SHARE: f64 = 0.8;
/// Queued keys sampled to choose a sweep's θ.
const SAMPLE: usize = 1 << 14;
/// Fewest positions a part must get for the workspace to load one part per thread (below
/// it, a second thread saves less than it costs), and half the fewest for sweeps (a smaller
/// mesh fits in cache as it is, and a sweep over few pieces is the likelier to overshoot).
const PART_VERTICES: usize = 1 << 15;

/// The sweeps' tuning, a field of every workspace so that tests can force each path.
#[derive(Debug, Clone, Copy)]
pub(crate) struct Settings {
    /// Share of the excess a sweep aims at ([`SHARE`]); 0 runs one queue from the start.
    pub share: f64,
    /// Fewest positions a part may get, and half the fewest for sweeps ([`PART_VERTICES`]).
    pub part_vertices: usize,
    /// One group in this many pilots the first sweep ([`PILOT_STRIDE`]).
    pub pilot_stride: usize,
    /// Fewest pilots for a piloted first sweep ([`MIN_PILOTS`]).
    pub min_pilots: usize,
    /// Share of the excess the piloted first sweep aims at ([`MAIN_SHARE`]).
    pub main_share: f64,
}

impl Default for Settings {
    fn default() -> Self {
        Self {
            share: SHARE,
            part_vertices: PART_VERTICES,
            pilot_stride: PILOT_STRIDE,
            min_pilots: MIN_PILOTS,
            main_share: MAIN_SHARE,
        }
    }
}

/// What the sweeps of a run did.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum Outcome {
    /// No sweep ran (one queue throughout).
    None,
    /// Sweeps ran and handed over to the single queue.
    Swept,
    /// A sweep reached the target: the caller ran again in one queue.
    ReachedTarget,
}

/// A group's own queue.
type Queue = RadixHeap<Candidate>;

/// A part's groups and their queues, while the sweeps run.
struct Lane {
    queues: Vec<Queue>,
    stats: RunStats,
}

impl Lane {
    /// The count a lane's statistics start from: they only ever go down by its removals.
    const START: u64 = u64::MAX / 2;
}

/// Sweeps the start of the collapse order over `parts`: a piloted first sweep, then sweeps
/// each aiming to remove `settings.share`
/// of the excess. Returns whether the parts' queues now hold the rest of the first round
/// (false: no sweep ran and nothing changed), or `None` when a sweep reached `target`,
/// leaving a state off the strict order.
pub(super) fn sweep(
    parts: &mut [Part],
    settings: Settings,
    stats: &mut RunStats,
    target: u64,
) -> Option<bool> {
    let share = settings.share;
    if stats.expanded <= target {
        return Some(false);
    }
    let groups: Vec<Vec<Vec<u32>>> = parts.par_iter().map(Part::groups).collect();
    if groups.iter().map(Vec::len).sum::<usize>() < 2 {
        return Some(false);
    }
    let mut lanes: Vec<Lane> = parts
        .par_iter_mut()
        .zip(groups)
        .map(|(part, groups)| Lane {
            queues: groups.iter().map(|g| part.seed_group(g)).collect(),
            stats: RunStats {
                expanded: Lane::START,
                ..RunStats::default()
            },
        })
        .collect();
    let first = stats.expanded - target;
    // How many more expanded triangles the sweeps may remove before they reach the target.
    let budget = AtomicI64::new(first as i64);
    let mut reached = !pilot_then_main(parts, &mut lanes, settings, first, &budget);
    for _ in 0..MAX_SWEEPS {
        if reached {
            break;
        }
        let excess = budget.load(Ordering::Relaxed);
        if (excess as f64) < TAIL * first as f64 {
            break;
        }
        let Some(theta) = threshold(parts, &lanes, Groups::All, share * excess as f64) else {
            break;
        };
        reached = !run_to(parts, &mut lanes, Groups::All, theta, &budget);
    }
    for lane in &lanes {
        stats.expanded -= Lane::START - lane.stats.expanded;
        stats.collapses += lane.stats.collapses;
        stats.error = stats.error.max(lane.stats.error);
    }
    if reached {
        return None;
    }
    parts.par_iter_mut().zip(lanes).for_each(|(part, lane)| {
        part.heap.clear();
        for &(key, c) in lane.queues.iter().flat_map(RadixHeap::items).flatten() {
            if part.is_current(&c) {
                part.heap.push(key, c);
            }
        }
    });
    Some(true)
}

impl Part {
    /// Runs one group's queue until its next key is above `theta`. False when the removals
    /// used up `budget` on the way (the count reached the target).
    fn sweep_queue(
        &mut self,
        queue: &mut Queue,
        theta: u64,
        stats: &mut RunStats,
        budget: &AtomicI64,
    ) -> bool {
        loop {
            let stamp = &self.stamp;
            let Some((_, c)) = queue.pop_valid_at_most(theta, |c| c.is_current(stamp)) else {
                return true;
            };
            let before = stats.expanded;
            if let Step::Collapsed(keep) = self.step(c, stats, f64::INFINITY) {
                let removed = (before - stats.expanded) as i64;
                if budget.fetch_sub(removed, Ordering::Relaxed) <= removed {
                    return false;
                }
                let ring = std::mem::take(&mut self.ring);
                for &u in &ring {
                    if let Some((key, entry)) = self.candidate(keep, u) {
                        queue.push(key, entry);
                    }
                }
                self.ring = ring;
            }
        }
    }

    /// Every edge of a group once (as [`Part::seed_heap`] queues them), into a new queue.
    fn seed_group(&mut self, group: &[u32]) -> Queue {
        let mut queue = Queue::default();
        for &v in group {
            self.collect_ring(v);
            let ring = std::mem::take(&mut self.ring);
            for &u in ring.iter().filter(|&&u| u > v) {
                if let Some((key, entry)) = self.candidate(v, u) {
                    queue.push(key, entry);
                }
            }
            self.ring = ring;
        }
        queue
    }

    /// The position vertices with triangles, by group: pieces (connected by triangles) in the
    /// order of their first vertex, consecutive ones joined until a group holds
    /// [`GROUP_VERTICES`].
    fn groups(&self) -> Vec<Vec<u32>> {
        let n = self.verts.len();
        let mut parent: Vec<u32> = (0..n as u32).collect();
        for t in &self.tris {
            let [a, b, c] = t.p;
            union(&mut parent, a, b);
            union(&mut parent, a, c);
        }
        // Every piece's root is its first vertex, so pieces come in order of it.
        let mut size = vec![0usize; n];
        for v in 0..n as u32 {
            let root = find(&mut parent, v);
            size[root as usize] += 1;
        }
        let mut group_of = vec![u32::MAX; n];
        let mut groups = 0u32;
        let mut filled = GROUP_VERTICES;
        for root in 0..n {
            if size[root] == 0 || parent[root] != root as u32 {
                continue;
            }
            if filled >= GROUP_VERTICES {
                groups += 1;
                filled = 0;
            }
            group_of[root] = groups - 1;
            filled += size[root];
        }
        let mut out = vec![Vec::new(); groups as usize];
        for v in 0..n as u32 {
            if self.verts[v as usize].adj_len > 0 {
                let root = find(&mut parent, v);
                out[group_of[root as usize] as usize].push(v);
            }
        }
        out.retain(|g| !g.is_empty());
        out
    }
}

/// Which groups a step of the sweeps runs.
#[derive(Clone, Copy, PartialEq, Eq)]
enum Groups {
    All,
    /// Every n-th group of each part.
    Pilot(usize),
    /// The others.
    Rest(usize),
}

impl Groups {
    fn has(self, g: usize) -> bool {
        match self {
            Groups::All => true,
            Groups::Pilot(n) => g.is_multiple_of(n),
            Groups::Rest(n) => !g.is_multiple_of(n),
        }
    }

    fn of<T>(self, queues: &[T]) -> impl Iterator<Item = &T> {
        queues
            .iter()
            .enumerate()
            .filter(move |&(g, _)| self.has(g))
            .map(|(_, q)| q)
    }
}

/// Runs the chosen groups of every part (in parallel) until their next key is above `theta`.
/// False when the removals used up `budget` (a sweep reached the target).
fn run_to(
    parts: &mut [Part],
    lanes: &mut [Lane],
    which: Groups,
    theta: u64,
    budget: &AtomicI64,
) -> bool {
    let stop = AtomicBool::new(false);
    parts.par_iter_mut().zip(lanes).for_each(|(part, lane)| {
        for (g, queue) in lane.queues.iter_mut().enumerate() {
            if !which.has(g) {
                continue;
            }
            if stop.load(Ordering::Relaxed)
                || !part.sweep_queue(queue, theta, &mut lane.stats, budget)
            {
                stop.store(true, Ordering::Relaxed);
                return;
            }
        }
    });
    !stop.into_inner()
}

/// Candidates queued in the chosen groups (current or stale).
fn queued(lanes: &[Lane], which: Groups) -> usize {
    lanes
        .iter()
        .flat_map(|l| which.of(&l.queues))
        .map(RadixHeap::len)
        .sum()
}

/// Expanded triangles the lanes removed so far.
fn removed(lanes: &[Lane]) -> u64 {
    lanes.iter().map(|l| Lane::START - l.stats.expanded).sum()
}

/// The first and largest sweep, in one pass: the pilot groups sweep on their own, in small
/// steps, until their removals, scaled by their share of the queued candidates, promise
/// [`MAIN_SHARE`] of the excess; every other group then runs once, straight to the pilots'
/// last key, while its piece is in cache. The state is again the single queue's at that key.
/// False when a step reached the target.
fn pilot_then_main(
    parts: &mut [Part],
    lanes: &mut [Lane],
    settings: Settings,
    first: u64,
    budget: &AtomicI64,
) -> bool {
    let stride = settings.pilot_stride.max(2);
    let groups: usize = lanes.iter().map(|l| l.queues.len()).sum();
    if groups < stride * settings.min_pilots {
        return true;
    }
    let scale =
        queued(lanes, Groups::All) as f64 / (queued(lanes, Groups::Pilot(stride)) as f64).max(1.0);
    let aim = settings.main_share * first as f64;
    let mut key = None;
    for _ in 0..MAX_SWEEPS {
        let promised = removed(lanes) as f64 * scale;
        if promised >= aim {
            break;
        }
        let share = SHARE * (aim - promised) / scale;
        let Some(theta) = threshold(parts, lanes, Groups::Pilot(stride), share) else {
            break;
        };
        if !run_to(parts, lanes, Groups::Pilot(stride), theta, budget) {
            return false;
        }
        key = Some(theta);
    }
    key.is_none_or(|theta| run_to(parts, lanes, Groups::Rest(stride), theta, budget))
}

/// The key up to which the queued current candidates would remove about `share` triangles,
/// at two per collapse times the submesh's instances (an estimate: some candidates fail their
/// checks, and collapses queue new ones). `None` when nothing is queued.
fn threshold(parts: &[Part], lanes: &[Lane], which: Groups, share: f64) -> Option<u64> {
    let total = queued(lanes, which);
    let stride = total.div_ceil(SAMPLE).max(1);
    let mut sample: Vec<(u64, u64)> = Vec::with_capacity(total / stride + lanes.len());
    for (part, lane) in parts.iter().zip(lanes) {
        let mut at = 0;
        for entries in which.of(&lane.queues).flat_map(RadixHeap::items) {
            while at < entries.len() {
                let (key, c) = &entries[at];
                if part.is_current(c) {
                    let instances = part.subs[part.vsub[c.p as usize] as usize].instances;
                    sample.push((*key, 2 * instances.max(1)));
                }
                at += stride;
            }
            at -= entries.len();
        }
    }
    sample.sort_unstable();
    let mut removed = 0.0;
    for &(key, weight) in &sample {
        removed += (weight * stride as u64) as f64;
        if removed >= share {
            return Some(key);
        }
    }
    sample.last().map(|&(key, _)| key)
}

/// The root of `x`'s piece, halving the path on the way.
pub(super) fn find(parent: &mut [u32], mut x: u32) -> u32 {
    while parent[x as usize] != x {
        let up = parent[parent[x as usize] as usize];
        parent[x as usize] = up;
        x = up;
    }
    x
}

/// Joins the pieces of `a` and `b` under the lesser root.
pub(super) fn union(parent: &mut [u32], a: u32, b: u32) {
    let (ra, rb) = (find(parent, a), find(parent, b));
    let (lo, hi) = (ra.min(rb), ra.max(rb));
    parent[hi as usize] = lo;
}

#[cfg(test)]
mod tests {
    //! The sweeps' promise: the same collapses as one queue, on any number of threads, and a
    //! sweep that reaches the target changes nothing.
    use glam::{Affine3A, Quat, Vec2, Vec3};
    use horizon_mesh::rng::Rng;
    use horizon_mesh::{Instance, InstancedMesh, Submesh};
    use proptest::prelude::*;

    use super::Outcome;
    use crate::{simplify_with, SimplifyOptions, Target, Workspace};

    /// `pieces` separate bumpy grids in one submesh, and a second submesh, bumpy too, placed
    /// three times (one mirrored). Random heights keep every cost distinct, so that no tie
    /// leaves the order to chance.
    fn pieces(pieces: usize, seed: u64) -> InstancedMesh {
        let mut rng = Rng::new(seed);
        let mut next = move || rng.unit();
        let n = 7u32;
        let mut grid = |origin: Vec3, sub: &mut Submesh| {
            let base = sub.positions.len() as u32;
            for j in 0..n {
                for i in 0..n {
                    let p = origin + Vec3::new(i as f32, j as f32, 0.4 * next());
                    sub.positions.push(p);
                    sub.uvs
                        .as_mut()
                        .expect("uvs")
                        .push(Vec2::new(i as f32, j as f32) / n as f32);
                }
            }
            for j in 0..n - 1 {
                for i in 0..n - 1 {
                    let a = base + j * n + i;
                    sub.indices
                        .extend([a, a + 1, a + n + 1, a, a + n + 1, a + n]);
                }
            }
        };
        let mut many = Submesh {
            uvs: Some(Vec::new()),
            ..Submesh::default()
        };
        for k in 0..pieces {
            grid(Vec3::new(10.0 * k as f32, 0.0, 0.0), &mut many);
        }
        let mut placed = Submesh {
            uvs: Some(Vec::new()),
            ..Submesh::default()
        };
        grid(Vec3::ZERO, &mut placed);
        let instances = vec![
            Instance {
                submesh: 0,
                transform: Affine3A::IDENTITY,
            },
            Instance {
                submesh: 1,
                transform: Affine3A::from_translation(Vec3::Y * 20.0),
            },
            Instance {
                submesh: 1,
                transform: Affine3A::from_scale_rotation_translation(
                    Vec3::new(1.0, 2.0, 0.5),
                    Quat::from_rotation_z(0.7),
                    Vec3::Y * 40.0,
                ),
            },
            Instance {
                submesh: 1,
                transform: Affine3A::from_scale(Vec3::new(-1.0, 1.0, 1.0)),
            },
        ];
        InstancedMesh {
            submeshes: vec![many, placed],
            instances,
            ..InstancedMesh::default()
        }
    }

    /// Simplifies `mesh` to `ratio` in a workspace with the given sweep share and smallest
    /// part, on `threads` threads; returns the mesh, the collapses and what the sweeps did.
    fn run(
        mesh: &InstancedMesh,
        ratio: f64,
        share: f64,
        part_vertices: usize,
        threads: usize,
    ) -> (InstancedMesh, u64, Outcome) {
        run_with(
            mesh,
            ratio,
            &SimplifyOptions::balanced(),
            share,
            part_vertices,
            super::PILOT_STRIDE,
            threads,
        )
    }

    /// [`run`] with `options`.
    fn run_with(
        mesh: &InstancedMesh,
        ratio: f64,
        options: &SimplifyOptions,
        share: f64,
        part_vertices: usize,
        pilot_stride: usize,
        threads: usize,
    ) -> (InstancedMesh, u64, Outcome) {
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()
            .expect("a thread pool");
        pool.install(|| {
            let mut ws = Workspace::new();
            ws.sweep.share = share;
            ws.sweep.main_share = share.max(super::MAIN_SHARE);
            ws.sweep.part_vertices = part_vertices;
            ws.sweep.pilot_stride = pilot_stride;
            ws.sweep.min_pilots = 2;
            let out =
                simplify_with(mesh, Target::Ratio(ratio), options, &mut ws).expect("a valid mesh");
            ws.validate().expect("a valid workspace");
            (out.mesh, out.report.collapses, ws.swept)
        })
    }

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(6))]

        /// Sweeps, in one part or in several, end where one queue ends.
        #[test]
        fn sweeps_collapse_what_one_queue_collapses(seed in 0u64..1000, count in 12usize..80, ratio in 0.05f64..0.6) {
            let mesh = pieces(count, seed);
            let (strict, strict_collapses, outcome) = run(&mesh, ratio, 0.0, 64, 1);
            prop_assert_eq!(outcome, Outcome::None);
            // Plain sweeps, and a piloted first sweep (every second group a pilot).
            for (threads, part_vertices, pilot_stride) in
                [(1, 64, 1 << 20), (2, 64, 1 << 20), (2, 200, 1 << 20), (1, 64, 2), (2, 64, 2)]
            {
                let options = SimplifyOptions::balanced();
                let (swept, collapses, outcome) =
                    run_with(&mesh, ratio, &options, super::SHARE, part_vertices, pilot_stride, threads);
                prop_assert_eq!(outcome, Outcome::Swept);
                prop_assert_eq!(collapses, strict_collapses);
                prop_assert_eq!(&swept.submeshes, &strict.submeshes);
            }
        }
    }

    /// A sweep aiming far past the target reaches it; the run then starts again in one queue
    /// and ends as one queue does.
    #[test]
    fn a_sweep_that_reaches_the_target_changes_nothing() {
        let mesh = pieces(60, 7);
        let (strict, strict_collapses, _) = run(&mesh, 0.3, 0.0, 64, 1);
        for (threads, pilot_stride) in [(1, 1 << 20), (2, 1 << 20), (1, 2), (2, 2)] {
            let options = SimplifyOptions::balanced();
            let (out, collapses, outcome) =
                run_with(&mesh, 0.3, &options, 50.0, 64, pilot_stride, threads);
            assert_eq!(outcome, Outcome::ReachedTarget);
            assert_eq!(collapses, strict_collapses);
            assert_eq!(out.submeshes, strict.submeshes);
        }
    }

    /// An error bound turns the sweeps off; parts still split the mesh, and the queue over
    /// them stops at the bound exactly where one queue stops.
    #[test]
    fn an_error_bound_stops_every_part_where_one_queue_stops() {
        let mesh = pieces(20, 11);
        let options = SimplifyOptions {
            max_error: Some(0.02),
            ..SimplifyOptions::balanced()
        };
        let (strict, strict_collapses, _) = run_with(&mesh, 0.0, &options, 0.0, 64, 2, 1);
        assert!(strict_collapses > 0);
        let (out, collapses, outcome) = run_with(&mesh, 0.0, &options, super::SHARE, 64, 2, 2);
        assert_eq!(outcome, Outcome::None);
        assert_eq!(collapses, strict_collapses);
        assert_eq!(out.submeshes, strict.submeshes);
    }

    /// One piece, or a mesh too small to split, is one group or one part: the sweeps leave it
    /// to the single queue or sweep it in place.
    #[test]
    fn one_piece_runs_in_one_queue() {
        let mesh = InstancedMesh {
            submeshes: vec![pieces(1, 3).submeshes.swap_remove(0)],
            instances: vec![Instance {
                submesh: 0,
                transform: Affine3A::IDENTITY,
            }],
            ..InstancedMesh::default()
        };
        let (_, _, outcome) = run(&mesh, 0.3, super::SHARE, 64, 2);
        assert_eq!(outcome, Outcome::None);
    }
}
