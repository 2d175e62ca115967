//! The served cut: a BVH cut (core paper eq. 3 and section 3; `DESIGN.md`, "Cut test") over
//! the tree at the last committed generation, drawn with the published aggregates, under a
//! client's budgets (`DESIGN.md`, "Entries and cuts"; "Generations, pending objects,
//! completeness").
//!
//! [`plan`] refines best-first from the root: the node whose worst case (an `r_max` object at
//! the bound's nearest point) subtends the largest solid angle is replaced by its children (a
//! leaf by its objects) while that angle is at least `min_solid_angle` and the cut stays
//! within every budget. The entry budget stops refinement before the first refinement that
//! would exceed it. A refinement that would exceed the byte, draw-call or triangle budget is
//! skipped, its node left in the cut, and refinement goes on with the next node, so the
//! budget is filled by smaller nodes (measured against stopping there in
//! `lab/results/levels.md`: never lower PSNR, up to 4.6 dB higher); `stopped_by` is
//! `max_entries` where the entry budget stopped refinement, and otherwise the budget that
//! refused a refinement first. Every refinement replaces a node by exactly its children, so
//! every object of the generation is counted exactly once, by itself or by one ancestor: the
//! cut is complete.
//!
//! Two things differ from the plain BVH cut, both because the tree runs ahead of the
//! published aggregates:
//! - A node the published manifest has no aggregate for (a node the tree made since) is
//!   refined at once, whatever its size and the budgets: there is nothing to draw it with.
//! - An object placed or moved after the published generation is pending. Wherever it
//!   subtends at least `min_solid_angle` it is its own entry (`pending: true`), and the
//!   aggregate that would hold it covers one object fewer; an aggregate left covering nothing
//!   is not sent. That aggregate may still draw a moved object at its old place or a deleted
//!   one until the next publish: a bounded lag in what is drawn, never in what is counted.
//!
//! Impostors (Chaudhuri et al. 2009; `horizon_aggregate::impostors`): a node in the cut that
//! has an impostor is sent as its impostor instead of its aggregate when the view allows
//! impostors, no orthoview pixel covers more than a screen pixel there (the handover: the
//! nearest point of the node's outer sphere at least `pixel / pixel_angle` away, which the
//! world's q puts where the node's sphere subtends `min_solid_angle` at the default pixel),
//! and some views face the eye ([`horizon_impostor::facing`]: the three nearest the direction
//! to the node). Only nodes the cut would draw with an aggregate become impostors, so every
//! object that subtends `min_solid_angle` is still its own entry, and the cut stays complete.
//!
//! Instances (issue 26's reuse-aware cuts): a node the cut would draw with its aggregate is
//! sent as its objects instead, each its model at its level, placed, where the models cost
//! less than the aggregate. During refinement each object is charged its model level divided
//! by the model's uses in the world (`LevelChooser::instances_win`); such a node is never
//! refined. After refinement, each aggregate left is weighed again against the model levels
//! the cut still lacks (`Planner::share_models`, within [`SHARED_MODELS_FACTOR`]). On a
//! world of reused models the cut then downloads each model once, as naive instancing does;
//! on distinct content the aggregates stay.
//!
//! Budgets count a shared asset once (bytes and draw calls) and triangles per entry, as a
//! client drawing each asset's placements in one instanced batch spends them.
//!
//! [`Plan::diff`] turns two plans into a stream's delta: removals with their reasons, and
//! additions naming the entries they replace (load before drop). An instances entry that
//! replaces the held one of the same node and objects, its models at other levels, sends no
//! assets or placements but reuses the held entry's, renamed ([`Reuse`]).

use std::cmp::Ordering;
use std::collections::BinaryHeap;
use std::sync::{Arc, RwLock};

use foldhash::{HashMap, HashMapExt, HashSet, HashSetExt};

use glam::{Affine3A, Vec3};
use horizon_aggregate::AggregateManifest;
use horizon_bvh::{solid_angle, worst_case_solid_angle, NodeId, ObjectId};
use horizon_protocol::{
    Addition, Asset, AssetRole, Budgets, Entry, EntryKind, Impostor, ImpostorView, Placement,
    Removal, RemoveReason, Renamed, Reuse, StoppedBy, View, DEFAULT_MAX_ENTRIES,
};
use horizon_world::{Served, World, WorldError};

mod carry;

use carry::{consulted, BandWatch, LevelBand};

/// Plans the cut for `view` over what `served` holds at `generation`: see the module docs.
pub fn plan(served: &Served<'_>, models: &AssetTable, view: &View) -> Plan {
    plan_after(served, models, view, None)
}

/// [`plan`] for a client that holds `held`: an object keeps the level of detail it has there
/// while that level stays within [`LEVEL_MARGIN`] of the level it would be given afresh, and
/// a model the level its objects share there while that is fine enough and at most
/// [`MODEL_LEVEL_SLACK`] finer than needed (`share_levels`).
///
/// Levels are as the view asks also where a byte, draw-call or triangle budget refuses
/// refinement ([`Coarsening::AsAsked`]; why, in [`Coarsening::Search`]).
pub fn plan_after(
    served: &Served<'_>,
    models: &AssetTable,
    view: &View,
    held: Option<&Plan>,
) -> Plan {
    plan_with(served, models, view, held, Coarsening::AsAsked)
}

/// How a plan chooses levels of detail when a byte, draw-call or triangle budget binds.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Coarsening {
    /// Levels as the view asks, whatever the budgets: what the service plans.
    AsAsked,
    /// Levels as the view asks; where such a budget refuses a refinement, plan again with the
    /// objects that plan draws at their levels and every other object's chosen for pixels
    /// [`COARSENING_STEP`] times wider, then wider again up to [`MAX_COARSENING`], and keep
    /// the finest levels that refine as far as the coarsest do ([`search_coarsening`]).
    ///
    /// Issue 28 asks for this ("coarser levels are chosen before anything is left out"),
    /// and it is measured against [`Coarsening::AsAsked`] (`horizon-lab fidelity
    /// --coarsen-peer`, `lab/bench/coarsen.sh`, `lab/results/levels.md`): on the city and
    /// on 2,000 distinct buildings, at the 25 seeded views where a byte or triangle budget
    /// binds, it changes no cut, since refinement already goes on past a refusal and fills
    /// the budget. Before it did (refinement stopped at the first refusal) the search changed
    /// 1 cut and lost 5.8 dB of PSNR there, and coarsening every object alike changed 4 of 11
    /// and lost 4.7 to 7.9 dB in 3 of them. A cut is complete, so what a budget leaves out of
    /// refinement is drawn by an aggregate, made for its node's display distance, and that
    /// spends the budget better than coarser objects do. So the service does not search;
    /// the lab measures it.
    Search,
    /// The plan the search makes at this step ([`coarsening_step`]), marked `coarsened`;
    /// at 1, the plan at the view's own levels, unmarked, as [`Coarsening::AsAsked`] makes.
    Fixed(f32),
}

/// One step of the coarsening ladder: a pixel's width times the square root of 2, so that a
/// step halves a pixel's footprint's area.
pub const COARSENING_STEP: f32 = std::f32::consts::SQRT_2;

/// The widest pixel levels are chosen for when a budget binds: 64 times the view's (12 steps;
/// a model's chain of quarter-triangle levels is seldom longer than 6).
pub const MAX_COARSENING: f32 = 64.0;

/// Steps of [`COARSENING_STEP`] up to [`MAX_COARSENING`].
pub const COARSENING_STEPS: u32 = 12;

/// Step `k` of the coarsening ladder, `sqrt(2)^k`, exact at even steps (a power of 2) and
/// the power of 2 below times [`COARSENING_STEP`] at odd ones.
pub fn coarsening_step(k: u32) -> f32 {
    let even = 2f32.powi((k / 2) as i32);
    if k.is_multiple_of(2) {
        even
    } else {
        even * COARSENING_STEP
    }
}

/// [`plan_after`] with the coarsening of levels under a binding budget chosen by the caller.
pub fn plan_with(
    served: &Served<'_>,
    models: &AssetTable,
    view: &View,
    held: Option<&Plan>,
    coarsening: Coarsening,
) -> Plan {
    let fine = plan_at(served, models, view, held, 1.0, None, true);
    let fixed = match coarsening {
        Coarsening::AsAsked => return fine,
        Coarsening::Fixed(1.0) => return fine,
        Coarsening::Fixed(factor) => Some(factor),
        Coarsening::Search => None,
    };
    if !binds(&fine) {
        return fine;
    }
    // Objects drawn at the view's own levels keep them: coarsening is for what a budget
    // would otherwise leave to aggregates, not for the nearest and largest objects.
    let keep = fine.decisions.own_levels(served.tree.bvh.object_slots());
    let at = |factor: f32| plan_at(served, models, view, held, factor, Some(&keep), true);
    match fixed {
        Some(factor) => {
            let mut p = at(factor);
            p.coarsened = Some(factor);
            p
        }
        None => search_coarsening(fine, at),
    }
}

/// Whether a byte, draw-call or triangle budget refused a refinement: one was skipped, or
/// (refinement stopping there, [`plan_stopping`]) it is the plan's `stopped_by`.
fn binds(p: &Plan) -> bool {
    p.skipped > 0
        || matches!(
            p.stopped_by,
            Some(StoppedBy::MaxBytes | StoppedBy::MaxDrawCalls | StoppedBy::MaxTriangles)
        )
}

/// The plan the issue asks for when a budget binds (issue 28: "coarser levels are chosen
/// before anything is left out"), given `fine`, the plan at the view's own levels, which a
/// byte, draw-call or triangle budget stopped: the objects it draws keep their levels, every
/// other object's is chosen for a pixel `step` times wider (`plan_at(step)`), and the plan kept
/// is the one of the smallest step that refines as far as the widest does (the same number of
/// refinements, or refinement not stopped by such a budget at all).
///
/// Only levels change from step to step, and coarser levels cost fewer bytes and triangles,
/// so how far refinement goes mostly grows with the step, and the step is found by bisection
/// as if it always did: at most 5 plans besides `fine`. It is not always so (instances are
/// weighed by levels and never refined, and a kept and a coarsened object of one model may
/// need two of its levels), so the step returned reaches as far as the widest and stays
/// within the budgets, but a smaller one might too. Coarsening every object alike was measured and
/// lost: on 2,000 distinct buildings it drew more buildings but the nearest ones coarser, up
/// to 8 dB of PSNR below the plan at the view's own levels (`lab/results/levels.md`). Each
/// plan found by the search is marked `coarsened`: its levels depend on plans at other steps,
/// so a stream plans it again rather than carrying it.
fn search_coarsening(fine: Plan, plan_at: impl Fn(f32) -> Plan) -> Plan {
    let reach = |p: &Plan| {
        if binds(p) {
            p.decisions.refined.len()
        } else {
            usize::MAX
        }
    };
    let step = coarsening_step;
    let mark = |mut p: Plan, k: u32| {
        p.coarsened = Some(step(k));
        p
    };
    let at_fine = reach(&fine);
    let coarsest = plan_at(step(COARSENING_STEPS));
    let target = reach(&coarsest);
    if at_fine >= target {
        return mark(fine, 0);
    }
    // Step `lo` falls short of the target, step `hi` reaches it.
    let (mut lo, mut hi, mut best) = (0, COARSENING_STEPS, coarsest);
    while hi - lo > 1 {
        let mid = (lo + hi) / 2;
        let p = plan_at(step(mid));
        if reach(&p) >= target {
            hi = mid;
            best = p;
        } else {
            lo = mid;
        }
    }
    mark(best, hi)
}

/// [`plan`], but refinement stops at the first refinement that a byte, draw-call or
/// triangle budget refuses, instead of going on past it: what the service did before it
/// filled budgets, the peer the lab measures the fill against (`horizon-lab fidelity
/// --stop-peer`, `lab/results/levels.md`).
pub fn plan_stopping(served: &Served<'_>, models: &AssetTable, view: &View) -> Plan {
    plan_at(served, models, view, None, 1.0, None, false)
}

/// One plan with levels chosen for pixels `coarsening` times wider than the view's, but
/// those `keep` gives (by tree id; [`UNCHOSEN`]: none); refinements a byte, draw-call or
/// triangle budget refuses skipped (`skip_refused`, the service's way) or stopping
/// refinement ([`plan_stopping`]).
fn plan_at(
    served: &Served<'_>,
    models: &AssetTable,
    view: &View,
    held: Option<&Plan>,
    coarsening: f32,
    keep: Option<&[u8]>,
    skip_refused: bool,
) -> Plan {
    let mut planner = Planner::new(served, models, view);
    planner.skip_refused = skip_refused;
    planner.level_pixel_angle = planner.pixel_angle * coarsening;
    if let Some(keep) = keep {
        for (slot, &level) in planner.chosen.iter().zip(keep) {
            slot.set(level);
        }
    }
    if let Some(held) = held {
        planner.held_levels = held.held_levels(served.tree);
        // A held model level may cost more bytes than the levels charged: held only where
        // no byte budget could be overrun by it.
        if view.budgets.max_bytes.is_none() {
            planner.held_model_levels = held.model_levels();
        }
    }
    planner.seed();
    let stopped_by = planner.refine();
    planner.refined_entries = planner.totals.entries;
    planner.frontier = planner.frontier();
    planner.share_models();
    planner.finish(stopped_by)
}

