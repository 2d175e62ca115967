//! Vertex runs: which submeshes write their vertices into shared accessors
//! (`share_vertices`).
//!
//! Submeshes of one attribute layout write their vertices into shared runs of up to 65,535
//! vertices (one position, normal, UV and colour accessor per run), and each primitive indexes
//! its part of the run with its own 16-bit index accessor, as glTF allows; readers that want a
//! primitive alone drop the vertices it does not index (ours does, in import). With quantized
//! positions a run is also bounded by the box its grid may cover.

use std::collections::BTreeMap;

use crate::model::{Aabb, Submesh};

/// Most vertices in a shared run: every index into it stays 16-bit.
const RUN_VERTICES: usize = 65_535;

/// Most runs of one layout open at once (each a box of its own), so that finding a run for a
/// submesh stays a bounded scan however scattered the boxes.
const OPEN_RUNS: usize = 16;

/// Which submeshes write their vertices together: with `share`, submeshes of one attribute
/// layout (normals, UVs, colours present or not) fill a run until the next would take it past
/// [`RUN_VERTICES`], or, with `reach` (quantized positions), past the box extent a member
/// tolerates; a submesh that alone exceeds the vertex limit, and every submesh without
/// `share`, has a run of its own. Returns the runs (submesh numbers in order) and, for each
/// submesh, its run and its place in it.
///
/// A submesh in its own run costs three or four accessors more than one sharing a run (a
/// position accessor with its bounds, normals, UVs): on an aggregate of many small instanced
/// submeshes those accessors are much of the JSON, and the JSON much of the file.
///
/// `reach[s]` is the largest box extent over which submesh `s`'s positions can be quantized
/// within the tolerance (see `Dequantize::fits` in `quantize.rs`). An aggregate mixes parts in
/// model space, a metre or two across, with geometry baked in world space a kilometre from the
/// origin; one run over both would round the small parts by centimetres, so a submesh joins the
/// first open run of its layout whose box, grown by its own, stays within every member's reach.
/// A run full of vertices closes, and past [`OPEN_RUNS`] of a layout the oldest does; with
/// every reach unbounded this is one open run per layout. A submesh whose own box is beyond
/// its reach keeps float positions wherever it goes, so it shares the runs of its layout kept
/// for such submeshes, unbounded; an empty one joins any run and bounds none.
pub(super) fn vertex_runs(
    submeshes: &[Submesh],
    share: bool,
    reach: Option<&[f32]>,
) -> (Vec<Vec<usize>>, Vec<(usize, usize)>) {
    /// A run still taking members: its number, vertices, box and the least reach among them.
    struct Open {
        run: usize,
        count: usize,
        bounds: Aabb,
        reach: f32,
    }
    let mut runs: Vec<Vec<usize>> = Vec::new();
    let mut run_of = Vec::with_capacity(submeshes.len());
    /// Normals, UVs and colours present or not, and whether the positions stay float.
    type Kind = ((bool, bool, bool), bool);
    // Per kind, the runs still open.
    let mut open: BTreeMap<Kind, Vec<Open>> = BTreeMap::new();
    for (s, sub) in submeshes.iter().enumerate() {
        let n = sub.positions.len();
        let layout = (
            sub.normals.is_some(),
            sub.uvs.is_some(),
            sub.colors.is_some(),
        );
        let mut bounds = Aabb::EMPTY;
        sub.positions.iter().for_each(|&p| bounds.grow(p));
        let own_extent = (bounds.max - bounds.min).max_element();
        let (own_reach, float) = match reach {
            Some(_) if n == 0 => (f32::INFINITY, false),
            Some(r) if own_extent <= r[s] => (r[s], false),
            Some(_) => (f32::INFINITY, true),
            None => (f32::INFINITY, false),
        };
        let candidates = open.entry((layout, float)).or_default();
        let fits_box = |o: &Open| {
            let grown = o.bounds.union(&bounds);
            n == 0 || (grown.max - grown.min).max_element() <= o.reach.min(own_reach)
        };
        let joined = share
            .then(|| {
                candidates
                    .iter()
                    .position(|o| o.count + n <= RUN_VERTICES && fits_box(o))
            })
            .flatten();
        if let Some(k) = joined {
            let o = &mut candidates[k];
            o.count += n;
            o.bounds = o.bounds.union(&bounds);
            o.reach = o.reach.min(own_reach);
            run_of.push((o.run, runs[o.run].len()));
            runs[o.run].push(s);
        } else {
            runs.push(vec![s]);
            run_of.push((runs.len() - 1, 0));
            if share && n <= RUN_VERTICES {
                // Runs this one's vertices would overflow are as good as full.
                candidates.retain(|o| o.count + n <= RUN_VERTICES);
                if candidates.len() == OPEN_RUNS {
                    candidates.remove(0);
                }
                candidates.push(Open {
                    run: runs.len() - 1,
                    count: n,
                    bounds,
                    reach: own_reach,
                });
            }
        }
    }
    (runs, run_of)
}

