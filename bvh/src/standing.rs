//! Standing cut queries: a cut kept per client and brought up to date as the viewer moves and
//! the tree changes, emitting ordered deltas (after Sirikata's `RTreeCutQueryHandler`,
//! Cheslack-Postava et al. 2012; core paper section 4; `DESIGN.md`, "Cut test").
//!
//! # Semantics
//! With hysteresis `h`, the standing cut's *refined set* `R` (the strict ancestors of its
//! entries) evolves as follows. A node `n` passes if its worst-case solid angle is at least
//! `Omega_min * (1 - h)` when `n` was refined after the previous update, and at least
//! `Omega_min * (1 + h)` otherwise. The new `R` is the set of nodes that pass together with
//! every ancestor; the cut is its frontier (the unrefined children of refined nodes, a refined
//! leaf's objects, or the root alone). So a node refines only at `(1 + h) Omega_min` and
//! coarsens only below `(1 - h) Omega_min`: no ping-pong in the band between.
//!
//! With `h = 0` this is exactly the set [`Bvh::cut`] refines, so whenever the cut fits in
//! `max_results` it *equals* the one-shot cut for the same query (the best-first order only
//! matters when the budget binds). If the cut would exceed `max_results`, the update falls back
//! to the one-shot best-first cut at `Omega_min` (no hysteresis while the budget binds) and
//! diffs against it; the result then equals the one-shot cut for any `h`. While the budget
//! binds, later updates start from the one-shot cut directly (the walk would only hit the
//! budget again) and return to the walk once a one-shot cut ends at least `max_children - 1`
//! entries short of the budget, which proves no refinement was skipped. The tests check
//! equality with the one-shot cut at `h = 0` over random walks with random inserts, removes
//! and rebuilds, and, for `h > 0`, equality with a from-scratch evaluation of the rule above
//! given the previous refined set, plus the absence of ping-pong.
//!
//! # What is incremental
//! An update walks down from the root through the nodes that stay (or become) refined and
//! tests each unrefined child once: it touches the previous cut's frontier (its entries and
//! their ancestors) plus whatever is newly refined, never the rest of the tree, and uses no
//! heap. Because the walk follows the *current* tree, tree changes (insert, remove, split,
//! condense, move, rebuild) need no notification: the walk sees the new structure, and the
//! previous refined set only serves as the hysteresis hint (a node id freed and reused by the
//! tree merely gets the hint of its predecessor).
//!
//! While the budget binds, the one-shot best-first cut is computed in two phases. The last
//! update tells where the budget bound it (the first node it kept for the budget); a
//! heap-free walk refines every node whose place in the best-first order ([`order_key`]:
//! solid angle, then id) comes a margin of refinements before that point, and the heap only
//! continues from the walk's frontier. If such a walk fits the budget, the best-first cut
//! refines all of its nodes before any other and keeps none of them for the budget, so the
//! result is the one-shot cut's exactly; if it overflows, the update runs the plain query
//! and the margin doubles. Only the few nodes near the binding point pass through the heap.
//!
//! The deltas: if the tree's [`Bvh::state_stamp`] is the one the last update saw, only the
//! viewer moved, and the deltas follow from the change of the refined set alone (a node that
//! became refined trades its entry for its children's, one that stopped being refined the
//! reverse), in O(refined set), with the unchanged entries untouched. Otherwise they are the
//! diff between the previous and new entries, by item, with a fast hash: O(cut size).
//!
//! # Delta order and meaning
//! One update's deltas are every [`CutDelta::Add`] first, then every [`CutDelta::Reparent`],
//! then every [`CutDelta::Remove`]: a client always has the new entries (a refinement's
//! children, a coarsening's aggregate) before it drops the old ones. `Add` of an item the
//! client already holds *replaces* it (its bounds or object count changed, e.g. an aggregate
//! after an insert below it, or an object after a move). `Reparent` changes only the parent
//! (e.g. after a split). `Remove` is permanent only for an object that left the world
//! (removed from the tree); every other removal is transient (replaced by a refinement,
//! a coarsening or the tree's restructuring). An object id that the tree frees and reuses for
//! a new object within one update arrives as a replacing `Add`.