/// A planned cut: what [`plan`] chose, with just enough to compare two plans; the wire
/// entries are made from it by [`Plan::entries`] or [`Plan::entry`].
#[derive(Clone, Debug)]
pub struct Plan {
    /// The manifest whose aggregates it names.
    pub manifest: Option<Arc<AggregateManifest>>,
    /// The model table its objects' assets are read from.
    pub models: Arc<Models>,
    /// The generation of the tree it was planned on.
    pub generation: u64,
    /// The published generation whose aggregates it names.
    pub published: u64,
    /// Objects at `generation`.
    pub objects: u64,
    /// The entries, in no particular order ([`Plan::entries`] sorts them).
    pub items: Vec<Planned>,
    /// The budget that stopped refinement, or refused a refinement first (see the module docs).
    pub stopped_by: Option<StoppedBy>,
    /// Objects left out because their model is not in the [`AssetTable`] yet (refresh it
    /// and plan again).
    pub missing_models: usize,
    /// The view it was planned for.
    pub view: View,
    /// What refinement decided, to tell whether a new eye would decide the same.
    pub decisions: Decisions,
    /// Where a byte, draw-call or triangle budget bound at the view's own levels of detail:
    /// how many times wider than the view's the pixel was that levels were chosen for (1:
    /// coarsening did not let refinement go further; see [`Coarsening::Search`]).
    pub coarsened: Option<f32>,
    /// Refinements a byte, draw-call or triangle budget refused and refinement went on past
    /// (0 for a plan of [`plan_stopping`]).
    pub skipped: usize,
}

/// The decisions that made a plan, by the node: with the same tree and the same view but
/// for the eye, planning again (with this plan held, [`plan_after`]) gives the same cut
/// when these decisions hold at the new eye ([`Decisions::hold_at`]) and so do the levels
/// that reach the wire ([`Plan::carry_to`]). Refinement took the nodes of `refined` in order
/// of their worst-case solid angle (each at least `min_solid_angle`), then either ran out of
/// nodes at or over it, or a budget refused `stopper`; `frontier` is every other node in the
/// cut.
#[derive(Clone, Debug, Default)]
pub struct Decisions {
    min_solid_angle: f32,
    refined: Vec<NodeId>,
    frontier: Vec<NodeId>,
    stopper: Option<NodeId>,
    over_at_seed: bool,
    /// Refinement went on past a refusal ([`Plan::skipped`]): `refined` and `frontier` do not
    /// say in which order refusals and refinements came, so the decisions never hold.
    skipped: bool,
    /// A byte, draw-call or triangle budget: totals are not monotone along refinement, so
    /// the order of the refined nodes matters too.
    ordered: bool,
    /// The entries refinement ended with, and the entry budget: whether another node's
    /// refinement would be refused too.
    entries: u64,
    max_entries: Option<u64>,
    /// Each pending object, and whether it subtended `min_solid_angle`.
    pending: Vec<(ObjectId, bool)>,
    /// Each object's own level of detail, of object entries and instances (before models
    /// share levels).
    levels: Vec<(ObjectId, u8)>,
    /// Every node whose instances refinement weighed against its aggregate (also of nodes
    /// refined later), and whether instances won.
    instances: Vec<(NodeId, bool)>,
    /// The level of every object [`Planner::share_models`] looked at, which with the cut
    /// refinement made decides what it switches.
    examined: Vec<(ObjectId, u8)>,
    /// Every object whose level the plan consulted, with that level: planning again, with
    /// the same node decisions and these levels, takes every step the same way. After
    /// [`Plan::carry_to`] took new levels (never under a byte, draw-call or triangle budget),
    /// every level consulted before (at the new eye) and every level it looked at: a
    /// superset of those planning again consults.
    consulted: Vec<(ObjectId, u8)>,
    /// Where each consulted level stays as it is, made at the first [`Plan::carry_to`]
    /// (empty before, and again once the chooser consults more objects).
    bands: Vec<LevelBand>,
    /// Which bands a carry checks (see [`BandWatch`]); none: every one.
    watch: Option<BandWatch>,
    /// Every node with an impostor that refinement put in the cut (also those refined later,
    /// and the children of a refused node), and the views it was charged for (0: none, its
    /// aggregate), with what deciding that again needs. After [`Decisions::refuse_instead`]
    /// the children are still the first refused node's: checking them again is only stricter,
    /// and without a byte, draw-call or triangle budget the new refused node's children
    /// decide nothing (each is one entry whatever it is drawn as).
    impostors: Vec<(NodeId, u16)>,
    nodes: Arc<NodeAssets>,
    pixel_angle: f32,
}

impl Decisions {
    /// Whether refinement at `eye`, on the tree the plan was made on, makes the same cut:
    /// the same nodes refined (in the same order where it matters), every other node left,
    /// every pending object on the same side of `min_solid_angle`, and a refusal of the same
    /// node or of one that grew past it (see [`Decisions::holds`]; [`Plan::carry_to`] then
    /// names it). Ties count as changes (the planner breaks them by node id), so "true" is
    /// exact: it evaluates the planner's own solid angles.
    pub fn hold_at(&self, tree: &horizon_world::Tree, eye: [f64; 3]) -> bool {
        self.holds(tree, eye).is_some()
    }

    /// [`Decisions::hold_at`], and which node the budget refuses there: the same
    /// (`Some(None)`), or the frontier node at this index (`Some(Some(i))`). A frontier node
    /// that grows past the refused one is refused in its place when refining it would go
    /// over the entry budget too, with no other budget and no pending object: the cut is
    /// the same, and only the node named as refused changes.
    fn holds(&self, tree: &horizon_world::Tree, eye: [f64; 3]) -> Option<Option<usize>> {
        if self.skipped {
            return None;
        }
        let hold = |yes: bool| yes.then_some(None);
        let eye = eye_of(eye);
        let bvh = &tree.bvh;
        let worst = |node: NodeId| node_worst_case(bvh, node, eye);
        let min = self.min_solid_angle;
        if self
            .pending
            .iter()
            .any(|&(o, seen)| subtends(bvh, o, eye, min) != Some(seen))
        {
            return None;
        }
        let imp = |n: NodeId| {
            let asset = self.nodes.get(n.0 as usize).and_then(Option::as_ref);
            asset.and_then(|a| a.impostor.as_ref())
        };
        if self.impostors.iter().any(|&(n, views)| {
            imp(n).map_or(0, |i| impostor_views(bvh, n, i, eye, self.pixel_angle)) != views
        }) {
            return None;
        }
        if self.over_at_seed {
            return Some(None);
        }
        // The weakest refined node, checking the order on the way where it matters.
        let mut weakest = f32::INFINITY;
        for &node in &self.refined {
            let a = worst(node)?;
            if a < min || (self.ordered && a >= weakest && weakest.is_finite()) {
                return None;
            }
            weakest = weakest.min(a);
        }
        // Every other node stays behind the refused one, or under the solid angle.
        let Some(x) = self.stopper else {
            return hold(
                self.frontier
                    .iter()
                    .all(|&n| worst(n).is_some_and(|a| a < min)),
            );
        };
        let ax = worst(x)?;
        if ax < min || ax >= weakest {
            return None;
        }
        // The frontier node refinement would take next instead, if one grew past it.
        let mut next: Option<(usize, f32)> = None;
        for (i, &node) in self.frontier.iter().enumerate() {
            let a = worst(node)?;
            if a >= weakest {
                return None;
            }
            if a >= ax && next.is_none_or(|(_, b)| a > b) {
                next = Some((i, a));
            }
        }
        let Some((i, af)) = next else {
            return Some(None);
        };
        // Ties decide by node id: count them as changes.
        let strictly_first = af > ax
            && self
                .frontier
                .iter()
                .enumerate()
                .all(|(k, &n)| k == i || worst(n).is_some_and(|a| a < af));
        let refused = !self.ordered
            && self.pending.is_empty()
            && strictly_first
            && self.max_entries.is_some_and(|max| {
                let node = self.frontier[i];
                let own = bvh.node(node).map_or(0, |n| u64::from(n.count() > 0));
                let refined = self.entries_refining(bvh, node);
                self.entries.saturating_sub(own) + refined > max
            });
        refused.then_some(Some(i))
    }

    /// The entries refining `node` puts in its place: a leaf's objects, or each child's
    /// aggregate (or instances, one entry all the same), or what stands for a child without
    /// one, as [`Planner::expand`] makes them. Only without pending objects (none is
    /// extracted) and with the node assets of the plan.
    fn entries_refining(&self, bvh: &horizon_bvh::Bvh, node: NodeId) -> u64 {
        let Some(n) = bvh.node(node) else {
            return 0;
        };
        if n.is_leaf() {
            return n.objects().count() as u64;
        }
        n.child_nodes()
            .map(|child| {
                let has_aggregate = self
                    .nodes
                    .get(child.0 as usize)
                    .is_some_and(Option::is_some);
                match bvh.node(child) {
                    Some(c) if has_aggregate => u64::from(c.count() > 0),
                    Some(_) => self.entries_refining(bvh, child),
                    None => 0,
                }
            })
            .sum()
    }

    /// Each object's own level by tree id, in a table of `slots` ([`UNCHOSEN`]: not in the
    /// cut).
    fn own_levels(&self, slots: usize) -> Vec<u8> {
        let mut levels = vec![UNCHOSEN; slots];
        for &(o, level) in &self.levels {
            if let Some(slot) = levels.get_mut(o.0 as usize) {
                *slot = level;
            }
        }
        levels
    }

    /// The node whose refinement a budget refused, if one did.
    pub fn refused(&self) -> Option<NodeId> {
        self.stopper
    }

    /// Makes frontier node `i` the refused one, and the refused one a frontier node.
    fn refuse_instead(&mut self, i: usize) {
        if let Some(x) = self.stopper.as_mut() {
            std::mem::swap(x, &mut self.frontier[i]);
        }
    }
}

/// A node's worst case seen from `eye`: an object of the node's `r_max` at its bound's
/// nearest point (`DESIGN.md`, "Cut test"). The planner and [`Decisions::hold_at`] both
/// use it, so that their decisions agree to the bit.
fn node_worst_case(bvh: &horizon_bvh::Bvh, node: NodeId, eye: Vec3) -> Option<f32> {
    let n = bvh.node(node)?;
    let b = n.bound();
    Some(worst_case_solid_angle(eye, b.centre, b.radius, n.r_max()))
}

/// Whether an object subtends `min` from `eye` (a pending object is then its own entry).
fn subtends(bvh: &horizon_bvh::Bvh, object: ObjectId, eye: Vec3, min: f32) -> Option<bool> {
    let s = bvh.object(object)?.sphere();
    Some(solid_angle(s.radius, (s.centre - eye).length()) >= min)
}

/// The level of detail of an object (`r`) seen from `eye`: 0 when its model is not in
/// `models` (the planner leaves such an object out, or draws it as level 0).
fn level_at(
    models: &Models,
    r: &horizon_bvh::ObjectRef<'_>,
    eye: Vec3,
    pixel_angle: f32,
    max_pixel_error: f64,
    held: Option<u8>,
) -> u8 {
    let Some(m) = models.get(r.model() as usize).and_then(Option::as_ref) else {
        return 0;
    };
    if m.levels.len() < 2 {
        return 0;
    }
    let s = r.sphere();
    let distance = (s.centre - eye).length() - s.radius;
    let scale = horizon_mesh::transform::max_axis_scale(&r.transform());
    m.choose(distance, scale, pixel_angle, max_pixel_error as f32, held)
}

/// The angle of one of a view's pixels, radians.
fn pixel_angle(view: &View) -> f32 {
    view.pixel_solid_angle.sqrt() as f32
}

/// A view's eye in the tree's precision.
fn eye_of(eye: [f64; 3]) -> Vec3 {
    Vec3::new(eye[0] as f32, eye[1] as f32, eye[2] as f32)
}

/// One planned entry.
#[derive(Clone, Debug, PartialEq)]
pub struct Planned {
    /// What names it: the wire id's parts.
    pub key: Key,
    /// What it draws.
    pub what: Drawn,
    /// Objects it counts.
    pub covers: u64,
    /// A pending object.
    pub pending: bool,
    /// Its sphere.
    pub center: [f32; 3],
    /// And radius.
    pub radius: f32,
    /// Solid angle from the eye: exact for an object, the worst case for an aggregate.
    pub solid_angle: f32,
}

