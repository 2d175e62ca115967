//! Export then import keeps what the model means: triangle counts, instance transforms (within
//! 1e-5 relative), mirrors, and shear. The real third-party models in `assets/models` and tiny
//! hand-built meshes are both used.

mod common;

use std::collections::BTreeSet;
use std::path::PathBuf;

use common::{cubes, relative_difference};
use glam::{Affine3A, Mat3, Quat, Vec3};
use horizon_mesh::{
    export_glb, import_bytes, import_file, ExportOptions, Format, ImportOptions, InstancedMesh,
    Submesh,
};
use proptest::prelude::*;

fn assets() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../assets/models")
}

fn shared_models() -> Vec<PathBuf> {
    let mut out = Vec::new();
    for dir in std::fs::read_dir(assets()).expect("assets/models exists") {
        for f in std::fs::read_dir(dir.expect("entry").path()).expect("model folder") {
            let p = f.expect("entry").path();
            let ext = p.extension().and_then(|e| e.to_str()).unwrap_or("");
            if ["glb", "gltf", "ply"].contains(&ext) {
                out.push(p);
            }
        }
    }
    out.sort();
    out
}

/// Every shared model with its name, imported with the default options.
fn shared_meshes() -> Vec<(String, InstancedMesh)> {
    shared_models()
        .into_iter()
        .map(|path| {
            let mesh = import_file(&path, &ImportOptions::default())
                .expect("imports")
                .mesh;
            (path.display().to_string(), mesh)
        })
        .collect()
}

fn reimport(mesh: &InstancedMesh, compress: bool) -> InstancedMesh {
    let options = ExportOptions {
        compress,
        ..ExportOptions::plain()
    };
    reimport_with(mesh, &options)
}

/// What aggregates are written as, but with float positions.
fn float_positions() -> ExportOptions {
    ExportOptions {
        position_tolerance: None,
        ..ExportOptions::aggregate(0.0)
    }
}

/// `mesh` exported with `options` and imported back, validated.
fn reimport_with(mesh: &InstancedMesh, options: &ExportOptions) -> InstancedMesh {
    let glb = export_glb(mesh, options).expect("exports");
    let back =
        import_bytes(&glb, Format::Glb, None, &ImportOptions::default()).expect("re-imports");
    back.mesh.validate().expect("valid");
    back.mesh
}

/// Every submesh of `a` and `b` placed by as many transforms, each within 1e-5 relative.
fn assert_same_placements(name: impl std::fmt::Display, a: &InstancedMesh, b: &InstancedMesh) {
    assert_placements_within(name, a, b, 1e-5);
}

/// Every submesh of `a` and `b` placed by as many transforms, each within `tolerance`
/// relative.
fn assert_placements_within(
    name: impl std::fmt::Display,
    a: &InstancedMesh,
    b: &InstancedMesh,
    tolerance: f32,
) {
    for (ta, tb) in transforms_by_submesh(a)
        .iter()
        .zip(&transforms_by_submesh(b))
    {
        assert_eq!(ta.len(), tb.len(), "{name}");
        for (x, y) in ta.iter().zip(tb) {
            assert!(
                relative_difference(x, y) <= tolerance,
                "{name}: {x:?} vs {y:?}"
            );
        }
    }
}

/// For each submesh, its instance transforms in order.
fn transforms_by_submesh(mesh: &InstancedMesh) -> Vec<Vec<Affine3A>> {
    mesh.instances_by_submesh()
        .iter()
        .map(|ks| ks.iter().map(|&k| mesh.instances[k].transform).collect())
        .collect()
}

#[test]
fn every_shared_model_round_trips_exactly_in_plain_glb() {
    let models = shared_meshes();
    let names: Vec<&String> = models.iter().map(|(name, _)| name).collect();
    assert!(
        models.len() >= 8,
        "expected the eight shared models, found {names:?}"
    );
    for (name, a) in models {
        let b = reimport(&a, false);
        assert_eq!(
            a.expanded_triangle_count(),
            b.expanded_triangle_count(),
            "{name}"
        );
        assert_eq!(
            a.unique_triangle_count(),
            b.unique_triangle_count(),
            "{name}"
        );
        assert_eq!(a.submeshes.len(), b.submeshes.len(), "{name}");
        assert_eq!(a.materials.len(), b.materials.len(), "{name}");
        assert!(
            a.textures == b.textures,
            "{name}: texture bytes are embedded unchanged"
        );
        // Plain export writes the same vertices and indices, so submeshes match exactly
        // (normals are normalised on export; the shared models' are already unit length).
        for (sa, sb) in a.submeshes.iter().zip(&b.submeshes) {
            // (assert! rather than assert_eq!, to keep a failure's message short)
            assert!(sa.positions == sb.positions, "{name}: positions differ");
            assert!(sa.indices == sb.indices, "{name}: indices differ");
            assert!(sa.uvs == sb.uvs, "{name}: uvs differ");
        }
        assert_same_placements(&name, &a, &b);
    }
}

