//! The collapse engine behind IAS and the QEM baseline (Azim et al. 2014, section 6.2: the
//! three-step algorithm; Garland and Heckbert 1997 for the collapse order).
//!
//! Every submesh with at least one instance is loaded into one set of global arrays:
//! - *position vertices*, welded by exact position within a submesh: they carry the quadric and
//!   the topology;
//! - *wedges*, the input vertices: they carry UVs, normals and colours, so a position vertex with
//!   two wedges sits on a seam;
//! - triangles, as three wedges and as their three position vertices.
//!
//! Collapses of position-vertex edges run in one global order of cost across all submeshes.
//! A collapse removes (degenerate triangles) x (instances of the submesh) from the expanded
//! count. Instances never enter the loop: their effect is folded into the quadrics up front
//! (see [`crate::weights`]), which is what makes IAS fast on heavily instanced meshes.
//!
//! On a large expanded mesh (the QEM baseline) the loop is bound by cache misses: the global
//! order visits the mesh at random. So what one step reads sits together: a vertex's quadric,
//! position, flags, scratch mark and adjacency range in two aligned cache lines (`Vert`), a
//! triangle's wedges and position vertices in one 32-byte record (`Tri`), and the stale queue
//! entries (an endpoint changed since the push: most of them, since every collapse queues its
//! neighbourhood's edges again and leaves the old entries behind) are dropped in bulk when the
//! radix heap redistributes a bucket, where their stamp checks overlap in memory.

use glam::{DVec3, Vec2, Vec3, Vec4};
use horizon_mesh::{InstancedMesh, Submesh};
use rayon::prelude::*;

use crate::options::SimplifyOptions;
use crate::quadric::Quadric;
use crate::radix_heap::RadixHeap;
use crate::weights::{FlipGuard, InstanceSet};
use crate::weld::Weld;

mod sweep;
mod workspace;

pub use workspace::Workspace;

const DEAD: u32 = u32::MAX;

/// Fewest items (vertices, triangles) a stage hands to the thread pool: entering it from
/// outside costs a wake-up, more than a small mesh's whole stage.
const PARALLEL_MIN: usize = 1 << 14;

/// One part of a [`Workspace`]: the pieces of the mesh it was given, loaded into one set of
/// arrays. Every buffer keeps its capacity between simplifications.
#[derive(Debug, Default)]
struct Part {
    // Position vertices: what a cost evaluation reads, together (two cache lines each).
    verts: Vec<Vert>,
    stamp: Vec<u32>,
    vsub: Vec<u32>,
    // Wedges (input vertices).
    wedge_pos: Vec<u32>,
    uv: Vec<Vec2>,
    normal: Vec<Vec3>,
    color: Vec<Vec4>,
    // Triangles.
    tris: Vec<Tri>,
    // Triangles around each position vertex: `adj[start..start + len]`, append-only.
    adj: Vec<u32>,
    // Scratch.
    generation: u32,
    heap: RadixHeap<Candidate>,
    tri_k: Vec<u32>,
    tri_r: Vec<u32>,
    ring: Vec<u32>,
    pairs: Vec<[u32; 2]>,
    // Per loaded submesh (the same list in every part of a workspace).
    subs: Vec<SubInfo>,
}

/// A position vertex: what planning a collapse reads, in two cache lines.
#[derive(Debug, Clone, Copy, Default)]
#[repr(C, align(128))]
struct Vert {
    quadric: Quadric,
    pos: DVec3,
    locked: bool,
    boundary: bool,
    /// Distinct wedges at the vertex (saturating at 3), kept current.
    wedge_count: u8,
    /// Scratch mark of the link check and the ring walk (see `next_generation`).
    mark: u32,
    /// Triangles around the vertex: `adj[adj_start..adj_start + adj_len]`.
    adj_start: u32,
    adj_len: u32,
}

/// A triangle as three wedges and as their three position vertices (`[DEAD; 3]` once
/// collapsed away), plus its input normal, in one aligned half cache line: the hot loop reads
/// topology, liveness and wedges in one load.
#[derive(Debug, Clone, Copy)]
#[repr(align(32))]
struct Tri {
    w: [u32; 3],
    p: [u32; 3],
    /// The unit normal the triangle had in the input, octahedron-encoded
    /// ([`encode_normal`]); [`NO_NORMAL`] for a zero-area input triangle. The flip test
    /// compares every new normal with it as well as with the current one, so that no chain of
    /// small turns, and no pass through a zero-area state, can turn a triangle over.
    n: [f32; 2],
}

/// [`Tri::n`] of a triangle that had no normal (zero area) in the input.
const NO_NORMAL: [f32; 2] = [f32::NAN, f32::NAN];

/// Octahedral encoding of a direction (zero encodes as [`NO_NORMAL`]).
fn encode_normal(n: DVec3) -> [f32; 2] {
    let l1 = n.x.abs() + n.y.abs() + n.z.abs();
    if !(l1 > 0.0 && l1.is_finite()) {
        return NO_NORMAL;
    }
    let (x, y) = (n.x / l1, n.y / l1);
    let (x, y) = if n.z < 0.0 { fold(x, y) } else { (x, y) };
    [x as f32, y as f32]
}

/// The direction [`encode_normal`] encoded (not normalised; the flip test needs none), or
/// `None` for [`NO_NORMAL`].
fn decode_normal(e: [f32; 2]) -> Option<DVec3> {
    if e[0].is_nan() {
        return None;
    }
    let (x, y) = (f64::from(e[0]), f64::from(e[1]));
    let z = 1.0 - x.abs() - y.abs();
    let (x, y) = if z < 0.0 { fold(x, y) } else { (x, y) };
    Some(DVec3::new(x, y, z))
}