/// An entry's identity: `o:<object>@<placed>` (`o:<object>@<placed>/<level>` at a level of
/// detail above 0) or `n:<node>@<hash>`, with the aggregate's
/// hash cut to its first 64 bits (the whole hash is in the plan's manifest).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub enum Key {
    /// A world object and the generation that placed it.
    Object {
        /// World id.
        object: u64,
        /// Generation of its placement.
        placed: u64,
        /// Its model's level of detail.
        level: u8,
    },
    /// A node and its aggregate's content.
    Aggregate {
        /// The node.
        node: u32,
        /// The first 64 bits of its GLB's hash.
        content: u64,
    },
    /// A node drawn as its impostor, and which of its views.
    Impostor {
        /// The node.
        node: u32,
        /// The first 64 bits of its impostor's key.
        content: u64,
        /// The views sent, a bit per index in the impostor's views.
        views: u16,
    },
    /// A node drawn as its objects' models, placed.
    Instances {
        /// The node.
        node: u32,
        /// A hash of its objects and their placements (`instances_content`).
        content: u64,
        /// A hash of its objects' levels of detail.
        levels: u64,
    },
}

/// What a planned entry draws, besides what its [`Key`] names.
#[derive(Clone, Debug, PartialEq)]
pub enum Drawn {
    /// A world object's model and placement.
    Object {
        /// The model's number (its asset is in the plan's model table).
        model: u64,
        /// Model to world.
        transform: Affine3A,
        /// Its id in the tree the plan was made on.
        tree: ObjectId,
        /// The coarsest level the object itself may be drawn at ([`ModelAsset::choose`]); the
        /// level drawn (the key's) is finer where another object of the model needs a finer
        /// one.
        needed: u8,
    },
    /// The node's published aggregate (in the plan's manifest).
    Aggregate,
    /// The node's published impostor (in the plan's manifest), the key's views of it.
    Impostor,
    /// The node's objects, each drawn as its model at a level of detail.
    Instances(Arc<[Instance]>),
}

/// One object of an instances entry.
#[derive(Clone, Debug, PartialEq)]
pub struct Instance {
    /// World id.
    pub object: u64,
    /// Tree id.
    pub tree: ObjectId,
    /// The generation that placed it.
    pub placed: u64,
    /// The model's number.
    pub model: u64,
    /// Model to world.
    pub transform: Affine3A,
    /// The coarsest level the object itself may be drawn at.
    pub needed: u8,
    /// The level drawn (finer where another object of the model needs it).
    pub level: u8,
}

/// What the cut needs of a model: its levels of detail, level 0 (the stored GLB) first.
#[derive(Clone, Debug, PartialEq)]
pub struct ModelAsset {
    /// At least one.
    pub levels: Vec<LevelAsset>,
}

/// One level of detail of a model: its GLB, what drawing it costs, and what it loses.
#[derive(Clone, Debug, PartialEq)]
pub struct LevelAsset {
    /// The GLB's hash.
    pub hash: String,
    /// Its bytes.
    pub bytes: u64,
    /// Triangles drawn (instances expanded).
    pub triangles: u64,
    /// Draw calls: one per submesh.
    pub draw_calls: u64,
    /// Hausdorff distance to level 0, model units.
    pub error: f32,
    /// Model units per texel (0 without textures).
    pub texel: f32,
}

/// A level of detail is kept while its error (and texel size) stay within this factor of
/// the threshold on either side: a coarser level is taken only once it is within the
/// threshold divided by the margin, and a held level is given up only once it exceeds the
/// threshold times the margin. Moving a little never flips levels back and forth.
pub const LEVEL_MARGIN: f32 = 1.25;

/// How many levels finer than its objects need a model may stay drawn at in a stream, where
/// the client holds that level already ([`share_levels`]): one level has about four times
/// the triangles of the next.
pub const MODEL_LEVEL_SLACK: u8 = 1;

impl ModelAsset {
    /// The level to draw an object of this model with, seen from `distance` (to the
    /// object's nearest point) under a transform that scales the model by at most `scale`:
    /// the coarsest whose error projects to at most `max_pixel_error` pixels of
    /// `pixel_angle` radians and whose texels are at most a pixel, with the hysteresis of
    /// [`LEVEL_MARGIN`] around a `held` level. Level 0 when `max_pixel_error` is 0.
    pub fn choose(
        &self,
        distance: f32,
        scale: f32,
        pixel_angle: f32,
        max_pixel_error: f32,
        held: Option<u8>,
    ) -> u8 {
        if max_pixel_error <= 0.0 || self.levels.len() < 2 || scale <= 0.0 {
            return 0;
        }
        // A pixel's footprint at the object's nearest point, in model units.
        let footprint = distance.max(0.0) * pixel_angle / scale;
        let coarsest = |factor: f32| -> usize {
            let limit = footprint * factor;
            self.levels
                .iter()
                .rposition(|l| l.error <= max_pixel_error * limit && l.texel <= limit)
                .unwrap_or(0)
        };
        let fresh = coarsest(1.0);
        if let Some(held) = held.map(usize::from).filter(|&h| h < self.levels.len()) {
            if (coarsest(1.0 / LEVEL_MARGIN)..=coarsest(LEVEL_MARGIN)).contains(&held) {
                return held as u8;
            }
        }
        fresh as u8
    }

    /// The open range of distances (as [`ModelAsset::choose`] takes them) at which
    /// `choose` surely gives `level`, with `held` and the rest as given; empty where it
    /// cannot tell. The edges are pulled in by a margin far above f32 rounding, so that a
    /// distance inside is `level` to the bit.
    ///
    /// Level k passes at distance d when d >= D_k, where D_k is
    /// `max(error_k / max_pixel_error, texel_k) * scale / pixel_angle` (scaled by the
    /// hysteresis factor), and `choose` takes the last level that passes. Afresh, `level`
    /// holds from D_level (level 0: from anywhere) up to the nearest D_k of a coarser level.
    /// Held, it holds from the nearest D_k of it or a coarser level divided by
    /// [`LEVEL_MARGIN`], up to that of a coarser level times it.
    pub fn band(
        &self,
        level: u8,
        held: Option<u8>,
        scale: f32,
        pixel_angle: f32,
        max_pixel_error: f32,
    ) -> (f32, f32) {
        const EMPTY: (f32, f32) = (f32::INFINITY, f32::NEG_INFINITY);
        if max_pixel_error <= 0.0 || self.levels.len() < 2 || scale <= 0.0 {
            return if level == 0 {
                (f32::NEG_INFINITY, f32::INFINITY)
            } else {
                EMPTY
            };
        }
        let l = usize::from(level);
        if l >= self.levels.len() || pixel_angle <= 0.0 {
            return EMPTY;
        }
        let at = |k: &LevelAsset| {
            let t = (f64::from(k.error) / f64::from(max_pixel_error)).max(f64::from(k.texel));
            t * f64::from(scale) / f64::from(pixel_angle)
        };
        let nearest = |from: usize| {
            self.levels[from..]
                .iter()
                .map(at)
                .fold(f64::INFINITY, f64::min)
        };
        let coarser = nearest(l + 1);
        let margin = f64::from(LEVEL_MARGIN);
        let (lo, hi) = match held.map(usize::from) {
            Some(h) if h == l => {
                let lo = if l == 0 {
                    f64::NEG_INFINITY
                } else {
                    nearest(l) / margin
                };
                (lo, coarser * margin)
            }
            Some(h) if h < self.levels.len() => return EMPTY,
            _ => {
                let lo = if l == 0 {
                    f64::NEG_INFINITY
                } else {
                    at(&self.levels[l])
                };
                (lo, coarser)
            }
        };
        // Far above f32's relative rounding (6e-8) in the distance and the footprint; and
        // positive, since `choose` takes a distance below 0 as 0.
        const SURE: f64 = 1e-4;
        let lo = lo.max(0.0);
        let lo = lo + lo * SURE + 1e-6;
        let hi = if hi.is_finite() {
            hi - hi.abs() * SURE - 1e-6
        } else {
            hi
        };
        if lo < hi {
            (lo as f32, hi as f32)
        } else {
            EMPTY
        }
    }

    fn level(&self, level: u8) -> &LevelAsset {
        let k = usize::from(level).min(self.levels.len().saturating_sub(1));
        &self.levels[k]
    }
}

/// What the planner needs of a node's published aggregate, and of its impostor if any.
#[derive(Clone, Debug, PartialEq)]
pub struct NodeAsset {
    /// GLB bytes.
    pub bytes: u64,
    /// Expanded triangles.
    pub triangles: u64,
    /// Draw calls: one per submesh.
    pub draw_calls: u64,
    /// The first 64 bits of the GLB's hash.
    pub content: u64,
    /// Its impostor.
    pub impostor: Option<NodeImpostor>,
}

/// What the planner needs of a node's published impostor.
#[derive(Clone, Debug, PartialEq)]
pub struct NodeImpostor {
    /// The largest orthoview pixel, world units.
    pub pixel: f32,
    /// The first 64 bits of its key.
    pub content: u64,
    /// Each view's direction.
    pub directions: Vec<[i8; 3]>,
    /// Each view's bytes (three images).
    pub bytes: Vec<u64>,
}

impl NodeImpostor {
    fn of(entry: &horizon_aggregate::ImpostorEntry) -> Self {
        Self {
            pixel: entry.pixel(),
            content: content_bits(&entry.key),
            directions: entry.views.iter().map(|v| v.direction).collect(),
            bytes: entry.views.iter().map(|v| v.bytes.iter().sum()).collect(),
        }
    }

    /// What sending the views of `mask` costs: bytes and draw calls (one per view).
    fn cost(&self, mask: u16) -> (u64, u64) {
        let chosen = (0..self.bytes.len().min(16)).filter(|&i| mask & (1 << i) != 0);
        chosen.fold((0, 0), |(b, d), i| (b + self.bytes[i], d + 1))
    }
}

/// The views of `imp` a cut at `eye` sends for `node`, a bit per view; 0 where the node is
/// drawn by its aggregate: the eye is within the handover distance, or no view faces it (see
/// the module docs). [`Planner`] and [`Decisions::hold_at`] both use it.
fn impostor_views(
    bvh: &horizon_bvh::Bvh,
    node: NodeId,
    imp: &NodeImpostor,
    eye: Vec3,
    pixel_angle: f32,
) -> u16 {
    let Some(n) = bvh.node(node) else {
        return 0;
    };
    let sphere = n.outer_sphere();
    let towards = sphere.centre - eye;
    let nearest = towards.length() - sphere.radius;
    // Within the handover (or a NaN from a degenerate view): the aggregate.
    let beyond = matches!(
        (nearest * pixel_angle).partial_cmp(&imp.pixel),
        Some(Ordering::Greater | Ordering::Equal)
    );
    if !beyond {
        return 0;
    }
    horizon_impostor::facing(&imp.directions, towards)
        .into_iter()
        .filter(|&i| i < 16)
        .fold(0, |m, i| m | (1 << i))
}

/// A manifest's aggregates by node id, for lookups on the planner's hot path.
pub type NodeAssets = Vec<Option<NodeAsset>>;

/// What cuts cost: every model's [`ModelAsset`] by model number (read from the world when a
/// number is new), and the published manifest's [`NodeAssets`] (made once per manifest).
#[derive(Debug, Default)]
pub struct AssetTable {
    by_number: RwLock<Arc<Models>>,
    nodes: std::sync::Mutex<Option<(Arc<AggregateManifest>, Arc<NodeAssets>)>>,
}

/// The model table at one moment: [`ModelAsset`]s by model number.
pub type Models = Vec<Option<Arc<ModelAsset>>>;

impl AssetTable {
    /// `manifest`'s aggregates by node id (made on its first use, then kept until the next
    /// manifest).
    fn node_assets(&self, manifest: Option<&Arc<AggregateManifest>>) -> Arc<NodeAssets> {
        let Some(manifest) = manifest else {
            return Arc::default();
        };
        let Ok(mut cached) = self.nodes.lock() else {
            return Arc::new(index_nodes(manifest));
        };
        if let Some((m, nodes)) = cached.as_ref() {
            if Arc::ptr_eq(m, manifest) {
                return nodes.clone();
            }
        }
        let nodes = Arc::new(index_nodes(manifest));
        *cached = Some((manifest.clone(), nodes.clone()));
        nodes
    }

    /// Makes sure every model number up to those `world` holds is known, with its levels of
    /// detail (a model known with its levels is kept as it is).
    pub fn refresh(&self, world: &World) -> Result<(), WorldError> {
        let rows = world.all_models()?;
        let before = self.models();
        let all = if before.is_empty() {
            Some(world.all_levels()?)
        } else {
            None
        };
        let mut table: Models = Vec::with_capacity(rows.len());
        for row in rows {
            let i = row.number as usize;
            if table.len() <= i {
                table.resize(i + 1, None);
            }
            if let Some(known) = before.get(i).and_then(Option::as_ref) {
                if known.levels.len() > 1 && known.levels[0].hash == row.asset {
                    table[i] = Some(known.clone());
                    continue;
                }
            }
            let stored = match &all {
                Some(all) => all.get(&row.asset).cloned().unwrap_or_default(),
                None => world.levels_of(&row.asset)?,
            };
            // A model not levelled yet is its stored GLB alone.
            let count = |key: &str| row.stats.get(key).and_then(|v| v.as_u64()).unwrap_or(0);
            let levels = if stored.is_empty() {
                vec![LevelAsset {
                    hash: row.asset.clone(),
                    bytes: row.bytes,
                    triangles: count("triangles_expanded"),
                    draw_calls: count("submeshes").max(1),
                    error: 0.0,
                    texel: 0.0,
                }]
            } else {
                stored
                    .iter()
                    .map(|l| LevelAsset {
                        hash: l.asset.clone(),
                        bytes: l.info.bytes,
                        triangles: l.info.triangles,
                        draw_calls: l.info.submeshes.max(1),
                        error: l.info.error as f32,
                        texel: l.info.texel_density.map_or(0.0, |d| (1.0 / d) as f32),
                    })
                    .collect()
            };
            table[i] = Some(Arc::new(ModelAsset { levels }));
        }
        *self
            .by_number
            .write()
            .map_err(|_| WorldError::Inconsistent("model table lock poisoned".into()))? =
            Arc::new(table);
        Ok(())
    }

