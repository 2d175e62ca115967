//! Cuts: `GET /v1/cut` and the entries that cuts and streams carry (`DESIGN.md`, "Entries and
//! cuts").

use serde::{Deserialize, Serialize};

/// The solid angle (steradians) below which an object is not sent alone, unless a view asks
/// for another: an object of 1 m radius at 56 m.
pub const DEFAULT_MIN_SOLID_ANGLE: f64 = 1e-3;

/// The solid angle of one screen pixel unless a view asks for another: 1920 pixels across a
/// 60-degree field of view.
pub const DEFAULT_PIXEL_SOLID_ANGLE: f64 = 3.0e-7;

/// The geometric error, in pixels, that an object's level of detail may show unless a view
/// asks for another (0: every object at full detail).
pub const DEFAULT_MAX_PIXEL_ERROR: f64 = 1.0;

/// The most entries a cut holds unless a view asks for another number.
pub const DEFAULT_MAX_ENTRIES: u64 = 4_000;

/// What a client asks of one cut: where it is, what it must see and what it can afford.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[cfg_attr(feature = "openapi", derive(utoipa::ToSchema))]
pub struct View {
    /// The viewer's position, world space.
    pub eye: [f64; 3],
    /// The smallest solid angle (steradians) shown as itself: in (0, 4 pi).
    #[serde(default = "default_min_solid_angle")]
    pub min_solid_angle: f64,
    /// The solid angle of one screen pixel: in (0, 4 pi).
    #[serde(default = "default_pixel_solid_angle")]
    pub pixel_solid_angle: f64,
    /// The most geometric error, in pixels of `pixel_solid_angle`, an object's level of
    /// detail may show at its nearest point (0: full detail): at least 0.
    #[serde(default = "default_max_pixel_error")]
    pub max_pixel_error: f64,
    /// Whether the client draws impostors (default true). Where a node's impostor is within
    /// a pixel of its content, the cut sends it instead of the node's aggregate.
    #[serde(default = "default_impostors")]
    pub impostors: bool,
    /// Whether a node whose objects' models are cheaper to send shared, at their levels of
    /// detail and placed, than as one aggregate mesh is sent that way, as an `instances`
    /// entry (default true).
    #[serde(default = "default_instances")]
    pub instances: bool,
    /// What the cut may cost.
    #[serde(default)]
    pub budgets: Budgets,
}

fn default_min_solid_angle() -> f64 {
    DEFAULT_MIN_SOLID_ANGLE
}

fn default_pixel_solid_angle() -> f64 {
    DEFAULT_PIXEL_SOLID_ANGLE
}

fn default_max_pixel_error() -> f64 {
    DEFAULT_MAX_PIXEL_ERROR
}

fn default_impostors() -> bool {
    true
}

fn default_instances() -> bool {
    true
}

/// The largest `max_entries` a view may ask for.
pub const MAX_ENTRIES_LIMIT: u64 = 1_000_000;

impl View {
    /// A view at `eye` with the default solid angles and budgets.
    pub fn at(eye: [f64; 3]) -> Self {
        Self {
            eye,
            min_solid_angle: DEFAULT_MIN_SOLID_ANGLE,
            pixel_solid_angle: DEFAULT_PIXEL_SOLID_ANGLE,
            max_pixel_error: DEFAULT_MAX_PIXEL_ERROR,
            impostors: true,
            instances: true,
            budgets: Budgets::default(),
        }
    }

