//! glTF features the importer must read: strips, fans, non-indexed primitives, sparse
//! accessors, KHR_mesh_quantization, EXT_mesh_gpu_instancing with normalized rotations,
//! node hierarchies, points and lines, and the PLY, OBJ and STL formats.

mod common;

use common::{f32_bytes, Fixture};
use glam::{Affine3A, Quat, Vec3};
use horizon_mesh::{import_bytes, Format, ImportOptions};
use serde_json::json;

fn opts() -> ImportOptions {
    ImportOptions::default()
}

#[test]
fn shared_mesh_nodes_become_one_submesh_with_two_instances() {
    let mut f = Fixture::triangle();
    f.json["scenes"][0]["nodes"] = json!([0, 1]);
    f.json["nodes"] = json!([{"mesh": 0}, {"mesh": 0, "translation": [2, 0, 0]}]);
    let m = f.import().expect("imports").mesh;
    assert_eq!((m.submeshes.len(), m.instances.len()), (1, 2));
    assert_eq!(
        m.instances[1].transform.translation,
        Vec3::new(2.0, 0.0, 0.0).into()
    );
}

#[test]
fn transforms_are_products_from_the_root() {
    // Parent scales by 2, child translates by 1 along x: the child's origin lands at x = 2.
    let mut f = Fixture::triangle();
    f.json["nodes"] =
        json!([{"scale": [2, 2, 2], "children": [1]}, {"mesh": 0, "translation": [1, 0, 0]}]);
    let m = f.import().expect("imports").mesh;
    let t = m.instances[0].transform;
    assert!((t.transform_point3(Vec3::ZERO) - Vec3::new(2.0, 0.0, 0.0)).length() < 1e-6);
    assert!((t.transform_vector3(Vec3::X) - Vec3::new(2.0, 0.0, 0.0)).length() < 1e-6);
}

#[test]
fn without_a_default_scene_every_scene_is_walked() {
    let mut f = Fixture::triangle();
    f.json.as_object_mut().expect("object").remove("scene");
    f.json["scenes"] = json!([{"nodes": [0]}, {"nodes": [0]}]);
    assert_eq!(f.import().expect("imports").mesh.instances.len(), 2);
}

#[test]
fn strips_fans_and_non_indexed_primitives_triangulate() {
    // Four vertices: a strip or fan of them is two triangles; unindexed as a list, one.
    let quad = f32_bytes(&[0., 0., 0., 1., 0., 0., 0., 1., 0., 1., 1., 0.]);
    for (mode, expected) in [(5, 2), (6, 2), (4, 1)] {
        let mut f = Fixture::triangle();
        let a = f.add_accessor(&quad, 5126, 4, "VEC3");
        f.json["meshes"][0]["primitives"] = json!([{"attributes": {"POSITION": a}, "mode": mode}]);
        let m = f.import().expect("imports").mesh;
        assert_eq!(m.expanded_triangle_count(), expected, "mode {mode}");
    }
}

#[test]
fn points_and_lines_are_skipped_and_counted() {
    let mut f = Fixture::triangle();
    let prim = f.json["meshes"][0]["primitives"][0].clone();
    let mut points = prim.clone();
    points["mode"] = json!(0);
    let mut lines = prim.clone();
    lines["mode"] = json!(1);
    f.json["meshes"][0]["primitives"] = json!([prim, points, lines]);
    let imported = f.import().expect("imports");
    assert_eq!(imported.skipped_non_triangle, 2);
    assert_eq!(imported.mesh.submeshes.len(), 1);
    assert!(imported
        .warnings
        .iter()
        .any(|w| w.contains("2 point or line")));
}