    /// The table as it is now.
    pub fn models(&self) -> Arc<Models> {
        self.by_number.read().map(|t| t.clone()).unwrap_or_default()
    }
}

fn index_nodes(manifest: &AggregateManifest) -> NodeAssets {
    let len = manifest
        .nodes
        .keys()
        .next_back()
        .map_or(0, |&n| n as usize + 1);
    let mut nodes = vec![None; len];
    for (&n, entry) in &manifest.nodes {
        let mut asset = NodeAsset::of(entry);
        asset.impostor = manifest.impostors.get(&n).map(NodeImpostor::of);
        nodes[n as usize] = Some(asset);
    }
    nodes
}

impl NodeAsset {
    /// What drawing a published aggregate costs.
    fn of(entry: &horizon_aggregate::AggregateEntry) -> Self {
        let stats = &entry.stats;
        Self {
            bytes: stats.bytes as u64,
            triangles: stats.triangles_out,
            draw_calls: stats.submeshes.max(1) as u64,
            content: content_bits(&entry.glb),
            impostor: None,
        }
    }
}

/// A unit the planner puts in or takes out of the cut.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
enum Unit {
    /// A node's aggregate with the pending objects it leaves to entries of their own.
    Node(NodeId),
    /// An object as itself.
    Object(ObjectId),
    /// A node as its objects, each its model at its level, with the pending objects it
    /// leaves to entries of their own. Never refined: its children would draw the same.
    Instances(NodeId),
}

/// An asset as the budgets count it: once per cut.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
enum AssetKey {
    Model(u64, u8),
    Node(NodeId),
    Impostor(NodeId, u16),
}

#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
struct Totals {
    entries: u64,
    bytes: u64,
    draw_calls: u64,
    triangles: u64,
}

/// A node in the refinement heap, by worst-case solid angle (ties by id, for determinism).
#[derive(Clone, Copy, Debug, PartialEq)]
struct Candidate {
    solid_angle: f32,
    node: NodeId,
}

impl Eq for Candidate {}

impl Ord for Candidate {
    fn cmp(&self, other: &Self) -> Ordering {
        self.solid_angle
            .total_cmp(&other.solid_angle)
            .then_with(|| other.node.0.cmp(&self.node.0))
    }
}

impl PartialOrd for Candidate {
    fn partial_cmp(&self, other: &Self) -> Option<Ordering> {
        Some(self.cmp(other))
    }
}

struct Planner<'a> {
    served: &'a Served<'a>,
    nodes: Arc<NodeAssets>,
    models: Arc<Models>,
    view: View,
    eye: Vec3,
    min_solid_angle: f32,
    budgets: Budgets,
    /// Pending objects (tree ids) under each node, at any depth.
    pending_under: HashMap<NodeId, Vec<ObjectId>>,
    pending: HashSet<ObjectId>,
    /// What the cut holds.
    units: HashSet<Unit>,
    heap: BinaryHeap<Candidate>,
    assets: HashMap<AssetKey, u32>,
    totals: Totals,
    /// Nodes refinement took (not those refined for want of an aggregate).
    refined: Vec<NodeId>,
    /// The node whose refinement a budget refused.
    stopper: Option<NodeId>,
    /// Even the coarsest cut was over a budget: nothing was refined by solid angle.
    over_at_seed: bool,
    /// The level of detail each object has in the plan a client holds.
    held_levels: HeldLevels,
    /// The level each model is drawn at in the plan a client holds (`share_levels`); empty
    /// under a byte budget.
    held_model_levels: HashMap<u64, u8>,
    /// The angle of one pixel, radians.
    pixel_angle: f32,
    /// The angle of the pixel levels of detail are chosen for: `pixel_angle`, or wider when
    /// a budget binds ([`Coarsening`]).
    level_pixel_angle: f32,
    /// Each node with an impostor put in the cut, and the views it was charged for.
    impostor_choices: Vec<(NodeId, u16)>,
    /// Each node whose instances were weighed against its aggregate, and the outcome.
    instance_choices: Vec<(NodeId, bool)>,
    /// Each object's level of detail once chosen, by tree id ([`UNCHOSEN`] before).
    chosen: Vec<std::cell::Cell<u8>>,
    /// The objects [`Planner::share_models`] looked at, with their levels.
    examined: Vec<(ObjectId, u8)>,
    /// The nodes refinement left in the cut, but the one a budget refused (before
    /// [`Planner::share_models`] draws some as instances: they are left all the same).
    frontier: Vec<NodeId>,
    /// The entries when refinement stopped.
    refined_entries: u64,
    /// Whether the cut's assets are counted: under a byte, draw-call or triangle budget,
    /// and for [`Planner::share_models`], which asks which model levels the cut holds.
    /// Otherwise entries alone are, and an object's level is chosen only for the entry
    /// that draws it.
    assets_count: bool,
    /// Skip a refinement a byte, draw-call or triangle budget refuses and go on (else stop
    /// there, [`plan_stopping`]), and how many were.
    skip_refused: bool,
    skipped: usize,
}

/// How much more than an aggregate's bytes and draw calls the model levels it would need,
/// beyond those the cut already has, may cost for the planner's second pass to draw its node
/// as instances instead: every object then shows within `max_pixel_error`, while an aggregate
/// was simplified for its node's nearest display distance. Chosen on the fidelity measure
/// (`lab/results/reuse.md`).
pub const SHARED_MODELS_FACTOR: f64 = 3.0;

/// Whether `b` has a byte, draw-call or triangle budget: one that the cut's assets count
/// towards, not its entries alone.
fn bounds_costs(b: &Budgets) -> bool {
    b.max_bytes.is_some() || b.max_draw_calls.is_some() || b.max_triangles.is_some()
}

/// A level not chosen yet (levels are far fewer).
const UNCHOSEN: u8 = u8::MAX;

impl<'a> Planner<'a> {
    fn new(served: &'a Served<'a>, models: &'a AssetTable, view: &View) -> Self {
        let tree = served.tree;
        let mut pending_under: HashMap<NodeId, Vec<ObjectId>> = HashMap::new();
        let mut pending = HashSet::new();
        for object in tree.placed_after(served.published) {
            let Some(id) = tree.tree_id(object) else {
                continue;
            };
            pending.insert(id);
            let mut at = tree.bvh.object(id).map(|o| o.leaf());
            while let Some(n) = at {
                pending_under.entry(n).or_default().push(id);
                at = tree.bvh.node(n).and_then(|r| r.parent());
            }
        }
        let mut budgets = view.budgets;
        budgets.max_entries.get_or_insert(DEFAULT_MAX_ENTRIES);
        Self {
            served,
            nodes: models.node_assets(served.manifest.as_ref()),
            models: models.models(),
            view: *view,
            eye: eye_of(view.eye),
            min_solid_angle: view.min_solid_angle as f32,
            budgets,
            pending_under,
            pending,
            // About the cut's size, so that the set does not grow step by step.
            units: HashSet::with_capacity(
                budgets
                    .max_entries
                    .map_or(4096, |n| n.min(1 << 16) as usize)
                    * 5
                    / 4,
            ),
            heap: BinaryHeap::new(),
            assets: HashMap::new(),
            totals: Totals::default(),
            refined: Vec::new(),
            stopper: None,
            over_at_seed: false,
            held_levels: HeldLevels::None,
            held_model_levels: HashMap::new(),
            pixel_angle: pixel_angle(view),
            level_pixel_angle: pixel_angle(view),
            impostor_choices: Vec::new(),
            instance_choices: Vec::new(),
            chosen: vec![std::cell::Cell::new(UNCHOSEN); tree.bvh.object_slots()],
            examined: Vec::new(),
            frontier: Vec::new(),
            refined_entries: 0,
            assets_count: view.instances || bounds_costs(&budgets),
            skip_refused: false,
            skipped: 0,
        }
    }

    /// The level of detail `o` is drawn with (see [`ModelAsset::choose`]).
    fn level_of(&self, o: ObjectId) -> u8 {
        self.levels().of(o)
    }