/// The octahedron's lower half folded over the diagonals onto the square's corners, and back:
/// the map is its own inverse.
fn fold(x: f64, y: f64) -> (f64, f64) {
    ((1.0 - y.abs()) * x.signum(), (1.0 - x.abs()) * y.signum())
}

#[derive(Debug, Clone)]
struct SubInfo {
    /// Index of the submesh in the input.
    source: usize,
    tri_base: u32,
    tri_end: u32,
    instances: u64,
    has_normals: bool,
    has_uvs: bool,
    has_colors: bool,
    guard: FlipGuard,
}

/// A candidate collapse in the global queue, keyed by its cost's bits.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
struct Candidate {
    p: u32,
    q: u32,
    stamp_p: u32,
    stamp_q: u32,
}

impl Candidate {
    /// Whether neither endpoint changed since the candidate was queued, by the endpoints'
    /// `stamp`s (a free test, so that a queue can be searched while the stamps are lent).
    #[inline]
    fn is_current(&self, stamp: &[u32]) -> bool {
        stamp[self.p as usize] == self.stamp_p && stamp[self.q as usize] == self.stamp_q
    }
}

/// Most wedges a removed corner vertex may carry.
const MAX_WEDGES: usize = 8;
/// Marks a wedge that becomes a new wedge at the kept position.
const NEW_WEDGE: u32 = u32::MAX - 1;

/// Where each wedge of the removed vertex goes: one pair, two along a seam, or one per face
/// group at a corner (`NEW_WEDGE` for a face group that `keep` does not touch).
#[derive(Clone, Copy, Debug)]
struct WedgeMap {
    pairs: [[u32; 2]; MAX_WEDGES],
    len: usize,
}

impl Default for WedgeMap {
    fn default() -> Self {
        Self {
            pairs: [[DEAD; 2]; MAX_WEDGES],
            len: 0,
        }
    }
}

impl WedgeMap {
    fn pairs(&self) -> &[[u32; 2]] {
        &self.pairs[..self.len]
    }

    fn push(&mut self, pair: [u32; 2]) {
        self.pairs[self.len] = pair;
        self.len += 1;
    }

    fn target(&self, from: u32) -> Option<u32> {
        self.pairs().iter().find(|p| p[0] == from).map(|p| p[1])
    }
}

/// How a collapse moves its vertices.
#[derive(Clone, Copy, Debug)]
struct Plan {
    keep: u32,
    remove: u32,
    target: DVec3,
    cost: f64,
    /// Both ends move to an optimal point (attributes interpolate); otherwise `remove` moves
    /// onto `keep` (a half-edge collapse).
    full: bool,
}

/// Which positions [`Part::load`] takes: those `owners[submesh][position]` gives to `part`,
/// one of `parts`.
#[derive(Clone, Copy)]
struct Only<'a> {
    owners: &'a [Vec<u8>],
    part: u8,
    parts: usize,
}

/// What [`Part::classify_edges`] finds around a run of vertices.
#[derive(Default)]
struct EdgeKinds {
    boundary: Vec<u32>,
    locked: Vec<u32>,
    /// (vertex, neighbour, triangle, weight) of every boundary or seam edge, once.
    constraints: Vec<(u32, u32, u32, f64)>,
    /// Scratch: the edge ends around the current vertex.
    entries: Vec<(u32, u32, u32, u32)>,
}

/// What became of one candidate taken off a queue.
enum Step {
    /// The plan or the checks refused it.
    Rejected,
    /// Its error is over the bound: the run ends.
    OverBound,
    /// It collapsed onto this vertex.
    Collapsed(u32),
}

/// The outcome of a run of the collapse loop.
#[derive(Debug, Default, Clone, Copy)]
pub(crate) struct RunStats {
    pub expanded: u64,
    pub collapses: u64,
    pub error: f64,
}

impl Part {
    /// Checks the state the last simplification left: every live triangle has three distinct,
    /// live position vertices of its own submesh, every vertex's adjacency names only
    /// triangles that hold it, and, the no-flip promise, no triangle faces more than 90
    /// degrees away from its input normal in any instance (in the exact f64 positions, before
    /// export rounds them).
    fn validate(&self) -> Result<(), String> {
        for (si, sub) in self.subs.iter().enumerate() {
            for t in sub.tri_base..sub.tri_end {
                if !self.alive(t) {
                    continue;
                }
                let p = self.tri_verts(t);
                if p[0] == p[1] || p[1] == p[2] || p[0] == p[2] {
                    return Err(format!("triangle {t} has a repeated vertex: {p:?}"));
                }
                if let Some(&v) = p.iter().find(|&&v| {
                    v as usize >= self.verts.len() || self.vsub[v as usize] != si as u32
                }) {
                    return Err(format!("triangle {t} of submesh {si} names vertex {v}"));
                }
                let [a, b, c] = p.map(|v| self.verts[v as usize].pos);
                let n = (b - a).cross(c - a);
                if let Some(input) = decode_normal(self.tris[t as usize].n) {
                    if !sub.guard.same_side(input, n) {
                        return Err(format!(
                            "triangle {t} of submesh {si} turned over: input normal {input}, now {n}"
                        ));
                    }
                }
            }
        }
        for (v, vert) in self.verts.iter().enumerate() {
            let start = vert.adj_start as usize;
            let ring = self
                .adj
                .get(start..start + vert.adj_len as usize)
                .ok_or_else(|| format!("vertex {v}: adjacency out of range"))?;
            if let Some(&t) = ring
                .iter()
                .find(|&&t| self.alive(t) && !self.tri_verts(t).contains(&(v as u32)))
            {
                return Err(format!(
                    "vertex {v} lists triangle {t}, which does not hold it"
                ));
            }
        }
        Ok(())
    }

