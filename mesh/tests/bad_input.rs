//! Every kind of bad input gets its own typed error, never a panic. Each test breaks one thing
//! in an otherwise valid file, so the error kind it asserts can only come from that one thing.

mod common;

use common::{f32_bytes, glb, Fixture};
use horizon_mesh::{import_bytes, import_file, Format, ImportError, ImportOptions, Limit, Limits};
use serde_json::json;

fn kind(result: Result<horizon_mesh::Imported, ImportError>) -> &'static str {
    match result {
        Ok(_) => "accepted",
        Err(e) => {
            // Every message is one line, fit to hand to a user.
            assert!(!e.to_string().contains('\n'), "{e}");
            e.kind()
        }
    }
}

#[test]
fn the_fixture_itself_is_valid() {
    // Without this, every test below could pass on a fixture that is always refused.
    let imported = Fixture::triangle().import().expect("valid fixture");
    assert_eq!(imported.mesh.expanded_triangle_count(), 1);
}

#[test]
fn truncated_glb_is_truncated() {
    let bytes = Fixture::triangle().glb();
    // Cut inside the binary chunk: the header still declares the full length.
    let cut = &bytes[..bytes.len() - 10];
    assert_eq!(
        kind(import_bytes(
            cut,
            Format::Glb,
            None,
            &ImportOptions::default()
        )),
        "truncated"
    );
    // Cut inside the 12-byte header.
    assert_eq!(
        kind(import_bytes(
            &bytes[..7],
            Format::Glb,
            None,
            &ImportOptions::default()
        )),
        "truncated"
    );
}

#[test]
fn garbage_and_wrong_magic_are_bad_magic() {
    let garbage: Vec<u8> = (0..500u32).map(|i| (i * 97 % 251) as u8 + 1).collect();
    assert_eq!(
        kind(import_bytes(
            &garbage,
            Format::Glb,
            None,
            &ImportOptions::default()
        )),
        "bad_magic"
    );
    let mut bytes = Fixture::triangle().glb();
    bytes[3] = b'X'; // "glTX"
    assert_eq!(
        kind(import_bytes(
            &bytes,
            Format::Glb,
            None,
            &ImportOptions::default()
        )),
        "bad_magic"
    );
}

#[test]
fn broken_json_is_json() {
    let bytes = br#"{"asset": {"version": "2.0"}, "nodes": [ "#;
    assert_eq!(
        kind(import_bytes(
            bytes,
            Format::Gltf,
            None,
            &ImportOptions::default()
        )),
        "json"
    );
    // Well-formed JSON that breaks the schema (a node's mesh is a string).
    let mut f = Fixture::triangle();
    f.json["nodes"][0]["mesh"] = json!("zero");
    assert_eq!(kind(f.import()), "json");
}

#[test]
fn accessor_past_its_buffer_view_is_out_of_bounds() {
    let mut f = Fixture::triangle();
    f.json["accessors"][0]["count"] = json!(4); // 48 bytes in a 36-byte view
    assert_eq!(kind(f.import()), "out_of_bounds");
}

#[test]
fn buffer_view_past_its_buffer_is_out_of_bounds() {
    let mut f = Fixture::triangle();
    f.json["bufferViews"][1]["byteOffset"] = json!(1000);
    assert_eq!(kind(f.import()), "out_of_bounds");
}

#[test]
fn huge_offsets_do_not_overflow() {
    let mut f = Fixture::triangle();
    f.json["bufferViews"][0]["byteOffset"] = json!(u64::MAX - 4);
    assert_eq!(kind(f.import()), "out_of_bounds");
}

#[test]
fn index_past_the_vertex_count_is_index_out_of_range() {
    let mut f = Fixture::triangle();
    f.bin[36 + 4..36 + 6].copy_from_slice(&3u16.to_le_bytes()); // third index = 3, only 3 vertices
    assert_eq!(kind(f.import()), "index_out_of_range");
}

#[test]
fn missing_references_are_missing_reference() {
    let mut f = Fixture::triangle();
    f.json["meshes"][0]["primitives"][0]["attributes"]["POSITION"] = json!(7);
    assert_eq!(kind(f.import()), "missing_reference");
    let mut f = Fixture::triangle();
    f.json["scenes"][0]["nodes"] = json!([5]);
    assert_eq!(kind(f.import()), "missing_reference");
}

#[test]
fn nan_position_is_non_finite() {
    let mut f = Fixture::triangle();
    f.bin[0..4].copy_from_slice(&f32::NAN.to_le_bytes());
    assert_eq!(kind(f.import()), "non_finite");
}

#[test]
fn infinite_node_transform_is_non_finite() {
    let mut f = Fixture::triangle();
    // 1e39 does not fit in an f32; it parses as infinity.
    f.json["nodes"][0]["translation"] = json!([1e39, 0, 0]);
    assert_eq!(kind(f.import()), "non_finite");
    let mut f = Fixture::triangle();
    let mut m = [0.0f64; 16];
    m[0] = 1e39;
    f.json["nodes"][0]["matrix"] = json!(m);
    assert_eq!(kind(f.import()), "non_finite");
}