    /// Checks what serde cannot: finite numbers, solid angles in (0, 4 pi), budgets of at
    /// least 1 and `max_entries` at most [`MAX_ENTRIES_LIMIT`]. The error is one line.
    pub fn check(&self) -> Result<(), String> {
        if let Some(axis) = self
            .eye
            .iter()
            .position(|v| !v.is_finite() || v.abs() > 1e15)
        {
            return Err(format!(
                "eye[{axis}] = {} is not a finite coordinate",
                self.eye[axis]
            ));
        }
        let sphere = 4.0 * std::f64::consts::PI;
        for (name, value) in [
            ("min_solid_angle", self.min_solid_angle),
            ("pixel_solid_angle", self.pixel_solid_angle),
        ] {
            if !(value.is_finite() && value > 0.0 && value < sphere) {
                return Err(format!("{name} = {value} is not in (0, 4 pi)"));
            }
        }
        if !(self.max_pixel_error.is_finite() && self.max_pixel_error >= 0.0) {
            return Err(format!(
                "max_pixel_error = {} is not a finite number of pixels, at least 0",
                self.max_pixel_error
            ));
        }
        let b = &self.budgets;
        for (name, value) in [
            ("max_entries", b.max_entries),
            ("max_bytes", b.max_bytes),
            ("max_draw_calls", b.max_draw_calls),
            ("max_triangles", b.max_triangles),
        ] {
            if value == Some(0) {
                return Err(format!("{name} must be at least 1"));
            }
        }
        if let Some(n) = b.max_entries.filter(|&n| n > MAX_ENTRIES_LIMIT) {
            return Err(format!(
                "max_entries = {n} is over the limit of {MAX_ENTRIES_LIMIT}"
            ));
        }
        Ok(())
    }
}

/// The budgets of a cut. Refinement goes largest solid angle first and never exceeds one:
/// it stops before `max_entries` would be exceeded, and skips a refinement that would exceed
/// `max_bytes`, `max_draw_calls` or `max_triangles` while smaller ones go on filling it. A
/// shared asset counts once per cut, and the placements of one asset one draw call, as a
/// batching client draws them.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[cfg_attr(feature = "openapi", derive(utoipa::ToSchema))]
#[serde(deny_unknown_fields)]
pub struct Budgets {
    /// The most entries (default [`DEFAULT_MAX_ENTRIES`]).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub max_entries: Option<u64>,
    /// The most asset bytes.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub max_bytes: Option<u64>,
    /// The most draw calls.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub max_draw_calls: Option<u64>,
    /// The most triangles drawn.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub max_triangles: Option<u64>,
}

/// The budget that stopped a cut's refinement, or that refused one of its refinements first
/// ([`CutResponse::stopped_by`]).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[cfg_attr(feature = "openapi", derive(utoipa::ToSchema))]
#[serde(rename_all = "snake_case")]
pub enum StoppedBy {
    /// `max_entries`.
    MaxEntries,
    /// `max_bytes`.
    MaxBytes,
    /// `max_draw_calls`.
    MaxDrawCalls,
    /// `max_triangles`.
    MaxTriangles,
}

/// `GET /v1/cut`: every object of `generation`, counted exactly once.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[cfg_attr(feature = "openapi", derive(utoipa::ToSchema))]
pub struct CutResponse {
    /// The generation whose objects the cut covers.
    pub generation: u64,
    /// The generation whose aggregates it names.
    pub published: u64,
    /// Objects at `generation`: the sum of the entries' `covers`.
    pub objects: u64,
    /// The entries, largest solid angle first.
    pub entries: Vec<Entry>,
    /// `max_entries` if the entry budget stopped refinement; otherwise the byte, draw-call or
    /// triangle budget that refused a refinement first (refinement went on past it with
    /// smaller nodes); none if no budget refused one.
    pub stopped_by: Option<StoppedBy>,
}

/// What an entry is.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[cfg_attr(feature = "openapi", derive(utoipa::ToSchema))]
#[serde(rename_all = "snake_case")]
pub enum EntryKind {
    /// An object, drawn as its model.
    Object,
    /// A BVH node, drawn as its aggregate.
    Aggregate,
    /// A BVH node, drawn as orthoview impostors.
    Impostor,
    /// A BVH node, drawn as its objects: each object's model at its level of detail, placed.
    /// The models are shared with every other entry that draws them.
    Instances,
}

/// What an asset is to the entry that names it.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[cfg_attr(feature = "openapi", derive(utoipa::ToSchema))]
#[serde(rename_all = "snake_case")]
pub enum AssetRole {
    /// An aggregate's merged mesh (GLB).
    Mesh,
    /// A model's stored GLB.
    Model,
    /// An orthoview image.
    Orthoview,
    /// An object's coarsest level of detail, which a client may draw until the entry's own
    /// level has loaded (progressive loading); not counted in the entry's `bytes`.
    Preview,
}