use std::collections::{BinaryHeap, HashMap, HashSet};
use std::hash::{BuildHasherDefault, Hasher};

use glam::Vec3;
use serde::{Deserialize, Serialize};

use crate::cut::{order_key, Candidate, Cut, CutEntry, CutItem, CutQuery, CutWorkspace};
use crate::solid_angle::worst_case_solid_angle;
use crate::tree::{Bvh, NodeId, NodeKind, ObjectId};

/// A client's standing cut: create it with [`StandingQuery::new`], then call
/// [`StandingQuery::update`] after every viewer move or batch of tree changes.
#[derive(Debug)]
pub struct StandingQuery {
    options: StandingOptions,
    /// The current entries, by item, with the update stamp that last saw them.
    entries: FastMap<CutItem, Slot>,
    /// The refined set after the last update (the hysteresis hint).
    refined: FastSet<u32>,
    /// The refined set being built.
    next_refined: FastSet<u32>,
    /// The new entries being built.
    fresh: Vec<CutEntry>,
    /// Walk stack.
    stack: Vec<u32>,
    /// Removals, emitted after the adds.
    removals: Vec<CutDelta>,
    /// The items an unchanged-tree update removes (scratch).
    removed: Vec<CutItem>,
    /// For the budget-bound updates (the one-shot best-first cut).
    workspace: CutWorkspace,
    fallback: Cut,
    /// The last update's cut was limited by the budget: start from the best-first cut.
    budget_bound: bool,
    /// The threshold of the next budget-bound update's seeding walk: an [`order_key`]
    /// `margin` refinements before the point where the budget bound the last best-first cut.
    threshold_key: Option<u64>,
    /// Refinements the threshold stays before that point: doubled when the walk overflows
    /// the budget, shrunk while it fits.
    margin: usize,
    /// Scratch for choosing the threshold.
    keys: Vec<u64>,
    /// The [`Bvh::state_stamp`] of the tree at the last update: while it holds, only the
    /// viewer moved, and the deltas follow from the change of the refined set alone.
    tree_stamp: Option<u64>,
    stamp: u32,
}

/// The margin's range and start (see `StandingQuery::margin`), in refinements.
const MIN_MARGIN: usize = 8;
const MAX_MARGIN: usize = 1 << 16;
const START_MARGIN: usize = 32;

/// The parameters of a standing query.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct StandingOptions {
    /// `Omega_min`: the solid angle (steradians) at which a node is refined.
    pub min_solid_angle: f32,
    /// The most entries the cut may hold, as in [`CutQuery::max_results`].
    pub max_results: usize,
    /// The hysteresis `h` in `[0, 1)`: refine at `(1 + h) Omega_min`, coarsen below
    /// `(1 - h) Omega_min`. 0 makes every update equal the one-shot cut.
    pub hysteresis: f32,
}

impl StandingOptions {
    /// `Omega_min` and `max_results` with hysteresis 0.1.
    pub fn new(min_solid_angle: f32, max_results: usize) -> Self {
        Self {
            min_solid_angle,
            max_results,
            hysteresis: 0.1,
        }
    }
}

/// One change to a client's cut.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub enum CutDelta {
    /// A new entry, or the new version of an entry the client holds (replace it).
    Add(CutEntry),
    /// Drop an entry. `transient`: its objects stay in the world and are covered by entries
    /// added in the same update; otherwise the object left the world.
    Remove {
        /// The entry's item.
        item: CutItem,
        /// Replaced by a refinement, coarsening or restructuring (true), or gone (false).
        transient: bool,
    },
    /// The entry's parent changed (a split or condense moved it), nothing else.
    Reparent {
        /// The entry's item.
        item: CutItem,
        /// Its new parent (`None`: it became the root).
        new_parent: Option<NodeId>,
    },
}