    /// How this plan chooses levels of detail, each object's once.
    fn levels(&self) -> LevelChooser<'_> {
        LevelChooser {
            tree: self.served.tree,
            models: &self.models,
            eye: self.eye,
            pixel_angle: self.level_pixel_angle,
            max_pixel_error: self.view.max_pixel_error,
            held: &self.held_levels,
            chosen: &self.chosen,
        }
    }

    /// The root, expanded at once wherever no aggregate can draw it.
    fn seed(&mut self) {
        let bvh = &self.served.tree.bvh;
        if bvh.is_empty() {
            return;
        }
        let mut added = Vec::new();
        self.expand(bvh.root(), &mut added);
        for unit in added {
            self.put(unit, 1);
        }
    }

    /// Best-first refinement; returns the budget that stopped it, if one did.
    fn refine(&mut self) -> Option<StoppedBy> {
        if let Some(over) = self.over_budget() {
            // Even the coarsest cut the published aggregates allow is over: say so.
            self.over_at_seed = true;
            return Some(over);
        }
        let mut first_refusal = None;
        // After a skipped refusal, the refused node is pushed again and its children stay
        // pushed though they were taken out of the cut: neither is tried.
        let mut refused: HashSet<NodeId> = HashSet::new();
        while let Some(top) = self.heap.pop() {
            if top.solid_angle < self.min_solid_angle {
                return first_refusal;
            }
            let node = top.node;
            if !refused.is_empty()
                && (refused.contains(&node) || !self.units.contains(&Unit::Node(node)))
            {
                continue;
            }
            let tree: &'a horizon_world::Tree = self.served.tree;
            let Some(n) = tree.bvh.node(node) else {
                continue;
            };
            let mut added = Vec::new();
            if n.is_leaf() {
                added.extend(n.objects().map(Unit::Object));
            } else {
                for child in n.child_nodes() {
                    self.expand(child, &mut added);
                }
            }
            self.put(Unit::Node(node), -1);
            for &unit in &added {
                self.put(unit, 1);
            }
            if let Some(over) = self.over_budget() {
                for &unit in &added {
                    self.put(unit, -1);
                }
                self.put(Unit::Node(node), 1);
                let over_entries = over == StoppedBy::MaxEntries;
                if self.skip_refused && !over_entries {
                    self.stopper.get_or_insert(node);
                    refused.insert(node);
                    first_refusal.get_or_insert(over);
                    self.skipped += 1;
                    continue;
                }
                self.stopper = Some(node);
                return Some(over);
            }
            self.refined.push(node);
        }
        first_refusal
    }

    /// The nodes refinement left in the cut, but the one a budget refused.
    fn frontier(&self) -> Vec<NodeId> {
        self.units
            .iter()
            .filter_map(|u| match *u {
                Unit::Node(n) if Some(n) != self.stopper => Some(n),
                _ => None,
            })
            .collect()
    }

    /// The second look at the aggregates left in the cut, with what the client must still
    /// download: an aggregate whose objects' model levels, less those the cut already has,
    /// cost at most [`SHARED_MODELS_FACTOR`] times its bytes and its draw calls becomes
    /// instances, if the budgets allow.
    /// Each switch brings models that make others cheaper, so it repeats, nodes in id order,
    /// until none switches. It depends only on the cut refinement made and the levels of the
    /// objects it looks at, which [`Decisions`] keep for [`Plan::carry_to`].
    fn share_models(&mut self) {
        if !self.view.instances {
            return;
        }
        loop {
            let mut nodes: Vec<NodeId> = self
                .units
                .iter()
                .filter_map(|u| match *u {
                    Unit::Node(n) => Some(n),
                    _ => None,
                })
                .filter(|&n| self.impostor_views(n) == 0)
                .collect();
            nodes.sort_unstable_by_key(|n| n.0);
            let mut switched = false;
            for node in nodes {
                let Some(a) = self.aggregate(node) else {
                    continue;
                };
                let limit = |v: u64| (v as f64 * SHARED_MODELS_FACTOR) as u64;
                let (bytes, draw_calls) = (limit(a.bytes), limit(a.draw_calls));
                if !self.cheaper_shared(node, bytes, draw_calls) {
                    continue;
                }
                self.put(Unit::Node(node), -1);
                self.put_shared(node, 1);
                if self.over_budget().is_some() {
                    self.put_shared(node, -1);
                    self.put(Unit::Node(node), 1);
                } else {
                    switched = true;
                }
            }
            if !switched {
                return;
            }
        }
    }

    /// Whether `node`'s objects' model levels that the cut does not hold yet cost at most
    /// `bytes` and `draw_calls` (given up as soon as they pass either).
    fn cheaper_shared(&mut self, node: NodeId, bytes: u64, draw_calls: u64) -> bool {
        let extracted: HashSet<ObjectId> = self.extracted(node).collect();
        let bvh = &self.served.tree.bvh;
        let mut under = Vec::new();
        bvh.objects_under(node, &mut under);
        let mut fresh: HashSet<(u64, u8)> = HashSet::new();
        let (mut b, mut c) = (0, 0);
        for o in under.into_iter().filter(|o| !extracted.contains(o)) {
            let Some(model) = bvh.object(o).map(|r| r.model()) else {
                return false;
            };
            let Some(m) = self.models.get(model as usize).and_then(Option::as_ref) else {
                return false;
            };
            let level = self.level_of(o);
            self.examined.push((o, level));
            if self.assets.contains_key(&AssetKey::Model(model, level))
                || !fresh.insert((model, level))
            {
                continue;
            }
            let l = m.level(level);
            b += l.bytes;
            c += l.draw_calls;
            if b > bytes || c > draw_calls {
                return false;
            }
        }
        true
    }

    /// [`Planner::put`] of `Unit::Instances(node)` made by [`Planner::share_models`], which
    /// [`Decisions`] do not record.
    fn put_shared(&mut self, node: NodeId, sign: i64) {
        if sign > 0 {
            self.units.insert(Unit::Instances(node));
        } else {
            self.units.remove(&Unit::Instances(node));
        }
        let (impostors, instances) = (self.impostor_choices.len(), self.instance_choices.len());
        self.charge_instances(node, sign);
        self.impostor_choices.truncate(impostors);
        self.instance_choices.truncate(instances);
    }

    /// What stands for `node` in the cut: its aggregate if the manifest has one, else its
    /// children (a leaf's objects), recursively.
    fn expand(&self, node: NodeId, out: &mut Vec<Unit>) {
        let bvh = &self.served.tree.bvh;
        let Some(n) = bvh.node(node) else {
            return;
        };
        if let Some(a) = self.aggregate(node) {
            let weigh = self.view.instances && self.impostor_views(node) == 0;
            if weigh && self.levels().instances_win(node, a) {
                out.push(Unit::Instances(node));
            } else {
                out.push(Unit::Node(node));
            }
        } else if n.is_leaf() {
            out.extend(n.objects().map(Unit::Object));
        } else {
            for child in n.child_nodes() {
                self.expand(child, out);
            }
        }
    }

    fn aggregate(&self, node: NodeId) -> Option<&NodeAsset> {
        self.nodes.get(node.0 as usize).and_then(Option::as_ref)
    }

    /// The views of `node`'s impostor the cut sends (0: its aggregate draws it).
    fn impostor_views(&self, node: NodeId) -> u16 {
        if !self.view.impostors {
            return 0;
        }
        match self.aggregate(node).and_then(|a| a.impostor.as_ref()) {
            Some(imp) => {
                impostor_views(&self.served.tree.bvh, node, imp, self.eye, self.pixel_angle)
            }
            None => 0,
        }
    }

    /// The pending objects a node's aggregate leaves to entries of their own.
    fn extracted(&self, node: NodeId) -> impl Iterator<Item = ObjectId> + '_ {
        let bvh = &self.served.tree.bvh;
        let under = if self.pending_under.is_empty() {
            None
        } else {
            self.pending_under.get(&node)
        };
        under
            .into_iter()
            .flatten()
            .copied()
            .filter(move |&o| subtends(bvh, o, self.eye, self.min_solid_angle) == Some(true))
    }

    /// Adds (`sign` 1) or takes out (-1) a unit and what it costs.
    fn put(&mut self, unit: Unit, sign: i64) {
        if sign > 0 {
            self.units.insert(unit);
        } else {
            self.units.remove(&unit);
        }
        match unit {
            Unit::Object(o) => self.charge_object(o, sign),
            Unit::Instances(node) => self.charge_instances(node, sign),
            Unit::Node(node) => {
                let extracted: Vec<ObjectId> = self.extracted(node).collect();
                for &o in &extracted {
                    self.charge_object(o, sign);
                }
                let count = self
                    .served
                    .tree
                    .bvh
                    .node(node)
                    .map_or(0, |n| u64::from(n.count()));
                if count > extracted.len() as u64 {
                    let views = self.impostor_views(node);
                    let has_impostor = self.aggregate(node).is_some_and(|a| a.impostor.is_some());
                    if sign > 0 && self.view.impostors && has_impostor {
                        // Every choice that cost something, also of nodes refined later: under
                        // a byte or draw-call budget it moved where refinement stopped.
                        self.impostor_choices.push((node, views));
                    }
                    if sign > 0 && self.view.instances && views == 0 {
                        // `expand` weighed its instances and they lost.
                        self.instance_choices.push((node, false));
                    }
                    if let Some(a) = self.aggregate(node) {
                        let (key, bytes, draw_calls, triangles) =
                            match a.impostor.as_ref().filter(|_| views != 0) {
                                Some(imp) => {
                                    let (bytes, calls) = imp.cost(views);
                                    (AssetKey::Impostor(node, views), bytes, calls, 0)
                                }
                                None => (AssetKey::Node(node), a.bytes, a.draw_calls, a.triangles),
                            };
                        self.charge(key, bytes, draw_calls, triangles, sign);
                    }
                }
                if sign > 0 {
                    if let Some(angle) = self.worst_case(node) {
                        if angle >= self.min_solid_angle {
                            self.heap.push(Candidate {
                                solid_angle: angle,
                                node,
                            });
                        }
                    }
                }
            }
        }
    }

    fn charge_object(&mut self, o: ObjectId, sign: i64) {
        let Some(model) = self.served.tree.bvh.object(o).map(|o| o.model()) else {
            return;
        };
        if !self.assets_count {
            self.count_entry(sign);
            return;
        }
        let level = self.level_of(o);
        let (bytes, draw_calls, triangles) = self
            .models
            .get(model as usize)
            .and_then(Option::as_ref)
            .map(|m| m.level(level))
            .map_or((0, 1, 0), |l| (l.bytes, l.draw_calls, l.triangles));
        self.charge(
            AssetKey::Model(model, level),
            bytes,
            draw_calls,
            triangles,
            sign,
        );
    }

    /// A node drawn as instances: its pending objects that subtend `min_solid_angle` as
    /// entries of their own, then one entry whose assets are its objects' model levels,
    /// each counted once per cut.
    fn charge_instances(&mut self, node: NodeId, sign: i64) {
        let extracted: HashSet<ObjectId> = self.extracted(node).collect();
        for &o in &extracted {
            self.charge_object(o, sign);
        }
        if sign > 0 {
            let has_impostor = self.aggregate(node).is_some_and(|a| a.impostor.is_some());
            if self.view.impostors && has_impostor {
                self.impostor_choices.push((node, 0));
            }
            self.instance_choices.push((node, true));
        }
        let mut under = Vec::new();
        self.served.tree.bvh.objects_under(node, &mut under);
        let mut assets: HashMap<(u64, u8), (u64, u64, u64)> = HashMap::new();
        for o in under.into_iter().filter(|o| !extracted.contains(o)) {
            let Some(model) = self.served.tree.bvh.object(o).map(|r| r.model()) else {
                continue;
            };
            let level = self.level_of(o);
            let Some(l) = self
                .models
                .get(model as usize)
                .and_then(Option::as_ref)
                .map(|m| m.level(level))
            else {
                continue;
            };
            let a = assets
                .entry((model, level))
                .or_insert((l.bytes, l.draw_calls, 0));
            a.2 += l.triangles;
        }
        if assets.is_empty() {
            return;
        }
        self.count_entry(sign);
        for ((model, level), (bytes, draw_calls, triangles)) in assets {
            self.charge_asset(
                AssetKey::Model(model, level),
                bytes,
                draw_calls,
                triangles,
                sign,
            );
        }
    }

    fn count_entry(&mut self, sign: i64) {
        let t = &mut self.totals;
        if sign > 0 {
            t.entries += 1;
        } else {
            t.entries = t.entries.saturating_sub(1);
        }
    }

    fn charge(&mut self, key: AssetKey, bytes: u64, draw_calls: u64, triangles: u64, sign: i64) {
        self.count_entry(sign);
        if self.assets_count {
            self.charge_asset(key, bytes, draw_calls, triangles, sign);
        }
    }

    /// An asset's bytes and draw calls, once per cut, and its triangles, every time.
    fn charge_asset(
        &mut self,
        key: AssetKey,
        bytes: u64,
        draw_calls: u64,
        triangles: u64,
        sign: i64,
    ) {
        let t = &mut self.totals;
        if sign > 0 {
            t.triangles += triangles;
            let count = self.assets.entry(key).or_insert(0);
            if *count == 0 {
                t.bytes += bytes;
                t.draw_calls += draw_calls;
            }
            *count += 1;
        } else {
            t.triangles = t.triangles.saturating_sub(triangles);
            if let Some(count) = self.assets.get_mut(&key) {
                *count = count.saturating_sub(1);
                if *count == 0 {
                    self.assets.remove(&key);
                    t.bytes = t.bytes.saturating_sub(bytes);
                    t.draw_calls = t.draw_calls.saturating_sub(draw_calls);
                }
            }
        }
    }

    fn over_budget(&self) -> Option<StoppedBy> {
        let t = &self.totals;
        let b = &self.budgets;
        let over = |limit: Option<u64>, value: u64| limit.is_some_and(|l| value > l);
        if over(b.max_entries, t.entries) {
            Some(StoppedBy::MaxEntries)
        } else if over(b.max_bytes, t.bytes) {
            Some(StoppedBy::MaxBytes)
        } else if over(b.max_draw_calls, t.draw_calls) {
            Some(StoppedBy::MaxDrawCalls)
        } else if over(b.max_triangles, t.triangles) {
            Some(StoppedBy::MaxTriangles)
        } else {
            None
        }
    }

    fn worst_case(&self, node: NodeId) -> Option<f32> {
        node_worst_case(&self.served.tree.bvh, node, self.eye)
    }

    /// `model` if the table has it; otherwise none, counted in `missing` (its objects are
    /// left out until the table is refreshed).
    fn known_model(&self, model: u64, missing: &std::cell::Cell<usize>) -> Option<u64> {
        if self.models.get(model as usize).is_none_or(Option::is_none) {
            missing.set(missing.get() + 1);
            return None;
        }
        Some(model)
    }

    /// The instances entry of a node: its objects but those `extracted` (pending, their own
    /// entries) or whose model the table lacks (counted in `missing`); none if that leaves
    /// nothing.
    fn instances_item(
        &self,
        node: NodeId,
        extracted: &HashSet<ObjectId>,
        missing: &std::cell::Cell<usize>,
    ) -> Option<Planned> {
        let tree = self.served.tree;
        let n = tree.bvh.node(node)?;
        let mut under = Vec::new();
        tree.bvh.objects_under(node, &mut under);
        let mut instances: Vec<Instance> = under
            .into_iter()
            .filter(|o| !extracted.contains(o))
            .filter_map(|o| {
                let r = tree.bvh.object(o)?;
                let model = self.known_model(r.model(), missing)?;
                let level = self.level_of(o);
                Some(Instance {
                    object: tree.world_id(o)?,
                    tree: o,
                    placed: tree.placed_at(o),
                    model,
                    transform: r.transform(),
                    needed: level,
                    level,
                })
            })
            .collect();
        if instances.is_empty() {
            return None;
        }
        instances.sort_unstable_by_key(|i| i.object);
        let sphere = n.outer_sphere();
        Some(Planned {
            key: Key::Instances {
                node: node.0,
                content: 0,
                levels: 0,
            },
            covers: instances.len() as u64,
            what: Drawn::Instances(instances.into()),
            pending: false,
            center: sphere.centre.to_array(),
            radius: sphere.radius,
            solid_angle: self.worst_case(node).unwrap_or(0.0),
        })
    }

    fn finish(mut self, stopped_by: Option<StoppedBy>) -> Plan {
        let b = &self.budgets;
        let mut decisions = Decisions {
            min_solid_angle: self.min_solid_angle,
            refined: std::mem::take(&mut self.refined),
            frontier: std::mem::take(&mut self.frontier),
            stopper: self.stopper,
            over_at_seed: self.over_at_seed,
            skipped: self.skipped > 0,
            ordered: bounds_costs(b),
            entries: self.refined_entries,
            max_entries: b.max_entries,
            pending: self
                .pending
                .iter()
                .filter_map(|&o| {
                    let seen = subtends(&self.served.tree.bvh, o, self.eye, self.min_solid_angle)?;
                    Some((o, seen))
                })
                .collect(),
            levels: Vec::new(),
            instances: std::mem::take(&mut self.instance_choices),
            examined: std::mem::take(&mut self.examined),
            consulted: Vec::new(),
            bands: Vec::new(),
            watch: None,
            impostors: {
                let mut choices = std::mem::take(&mut self.impostor_choices);
                choices.sort_unstable_by_key(|&(n, _)| n.0);
                choices.dedup();
                choices
            },
            nodes: self.nodes.clone(),
            pixel_angle: self.pixel_angle,
        };
        let tree = self.served.tree;
        let published = self.served.published;
        let mut items = Vec::with_capacity(self.units.len());
        let missing = std::cell::Cell::new(0);
        let object_item = |o: ObjectId, pending: bool| -> Option<Planned> {
            let r = tree.bvh.object(o)?;
            let object = tree.world_id(o)?;
            let sphere = r.sphere();
            let model = self.known_model(r.model(), &missing)?;
            let level = self.level_of(o);
            Some(Planned {
                key: Key::Object {
                    object,
                    placed: tree.placed_at(o),
                    level,
                },
                what: Drawn::Object {
                    model,
                    transform: r.transform(),
                    tree: o,
                    needed: level,
                },
                covers: 1,
                pending,
                center: sphere.centre.to_array(),
                radius: sphere.radius,
                solid_angle: solid_angle(sphere.radius, (sphere.centre - self.eye).length()),
            })
        };
        for &unit in &self.units {
            match unit {
                Unit::Object(o) => {
                    items.extend(object_item(o, self.pending.contains(&o)));
                }
                Unit::Instances(node) => {
                    let extracted: HashSet<ObjectId> = self.extracted(node).collect();
                    items.extend(extracted.iter().filter_map(|&o| object_item(o, true)));
                    items.extend(self.instances_item(node, &extracted, &missing));
                }
                Unit::Node(node) => {
                    let extracted: Vec<ObjectId> = self.extracted(node).collect();
                    items.extend(extracted.iter().filter_map(|&o| object_item(o, true)));
                    let (Some(n), Some(entry)) = (tree.bvh.node(node), self.aggregate(node)) else {
                        continue;
                    };
                    let covers = u64::from(n.count()).saturating_sub(extracted.len() as u64);
                    if covers == 0 {
                        continue;
                    }
                    let sphere = n.outer_sphere();
                    let views = self.impostor_views(node);
                    let (key, what) = match entry.impostor.as_ref().filter(|_| views != 0) {
                        Some(imp) => (
                            Key::Impostor {
                                node: node.0,
                                content: imp.content,
                                views,
                            },
                            Drawn::Impostor,
                        ),
                        None => (
                            Key::Aggregate {
                                node: node.0,
                                content: entry.content,
                            },
                            Drawn::Aggregate,
                        ),
                    };
                    items.push(Planned {
                        key,
                        what,
                        covers,
                        pending: false,
                        center: sphere.centre.to_array(),
                        radius: sphere.radius,
                        solid_angle: self.worst_case(node).unwrap_or(0.0),
                    });
                }
            }
        }
        decisions.levels = Vec::with_capacity(items.len());
        for p in &items {
            match &p.what {
                Drawn::Object { tree, needed, .. } => decisions.levels.push((*tree, *needed)),
                Drawn::Instances(instances) => {
                    decisions
                        .levels
                        .extend(instances.iter().map(|i| (i.tree, i.needed)));
                }
                Drawn::Aggregate | Drawn::Impostor => {}
            }
        }
        // In a coarsened plan this names every kept level too, consulted or not: such a plan
        // is never carried (`Plan::carry_to`), so the bands never see them.
        decisions.consulted = consulted(&self.chosen);
        if self.budgets.max_triangles.is_none() {
            share_levels(&mut items, &self.held_model_levels);
        }
        for p in &mut items {
            if let (
                Key::Instances {
                    content, levels, ..
                },
                Drawn::Instances(instances),
            ) = (&mut p.key, &p.what)
            {
                *content = instances_content(instances, |i| [i.object, i.placed, i.model]);
                *levels = instances_content(instances, |i| [u64::from(i.level)]);
            }
        }
        Plan {
            manifest: self.served.manifest.clone(),
            models: self.models.clone(),
            generation: tree.generation,
            published,
            objects: tree.bvh.len() as u64,
            items,
            stopped_by,
            missing_models: missing.get(),
            view: self.view,
            decisions,
            coarsened: None,
            skipped: self.skipped,
        }
    }
}

