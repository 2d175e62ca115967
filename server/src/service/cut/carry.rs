//! Carrying a held plan to a new eye (a stream's view that may leave its cut as it was):
//! [`Plan::carry_to`] answers, without planning, whether planning again there with the plan
//! held ([`super::plan_after`]) would make the same cut, and if so makes the plan the one
//! planning again would make.
//!
//! Three checks, cheapest first:
//! - the node decisions ([`super::Decisions::holds`]): the worst-case solid angles of the
//!   nodes refinement took, refused and left (core paper eq. 3), and, with only the entry
//!   budget, a frontier node that grew past the refused one and is refused in its place;
//! - every level of detail the plan consulted, against its [`LevelBand`]: one distance per
//!   object, choosing again only outside the band, and within [`BAND_REACH`] of the eye
//!   where all were last checked only the bands that were near an edge there
//!   ([`BandWatch`]);
//! - where some level moved, whether it reaches the wire: a model's shared level
//!   ([`super::share_levels`]), the weighing of instances (bottom-up, exact) and the assets
//!   `share_models` found in the cut. Under a byte, draw-call or triangle budget any moved
//!   level plans again.

use super::*;

impl Plan {
    /// Carries this plan to `eye` if planning again there with it held ([`plan_after`]), on
    /// the tree it was made on and with the rest of its view, gives the same cut: its
    /// [`Decisions`] hold there, the aggregates the planner weighed against their objects
    /// weigh the same, and every model keeps the level its objects share. The objects' own
    /// levels (what the next step's hysteresis starts from) become those planning again
    /// would give, so the plan is then the one planning again makes. False otherwise, and the
    /// plan draws the same (its level bands and their watch may have been worked out).
    ///
    /// An object's own level matters to the wire only through its model's shared level
    /// ([`share_levels`]) and the weighing of instances, so with 60,000 objects in a cut
    /// (instances of a reused world) a small step that moves a few of them across a level
    /// keeps the cut. Under a byte, draw-call or triangle budget every level counts towards
    /// where refinement stops, and any change replans; a plan that went on past a refusal
    /// of such a budget ([`Plan::skipped`]) or whose levels were coarsened because one bound
    /// ([`Plan::coarsened`]) always does.
    pub fn carry_to(&mut self, tree: &horizon_world::Tree, eye: [f64; 3]) -> bool {
        if self.coarsened.is_some() {
            // Its levels were chosen by comparing plans at several coarsenings: plan again.
            return false;
        }
        // Decisions that went on past a refusal never hold (`Decisions::holds`).
        let Some(refused) = self.decisions.holds(tree, eye) else {
            return false;
        };
        let eye = eye_of(eye);
        let outside = self.levels_outside_bands(tree, eye);
        if outside.iter().any(|&(_, level)| level == UNCHOSEN) {
            // An object the tree lacks: not the tree the plan was made on.
            return false;
        }
        let bands = &self.decisions.bands;
        if outside.iter().any(|&(i, level)| level != bands[i].level) {
            if self.decisions.ordered {
                // Some level changed, and under a byte, draw-call or triangle budget any
                // level may move where refinement stops (also one charged for the refusal
                // alone).
                return false;
            }
            let Some((chosen, changed)) = self.levels_at(tree, eye, &outside) else {
                return false;
            };
            if changed {
                self.take_levels(&chosen);
            }
            // Planning again would consult these levels; the bands follow them.
            self.follow_levels(tree, &chosen);
        }
        if let Some(i) = refused {
            self.decisions.refuse_instead(i);
        }
        true
    }

