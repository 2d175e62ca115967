//! The workspace: the engine's stages over one part, or over one part per thread.
//!
//! A mesh that falls into many separate pieces (no edge between them) is loaded as one part
//! per thread, each holding whole pieces: the parts load, build quadrics and sweep in
//! parallel (see [`super::sweep`]). The collapse order stays one global order: the single
//! queue's last stretch takes, at every step, the part whose next candidate costs least, and
//! the result is the same as in one part, byte for byte, for any number of threads.

use std::sync::atomic::AtomicU32;
use std::sync::atomic::Ordering::Relaxed;

use glam::Vec2;
use horizon_mesh::{InstancedMesh, Submesh};
use rayon::prelude::*;

use super::{sweep, Only, Part, RunStats, Step, DEAD, PARALLEL_MIN};
use crate::options::SimplifyOptions;
use crate::weights::InstanceSet;
use crate::weld::Weld;

/// Scratch memory reused between simplifications: every buffer keeps its capacity.
#[derive(Debug)]
pub struct Workspace {
    /// One part, or one per thread on a large mesh of many pieces.
    parts: Vec<Part>,
    /// With several parts: for every loaded submesh, its triangles in input order as (part,
    /// triangle in the part). Empty with one part.
    layout: Vec<Vec<(u32, u32)>>,
    /// How the first part of the order is swept.
    pub(super) sweep: sweep::Settings,
    /// What the last run's sweeps did.
    pub(super) swept: sweep::Outcome,
    /// Distinct positions loaded.
    positions: usize,
}

impl Default for Workspace {
    fn default() -> Self {
        Self {
            parts: vec![Part::default()],
            layout: Vec::new(),
            sweep: sweep::Settings::default(),
            swept: sweep::Outcome::None,
            positions: 0,
        }
    }
}

impl Workspace {
    /// An empty workspace.
    pub fn new() -> Self {
        Self::default()
    }

    /// Checks the state the last simplification left: every live triangle has three distinct,
    /// live position vertices of its own submesh, every vertex's adjacency names only
    /// triangles that hold it, and, the no-flip promise, no triangle faces more than 90
    /// degrees away from its input normal in any instance (in the exact f64 positions, before
    /// export rounds them).
    pub fn validate(&self) -> Result<(), String> {
        for (i, part) in self.parts.iter().enumerate() {
            part.validate().map_err(|e| format!("part {i}: {e}"))?;
        }
        Ok(())
    }

    /// Stage 1: welds the instanced submeshes of `mesh` (in parallel), splits a large mesh of
    /// many pieces into one part per thread, and loads the parts. Returns the expanded
    /// triangle count loaded.
    pub(crate) fn load(&mut self, mesh: &InstancedMesh, sets: &[InstanceSet]) -> u64 {
        let weld = |(sub, set): (&Submesh, &InstanceSet)| {
            (set.count() > 0 && !sub.indices.is_empty()).then(|| crate::weld::weld(sub))
        };
        let vertices: usize = mesh.submeshes.iter().map(|s| s.positions.len()).sum();
        let welds: Vec<Option<Weld>> = if vertices < PARALLEL_MIN {
            mesh.submeshes.iter().zip(sets).map(weld).collect()
        } else {
            mesh.submeshes.par_iter().zip(sets).map(weld).collect()
        };
        let positions: usize = welds.iter().flatten().map(|w| w.positions as usize).sum();
        self.positions = positions;
        // Asked only of a large mesh: the first call starts the thread pool.
        let most = positions / self.sweep.part_vertices.max(1);
        let mut count = if most < 2 {
            1
        } else {
            rayon::current_num_threads().min(most).min(u8::MAX as usize)
        };
        self.layout.clear();
        let roots: Vec<Vec<u32>> = if count < 2 || self.sweep.share <= 0.0 {
            Vec::new()
        } else {
            welds
                .par_iter()
                .zip(&mesh.submeshes)
                .map(|(weld, sub)| weld.as_ref().map_or_else(Vec::new, |w| piece_roots(sub, w)))
                .collect()
        };
        let pieces = roots
            .iter()
            .flat_map(|r| r.iter().enumerate())
            .filter(|&(id, &root)| root as usize == id)
            .count();
        count = count.min(pieces);
        if count < 2 {
            self.parts.truncate(1);
            return self.parts[0].load(mesh, sets, &welds, None);
        }
        let owners = owners(&roots, count);
        self.parts.resize_with(count, Part::default);
        let expanded = self
            .parts
            .par_iter_mut()
            .enumerate()
            .map(|(i, part)| {
                let only = Only {
                    owners: &owners,
                    part: i as u8,
                    parts: count,
                };
                part.load(mesh, sets, &welds, Some(only))
            })
            .sum();
        // Where each input triangle went: parts keep input order, so the triangles of one
        // submesh in one part follow from its base, one after another.
        let mut next: Vec<u32> = vec![0; count];
        for (j, (s, weld)) in welds
            .iter()
            .enumerate()
            .filter_map(|(s, w)| w.as_ref().map(|w| (s, w)))
            .enumerate()
        {
            for (p, n) in next.iter_mut().enumerate() {
                *n = self.parts[p].subs[j].tri_base;
            }
            let mut tris = Vec::new();
            for ids in mesh.submeshes[s]
                .indices
                .chunks_exact(3)
                .filter_map(|t| weld.triangle(t))
            {
                let p = owners[s][ids[0] as usize] as usize;
                tris.push((p as u32, next[p]));
                next[p] += 1;
            }
            self.layout.push(tris);
        }
        expanded
    }

