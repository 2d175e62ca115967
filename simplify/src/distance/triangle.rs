//! Exact closest point on a triangle (Ericson, "Real-Time Collision Detection", 2005, section
//! 5.1.5: the Voronoi-region method) and on a segment (section 5.1.2), in f64.
//!
//! Degenerate triangles (a point, a segment, or a sliver too thin for the region tests to be
//! trusted) are handled as the union of their three edges, which is what they are as surfaces.

use glam::DVec3;

/// A triangle whose squared normal length is below this fraction of its squared longest edge,
/// squared, is treated as its three edges. The threshold keeps the region tests well away from
/// round-off (their relative error grows like `eps / sin(angle)`), and the distance error of the
/// fallback is at most the triangle's height, here below `1e-8` times its longest edge.
const DEGENERATE_SIN2: f64 = 1e-16;

/// The point of segment `ab` closest to `p`. A zero-length segment is the point `a`.
pub fn closest_point_on_segment(p: DVec3, a: DVec3, b: DVec3) -> DVec3 {
    let ab = b - a;
    let len2 = ab.length_squared();
    if len2 <= 0.0 {
        return a;
    }
    let t = ((p - a).dot(ab) / len2).clamp(0.0, 1.0);
    a + ab * t
}

/// The point of triangle `abc` (the filled triangle, edges and vertices included) closest to
/// `p`. Exact up to f64 round-off for any input, degenerate triangles included.
pub fn closest_point_on_triangle(p: DVec3, a: DVec3, b: DVec3, c: DVec3) -> DVec3 {
    closest_on_triangle(p, a, b, c).0
}

/// The closest point of triangle `abc` to `p` and its squared distance. In the face region the
/// distance is measured along the normal, `((p - a) . n)^2 / |n|^2`, which carries no in-plane
/// round-off: a point sampled on a coplanar triangle comes out at exactly the planes' offset (0
/// for identical axis-aligned surfaces, 0.5 for a copy moved 0.5 along an axis).
pub fn closest_on_triangle(p: DVec3, a: DVec3, b: DVec3, c: DVec3) -> (DVec3, f64) {
    let q = |q: DVec3| (q, q.distance_squared(p));
    let ab = b - a;
    let ac = c - a;
    let bc = c - b;
    let longest2 = ab
        .length_squared()
        .max(ac.length_squared())
        .max(bc.length_squared());
    let n = ab.cross(ac);
    let n2 = n.length_squared();
    if n2 <= DEGENERATE_SIN2 * longest2 * longest2 {
        return q(closest_on_edges(p, a, b, c));
    }

    // Vertex region A.
    let ap = p - a;
    let d1 = ab.dot(ap);
    let d2 = ac.dot(ap);
    if d1 <= 0.0 && d2 <= 0.0 {
        return q(a);
    }
    // Vertex region B.
    let bp = p - b;
    let d3 = ab.dot(bp);
    let d4 = ac.dot(bp);
    if d3 >= 0.0 && d4 <= d3 {
        return q(b);
    }
    // Edge region AB.
    let vc = d1 * d4 - d3 * d2;
    if vc <= 0.0 && d1 >= 0.0 && d3 <= 0.0 {
        return q(a + ab * (d1 / (d1 - d3)));
    }
    // Vertex region C.
    let cp = p - c;
    let d5 = ab.dot(cp);
    let d6 = ac.dot(cp);
    if d6 >= 0.0 && d5 <= d6 {
        return q(c);
    }
    // Edge region AC.
    let vb = d5 * d2 - d1 * d6;
    if vb <= 0.0 && d2 >= 0.0 && d6 <= 0.0 {
        return q(a + ac * (d2 / (d2 - d6)));
    }
    // Edge region BC.
    let va = d3 * d6 - d5 * d4;
    let e4 = d4 - d3;
    let e5 = d5 - d6;
    if va <= 0.0 && e4 >= 0.0 && e5 >= 0.0 {
        return q(b + bc * (e4 / (e4 + e5)));
    }
    // Face region: the projection onto the plane. (Ericson interpolates with the barycentric
    // coordinates (va, vb, vc) / (va + vb + vc); the projection is the same point, and its
    // distance along the normal avoids in-plane round-off.)
    if va + vb + vc <= 0.0 {
        // Unreachable for a triangle that passed the degeneracy test; kept as a safe net.
        return q(closest_on_edges(p, a, b, c));
    }
    let s = ap.dot(n);
    (p - n * (s / n2), s * s / n2)
}

/// The closest point on the three edges of `abc`.
fn closest_on_edges(p: DVec3, a: DVec3, b: DVec3, c: DVec3) -> DVec3 {
    let mut best = closest_point_on_segment(p, a, b);
    let mut best_d2 = best.distance_squared(p);
    for (s, e) in [(b, c), (c, a)] {
        let q = closest_point_on_segment(p, s, e);
        let d2 = q.distance_squared(p);
        if d2 < best_d2 {
            best = q;
            best_d2 = d2;
        }
    }
    best
}