#[test]
fn every_shared_model_keeps_counts_and_bounds_when_compressed() {
    for (name, a) in shared_meshes() {
        let b = reimport(&a, true);
        assert_eq!(
            a.expanded_triangle_count(),
            b.expanded_triangle_count(),
            "{name}"
        );
        assert_eq!(a.instances.len(), b.instances.len(), "{name}");
        // 16-bit positions move a vertex by at most half a step of the largest submesh extent
        // per axis; scaled by the instance, that stays well under 1e-4 of the diagonal.
        let (ba, bb) = (a.bounds(), b.bounds());
        let tolerance = 1e-4 * ba.diagonal();
        assert!(
            (ba.min - bb.min).abs().max_element() <= tolerance,
            "{name}: {ba:?} vs {bb:?}"
        );
        assert!(
            (ba.max - bb.max).abs().max_element() <= tolerance,
            "{name}: {ba:?} vs {bb:?}"
        );
    }
}

#[test]
fn compressed_is_smaller_for_real_geometry() {
    // The bunny has 16k triangles of float data: quantization and the meshopt codec must win.
    let a = import_file(
        &assets().join("bunny_trimesh/bunny.ply"),
        &ImportOptions::default(),
    )
    .expect("imports")
    .mesh;
    let plain = export_glb(&a, &ExportOptions::plain())
        .expect("exports")
        .len();
    let compressed = export_glb(&a, &ExportOptions::compressed())
        .expect("exports")
        .len();
    assert!(
        compressed * 2 < plain,
        "plain {plain} B, compressed {compressed} B"
    );
}

#[test]
fn trs_instances_become_one_gpu_instanced_node() {
    // Two translated cubes: both TRS, so one node with EXT_mesh_gpu_instancing.
    let mesh = cubes(&[
        Affine3A::IDENTITY,
        Affine3A::from_translation(Vec3::X * 3.0),
    ]);
    let glb = export_glb(&mesh, &ExportOptions::plain()).expect("exports");
    let doc = gltf::Glb::from_slice(&glb).expect("glb");
    let json: serde_json::Value = serde_json::from_slice(&doc.json).expect("json");
    assert_eq!(json["nodes"].as_array().map(Vec::len), Some(1));
    assert!(json["nodes"][0]["extensions"]["EXT_mesh_gpu_instancing"].is_object());
    assert_eq!(reimport(&mesh, false).instances.len(), 2);
}

fn json_of(glb: &[u8]) -> serde_json::Value {
    serde_json::from_slice(&gltf::Glb::from_slice(glb).expect("glb").json).expect("json")
}

#[test]
fn translated_instances_store_translations_alone() {
    // Identity rotation and unit scale for every instance: both attributes are left out.
    let mesh = cubes(&[
        Affine3A::from_translation(Vec3::Z),
        Affine3A::from_translation(Vec3::X * 3.0),
    ]);
    let json = json_of(&export_glb(&mesh, &ExportOptions::plain()).expect("exports"));
    let attributes = &json["nodes"][0]["extensions"]["EXT_mesh_gpu_instancing"]["attributes"];
    let names: Vec<&String> = attributes.as_object().expect("attributes").keys().collect();
    assert_eq!(names, ["TRANSLATION"]);
    let back = transforms_by_submesh(&reimport(&mesh, false));
    assert_eq!(back, transforms_by_submesh(&mesh));
}

#[test]
fn accessors_of_one_kind_share_a_buffer_view() {
    // Three submeshes with positions, normals and UVs, two of them instanced: one view per
    // kind (stride-12 and stride-8 vertex data, indices, instance data), not one per accessor.
    let mut mesh = cubes(&[
        Affine3A::from_rotation_y(0.5),
        Affine3A::from_translation(Vec3::X * 3.0),
    ]);
    let second = mesh.submeshes[0].clone();
    mesh.submeshes.push(second.clone());
    mesh.submeshes.push(second);
    for (submesh, x) in [(1, 6.0), (1, 9.0), (2, 12.0)] {
        mesh.instances.push(horizon_mesh::Instance {
            submesh,
            transform: Affine3A::from_scale_rotation_translation(
                Vec3::new(1.0, 2.0, 1.0),
                Quat::from_rotation_z(0.3),
                Vec3::X * x,
            ),
        });
    }
    let glb = export_glb(&mesh, &ExportOptions::plain()).expect("exports");
    let json = json_of(&glb);
    let accessors = json["accessors"].as_array().expect("accessors").len();
    let views = json["bufferViews"].as_array().expect("views").len();
    assert!(accessors > 10, "{accessors} accessors");
    assert!(views <= 4, "{views} buffer views for {accessors} accessors");
    // Shortest float text: no widened f32 digits in the document.
    let text =
        String::from_utf8(gltf::Glb::from_slice(&glb).expect("glb").json.to_vec()).expect("utf-8");
    assert!(!text.contains("0000000"), "long float text in {text}");
    // The meaning survives exactly.
    let back = reimport(&mesh, false);
    assert_eq!(
        back.expanded_triangle_count(),
        mesh.expanded_triangle_count()
    );
    assert_eq!(transforms_by_submesh(&back), transforms_by_submesh(&mesh));
}