#[test]
fn nan_gpu_instance_transform_is_non_finite() {
    let mut f = Fixture::triangle();
    let a = f.add_accessor(
        &f32_bytes(&[0.0, 0.0, 0.0, f32::NAN, 0.0, 0.0]),
        5126,
        2,
        "VEC3",
    );
    f.json["nodes"][0]["extensions"] =
        json!({"EXT_mesh_gpu_instancing": {"attributes": {"TRANSLATION": a}}});
    assert_eq!(kind(f.import()), "non_finite");
}

#[test]
fn node_cycle_is_node_cycle() {
    let mut f = Fixture::triangle();
    f.json["nodes"] = json!([{"mesh": 0, "children": [1]}, {"children": [0]}]);
    assert_eq!(kind(f.import()), "node_cycle");
    // A node that is its own child.
    let mut f = Fixture::triangle();
    f.json["nodes"] = json!([{"mesh": 0, "children": [0]}]);
    assert_eq!(kind(f.import()), "node_cycle");
}

#[test]
fn a_shared_child_is_not_a_cycle() {
    // Nodes 0 and 1 both hold node 2: a DAG, drawn twice, not a cycle.
    let mut f = Fixture::triangle();
    f.json["scenes"][0]["nodes"] = json!([0, 1]);
    f.json["nodes"] =
        json!([{"children": [2]}, {"children": [2], "translation": [5, 0, 0]}, {"mesh": 0}]);
    let imported = f.import().expect("a DAG is fine");
    assert_eq!(imported.mesh.instances.len(), 2);
}

#[test]
fn remote_and_escaping_uris_are_forbidden() {
    for uri in [
        "http://example.com/a.bin",
        "https://example.com/a.bin",
        "../outside.bin",
        "/etc/passwd",
    ] {
        let mut f = Fixture::triangle();
        f.json["buffers"][0]["uri"] = json!(uri);
        let bytes = serde_json::to_vec(&f.json).expect("json");
        let dir = std::env::temp_dir();
        let result = import_bytes(&bytes, Format::Gltf, Some(&dir), &ImportOptions::default());
        assert_eq!(kind(result), "forbidden_uri", "{uri}");
    }
}

#[test]
fn a_symlink_out_of_the_folder_is_forbidden() {
    let dir = std::env::temp_dir().join(format!("horizon-symlink-{}", std::process::id()));
    std::fs::create_dir_all(&dir).expect("temp dir");
    let outside = std::env::temp_dir().join(format!("horizon-outside-{}.bin", std::process::id()));
    std::fs::write(&outside, Fixture::triangle().bin).expect("write");
    let link = dir.join("inside.bin");
    let _ = std::fs::remove_file(&link);
    std::os::unix::fs::symlink(&outside, &link).expect("symlink");
    let mut f = Fixture::triangle();
    f.json["buffers"][0]["uri"] = json!("inside.bin");
    let path = dir.join("model.gltf");
    std::fs::write(&path, serde_json::to_vec(&f.json).expect("json")).expect("write");
    assert_eq!(
        kind(import_file(&path, &ImportOptions::default())),
        "forbidden_uri"
    );
    // The same file, really inside the folder, is read.
    std::fs::remove_file(&link).expect("unlink");
    std::fs::copy(&outside, &link).expect("copy");
    assert_eq!(
        kind(import_file(&path, &ImportOptions::default())),
        "accepted"
    );
    let _ = std::fs::remove_dir_all(&dir);
    let _ = std::fs::remove_file(&outside);
}

/// A material whose base colour texture is the given image bytes.
fn with_image(bytes: &[u8], mime: &str) -> Fixture {
    let mut f = Fixture::triangle();
    let offset = f.append(bytes);
    f.json["bufferViews"]
        .as_array_mut()
        .expect("array")
        .push(json!({"buffer": 0, "byteOffset": offset, "byteLength": bytes.len()}));
    let view = f.json["bufferViews"].as_array().expect("array").len() - 1;
    f.json["images"] = json!([{"bufferView": view, "mimeType": mime}]);
    f.json["textures"] = json!([{"source": 0}]);
    f.json["materials"] = json!([{"pbrMetallicRoughness": {"baseColorTexture": {"index": 0}}}]);
    f.json["meshes"][0]["primitives"][0]["material"] = json!(0);
    f
}

fn png(width: u32, height: u32) -> Vec<u8> {
    let img = image::RgbaImage::from_pixel(width, height, image::Rgba([200, 100, 50, 255]));
    let mut out = std::io::Cursor::new(Vec::new());
    img.write_to(&mut out, image::ImageFormat::Png)
        .expect("encodes");
    out.into_inner()
}