    /// Stage 2: quadrics, part by part in parallel.
    pub(crate) fn build_quadrics(&mut self, sets: &[InstanceSet], options: &SimplifyOptions) {
        match &mut self.parts[..] {
            [one] => one.build_quadrics(sets, options),
            parts => parts
                .par_iter_mut()
                .for_each(|part| part.build_quadrics(sets, options)),
        }
    }

    /// Stage 3: collapses in one global order of cost until the expanded count reaches
    /// `target`, the error bound is hit, or nothing more can collapse.
    ///
    /// Where a large mesh falls into many separate pieces, the first and largest part of the work
    /// runs piece by piece in sweeps of rising cost (see [`sweep`]), which keeps each piece in
    /// cache; the sweeps end in exactly the state of the single queue, which takes over for the
    /// rest. `None` means a sweep went past the target: the caller loads the mesh again and
    /// runs [`Self::run_strict`].
    pub(crate) fn run(
        &mut self,
        expanded: u64,
        target: u64,
        options: &SimplifyOptions,
    ) -> Option<RunStats> {
        let mut stats = RunStats {
            expanded,
            ..RunStats::default()
        };
        self.swept = sweep::Outcome::None;
        // A mesh smaller than two parts' worth fits in cache as it is: it stays in one queue.
        let large = self.positions >= 2 * self.sweep.part_vertices;
        let queued = if options.max_error.is_none() && self.sweep.share > 0.0 && large {
            let queued = sweep::sweep(&mut self.parts, self.sweep, &mut stats, target);
            self.swept = match queued {
                None => sweep::Outcome::ReachedTarget,
                Some(true) => sweep::Outcome::Swept,
                Some(false) => sweep::Outcome::None,
            };
            queued?
        } else {
            false
        };
        Some(run_queue(&mut self.parts, stats, target, options, queued))
    }

    /// Stage 3 in one queue from the start: [`Self::run`] without the sweeps.
    pub(crate) fn run_strict(
        &mut self,
        expanded: u64,
        target: u64,
        options: &SimplifyOptions,
    ) -> RunStats {
        let stats = RunStats {
            expanded,
            ..RunStats::default()
        };
        run_queue(&mut self.parts, stats, target, options, false)
    }

    /// Stage 4: the simplified mesh: surviving wedges of each submesh, compacted, with the
    /// input's materials, textures and instances. Submeshes left without triangles go, with
    /// their instances. Also returns, for every input submesh, its index in the output (`None`
    /// when it lost all its triangles and was dropped with its instances).
    pub(crate) fn assemble(&self, mesh: &InstancedMesh) -> (InstancedMesh, Vec<Option<usize>>) {
        let parts = &self.parts;
        // Each wedge belongs to one submesh, so the submeshes assemble in parallel, each
        // numbering its own wedges (atomics only to share the table; no two threads touch
        // one entry).
        let remap: Vec<Vec<AtomicU32>> = parts
            .iter()
            .map(|p| {
                (0..p.wedge_pos.len())
                    .map(|_| AtomicU32::new(DEAD))
                    .collect()
            })
            .collect();
        let build = |(j, info): (usize, &super::SubInfo)| {
            let mut sub = Submesh {
                material: mesh.submeshes[info.source].material,
                ..Submesh::default()
            };
            let mut normals = Vec::new();
            let mut uvs: Vec<Vec2> = Vec::new();
            let mut colors = Vec::new();
            let mut take = |p: usize, t: u32| {
                let part = &parts[p];
                if !part.alive(t) {
                    return;
                }
                for &w in &part.tris[t as usize].w {
                    let wi = w as usize;
                    let mut id = remap[p][wi].load(Relaxed);
                    if id == DEAD {
                        id = sub.positions.len() as u32;
                        remap[p][wi].store(id, Relaxed);
                        let v = part.wedge_pos[wi] as usize;
                        sub.positions.push(part.verts[v].pos.as_vec3());
                        normals.push(part.normal[wi]);
                        uvs.push(part.uv[wi]);
                        colors.push(part.color[wi]);
                    }
                    sub.indices.push(id);
                }
            };
            if self.layout.is_empty() {
                (info.tri_base..info.tri_end).for_each(|t| take(0, t));
            } else {
                self.layout[j]
                    .iter()
                    .for_each(|&(p, t)| take(p as usize, t));
            }
            sub.normals = info.has_normals.then_some(normals);
            sub.uvs = info.has_uvs.then_some(uvs);
            sub.colors = info.has_colors.then_some(colors);
            (info.source, sub)
        };
        let wedges: usize = parts.iter().map(|p| p.wedge_pos.len()).sum();
        let built: Vec<(usize, Submesh)> = if wedges < PARALLEL_MIN {
            parts[0].subs.iter().enumerate().map(build).collect()
        } else {
            parts[0].subs.par_iter().enumerate().map(build).collect()
        };
        // Submeshes that were not loaded (no instances, or no triangles) stay as they are.
        let mut out_subs: Vec<Option<Submesh>> = vec![None; mesh.submeshes.len()];
        let mut loaded = vec![false; mesh.submeshes.len()];
        for (source, sub) in built {
            loaded[source] = true;
            out_subs[source] = (!sub.indices.is_empty()).then_some(sub);
        }
        for (s, sub) in mesh.submeshes.iter().enumerate() {
            if !loaded[s] {
                out_subs[s] = Some(sub.clone());
            }
        }
        let keep: Vec<bool> = out_subs.iter().map(Option::is_some).collect();
        let mut out = InstancedMesh {
            submeshes: out_subs
                .into_iter()
                .map(Option::unwrap_or_default)
                .collect(),
            instances: mesh.instances.clone(),
            materials: mesh.materials.clone(),
            textures: mesh.textures.clone(),
        };
        let kept = out.retain_submeshes(&keep);
        (out, kept)
    }
}