#[cfg(test)]
mod tests {
    use super::*;
    use glam::Vec3;
    use proptest::prelude::*;

    /// A submesh of `n` vertices spread over `[x, x + width]` on the x axis, with or without
    /// normals.
    fn strip(n: usize, x: f32, width: f32, normals: bool) -> Submesh {
        let positions: Vec<Vec3> = (0..n)
            .map(|i| Vec3::new(x + width * i as f32 / (n.max(2) - 1) as f32, 0.0, 0.0))
            .collect();
        Submesh {
            normals: normals.then(|| vec![Vec3::Z; n]),
            indices: (0..(n - n % 3) as u32).collect(),
            positions,
            ..Default::default()
        }
    }

    /// The runs of the simplest policy, which ignores boxes: one open run per layout, replaced
    /// when the next submesh would take it past the vertex limit.
    fn one_open_run_per_layout(submeshes: &[Submesh], share: bool) -> Vec<Vec<usize>> {
        let mut runs: Vec<Vec<usize>> = Vec::new();
        let mut open: BTreeMap<(bool, bool, bool), (usize, usize)> = BTreeMap::new();
        for (s, sub) in submeshes.iter().enumerate() {
            let n = sub.positions.len();
            let layout = (
                sub.normals.is_some(),
                sub.uvs.is_some(),
                sub.colors.is_some(),
            );
            match open.get_mut(&layout) {
                Some((run, count)) if share && *count + n <= RUN_VERTICES => {
                    *count += n;
                    runs[*run].push(s);
                }
                _ => {
                    runs.push(vec![s]);
                    if share && n <= RUN_VERTICES {
                        open.insert(layout, (runs.len() - 1, n));
                    }
                }
            }
        }
        runs
    }

    proptest! {
        #[test]
        fn without_a_reach_each_layout_has_one_open_run(
            parts in prop::collection::vec((0usize..40_000, any::<bool>()), 0..24),
            share in any::<bool>(),
        ) {
            let submeshes: Vec<Submesh> = parts
                .iter()
                .enumerate()
                .map(|(k, &(n, normals))| strip(n, k as f32, 1.0, normals))
                .collect();
            let (runs, run_of) = vertex_runs(&submeshes, share, None);
            prop_assert_eq!(&runs, &one_open_run_per_layout(&submeshes, share));
            for (s, &(run, at)) in run_of.iter().enumerate() {
                prop_assert_eq!(runs[run][at], s);
            }
        }
    }

    #[test]
    fn a_submesh_joins_a_run_only_within_every_members_reach() {
        // A tolerates a box of 3, B and C of 100. B's box stretches A's run to 6: past A's
        // reach though within B's own, so B opens a run of its own; C, beside A, rejoins A's
        // run, which stayed open beside B's.
        let submeshes = [
            strip(3, 0.0, 1.0, true),
            strip(3, 5.0, 1.0, true),
            strip(3, 1.5, 1.0, true),
        ];
        let (runs, _) = vertex_runs(&submeshes, true, Some(&[3.0, 100.0, 100.0]));
        assert_eq!(runs, vec![vec![0, 2], vec![1]]);
        // A submesh wider than its own reach keeps float positions wherever it goes: it
        // shares the float runs of its layout, whatever their boxes.
        let wide = [
            strip(3, 0.0, 10.0, true),
            strip(3, 500.0, 10.0, true),
            strip(3, 0.0, 1.0, true),
        ];
        let (runs, _) = vertex_runs(&wide, true, Some(&[1.0, 1.0, 100.0]));
        assert_eq!(runs, vec![vec![0, 1], vec![2]]);
    }
}
