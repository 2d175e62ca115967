//! The similarity-aware node split (Azim et al. 2014, section 4.2), on Guttman's quadratic
//! R-tree split (1984).
//!
//! 1. Seeds: the pair of entries whose merged box wastes the most volume
//!    (`V(a + b) - V(a) - V(b)`) is Guttman's choice; the paper instead takes, among the
//!    pairs whose waste is within 20% of that maximum, the pair with the largest shape
//!    descriptor difference, so that dissimilar entries start the two groups.
//! 2. Distribution: each remaining entry joins the group minimising eq. 1 (the group's
//!    descriptor centroid and box volume), in Guttman's PickNext order (the entry with the
//!    strongest preference first). A group that needs every remaining entry to reach the
//!    minimum fill takes them all.
//!
//! An entry is an object (leaf split) or a child node (internal split); a child node enters
//! with its descriptor centroid, weighted by its object count in the group's centroid.

use crate::bounds::Aabb;
use crate::insert::descriptor_distance;
use crate::options::MAX_BRANCHING;
use crate::tree::{Bvh, NodeKind, NONE};
use crate::{SHAPE_LEN, TEXTURE_LEN};

/// The fraction of the maximum waste within which a seed pair may be chosen for its shape
/// difference instead (the paper's "within 20% of the maximum bounding volume waste").
const SEED_WASTE_TOLERANCE: f32 = 0.2;

impl Bvh {
    /// Splits overflowing node `n` in two: `n` keeps one group and a new sibling takes the
    /// other. The sibling joins `n`'s parent (which may overflow in turn; the caller walks
    /// up), or, when `n` is the root, a new root holding both grows the tree by one level.
    pub(crate) fn split(&mut self, n: u32) {
        // Gather the entries: box, descriptor centroid and weight of each child.
        let entries = self.split_entries(n);
        // Pick the seeds, then distribute the rest by eq. 1.
        let (a, b) = self.pick_seeds(&entries);
        let in_a = self.distribute(&entries, a, b);
        // Write the two groups back: `n` keeps group A, the sibling gets group B.
        let sibling = self.write_groups(n, &entries, &in_a);
        // Attach the sibling to the parent, or grow a new root.
        self.attach_sibling(n, sibling);
    }

    /// The entries of node `n`.
    fn split_entries(&self, n: u32) -> Entries {
        let kids = self.kids(n);
        let leaf = self.nodes[n as usize].kind == NodeKind::Leaf;
        let mut e = Entries {
            ids: kids.to_vec(),
            boxes: Vec::with_capacity(kids.len()),
            weight: Vec::with_capacity(kids.len()),
            shape: Vec::with_capacity(kids.len() * SHAPE_LEN),
            texture: Vec::with_capacity(kids.len() * TEXTURE_LEN),
        };
        for &k in kids {
            if leaf {
                e.boxes
                    .push(Aabb::of_sphere(self.objects.sphere[k as usize]));
                e.weight.push(1);
                e.shape.extend_from_slice(self.objects.shape(k));
                e.texture.extend_from_slice(self.objects.texture(k));
            } else {
                let node = &self.nodes[k as usize];
                let inv = 1.0 / node.count.max(1) as f32;
                e.boxes.push(node.aabb);
                e.weight.push(node.count);
                e.shape.extend(self.shape_sum(k).iter().map(|&s| s * inv));
                e.texture
                    .extend(self.texture_sum(k).iter().map(|&s| s * inv));
            }
        }
        e
    }