#[test]
fn short_rotations_stay_within_their_quantization_error() {
    let transforms: Vec<Affine3A> = (0..20)
        .map(|k| {
            Affine3A::from_scale_rotation_translation(
                Vec3::splat(1.0 + k as f32 * 0.1),
                Quat::from_euler(
                    glam::EulerRot::XYZ,
                    k as f32 * 0.7,
                    1.0 - k as f32 * 0.3,
                    0.2,
                ),
                Vec3::new(k as f32, 0.0, -2.0 * k as f32),
            )
        })
        .collect();
    let mesh = cubes(&transforms);
    let plain = export_glb(&mesh, &ExportOptions::plain()).expect("exports");
    let options = ExportOptions {
        short_rotations: true,
        ..ExportOptions::plain()
    };
    let short = export_glb(&mesh, &options).expect("exports");
    // 8 bytes saved per instance, less the accessor's `"normalized":true` in the JSON.
    assert!(
        short.len() + 8 * 20 <= plain.len() + 32,
        "{} vs {}",
        short.len(),
        plain.len()
    );
    let back = import_bytes(&short, Format::Glb, None, &ImportOptions::default()).expect("imports");
    let back = &transforms_by_submesh(&back.mesh)[0];
    for (a, b) in transforms.iter().zip(back) {
        // Rotation within about 3e-5 rad: each axis of the (uniformly scaled) frame moves
        // by at most about that much of its length.
        for (u, v) in [
            (a.matrix3.x_axis, b.matrix3.x_axis),
            (a.matrix3.y_axis, b.matrix3.y_axis),
            (a.matrix3.z_axis, b.matrix3.z_axis),
        ] {
            let off = (u - v).length() / u.length();
            assert!(off < 1e-4, "axis {u} came back as {v}");
        }
        assert!((a.translation - b.translation).length() < 1e-5);
    }
}

#[test]
fn a_single_instance_is_a_matrix_node() {
    let mesh = cubes(&[Affine3A::from_translation(Vec3::Y)]);
    let glb = export_glb(&mesh, &ExportOptions::plain()).expect("exports");
    let json: serde_json::Value =
        serde_json::from_slice(&gltf::Glb::from_slice(&glb).expect("glb").json).expect("json");
    assert!(json["nodes"][0]["matrix"].is_array());
    assert!(json.get("extensionsUsed").is_none());
}

#[test]
fn mirrored_instances_stay_mirrored_and_their_expansion_faces_out() {
    let mirror = Affine3A::from_scale(Vec3::new(-1.0, 1.0, 1.0));
    let mesh = cubes(&[Affine3A::IDENTITY, mirror]);
    for compress in [false, true] {
        let back = reimport(&mesh, compress);
        let dets: Vec<f32> = back
            .instances
            .iter()
            .map(|i| i.transform.matrix3.determinant())
            .collect();
        assert!(
            dets[0] > 0.0 && dets[1] < 0.0,
            "compress={compress}: {dets:?}"
        );
        // Expansion flips the mirrored copy's winding, so every triangle's normal still points
        // away from its cube's centre.
        let e = back.expand();
        for (t, tri) in e.indices.chunks_exact(3).enumerate() {
            let [a, b, c] = [0, 1, 2].map(|k| e.positions[tri[k] as usize]);
            let inst = &back.instances[e.triangle_instance[t] as usize];
            let centre = inst.transform.transform_point3(Vec3::splat(0.5));
            let normal = (b - a).cross(c - a);
            assert!(
                normal.dot((a + b + c) / 3.0 - centre) > 0.0,
                "compress={compress} triangle {t}"
            );
        }
    }
}

#[test]
fn sheared_instances_survive_through_a_parent_and_child_node() {
    // A rotated child under a non-uniformly scaled parent: shear, which no glTF matrix may hold.
    let shear = Affine3A::from_scale(Vec3::new(3.0, 1.0, 1.0))
        * Affine3A::from_quat(Quat::from_rotation_z(0.6));
    let mesh = cubes(&[shear, Affine3A::from_translation(Vec3::Z * 4.0) * shear]);
    for compress in [false, true] {
        let back = reimport(&mesh, compress);
        assert_eq!(back.instances.len(), 2);
        if !compress {
            for (a, b) in mesh.instances.iter().zip(&back.instances) {
                assert!(relative_difference(&a.transform, &b.transform) <= 1e-5);
            }
        }
        let (ba, bb) = (mesh.bounds(), back.bounds());
        assert!(
            (ba.min - bb.min).abs().max_element() < 1e-3
                && (ba.max - bb.max).abs().max_element() < 1e-3
        );
    }
}

