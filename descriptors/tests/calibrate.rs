//! The Table 1 calibration's pieces: renders in the canonical frame, SSIM on them, perturbed
//! variants.

use std::path::PathBuf;

use glam::{Affine3A, Quat, Vec3};
use horizon_descriptors::calibrate::compare_models;
use horizon_descriptors::calibrate::perturb::Perturbation;
use horizon_descriptors::calibrate::render::{Scene, BACKGROUND};
use horizon_descriptors::calibrate::ssim::ssim;
use horizon_mesh::{import_file, ImportOptions, InstancedMesh};

fn model(rel: &str) -> InstancedMesh {
    let path = PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("../assets/models")
        .join(rel);
    import_file(&path, &ImportOptions::default())
        .expect("shared model imports")
        .mesh
}

fn moved(mesh: &InstancedMesh, motion: Affine3A) -> InstancedMesh {
    let mut out = mesh.clone();
    for i in &mut out.instances {
        i.transform = motion * i.transform;
    }
    out
}

#[test]
fn a_rigidly_moved_copy_renders_the_same_in_the_canonical_frame() {
    let bunny = model("bunny_trimesh/bunny.ply");
    let motion = Affine3A::from_scale_rotation_translation(
        Vec3::splat(3.7),
        Quat::from_euler(glam::EulerRot::XYZ, 0.4, 2.1, -1.3),
        Vec3::new(10.0, -4.0, 2.5),
    );
    let a = Scene::new(&bunny).expect("scene");
    let b = Scene::new(&moved(&bunny, motion)).expect("scene");
    for axis in 0..3 {
        let (ia, ib) = (a.render(axis, true, 110), b.render(axis, true, 110));
        let covered = ia.pixels.iter().filter(|p| **p != BACKGROUND).count();
        assert!(
            covered > 110 * 110 / 10,
            "view {axis} draws the model: {covered} pixels"
        );
        let score = ssim(&ia, &ib, BACKGROUND);
        assert!(score > 0.97, "view {axis}: SSIM {score}");
    }
}

#[test]
fn distinct_models_and_strong_perturbations_score_lower_than_slight_ones() {
    let truck = model("CesiumMilkTruck/CesiumMilkTruck.glb");
    let bunny = model("bunny_trimesh/bunny.ply");
    let score = |mesh: &InstancedMesh| compare_models(&truck, mesh, 110).expect("renders");
    let mirrored = score(&moved(
        &truck,
        Affine3A::from_scale(Vec3::new(-1.0, 1.0, 1.0)),
    ));
    let slight = score(&Perturbation::Noise { relative: 0.002 }.apply(&truck, 1));
    let strong = score(&Perturbation::Noise { relative: 0.03 }.apply(&truck, 1));
    let tinted = |tint: Vec3| score(&Perturbation::Recolour { tint }.apply(&truck, 1));
    let (faint, recoloured) = (
        tinted(Vec3::new(1.0, 0.95, 0.95)),
        tinted(Vec3::new(0.5, 0.8, 1.0)),
    );
    let other = score(&bunny);
    assert!(
        mirrored > 0.97,
        "a mirrored copy aligns by a sign flip: {mirrored}"
    );
    assert!(slight > strong, "noise: slight {slight} vs strong {strong}");
    assert!(faint > 0.99, "a faint tint changes little: {faint}");
    assert!(recoloured < 0.95, "a strong tint is seen: {recoloured}");
    assert!(
        strong > other,
        "strong noise {strong} vs another model {other}"
    );
}

#[test]
fn rendering_an_empty_model_is_an_error() {
    assert!(Scene::new(&InstancedMesh::default()).is_err());
}
