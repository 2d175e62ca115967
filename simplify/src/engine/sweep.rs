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
//! cache while it runs. Each sweep aims to remove [`SHARE`] of the triangles still over the
//! target, choosing θ from a sample of the queued keys. Once little is left, the pieces'
//! queues pour into the single queue, which finishes the run in strict order.
//!
//! Pieces are also independent in memory, so on a large mesh the sweeps run in parallel: the
//! groups of pieces are split into one part per thread, each copied into a workspace of its
//! own, swept there and copied back. A group's sweep does not depend on where it runs, so the
//! result is the same with any number of threads.
//!
//! The one case the argument does not cover: a sweep that reaches the target. The single queue
//! would have stopped somewhere inside it, so the state is not one the strict order passes
//! through. The sweep reports it, and the caller starts again in one queue.

use std::sync::atomic::{AtomicBool, AtomicI64, Ordering};

use rayon::prelude::*;

use super::{Candidate, RadixHeap, RunStats, Step, Tri, Workspace, DEAD};

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
/// Queued keys sampled to choose a sweep's θ.
const SAMPLE: usize = 1 << 16;
/// Fewest position vertices a part must get for the sweeps to run in parallel: below it,
/// copying the parts out and back costs more than the second thread saves.
const PART_VERTICES: usize = 1 << 15;

/// The sweeps' tuning, a field of every workspace so that tests can force each path.
#[derive(Debug, Clone, Copy)]
pub(crate) struct Settings {
    /// Share of the excess a sweep aims at ([`SHARE`]); 0 runs one queue from the start.
    pub share: f64,
    /// Fewest vertices a part may get ([`PART_VERTICES`]).
    pub part_vertices: usize,
}

