//! Orthoviews (Chaudhuri et al. 2009): a cube seen from every canonical direction, compositing
//! against rendering, bounds, encoding, and degenerate nodes.

#![allow(clippy::unwrap_used)]

use std::sync::Arc;

use glam::{Affine3A, Vec3};
use horizon_impostor::orthoview::{from_octahedral, octahedral, DEPTH_THRESHOLD};
use horizon_impostor::{canonical_directions, resolution, Orthoview, PreparedMesh, SceneBuilder};
use horizon_mesh::{Aabb, Instance, InstancedMesh, Submesh};

/// An axis-aligned box from `min` to `max`, outward winding.
fn cuboid(min: Vec3, max: Vec3) -> InstancedMesh {
    let positions: Vec<Vec3> = (0..8)
        .map(|i| {
            Vec3::new(
                if i & 1 == 0 { min.x } else { max.x },
                if i & 2 == 0 { min.y } else { max.y },
                if i & 4 == 0 { min.z } else { max.z },
            )
        })
        .collect();
    let indices = vec![
        0, 2, 1, 1, 2, 3, 4, 5, 6, 5, 7, 6, 0, 1, 4, 1, 5, 4, 2, 6, 3, 3, 6, 7, 0, 4, 2, 2, 4, 6,
        1, 3, 5, 3, 7, 5,
    ];
    InstancedMesh {
        submeshes: vec![Submesh {
            positions,
            indices,
            ..Submesh::default()
        }],
        instances: vec![Instance {
            submesh: 0,
            transform: Affine3A::IDENTITY,
        }],
        ..InstancedMesh::default()
    }
}

fn scene(meshes: &[InstancedMesh]) -> horizon_impostor::Scene {
    let mut b = SceneBuilder::default();
    for m in meshes {
        b.add(&Arc::new(PreparedMesh::new(m)), &Affine3A::IDENTITY);
    }
    b.build()
}

fn aabb(min: Vec3, max: Vec3) -> Aabb {
    Aabb { min, max }
}

/// Distance from `p` to the surface of the box.
fn to_surface(p: Vec3, min: Vec3, max: Vec3) -> f32 {
    let inside = p.cmpge(min).all() && p.cmple(max).all();
    if inside {
        (p - min).min(max - p).min_element()
    } else {
        (p - p.clamp(min, max)).length()
    }
}

#[test]
fn a_cube_from_every_canonical_direction_has_known_depth_and_normals() {
    let (min, max) = (Vec3::ZERO, Vec3::ONE);
    let s = scene(&[cuboid(min, max)]);
    let dirs = canonical_directions();
    assert_eq!(dirs.len(), 26);
    for d in dirs {
        let view = Orthoview::render(&s, &aabb(min, max), d, 32);
        view.validate().unwrap();
        let dir = Vec3::new(f32::from(d[0]), f32::from(d[1]), f32::from(d[2])).normalize();
        let pixel = view.pixel_size();
        let axis = d.iter().filter(|&&c| c != 0).count() == 1;
        assert!(view.covered() > 0, "{d:?} sees nothing");
        for y in 0..view.height {
            for x in 0..view.width {
                let Some(p) = view.point(x, y) else {
                    // Along an axis the cube's face fills the whole image.
                    assert!(!axis, "{d:?}: pixel ({x}, {y}) is empty");
                    continue;
                };
                assert!(
                    to_surface(p, min, max) <= pixel,
                    "{d:?}: {p} is off the cube"
                );
                let n = view.normal_at(x, y);
                assert!(n.dot(dir) < 0.0, "{d:?}: a normal {n} faces away");
                if axis {
                    // The face towards the viewer, at depth 0.
                    assert!((n + dir).length() < 0.02, "{d:?}: normal {n}");
                    let face = if dir.max_element() > 0.0 { min } else { max };
                    assert!((p.dot(dir) - face.dot(dir)).abs() <= 1e-3, "{d:?}: depth");
                }
            }
        }
        // Along a corner diagonal such as (1, 1, 1) three faces show, a hexagon inside its
        // bounding rectangle; along an axis or an edge diagonal the cube fills the rectangle.
        let share = view.covered() as f32 / (view.width * view.height) as f32;
        if d.iter().all(|&c| c != 0) {
            assert!(share > 0.4 && share < 1.0, "{d:?}: {share}");
        } else {
            assert_eq!(share, 1.0, "{d:?}");
        }
    }
}

