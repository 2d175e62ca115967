//! Metro-style symmetric Hausdorff distance between two triangle meshes (Cignoni, Rocchini and
//! Scopigno 1998, "Metro: measuring error on simplified surfaces"), sampled the way MeshLab's
//! `get_hausdorff_distance` filter samples with vertex, edge and face sampling on; exact
//! point-to-triangle distances by Ericson's Voronoi-region method ("Real-Time Collision
//! Detection", 2005, section 5.1.5) through a BVH over the target's triangles.
//!
//! For each direction X -> Y the samples on X are:
//! - every vertex that a triangle of X uses;
//! - edge samples: the unique edges (by vertex index) share `samples` points in proportion to
//!   their length, evenly spaced inside each edge without touching its ends (MeshLab's
//!   `EdgeUniform`, which also gets the full sample count);
//! - face samples: `samples` area-uniform points, stratified along the cumulative area and
//!   jittered by a seeded counter-based generator (MeshLab draws the same distribution with
//!   plain Monte Carlo).
//!
//! Each sample's distance to Y is the exact distance to Y's nearest triangle. The direction's
//! figures are the maximum, mean and RMS over its samples; the Hausdorff distance is the larger of
//! the two maxima. Everything is deterministic for a given seed, whatever the thread count.
//!
//! Differences from MeshLab: it samples a random subset of `samples` vertices when a mesh has
//! more, where this samples them all (vertices are where a simplified surface strays most); and
//! its relative figure divides by the box of all vertices, where this uses the vertices that
//! triangles use. `tests/reference/check_simplify.py` checks that the two agree on the
//! simplified reference models.

mod bvh;
mod triangle;

use std::time::Instant;

use glam::{DVec3, Vec3};
use horizon_mesh::rng::{mix, Rng};
use horizon_mesh::{ExpandedMesh, InstancedMesh};
use rayon::prelude::*;
use serde::{Deserialize, Serialize};

pub use bvh::{Closest, InvalidBvh, TriangleBvh};
pub use triangle::{closest_on_triangle, closest_point_on_segment, closest_point_on_triangle};

/// Samples handled by one task; fixed so that sums come out the same on any thread count.
const CHUNK: usize = 1024;
/// Stream constants that give the two directions independent random sequences.
const FORWARD_STREAM: u64 = 0x0A;
const BACKWARD_STREAM: u64 = 0x0B;

/// How densely to sample.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct DistanceOptions {
    /// Area-uniform face samples per direction; the edge samples get the same budget, and every
    /// used vertex is sampled on top (as pymeshlab's `samplenum`).
    pub samples: usize,
    /// Seed of the face-sample jitter.
    pub seed: u64,
}

impl Default for DistanceOptions {
    fn default() -> Self {
        Self {
            samples: 100_000,
            seed: 0,
        }
    }
}

/// Distances from the samples of one mesh to the surface of the other.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct DirectionStats {
    /// Largest sample distance: the one-sided Hausdorff distance.
    pub max: f64,
    /// Mean sample distance.
    pub mean: f64,
    /// Root mean square of the sample distances.
    pub rms: f64,
    /// Number of samples (vertices, edge and face samples).
    pub samples: usize,
}

/// The symmetric surface distance between meshes A and B.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct DistanceReport {
    /// Samples on A measured to B.
    pub forward: DirectionStats,
    /// Samples on B measured to A.
    pub backward: DirectionStats,
    /// `max(forward.max, backward.max)`.
    pub hausdorff: f64,
    /// Bounding-box diagonal of A's used vertices (pymeshlab's relative figures use the first
    /// mesh's diagonal too).
    pub diagonal: f64,
    /// `hausdorff / diagonal`, or 0 when the diagonal is 0.
    pub hausdorff_rel_diag: f64,
    /// Wall-clock time of the whole computation.
    pub seconds: f64,
}