#[test]
fn an_image_that_fails_to_decode_is_image_decode() {
    // A valid PNG signature and header followed by a corrupt body.
    let mut bytes = png(8, 8);
    let body = bytes.len() - 20;
    for b in &mut bytes[40..body] {
        *b ^= 0x5A;
    }
    assert_eq!(
        kind(with_image(&bytes, "image/png").import()),
        "image_decode"
    );
    // Not an image at all.
    assert_eq!(
        kind(with_image(b"this is not an image", "image/png").import()),
        "image_decode"
    );
    // A good image is accepted, so the failures above come from the bytes.
    assert_eq!(
        kind(with_image(&png(8, 8), "image/png").import()),
        "accepted"
    );
}

#[test]
fn every_limit_is_enforced() {
    let strict = |edit: fn(&mut Limits)| {
        let mut limits = Limits::default();
        edit(&mut limits);
        ImportOptions {
            limits,
            ..Default::default()
        }
    };
    let bytes = with_image(&png(16, 16), "image/png").glb();
    let import = |o: ImportOptions| import_bytes(&bytes, Format::Glb, None, &o);
    let limit = |o: ImportOptions| import(o).err().and_then(|e| e.limit());
    assert_eq!(limit(strict(|l| l.max_bytes = 100)), Some(Limit::Bytes));
    assert_eq!(
        limit(strict(|l| l.max_triangles = 0)),
        Some(Limit::Triangles)
    );
    assert_eq!(
        limit(strict(|l| l.max_instances = 0)),
        Some(Limit::Instances)
    );
    assert_eq!(limit(strict(|l| l.max_textures = 0)), Some(Limit::Textures));
    assert_eq!(
        limit(strict(|l| l.max_texture_pixels = 255)),
        Some(Limit::Textures)
    );
    assert_eq!(
        limit(strict(|l| l.max_texture_side = 15)),
        Some(Limit::Textures)
    );
    assert_eq!(
        kind(import(strict(|l| l.max_texture_side = 15))),
        "limit_exceeded"
    );
    // At exactly the sizes of this file every limit passes: 1 triangle, 1 instance, 256 px,
    // 16 px a side.
    let exact = ImportOptions {
        limits: Limits {
            max_bytes: bytes.len() as u64,
            max_triangles: 1,
            max_instances: 1,
            max_textures: 1,
            max_texture_pixels: 256,
            max_texture_side: 16,
        },
        ..Default::default()
    };
    assert_eq!(kind(import(exact)), "accepted");
}

#[test]
fn an_instance_bomb_stops_at_the_instance_limit() {
    // A chain of 40 nodes each holding the next twice would be 2^40 placements.
    let mut f = Fixture::triangle();
    let nodes: Vec<_> = (0..40)
        .map(|i| json!({"children": [i + 1, i + 1]}))
        .chain([json!({"mesh": 0})])
        .collect();
    f.json["nodes"] = json!(nodes);
    assert_eq!(kind(f.import()), "limit_exceeded");
}

#[test]
fn unsupported_required_extension_is_unsupported() {
    let mut f = Fixture::triangle();
    f.json["extensionsRequired"] = json!(["KHR_draco_mesh_compression"]);
    f.json["extensionsUsed"] = json!(["KHR_draco_mesh_compression"]);
    assert_eq!(kind(f.import()), "unsupported");
}

#[test]
fn bad_ply_obj_and_stl_are_parse_errors_or_index_errors() {
    let opts = ImportOptions::default();
    let ply = b"ply\nformat ascii 1.0\nelement vertex 1\nproperty float x\nproperty float y\nproperty float z\nelement face 1\nproperty list uchar int vertex_indices\nend_header\n0 0 0\n3 0 1 2\n";
    assert_eq!(
        kind(import_bytes(ply, Format::Ply, None, &opts)),
        "index_out_of_range"
    );
    assert_eq!(
        kind(import_bytes(
            b"ply\nformat nonsense\n",
            Format::Ply,
            None,
            &opts
        )),
        "parse"
    );
    assert_eq!(
        kind(import_bytes(
            b"solid x\nfacet normal oops\n",
            Format::Stl,
            None,
            &opts
        )),
        "parse"
    );
    // Face indices past the vertices.
    let obj = b"v 0 0 0\nv 1 0 0\nf 1 2 9\n";
    let k = kind(import_bytes(obj, Format::Obj, None, &opts));
    assert!(k == "parse" || k == "index_out_of_range", "{k}");
}

#[test]
fn empty_input_is_refused_cleanly() {
    let opts = ImportOptions::default();
    for format in [Format::Glb, Format::Gltf] {
        assert_eq!(kind(import_bytes(b"", format, None, &opts)), "truncated");
    }
    assert_eq!(
        kind(import_bytes(
            &glb(&json!({"asset": {"version": "2.0"}}), &[]),
            Format::Glb,
            None,
            &opts
        )),
        "accepted"
    );
}
