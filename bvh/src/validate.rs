//! The invariant checker (house style: every core structure has one; obvhs
//! `Bvh2::validate`, etagere `check()`). It never panics, even on a corrupt deserialised tree.

use crate::bounds::Aabb;
use crate::tree::{Bvh, NodeKind, FREE_SLOT, NONE};
use crate::{InvalidTree, SHAPE_LEN, TEXTURE_LEN};

impl Bvh {
    /// Checks every invariant of the tree:
    /// - options valid; array lengths agree with the node and object counts;
    /// - the root has no parent and is a leaf or an internal node with at least 2 children;
    /// - parent/child links agree; every node is reached once from the root; every leaf is at
    ///   depth `height`; every non-root node has `min_children..=max_children` children;
    /// - every live object is held by exactly one leaf, the one it records;
    /// - counts and descriptor sums equal the objects below (the f32 sums within
    ///   `4 * count * f32::EPSILON` of the magnitudes summed, the most their rounding allows);
    /// - every object's centre lies in every ancestor's max-sphere bound, its radius is at
    ///   most the ancestor's `r_max` (which equals the largest radius below) and its sphere
    ///   lies in the ancestor's box (f32 tolerance: a few units in the last place of the
    ///   coordinates' magnitude);
    /// - the free lists hold exactly the free slots, once each;
    /// - every stored number is finite.
    pub fn validate(&self) -> Result<(), InvalidTree> {
        // Shapes of the arrays, before anything is indexed.
        self.options
            .validate()
            .map_err(|e| InvalidTree(e.to_string()))?;
        self.check_lengths()?;
        // Structure: links, fill, depth, and which objects each leaf holds.
        let reached = self.check_structure()?;
        // Totals and bounds against the objects below each node.
        self.check_totals_and_bounds()?;
        // Free lists.
        self.check_free_lists(&reached)
    }

    fn check_lengths(&self) -> Result<(), InvalidTree> {
        let nodes = self.nodes.len();
        let o = &self.objects;
        let slots = o.leaf.len();
        let ok = self.children.len() == nodes * self.stride()
            && self.shape_sum.len() == nodes * SHAPE_LEN
            && self.texture_sum.len() == nodes * TEXTURE_LEN
            && o.model.len() == slots
            && o.transform.len() == slots
            && o.sphere.len() == slots
            && o.shape.len() == slots * SHAPE_LEN
            && o.texture.len() == slots * TEXTURE_LEN;
        if !ok {
            return fail("array lengths disagree with the node and object counts");
        }
        if (self.root as usize) >= nodes {
            return fail(format!("root {} is out of range", self.root));
        }
        if !o.shape.iter().chain(&o.texture).all(|v| v.is_finite())
            || !o.sphere.iter().all(|s| s.is_valid())
            || !o.transform.iter().all(|t| t.is_finite())
        {
            return fail("an object has a non-finite descriptor, sphere or transform");
        }
        Ok(())
    }

    /// Walks from the root; returns which node slots were reached.
    fn check_structure(&self) -> Result<Vec<bool>, InvalidTree> {
        let opts = &self.options;
        let mut reached = vec![false; self.nodes.len()];
        let mut held = vec![false; self.objects.leaf.len()];
        let root = &self.nodes[self.root as usize];
        if root.parent != NONE {
            return fail("the root has a parent");
        }
        if root.kind == NodeKind::Internal && root.len < 2 {
            return fail("the internal root has fewer than 2 children");
        }
        let mut stack = vec![(self.root, 0u32)];
        while let Some((n, depth)) = stack.pop() {
            let node = &self.nodes[n as usize];
            if std::mem::replace(&mut reached[n as usize], true) {
                return fail(format!("node {n} is reached twice"));
            }
            let len = node.len as usize;
            if len > opts.max_children {
                return fail(format!("node {n} has {len} children"));
            }
            if n != self.root && len < opts.min_children {
                return fail(format!("non-root node {n} has {len} children"));
            }
            let finite = node.centre.is_finite()
                && node.radius.is_finite()
                && node.radius >= 0.0
                && node.r_max.is_finite()
                && node.aabb.min.is_finite()
                && node.aabb.max.is_finite();
            if !finite {
                return fail(format!("node {n} has a non-finite bound"));
            }
            let kids = self.kids(n);
            match node.kind {
                NodeKind::Free => return fail(format!("free node {n} is in the tree")),
                NodeKind::Leaf => {
                    if depth != self.height {
                        return fail(format!("leaf {n} at depth {depth}, not {}", self.height));
                    }
                    for &o in kids {
                        let Some(&leaf) = self.objects.leaf.get(o as usize) else {
                            return fail(format!("leaf {n} holds unknown object {o}"));
                        };
                        if leaf != n {
                            return fail(format!("object {o} is in leaf {n} but records {leaf}"));
                        }
                        if std::mem::replace(&mut held[o as usize], true) {
                            return fail(format!("object {o} is held twice"));
                        }
                    }
                }
                NodeKind::Internal => {
                    if depth >= self.height {
                        return fail(format!("internal node {n} at depth {depth}"));
                    }
                    for &c in kids {
                        let Some(child) = self.nodes.get(c as usize) else {
                            return fail(format!("node {n} has unknown child {c}"));
                        };
                        if child.parent != n {
                            return fail(format!(
                                "child {c} of {n} records parent {}",
                                child.parent
                            ));
                        }
                        stack.push((c, depth + 1));
                    }
                }
            }
        }
        // Every live object is held (no object is left unplaced).
        for (o, &leaf) in self.objects.leaf.iter().enumerate() {
            if leaf != FREE_SLOT && !held[o] {
                return fail(format!("live object {o} is in no leaf"));
            }
        }
        Ok(reached)
    }

