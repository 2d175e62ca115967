//! The ray caster against scenes whose images are known: coverage, depth, face culling,
//! mirroring and occlusion.

use std::sync::Arc;

use glam::{Affine3A, Vec3, Vec4};
use horizon_impostor::{compare, Camera, PreparedMesh, SceneBuilder};
use horizon_mesh::{Instance, InstancedMesh, Material, Submesh};

/// A square of side 2 centred on the origin in the z = 0 plane, front face towards +z, in
/// `color`; `double_sided` as given.
fn square(color: Vec4, double_sided: bool, reversed: bool) -> InstancedMesh {
    let positions = vec![
        Vec3::new(-1.0, -1.0, 0.0),
        Vec3::new(1.0, -1.0, 0.0),
        Vec3::new(1.0, 1.0, 0.0),
        Vec3::new(-1.0, 1.0, 0.0),
    ];
    let mut indices = vec![0, 1, 2, 0, 2, 3];
    if reversed {
        indices = vec![0, 2, 1, 0, 3, 2];
    }
    InstancedMesh {
        submeshes: vec![Submesh {
            positions,
            indices,
            material: Some(0),
            ..Submesh::default()
        }],
        instances: vec![Instance {
            submesh: 0,
            transform: Affine3A::IDENTITY,
        }],
        materials: vec![Material {
            base_color_factor: color,
            double_sided,
            ..Material::default()
        }],
        textures: Vec::new(),
    }
}

/// 64 x 64 pixels, 90 degrees, from (0, 0, 5) towards the origin: the square spans the
/// middle 40% of the image.
fn camera() -> Camera {
    Camera::look_at(Vec3::new(0.0, 0.0, 5.0), Vec3::ZERO, 64, 64, 90.0)
}

fn render(meshes: &[(InstancedMesh, Affine3A)]) -> horizon_impostor::Frame {
    let mut scene = SceneBuilder::default();
    for (mesh, at) in meshes {
        scene.add(&Arc::new(PreparedMesh::new(mesh)), at);
    }
    let frame = scene.build().render(&camera(), 1);
    frame.validate().expect("a valid frame");
    frame
}

fn at(frame: &horizon_impostor::Frame, x: u32, y: u32) -> usize {
    (y * frame.width + x) as usize
}

#[test]
fn a_square_facing_the_camera_covers_its_projection_at_its_depth() {
    let frame = render(&[(
        square(Vec4::new(1.0, 0.0, 0.0, 1.0), false, false),
        Affine3A::IDENTITY,
    )]);
    // Projected half-width: 1 / 5 of the half-image (tan 45 = 1), so 6.4 pixels either side
    // of the centre: 12 or 13 pixels across, about 2.5% to 4.2% of the image.
    let covered = frame.covered();
    assert!(covered > 0.03 && covered < 0.045, "{covered}");
    let centre = at(&frame, 32, 32);
    assert_eq!(frame.coverage[centre], 1.0);
    assert!(
        (frame.depth[centre] - 5.0).abs() < 0.01,
        "{}",
        frame.depth[centre]
    );
    // Red, lit: the red channel dominates, the others are black.
    let [r, g, b] = frame.color[centre];
    assert!(r > 100 && g == 0 && b == 0, "{:?}", frame.color[centre]);
    assert_eq!(frame.coverage[at(&frame, 2, 2)], 0.0);
}

#[test]
fn back_faces_draw_only_when_double_sided() {
    let red = Vec4::new(1.0, 0.0, 0.0, 1.0);
    let single = render(&[(square(red, false, true), Affine3A::IDENTITY)]);
    assert_eq!(single.covered(), 0.0);
    let double = render(&[(square(red, true, true), Affine3A::IDENTITY)]);
    assert!(double.covered() > 0.03);
}

#[test]
fn a_mirroring_placement_keeps_front_faces_in_front() {
    let red = Vec4::new(1.0, 0.0, 0.0, 1.0);
    let mirror = Affine3A::from_scale(Vec3::new(-1.0, 1.0, 1.0));
    let frame = render(&[(square(red, false, false), mirror)]);
    assert!(frame.covered() > 0.03, "{}", frame.covered());
}

#[test]
fn the_nearer_of_two_surfaces_is_drawn() {
    let red = square(Vec4::new(1.0, 0.0, 0.0, 1.0), false, false);
    let green = square(Vec4::new(0.0, 1.0, 0.0, 1.0), false, false);
    let near = Affine3A::from_translation(Vec3::new(0.0, 0.0, 1.0));
    let frame = render(&[(red, Affine3A::IDENTITY), (green, near)]);
    let centre = at(&frame, 32, 32);
    assert!((frame.depth[centre] - 4.0).abs() < 0.01);
    assert!(frame.color[centre][1] > 100 && frame.color[centre][0] == 0);
}

#[test]
fn comparing_a_render_with_one_missing_a_surface_counts_its_pixels_as_holes() {
    let red = square(Vec4::new(1.0, 0.0, 0.0, 1.0), false, false);
    let both = render(&[
        (red.clone(), Affine3A::IDENTITY),
        (
            red.clone(),
            Affine3A::from_translation(Vec3::new(2.5, 0.0, 0.0)),
        ),
    ]);
    let one = render(&[(red, Affine3A::IDENTITY)]);
    let c = compare(&both, &one);
    let expected = both.covered() - one.covered();
    assert!((c.holes - expected).abs() < 1e-9 && c.holes > 0.01, "{c:?}");
    assert!(c.psnr < 40.0 && c.ssim < 1.0);
    assert_eq!(compare(&both, &both).holes, 0.0);
}

#[test]
fn picking_names_the_placement_seen_at_a_pixel() {
    let red = square(Vec4::new(1.0, 0.0, 0.0, 1.0), false, false);
    let mesh = Arc::new(PreparedMesh::new(&red));
    let mut scene = SceneBuilder::default();
    // Placement 0 behind, placement 1 in front at the centre, placement 2 off to the right.
    scene.add(&mesh, &Affine3A::IDENTITY);
    scene.add(&mesh, &Affine3A::from_translation(Vec3::new(0.0, 0.0, 1.0)));
    scene.add(&mesh, &Affine3A::from_translation(Vec3::new(3.0, 0.0, 0.0)));
    let scene = scene.build();
    let cam = camera();
    let (front, t) = scene.pick(&cam, 32.0, 32.0).expect("a hit");
    assert_eq!(front, 1);
    assert!((t - 4.0).abs() < 1e-3);
    // The third square spans x in [2, 4] at depth 5: about pixels 45 to 58.
    assert_eq!(scene.pick(&cam, 51.0, 32.0).map(|p| p.0), Some(2));
    assert_eq!(scene.pick(&cam, 2.0, 2.0), None);
}

#[test]
fn axis_aligned_rays_with_negative_zeros_still_hit() {
    let red = square(Vec4::new(1.0, 0.0, 0.0, 1.0), false, false);
    let mut scene = SceneBuilder::default();
    scene.add(&Arc::new(PreparedMesh::new(&red)), &Affine3A::IDENTITY);
    let scene = scene.build();
    for dir in [Vec3::NEG_Z, -Vec3::Z, Vec3::new(-0.0, 0.0, -1.0)] {
        let t = scene.cast(Vec3::new(0.2, 0.3, 5.0), dir);
        assert_eq!(t, Some(5.0), "{dir:?}");
    }
}