#[test]
fn attributes_survive_compression_within_quantization_error() {
    let mut mesh = cubes(&[Affine3A::IDENTITY]);
    let s = &mut mesh.submeshes[0];
    s.uvs = Some(
        s.positions
            .iter()
            .map(|p| glam::Vec2::new(p.x, p.y))
            .collect(),
    );
    s.colors = Some(s.positions.iter().map(|p| p.extend(1.0)).collect());
    let back = reimport(&mesh, true);
    let b = &back.submeshes[0];
    let inst = back.instances[0].transform;
    // Vertices may be reordered; match each original vertex to its position after export.
    for (k, p) in mesh.submeshes[0].positions.iter().enumerate() {
        let j = b
            .positions
            .iter()
            .position(|q| (inst.transform_point3(*q) - *p).length() < 1e-4)
            .expect("every vertex is kept");
        let n = mesh.submeshes[0].normals.as_ref().expect("normals")[k];
        assert!(
            (b.normals.as_ref().expect("normals")[j] - n).length() < 0.02,
            "8-bit normals"
        );
        assert!((b.uvs.as_ref().expect("uvs")[j] - glam::Vec2::new(p.x, p.y)).length() < 1e-4);
        assert!((b.colors.as_ref().expect("colors")[j] - p.extend(1.0)).length() < 1e-4);
    }
}

fn arbitrary_transform() -> impl Strategy<Value = Affine3A> {
    (
        prop::array::uniform9(-3.0f32..3.0),
        prop::array::uniform3(-50.0f32..50.0),
    )
        .prop_filter("invertible", |(m, _)| {
            Mat3::from_cols_array(m).determinant().abs() > 1e-2
        })
        .prop_map(|(m, t)| {
            Affine3A::from_mat3_translation(Mat3::from_cols_array(&m), Vec3::from(t))
        })
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(48))]

    /// Any invertible affine transforms (mirrors and shear included) round-trip within 1e-5.
    #[test]
    fn any_transforms_round_trip(transforms in prop::collection::vec(arbitrary_transform(), 1..6)) {
        let mesh = cubes(&transforms);
        let back = reimport(&mesh, false);
        prop_assert_eq!(back.expanded_triangle_count(), mesh.expanded_triangle_count());
        for (a, b) in mesh.instances.iter().zip(&back.instances) {
            prop_assert!(relative_difference(&a.transform, &b.transform) <= 1e-5,
                "{:?} vs {:?}", a.transform, b.transform);
        }
    }
}

#[test]
fn extreme_transforms_export_without_overflow() {
    // Found by the fuzzer: folding 16-bit dequantisation into a 1e36 scale overflowed f32 and
    // wrote null into the JSON. Such a submesh now stays unquantised, and both exports re-import.
    let huge = Affine3A::from_scale_rotation_translation(
        Vec3::splat(3e36),
        Quat::from_rotation_x(0.3),
        Vec3::splat(2e38),
    );
    let mesh = cubes(&[huge, Affine3A::IDENTITY]);
    for compress in [false, true] {
        let back = reimport(&mesh, compress);
        assert_eq!(
            back.expanded_triangle_count(),
            mesh.expanded_triangle_count()
        );
    }
}

/// The `attributes` object of each mesh's primitive, in mesh order.
fn primitive_attributes(json: &serde_json::Value) -> Vec<serde_json::Value> {
    json["meshes"]
        .as_array()
        .expect("meshes")
        .iter()
        .map(|m| m["primitives"][0]["attributes"].clone())
        .collect()
}

/// The component type of each primitive's index accessor, in mesh order.
fn index_types(json: &serde_json::Value) -> Vec<u64> {
    json["meshes"]
        .as_array()
        .expect("meshes")
        .iter()
        .map(|m| {
            let a = m["primitives"][0]["indices"].as_u64().expect("indices") as usize;
            json["accessors"][a]["componentType"]
                .as_u64()
                .expect("type")
        })
        .collect()
}

#[test]
fn every_shared_model_round_trips_exactly_with_shared_vertex_runs() {
    for (name, a) in shared_meshes() {
        let shared = export_glb(&a, &ExportOptions::parts()).expect("exports");
        let alone = export_glb(&a, &ExportOptions::plain()).expect("exports");
        assert!(shared.len() <= alone.len(), "{name}: sharing grew the file");
        let b = import_bytes(&shared, Format::Glb, None, &ImportOptions::default())
            .expect("re-imports")
            .mesh;
        b.validate().expect("valid");
        assert_eq!(a.submeshes.len(), b.submeshes.len(), "{name}");
        assert_eq!(a.materials.len(), b.materials.len(), "{name}");
        // The importer keeps what each primitive indexes, so every submesh comes back as it was.
        for (sa, sb) in a.submeshes.iter().zip(&b.submeshes) {
            assert!(sa.positions == sb.positions, "{name}: positions differ");
            assert!(sa.indices == sb.indices, "{name}: indices differ");
            assert!(sa.uvs == sb.uvs, "{name}: uvs differ");
            assert!(sa.colors == sb.colors, "{name}: colours differ");
            assert_eq!(sa.material, sb.material, "{name}");
        }
        assert_same_placements(&name, &a, &b);
    }
}