    /// Stage 1: loads the instanced submeshes of `mesh` (`welds[s]` numbers the positions of
    /// submesh `s`, `None` for one that draws nothing), or with `only = (owners, part)` just
    /// the positions `owners[s]` gives to `part`, with their wedges and triangles. Then
    /// classifies seams. Returns the expanded triangle count loaded.
    fn load(
        &mut self,
        mesh: &InstancedMesh,
        sets: &[InstanceSet],
        welds: &[Option<Weld>],
        only: Option<Only<'_>>,
    ) -> u64 {
        self.clear();
        // Room for everything up front (a part's share of it), so that no array is copied
        // while it grows.
        let share = only.map_or(1, |o| o.parts);
        let loaded = || {
            mesh.submeshes
                .iter()
                .zip(welds)
                .filter(|(_, weld)| weld.is_some())
        };
        let wedges: usize = loaded().map(|(sub, _)| sub.positions.len()).sum::<usize>() / share;
        let tris: usize = loaded()
            .map(|(sub, _)| sub.indices.len() / 3)
            .sum::<usize>()
            / share;
        self.verts.reserve(wedges);
        self.vsub.reserve(wedges);
        self.wedge_pos.reserve(wedges);
        self.uv.reserve(wedges);
        self.normal.reserve(wedges);
        self.color.reserve(wedges);
        self.tris.reserve(tris);
        let mut expanded = 0u64;
        for (s, ((sub, set), weld)) in mesh.submeshes.iter().zip(sets).zip(welds).enumerate() {
            let Some(weld) = weld else {
                continue;
            };
            let sub_id = self.subs.len() as u32;
            let tri_base = self.tris.len() as u32;
            let owner = only.map(|o| (&o.owners[s][..], o.part));
            self.load_submesh(sub, weld, owner, sub_id);
            let tri_end = self.tris.len() as u32;
            expanded += u64::from(tri_end - tri_base) * set.count() as u64;
            self.subs.push(SubInfo {
                source: s,
                tri_base,
                tri_end,
                instances: set.count() as u64,
                has_normals: sub.normals.is_some(),
                has_uvs: sub.uvs.is_some(),
                has_colors: sub.colors.is_some(),
                guard: set.flip_guard(),
            });
        }
        self.build_adjacency();
        let n = self.verts.len();
        self.stamp = vec![0; n];
        self.generation = 0;
        for v in 0..n as u32 {
            self.verts[v as usize].wedge_count = self.wedges_at(v).0 as u8;
        }
        expanded
    }

    fn clear(&mut self) {
        self.verts.clear();
        self.vsub.clear();
        self.wedge_pos.clear();
        self.uv.clear();
        self.normal.clear();
        self.color.clear();
        self.tris.clear();
        self.heap.clear();
        self.subs.clear();
        self.adj.clear();
    }

    /// Appends one submesh, or with `owner = (owners, part)` the positions `owners` gives to
    /// `part` (with their wedges, and the triangles on them). Positions, wedges and triangles
    /// keep their input order.
    fn load_submesh(
        &mut self,
        sub: &Submesh,
        weld: &Weld,
        owner: Option<(&[u8], u8)>,
        sub_id: u32,
    ) {
        let mine = |id: u32| owner.is_none_or(|(owners, part)| owners[id as usize] == part);
        let mut vert_of = vec![DEAD; weld.positions as usize];
        let mut wedge_of = vec![DEAD; sub.positions.len()];
        for (i, p) in sub.positions.iter().enumerate() {
            let id = weld.ids[i];
            if !mine(id) {
                continue;
            }
            if vert_of[id as usize] == DEAD {
                vert_of[id as usize] = self.verts.len() as u32;
                self.verts.push(Vert {
                    pos: p.as_dvec3(),
                    ..Vert::default()
                });
                self.vsub.push(sub_id);
            }
            wedge_of[i] = self.wedge_pos.len() as u32;
            self.wedge_pos.push(vert_of[id as usize]);
            self.uv.push(sub.uvs.as_ref().map_or(Vec2::ZERO, |u| u[i]));
            self.normal
                .push(sub.normals.as_ref().map_or(Vec3::ZERO, |n| n[i]));
            self.color
                .push(sub.colors.as_ref().map_or(Vec4::ONE, |c| c[i]));
        }
        for t in sub.indices.chunks_exact(3) {
            let Some(ids) = weld.triangle(t).filter(|ids| mine(ids[0])) else {
                continue;
            };
            let w = [t[0], t[1], t[2]].map(|i| wedge_of[i as usize]);
            let p = ids.map(|id| vert_of[id as usize]);
            let [a, b, c] = p.map(|v| self.verts[v as usize].pos);
            let n = encode_normal((b - a).cross(c - a));
            self.tris.push(Tri { w, p, n });
        }
    }

    fn build_adjacency(&mut self) {
        for v in &mut self.verts {
            v.adj_len = 0;
        }
        for t in &self.tris {
            for &v in &t.p {
                self.verts[v as usize].adj_len += 1;
            }
        }
        let mut acc = 0u32;
        for v in &mut self.verts {
            v.adj_start = acc;
            acc += v.adj_len;
        }
        self.adj.clear();
        // Every collapse appends the merged list of its kept vertex: room for about as many
        // entries again as the initial lists, so the arena is not copied while it grows.
        self.adj.reserve(2 * acc as usize);
        self.adj.resize(acc as usize, 0);
        let mut fill: Vec<u32> = self.verts.iter().map(|v| v.adj_start).collect();
        for (i, t) in self.tris.iter().enumerate() {
            for &v in &t.p {
                let v = v as usize;
                self.adj[fill[v] as usize] = i as u32;
                fill[v] += 1;
            }
        }
    }