#[test]
fn compositing_two_children_equals_rendering_their_union() {
    let a = (Vec3::ZERO, Vec3::ONE);
    let b = (Vec3::new(1.0, 0.0, 0.0), Vec3::new(2.0, 0.7, 1.0));
    let (sa, sb) = (scene(&[cuboid(a.0, a.1)]), scene(&[cuboid(b.0, b.1)]));
    let union = scene(&[cuboid(a.0, a.1), cuboid(b.0, b.1)]);
    let parent = aabb(Vec3::ZERO, Vec3::new(2.0, 1.0, 1.0));
    let q = 32;
    for d in canonical_directions() {
        let ca = Orthoview::render(&sa, &aabb(a.0, a.1), d, q);
        let cb = Orthoview::render(&sb, &aabb(b.0, b.1), d, q);
        let composited = Orthoview::composite(&[&ca, &cb], &parent, d, q);
        composited.validate().unwrap();
        let rendered = Orthoview::render(&union, &parent, d, q);
        assert_eq!(
            (composited.width, composited.height),
            (rendered.width, rendered.height)
        );
        let pixel = rendered.pixel_size();
        let (mut both, mut close, mut only) = (0, 0, 0);
        for y in 0..rendered.height {
            for x in 0..rendered.width {
                match (composited.point(x, y), rendered.point(x, y)) {
                    (Some(p), Some(r)) => {
                        both += 1;
                        let dir = Vec3::new(f32::from(d[0]), f32::from(d[1]), f32::from(d[2]))
                            .normalize();
                        if (p - r).dot(dir).abs() <= DEPTH_THRESHOLD * pixel {
                            close += 1;
                        }
                    }
                    (None, None) => {}
                    _ => only += 1,
                }
            }
        }
        // Silhouettes may differ by a pixel's edge; depths agree within the threshold.
        assert!(both > 0, "{d:?}");
        assert!(
            close as f32 >= 0.95 * both as f32,
            "{d:?}: {close} of {both} close"
        );
        let edge = 2 * (rendered.width + rendered.height) as usize * 2;
        assert!(
            only <= edge,
            "{d:?}: {only} pixels covered by one and not the other"
        );
    }
}

/// A hierarchy of composites, as a rebuild makes it up a tree: at every level each node's
/// children are composited into a box holding theirs and a little more, at the same q. Every
/// level's views keep their samples inside their box (`validate`, which reading a stored
/// view back runs): the rounding of one level must not carry into the next.
#[test]
fn composites_of_composites_keep_their_samples_inside_their_boxes() {
    let mut rng = horizon_mesh::rng::Rng::new(7);
    // A flat, wide world, as a city's upper nodes are; leaves of a few boxes each.
    let mut leaves: Vec<(Aabb, horizon_impostor::Scene)> = Vec::new();
    for i in 0..16 {
        let x0 = i as f32 * 40.0;
        let boxes: Vec<(Vec3, Vec3)> = (0..3)
            .map(|_| {
                let min = Vec3::new(
                    x0 + rng.range(0.0, 30.0),
                    rng.range(-0.2, 0.0),
                    rng.range(0.0, 300.0),
                );
                (
                    min,
                    min + Vec3::new(
                        rng.range(1.0, 10.0),
                        rng.range(0.1, 5.0),
                        rng.range(1.0, 10.0),
                    ),
                )
            })
            .collect();
        let bounds = boxes
            .iter()
            .fold(Aabb::EMPTY, |b, &(lo, hi)| b.union(&aabb(lo, hi)));
        let meshes: Vec<InstancedMesh> = boxes.iter().map(|&(lo, hi)| cuboid(lo, hi)).collect();
        leaves.push((bounds, scene(&meshes)));
    }
    let q = 16;
    for d in canonical_directions() {
        let mut level: Vec<Orthoview> = leaves
            .iter()
            .map(|(b, s)| Orthoview::render(s, b, d, q))
            .collect();
        let mut depth = 0;
        while level.len() > 1 {
            depth += 1;
            level = level
                .chunks(2)
                .map(|pair| {
                    let grown = pair.iter().fold(Aabb::EMPTY, |b, v| b.union(&v.bounds));
                    let parent = aabb(grown.min - Vec3::splat(0.37), grown.max);
                    let views: Vec<&Orthoview> = pair.iter().collect();
                    let view = Orthoview::composite(&views, &parent, d, q);
                    if let Err(e) = view.validate() {
                        panic!("{d:?}, level {depth}: {e}");
                    }
                    // A pixel's sample is its centre at its depth: within half a pixel's
                    // diagonal of the box, at every level.
                    let b = view.bounds;
                    for y in 0..view.height {
                        for x in 0..view.width {
                            if let Some(p) = view.point(x, y) {
                                let off = (p - p.clamp(b.min, b.max)).length();
                                assert!(
                                    off <= 0.72 * view.pixel_size(),
                                    "{d:?}, level {depth}: ({x}, {y}) {off} out, pixel {}",
                                    view.pixel_size()
                                );
                            }
                        }
                    }
                    view
                })
                .collect();
        }
        assert!(level[0].covered() > 0, "{d:?}");
    }
}