#[test]
fn every_shared_model_keeps_its_geometry_as_an_aggregate_within_short_attribute_error() {
    // Aggregates write normals as 8-bit and UVs in [0, 1] as 16-bit normalized integers:
    // with float positions, positions and indices come back exactly, placements within the
    // short rotations' error, normals within about half a degree, UVs within half a step of
    // 1/65535, and UVs outside [0, 1] stay float, exact.
    let options = float_positions();
    for (name, a) in shared_meshes() {
        let b = reimport_with(&a, &options);
        assert_eq!(a.submeshes.len(), b.submeshes.len(), "{name}");
        for (sa, sb) in a.submeshes.iter().zip(&b.submeshes) {
            assert!(sa.positions == sb.positions, "{name}: positions differ");
            assert!(sa.indices == sb.indices, "{name}: indices differ");
            if let (Some(na), Some(nb)) = (&sa.normals, &sb.normals) {
                for (x, y) in na.iter().zip(nb) {
                    let x = x.try_normalize().unwrap_or(Vec3::Z);
                    let y = y.normalize();
                    assert!(
                        x.angle_between(y) < 0.01,
                        "{name}: normal {x} came back as {y}"
                    );
                }
            }
            assert_eq!(sa.normals.is_some(), sb.normals.is_some(), "{name}");
            if let (Some(ua), Some(ub)) = (&sa.uvs, &sb.uvs) {
                let unit = ua
                    .iter()
                    .all(|t| t.cmpge(glam::Vec2::ZERO).all() && t.cmple(glam::Vec2::ONE).all());
                for (x, y) in ua.iter().zip(ub) {
                    let off = (*x - *y).abs().max_element();
                    let bound = if unit { 0.5 / 65535.0 + 1e-7 } else { 0.0 };
                    assert!(off <= bound, "{name}: uv {x} came back as {y}");
                }
            }
            assert_eq!(sa.uvs.is_some(), sb.uvs.is_some(), "{name}");
        }
        // 16-bit rotations: within about 3e-5 rad.
        assert_placements_within(&name, &a, &b, 1e-4);
    }
}

/// The largest distance between a vertex of `a` and the same vertex of `b`, each placed by the
/// same-numbered instance of its submesh, and the largest coordinate (for f32 slack).
fn placed_vertex_error(name: &str, a: &InstancedMesh, b: &InstancedMesh) -> (f32, f32) {
    assert_eq!(a.submeshes.len(), b.submeshes.len(), "{name}");
    let (mut worst, mut magnitude) = (0.0f32, 0.0f32);
    for (s, (ta, tb)) in transforms_by_submesh(a)
        .iter()
        .zip(&transforms_by_submesh(b))
        .enumerate()
    {
        assert_eq!(ta.len(), tb.len(), "{name}: submesh {s}");
        let (pa, pb) = (&a.submeshes[s].positions, &b.submeshes[s].positions);
        assert_eq!(pa.len(), pb.len(), "{name}: submesh {s}");
        assert!(
            a.submeshes[s].indices == b.submeshes[s].indices,
            "{name}: indices"
        );
        for (x, y) in ta.iter().zip(tb) {
            for (p, q) in pa.iter().zip(pb) {
                let (p, q) = (x.transform_point3(*p), y.transform_point3(*q));
                worst = worst.max(p.distance(q));
                magnitude = magnitude.max(p.abs().max_element());
            }
        }
    }
    (worst, magnitude)
}

/// POSITION accessors' component types, one per distinct accessor.
fn position_types(json: &serde_json::Value) -> BTreeSet<u64> {
    let mut accessors = BTreeSet::new();
    for attributes in primitive_attributes(json) {
        accessors.insert(attributes["POSITION"].as_u64().expect("position"));
    }
    accessors
        .iter()
        .map(|&a| {
            json["accessors"][a as usize]["componentType"]
                .as_u64()
                .expect("type")
        })
        .collect()
}

#[test]
fn every_shared_model_keeps_every_placed_vertex_within_the_position_tolerance() {
    // Aggregates store positions as 16-bit integers where that keeps every vertex, in every
    // placement (the models' mirrored and scaled ones), within the tolerance; a generous
    // tolerance quantizes every run, a zero one none, one between some, and either way each
    // placed vertex comes back within it (plus f32 rounding) of where the same export with
    // float positions puts it (which the test above holds to the input, short rotations'
    // error included).
    let float = float_positions();
    let mut mixed = 0;
    for (name, input) in shared_meshes() {
        let a = reimport_with(&input, &float);
        let diagonal = input.bounds().diagonal();
        // A 16-bit grid over the whole model moves a vertex by up to 1.3e-5 of the diagonal:
        // the middle tolerances quantize some runs and refuse others.
        let cases = [
            (1e-3, Some(5123)),
            (2e-5, None),
            (1e-5, None),
            (5e-6, None),
            (0.0, Some(5126)),
        ];
        for (relative, all_of) in cases {
            let tolerance = diagonal * relative;
            let options = ExportOptions::aggregate(tolerance);
            let glb = export_glb(&input, &options).expect("exports");
            let types = position_types(&json_of(&glb));
            if let Some(expected) = all_of {
                assert!(
                    types.iter().all(|&t| t == expected),
                    "{name} at {relative}: position types {types:?}"
                );
            }
            mixed += usize::from(types.len() > 1);
            let b = reimport_with(&input, &options);
            let (worst, magnitude) = placed_vertex_error(&name, &a, &b);
            let slack = 4.0 * f32::EPSILON * magnitude;
            assert!(
                worst <= tolerance + slack,
                "{name} at {relative}: a vertex moved {worst} (tolerance {tolerance})"
            );
        }
    }
    // Runs quantized beside runs refused in one file, so the bound is tested at its edge.
    assert!(mixed > 0, "no tolerance split any model's runs");
}