/// A blob an entry needs, served at `/assets/{hash}`.
#[derive(Clone, Debug, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[cfg_attr(feature = "openapi", derive(utoipa::ToSchema))]
pub struct Asset {
    /// Its content hash.
    pub hash: String,
    /// Its size in bytes (uncompressed).
    pub bytes: u64,
    /// What it is.
    pub role: AssetRole,
}

/// Where an asset is drawn: a 3x4 column-major model-to-world matrix.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[cfg_attr(feature = "openapi", derive(utoipa::ToSchema))]
pub struct Placement {
    /// The asset's hash.
    pub asset: String,
    /// Columns x, y, z, then the translation.
    pub matrix: [f32; 12],
}

/// One entry of a cut.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[cfg_attr(feature = "openapi", derive(utoipa::ToSchema))]
pub struct Entry {
    /// Names one content, never two: `o:<object id>@<generation that placed it>` for an
    /// object, `n:<node id>@<asset hash>` for an aggregate, `n:<node id>@<impostor key>.<views
    /// sent, a bit each, hex>` for an impostor, `n:<node id>@i<16 hex digits>/<16 hex
    /// digits>` for instances (a hash of the objects and their placements, then one of their
    /// levels of detail: like an object's `/<level>`, the part a stream's hysteresis may keep
    /// apart from a fresh cut).
    pub id: String,
    /// What it is.
    pub kind: EntryKind,
    /// The blobs it needs.
    pub assets: Vec<Asset>,
    /// Where they are drawn (an aggregate's mesh is in world space: the identity; an impostor
    /// has none, its views say where they are; instances have one per object).
    pub placements: Vec<Placement>,
    /// The level of detail of an object's model (0: the model as uploaded; see the model's
    /// `levels`): the coarsest whose error, projected at the object's nearest point, is at
    /// most the view's `max_pixel_error` and whose textures still give a texel per pixel.
    pub level: u32,
    /// A new or moved object that the published aggregates do not hold yet.
    #[serde(default, skip_serializing_if = "std::ops::Not::not")]
    pub pending: bool,
    /// Asset bytes.
    pub bytes: u64,
    /// Triangles drawn (0 for an impostor: its splats are not counted as triangles).
    pub triangles: u64,
    /// Draw calls.
    pub draw_calls: u64,
    /// A sphere around what it draws: centre.
    pub center: [f32; 3],
    /// And radius.
    pub radius: f32,
    /// The objects of the cut's generation that it stands for.
    pub covers: u64,
    /// An impostor's orthoviews (kind `impostor` only).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub impostor: Option<Impostor>,
}

/// The orthoviews of an impostor entry that face the viewer (Chaudhuri et al. 2009): each an
/// orthographic depth image of the box `min`..`max` looking along a canonical direction.
///
/// A view's image plane is perpendicular to `direction`, with `u = normalize(up x d)` (`up` the
/// world's y, or z when `d` is vertical) and `v = d x u`; pixel (0, 0)'s corner is at the
/// smallest `u` and `v` of the box's corners, and pixels are square, `pixel` world units,
/// `width` x `height` of them. Depth 1..=65535 spans the box's extent along `d` from its
/// nearest corner; 0 is empty.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[cfg_attr(feature = "openapi", derive(utoipa::ToSchema))]
pub struct Impostor {
    /// The box's smallest corner.
    pub min: [f32; 3],
    /// Its largest.
    pub max: [f32; 3],
    /// Nearest the view direction first.
    pub views: Vec<ImpostorView>,
}

/// One orthoview of an [`Impostor`]: three PNGs, named by their asset hashes.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[cfg_attr(feature = "openapi", derive(utoipa::ToSchema))]
pub struct ImpostorView {
    /// The canonical direction it looks along, from {-1, 0, 1}^3.
    pub direction: [i8; 3],
    /// Pixels across.
    pub width: u32,
    /// Pixels down.
    pub height: u32,
    /// A pixel's size, world units.
    pub pixel: f32,
    /// sRGB colour, alpha the pixel's coverage (RGBA 8).
    pub color: String,
    /// Depth (grey 16).
    pub depth: String,
    /// Octahedral normals (grey and alpha 8: the two coordinates).
    pub normal: String,
}