    /// The position vertices of triangle `t` (`[DEAD; 3]` once it is gone).
    #[inline]
    fn tri_verts(&self, t: u32) -> [u32; 3] {
        self.tris[t as usize].p
    }

    #[inline]
    fn alive(&self, t: u32) -> bool {
        self.tris[t as usize].p[0] != DEAD
    }

    fn tris_of(&self, v: u32) -> &[u32] {
        let s = self.verts[v as usize].adj_start as usize;
        &self.adj[s..s + self.verts[v as usize].adj_len as usize]
    }

    fn next_generation(&mut self) -> u32 {
        if self.generation >= u32::MAX - 4 {
            self.verts.iter_mut().for_each(|v| v.mark = 0);
            self.generation = 0;
        }
        self.generation += 2;
        self.generation
    }

    /// Stage 2: quadrics. Face planes come from `face_quadric` (which folds in every
    /// instance); boundary and seam edges add constraint planes from `edge_constraint`.
    /// Vertices on non-manifold edges are locked.
    fn build_quadrics(&mut self, sets: &[InstanceSet], options: &SimplifyOptions) {
        // Face weights, submesh by submesh: each folds in the submesh's instances.
        let mut weights: Vec<(f64, f64)> = Vec::with_capacity(self.tris.len());
        for info in &self.subs {
            let tris = &self.tris[info.tri_base as usize..info.tri_end as usize];
            let verts = &self.verts;
            let normal = |t: &Tri| {
                let [a, b, c] = t.p.map(|v| verts[v as usize].pos);
                (b - a).cross(c - a)
            };
            let normals: Vec<DVec3> = if tris.len() < PARALLEL_MIN {
                tris.iter().map(normal).collect()
            } else {
                tris.par_iter().with_min_len(4096).map(normal).collect()
            };
            weights.extend(sets[info.source].face_weights(&normals));
        }
        // Face quadrics, vertex by vertex (in parallel), each summing its triangles' planes in
        // triangle order.
        let pos: Vec<DVec3> = self.verts.iter().map(|v| v.pos).collect();
        let (tris, adj) = (&self.tris, &self.adj);
        let accumulate = |vert: &mut Vert| {
            let start = vert.adj_start as usize;
            for &t in &adj[start..start + vert.adj_len as usize] {
                let [a, b, c] = tris[t as usize].p.map(|v| pos[v as usize]);
                let n2 = (b - a).cross(c - a);
                let len = n2.length();
                if len == 0.0 {
                    continue;
                }
                let n = n2 / len;
                let area = 0.5 * len;
                let (w_plane, w_area) = weights[t as usize];
                vert.quadric +=
                    Quadric::from_plane(n, -n.dot(a), area * w_plane).with_weight(area * w_area);
            }
        };
        let small = self.verts.len() < PARALLEL_MIN;
        if small {
            self.verts.iter_mut().for_each(accumulate);
        } else {
            self.verts
                .par_iter_mut()
                .with_min_len(4096)
                .for_each(accumulate);
        }
        // Boundary, seam and non-manifold edges, found vertex by vertex (in parallel, then
        // applied in vertex order).
        let found: Vec<EdgeKinds> = if small {
            let mut found = EdgeKinds::default();
            for v in 0..self.verts.len() as u32 {
                self.classify_edges(v, options, &mut found);
            }
            vec![found]
        } else {
            (0..self.verts.len() as u32)
                .into_par_iter()
                .with_min_len(4096)
                .fold(EdgeKinds::default, |mut found, v| {
                    self.classify_edges(v, options, &mut found);
                    found
                })
                .collect()
        };
        let mut constraints: Vec<(u32, u32, u32, f64)> = Vec::new();
        for found in found {
            for v in found.boundary {
                self.verts[v as usize].boundary = true;
            }
            for v in found.locked {
                self.verts[v as usize].locked = true;
            }
            constraints.extend(found.constraints);
        }
        for &(a, b, t, weight) in &constraints {
            if weight <= 0.0 {
                continue;
            }
            let info = &self.subs[self.vsub[a as usize] as usize];
            let set = &sets[info.source];
            let [p0, p1, p2] = self.tri_verts(t).map(|v| self.verts[v as usize].pos);
            let n = (p1 - p0).cross(p2 - p0).normalize_or_zero();
            if n == DVec3::ZERO {
                continue;
            }
            let (pa, pb) = (self.verts[a as usize].pos, self.verts[b as usize].pos);
            let u = set.edge_constraint(pa, pb, n);
            let u = u.map(|x| x * weight);
            let q = Quadric::from_planes_through(u, pa, 0.0);
            self.verts[a as usize].quadric += q;
            self.verts[b as usize].quadric += q;
        }
        if options.lock_boundary {
            for v in &mut self.verts {
                v.locked |= v.boundary;
            }
        }
    }