impl Default for Settings {
    fn default() -> Self {
        Self {
            share: SHARE,
            part_vertices: PART_VERTICES,
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

/// A share of the groups, swept in a workspace of its own.
struct Part {
    ws: Workspace,
    /// Each group's position vertices, in `ws`'s numbering.
    groups: Vec<Vec<u32>>,
    queues: Vec<Queue>,
    stats: RunStats,
    /// Where `ws`'s vertices, triangles and wedges sit in the whole workspace; `None` when
    /// `ws` is the whole workspace, moved out for the sweeps.
    map: Option<PartMap>,
}

/// Local to global numbering of a part.
struct PartMap {
    verts: Vec<u32>,
    tris: Vec<u32>,
    wedges: Vec<u32>,
}

impl Workspace {
    /// Sweeps the start of the collapse order. Returns whether the global queue now holds the
    /// rest of the first round (false: no sweep ran and nothing changed), or `None` when a
    /// sweep reached `target`, leaving a state off the strict order.
    pub(super) fn sweep(&mut self, stats: &mut RunStats, target: u64) -> Option<bool> {
        if stats.expanded <= target {
            return Some(false);
        }
        let groups = self.groups();
        if groups.len() < 2 {
            return Some(false);
        }
        // Read before `split`, which may move this workspace into the one part.
        let share = self.sweep.share;
        let first = stats.expanded - target;
        // How many more expanded triangles the sweeps may remove before they reach the target.
        let budget = AtomicI64::new(first as i64);
        let mut parts = self.split(groups);
        parts.par_iter_mut().for_each(|part| {
            part.queues = part.groups.iter().map(|g| part.ws.seed_group(g)).collect();
        });
        let mut reached = false;
        for _ in 0..MAX_SWEEPS {
            let excess = budget.load(Ordering::Relaxed);
            if (excess as f64) < TAIL * first as f64 {
                break;
            }
            let Some(theta) = threshold(&parts, share * excess as f64) else {
                break;
            };
            let stop = AtomicBool::new(false);
            parts.par_iter_mut().for_each(|part| {
                for queue in &mut part.queues {
                    if stop.load(Ordering::Relaxed)
                        || !part.ws.sweep_queue(queue, theta, &mut part.stats, &budget)
                    {
                        stop.store(true, Ordering::Relaxed);
                        return;
                    }
                }
            });
            if stop.into_inner() {
                reached = true;
                break;
            }
        }
        let queues = self.join(parts, stats);
        if reached {
            return None;
        }
        self.heap.clear();
        for &(key, c) in queues.iter().flat_map(RadixHeap::items).flatten() {
            if self.is_current(&c) {
                self.heap.push(key, c);
            }
        }
        Some(true)
    }

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
            let Some((_, c)) = queue.pop_valid_at_most(theta, |c| {
                stamp[c.p as usize] == c.stamp_p && stamp[c.q as usize] == c.stamp_q
            }) else {
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

    /// Every edge of a group once (as [`Workspace::seed_heap`] queues them), into a new queue.
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

    /// The groups in one part per thread, each copied into a workspace of its own; or, for a
    /// small mesh or one thread, one part that is this workspace, moved out.
    fn split(&mut self, groups: Vec<Vec<u32>>) -> Vec<Part> {
        let total: usize = groups.iter().map(Vec::len).sum();
        let count = rayon::current_num_threads()
            .min(total / self.sweep.part_vertices.max(1))
            .min(groups.len());
        if count < 2 {
            let ws = std::mem::take(self);
            return vec![Part::new(ws, groups, None)];
        }
        // Consecutive groups, about `total / count` vertices a part.
        let mut shares: Vec<Vec<Vec<u32>>> = vec![Vec::new()];
        let mut filled = 0;
        for group in groups {
            if filled * count >= total * shares.len() && shares.len() < count {
                shares.push(Vec::new());
            }
            filled += group.len();
            shares.last_mut().expect("one share").push(group);
        }
        // Local numbers, one part after another: vertices, then the triangles of each vertex
        // that lists them first, then the wedges of those triangles.
        let mut local_vert = vec![DEAD; self.verts.len()];
        let mut local_tri = vec![DEAD; self.tris.len()];
        let mut local_wedge = vec![DEAD; self.wedge_pos.len()];
        let maps: Vec<PartMap> = shares
            .iter()
            .map(|share| {
                let verts: Vec<u32> = share.iter().flatten().copied().collect();
                for (l, &v) in verts.iter().enumerate() {
                    local_vert[v as usize] = l as u32;
                }
                let mut tris = Vec::new();
                let mut wedges = Vec::new();
                for &v in &verts {
                    for &t in self.tris_of(v) {
                        let tri = self.tris[t as usize];
                        if tri.p[0] != v {
                            continue;
                        }
                        local_tri[t as usize] = tris.len() as u32;
                        tris.push(t);
                        for w in tri.w {
                            if local_wedge[w as usize] == DEAD {
                                local_wedge[w as usize] = wedges.len() as u32;
                                wedges.push(w);
                            }
                        }
                    }
                }
                PartMap {
                    verts,
                    tris,
                    wedges,
                }
            })
            .collect();
        let this = &*self;
        let (lv, lt, lw) = (&local_vert, &local_tri, &local_wedge);
        maps.into_par_iter()
            .zip(shares)
            .map(|(map, share)| {
                let ws = this.extract(&map, lv, lt, lw);
                let groups = share
                    .into_iter()
                    .map(|g| g.into_iter().map(|v| lv[v as usize]).collect())
                    .collect();
                Part::new(ws, groups, Some(map))
            })
            .collect()
    }

    /// A workspace holding just the vertices, triangles and wedges of `map`, renumbered.
    fn extract(
        &self,
        map: &PartMap,
        local_vert: &[u32],
        local_tri: &[u32],
        local_wedge: &[u32],
    ) -> Workspace {
        let mut ws = Workspace {
            subs: self.subs.clone(),
            sweep: self.sweep,
            ..Workspace::default()
        };
        ws.verts.reserve(map.verts.len());
        for &v in &map.verts {
            let mut vert = self.verts[v as usize];
            vert.mark = 0;
            vert.adj_start = ws.adj.len() as u32;
            ws.adj
                .extend(self.tris_of(v).iter().map(|&t| local_tri[t as usize]));
            ws.verts.push(vert);
            ws.stamp.push(self.stamp[v as usize]);
            ws.vsub.push(self.vsub[v as usize]);
        }
        // Room for the lists collapses append, as `build_adjacency` leaves.
        ws.adj.reserve(ws.adj.len());
        for &w in &map.wedges {
            let w = w as usize;
            ws.wedge_pos.push(local_vert[self.wedge_pos[w] as usize]);
            ws.uv.push(self.uv[w]);
            ws.normal.push(self.normal[w]);
            ws.color.push(self.color[w]);
        }
        ws.tris.extend(map.tris.iter().map(|&t| {
            let tri = self.tris[t as usize];
            Tri {
                w: tri.w.map(|w| local_wedge[w as usize]),
                p: tri.p.map(|v| local_vert[v as usize]),
                n: tri.n,
            }
        }));
        ws
    }

    /// Takes the parts back (copying each into place, or moving the whole workspace back),
    /// adds their collapses to `stats`, and returns their queues in this workspace's numbering.
    fn join(&mut self, parts: Vec<Part>, stats: &mut RunStats) -> Vec<Queue> {
        let mut queues = Vec::new();
        for part in parts {
            let Part {
                ws,
                queues: part_queues,
                stats: part_stats,
                map,
                ..
            } = part;
            stats.expanded -= Part::START - part_stats.expanded;
            stats.collapses += part_stats.collapses;
            stats.error = stats.error.max(part_stats.error);
            let Some(map) = map else {
                *self = ws;
                queues.extend(part_queues);
                continue;
            };
            self.absorb(&ws, &map);
            for queue in part_queues {
                let mut global = Queue::default();
                for &(key, c) in queue.items().flatten() {
                    let (p, q) = (map.verts[c.p as usize], map.verts[c.q as usize]);
                    global.push(key, Candidate { p, q, ..c });
                }
                queues.push(global);
            }
        }
        queues
    }

    /// Copies a part's state into place: its vertices, triangles and wedges over the ones it
    /// was cut from, its new wedges and adjacency lists appended.
    fn absorb(&mut self, ws: &Workspace, map: &PartMap) {
        let mut wedge = map.wedges.clone();
        for lw in map.wedges.len()..ws.wedge_pos.len() {
            wedge.push(self.wedge_pos.len() as u32);
            self.wedge_pos.push(DEAD);
            self.uv.push(ws.uv[lw]);
            self.normal.push(ws.normal[lw]);
            self.color.push(ws.color[lw]);
        }
        for (lw, &w) in wedge.iter().enumerate() {
            let w = w as usize;
            let at = ws.wedge_pos[lw];
            self.wedge_pos[w] = if at == DEAD {
                DEAD
            } else {
                map.verts[at as usize]
            };
            self.uv[w] = ws.uv[lw];
            self.normal[w] = ws.normal[lw];
            self.color[w] = ws.color[lw];
        }
        for (lt, &t) in map.tris.iter().enumerate() {
            let tri = ws.tris[lt];
            self.tris[t as usize] = Tri {
                w: tri.w.map(|w| wedge[w as usize]),
                p: if tri.p[0] == DEAD {
                    [DEAD; 3]
                } else {
                    tri.p.map(|v| map.verts[v as usize])
                },
                n: tri.n,
            };
        }
        for (l, &v) in map.verts.iter().enumerate() {
            let mut vert = ws.verts[l];
            // Marks are compared with this workspace's generations from here on.
            vert.mark = 0;
            vert.adj_start = self.adj.len() as u32;
            self.adj
                .extend(ws.tris_of(l as u32).iter().map(|&t| map.tris[t as usize]));
            self.verts[v as usize] = vert;
            self.stamp[v as usize] = ws.stamp[l];
        }
    }
}

impl Part {
    /// The count a part's statistics start from: they only ever go down by its removals.
    const START: u64 = u64::MAX / 2;

    fn new(ws: Workspace, groups: Vec<Vec<u32>>, map: Option<PartMap>) -> Self {
        Self {
            ws,
            groups,
            queues: Vec::new(),
            stats: RunStats {
                expanded: Self::START,
                ..RunStats::default()
            },
            map,
        }
    }
}

/// The key up to which the parts' queued current candidates would remove about `share`
/// triangles, at two per collapse times the submesh's instances (an estimate: some candidates
/// fail their checks, and collapses queue new ones). `None` when nothing is queued.
fn threshold(parts: &[Part], share: f64) -> Option<u64> {
    let total: usize = parts
        .iter()
        .flat_map(|p| &p.queues)
        .map(RadixHeap::len)
        .sum();
    let stride = total.div_ceil(SAMPLE).max(1);
    let mut sample: Vec<(u64, u64)> = Vec::with_capacity(total / stride + parts.len());
    for part in parts {
        let ws = &part.ws;
        let mut at = 0;
        for entries in part.queues.iter().flat_map(RadixHeap::items) {
            while at < entries.len() {
                let (key, c) = &entries[at];
                if ws.is_current(c) {
                    let instances = ws.subs[ws.vsub[c.p as usize] as usize].instances;
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
fn find(parent: &mut [u32], mut x: u32) -> u32 {
    while parent[x as usize] != x {
        let up = parent[parent[x as usize] as usize];
        parent[x as usize] = up;
        x = up;
    }
    x
}

/// Joins the pieces of `a` and `b` under the lesser root.
fn union(parent: &mut [u32], a: u32, b: u32) {
    let (ra, rb) = (find(parent, a), find(parent, b));
    let (lo, hi) = (ra.min(rb), ra.max(rb));
    parent[hi as usize] = lo;
}

#[cfg(test)]
mod tests {
    //! The sweeps' promise: the same collapses as one queue, on any number of threads, and a
    //! sweep that reaches the target changes nothing.
    use glam::{Affine3A, Quat, Vec2, Vec3};
    use horizon_mesh::{Instance, InstancedMesh, Submesh};
    use proptest::prelude::*;

    use super::Outcome;
    use crate::{simplify_with, SimplifyOptions, Target, Workspace};

    /// `pieces` separate bumpy grids in one submesh, and a second submesh, bumpy too, placed
    /// three times (one mirrored). Random heights keep every cost distinct, so that no tie
    /// leaves the order to chance.
    fn pieces(pieces: usize, seed: u64) -> InstancedMesh {
        let mut rng = seed.wrapping_mul(0x9E37_79B9_7F4A_7C15) | 1;
        let mut next = move || {
            rng ^= rng << 13;
            rng ^= rng >> 7;
            rng ^= rng << 17;
            (rng >> 11) as f32 / (1u64 << 53) as f32
        };
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
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()
            .expect("a thread pool");
        pool.install(|| {
            let mut ws = Workspace::new();
            ws.sweep.share = share;
            ws.sweep.part_vertices = part_vertices;
            let out = simplify_with(
                mesh,
                Target::Ratio(ratio),
                &SimplifyOptions::balanced(),
                &mut ws,
            )
            .expect("a valid mesh");
            ws.validate().expect("a valid workspace");
            (out.mesh, out.report.collapses, ws.swept)
        })
    }

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(6))]

        /// Sweeps, in one part or in several, end where one queue ends.
        #[test]
        fn sweeps_collapse_what_one_queue_collapses(seed in 0u64..1000, count in 12usize..40, ratio in 0.05f64..0.6) {
            let mesh = pieces(count, seed);
            let (strict, strict_collapses, outcome) = run(&mesh, ratio, 0.0, 64, 1);
            prop_assert_eq!(outcome, Outcome::None);
            for (threads, part_vertices) in [(1, 64), (2, 64), (2, 1 << 30)] {
                let (swept, collapses, outcome) = run(&mesh, ratio, super::SHARE, part_vertices, threads);
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
        let mesh = pieces(12, 7);
        let (strict, strict_collapses, _) = run(&mesh, 0.3, 0.0, 64, 1);
        for threads in [1, 2] {
            let (out, collapses, outcome) = run(&mesh, 0.3, 50.0, 64, threads);
            assert_eq!(outcome, Outcome::ReachedTarget);
            assert_eq!(collapses, strict_collapses);
            assert_eq!(out.submeshes, strict.submeshes);
        }
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