#[test]
fn sparse_accessors_replace_their_elements() {
    // Move vertex 2 from (0,1,0) to (0,5,0) through a sparse substitution.
    let mut f = Fixture::triangle();
    let idx_off = f.append(&[2u8, 0, 0, 0]);
    let val_off = f.append(&f32_bytes(&[0.0, 5.0, 0.0]));
    let views = f.json["bufferViews"].as_array_mut().expect("array");
    views.push(json!({"buffer": 0, "byteOffset": idx_off, "byteLength": 1}));
    views.push(json!({"buffer": 0, "byteOffset": val_off, "byteLength": 12}));
    f.json["accessors"][0]["sparse"] = json!({"count": 1,
        "indices": {"bufferView": 2, "componentType": 5121},
        "values": {"bufferView": 3}});
    let m = f.import().expect("imports").mesh;
    assert_eq!(m.submeshes[0].positions[2], Vec3::new(0.0, 5.0, 0.0));
    // A sparse index past the element count is refused.
    f.bin[idx_off] = 9;
    assert_eq!(
        f.import().expect_err("out of range").kind(),
        "out_of_bounds"
    );
}

#[test]
fn quantized_positions_and_normalized_instance_rotations_are_read() {
    // KHR_mesh_quantization: u16 positions (integers, not normalized), padded to 8 bytes.
    let mut f = Fixture::triangle();
    let mut pos = Vec::new();
    for p in [[0u16, 0, 0], [100, 0, 0], [0, 100, 0]] {
        for c in p {
            pos.extend_from_slice(&c.to_le_bytes());
        }
        pos.extend_from_slice(&[0, 0]);
    }
    let off = f.append(&pos);
    f.json["bufferViews"]
        .as_array_mut()
        .expect("array")
        .push(json!({"buffer": 0, "byteOffset": off, "byteLength": 24, "byteStride": 8}));
    f.json["accessors"][0] =
        json!({"bufferView": 2, "componentType": 5123, "count": 3, "type": "VEC3"});
    // Rotation of 90 degrees about z as normalized i16: (0, 0, 0.7071, 0.7071).
    let q = (std::f32::consts::FRAC_1_SQRT_2 * 32767.0).round() as i16;
    let rot: Vec<u8> = [0i16, 0, q, q]
        .iter()
        .flat_map(|v| v.to_le_bytes())
        .collect();
    let r = f.add_accessor(&rot, 5122, 1, "VEC4");
    f.json["accessors"][r]["normalized"] = json!(true);
    f.json["nodes"][0]["extensions"] =
        json!({"EXT_mesh_gpu_instancing": {"attributes": {"ROTATION": r}}});
    f.json["extensionsRequired"] = json!(["KHR_mesh_quantization", "EXT_mesh_gpu_instancing"]);
    f.json["extensionsUsed"] = json!(["KHR_mesh_quantization", "EXT_mesh_gpu_instancing"]);
    let m = f.import().expect("imports").mesh;
    assert_eq!(m.submeshes[0].positions[1], Vec3::new(100.0, 0.0, 0.0));
    // The rotated x axis points along y.
    let t = m.instances[0].transform;
    assert!(
        (t.transform_vector3(Vec3::X) - Vec3::Y).length() < 1e-4,
        "{t:?}"
    );
}

#[test]
fn gpu_instances_compose_with_the_node_transform() {
    // Node translates by (0, 10, 0); two GPU instances translate by (1,0,0) and (2,0,0).
    let mut f = Fixture::triangle();
    let t = f.add_accessor(&f32_bytes(&[1., 0., 0., 2., 0., 0.]), 5126, 2, "VEC3");
    f.json["nodes"][0]["translation"] = json!([0, 10, 0]);
    f.json["nodes"][0]["extensions"] =
        json!({"EXT_mesh_gpu_instancing": {"attributes": {"TRANSLATION": t}}});
    let m = f.import().expect("imports").mesh;
    let origins: Vec<Vec3> = m
        .instances
        .iter()
        .map(|i| i.transform.transform_point3(Vec3::ZERO))
        .collect();
    assert_eq!(
        origins,
        vec![Vec3::new(1.0, 10.0, 0.0), Vec3::new(2.0, 10.0, 0.0)]
    );
}