    /// The edges around `v` that end at a neighbour with one triangle (boundary), two with
    /// different wedges (seam) or more (non-manifold), into `found`.
    fn classify_edges(&self, v: u32, options: &SimplifyOptions, found: &mut EdgeKinds) {
        // (neighbour, triangle, wedge at v, wedge at neighbour)
        let entries = &mut found.entries;
        entries.clear();
        for &t in self.tris_of(v) {
            let tri = self.tris[t as usize].w;
            let tp = self.tris[t as usize].p;
            for c in 0..3 {
                if tp[c] == v {
                    for d in [(c + 1) % 3, (c + 2) % 3] {
                        entries.push((tp[d], t, tri[c], tri[d]));
                    }
                }
            }
        }
        entries.sort_unstable();
        let mut i = 0;
        while i < entries.len() {
            let mut j = i;
            while j < entries.len() && entries[j].0 == entries[i].0 {
                j += 1;
            }
            let u = entries[i].0;
            let group = &entries[i..j];
            match group.len() {
                1 => {
                    found.boundary.push(v);
                    if v < u {
                        found
                            .constraints
                            .push((v, u, group[0].1, options.boundary_weight));
                    }
                }
                2 => {
                    let seam = group[0].2 != group[1].2 || group[0].3 != group[1].3;
                    if seam && v < u {
                        found
                            .constraints
                            .push((v, u, group[0].1, options.seam_weight));
                        found
                            .constraints
                            .push((v, u, group[1].1, options.seam_weight));
                    }
                }
                _ => found.locked.extend([v, u]),
            }
            i = j;
        }
    }

    /// Distinct wedges at `v` (up to two) and their count (saturating at 3).
    fn wedges_at(&self, v: u32) -> (u32, [u32; 2]) {
        let mut out = [DEAD; 2];
        let mut n = 0;
        for &t in self.tris_of(v) {
            let tp = self.tris[t as usize].p;
            if tp[0] == DEAD {
                continue;
            }
            for (c, &w) in self.tris[t as usize].w.iter().enumerate() {
                if tp[c] == v && !out[..n.min(2) as usize].contains(&w) {
                    if n >= 2 {
                        return (3, out);
                    }
                    out[n as usize] = w;
                    n += 1;
                }
            }
        }
        (n, out)
    }

    /// Whether the edge `p q` lies on a seam: two triangles whose wedges differ at both ends.
    fn is_seam_edge(&self, p: u32, q: u32) -> bool {
        let mut pairs = [[DEAD; 2]; 2];
        let mut n = 0;
        for &t in self.tris_of(p) {
            let tp = self.tris[t as usize].p;
            if tp[0] == DEAD {
                continue;
            }
            let tri = self.tris[t as usize].w;
            let wp = tp.iter().position(|&v| v == p);
            let wq = tp.iter().position(|&v| v == q);
            if let (Some(wp), Some(wq)) = (wp, wq) {
                let (wp, wq) = (tri[wp], tri[wq]);
                if n == 2 {
                    return false;
                }
                pairs[n] = [wp, wq];
                n += 1;
            }
        }
        n == 2 && pairs[0][0] != pairs[1][0] && pairs[0][1] != pairs[1][1]
    }

    /// The collapse of edge `p q`: which end stays, where it goes, and the cost (eq. 5),
    /// or `None` when the seam and lock rules forbid it.
    fn plan(&self, p: u32, q: u32) -> Option<Plan> {
        // Roles: 0 free (one wedge), 1 on a seam (two), 2 a corner of seams (three or more
        // wedges, e.g. a box corner with a normal per face), 3 locked (never moves).
        let role = |v: u32| -> u8 {
            if self.verts[v as usize].locked {
                return 3;
            }
            match self.verts[v as usize].wedge_count {
                0 | 1 => 0,
                2 => 1,
                _ => 2,
            }
        };
        let (rp, rq) = (role(p), role(q));
        let sum = self.verts[p as usize].quadric + self.verts[q as usize].quadric;
        let (pp, pq) = (self.verts[p as usize].pos, self.verts[q as usize].pos);
        let half = |keep: u32, remove: u32| {
            let target = self.verts[keep as usize].pos;
            Some(Plan {
                keep,
                remove,
                target,
                cost: sum.eval(target),
                full: false,
            })
        };
        match (rp, rq) {
            (0, 0) => Some(self.full_plan(p, q, &sum, pp, pq)),
            (1, 1) => self
                .is_seam_edge(p, q)
                .then(|| self.full_plan(p, q, &sum, pp, pq)),
            (_, 0) => half(p, q),
            (0, _) => half(q, p),
            (2 | 3, 1) => self.is_seam_edge(p, q).then(|| half(p, q)).flatten(),
            (1, 2 | 3) => self.is_seam_edge(p, q).then(|| half(q, p)).flatten(),
            // A corner moves onto its neighbour, each of its faces keeping its own attributes.
            (2, 2) => {
                let (a, b) = (half(p, q)?, half(q, p)?);
                Some(if a.cost <= b.cost { a } else { b })
            }
            (3, 2) => half(p, q),
            (2, 3) => half(q, p),
            _ => None,
        }
    }

    /// Optimal placement (eq. 6), falling back to the best point of the segment, which
    /// includes the endpoints and the midpoint.
    fn full_plan(&self, p: u32, q: u32, sum: &Quadric, pp: DVec3, pq: DVec3) -> Plan {
        let mid = 0.5 * (pp + pq);
        let reach = (pq - pp).length_squared() * 4.0;
        let target = match sum.optimum() {
            Some(x) if (x - mid).length_squared() <= reach => x,
            _ => pp.lerp(pq, sum.best_on_segment(pp, pq)),
        };
        let cost = sum.eval(target);
        Plan {
            keep: p,
            remove: q,
            target,
            cost,
            full: true,
        }
    }

    fn push(&mut self, p: u32, q: u32) {
        if let Some((key, candidate)) = self.candidate(p, q) {
            self.heap.push(key, candidate);
        }
    }