/// Every object of a model drawn at the finest level any of them needs: that level is
/// downloaded anyway, so the others reuse it instead of adding a coarser one. A cut's bytes
/// and draw calls only fall by it (one asset per model instead of one per level used), and
/// its triangles stay at most those of the cut without levels; under a triangle budget the
/// planner leaves every object at its own level.
///
/// For a client that holds a plan, a model keeps the level it is `held` at while that level
/// is at least as fine as the finest needed and at most [`MODEL_LEVEL_SLACK`] levels finer:
/// the client has it already, and every placement of the model would be resent with a new
/// level (a stream's cost of a model's level is its number of copies in the cut).
fn share_levels(items: &mut [Planned], held: &HashMap<u64, u8>) {
    let mut finest: HashMap<u64, u8> = HashMap::new();
    let mut need = |model: u64, needed: u8| {
        let f = finest.entry(model).or_insert(needed);
        *f = (*f).min(needed);
    };
    for p in items.iter() {
        match &p.what {
            Drawn::Object { model, needed, .. } => need(*model, *needed),
            Drawn::Instances(instances) => {
                for i in instances.iter() {
                    need(i.model, i.needed);
                }
            }
            Drawn::Aggregate | Drawn::Impostor => {}
        }
    }
    for (model, f) in finest.iter_mut() {
        *f = shared_level(*f, held.get(model).copied());
    }
    for p in items.iter_mut() {
        match (&mut p.what, &mut p.key) {
            (Drawn::Object { model, .. }, Key::Object { level, .. }) => *level = finest[model],
            (Drawn::Instances(instances), _) => {
                for i in instances_mut(instances) {
                    i.level = finest[&i.model];
                }
            }
            _ => {}
        }
    }
}

/// The level a model's objects share when the finest any needs is `finest` and a client
/// holds it at `held`: the held level while it is at least as fine and at most
/// [`MODEL_LEVEL_SLACK`] finer, else the finest needed.
fn shared_level(finest: u8, held: Option<u8>) -> u8 {
    match held {
        Some(h) if h <= finest && finest - h <= MODEL_LEVEL_SLACK => h,
        _ => finest,
    }
}

/// An instances entry's objects to change, copied first if another plan shares them.
fn instances_mut(instances: &mut Arc<[Instance]>) -> &mut [Instance] {
    if Arc::get_mut(instances).is_none() {
        *instances = instances.to_vec().into();
    }
    Arc::get_mut(instances).expect("a copy no other plan holds")
}

/// What names an instances entry's content: a hash of `words` of each instance, in the order
/// of the ids (FNV-1a's offset and prime over whole words, each word's high bits folded down
/// first so that they count too). The objects, the generations that placed them and their
/// models name the content; their levels, hashed apart, name its level of detail.
fn instances_content<const N: usize>(
    instances: &[Instance],
    words: impl Fn(&Instance) -> [u64; N],
) -> u64 {
    let mut h: u64 = 0xcbf2_9ce4_8422_2325;
    for i in instances {
        for word in words(i) {
            h ^= word ^ (word >> 29);
            h = h.wrapping_mul(0x0000_0100_0000_01b3);
            h ^= h >> 32;
        }
    }
    h
}

/// The levels of detail the objects have in the plan a client holds, which planning again
/// keeps within [`LEVEL_MARGIN`].
#[derive(Debug)]
enum HeldLevels {
    /// No plan held.
    None,
    /// By tree id, of a plan made on the same tree ([`UNCHOSEN`]: not held).
    ByTree(Vec<u8>),
    /// By world id, of a plan made on an earlier tree.
    ByWorld(HashMap<u64, u8>),
}

impl HeldLevels {
    fn of(&self, tree: &horizon_world::Tree, o: ObjectId) -> Option<u8> {
        match self {
            HeldLevels::None => None,
            HeldLevels::ByTree(levels) => {
                levels.get(o.0 as usize).copied().filter(|&l| l != UNCHOSEN)
            }
            HeldLevels::ByWorld(levels) => levels.get(&tree.world_id(o)?).copied(),
        }
    }
}

/// How a plan chooses objects' levels of detail, and weighs a node's instances against its
/// aggregate: the planner and [`Plan::carry_to`] both use it, so that they agree to the bit.
struct LevelChooser<'a> {
    tree: &'a horizon_world::Tree,
    models: &'a Models,
    eye: Vec3,
    pixel_angle: f32,
    max_pixel_error: f64,
    /// The levels objects have in the plan a client holds.
    held: &'a HeldLevels,
    /// Levels already chosen, by tree id (empty: none kept).
    chosen: &'a [std::cell::Cell<u8>],
}

impl LevelChooser<'_> {
    /// The level an object is drawn at (0 when its model is not in the table).
    fn of(&self, o: ObjectId) -> u8 {
        let slot = self.chosen.get(o.0 as usize);
        if let Some(level) = slot.map(std::cell::Cell::get).filter(|&l| l != UNCHOSEN) {
            return level;
        }
        let level = self.choose(o);
        if let Some(slot) = slot {
            slot.set(level);
        }
        level
    }

    fn choose(&self, o: ObjectId) -> u8 {
        let Some(r) = self.tree.bvh.object(o) else {
            return 0;
        };
        let held = self.held.of(self.tree, o);
        level_at(
            self.models,
            &r,
            self.eye,
            self.pixel_angle,
            self.max_pixel_error,
            held,
        )
    }

    /// Whether `node` costs less drawn as its objects' models than as its aggregate `a`.
    ///
    /// Each object is charged its level's bytes and draw calls divided by the number of
    /// objects in the world that share its model ([`share`]): a model placed a thousand
    /// times is downloaded once for all of them, so each placement owes a thousandth of it.
    /// A node of distinct models is charged every model whole. Instances win when that
    /// share is at most the aggregate's bytes and at most its draw calls ([`fits`]). The sum
    /// is taken in the tree's order and given up as soon as it passes either, so a node of
    /// distinct models costs a few objects' visits. A node with an object whose model is not
    /// in the table cannot be drawn as instances.
    fn instances_win(&self, node: NodeId, a: &NodeAsset) -> bool {
        let bvh = &self.tree.bvh;
        let (mut bytes, mut calls) = (0u128, 0u128);
        let mut stack = vec![node];
        while let Some(n) = stack.pop() {
            let Some(r) = bvh.node(n) else {
                return false;
            };
            if !r.is_leaf() {
                stack.extend(r.child_nodes());
                continue;
            }
            for o in r.objects() {
                let Some((b, c)) = self.placement_share(o) else {
                    return false;
                };
                bytes = bytes.saturating_add(b);
                calls = calls.saturating_add(c);
                if !fits(a, (bytes, calls)) {
                    return false;
                }
            }
        }
        true
    }

    /// What one placement of `o` owes of its model level's bytes and draw calls ([`share`]);
    /// none when its model is not in the table.
    fn placement_share(&self, o: ObjectId) -> Option<(u128, u128)> {
        let model = self.tree.bvh.object(o)?.model();
        let m = self.models.get(model as usize).and_then(Option::as_ref)?;
        let l = m.level(self.of(o));
        let uses = self.tree.uses(model);
        Some((share(l.bytes, uses), share(l.draw_calls, uses)))
    }

    /// [`LevelChooser::instances_win`] of every node of `weighed` at once: each node's
    /// placements' shares summed bottom-up over the tree from `root`, so that nested nodes
    /// do not walk their objects again. Integer shares make the sums the same in any order,
    /// so each answer is the early-exit walk's to the bit.
    fn instances_win_all(
        &self,
        root: NodeId,
        weighed: &HashSet<NodeId>,
        nodes: &NodeAssets,
    ) -> HashMap<NodeId, bool> {
        // A node's total, or none where an object under it cannot be weighed.
        let mut totals: HashMap<NodeId, Option<(u128, u128)>> = HashMap::new();
        let mut out = HashMap::new();
        let bvh = &self.tree.bvh;
        // Post-order: a node is pushed again (`true`) after its children.
        let mut stack = vec![(root, false)];
        while let Some((n, children_done)) = stack.pop() {
            let Some(r) = bvh.node(n) else {
                totals.insert(n, None);
                continue;
            };
            let total = if r.is_leaf() {
                r.objects().try_fold((0u128, 0u128), |(b, c), o| {
                    let (pb, pc) = self.placement_share(o)?;
                    Some((b.saturating_add(pb), c.saturating_add(pc)))
                })
            } else if !children_done {
                stack.push((n, true));
                stack.extend(r.child_nodes().map(|c| (c, false)));
                continue;
            } else {
                r.child_nodes().try_fold((0u128, 0u128), |(b, c), child| {
                    let (cb, cc) = totals.get(&child).copied().flatten()?;
                    Some((b.saturating_add(cb), c.saturating_add(cc)))
                })
            };
            totals.insert(n, total);
            if weighed.contains(&n) {
                let asset = nodes.get(n.0 as usize).and_then(Option::as_ref);
                let won = total.zip(asset).is_some_and(|(t, a)| fits(a, t));
                out.insert(n, won);
            }
        }
        out
    }
}