/// Why a distance could not be measured.
#[derive(Clone, Debug, PartialEq, Eq, thiserror::Error)]
pub enum DistanceError {
    /// A mesh has no triangles, so it has no surface to measure to or from.
    #[error("the {mesh} mesh has no triangles")]
    Empty {
        /// Which mesh: "first" or "second" (or "sampled" / "target" for [`one_sided`]).
        mesh: &'static str,
    },
    /// The index list is not a whole number of triangles.
    #[error("the {mesh} mesh has {count} indices, not a multiple of 3")]
    PartialTriangle {
        /// Which mesh.
        mesh: &'static str,
        /// Its index count.
        count: usize,
    },
    /// An index points past the vertex array.
    #[error("the {mesh} mesh has index {index} past its {vertices} vertices")]
    IndexOutOfRange {
        /// Which mesh.
        mesh: &'static str,
        /// The offending index.
        index: u32,
        /// The vertex count.
        vertices: usize,
    },
    /// A vertex used by a triangle is NaN or infinite.
    #[error("the {mesh} mesh has a non-finite vertex {vertex}")]
    NonFinite {
        /// Which mesh.
        mesh: &'static str,
        /// The vertex index.
        vertex: u32,
    },
}

/// The symmetric Metro distance between two meshes in world space.
pub fn hausdorff(
    a: &ExpandedMesh,
    b: &ExpandedMesh,
    options: &DistanceOptions,
) -> Result<DistanceReport, DistanceError> {
    let start = Instant::now();
    check(a, "first")?;
    check(b, "second")?;
    let diagonal = used_diagonal(a);
    let (bvh_a, bvh_b) = rayon::join(
        || TriangleBvh::new(triangles(a)),
        || TriangleBvh::new(triangles(b)),
    );
    let forward = measure(
        &sample_points(a, options.samples, options.seed, FORWARD_STREAM),
        &bvh_b,
    );
    let backward = measure(
        &sample_points(b, options.samples, options.seed, BACKWARD_STREAM),
        &bvh_a,
    );
    let hausdorff = forward.max.max(backward.max);
    Ok(DistanceReport {
        forward,
        backward,
        hausdorff,
        diagonal,
        hausdorff_rel_diag: if diagonal > 0.0 {
            hausdorff / diagonal
        } else {
            0.0
        },
        seconds: start.elapsed().as_secs_f64(),
    })
}

/// [`hausdorff`] between the expansions of two instanced meshes; `seconds` includes expanding.
pub fn hausdorff_instanced(
    a: &InstancedMesh,
    b: &InstancedMesh,
    options: &DistanceOptions,
) -> Result<DistanceReport, DistanceError> {
    let start = Instant::now();
    let (ea, eb) = rayon::join(|| a.expand(), || b.expand());
    let mut report = hausdorff(&ea, &eb, options)?;
    report.seconds = start.elapsed().as_secs_f64();
    Ok(report)
}

/// One direction only: samples on `from` measured to the surface in `to`, the same figures as
/// `hausdorff(from, to).forward`. Lets a caller build the BVH of a reference mesh once and
/// measure many candidates against it.
pub fn one_sided(
    from: &ExpandedMesh,
    to: &TriangleBvh,
    options: &DistanceOptions,
) -> Result<DirectionStats, DistanceError> {
    check(from, "sampled")?;
    if to.is_empty() {
        return Err(DistanceError::Empty { mesh: "target" });
    }
    Ok(measure(
        &sample_points(from, options.samples, options.seed, FORWARD_STREAM),
        to,
    ))
}

/// The sample points [`hausdorff`] takes on `mesh` in the forward direction: used vertices, then
/// edge samples, then face samples.
pub fn surface_samples(
    mesh: &ExpandedMesh,
    options: &DistanceOptions,
) -> Result<Vec<DVec3>, DistanceError> {
    check(mesh, "sampled")?;
    Ok(sample_points(
        mesh,
        options.samples,
        options.seed,
        FORWARD_STREAM,
    ))
}

impl TriangleBvh {
    /// The BVH over a mesh's triangles, after checking its indices and positions.
    pub fn from_mesh(mesh: &ExpandedMesh) -> Result<Self, DistanceError> {
        check(mesh, "target")?;
        Ok(Self::new(triangles(mesh)))
    }
}