/// What an update did.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct UpdateStats {
    /// Nodes whose worst-case solid angle was evaluated.
    pub nodes_visited: usize,
    /// The budget bound, so the update used the one-shot best-first cut.
    pub fell_back: bool,
    /// That best-first cut was seeded by a threshold walk that fit the budget (the cheap
    /// case), rather than computed from the root.
    pub seeded: bool,
    /// Nodes the best-first refinement popped from its heap and refined.
    pub heap_refinements: usize,
}

/// Applies one update's deltas to a client-side copy of the cut: `Add` inserts or replaces,
/// `Reparent` sets the parent, `Remove` drops. Entries are compared by the caller; the
/// `solid_angle` field is as of the update that last added the entry.
pub fn apply_deltas(cut: &mut HashMap<CutItem, CutEntry>, deltas: &[CutDelta]) {
    for delta in deltas {
        match *delta {
            CutDelta::Add(entry) => {
                cut.insert(entry.item, entry);
            }
            CutDelta::Reparent { item, new_parent } => {
                if let Some(entry) = cut.get_mut(&item) {
                    entry.parent = new_parent;
                }
            }
            CutDelta::Remove { item, .. } => {
                cut.remove(&item);
            }
        }
    }
}

impl StandingQuery {
    /// An empty standing cut; the first [`update`](Self::update) adds every entry.
    pub fn new(options: StandingOptions) -> Self {
        Self {
            options,
            entries: FastMap::default(),
            refined: FastSet::default(),
            next_refined: FastSet::default(),
            fresh: Vec::new(),
            stack: Vec::new(),
            removals: Vec::new(),
            removed: Vec::new(),
            workspace: CutWorkspace::new(),
            fallback: Cut::default(),
            budget_bound: false,
            threshold_key: None,
            margin: START_MARGIN,
            keys: Vec::new(),
            tree_stamp: None,
            stamp: 0,
        }
    }

    /// The options.
    pub fn options(&self) -> &StandingOptions {
        &self.options
    }

    /// Number of entries in the cut.
    pub fn len(&self) -> usize {
        self.entries.len()
    }

    /// Whether the cut is empty (before the first update, or for an empty tree).
    pub fn is_empty(&self) -> bool {
        self.entries.is_empty()
    }