/// `n` vertices scattered in the unit cube, as triangles of three consecutive vertices: over
/// many vertices, rounding to a grid comes close to its worst case on every axis at once.
fn point_cloud(n: u32, seed: u64) -> Submesh {
    let mut state = seed;
    let mut next = move || {
        state = state
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        (state >> 40) as f32 / (1u64 << 24) as f32
    };
    let positions: Vec<Vec3> = (0..n).map(|_| Vec3::new(next(), next(), next())).collect();
    Submesh {
        positions,
        indices: (0..n - n % 3).collect(),
        ..Default::default()
    }
}

#[test]
fn sheared_and_strongly_scaled_placements_stay_within_every_tolerance() {
    // A point cloud stretched tenfold along its own diagonal (a rotation, then a non-uniform
    // scale: shear, written as a parent and child pair), mirrored, and twice uniformly scaled
    // (GPU-instanced). Rounding to the grid moves a vertex by up to half a step on every axis
    // at once, and the stretch magnifies exactly that diagonal: by 8.7 steps, where the
    // longest stretched axis would promise 5.1. Over a sweep of tolerances 15% apart, every
    // placed vertex stays within the tolerance of the float export, and the sweep passes from
    // float to quantized, so at the first tolerance that quantizes the rounding is near its
    // bound.
    let diagonal = Quat::from_rotation_arc(Vec3::ONE.normalize(), Vec3::X);
    let stretch = Mat3::from_diagonal(Vec3::new(10.0, 1.0, 1.0)) * Mat3::from_quat(diagonal);
    let mut mesh = InstancedMesh {
        submeshes: vec![point_cloud(6000, 7)],
        ..Default::default()
    };
    for transform in [
        Affine3A::from_mat3(stretch),
        Affine3A::from_scale(Vec3::new(-2.0, 1.0, 1.5)),
        Affine3A::from_scale(Vec3::splat(2.0)),
        Affine3A::from_scale_rotation_translation(
            Vec3::splat(2.0),
            Quat::from_rotation_y(0.7),
            Vec3::new(5.0, 0.0, 0.0),
        ),
    ] {
        mesh.instances.push(horizon_mesh::Instance {
            submesh: 0,
            transform,
        });
    }
    let float = float_positions();
    let exact = reimport_with(&mesh, &float);
    let mut seen = BTreeSet::new();
    let mut tolerance = 1e-5f32;
    while tolerance < 1e-2 {
        let options = ExportOptions::aggregate(tolerance);
        let types = position_types(&json_of(&export_glb(&mesh, &options).expect("exports")));
        seen.extend(types.iter().copied());
        let back = reimport_with(&mesh, &options);
        let (worst, magnitude) = placed_vertex_error("cloud", &exact, &back);
        assert!(
            worst <= tolerance + 8.0 * f32::EPSILON * magnitude,
            "a vertex moved {worst} at tolerance {tolerance} ({types:?})"
        );
        tolerance *= 1.15;
    }
    assert_eq!(
        seen,
        BTreeSet::from([5123, 5126]),
        "the sweep crosses the bound"
    );
}

#[test]
fn runs_refused_quantization_still_share_their_vertices() {
    // Ten cubes of one layout, each placed twice: with a tolerance no grid meets they keep
    // float positions and share one run of vertex accessors, as without quantization.
    let mut mesh = InstancedMesh::default();
    for k in 0..10 {
        mesh.submeshes.push(common::cube());
        for x in [0.0, 2.0] {
            mesh.instances.push(horizon_mesh::Instance {
                submesh: k,
                transform: Affine3A::from_translation(Vec3::new(x, 3.0 * k as f32, 0.0)),
            });
        }
    }
    let float = float_positions();
    let unshared = json_of(&export_glb(&mesh, &float).expect("exports"));
    for tolerance in [0.0, 1e-9, -1.0, f32::NAN] {
        let options = ExportOptions::aggregate(tolerance);
        let json = json_of(&export_glb(&mesh, &options).expect("exports"));
        assert_eq!(position_types(&json), BTreeSet::from([5126]), "{tolerance}");
        assert_eq!(
            json["accessors"].as_array().map(Vec::len),
            unshared["accessors"].as_array().map(Vec::len),
            "{tolerance}: runs split"
        );
    }
}