/// Units of a placement's share of a byte or a draw call: shares are whole units so that
/// their sums do not depend on the order they are taken in, and fine enough (2^-32) that a
/// model's draw call shared by a billion placements still counts.
const SHARE_UNIT: u128 = 1 << 32;

/// One placement's share of `value` (a model level's bytes or draw calls) when `uses`
/// placements share the model, in [`SHARE_UNIT`]s.
fn share(value: u64, uses: u32) -> u128 {
    u128::from(value) * SHARE_UNIT / u128::from(uses.max(1))
}

/// Whether placements' shares `(bytes, draw_calls)` cost at most aggregate `a`.
fn fits(a: &NodeAsset, (bytes, calls): (u128, u128)) -> bool {
    bytes <= u128::from(a.bytes) * SHARE_UNIT && calls <= u128::from(a.draw_calls) * SHARE_UNIT
}

impl Planned {
    /// The same entry, as a client holding it would compare it.
    fn same(&self, other: &Planned) -> bool {
        self.covers == other.covers
            && self.pending == other.pending
            && self.center == other.center
            && self.radius == other.radius
    }

    /// An object's level of detail (0 for a node).
    fn level(&self) -> u8 {
        match self.key {
            Key::Object { level, .. } => level,
            Key::Aggregate { .. } | Key::Impostor { .. } | Key::Instances { .. } => 0,
        }
    }

    fn node(&self) -> Option<NodeId> {
        match self.key {
            Key::Aggregate { node, .. }
            | Key::Impostor { node, .. }
            | Key::Instances { node, .. } => Some(NodeId(node)),
            Key::Object { .. } => None,
        }
    }

    fn object(&self) -> Option<u64> {
        match self.key {
            Key::Object { object, .. } => Some(object),
            Key::Aggregate { .. } | Key::Impostor { .. } | Key::Instances { .. } => None,
        }
    }
}

/// A stored orthoview as the wire names it (the lab's measures use it too).
pub fn wire_view(v: &horizon_aggregate::ImpostorView) -> ImpostorView {
    ImpostorView {
        direction: v.direction,
        width: v.width,
        height: v.height,
        pixel: v.pixel,
        color: v.color.clone(),
        depth: v.depth.clone(),
        normal: v.normal.clone(),
    }
}

/// The first 64 bits of a hex content hash (0 for a hash too short to have them).
fn content_bits(hash: &str) -> u64 {
    hash.get(..16)
        .and_then(|h| u64::from_str_radix(h, 16).ok())
        .unwrap_or(0)
}

/// A 3x4 column-major matrix: the three axes, then the translation.
fn matrix_of(t: &Affine3A) -> [f32; 12] {
    let m = t.matrix3;
    let c = t.translation;
    [
        m.x_axis.x, m.x_axis.y, m.x_axis.z, m.y_axis.x, m.y_axis.y, m.y_axis.z, m.z_axis.x,
        m.z_axis.y, m.z_axis.z, c.x, c.y, c.z,
    ]
}

impl Plan {
    /// The wire entries, largest solid angle first (ties by id).
    pub fn entries(&self) -> Vec<Entry> {
        let mut order: Vec<&Planned> = self.items.iter().collect();
        order.sort_unstable_by(|a, b| {
            b.solid_angle
                .total_cmp(&a.solid_angle)
                .then_with(|| a.key.cmp(&b.key))
        });
        order.into_iter().map(|p| self.entry(p)).collect()
    }

    /// The aggregate a planned entry draws, if it is one.
    fn aggregate(&self, p: &Planned) -> Option<&horizon_aggregate::AggregateEntry> {
        let node = p.node()?;
        self.manifest.as_ref()?.nodes.get(&node.0)
    }

    /// A planned entry's wire id.
    pub fn id(&self, p: &Planned) -> String {
        match p.key {
            Key::Object {
                object,
                placed,
                level: 0,
            } => format!("o:{object}@{placed}"),
            Key::Object {
                object,
                placed,
                level,
            } => format!("o:{object}@{placed}/{level}"),
            Key::Aggregate { node, .. } => {
                let hash = self.aggregate(p).map_or("", |a| a.glb.as_str());
                format!("n:{node}@{hash}")
            }
            Key::Impostor { node, views, .. } => {
                let key = self.impostor(p).map_or("", |i| i.key.as_str());
                format!("n:{node}@{key}.{views:03x}")
            }
            Key::Instances {
                node,
                content,
                levels,
            } => format!("n:{node}@i{content:016x}/{levels:016x}"),
        }
    }

    /// The impostor a planned entry draws, if it is one.
    fn impostor(&self, p: &Planned) -> Option<&horizon_aggregate::ImpostorEntry> {
        let Key::Impostor { node, .. } = p.key else {
            return None;
        };
        self.manifest.as_ref()?.impostors.get(&node)
    }

    /// An impostor entry: its views facing the eye, nearest the view direction first, with
    /// their images as assets.
    fn impostor_entry(&self, p: &Planned) -> Entry {
        let Key::Impostor { views: mask, .. } = p.key else {
            unreachable!("impostor_entry is only called for impostors");
        };
        let towards = Vec3::from(p.center) - eye_of(self.view.eye);
        let mut chosen: Vec<&horizon_aggregate::ImpostorView> = self
            .impostor(p)
            .iter()
            .flat_map(|i| i.views.iter().enumerate())
            .filter(|(k, _)| *k < 16 && mask & (1 << k) != 0)
            .map(|(_, v)| v)
            .collect();
        let along = |v: &horizon_aggregate::ImpostorView| {
            let d = v.direction.map(f32::from);
            Vec3::from(d).normalize_or_zero().dot(towards)
        };
        chosen.sort_by(|a, b| along(b).total_cmp(&along(a)));
        let assets: Vec<Asset> = chosen
            .iter()
            .flat_map(|v| {
                [&v.color, &v.depth, &v.normal]
                    .into_iter()
                    .zip(v.bytes)
                    .map(|(hash, bytes)| Asset {
                        hash: hash.clone(),
                        bytes,
                        role: AssetRole::Orthoview,
                    })
            })
            .collect();
        let imp = self.impostor(p);
        Entry {
            id: self.id(p),
            kind: EntryKind::Impostor,
            bytes: assets.iter().map(|a| a.bytes).sum(),
            assets,
            placements: Vec::new(),
            level: 0,
            pending: false,
            triangles: 0,
            draw_calls: chosen.len() as u64,
            center: p.center,
            radius: p.radius,
            covers: p.covers,
            impostor: Some(Impostor {
                min: imp.map_or([0.0; 3], |i| i.min),
                max: imp.map_or([0.0; 3], |i| i.max),
                views: chosen.iter().map(|v| wire_view(v)).collect(),
            }),
        }
    }

    /// An instances entry: each model level once among its assets, each object a placement.
    fn instances_entry(&self, p: &Planned, instances: &[Instance]) -> Entry {
        let mut assets: Vec<Asset> = Vec::new();
        let mut index: HashMap<(u64, u8), usize> = HashMap::new();
        let mut placements = Vec::with_capacity(instances.len());
        let (mut triangles, mut draw_calls) = (0, 0);
        for i in instances {
            let Some(m) = self.models.get(i.model as usize).and_then(Option::as_ref) else {
                continue;
            };
            let l = m.level(i.level);
            if let std::collections::hash_map::Entry::Vacant(v) = index.entry((i.model, i.level)) {
                v.insert(assets.len());
                assets.push(Asset {
                    hash: l.hash.clone(),
                    bytes: l.bytes,
                    role: AssetRole::Model,
                });
                draw_calls += l.draw_calls;
            }
            triangles += l.triangles;
            placements.push(Placement {
                asset: l.hash.clone(),
                matrix: matrix_of(&i.transform),
            });
        }
        Entry {
            id: self.id(p),
            kind: EntryKind::Instances,
            bytes: assets.iter().map(|a| a.bytes).sum(),
            assets,
            placements,
            level: 0,
            pending: false,
            triangles,
            draw_calls,
            center: p.center,
            radius: p.radius,
            covers: p.covers,
            impostor: None,
        }
    }

    /// The level each model is drawn at (the finest, where a plan under a triangle budget
    /// draws a model at several): what [`plan_after`] holds shared levels to.
    fn model_levels(&self) -> HashMap<u64, u8> {
        let mut levels: HashMap<u64, u8> = HashMap::new();
        let mut at = |model: u64, level: u8| {
            let l = levels.entry(model).or_insert(level);
            *l = (*l).min(level);
        };
        for p in &self.items {
            match (&p.what, p.key) {
                (Drawn::Object { model, .. }, Key::Object { level, .. }) => at(*model, level),
                (Drawn::Instances(instances), _) => {
                    instances.iter().for_each(|i| at(i.model, i.level));
                }
                _ => {}
            }
        }
        levels
    }

    /// The levels of detail its objects need: what [`plan_after`] holds them to. By tree id
    /// on the tree the plan was made on (its own levels, [`Decisions`]), else by world id.
    fn held_levels(&self, tree: &horizon_world::Tree) -> HeldLevels {
        if tree.generation == self.generation {
            let levels = self.decisions.own_levels(tree.bvh.object_slots());
            debug_assert!(
                self.levels_by_world().iter().all(|(&w, &level)| {
                    tree.tree_id(w)
                        .is_some_and(|o| levels[o.0 as usize] == level)
                }),
                "a plan's own levels are its entries' levels"
            );
            return HeldLevels::ByTree(levels);
        }
        HeldLevels::ByWorld(self.levels_by_world())
    }

    /// Its entries' objects' own levels, by world id.
    fn levels_by_world(&self) -> HashMap<u64, u8> {
        let mut held = HashMap::new();
        for p in &self.items {
            match &p.what {
                Drawn::Object { needed, .. } => {
                    if let Key::Object { object, .. } = p.key {
                        held.insert(object, *needed);
                    }
                }
                Drawn::Instances(instances) => {
                    held.extend(instances.iter().map(|i| (i.object, i.needed)));
                }
                Drawn::Aggregate | Drawn::Impostor => {}
            }
        }
        held
    }

    /// A planned entry as the wire carries it.
    pub fn entry(&self, p: &Planned) -> Entry {
        match &p.what {
            Drawn::Impostor => return self.impostor_entry(p),
            Drawn::Instances(instances) => return self.instances_entry(p, instances),
            Drawn::Object { .. } | Drawn::Aggregate => {}
        }
        let mut level = 0;
        let mut preview = None;
        let (kind, asset, bytes, triangles, draw_calls, matrix, role) = match &p.what {
            Drawn::Object {
                model, transform, ..
            } => {
                let l = p.level();
                level = u32::from(l);
                let asset = self.models.get(*model as usize).and_then(Option::as_ref);
                preview = asset
                    .and_then(|m| {
                        m.levels
                            .last()
                            .filter(|_| usize::from(l) + 1 < m.levels.len())
                    })
                    .map(|c| Asset {
                        hash: c.hash.clone(),
                        bytes: c.bytes,
                        role: AssetRole::Preview,
                    });
                let m = asset.map(|m| m.level(l));
                (
                    EntryKind::Object,
                    m.map_or(String::new(), |m| m.hash.clone()),
                    m.map_or(0, |m| m.bytes),
                    m.map_or(0, |m| m.triangles),
                    m.map_or(1, |m| m.draw_calls),
                    matrix_of(transform),
                    AssetRole::Model,
                )
            }
            Drawn::Impostor | Drawn::Instances(_) => {
                unreachable!("impostors and instances have entries of their own")
            }
            Drawn::Aggregate => {
                let a = self.aggregate(p);
                let cost = a.map(NodeAsset::of);
                (
                    EntryKind::Aggregate,
                    a.map_or(String::new(), |a| a.glb.clone()),
                    cost.as_ref().map_or(0, |c| c.bytes),
                    cost.as_ref().map_or(0, |c| c.triangles),
                    cost.as_ref().map_or(1, |c| c.draw_calls),
                    matrix_of(&Affine3A::IDENTITY),
                    AssetRole::Mesh,
                )
            }
        };
        Entry {
            id: self.id(p),
            kind,
            assets: std::iter::once(Asset {
                hash: asset.clone(),
                bytes,
                role,
            })
            .chain(preview)
            .collect(),
            placements: vec![Placement { asset, matrix }],
            level,
            pending: p.pending,
            bytes,
            triangles,
            draw_calls,
            center: p.center,
            radius: p.radius,
            covers: p.covers,
            impostor: None,
        }
    }