#[test]
fn unused_vertices_are_dropped_per_primitive() {
    // Two primitives share one 4-vertex accessor, each using 3 of the vertices.
    let quad = f32_bytes(&[0., 0., 0., 1., 0., 0., 0., 1., 0., 1., 1., 0.]);
    let mut f = Fixture::triangle();
    let p = f.add_accessor(&quad, 5126, 4, "VEC3");
    let i1 = f.add_accessor(&[0, 0, 1, 0, 2, 0], 5123, 3, "SCALAR");
    let i2 = f.add_accessor(&[1, 0, 3, 0, 2, 0], 5123, 3, "SCALAR");
    f.json["meshes"][0]["primitives"] = json!([
        {"attributes": {"POSITION": p}, "indices": i1},
        {"attributes": {"POSITION": p}, "indices": i2}]);
    let m = f.import().expect("imports").mesh;
    assert_eq!(
        m.submeshes
            .iter()
            .map(|s| s.positions.len())
            .collect::<Vec<_>>(),
        vec![3, 3]
    );
    // The second keeps old vertices 1, 2, 3 in their original order, so old 3 is new 2.
    assert_eq!(m.submeshes[1].positions[2], Vec3::new(1.0, 1.0, 0.0));
    assert_eq!(m.submeshes[1].indices, vec![0, 2, 1]);
}

#[test]
fn ply_obj_and_stl_import() {
    // A unit square as two triangles in each format.
    let ply = b"ply\nformat ascii 1.0\nelement vertex 4\nproperty float x\nproperty float y\nproperty float z\nelement face 1\nproperty list uchar int vertex_indices\nend_header\n0 0 0\n1 0 0\n1 1 0\n0 1 0\n4 0 1 2 3\n";
    let obj =
        b"v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nvt 0 0\nvt 1 0\nvt 1 1\nvt 0 1\nf 1/1 2/2 3/3 4/4\n";
    let mut stl = vec![0u8; 80];
    stl.extend_from_slice(&2u32.to_le_bytes());
    for tri in [
        [[0., 0., 0.], [1., 0., 0.], [1., 1., 0.]],
        [[0., 0., 0.], [1., 1., 0.], [0., 1., 0.]],
    ] {
        stl.extend_from_slice(&f32_bytes(&[0., 0., 1.]));
        for v in tri {
            stl.extend_from_slice(&f32_bytes(&v));
        }
        stl.extend_from_slice(&[0, 0]);
    }
    for (bytes, format) in [
        (&ply[..], Format::Ply),
        (&obj[..], Format::Obj),
        (&stl[..], Format::Stl),
    ] {
        let m = import_bytes(bytes, format, None, &opts())
            .expect("imports")
            .mesh;
        assert_eq!(m.expanded_triangle_count(), 2, "{format:?}");
        let b = m.bounds();
        assert_eq!(
            (b.min, b.max),
            (Vec3::ZERO, Vec3::new(1.0, 1.0, 0.0)),
            "{format:?}"
        );
        assert_eq!(Format::detect(None, bytes).expect("detects"), format);
    }
    // OBJ's V axis is flipped into glTF's convention.
    let m = import_bytes(obj, Format::Obj, None, &opts())
        .expect("imports")
        .mesh;
    let s = &m.submeshes[0];
    let k = s
        .positions
        .iter()
        .position(|p| *p == Vec3::ZERO)
        .expect("origin");
    assert_eq!(s.uvs.as_ref().expect("uvs")[k], glam::Vec2::new(0.0, 1.0));
}

#[test]
fn expansion_places_every_instance() {
    let mesh = common::cubes(&[
        Affine3A::IDENTITY,
        Affine3A::from_rotation_translation(Quat::from_rotation_y(1.0), Vec3::X * 5.0),
    ]);
    let e = mesh.expand();
    assert_eq!(e.indices.len() / 3, 24);
    assert_eq!(e.positions.len(), 16);
    assert!(e.positions.iter().any(|p| p.x > 4.0));
}
