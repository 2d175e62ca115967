//! Shared fixtures: a tiny glTF built in code, GLB assembly, and transform comparison.
#![allow(dead_code)]

use glam::{Affine3A, Mat4, Vec3};
use horizon_mesh::{
    import_bytes, Format, ImportError, ImportOptions, Imported, Instance, InstancedMesh, Submesh,
};
use serde_json::{json, Value};

/// A glTF document with one triangle (positions f32, indices u16) under one node, plus its
/// binary buffer. Tests mutate the JSON or the bytes to make each kind of bad input.
pub struct Fixture {
    pub json: Value,
    pub bin: Vec<u8>,
}

impl Fixture {
    /// The triangle (0,0,0), (1,0,0), (0,1,0): 36 bytes of positions then 6 of indices.
    pub fn triangle() -> Self {
        let mut bin = Vec::new();
        for p in [[0.0f32, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]] {
            for c in p {
                bin.extend_from_slice(&c.to_le_bytes());
            }
        }
        for i in [0u16, 1, 2] {
            bin.extend_from_slice(&i.to_le_bytes());
        }
        bin.extend_from_slice(&[0, 0]);
        let json = json!({
            "asset": {"version": "2.0"},
            "scene": 0,
            "scenes": [{"nodes": [0]}],
            "nodes": [{"mesh": 0}],
            "meshes": [{"primitives": [{"attributes": {"POSITION": 0}, "indices": 1}]}],
            "accessors": [
                {"bufferView": 0, "componentType": 5126, "count": 3, "type": "VEC3",
                 "min": [0, 0, 0], "max": [1, 1, 0]},
                {"bufferView": 1, "componentType": 5123, "count": 3, "type": "SCALAR"}
            ],
            "bufferViews": [
                {"buffer": 0, "byteOffset": 0, "byteLength": 36},
                {"buffer": 0, "byteOffset": 36, "byteLength": 6}
            ],
            "buffers": [{"byteLength": 44}]
        });
        Self { json, bin }
    }

    /// Appends bytes to the buffer (4-byte aligned) and returns their offset.
    pub fn append(&mut self, bytes: &[u8]) -> usize {
        while !self.bin.len().is_multiple_of(4) {
            self.bin.push(0);
        }
        let offset = self.bin.len();
        self.bin.extend_from_slice(bytes);
        self.json["buffers"][0]["byteLength"] = json!(self.bin.len());
        offset
    }

    /// Adds a buffer view and an accessor over `bytes`; returns the accessor index.
    pub fn add_accessor(
        &mut self,
        bytes: &[u8],
        component_type: u32,
        count: usize,
        ty: &str,
    ) -> usize {
        let offset = self.append(bytes);
        let views = self.json["bufferViews"].as_array_mut().expect("array");
        views.push(json!({"buffer": 0, "byteOffset": offset, "byteLength": bytes.len()}));
        let view = views.len() - 1;
        let accessors = self.json["accessors"].as_array_mut().expect("array");
        accessors.push(json!({"bufferView": view, "componentType": component_type, "count": count, "type": ty}));
        accessors.len() - 1
    }

    pub fn glb(&self) -> Vec<u8> {
        glb(&self.json, &self.bin)
    }

    pub fn import(&self) -> Result<Imported, ImportError> {
        import_bytes(&self.glb(), Format::Glb, None, &ImportOptions::default())
    }
}

/// Assembles a GLB from a JSON document and a binary chunk.
pub fn glb(json: &Value, bin: &[u8]) -> Vec<u8> {
    let glb = gltf::Glb {
        header: gltf::binary::Header {
            magic: *b"glTF",
            version: 2,
            length: 0,
        },
        json: serde_json::to_vec(json).expect("serialises").into(),
        bin: Some(bin.to_vec().into()),
    };
    glb.to_vec().expect("assembles")
}

pub fn f32_bytes(values: &[f32]) -> Vec<u8> {
    values.iter().flat_map(|v| v.to_le_bytes()).collect()
}

/// Largest absolute difference between two transforms, relative to the larger magnitude.
pub fn relative_difference(a: &Affine3A, b: &Affine3A) -> f32 {
    let (a, b) = (
        Mat4::from(*a).to_cols_array(),
        Mat4::from(*b).to_cols_array(),
    );
    let scale = a.iter().chain(&b).fold(1e-30f32, |m, x| m.max(x.abs()));
    a.iter()
        .zip(&b)
        .fold(0.0f32, |m, (x, y)| m.max((x - y).abs()))
        / scale
}

/// A unit cube (12 triangles) with normals per corner, as a submesh with no material.
pub fn cube() -> Submesh {
    let positions: Vec<Vec3> = (0..8)
        .map(|i| Vec3::new((i & 1) as f32, ((i >> 1) & 1) as f32, ((i >> 2) & 1) as f32))
        .collect();
    let normals = positions.iter().map(|p| (*p - 0.5).normalize()).collect();
    // Two triangles per face, counter-clockwise seen from outside.
    let indices = vec![
        0, 2, 1, 1, 2, 3, // z = 0
        4, 5, 6, 5, 7, 6, // z = 1
        0, 1, 4, 1, 5, 4, // y = 0
        2, 6, 3, 3, 6, 7, // y = 1
        0, 4, 2, 2, 4, 6, // x = 0
        1, 3, 5, 3, 7, 5, // x = 1
    ];
    Submesh {
        positions,
        normals: Some(normals),
        indices,
        ..Default::default()
    }
}

/// One cube placed at each transform.
pub fn cubes(transforms: &[Affine3A]) -> InstancedMesh {
    InstancedMesh {
        submeshes: vec![cube()],
        instances: transforms
            .iter()
            .map(|&transform| Instance {
                submesh: 0,
                transform,
            })
            .collect(),
        ..Default::default()
    }
}