#[test]
fn images_round_trip_losslessly_and_normals_survive_two_bytes() {
    let (min, max) = (Vec3::new(-1.0, 0.0, -2.0), Vec3::new(3.0, 2.0, 1.0));
    let s = scene(&[cuboid(min, max)]);
    let view = Orthoview::render(&s, &aabb(min, max), [1, -1, 1], 40);
    let images = view.encode().unwrap();
    let back = Orthoview::decode(&view.bounds, view.direction, &images).unwrap();
    assert_eq!(back, view);
    for n in [
        Vec3::X,
        -Vec3::Y,
        Vec3::new(1.0, -2.0, -3.0).normalize(),
        -Vec3::Z,
    ] {
        let m = from_octahedral(octahedral(n));
        assert!(n.dot(m) > 0.999, "{n} -> {m}");
    }
    // Damaged images are an error, not a panic.
    let mut bad = images.clone();
    bad[1].truncate(20);
    assert!(Orthoview::decode(&view.bounds, view.direction, &bad).is_err());
}

#[test]
fn empty_and_flat_nodes_give_valid_orthoviews() {
    let empty = scene(&[]);
    let flat_quad = InstancedMesh {
        submeshes: vec![Submesh {
            positions: vec![Vec3::ZERO, Vec3::X, Vec3::new(1.0, 0.0, 1.0), Vec3::Z],
            indices: vec![0, 2, 1, 0, 3, 2],
            ..Submesh::default()
        }],
        instances: vec![Instance {
            submesh: 0,
            transform: Affine3A::IDENTITY,
        }],
        ..InstancedMesh::default()
    };
    let flat = scene(&[flat_quad]);
    let flat_box = aabb(Vec3::ZERO, Vec3::new(1.0, 0.0, 1.0));
    for d in canonical_directions() {
        let e = Orthoview::render(&empty, &aabb(Vec3::ZERO, Vec3::ONE), d, 8);
        e.validate().unwrap();
        assert_eq!(e.covered(), 0);
        let none = Orthoview::render(&empty, &Aabb::EMPTY, d, 8);
        none.validate().unwrap();
        let f = Orthoview::render(&flat, &flat_box, d, 8);
        f.validate().unwrap();
        let c = Orthoview::composite(&[&e, &f], &flat_box, d, 8);
        c.validate().unwrap();
        let nothing = Orthoview::composite(&[], &flat_box, d, 8);
        nothing.validate().unwrap();
        assert_eq!(nothing.covered(), 0);
    }
    // The resolution is at least one pixel whatever it is given.
    assert_eq!(resolution(0.0, 0.0, 0.0, 0.0), 1);
}

#[test]
fn the_resolution_puts_one_orthoview_pixel_on_at_most_one_screen_pixel() {
    for &(extent, distance, pixel_angle, theta) in &[
        (10.0f32, 1000.0f32, 5.5e-4f32, 0.96f32),
        (300.0, 9000.0, 5.5e-4, 0.785),
        (1.0, 28.0, 5.5e-4, 0.1),
    ] {
        let q = resolution(extent, distance, pixel_angle, theta) as f32;
        // A surface seen theta from the direction: its orthoview pixel, foreshortened.
        let on_screen = |q: f32| extent / q / theta.cos() / (distance * pixel_angle);
        assert!(on_screen(q) <= 1.0 + 1e-4, "{q}");
        assert!(on_screen(q - 1.0) > 1.0, "{q} is more than needed");
    }
    // A node's q: pixel-exact where its largest object subtends min_solid_angle.
    let (omega, pixel) = (1e-3f32, 3.0e-7f32);
    let q = horizon_impostor::node_resolution(3.0, 2.0, omega, pixel);
    let distance = 2.0 * (std::f32::consts::PI / omega).sqrt();
    assert_eq!(
        q,
        resolution(3.0, distance, pixel.sqrt(), horizon_impostor::WORLD_THETA)
    );
    assert!((horizon_impostor::MIN_Q..horizon_impostor::MAX_Q).contains(&q));
    // Within bounds however large or small the node.
    assert_eq!(
        horizon_impostor::node_resolution(1e5, 1.0, omega, pixel),
        horizon_impostor::MAX_Q
    );
    assert_eq!(
        horizon_impostor::node_resolution(0.1, 1.0, omega, pixel),
        horizon_impostor::MIN_Q
    );
}