    /// Recomputes every node's totals from its objects, checking bounds on the way.
    fn check_totals_and_bounds(&self) -> Result<(), InvalidTree> {
        let nodes = self.nodes.len();
        let mut count = vec![0u32; nodes];
        let mut radius = vec![0.0f32; nodes];
        let mut shape = vec![0.0f64; nodes * SHAPE_LEN];
        let mut texture = vec![0.0f64; nodes * TEXTURE_LEN];
        let mut magnitude = vec![0.0f64; nodes];
        for (o, &leaf) in self.objects.leaf.iter().enumerate() {
            if leaf == FREE_SLOT {
                continue;
            }
            let sphere = self.objects.sphere[o];
            let s = &self.objects.shape[o * SHAPE_LEN..(o + 1) * SHAPE_LEN];
            let t = &self.objects.texture[o * TEXTURE_LEN..(o + 1) * TEXTURE_LEN];
            let mag: f64 = s.iter().chain(t).map(|v| f64::from(v.abs())).sum();
            // Up the (already checked) parent links.
            let mut n = leaf;
            while n != NONE {
                let i = n as usize;
                let node = &self.nodes[i];
                let scale = node
                    .centre
                    .abs()
                    .max_element()
                    .max(sphere.centre.abs().max_element())
                    + node.radius
                    + sphere.radius;
                let tolerance = 1e-5 * scale + 1e-6;
                if (sphere.centre - node.centre).length() > node.radius + tolerance {
                    return fail(format!("object {o}'s centre is outside node {n}'s bound"));
                }
                if !node.aabb.contains(&Aabb::of_sphere(sphere), tolerance) {
                    return fail(format!("object {o}'s sphere is outside node {n}'s box"));
                }
                count[i] += 1;
                radius[i] = radius[i].max(sphere.radius);
                magnitude[i] += mag;
                for (d, &v) in shape[i * SHAPE_LEN..(i + 1) * SHAPE_LEN].iter_mut().zip(s) {
                    *d += f64::from(v);
                }
                for (d, &v) in texture[i * TEXTURE_LEN..(i + 1) * TEXTURE_LEN]
                    .iter_mut()
                    .zip(t)
                {
                    *d += f64::from(v);
                }
                n = node.parent;
            }
        }
        for (i, node) in self.nodes.iter().enumerate() {
            if node.kind == NodeKind::Free {
                continue;
            }
            if node.count != count[i] {
                return fail(format!(
                    "node {i} counts {} objects, holds {}",
                    node.count, count[i]
                ));
            }
            if node.r_max != radius[i] {
                return fail(format!(
                    "node {i} has r_max {} but the largest radius is {}",
                    node.r_max, radius[i]
                ));
            }
            // Each addition since the last recomputation rounds by at most EPSILON/2 of a
            // partial sum bounded by the magnitude; there are at most `count` of them, plus
            // one rounding per recomputation below (fewer than `count` nodes).
            let tolerance =
                4.0 * f64::from(count[i]) * f64::from(f32::EPSILON) * magnitude[i] + 1e-6;
            let sums = self.shape_sum[i * SHAPE_LEN..(i + 1) * SHAPE_LEN]
                .iter()
                .zip(&shape[i * SHAPE_LEN..(i + 1) * SHAPE_LEN])
                .chain(
                    self.texture_sum[i * TEXTURE_LEN..(i + 1) * TEXTURE_LEN]
                        .iter()
                        .zip(&texture[i * TEXTURE_LEN..(i + 1) * TEXTURE_LEN]),
                );
            for (&stored, &exact) in sums {
                // NaN is never within tolerance.
                let error = (f64::from(stored) - exact).abs();
                if error.is_nan() || error > tolerance {
                    return fail(format!(
                        "node {i}'s descriptor sum {stored} should be {exact}"
                    ));
                }
            }
        }
        if self.nodes[self.root as usize].count as usize != self.objects.live {
            return fail("the root does not count every live object");
        }
        Ok(())
    }

    fn check_free_lists(&self, reached: &[bool]) -> Result<(), InvalidTree> {
        // Nodes: the free list is exactly the unreached slots, each marked free.
        let mut listed = vec![false; self.nodes.len()];
        for &n in &self.free_nodes {
            let Some(node) = self.nodes.get(n as usize) else {
                return fail(format!("free list holds unknown node {n}"));
            };
            if node.kind != NodeKind::Free || reached[n as usize] {
                return fail(format!("free list holds live node {n}"));
            }
            if std::mem::replace(&mut listed[n as usize], true) {
                return fail(format!("free list holds node {n} twice"));
            }
        }
        if let Some(n) = (0..self.nodes.len()).find(|&n| !reached[n] && !listed[n]) {
            return fail(format!("node {n} is neither in the tree nor free"));
        }
        // Objects: the free list is exactly the free slots.
        let mut listed = vec![false; self.objects.leaf.len()];
        for &o in &self.objects.free {
            match self.objects.leaf.get(o as usize) {
                Some(&FREE_SLOT) => {}
                _ => return fail(format!("object free list holds live or unknown slot {o}")),
            }
            if std::mem::replace(&mut listed[o as usize], true) {
                return fail(format!("object free list holds slot {o} twice"));
            }
        }
        let free = self
            .objects
            .leaf
            .iter()
            .filter(|&&l| l == FREE_SLOT)
            .count();
        if free != self.objects.free.len() || self.objects.leaf.len() - free != self.objects.live {
            return fail("object free list and live count disagree with the slots");
        }
        Ok(())
    }
}

fn fail<T>(reason: impl Into<String>) -> Result<T, InvalidTree> {
    Err(InvalidTree(reason.into()))
}
