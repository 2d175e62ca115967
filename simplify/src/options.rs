//! What a simplification is asked for, and what it reports back.

use serde::Serialize;

/// How many expanded triangles to keep.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Target {
    /// A fraction in `[0, 1]` of the input's expanded triangles.
    Ratio(f64),
    /// An absolute number of expanded triangles.
    Triangles(u64),
}

impl Target {
    /// The expanded triangle count to stop at, for an input of `expanded` triangles.
    pub fn resolve(&self, expanded: u64) -> u64 {
        match *self {
            Target::Ratio(r) => (expanded as f64 * r.clamp(0.0, 1.0)).round() as u64,
            Target::Triangles(n) => n.min(expanded),
        }
    }
}

/// Knobs of the collapse engine. Start from a preset.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SimplifyOptions {
    /// Weight of the constraint planes through boundary edges (edges with one triangle in
    /// their submesh, which includes material borders), relative to the face quadrics.
    pub boundary_weight: f64,
    /// Weight of the constraint planes through UV and normal seams.
    pub seam_weight: f64,
    /// Never move a boundary vertex (keeps submeshes watertight against their neighbours).
    pub lock_boundary: bool,
    /// Stop once the next collapse would exceed this error (world units), even above target.
    pub max_error: Option<f64>,
}

impl SimplifyOptions {
    /// The default: boundaries and seams held by strong constraint planes but free to slide.
    pub fn balanced() -> Self {
        Self {
            boundary_weight: 4.0,
            seam_weight: 1.0,
            lock_boundary: false,
            max_error: None,
        }
    }

    /// Boundary vertices never move: for aggregates whose pieces must keep meeting exactly.
    pub fn locked_boundary() -> Self {
        Self {
            lock_boundary: true,
            ..Self::balanced()
        }
    }

    /// Light constraints: the smallest error on closed surfaces, at the cost of borders.
    pub fn aggressive() -> Self {
        Self {
            boundary_weight: 0.5,
            seam_weight: 0.25,
            ..Self::balanced()
        }
    }
}

impl Default for SimplifyOptions {
    fn default() -> Self {
        Self::balanced()
    }
}

/// What a simplification did.
#[derive(Clone, Debug, Default, PartialEq, Serialize)]
pub struct SimplifyReport {
    /// `"ias"` or `"qem"`.
    pub method: &'static str,
    /// Expanded triangles (as drawn) before.
    pub triangles_in: u64,
    /// Expanded triangles after.
    pub triangles_out: u64,
    /// The expanded count asked for.
    pub triangles_target: u64,
    /// Triangles stored once per submesh, before.
    pub unique_triangles_in: u64,
    /// Triangles stored once per submesh, after.
    pub unique_triangles_out: u64,
    /// Edge collapses performed.
    pub collapses: u64,
    /// The largest quadric error reached, as a root-mean-square distance in world units.
    pub error: f64,
    /// Wall time of the simplification proper (not import or export).
    pub seconds: f64,
}