    /// The delta from `before` (what a client holds) to this plan: entries to remove, with
    /// why, then entries to add, each naming the removed entries whose objects it now
    /// draws. `served` is the tree this plan was made on; ancestry is read from it.
    pub fn diff(&self, before: &Plan, served: &Served<'_>) -> (Vec<Addition>, Vec<Removal>) {
        // One map, of the entries held: each planned entry looks up its key there, and the
        // held entries no planned one kept are gone.
        let mut old: HashMap<Key, usize> = HashMap::with_capacity(before.items.len());
        old.extend(before.items.iter().enumerate().map(|(i, p)| (p.key, i)));
        let mut kept = vec![false; before.items.len()];
        let fresh: Vec<&Planned> = self
            .items
            .iter()
            .filter(|p| match old.get(&p.key) {
                Some(&i) if before.items[i].same(p) => {
                    kept[i] = true;
                    false
                }
                _ => true,
            })
            .collect();
        let gone: Vec<&Planned> = before
            .items
            .iter()
            .zip(&kept)
            .filter_map(|(p, &kept)| (!kept).then_some(p))
            .collect();
        if gone.is_empty() && fresh.is_empty() {
            return (Vec::new(), Vec::new());
        }
        let tree = served.tree;
        let bvh = &tree.bvh;
        // Where each removed entry sat in the tree now: its node, or its object's leaf.
        let place_of = |p: &Planned| -> Option<NodeId> {
            p.node().or_else(|| {
                let o = tree.tree_id(p.object()?)?;
                bvh.object(o).map(|o| o.leaf())
            })
        };
        let ancestors = |start: Option<NodeId>| {
            std::iter::successors(start, move |&n| bvh.node(n).and_then(|r| r.parent()))
        };
        let fresh_nodes: HashMap<NodeId, usize> = fresh
            .iter()
            .enumerate()
            .filter_map(|(i, p)| p.node().map(|n| (n, i)))
            .collect();
        let fresh_objects: HashMap<u64, usize> = fresh
            .iter()
            .enumerate()
            .filter_map(|(i, p)| p.object().map(|o| (o, i)))
            .collect();
        let gone_nodes: HashMap<NodeId, usize> = gone
            .iter()
            .enumerate()
            .filter_map(|(i, p)| p.node().map(|n| (n, i)))
            .collect();
        let mut replaces: Vec<Vec<String>> = vec![Vec::new(); fresh.len()];
        // The held instances entry of the same node and objects each fresh one may reuse.
        let mut reusable: Vec<Option<&Planned>> = vec![None; fresh.len()];
        let mut removals = Vec::with_capacity(gone.len());
        for p in &gone {
            let id = before.id(p);
            let reason = if let Some(&i) = p
                .node()
                .and_then(|n| fresh_nodes.get(&n))
                .or_else(|| p.object().and_then(|o| fresh_objects.get(&o)))
            {
                // The same node or object, in a new version or at another level of detail.
                replaces[i].push(id.clone());
                if let (Key::Instances { content: a, .. }, Key::Instances { content: b, .. }) =
                    (p.key, fresh[i].key)
                {
                    if a == b {
                        reusable[i] = Some(p);
                    }
                }
                match (p.key, fresh[i].key) {
                    (
                        Key::Object {
                            placed: a,
                            level: from,
                            ..
                        },
                        Key::Object {
                            placed: b,
                            level: to,
                            ..
                        },
                    ) if a == b && from != to => {
                        if to < from {
                            RemoveReason::Refined
                        } else {
                            RemoveReason::Coarsened
                        }
                    }
                    _ => RemoveReason::Replaced,
                }
            } else if p.object().is_some_and(|o| tree.tree_id(o).is_none()) {
                RemoveReason::Deleted
            } else if let Some(&i) = ancestors(place_of(p))
                .skip(usize::from(p.node().is_some()))
                .find_map(|a| fresh_nodes.get(&a))
            {
                // An ancestor came in: the viewer went away.
                replaces[i].push(id.clone());
                RemoveReason::Coarsened
            } else {
                // Finer entries came in (found below, from their side), or the tree moved.
                RemoveReason::Refined
            };
            removals.push(Removal { id, reason });
        }
        for (i, p) in fresh.iter().enumerate() {
            let start = match p.node() {
                Some(node) => bvh.node(node).and_then(|r| r.parent()),
                None => place_of(p),
            };
            for a in ancestors(start) {
                if let Some(&g) = gone_nodes.get(&a) {
                    if removals[g].reason == RemoveReason::Refined {
                        replaces[i].push(removals[g].id.clone());
                    }
                }
            }
        }
        let additions = fresh
            .iter()
            .zip(replaces)
            .zip(reusable)
            .map(|((p, replaces), reusable)| {
                let mut entry = self.entry(p);
                let reuses = reusable.and_then(|held| reuse(&before.entry(held), &mut entry));
                Addition {
                    entry,
                    replaces,
                    reuses,
                }
            })
            .collect();
        (additions, removals)
    }
}

/// Sends `entry`'s assets and placements as `held`'s renamed, where they are: each held asset
/// becomes one asset of `entry` (instances whose models changed level), and renaming `held`'s
/// assets and placements so gives `entry`'s exactly. Empties them in `entry` then.
fn reuse(held: &Entry, entry: &mut Entry) -> Option<Reuse> {
    if held.assets.len() != entry.assets.len() || held.placements.len() != entry.placements.len() {
        return None;
    }
    let mut assets: Vec<Renamed> = Vec::new();
    for (from, to) in held.assets.iter().zip(&entry.assets) {
        if assets.iter().any(|r| r.from == from.hash) {
            return None;
        }
        if from.hash != to.hash || from.bytes != to.bytes {
            assets.push(Renamed {
                from: from.hash.clone(),
                to: to.hash.clone(),
                bytes: to.bytes,
            });
        }
    }
    let reuse = Reuse {
        entry: held.id.clone(),
        assets,
    };
    let mut made = entry.clone();
    reuse.fill(held, &mut made);
    if made != *entry {
        return None;
    }
    entry.assets = Vec::new();
    entry.placements = Vec::new();
    Some(reuse)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Objects of model 7 that need levels 2 and 3, one alone and one as an instance.
    fn needing_2_and_3() -> Vec<Planned> {
        let object = |object: u64, needed: u8| Planned {
            key: Key::Object {
                object,
                placed: 1,
                level: needed,
            },
            what: Drawn::Object {
                model: 7,
                transform: Affine3A::IDENTITY,
                tree: ObjectId(object as u32),
                needed,
            },
            covers: 1,
            pending: false,
            center: [0.0; 3],
            radius: 1.0,
            solid_angle: 0.0,
        };
        let instance = Instance {
            object: 2,
            tree: ObjectId(2),
            placed: 1,
            model: 7,
            transform: Affine3A::IDENTITY,
            needed: 3,
            level: 3,
        };
        vec![
            object(1, 2),
            Planned {
                key: Key::Instances {
                    node: 0,
                    content: 0,
                    levels: 0,
                },
                what: Drawn::Instances(vec![instance].into()),
                ..object(0, 0)
            },
        ]
    }

    fn levels_of(items: &[Planned]) -> Vec<u8> {
        items
            .iter()
            .flat_map(|p| match (&p.what, p.key) {
                (Drawn::Instances(i), _) => i.iter().map(|i| i.level).collect(),
                (_, Key::Object { level, .. }) => vec![level],
                _ => vec![],
            })
            .collect()
    }

    #[test]
    fn a_model_shares_its_finest_needed_level_or_the_held_one_within_the_slack() {
        let shared = |held: &[(u64, u8)]| {
            let mut items = needing_2_and_3();
            share_levels(&mut items, &held.iter().copied().collect());
            levels_of(&items)
        };
        assert_eq!(shared(&[]), [2, 2], "the finest any object needs");
        assert_eq!(shared(&[(7, 1)]), [1, 1], "held one level finer: kept");
        assert_eq!(shared(&[(7, 0)]), [2, 2], "held two levels finer: dropped");
        assert_eq!(
            shared(&[(7, 3)]),
            [2, 2],
            "held coarser than needed: refined"
        );
        assert_eq!(shared(&[(8, 1)]), [2, 2], "another model's level: ignored");
    }

    /// A chain whose error doubles and texels double in size at every level.
    fn chain() -> ModelAsset {
        ModelAsset {
            levels: (0..6)
                .map(|k| LevelAsset {
                    hash: format!("{k}"),
                    bytes: 1000 >> k,
                    triangles: 4000 >> (2 * k),
                    draw_calls: 1,
                    error: if k == 0 { 0.0 } else { 0.01 * (1 << k) as f32 },
                    texel: 0.005 * (1 << k) as f32,
                })
                .collect(),
        }
    }

    const PIXEL: f32 = 5.5e-4;

    #[test]
    fn level_choice_is_monotone_in_distance_and_scale() {
        let m = chain();
        let mut last = 0;
        let mut seen = HashSet::new();
        for step in 0..2000 {
            let d = 0.5 * 1.005f32.powi(step);
            let level = m.choose(d, 1.0, PIXEL, 1.0, None);
            assert!(level >= last, "level {level} at {d} m after {last}");
            // The chosen level's error and texels are within a pixel; the next one's are not.
            let footprint = d * PIXEL;
            let l = &m.levels[level as usize];
            assert!(l.error <= footprint && l.texel <= footprint || level == 0);
            if let Some(next) = m.levels.get(level as usize + 1) {
                assert!(next.error > footprint || next.texel > footprint);
            }
            // A larger object (scaled up) never gets a coarser level at the same distance.
            assert!(m.choose(d, 2.0, PIXEL, 1.0, None) <= level);
            seen.insert(level);
            last = level;
        }
        assert_eq!(
            seen.len(),
            m.levels.len(),
            "every level is chosen somewhere"
        );
    }

    #[test]
    fn inside_its_band_a_level_is_what_choose_gives_and_bands_cover_almost_every_distance() {
        let m = chain();
        let mut rng = horizon_mesh::rng::Rng::new(5);
        let (mut inside, mut counted, mut samples) = (0, 0, 0);
        for _ in 0..20_000 {
            let d = 0.01 * 1e6f32.powf(rng.unit_f64() as f32) - 0.005;
            let scale = 0.25 * 16f32.powf(rng.unit_f64() as f32);
            let error = [1.0, 0.5, 3.0, 0.0][samples % 4];
            samples += 1;
            let held = match samples % 3 {
                0 => None,
                _ => Some(m.choose(d * 1.1, scale, PIXEL, error, None)),
            };
            let level = m.choose(d, scale, PIXEL, error, held);
            let (lo, hi) = m.band(level, held, scale, PIXEL, error);
            // Every distance above 0 where the level chosen is the one held (or none is) lies
            // in its band, but for a sliver at the band's edges.
            if d > 0.0 && held.is_none_or(|h| h == level) {
                counted += 1;
                if d > lo && d < hi {
                    inside += 1;
                }
            }
            // Wherever a band says a level, `choose` gives it: probe the band's inside.
            for k in 0..8 {
                if lo >= hi {
                    break;
                }
                let t = (k as f32 + 0.5) / 8.0;
                let probe = if hi.is_finite() && lo.is_finite() {
                    lo + (hi - lo) * t
                } else if lo.is_finite() {
                    lo * (1.0 + 10.0 * t) + t
                } else {
                    hi.min(1e4) * t - (1.0 - t)
                };
                if probe > lo && probe < hi {
                    assert_eq!(
                        m.choose(probe, scale, PIXEL, error, held),
                        level,
                        "band ({lo}, {hi}) of level {level} held {held:?} at {probe}"
                    );
                }
            }
            // Near the edges too, where rounding would show.
            for edge in [lo, hi] {
                if edge.is_finite() {
                    for probe in [edge * (1.0 + 1e-6), edge * (1.0 - 1e-6)] {
                        if probe > lo && probe < hi {
                            assert_eq!(m.choose(probe, scale, PIXEL, error, held), level);
                        }
                    }
                }
            }
            // A level other than the one held has no band: it is chosen again.
            if held.is_some_and(|h| h != level) {
                assert!(lo >= hi, "level {level} held {held:?}: ({lo}, {hi})");
            }
        }
        assert!(
            inside * 1000 > counted * 998,
            "{inside} of {counted} distances inside their level's band"
        );
    }

    #[test]
    fn no_error_allowed_is_level_zero_and_a_held_level_stays_within_the_margin() {
        let m = chain();
        assert_eq!(m.choose(1e6, 1.0, PIXEL, 0.0, None), 0);
        // Just past the distance where level 2 becomes allowed: a client holding level 1
        // keeps it until level 2 is allowed with the margin to spare.
        let at = |level: usize| m.levels[level].error.max(m.levels[level].texel) / PIXEL;
        let d2 = at(2);
        assert_eq!(m.choose(d2 * 1.01, 1.0, PIXEL, 1.0, None), 2);
        assert_eq!(m.choose(d2 * 1.01, 1.0, PIXEL, 1.0, Some(1)), 1);
        assert_eq!(
            m.choose(d2 * LEVEL_MARGIN * 1.01, 1.0, PIXEL, 1.0, Some(1)),
            2
        );
        // Coming back, a client holding level 2 keeps it a little nearer than allowed.
        assert_eq!(m.choose(d2 * 0.9, 1.0, PIXEL, 1.0, None), 1);
        assert_eq!(m.choose(d2 * 0.9, 1.0, PIXEL, 1.0, Some(2)), 2);
        assert_eq!(
            m.choose(d2 / LEVEL_MARGIN * 0.99, 1.0, PIXEL, 1.0, Some(2)),
            1
        );
        // A level the model does not have is not kept.
        assert_eq!(m.choose(d2 * 1.01, 1.0, PIXEL, 1.0, Some(40)), 2);
    }
}