    /// The queue entry of edge `p q`: its key and the endpoints' stamps, or `None` when the
    /// edge may not collapse.
    fn candidate(&self, p: u32, q: u32) -> Option<(u64, Candidate)> {
        let plan = self.plan(p, q)?;
        let candidate = Candidate {
            p,
            q,
            stamp_p: self.stamp[p as usize],
            stamp_q: self.stamp[q as usize],
        };
        // The queue orders collapses by cost per instance: a collapse in a submesh drawn n
        // times removes n times the triangles for its summed cost, so this is the error
        // paid per expanded triangle removed. Ordering by the raw summed cost (the paper's
        // section 6.2, step 3) would spend every cheap edge of the once-drawn submeshes
        // first, over-simplifying a tree's trunk to spare its thousands of leaves.
        let instances = self.subs[self.vsub[p as usize] as usize].instances.max(1);
        let priority = plan.cost / instances as f64;
        Some((priority.to_bits(), candidate))
    }

    /// Every current edge once, into the heap.
    fn seed_heap(&mut self) {
        self.heap.clear();
        for v in 0..self.verts.len() as u32 {
            if self.verts[v as usize].adj_len == 0 {
                continue;
            }
            self.collect_ring(v);
            let ring = std::mem::take(&mut self.ring);
            for &u in ring.iter().filter(|&&u| u > v) {
                self.push(v, u);
            }
            self.ring = ring;
        }
    }

    /// The distinct neighbours of `v` into `self.ring`.
    fn collect_ring(&mut self, v: u32) {
        let g = self.next_generation();
        self.ring.clear();
        let s = self.verts[v as usize].adj_start as usize;
        let e = s + self.verts[v as usize].adj_len as usize;
        for i in s..e {
            let t = self.adj[i];
            let tp = self.tri_verts(t);
            if tp[0] == DEAD {
                continue;
            }
            for u in tp {
                if u != v && self.verts[u as usize].mark != g {
                    self.verts[u as usize].mark = g;
                    self.ring.push(u);
                }
            }
        }
    }

    /// Whether candidate `c` is current: neither endpoint changed since it was queued.
    #[inline]
    fn is_current(&self, c: &Candidate) -> bool {
        c.is_current(&self.stamp)
    }

    /// One current candidate off a queue: plan it, check it, collapse it. After a collapse
    /// `self.ring` holds the kept vertex's neighbours, whose edges the caller queues again.
    fn step(&mut self, c: Candidate, stats: &mut RunStats, max_cost_error: f64) -> Step {
        let Some(plan) = self.plan(c.p, c.q) else {
            return Step::Rejected;
        };
        let keep = plan.keep as usize;
        let weight =
            self.verts[keep].quadric.weight() + self.verts[plan.remove as usize].quadric.weight();
        let error = if weight > 0.0 {
            (plan.cost / weight).sqrt()
        } else {
            plan.cost.sqrt()
        };
        if error > max_cost_error {
            return Step::OverBound;
        }
        let Some(removed) = self.try_collapse(&plan) else {
            return Step::Rejected;
        };
        let sub = &self.subs[self.vsub[keep] as usize];
        stats.expanded -= removed * sub.instances;
        stats.collapses += 1;
        stats.error = stats.error.max(error);
        self.collect_ring(plan.keep);
        // Touch every neighbour's quadric and stamp first: the loads miss the cache
        // independently and overlap, where the costs the caller computes next would wait for
        // them one neighbour at a time.
        let touched: f64 = self
            .ring
            .iter()
            .map(|&u| {
                let v = &self.verts[u as usize];
                v.quadric.touch() + f64::from(self.stamp[u as usize])
            })
            .sum();
        std::hint::black_box(touched);
        Step::Collapsed(plan.keep)
    }

    /// Checks the collapse (link condition, no duplicate faces, seams, flips) and performs it.
    /// Returns the number of triangles removed from the submesh.
    fn try_collapse(&mut self, plan: &Plan) -> Option<u64> {
        let (k, r) = (plan.keep, plan.remove);
        let mut tri_k = std::mem::take(&mut self.tri_k);
        let mut tri_r = std::mem::take(&mut self.tri_r);
        tri_k.clear();
        tri_r.clear();
        let mut edge = [DEAD; 2];
        let mut n_edge = 0usize;
        for &t in self.tris_of(k) {
            if self.alive(t) {
                tri_k.push(t);
            }
        }
        for &t in self.tris_of(r) {
            let tp = self.tri_verts(t);
            if tp[0] == DEAD {
                continue;
            }
            if tp.contains(&k) {
                if n_edge == 2 {
                    n_edge = 3;
                    break;
                }
                edge[n_edge] = t;
                n_edge += 1;
            } else {
                tri_r.push(t);
            }
        }
        let ok = self.check(plan, &tri_k, &tri_r, &edge[..n_edge.min(2)], n_edge);
        let result = ok.map(|map| {
            self.apply(plan, &tri_k, &tri_r, &edge[..n_edge], map.pairs());
            n_edge as u64
        });
        self.tri_k = tri_k;
        self.tri_r = tri_r;
        result
    }

