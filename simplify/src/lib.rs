//! Simplification of instanced meshes: instance-aware simplification (IAS, Azim et al. 2014,
//! section 6), the classic quadric baseline on the expanded mesh, and Metro-style Hausdorff
//! distance.
//!
//! # Layout
//! - [`simplify`] / [`simplify_with`]: IAS, the entry point. [`simplify_qem`]: the baseline.
//! - `engine`: the collapse engine both share (welding, seams, global cost order, checks).
//! - `weights`: how instances fold into the quadrics (M^T Q M, summed).
//! - [`quadric`]: error quadrics (eqs. 4 to 6).
//! - [`qem`]: expansion into one instance for the baseline.
//! - [`options`]: targets, option presets and the report.
//! - [`distance`]: Metro-style symmetric Hausdorff distance through a triangle BVH.

mod baseline;
pub mod distance;
mod engine;
pub mod options;
pub mod qem;
pub mod quadric;
mod radix_heap;
mod weights;
mod weld;

use std::time::Instant;

use horizon_mesh::{InstancedMesh, InvalidMesh};

pub use baseline::simplify_meshopt;
pub use engine::Workspace;
pub use options::{SimplifyOptions, SimplifyReport, Target};

/// Why a simplification was refused.
#[derive(Debug, thiserror::Error)]
pub enum SimplifyError {
    /// The input breaks the mesh model's invariants.
    #[error("invalid mesh: {0}")]
    InvalidMesh(#[from] InvalidMesh),
    /// The ratio is outside [0, 1] or not a number.
    #[error("ratio {0} is not a fraction between 0 and 1")]
    BadRatio(f64),
}

/// A simplified mesh and what it took.
#[derive(Debug, Clone)]
pub struct Simplified {
    /// The simplified mesh: same materials, textures and instances (less any submesh that
    /// lost all its triangles).
    pub mesh: InstancedMesh,
    /// Counts, error and time.
    pub report: SimplifyReport,
    /// For every input submesh, its index in `mesh`, or `None` if it lost all its triangles.
    /// Empty for [`simplify_meshopt`], which merges every submesh into one.
    pub kept: Vec<Option<usize>>,
}

/// Instance-aware simplification of `mesh` down to `target` expanded triangles.
pub fn simplify(
    mesh: &InstancedMesh,
    target: Target,
    options: &SimplifyOptions,
) -> Result<Simplified, SimplifyError> {
    simplify_with(mesh, target, options, &mut Workspace::new())
}

/// [`simplify`] reusing the buffers of `workspace`.
pub fn simplify_with(
    mesh: &InstancedMesh,
    target: Target,
    options: &SimplifyOptions,
    workspace: &mut Workspace,
) -> Result<Simplified, SimplifyError> {
    let start = Instant::now();
    // Stage 1: check the input and the target.
    let triangles_target = checked_target(mesh, target)?;
    Ok(run_engine(
        mesh,
        triangles_target,
        options,
        workspace,
        start,
    ))
}

/// Validates `mesh` and resolves `target` against its expanded triangle count.
fn checked_target(mesh: &InstancedMesh, target: Target) -> Result<u64, SimplifyError> {
    mesh.validate()?;
    if let Target::Ratio(r) = target {
        if !(0.0..=1.0).contains(&r) {
            return Err(SimplifyError::BadRatio(r));
        }
    }
    Ok(target.resolve(mesh.expanded_triangle_count()))
}

/// Stages 2 and 3 of [`simplify_with`] on a mesh already validated; the report's time runs
/// from `start`.
fn run_engine(
    mesh: &InstancedMesh,
    triangles_target: u64,
    options: &SimplifyOptions,
    workspace: &mut Workspace,
    start: Instant,
) -> Simplified {
    let triangles_in = mesh.expanded_triangle_count();
    // Stage 2: fold the instances of each submesh into weights (M^T Q M, summed).
    let by_submesh = mesh.instances_by_submesh();
    let sets: Vec<weights::InstanceSet> = by_submesh
        .iter()
        .map(|ks| weights::InstanceSet::new(ks.iter().map(|&k| &mesh.instances[k])))
        .collect();
    // Stage 3: load, weld, classify; quadrics; collapse in one global order; assemble.
    // Submeshes without instances draw nothing and stay as they are; triangles with a repeated
    // position are dropped on load, so `loaded` may be below `triangles_in`.
    let loaded = workspace.load(mesh, &sets);
    workspace.build_quadrics(&sets, options);
    let stats = workspace
        .run(loaded, triangles_target, options)
        .unwrap_or_else(|| {
            // A sweep reached the target inside the strict order's last stretch: again, in
            // one queue.
            workspace.load(mesh, &sets);
            workspace.build_quadrics(&sets, options);
            workspace.run_strict(loaded, triangles_target, options)
        });
    let (out, kept) = workspace.assemble(mesh);
    let report = SimplifyReport {
        method: "ias",
        triangles_in,
        triangles_out: out.expanded_triangle_count(),
        triangles_target,
        unique_triangles_in: mesh.unique_triangle_count(),
        unique_triangles_out: out.unique_triangle_count(),
        collapses: stats.collapses,
        error: stats.error,
        seconds: start.elapsed().as_secs_f64(),
    };
    debug_assert_eq!(report.triangles_out, stats.expanded);
    Simplified {
        mesh: out,
        report,
        kept,
    }
}

/// The baseline: `mesh` expanded into one instance, then the same engine. The reported time
/// is the simplification of the expanded mesh, as for the third-party simplifiers, which are
/// handed the expanded mesh; the expansion itself is not counted.
pub fn simplify_qem(
    mesh: &InstancedMesh,
    target: Target,
    options: &SimplifyOptions,
) -> Result<Simplified, SimplifyError> {
    let triangles_target = checked_target(mesh, target)?;
    // The expansion of a valid mesh is valid: it is not checked again, nor timed.
    let expanded = qem::expand_to_single_instance(mesh);
    let start = Instant::now();
    let mut result = run_engine(
        &expanded,
        triangles_target,
        options,
        &mut Workspace::new(),
        start,
    );
    result.report.method = "qem";
    result.report.unique_triangles_in = mesh.unique_triangle_count();
    Ok(result)
}
