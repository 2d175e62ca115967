//! Removal with Guttman's CondenseTree (R-trees, 1984) and object moves.
//!
//! Remove takes the object out of its leaf and its ancestors' totals, then walks up: a
//! non-root node left with fewer than `min_children` children is dissolved and its objects
//! are reinserted by eq. 1 (Guttman reinserts whole entries at their level; reinserting
//! objects is simpler, keeps every leaf at one depth trivially, and underfull nodes are small).
//! A root with a single child is replaced by that child.
//!
//! Move policy: an object whose new centre still lies inside its leaf's max-sphere bound stays
//! in its leaf and only the bounds on its path are refitted (O(height * branching)). One that
//! leaves the bound is removed and reinserted by eq. 1. There is no slack beyond the bound on
//! purpose: a leaf's bound never grows through moves alone, so repeated small moves cannot
//! make it creep outward, and a reinsertion costs no more than an insert.

use crate::bounds::Sphere;
use crate::tree::{check_placement, Bvh, NodeKind, ObjectId, NONE, UNPLACED};
use crate::BvhError;
use glam::Affine3A;

impl Bvh {
    /// Removes an object. Its id becomes free for reuse.
    pub fn remove(&mut self, id: ObjectId) -> Result<(), BvhError> {
        self.touch();
        let o = self.live_object(id)?;
        self.unplace(o);
        self.objects.release(o);
        self.debug_validate();
        Ok(())
    }

    /// Moves an object: a new transform and world-space bounding sphere (see the module
    /// documentation for when it is reinserted).
    pub fn move_object(
        &mut self,
        id: ObjectId,
        transform: Affine3A,
        sphere: Sphere,
    ) -> Result<(), BvhError> {
        self.touch();
        // Refuse bad input before anything changes.
        let o = self.live_object(id)?;
        check_placement(&transform, &sphere)?;
        self.objects.transform[o as usize] = transform;
        self.objects.sphere[o as usize] = sphere;
        // Still inside its leaf's bound: refit the path. Outside: reinsert by eq. 1.
        let leaf = self.objects.leaf[o as usize];
        let node = &self.nodes[leaf as usize];
        if (sphere.centre - node.centre).length() <= node.radius {
            self.refit_upward(leaf);
        } else {
            self.unplace(o);
            self.place(o);
        }
        self.debug_validate();
        Ok(())
    }

    /// Takes a placed object out of the hierarchy (it stays stored, unplaced), condensing
    /// underfull nodes and reinserting their objects.
    ///
    /// The path's totals are recomputed from the children (added in f64) rather than
    /// decremented, so that removals never leave rounding drift behind: a running sum only
    /// ever accumulates additions, whose rounding is relative to the magnitudes summed (what
    /// `validate` allows for), and a node that shrinks from many objects to few holds sums
    /// as good as a fresh recomputation, not the leftovers of cancelled large values.
    pub(crate) fn unplace(&mut self, o: u32) {
        // Out of the leaf.
        let leaf = self.objects.leaf[o as usize];
        self.remove_kid(leaf, o);
        self.objects.leaf[o as usize] = UNPLACED;
        // Condense: dissolve underfull non-root nodes on the path, recompute the rest.
        let mut orphans = Vec::new();
        let mut n = leaf;
        while n != self.root {
            let parent = self.nodes[n as usize].parent;
            if (self.nodes[n as usize].len as usize) < self.options.min_children {
                self.dissolve(n, &mut orphans);
            } else {
                self.recompute_totals(n);
                self.refit(n);
            }
            n = parent;
        }
        self.recompute_totals(self.root);
        self.refit(self.root);
        // A root with one child hands over to it.
        while self.nodes[self.root as usize].kind == NodeKind::Internal
            && self.nodes[self.root as usize].len == 1
        {
            let old = self.root;
            self.root = self.kids(old)[0];
            self.nodes[self.root as usize].parent = NONE;
            self.free_node(old);
            self.height -= 1;
        }
        // Reinsert the orphans by eq. 1.
        for orphan in orphans {
            self.place(orphan);
        }
    }

    /// Detaches non-root node `n` from its parent (whose totals the caller recomputes), frees
    /// its subtree and appends its objects, now unplaced, to `orphans`.
    fn dissolve(&mut self, n: u32, orphans: &mut Vec<u32>) {
        let parent = self.nodes[n as usize].parent;
        self.remove_kid(parent, n);
        let mut stack = vec![n];
        while let Some(m) = stack.pop() {
            match self.nodes[m as usize].kind {
                NodeKind::Leaf => {
                    let start = m as usize * self.stride();
                    let len = self.nodes[m as usize].len as usize;
                    for &o in &self.children[start..start + len] {
                        self.objects.leaf[o as usize] = UNPLACED;
                        orphans.push(o);
                    }
                }
                _ => stack.extend_from_slice(self.kids(m)),
            }
            self.free_node(m);
        }
    }
}