// ---------------------------------------------------------------------------------------------
// Stage 1: input checks.

/// Checks that the mesh has triangles, whole index triples in range, and finite used vertices.
fn check(mesh: &ExpandedMesh, role: &'static str) -> Result<(), DistanceError> {
    if !mesh.indices.len().is_multiple_of(3) {
        return Err(DistanceError::PartialTriangle {
            mesh: role,
            count: mesh.indices.len(),
        });
    }
    if mesh.indices.is_empty() {
        return Err(DistanceError::Empty { mesh: role });
    }
    let vertices = mesh.positions.len();
    for &index in &mesh.indices {
        match mesh.positions.get(index as usize) {
            None => {
                return Err(DistanceError::IndexOutOfRange {
                    mesh: role,
                    index,
                    vertices,
                })
            }
            Some(p) if !p.is_finite() => {
                return Err(DistanceError::NonFinite {
                    mesh: role,
                    vertex: index,
                })
            }
            Some(_) => {}
        }
    }
    Ok(())
}

/// The mesh's triangles as vertex triples (call after [`check`]).
fn triangles(mesh: &ExpandedMesh) -> Vec<[Vec3; 3]> {
    mesh.indices
        .chunks_exact(3)
        .map(|t| [t[0], t[1], t[2]].map(|i| mesh.positions[i as usize]))
        .collect()
}

/// Bounding-box diagonal of the vertices that triangles use (call after [`check`]).
fn used_diagonal(mesh: &ExpandedMesh) -> f64 {
    let (mut lo, mut hi) = (DVec3::INFINITY, DVec3::NEG_INFINITY);
    for &i in &mesh.indices {
        let p = mesh.positions[i as usize].as_dvec3();
        lo = lo.min(p);
        hi = hi.max(p);
    }
    if lo.cmple(hi).all() {
        (hi - lo).length()
    } else {
        0.0
    }
}

// ---------------------------------------------------------------------------------------------
// Stage 2: sampling (call after `check`).

/// Vertex, edge and face samples of `mesh`, in that order.
fn sample_points(mesh: &ExpandedMesh, samples: usize, seed: u64, stream: u64) -> Vec<DVec3> {
    let mut points = vertex_samples(mesh);
    points.extend(edge_samples(mesh, samples));
    points.extend(face_samples(mesh, samples, seed, stream));
    points
}

/// Every vertex a triangle uses, in index order.
fn vertex_samples(mesh: &ExpandedMesh) -> Vec<DVec3> {
    let mut used = vec![false; mesh.positions.len()];
    for &i in &mesh.indices {
        used[i as usize] = true;
    }
    mesh.positions
        .iter()
        .zip(&used)
        .filter(|(_, &u)| u)
        .map(|(p, _)| p.as_dvec3())
        .collect()
}

/// `budget` points spread over the unique edges in proportion to length (MeshLab's
/// `EdgeUniform`): an edge whose cumulative-length interval holds `k` multiples of the spacing
/// gets `k` points at `i / (k + 1)`, `i = 1..=k`. The total is exactly `budget` unless every edge
/// has zero length.
fn edge_samples(mesh: &ExpandedMesh, budget: usize) -> Vec<DVec3> {
    let mut edges: Vec<u64> = Vec::with_capacity(mesh.indices.len());
    edges.extend(
        mesh.indices
            .chunks_exact(3)
            .flat_map(|t| [(t[0], t[1]), (t[1], t[2]), (t[2], t[0])])
            .filter(|(i, j)| i != j)
            .map(|(i, j)| (u64::from(i.min(j)) << 32) | u64::from(i.max(j))),
    );
    edges.par_sort_unstable();
    edges.dedup();
    let ends = |e: u64| {
        (
            mesh.positions[(e >> 32) as usize].as_dvec3(),
            mesh.positions[(e & 0xFFFF_FFFF) as usize].as_dvec3(),
        )
    };
    let lengths: Vec<f64> = edges
        .iter()
        .map(|&e| {
            let (p, q) = ends(e);
            p.distance(q)
        })
        .collect();
    let total: f64 = lengths.iter().sum();
    if budget == 0 || total <= 0.0 {
        return Vec::new();
    }
    let mut out = Vec::with_capacity(budget);
    let (mut cumulative, mut placed) = (0.0f64, 0usize);
    for (k, (&e, &len)) in edges.iter().zip(&lengths).enumerate() {
        cumulative += len;
        let upto = if k + 1 == edges.len() {
            budget
        } else {
            ((budget as f64 * cumulative / total) as usize).min(budget)
        };
        let count = upto.saturating_sub(placed);
        placed += count;
        let (p, q) = ends(e);
        let step = 1.0 / (count + 1) as f64;
        out.extend((1..=count).map(|i| p.lerp(q, step * i as f64)));
    }
    out
}