    /// Every consulted level whose object is outside its [`LevelBand`] at `eye`, by its
    /// band's index, with the level planning again there would consult (chosen again, held
    /// as the band is); every other consulted level stays as it is. The bands are made here
    /// if the plan has none yet. Within [`BAND_REACH`] of where every band was last
    /// checked, only the bands its [`BandWatch`] names are.
    fn levels_outside_bands(&mut self, tree: &horizon_world::Tree, eye: Vec3) -> Vec<(usize, u8)> {
        if self.decisions.consulted.is_empty() {
            return Vec::new();
        }
        if self.decisions.bands.is_empty() {
            self.decisions.bands = self.level_bands(tree);
            self.decisions.watch = None;
        }
        let bands = &self.decisions.bands;
        let distance = |b: &LevelBand| (b.centre - eye).length() - b.radius;
        let inside = |b: &LevelBand, d: f32| d > b.lo && d < b.hi;
        let mut outside: Vec<usize> = Vec::new();
        match &self.decisions.watch {
            Some(w) if w.covers(eye) => {
                outside.extend(
                    w.near
                        .iter()
                        .map(|&i| i as usize)
                        .filter(|&i| !inside(&bands[i], distance(&bands[i]))),
                );
            }
            _ => {
                let mut near = Vec::new();
                for (i, b) in bands.iter().enumerate() {
                    let d = distance(b);
                    if !inside(b, d) {
                        outside.push(i);
                    }
                    // Named unless surely inside by the reach and the rounding of `d` (NaN
                    // compares false: named).
                    let reach = BAND_REACH + ROUNDING * (d.abs() + b.radius);
                    if !(d - b.lo >= reach && b.hi - d >= reach) {
                        near.push(i as u32);
                    }
                }
                self.decisions.watch = Some(BandWatch { eye, near });
            }
        }
        let pixel_angle = pixel_angle(&self.view);
        let error = self.view.max_pixel_error;
        let bvh = &tree.bvh;
        outside
            .into_iter()
            .map(|i| {
                let b = &bands[i];
                let level = bvh.object(b.object).map_or(UNCHOSEN, |r| {
                    let held = (b.held != UNCHOSEN).then_some(b.held);
                    level_at(&self.models, &r, eye, pixel_angle, error, held)
                });
                (i, level)
            })
            .collect()
    }

    /// The band of every consulted level: its object's own level is held where the object
    /// is in the cut (as planning again with this plan held anchors it), chosen afresh
    /// elsewhere.
    fn level_bands(&self, tree: &horizon_world::Tree) -> Vec<LevelBand> {
        let held = self.decisions.own_levels(tree.bvh.object_slots());
        self.decisions
            .consulted
            .iter()
            .map(|&(o, level)| {
                let held = held.get(o.0 as usize).copied().unwrap_or(UNCHOSEN);
                self.band(tree, o, level, held)
            })
            .collect()
    }

    /// Where `o` keeps `level`, held at `held` ([`UNCHOSEN`]: chosen afresh); an empty band
    /// for an object the tree lacks.
    fn band(&self, tree: &horizon_world::Tree, o: ObjectId, level: u8, held: u8) -> LevelBand {
        let mut band = LevelBand {
            object: o,
            centre: Vec3::ZERO,
            radius: 0.0,
            lo: f32::INFINITY,
            hi: f32::NEG_INFINITY,
            level,
            held,
        };
        let Some(r) = tree.bvh.object(o) else {
            return band;
        };
        let sphere = r.sphere();
        (band.centre, band.radius) = (sphere.centre, sphere.radius);
        if let Some(m) = self.models.get(r.model() as usize).and_then(Option::as_ref) {
            let scale = horizon_mesh::transform::max_axis_scale(&r.transform());
            let anchor = (held != UNCHOSEN).then_some(held);
            let pixel_angle = pixel_angle(&self.view);
            let error = self.view.max_pixel_error as f32;
            (band.lo, band.hi) = m.band(level, anchor, scale, pixel_angle, error);
        }
        band
    }