#[test]
fn tiny_and_empty_submeshes_neither_fail_nor_spoil_a_run() {
    // A submesh whose box is below f32's normal range cannot be put on a 16-bit grid: it keeps
    // float positions (compressed too) instead of failing. An empty submesh placed at a
    // scale of 10,000 draws nothing: it is left out (glTF has no empty accessor) and keeps no
    // cube from quantizing.
    let mut mesh = cubes(&[
        Affine3A::IDENTITY,
        Affine3A::from_translation(Vec3::X * 3.0),
    ]);
    mesh.submeshes.push(Submesh {
        positions: vec![Vec3::ZERO, Vec3::splat(1e-41), Vec3::new(0.0, 1e-41, 0.0)],
        indices: vec![0, 1, 2],
        ..Default::default()
    });
    mesh.submeshes.push(Submesh::default());
    mesh.submeshes.push(common::cube());
    for (submesh, scale) in [(1, 1.0), (2, 1e4), (2, 2e4), (3, 1.0)] {
        mesh.instances.push(horizon_mesh::Instance {
            submesh,
            transform: Affine3A::from_scale(Vec3::splat(scale)),
        });
    }
    for options in [ExportOptions::aggregate(1e-3), ExportOptions::compressed()] {
        let back = reimport_with(&mesh, &options);
        assert_eq!(
            back.expanded_triangle_count(),
            mesh.expanded_triangle_count()
        );
    }
    let json = json_of(&export_glb(&mesh, &ExportOptions::aggregate(1e-3)).expect("exports"));
    let attributes = primitive_attributes(&json);
    let position = |m: usize| attributes[m]["POSITION"].as_u64().expect("position") as usize;
    let component = |m: usize| json["accessors"][position(m)]["componentType"].as_u64();
    // The empty submesh is left out of the file (it draws nothing): the second cube is mesh 2.
    assert_eq!(attributes.len(), 3);
    assert_eq!(component(0), Some(5123), "cube");
    assert_eq!(component(2), Some(5123), "cube after the empty submesh");
    assert_eq!(position(0), position(2), "the cubes share a run");
    assert_eq!(component(1), Some(5126), "subnormal box");
}

#[test]
fn small_parts_and_far_baked_geometry_quantize_in_runs_of_their_own() {
    // An aggregate's model-space parts (a unit cube placed twice, mirrored and stretched, and
    // another placed twice at unit scale after it) and geometry baked in world space a
    // kilometre away share one layout, but one grid over both would round the cubes by
    // centimetres: the cubes share a run and the baked geometry has its own, both quantized,
    // and every placed vertex stays within the tolerance. The GPU-instanced nodes carry the
    // grid's step as their scale, so unit-scale instances still need no SCALE stream.
    let mut mesh = cubes(&[
        Affine3A::from_scale(Vec3::new(-1.0, 1.0, 2.5)),
        Affine3A::from_translation(Vec3::X * 3.0),
    ]);
    let mut baked = common::cube();
    for p in &mut baked.positions {
        *p = *p * 15.0 + Vec3::new(1500.0, 0.0, 800.0);
    }
    mesh.submeshes.push(baked);
    mesh.instances.push(horizon_mesh::Instance {
        submesh: 1,
        transform: Affine3A::IDENTITY,
    });
    mesh.submeshes.push(common::cube());
    for x in [10.0, 20.0] {
        mesh.instances.push(horizon_mesh::Instance {
            submesh: 2,
            transform: Affine3A::from_translation(Vec3::new(x, 0.0, 5.0)),
        });
    }
    let tolerance = 1e-3;
    let options = ExportOptions::aggregate(tolerance);
    let json = json_of(&export_glb(&mesh, &options).expect("exports"));
    let float = float_positions();
    assert_eq!(position_types(&json), BTreeSet::from([5123]));
    let positions: Vec<u64> = primitive_attributes(&json)
        .iter()
        .map(|a| a["POSITION"].as_u64().expect("position"))
        .collect();
    assert_eq!(positions[0], positions[2], "the cubes share a run");
    assert_ne!(positions[0], positions[1], "the baked geometry has its own");
    // The nodes of the two cubes: each scaled by the step of their run's grid, a unit cube's
    // (1 / 65535, rounded up to two digits).
    let nodes = json["nodes"].as_array().expect("nodes");
    let instanced = |mesh_index: u64| {
        nodes
            .iter()
            .find(|n| n["mesh"].as_u64() == Some(mesh_index))
            .expect("node")
    };
    for m in [0, 2] {
        let scale = &instanced(m)["scale"];
        assert_eq!(
            scale,
            &serde_json::json!([0.000016, 0.000016, 0.000016]),
            "{m}"
        );
    }
    let attributes = |m: u64| &instanced(m)["extensions"]["EXT_mesh_gpu_instancing"]["attributes"];
    assert!(
        attributes(0).get("SCALE").is_some(),
        "stretched and mirrored"
    );
    assert!(attributes(2).get("SCALE").is_none(), "unit scale");
    let back = reimport_with(&mesh, &options);
    let exact = reimport_with(&mesh, &float);
    let (worst, magnitude) = placed_vertex_error("parts and baked", &exact, &back);
    assert!(
        worst <= tolerance + 4.0 * f32::EPSILON * magnitude,
        "{worst}"
    );
}