    /// The current entries, in no particular order, each with the solid angle of the update
    /// that last sent it (as a client holding the deltas has it).
    pub fn entries(&self) -> impl Iterator<Item = &CutEntry> + '_ {
        self.entries.values().map(|slot| &slot.entry)
    }

    /// Brings the cut up to date for a viewer at `position` in `bvh` (which may have changed
    /// in any way since the last update) and appends the ordered deltas to `deltas`.
    pub fn update(&mut self, bvh: &Bvh, position: Vec3, deltas: &mut Vec<CutDelta>) -> UpdateStats {
        let mut stats = UpdateStats::default();
        let walked = !self.budget_bound && self.walk(bvh, position, &mut stats);
        if !walked {
            stats.fell_back = true;
            self.best_first(bvh, position, &mut stats);
            // A best-first cut that skipped a refinement for the budget ended within
            // `max_children - 1` entries of it; one further away is the plain threshold cut,
            // so the next update can walk again.
            self.budget_bound =
                self.fresh.len() + bvh.options.max_children > self.options.max_results.max(1) + 1;
            self.next_refined.clear();
            self.next_refined
                .extend(self.workspace.refined.iter().copied());
        }
        if self.tree_stamp == Some(bvh.state_stamp()) {
            self.diff_refined(bvh, position, deltas);
        } else {
            self.diff(bvh, deltas);
            self.tree_stamp = Some(bvh.state_stamp());
        }
        std::mem::swap(&mut self.refined, &mut self.next_refined);
        stats
    }

    /// The hysteresis walk from the root; false if the cut would exceed the budget.
    fn walk(&mut self, bvh: &Bvh, viewer: Vec3, stats: &mut UpdateStats) -> bool {
        self.fresh.clear();
        self.next_refined.clear();
        self.stack.clear();
        if bvh.is_empty() {
            return true;
        }
        let omega = self.options.min_solid_angle;
        let h = self.options.hysteresis;
        let (lo, hi) = (omega * (1.0 - h), omega * (1.0 + h));
        let budget = self.options.max_results.max(1);
        let mut size = 1usize;
        self.stack.push(bvh.root);
        while let Some(n) = self.stack.pop() {
            let node = &bvh.nodes[n as usize];
            let solid_angle = worst_case_solid_angle(viewer, node.centre, node.radius, node.r_max);
            stats.nodes_visited += 1;
            let threshold = if self.refined.contains(&n) { lo } else { hi };
            if solid_angle < threshold {
                self.fresh.push(bvh.aggregate(n, node, solid_angle));
                continue;
            }
            size += node.len as usize - 1;
            if size > budget {
                return false;
            }
            self.next_refined.insert(n);
            bvh.refine_onto(viewer, n, &mut self.fresh, &mut self.stack);
        }
        true
    }

    /// The one-shot best-first cut into `fresh`, and its refined nodes into
    /// `workspace.refined`.
    ///
    /// Computed in two phases when the last update told where the budget bound: a heap-free
    /// walk refines every node whose [`order_key`] is at least a threshold chosen a margin
    /// before that point, then the best-first refinement continues from the walk's
    /// frontier. The result is the one-shot cut's, because the best-first order refines
    /// every node of such a walk before any other and, when the walk fits the budget, keeps
    /// none of them for it (see `Bvh::refine_best_first`). Only the nodes near the binding
    /// point pass through the heap. A walk that overflows the budget is dropped for the
    /// plain query, and the margin doubles.
    fn best_first(&mut self, bvh: &Bvh, position: Vec3, stats: &mut UpdateStats) {
        let query = CutQuery {
            position,
            min_solid_angle: self.options.min_solid_angle,
            max_results: self.options.max_results,
        };
        let seeded = match self.threshold_key {
            Some(key) if !bvh.is_empty() => self.threshold_seed(bvh, &query, key),
            _ => None,
        };
        match seeded {
            Some(size) => {
                stats.seeded = true;
                let walked = self.workspace.refined.len();
                bvh.refine_best_first(&query, &mut self.workspace, size, &mut self.fallback);
                stats.heap_refinements = self.workspace.refined.len() - walked;
                self.margin = (self.margin - self.margin / 8).max(MIN_MARGIN);
            }
            None => {
                if self.threshold_key.is_some() {
                    self.margin = (self.margin * 2).min(MAX_MARGIN);
                }
                bvh.cut_into(&query, &mut self.workspace, &mut self.fallback);
                stats.heap_refinements = self.workspace.refined.len();
            }
        }
        self.threshold_key = self.next_threshold();
        stats.nodes_visited += self.fallback.nodes_visited;
        std::mem::swap(&mut self.fresh, &mut self.fallback.entries);
    }

    /// The key `margin` refinements before the first node the budget kept from refining
    /// (the `margin + 1`-th smallest key refined before it), or `None` if the budget did not
    /// bind that late.
    fn next_threshold(&mut self) -> Option<u64> {
        let skipped_at = self.workspace.skipped_at?;
        if skipped_at <= self.margin {
            return None;
        }
        self.keys.clear();
        self.keys
            .extend_from_slice(&self.workspace.refined_keys[..skipped_at]);
        Some(*self.keys.select_nth_unstable(self.margin).1)
    }

    /// The cut refining exactly the nodes whose [`order_key`] is at least `threshold`, as a
    /// seed for the best-first refinement: objects and nodes below `Omega_min` into
    /// `fallback.entries`, the other unrefined nodes into the workspace heap, the refined
    /// nodes into `workspace.refined`. Returns the cut's size, or `None` if it would exceed
    /// the budget.
    fn threshold_seed(&mut self, bvh: &Bvh, query: &CutQuery, threshold: u64) -> Option<usize> {
        let viewer = query.position;
        let budget = query.max_results.max(1);
        let out = &mut self.fallback;
        out.entries.clear();
        out.nodes_visited = 1;
        let ws = &mut self.workspace;
        ws.refined.clear();
        ws.refined_keys.clear();
        ws.skipped_at = None;
        let mut frontier = std::mem::take(&mut ws.heap).into_vec();
        frontier.clear();
        self.stack.clear();
        self.stack.push(bvh.root);
        let mut size = 1usize;
        let mut fits = true;
        while let Some(n) = self.stack.pop() {
            let node = &bvh.nodes[n as usize];
            let solid_angle = worst_case_solid_angle(viewer, node.centre, node.radius, node.r_max);
            let key = order_key(solid_angle, n);
            if key < threshold {
                if solid_angle < query.min_solid_angle {
                    out.entries.push(bvh.aggregate(n, node, solid_angle));
                } else {
                    frontier.push(Candidate {
                        solid_angle,
                        node: n,
                    });
                }
                continue;
            }
            size += node.len as usize - 1;
            if size > budget {
                fits = false;
                break;
            }
            ws.refined.push(n);
            ws.refined_keys.push(key);
            out.nodes_visited += bvh.refine_onto(viewer, n, &mut out.entries, &mut self.stack);
        }
        // Heapify the frontier in linear time.
        ws.heap = BinaryHeap::from(frontier);
        fits.then_some(size)
    }

    /// The deltas when the tree is the one the last update saw: only the refined set changed
    /// (from `refined` to `next_refined`, both closed under ancestors), so only the entries
    /// next to a node that changed sides change. A newly refined node drops its own entry (if
    /// it had one: it may have been several levels below the old cut) for those of its
    /// children that stay unrefined, or of its objects; a node no longer refined regains its
    /// entry (if its parent stays refined) and drops its children's. O(refined set), not
    /// O(cut): the unchanged entries keep the solid angle they were sent with.
    fn diff_refined(&mut self, bvh: &Bvh, viewer: Vec3, deltas: &mut Vec<CutDelta>) {
        let root = bvh.root;
        let (old, new) = (&self.refined, &self.next_refined);
        let entries = &mut self.entries;
        let stamp = self.stamp;
        let mut removals = std::mem::take(&mut self.removed);
        removals.clear();
        let mut add = |entry: CutEntry, deltas: &mut Vec<CutDelta>| {
            deltas.push(CutDelta::Add(entry));
            entries.insert(entry.item, Slot { entry, stamp });
        };
        let has_entry = |n: u32, refined: &FastSet<u32>| {
            n == root || refined.contains(&bvh.nodes[n as usize].parent)
        };
        let aggregate = |n: u32| {
            let node = &bvh.nodes[n as usize];
            let solid_angle = worst_case_solid_angle(viewer, node.centre, node.radius, node.r_max);
            bvh.aggregate(n, node, solid_angle)
        };
        for &n in new.iter().filter(|n| !old.contains(n)) {
            if has_entry(n, old) {
                removals.push(CutItem::Aggregate(NodeId(n)));
            }
            let kids = bvh.kids(n);
            if bvh.nodes[n as usize].kind == NodeKind::Leaf {
                for &o in kids {
                    add(bvh.object_entry(viewer, o, n), deltas);
                }
            } else {
                for &c in kids.iter().filter(|c| !new.contains(c)) {
                    add(aggregate(c), deltas);
                }
            }
        }
        for &n in old.iter().filter(|n| !new.contains(n)) {
            if has_entry(n, new) {
                add(aggregate(n), deltas);
            }
            let kids = bvh.kids(n);
            if bvh.nodes[n as usize].kind == NodeKind::Leaf {
                removals.extend(kids.iter().map(|&o| CutItem::Object(ObjectId(o))));
            } else {
                removals.extend(
                    kids.iter()
                        .filter(|c| !old.contains(c))
                        .map(|&c| CutItem::Aggregate(NodeId(c))),
                );
            }
        }
        // The tree is unchanged, so every object is still in the world: all transient.
        for &item in &removals {
            let was = self.entries.remove(&item);
            debug_assert!(was.is_some(), "{item:?} was not in the cut");
            deltas.push(CutDelta::Remove {
                item,
                transient: true,
            });
        }
        self.removed = removals;
    }

    /// Diffs `fresh` against `entries`, updating `entries`: adds, reparents, then removes.
    fn diff(&mut self, bvh: &Bvh, deltas: &mut Vec<CutDelta>) {
        self.stamp = self.stamp.wrapping_add(1);
        let stamp = self.stamp;
        let mut reparents = std::mem::take(&mut self.removals);
        reparents.clear();
        for entry in &self.fresh {
            match self.entries.get_mut(&entry.item) {
                None => {
                    deltas.push(CutDelta::Add(*entry));
                    self.entries.insert(
                        entry.item,
                        Slot {
                            entry: *entry,
                            stamp,
                        },
                    );
                }
                Some(slot) => {
                    let old = &slot.entry;
                    if old.sphere != entry.sphere
                        || old.aabb != entry.aabb
                        || old.covers != entry.covers
                    {
                        deltas.push(CutDelta::Add(*entry));
                    } else if old.parent != entry.parent {
                        reparents.push(CutDelta::Reparent {
                            item: entry.item,
                            new_parent: entry.parent,
                        });
                    }
                    slot.entry = *entry;
                    slot.stamp = stamp;
                }
            }
        }
        deltas.append(&mut reparents);
        self.entries.retain(|item, slot| {
            if slot.stamp == stamp {
                return true;
            }
            let transient = match *item {
                CutItem::Object(o) => bvh.object(o).is_some(),
                CutItem::Aggregate(_) => true,
            };
            reparents.push(CutDelta::Remove {
                item: *item,
                transient,
            });
            false
        });
        deltas.append(&mut reparents);
        self.removals = reparents;
    }
}