/// Which part owns each position of each loaded submesh, from the first position of its
/// piece (`roots`): pieces in order of submesh and first position, cut into `count` runs of
/// about equal size.
fn owners(roots: &[Vec<u32>], count: usize) -> Vec<Vec<u8>> {
    let total: usize = roots.iter().map(Vec::len).sum();
    let mut seen = 0usize;
    roots
        .iter()
        .map(|roots| {
            let mut owner = vec![0u8; roots.len()];
            for (id, &root) in roots.iter().enumerate() {
                // A root comes first in its piece, so its owner is set before its members'.
                owner[id] = if root as usize == id {
                    ((seen * count / total.max(1)).min(count - 1)) as u8
                } else {
                    owner[root as usize]
                };
                seen += 1;
            }
            owner
        })
        .collect()
}

/// For every position of `sub`, the first position of its piece.
fn piece_roots(sub: &Submesh, weld: &Weld) -> Vec<u32> {
    let mut parent: Vec<u32> = (0..weld.positions).collect();
    for [a, b, c] in sub.indices.chunks_exact(3).filter_map(|t| weld.triangle(t)) {
        sweep::union(&mut parent, a, b);
        sweep::union(&mut parent, a, c);
    }
    (0..weld.positions)
        .map(|id| sweep::find(&mut parent, id))
        .collect()
}

/// The collapse loop over the parts' queues, always taking the least key of any part: one
/// global order. `queued` when the queues already hold the first round's candidates (left by
/// the sweeps); otherwise every round seeds them afresh.
fn run_queue(
    parts: &mut [Part],
    mut stats: RunStats,
    target: u64,
    options: &SimplifyOptions,
    mut queued: bool,
) -> RunStats {
    let max_cost_error = options.max_error.unwrap_or(f64::INFINITY);
    'rounds: while stats.expanded > target {
        if !std::mem::take(&mut queued) {
            match &mut *parts {
                [one] => one.seed_heap(),
                parts => parts.par_iter_mut().for_each(Part::seed_heap),
            }
        }
        let before = stats.collapses;
        while stats.expanded > target {
            // Entries older than an endpoint's last change are stale: dropped unseen.
            let mut best: Option<(u64, usize)> = None;
            for (i, part) in parts.iter_mut().enumerate() {
                let stamp = &part.stamp;
                let key = part.heap.peek_valid(|c| c.is_current(stamp));
                if let Some(key) = key {
                    if best.is_none_or(|(least, _)| key < least) {
                        best = Some((key, i));
                    }
                }
            }
            let Some((_, i)) = best else {
                break;
            };
            let part = &mut parts[i];
            let Some((_, c)) = part.heap.pop_valid(|_| true) else {
                break;
            };
            match part.step(c, &mut stats, max_cost_error) {
                Step::Rejected => {}
                Step::OverBound => break 'rounds,
                Step::Collapsed(keep) => {
                    let ring = std::mem::take(&mut part.ring);
                    for &u in &ring {
                        part.push(keep, u);
                    }
                    part.ring = ring;
                }
            }
        }
        if stats.collapses == before {
            break;
        }
    }
    stats
}