    /// The validity checks; on success, the wedge map of `remove`'s wedges onto `keep`'s.
    fn check(
        &mut self,
        plan: &Plan,
        tri_k: &[u32],
        tri_r: &[u32],
        edge: &[u32],
        n_edge: usize,
    ) -> Option<WedgeMap> {
        let (k, r) = (plan.keep, plan.remove);
        if n_edge == 0 || n_edge > 2 {
            return None;
        }
        if n_edge == 2 && self.verts[k as usize].boundary && self.verts[r as usize].boundary {
            return None; // would pinch the surface at a boundary
        }
        // Link condition: the common neighbours are exactly the edge triangles' apexes.
        let g = self.next_generation();
        for &t in tri_r.iter().chain(edge) {
            for v in self.tri_verts(t) {
                if v != r && v != k {
                    self.verts[v as usize].mark = g;
                }
            }
        }
        let mut common = 0;
        for &t in tri_k {
            for v in self.tri_verts(t) {
                if v != k && v != r && self.verts[v as usize].mark == g {
                    self.verts[v as usize].mark = g + 1;
                    common += 1;
                }
            }
        }
        if common != n_edge {
            return None;
        }
        // No two faces may become one (the tetrahedron case).
        self.pairs.clear();
        for &t in tri_k {
            if edge.contains(&t) {
                continue;
            }
            let mut o = self.tri_verts(t).into_iter().filter(|&v| v != k);
            let (a, b) = (o.next().unwrap_or(DEAD), o.next().unwrap_or(DEAD));
            self.pairs.push([a.min(b), a.max(b)]);
        }
        for &t in tri_r {
            let mut o = self.tri_verts(t).into_iter().filter(|&v| v != r);
            let (a, b) = (o.next().unwrap_or(DEAD), o.next().unwrap_or(DEAD));
            if self.pairs.contains(&[a.min(b), a.max(b)]) {
                return None;
            }
        }
        // Wedges: where each of `remove`'s wedges goes.
        let map = self.wedge_map(plan, edge, tri_r)?;
        for &t in tri_r {
            let tp = self.tris[t as usize].p;
            for (c, &w) in self.tris[t as usize].w.iter().enumerate() {
                if tp[c] == r && !map.pairs().iter().any(|m| m[0] == w) {
                    return None;
                }
            }
        }
        // No triangle may flip, in any instance.
        let guard = &self.subs[self.vsub[k as usize] as usize].guard;
        for &t in tri_k.iter().filter(|t| !edge.contains(t)).chain(tri_r) {
            let v = self.tri_verts(t);
            let old = v.map(|x| self.verts[x as usize].pos);
            let new = v.map(|x| {
                if x == k || x == r {
                    plan.target
                } else {
                    self.verts[x as usize].pos
                }
            });
            let n0 = (old[1] - old[0]).cross(old[2] - old[0]);
            let n1 = (new[1] - new[0]).cross(new[2] - new[0]);
            if n0 != DVec3::ZERO && !guard.same_side(n0, n1) {
                return None;
            }
            if let Some(input) = decode_normal(self.tris[t as usize].n) {
                if !guard.same_side(input, n1) {
                    return None;
                }
            }
        }
        Some(map)
    }

    fn wedge_map(&self, plan: &Plan, edge: &[u32], tri_r: &[u32]) -> Option<WedgeMap> {
        let (k, r) = (plan.keep, plan.remove);
        let at = |t: u32, v: u32| {
            self.tris[t as usize]
                .p
                .iter()
                .position(|&x| x == v)
                .map_or(DEAD, |c| self.tris[t as usize].w[c])
        };
        // One wedge (kept exact by `apply`) is the common case: it is the one on the edge.
        let (nr, wr) = if self.verts[r as usize].wedge_count == 1 {
            (1, [at(edge[0], r), DEAD])
        } else {
            self.wedges_at(r)
        };
        if nr == 0 {
            return None;
        }
        if nr == 1 {
            // `remove` has one wedge: it becomes the wedge `keep` shows on the edge.
            let wk = at(edge[0], k);
            if edge.iter().any(|&t| at(t, k) != wk) {
                return None;
            }
            let mut map = WedgeMap::default();
            map.push([wr[0], wk]);
            return Some(map);
        }
        if nr == 2 {
            // A seam vertex moves along its seam: each side keeps its own wedge.
            if edge.len() != 2 {
                return None;
            }
            let (a, b) = (
                [at(edge[0], r), at(edge[0], k)],
                [at(edge[1], r), at(edge[1], k)],
            );
            if a[0] == b[0] || a[1] == b[1] {
                return None;
            }
            let mut map = WedgeMap::default();
            map.push(a);
            map.push(b);
            return Some(map);
        }
        // A corner: wedges on the edge's faces join `keep`'s wedge there; the others become new
        // wedges at `keep`'s position, so every face keeps its own attributes.
        let mut map = WedgeMap::default();
        for &e in edge {
            let (wr, wk) = (at(e, r), at(e, k));
            match map.target(wr) {
                Some(existing) if existing != wk => return None,
                Some(_) => {}
                None => map.push([wr, wk]),
            }
        }
        for &t in tri_r {
            let wr = at(t, r);
            if map.target(wr).is_none() {
                if map.len == MAX_WEDGES {
                    return None;
                }
                map.push([wr, NEW_WEDGE]);
            }
        }
        Some(map)
    }

    /// UV and colour of a new wedge at `at`, from the plane of triangle `t` (which uses `w`):
    /// barycentric coordinates of the projected point, extrapolated if it lies outside.
    fn extrapolate(&self, t: u32, at: DVec3) -> (Vec2, Vec4) {
        let tri = self.tris[t as usize].w;
        let [a, b, c] = self.tris[t as usize].p.map(|v| self.verts[v as usize].pos);
        let (e0, e1, d) = (b - a, c - a, at - a);
        let (d00, d01, d11) = (e0.dot(e0), e0.dot(e1), e1.dot(e1));
        let (d20, d21) = (d.dot(e0), d.dot(e1));
        let denom = d00 * d11 - d01 * d01;
        let (v, w) = if denom.abs() > 0.0 {
            (
                (d11 * d20 - d01 * d21) / denom,
                (d00 * d21 - d01 * d20) / denom,
            )
        } else {
            (0.0, 0.0)
        };
        let l = [(1.0 - v - w) as f32, v as f32, w as f32];
        let uv = (0..3).map(|i| self.uv[tri[i] as usize] * l[i]).sum();
        let color = (0..3).map(|i| self.color[tri[i] as usize] * l[i]).sum();
        (uv, color)
    }

