//! STL import (ASCII or binary), through the `stl_io` crate. STL has one unindexed triangle
//! soup with face normals; `stl_io` merges equal vertices, and we keep no normals since face
//! normals would be wrong at every smooth vertex.

use std::io::Cursor;

use glam::Vec3;

use super::{ImportOptions, Imported};
use crate::error::ImportError;
use crate::model::{Instance, InstancedMesh, Submesh};

/// Whether `bytes` has the exact size a binary STL declares: an 80-byte header, a triangle
/// count, and 50 bytes per triangle.
pub(crate) fn looks_binary(bytes: &[u8]) -> bool {
    bytes.len() >= 84
        && u64::from(u32::from_le_bytes([
            bytes[80], bytes[81], bytes[82], bytes[83],
        ])) * 50
            + 84
            == bytes.len() as u64
}

pub(crate) fn import(bytes: &[u8], _options: &ImportOptions) -> Result<Imported, ImportError> {
    let parsed = stl_io::read_stl(&mut Cursor::new(bytes)).map_err(|e| ImportError::Parse {
        format: "STL",
        reason: e.to_string(),
    })?;
    let positions: Vec<Vec3> = parsed.vertices.iter().map(|v| Vec3::from(v.0)).collect();
    if positions.iter().any(|p| !p.is_finite()) {
        return Err(ImportError::NonFinite("STL vertex position".into()));
    }
    let mut indices = Vec::with_capacity(parsed.faces.len() * 3);
    for face in &parsed.faces {
        for &v in &face.vertices {
            if v >= positions.len() {
                return Err(ImportError::IndexOutOfRange {
                    what: "STL face".into(),
                    index: v as u64,
                    vertices: positions.len(),
                });
            }
            indices.push(v as u32);
        }
    }
    Ok(Imported {
        mesh: single_instance(Submesh {
            positions,
            indices,
            ..Default::default()
        }),
        ..Default::default()
    })
}

/// A model of one submesh placed once, as the single-mesh formats give. Vertices no triangle
/// uses are dropped, as the glTF importer does, so every importer yields the same model.
pub(crate) fn single_instance(mut submesh: Submesh) -> InstancedMesh {
    compact_submesh(&mut submesh);
    InstancedMesh {
        submeshes: vec![submesh],
        instances: vec![Instance {
            submesh: 0,
            transform: glam::Affine3A::IDENTITY,
        }],
        ..Default::default()
    }
}

/// Drops the vertices no triangle uses from a submesh whose indices are already checked.
pub(crate) fn compact_submesh(s: &mut Submesh) {
    let kept = super::compact_vertices(&mut s.indices, s.positions.len());
    if kept.len() == s.positions.len() {
        return;
    }
    s.positions = super::gather(&s.positions, &kept);
    if let Some(v) = &mut s.normals {
        *v = super::gather(v, &kept);
    }
    if let Some(v) = &mut s.uvs {
        *v = super::gather(v, &kept);
    }
    if let Some(v) = &mut s.colors {
        *v = super::gather(v, &kept);
    }
}