    /// Makes the consulted levels those at `chosen`, which the carried plan now holds (its
    /// objects' own levels taken from it): a band whose level moved is made again, and all
    /// of them if the chooser looked at objects the plan had not consulted.
    fn follow_levels(&mut self, tree: &horizon_world::Tree, chosen: &[std::cell::Cell<u8>]) {
        let consulted = consulted(chosen);
        if consulted.len() != self.decisions.bands.len() {
            self.decisions.consulted = consulted;
            self.decisions.bands.clear();
            self.decisions.watch = None;
            return;
        }
        for (i, &(o, level)) in consulted.iter().enumerate() {
            let b = self.decisions.bands[i];
            debug_assert_eq!(b.object, o, "bands follow the consulted levels");
            if b.level != level {
                // An object in the cut is held at its own level, which is now this one.
                let held = if b.held == UNCHOSEN { UNCHOSEN } else { level };
                // Only a band the eye left moves, and the watch names every such band, so
                // it checks this one at every carry until all are checked again.
                self.decisions.bands[i] = self.band(tree, o, level, held);
            }
        }
        self.decisions.consulted = consulted;
    }

    /// The objects' own levels planning again at `eye` would choose, by tree id, and whether
    /// any differs from this plan's; none if planning again would make another cut. Only
    /// without a byte, draw-call or triangle budget, where levels reach the wire through
    /// shared levels, the weighing of instances and `share_models` alone.
    fn levels_at(
        &self,
        tree: &horizon_world::Tree,
        eye: Vec3,
        outside: &[(usize, u8)],
    ) -> Option<(Vec<std::cell::Cell<u8>>, bool)> {
        let bvh = &tree.bvh;
        let pixel_angle = pixel_angle(&self.view);
        let max_pixel_error = self.view.max_pixel_error;
        // Every consulted level, as its band or its choice outside it gives it: held at its
        // own level for an object in the cut, chosen afresh for any other (as the chooser
        // below would choose it).
        let chosen = vec![std::cell::Cell::new(UNCHOSEN); bvh.object_slots()];
        for b in &self.decisions.bands {
            chosen.get(b.object.0 as usize)?.set(b.level);
        }
        for &(i, level) in outside {
            chosen
                .get(self.decisions.bands[i].object.0 as usize)?
                .set(level);
        }
        // The (model, level) pairs whose objects changed: the assets `share_models` found
        // in the cut may differ in these alone.
        let mut touched: HashSet<(u64, u8)> = HashSet::new();
        for &(o, level) in &self.decisions.levels {
            let r = bvh.object(o)?;
            let slot = chosen.get(o.0 as usize)?;
            if slot.get() == UNCHOSEN {
                // Consulted levels include every object in the cut; this only if not.
                let now = level_at(
                    &self.models,
                    &r,
                    eye,
                    pixel_angle,
                    max_pixel_error,
                    Some(level),
                );
                slot.set(now);
            }
            let now = slot.get();
            if now != level {
                touched.insert((r.model(), level));
                touched.insert((r.model(), now));
            }
        }
        // Objects outside the cut have no held level: the chooser picks theirs afresh, as
        // the planner would.
        let unheld = HeldLevels::None;
        let chooser = LevelChooser {
            tree,
            models: &self.models,
            eye,
            pixel_angle,
            max_pixel_error,
            held: &unheld,
            chosen: &chosen,
        };
        let examined_hold = self.decisions.examined.iter().all(|&(o, level)| {
            chooser.of(o) == level
                && (touched.is_empty()
                    || bvh
                        .object(o)
                        .is_some_and(|r| !touched.contains(&(r.model(), level))))
        });
        let instances = &self.decisions.instances;
        let weighed_hold = examined_hold
            && (instances.is_empty() || {
                let weighed: HashSet<NodeId> = instances.iter().map(|&(n, _)| n).collect();
                let now = chooser.instances_win_all(bvh.root(), &weighed, &self.decisions.nodes);
                instances
                    .iter()
                    .all(|&(node, won)| now.get(&node).copied().unwrap_or(false) == won)
            });
        if !weighed_hold {
            return None;
        }
        if !touched.is_empty() && !self.shared_levels_hold(tree, &chosen, &touched) {
            return None;
        }
        Some((chosen, !touched.is_empty()))
    }