#[test]
fn every_view_from_above_is_within_theta_of_a_world_direction_and_faces_two_or_three() {
    use horizon_impostor::{facing, WORLD_DIRECTIONS, WORLD_THETA};
    let dirs: Vec<Vec3> = WORLD_DIRECTIONS
        .iter()
        .map(|d| Vec3::new(d[0] as f32, d[1] as f32, d[2] as f32).normalize())
        .collect();
    // No direction looks up, and none along a grid street (x or z alone, level or down).
    assert!(WORLD_DIRECTIONS.iter().all(|d| d[1] <= 0));
    assert!(WORLD_DIRECTIONS
        .iter()
        .all(|d| d[0] != 0 && d[2] != 0 || (d[0], d[2]) == (0, 0)));
    let mut worst = 0.0f32;
    for i in 0..=400 {
        for j in 0..80 {
            let elevation = -(i as f32) / 400.0 * std::f32::consts::FRAC_PI_2;
            let azimuth = j as f32 / 80.0 * std::f32::consts::TAU;
            let v = Vec3::new(
                elevation.cos() * azimuth.cos(),
                elevation.sin(),
                elevation.cos() * azimuth.sin(),
            );
            let nearest = dirs.iter().map(|d| d.dot(v).clamp(-1.0, 1.0).acos());
            worst = worst.max(nearest.fold(f32::INFINITY, f32::min));
            let chosen = facing(&WORLD_DIRECTIONS, v);
            // At least two face every such view (a level diagonal view has exactly two).
            assert!((2..=3).contains(&chosen.len()), "{v}: {chosen:?}");
            // Nearest first.
            let angle = |k: usize| dirs[chosen[k]].dot(v);
            assert!((1..chosen.len()).all(|k| angle(k - 1) >= angle(k) - 1e-6));
        }
    }
    assert!(worst <= WORLD_THETA + 1e-3, "{worst}");
    assert!(worst >= WORLD_THETA - 2e-3, "{worst}");
    // Looking up, nothing faces: the cut draws geometry.
    assert!(facing(&WORLD_DIRECTIONS, Vec3::Y).is_empty());
}

/// An orthoview's splats: one square per covered pixel, centred on its sample, facing against
/// the direction (towards a viewer looking along it), and ray-cast along the direction they
/// give back the orthoview's depths.
#[test]
fn splats_stand_on_their_samples_and_render_back_the_depths() {
    let (min, max) = (Vec3::ZERO, Vec3::new(2.0, 1.0, 1.5));
    let s = scene(&[cuboid(min, max)]);
    for d in [[0, -1, 0], [1, -1, 1], [-1, 0, 1]] {
        let view = Orthoview::render(&s, &aabb(min, max), d, 24);
        let mesh = view.splats();
        mesh.validate().unwrap();
        let sub = &mesh.submeshes[0];
        assert_eq!(sub.indices.len(), 6 * view.covered());
        let dir = Vec3::new(f32::from(d[0]), f32::from(d[1]), f32::from(d[2])).normalize();
        for t in sub.indices.chunks(3) {
            let [a, b, c] = [0, 1, 2].map(|k| sub.positions[t[k] as usize]);
            let facing = (b - a).cross(c - a).normalize();
            assert!(
                (facing + dir).length() < 1e-3,
                "{d:?}: a splat faces {facing}"
            );
        }
        // Ray-cast along the direction, the splats stand where the cube's surface is.
        let splats = scene(&[mesh]);
        let again = Orthoview::render(&splats, &aabb(min, max), d, 24);
        let pixel = view.pixel_size();
        let mut compared = 0;
        for y in 0..view.height {
            for x in 0..view.width {
                if let (Some(p), Some(q)) = (view.point(x, y), again.point(x, y)) {
                    assert!((p - q).length() <= 2.0 * pixel, "{d:?}: ({x}, {y})");
                    compared += 1;
                }
            }
        }
        assert!(
            compared * 10 >= view.covered() * 9,
            "{d:?}: {compared} of {}",
            view.covered()
        );
    }
}