    /// The seed pair: the largest shape difference among the pairs whose waste is within
    /// [`SEED_WASTE_TOLERANCE`] of the most wasteful pair's.
    fn pick_seeds(&self, e: &Entries) -> (usize, usize) {
        let k = e.ids.len();
        // The most wasteful pair's waste.
        let waste = |i: usize, j: usize| {
            e.boxes[i].union(e.boxes[j]).volume() - e.boxes[i].volume() - e.boxes[j].volume()
        };
        let mut max_waste = f32::NEG_INFINITY;
        for i in 0..k {
            for j in i + 1..k {
                max_waste = max_waste.max(waste(i, j));
            }
        }
        // Among the pairs within tolerance of it, the largest shape difference (ties: more
        // waste). The tolerance is relative to |max waste| so that it also works when every
        // pair overlaps (negative waste).
        let threshold = max_waste - SEED_WASTE_TOLERANCE * max_waste.abs();
        let mut best = (f32::NEG_INFINITY, f32::NEG_INFINITY, 0, 1);
        for i in 0..k {
            for j in i + 1..k {
                let w = waste(i, j);
                if w < threshold {
                    continue;
                }
                let d = squared_distance(e.shape_of(i), e.shape_of(j));
                if (d, w) > (best.0, best.1) {
                    best = (d, w, i, j);
                }
            }
        }
        (best.2, best.3)
    }

    /// Assigns every entry to group A (`true`) or B by eq. 1, respecting the minimum fill.
    fn distribute(&self, e: &Entries, a: usize, b: usize) -> [bool; MAX_BRANCHING + 1] {
        let k = e.ids.len();
        let min = self.options.min_children;
        let mut groups = [Group::new(e, a), Group::new(e, b)];
        let mut in_a = [false; MAX_BRANCHING + 1];
        let mut done = [false; MAX_BRANCHING + 1];
        in_a[a] = true;
        done[a] = true;
        done[b] = true;
        let mut remaining = k - 2;
        while remaining > 0 {
            // A group that needs all the rest to reach the minimum fill takes them.
            let forced = (0..2).find(|&g| groups[g].size + remaining <= min);
            if let Some(g) = forced {
                for i in 0..k {
                    if !done[i] {
                        in_a[i] = g == 0;
                        done[i] = true;
                    }
                }
                break;
            }
            // PickNext: the entry whose two eq. 1 costs differ most goes first, to its
            // cheaper group (ties: the smaller group).
            let mut pick = (f32::NEG_INFINITY, 0, 0);
            for i in (0..k).filter(|&i| !done[i]) {
                let cost_a = self.group_cost(e, i, &groups[0], &groups[1]);
                let cost_b = self.group_cost(e, i, &groups[1], &groups[0]);
                let to = match cost_a.partial_cmp(&cost_b) {
                    Some(std::cmp::Ordering::Less) => 0,
                    Some(std::cmp::Ordering::Greater) => 1,
                    _ => usize::from(groups[1].size < groups[0].size),
                };
                let preference = (cost_a - cost_b).abs();
                if preference > pick.0 || pick.0 == f32::NEG_INFINITY {
                    pick = (preference, i, to);
                }
            }
            let (_, i, to) = pick;
            groups[to].add(e, i);
            in_a[i] = to == 0;
            done[i] = true;
            remaining -= 1;
        }
        in_a
    }

    /// Eq. 1 for entry `i` joining `group`, with `Vmax` taken over both groups' grown boxes.
    fn group_cost(&self, e: &Entries, i: usize, group: &Group, other: &Group) -> f32 {
        let opts = &self.options;
        let v_c = group.aabb.union(e.boxes[i]).volume();
        let v_other = other.aabb.union(e.boxes[i]).volume();
        let v_max = v_c.max(v_other);
        let volume = if v_max > 0.0 {
            (v_c - group.aabb.volume()) / v_max
        } else {
            0.0
        };
        let similarity = if opts.mu > 0.0 {
            descriptor_distance(
                opts,
                e.shape_of(i),
                e.texture_of(i),
                &group.shape,
                &group.texture,
                group.weight,
            )
        } else {
            0.0
        };
        opts.mu * similarity + (1.0 - opts.mu) * volume
    }