    /// Whether every model of `touched` keeps its shared level with its objects' own levels
    /// at `chosen` ([`share_levels`], this plan's levels held).
    fn shared_levels_hold(
        &self,
        tree: &horizon_world::Tree,
        chosen: &[std::cell::Cell<u8>],
        touched: &HashSet<(u64, u8)>,
    ) -> bool {
        let models: HashSet<u64> = touched.iter().map(|&(m, _)| m).collect();
        let mut finest: HashMap<u64, u8> = HashMap::new();
        for &(o, _) in &self.decisions.levels {
            let Some(model) = tree.bvh.object(o).map(|r| r.model()) else {
                return false;
            };
            if models.contains(&model) {
                let now = chosen.get(o.0 as usize).map_or(0, std::cell::Cell::get);
                let f = finest.entry(model).or_insert(now);
                *f = (*f).min(now);
            }
        }
        let held = self.model_levels();
        finest.iter().all(|(model, &f)| {
            held.get(model)
                .is_some_and(|&h| shared_level(f, Some(h)) == h)
        })
    }

    /// Takes the objects' own levels at `chosen` (tree ids) into the plan.
    fn take_levels(&mut self, chosen: &[std::cell::Cell<u8>]) {
        let now = |o: ObjectId| {
            chosen
                .get(o.0 as usize)
                .map(std::cell::Cell::get)
                .filter(|&l| l != UNCHOSEN)
        };
        for (o, level) in &mut self.decisions.levels {
            if let Some(l) = now(*o) {
                *level = l;
            }
        }
        for p in &mut self.items {
            match &mut p.what {
                Drawn::Object { tree, needed, .. } => {
                    if let Some(l) = now(*tree) {
                        *needed = l;
                    }
                }
                Drawn::Instances(instances)
                    if instances
                        .iter()
                        .any(|i| now(i.tree).is_some_and(|l| l != i.needed)) =>
                {
                    for i in instances_mut(instances) {
                        if let Some(l) = now(i.tree) {
                            i.needed = l;
                        }
                    }
                }
                _ => {}
            }
        }
    }
}

/// Every level a planner's chooser holds, by tree id.
pub(super) fn consulted(chosen: &[std::cell::Cell<u8>]) -> Vec<(ObjectId, u8)> {
    chosen
        .iter()
        .enumerate()
        .filter(|(_, l)| l.get() != UNCHOSEN)
        .map(|(o, l)| (ObjectId(o as u32), l.get()))
        .collect()
}

/// The distances from an eye to an object's sphere at which its level of detail is surely
/// `level` ([`ModelAsset::band`]): a plan carried to a new eye checks these instead of
/// choosing 60,000 levels again, and chooses again only outside them.
#[derive(Clone, Copy, Debug)]
pub(super) struct LevelBand {
    object: ObjectId,
    centre: Vec3,
    radius: f32,
    /// The level is `level` at distances strictly between these.
    lo: f32,
    hi: f32,
    level: u8,
    /// The level planning again holds the object to ([`UNCHOSEN`]: none).
    held: u8,
}

/// How far (world units) an eye may move from where every [`LevelBand`] was last checked
/// before all are checked again; until then a carry checks only those that were within
/// this of an edge there. A walk at 1.4 m/s and 10 views a second checks all every 14 views.
pub(super) const BAND_REACH: f32 = 2.0;

/// Far above the relative f32 rounding of the distances a [`BandWatch`] compares (about
/// 1e-7 of each): added, times each distance, to the reach.
const ROUNDING: f32 = 1e-5;

/// Where every band was last checked, and which were within [`BAND_REACH`] of an edge
/// there: a band's distance moves by at most what the eye moves, so with the eye less than
/// `BAND_REACH` from `eye` every other band holds. A band made again (its level moved) was
/// outside, so it is one of those named.
#[derive(Clone, Debug)]
pub(super) struct BandWatch {
    eye: Vec3,
    near: Vec<u32>,
}

impl BandWatch {
    /// Whether a carry to `eye` may check only the bands named.
    fn covers(&self, eye: Vec3) -> bool {
        let moved = (eye - self.eye).length();
        moved + ROUNDING * (eye.length() + self.eye.length()) < BAND_REACH
    }
}