/// An entry and the update that last produced it.
#[derive(Clone, Copy, Debug)]
struct Slot {
    entry: CutEntry,
    stamp: u32,
}

type FastMap<K, V> = HashMap<K, V, BuildHasherDefault<FastHasher>>;
type FastSet<K> = HashSet<K, BuildHasherDefault<FastHasher>>;

/// A multiplicative hash for small integer keys (node and object ids); the standard SipHash
/// would dominate an update's cost. Not resistant to adversarial keys, which ids are not.
#[derive(Clone, Copy, Debug, Default)]
struct FastHasher(u64);

impl FastHasher {
    #[inline]
    fn mix(&mut self, v: u64) {
        self.0 = (self.0.rotate_left(5) ^ v).wrapping_mul(0x51_7c_c1_b7_27_22_0a_95);
    }
}

impl Hasher for FastHasher {
    #[inline]
    fn finish(&self) -> u64 {
        self.0
    }

    #[inline]
    fn write(&mut self, bytes: &[u8]) {
        for &b in bytes {
            self.mix(u64::from(b));
        }
    }

    #[inline]
    fn write_u32(&mut self, v: u32) {
        self.mix(u64::from(v));
    }

    #[inline]
    fn write_u64(&mut self, v: u64) {
        self.mix(v);
    }

    #[inline]
    fn write_usize(&mut self, v: usize) {
        self.mix(v as u64);
    }

    #[inline]
    fn write_isize(&mut self, v: isize) {
        self.mix(v as u64);
    }
}