    /// Rewrites `n` with group A and a new sibling with group B; recomputes both nodes' totals
    /// and bounds and repoints the moved children. Returns the sibling.
    fn write_groups(&mut self, n: u32, e: &Entries, in_a: &[bool]) -> u32 {
        let kind = self.nodes[n as usize].kind;
        let mut group_a = [0u32; MAX_BRANCHING + 1];
        let mut group_b = [0u32; MAX_BRANCHING + 1];
        let (mut len_a, mut len_b) = (0, 0);
        for (i, &id) in e.ids.iter().enumerate() {
            if in_a[i] {
                group_a[len_a] = id;
                len_a += 1;
            } else {
                group_b[len_b] = id;
                len_b += 1;
            }
        }
        let sibling = self.alloc_node(kind, NONE);
        self.set_kids(n, &group_a[..len_a]);
        self.set_kids(sibling, &group_b[..len_b]);
        for &id in &group_b[..len_b] {
            match kind {
                NodeKind::Leaf => self.objects.leaf[id as usize] = sibling,
                _ => self.nodes[id as usize].parent = sibling,
            }
        }
        for half in [n, sibling] {
            self.recompute_totals(half);
            self.refit(half);
        }
        sibling
    }

    /// Hangs `sibling` beside `n`: under `n`'s parent, or under a new root.
    fn attach_sibling(&mut self, n: u32, sibling: u32) {
        let parent = self.nodes[n as usize].parent;
        if parent != NONE {
            self.nodes[sibling as usize].parent = parent;
            self.push_kid(parent, sibling);
            return;
        }
        let root = self.alloc_node(NodeKind::Internal, NONE);
        self.set_kids(root, &[n, sibling]);
        self.nodes[n as usize].parent = root;
        self.nodes[sibling as usize].parent = root;
        self.recompute_totals(root);
        self.refit(root);
        self.root = root;
        self.height += 1;
    }
}

/// The children of a node being split, with what eq. 1 needs of each.
struct Entries {
    /// Object ids (leaf) or node ids (internal node).
    ids: Vec<u32>,
    /// Boxes of the object spheres.
    boxes: Vec<Aabb>,
    /// Objects each entry stands for (1 for an object).
    weight: Vec<u32>,
    /// Descriptor centroids, `SHAPE_LEN` per entry.
    shape: Vec<f32>,
    /// Texture centroids, `TEXTURE_LEN` per entry.
    texture: Vec<f32>,
}

impl Entries {
    fn shape_of(&self, i: usize) -> &[f32] {
        &self.shape[i * SHAPE_LEN..(i + 1) * SHAPE_LEN]
    }

    fn texture_of(&self, i: usize) -> &[f32] {
        &self.texture[i * TEXTURE_LEN..(i + 1) * TEXTURE_LEN]
    }
}

/// A group being formed: its box and the object-weighted descriptor sums of its entries.
struct Group {
    aabb: Aabb,
    shape: [f32; SHAPE_LEN],
    texture: [f32; TEXTURE_LEN],
    weight: u32,
    size: usize,
}

impl Group {
    fn new(e: &Entries, seed: usize) -> Self {
        let mut g = Self {
            aabb: Aabb::EMPTY,
            shape: [0.0; SHAPE_LEN],
            texture: [0.0; TEXTURE_LEN],
            weight: 0,
            size: 0,
        };
        g.add(e, seed);
        g
    }

    fn add(&mut self, e: &Entries, i: usize) {
        let w = e.weight[i] as f32;
        self.aabb = self.aabb.union(e.boxes[i]);
        for (s, &c) in self.shape.iter_mut().zip(e.shape_of(i)) {
            *s += w * c;
        }
        for (s, &c) in self.texture.iter_mut().zip(e.texture_of(i)) {
            *s += w * c;
        }
        self.weight += e.weight[i];
        self.size += 1;
    }
}

fn squared_distance(a: &[f32], b: &[f32]) -> f32 {
    a.iter().zip(b).map(|(x, y)| (x - y) * (x - y)).sum()
}