/// `count` area-uniform points: sample `i` falls at cumulative area `(i + u) / count` of the
/// total (stratified), at a uniformly random point of that triangle. Zero-area triangles are
/// never chosen; if all are zero-area there are no face samples.
///
/// Sample `i` takes draws `3i .. 3i + 3` of one seeded sequence, so each parallel task skips to
/// its own draws and the points do not depend on the thread count.
fn face_samples(mesh: &ExpandedMesh, count: usize, seed: u64, stream: u64) -> Vec<DVec3> {
    let corners = |t: usize| {
        let i = &mesh.indices[3 * t..3 * t + 3];
        [i[0], i[1], i[2]].map(|i| mesh.positions[i as usize].as_dvec3())
    };
    let triangles = mesh.indices.len() / 3;
    let mut cumulative = Vec::with_capacity(triangles);
    let mut total = 0.0f64;
    for t in 0..triangles {
        let [a, b, c] = corners(t);
        total += 0.5 * (b - a).cross(c - a).length();
        cumulative.push(total);
    }
    if count == 0 || total <= 0.0 {
        return Vec::new();
    }
    let sequence = Rng::new(mix(seed ^ mix(stream)));
    (0..count)
        .into_par_iter()
        .map(|i| {
            let mut rng = sequence.clone();
            rng.skip(3 * i as u64);
            let target = (i as f64 + rng.unit_f64()) / count as f64 * total;
            let t = cumulative
                .partition_point(|&c| c <= target)
                .min(triangles - 1);
            let [a, b, c] = corners(t);
            let s = rng.unit_f64().sqrt();
            let r = rng.unit_f64();
            // Relative to a, so that a coordinate shared by all three vertices stays exact.
            a + (b - a) * (s * (1.0 - r)) + (c - a) * (s * r)
        })
        .collect()
}

// ---------------------------------------------------------------------------------------------
// Stage 3: distance queries and statistics.

/// Distance from every point to the BVH's surface, reduced to max, mean and RMS. Chunks are fixed
/// and reduced in order, so the result does not depend on scheduling.
fn measure(points: &[DVec3], target: &TriangleBvh) -> DirectionStats {
    let partials: Vec<(f64, f64, f64)> = points
        .par_chunks(CHUNK)
        .map(|chunk| {
            let mut stack = Vec::with_capacity(64);
            let mut hint = None;
            let (mut max, mut sum, mut sum_sq) = (0.0f64, 0.0f64, 0.0f64);
            for &p in chunk {
                // Consecutive samples are close, so the previous answer seeds the pruning.
                let Some((slot, _, d2)) = target.closest_hinted(p, hint, &mut stack) else {
                    continue;
                };
                hint = Some(slot);
                let d = d2.sqrt();
                max = max.max(d);
                sum += d;
                sum_sq += d2;
            }
            (max, sum, sum_sq)
        })
        .collect();
    let (mut max, mut sum, mut sum_sq) = (0.0f64, 0.0f64, 0.0f64);
    for (m, s, q) in partials {
        max = max.max(m);
        sum += s;
        sum_sq += q;
    }
    let n = points.len();
    let mean_of = |x: f64| if n > 0 { x / n as f64 } else { 0.0 };
    DirectionStats {
        max,
        mean: mean_of(sum),
        rms: mean_of(sum_sq).sqrt(),
        samples: n,
    }
}