#[test]
fn submeshes_of_one_layout_share_one_run_of_vertex_accessors() {
    // Three cubes with normals and one without, each placed twice: the three share one
    // position and one normal accessor, the fourth (another layout) has its own; every
    // primitive keeps its own 16-bit index accessor.
    let mut mesh = cubes(&[
        Affine3A::IDENTITY,
        Affine3A::from_translation(Vec3::X * 2.0),
    ]);
    let mut bare = common::cube();
    bare.normals = None;
    for (k, sub) in [mesh.submeshes[0].clone(), mesh.submeshes[0].clone(), bare]
        .into_iter()
        .enumerate()
    {
        mesh.submeshes.push(sub);
        for x in [0.0, 2.0] {
            mesh.instances.push(horizon_mesh::Instance {
                submesh: k + 1,
                transform: Affine3A::from_translation(Vec3::new(x, 3.0 * (k + 1) as f32, 0.0)),
            });
        }
    }
    let glb = export_glb(&mesh, &ExportOptions::parts()).expect("exports");
    let json = json_of(&glb);
    let attributes = primitive_attributes(&json);
    assert_eq!(attributes.len(), 4);
    assert_eq!(attributes[0], attributes[1]);
    assert_eq!(attributes[0], attributes[2]);
    assert_ne!(attributes[0]["POSITION"], attributes[3]["POSITION"]);
    assert!(attributes[3].get("NORMAL").is_none());
    let position = attributes[0]["POSITION"].as_u64().expect("index") as usize;
    assert_eq!(json["accessors"][position]["count"], 24, "three cubes of 8");
    let indices: Vec<u64> = json["meshes"]
        .as_array()
        .expect("meshes")
        .iter()
        .map(|m| m["primitives"][0]["indices"].as_u64().expect("indices"))
        .collect();
    let distinct: BTreeSet<u64> = indices.iter().copied().collect();
    assert_eq!(distinct.len(), 4, "one index accessor per primitive");
    assert_eq!(index_types(&json), [5123; 4]);
    // Three fewer vertex accessors than without sharing (two positions, two normals, less
    // nothing for the lone layout), so the JSON is shorter.
    let alone = json_of(&export_glb(&mesh, &ExportOptions::plain()).expect("exports"));
    let count = |j: &serde_json::Value| j["accessors"].as_array().expect("accessors").len();
    assert_eq!(count(&alone) - count(&json), 4);
    // What the mesh means survives exactly.
    let back = import_bytes(&glb, Format::Glb, None, &ImportOptions::default())
        .expect("re-imports")
        .mesh;
    for (a, b) in mesh.submeshes.iter().zip(&back.submeshes) {
        assert!(a.positions == b.positions && a.indices == b.indices);
        assert_eq!(a.normals.is_some(), b.normals.is_some());
    }
    assert_eq!(transforms_by_submesh(&back), transforms_by_submesh(&mesh));
}

/// A strip of `n` vertices along x, its triangles (i, i + 1, i + 2).
fn strip(n: u32, y: f32) -> horizon_mesh::Submesh {
    horizon_mesh::Submesh {
        positions: (0..n)
            .map(|i| Vec3::new(i as f32 * 0.01, y + (i % 2) as f32, 0.0))
            .collect(),
        indices: (0..n - 2).flat_map(|i| [i, i + 1, i + 2]).collect(),
        ..Default::default()
    }
}

#[test]
fn a_run_closes_before_it_would_pass_65535_vertices() {
    // Three strips of 30,000 vertices: the first two fill one run (60,000), the third would
    // take it to 90,000 and starts its own. Every index stays 16-bit.
    let mesh = InstancedMesh {
        submeshes: (0..3).map(|k| strip(30_000, 2.0 * k as f32)).collect(),
        instances: (0..3)
            .flat_map(|k| {
                [0.0, 100.0].map(|x| horizon_mesh::Instance {
                    submesh: k,
                    transform: Affine3A::from_translation(Vec3::Z * x),
                })
            })
            .collect(),
        ..Default::default()
    };
    let glb = export_glb(&mesh, &ExportOptions::parts()).expect("exports");
    let json = json_of(&glb);
    let attributes = primitive_attributes(&json);
    assert_eq!(attributes[0], attributes[1]);
    assert_ne!(attributes[1]["POSITION"], attributes[2]["POSITION"]);
    assert_eq!(index_types(&json), [5123; 3]);
    let back = import_bytes(&glb, Format::Glb, None, &ImportOptions::default())
        .expect("re-imports")
        .mesh;
    for (a, b) in mesh.submeshes.iter().zip(&back.submeshes) {
        assert!(a.positions == b.positions && a.indices == b.indices);
    }
}