    fn apply(&mut self, plan: &Plan, tri_k: &[u32], tri_r: &[u32], edge: &[u32], map: &[[u32; 2]]) {
        let (k, r) = (plan.keep, plan.remove);
        let mut map: WedgeMap = {
            let mut m = WedgeMap::default();
            map.iter().for_each(|&p| m.push(p));
            m
        };
        for i in 0..map.len {
            let [wr, target] = map.pairs[i];
            if target != NEW_WEDGE {
                continue;
            }
            let Some(&t) = tri_r
                .iter()
                .find(|&&t| self.tris[t as usize].w.contains(&wr))
            else {
                continue;
            };
            let (uv, color) = self.extrapolate(t, plan.target);
            let id = self.wedge_pos.len() as u32;
            self.wedge_pos.push(k);
            self.uv.push(uv);
            self.color.push(color);
            self.normal.push(self.normal[wr as usize]);
            map.pairs[i][1] = id;
        }
        let map = map.pairs();
        // The apexes of the edge triangles, which lose a triangle.
        let mut apexes = [DEAD; 2];
        for (a, &t) in apexes.iter_mut().zip(edge) {
            *a = self
                .tri_verts(t)
                .into_iter()
                .find(|&v| v != k && v != r)
                .unwrap_or(DEAD);
        }
        for &t in edge {
            self.tris[t as usize].p = [DEAD; 3];
        }
        for &t in tri_r {
            for c in 0..3 {
                let w = self.tris[t as usize].w[c];
                if self.tris[t as usize].p[c] == r {
                    if let Some(m) = map.iter().find(|m| m[0] == w) {
                        self.tris[t as usize].w[c] = m[1];
                        self.tris[t as usize].p[c] = k;
                    }
                }
            }
        }
        // Attributes: a full collapse interpolates each kept wedge towards its partner.
        if plan.full {
            let (pk, pr) = (self.verts[k as usize].pos, self.verts[r as usize].pos);
            let d = pr - pk;
            let len2 = d.length_squared();
            let t = if len2 > 0.0 {
                ((plan.target - pk).dot(d) / len2).clamp(0.0, 1.0) as f32
            } else {
                0.0
            };
            for &[wr, wk] in map {
                let (wr, wk) = (wr as usize, wk as usize);
                self.uv[wk] = self.uv[wk].lerp(self.uv[wr], t);
                self.color[wk] = self.color[wk].lerp(self.color[wr], t);
                let n = self.normal[wk].lerp(self.normal[wr], t);
                self.normal[wk] = if n.length_squared() > 1e-12 {
                    n.normalize()
                } else {
                    self.normal[wk]
                };
            }
        }
        for &[wr, _] in map {
            self.wedge_pos[wr as usize] = DEAD;
        }
        self.verts[k as usize].pos = plan.target;
        let qr = self.verts[r as usize].quadric;
        self.verts[k as usize].quadric += qr;
        self.stamp[k as usize] = self.stamp[k as usize].wrapping_add(1);
        self.stamp[r as usize] = self.stamp[r as usize].wrapping_add(1);
        let br = self.verts[r as usize].boundary;
        self.verts[k as usize].boundary |= br;
        let lr = self.verts[r as usize].locked;
        self.verts[k as usize].locked |= lr;
        // The merged triangle list goes to the end of the arena.
        let start = self.adj.len() as u32;
        for &t in tri_k.iter().chain(tri_r) {
            if self.alive(t) {
                self.adj.push(t);
            }
        }
        self.verts[k as usize].adj_start = start;
        self.verts[k as usize].adj_len = self.adj.len() as u32 - start;
        self.verts[r as usize].adj_len = 0;
        // Wedge counts change at `keep` and at the apexes that lost an edge triangle; a vertex
        // with one wedge keeps one.
        if map.len() > 1 || self.verts[k as usize].wedge_count > 1 {
            self.verts[k as usize].wedge_count = self.wedges_at(k).0 as u8;
        }
        for v in apexes {
            if v != DEAD && self.verts[v as usize].wedge_count > 1 {
                self.verts[v as usize].wedge_count = self.wedges_at(v).0 as u8;
            }
        }
    }
}

#[cfg(test)]
mod layout_tests {
    /// What planning a collapse reads about a vertex fits in two cache lines.
    #[test]
    fn a_vertex_is_two_cache_lines() {
        assert_eq!(std::mem::size_of::<super::Vert>(), 128);
    }

    /// A triangle, input normal included, is half a cache line.
    #[test]
    fn a_triangle_is_half_a_cache_line() {
        assert_eq!(std::mem::size_of::<super::Tri>(), 32);
    }

    /// The octahedral code keeps a direction to float precision, in all eight octants and on
    /// the axes, and marks zero as no normal.
    #[test]
    fn normals_survive_their_encoding() {
        use glam::DVec3;
        let mut dirs = vec![
            DVec3::X,
            -DVec3::X,
            DVec3::Y,
            -DVec3::Y,
            DVec3::Z,
            -DVec3::Z,
        ];
        for sx in [-1.0, 1.0] {
            for sy in [-1.0, 1.0] {
                for sz in [-1.0, 1.0] {
                    dirs.push(DVec3::new(0.3 * sx, 0.5 * sy, 0.8 * sz));
                    dirs.push(DVec3::new(2.0 * sx, 1e-3 * sy, 7.0 * sz));
                }
            }
        }
        for d in dirs {
            let back = super::decode_normal(super::encode_normal(d)).expect("a direction");
            let err = back.normalize().angle_between(d.normalize());
            assert!(err < 1e-6, "{d} came back as {back} ({err} rad)");
        }
        assert!(super::decode_normal(super::encode_normal(DVec3::ZERO)).is_none());
    }
}
