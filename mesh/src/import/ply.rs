//! PLY import (ASCII or binary), through the `ply-rs-bw` crate. Reads the `vertex` element
//! (x, y, z; optional normals, texture coordinates and colours) and the `face` element's
//! `vertex_indices` (or `vertex_index`) lists, fanning polygons into triangles.

use glam::{Vec2, Vec3, Vec4};
use ply_rs_bw::parser::Parser;
use ply_rs_bw::ply::{DefaultElement, Property};

use super::stl::single_instance;
use super::{ImportOptions, Imported};
use crate::error::ImportError;
use crate::model::Submesh;

pub(crate) fn import(bytes: &[u8], _options: &ImportOptions) -> Result<Imported, ImportError> {
    let mut source = bytes;
    let ply = Parser::<DefaultElement>::new()
        .read_ply(&mut source)
        .map_err(|e| ImportError::Parse {
            format: "PLY",
            reason: e.to_string().lines().next().unwrap_or("").to_owned(),
        })?;
    let no_vertices = Vec::new();
    let vertices = ply.payload.get("vertex").unwrap_or(&no_vertices);
    // Stage 1: vertex attributes, by the property names common writers use.
    let scalar =
        |v: &DefaultElement, names: &[&str]| names.iter().find_map(|n| v.get(*n).and_then(as_f64));
    let mut positions = Vec::with_capacity(vertices.len());
    let mut normals = Vec::new();
    let mut uvs = Vec::new();
    let mut colors = Vec::new();
    for v in vertices {
        let p = [&["x"][..], &["y"], &["z"]].map(|n| scalar(v, n));
        let [Some(x), Some(y), Some(z)] = p else {
            return Err(ImportError::Parse {
                format: "PLY",
                reason: "a vertex lacks x, y or z".into(),
            });
        };
        positions.push(Vec3::new(x as f32, y as f32, z as f32));
        if let [Some(x), Some(y), Some(z)] = [&["nx"][..], &["ny"], &["nz"]].map(|n| scalar(v, n)) {
            normals.push(Vec3::new(x as f32, y as f32, z as f32));
        }
        let uv = [&["s", "u", "texture_u"][..], &["t", "v", "texture_v"]].map(|n| scalar(v, n));
        if let [Some(s), Some(t)] = uv {
            // PLY texture coordinates have their origin at the bottom left; glTF's is top left.
            uvs.push(Vec2::new(s as f32, 1.0 - t as f32));
        }
        let rgba = [&["red"][..], &["green"], &["blue"], &["alpha"]].map(|n| v.get(n[0]));
        if let [Some(r), Some(g), Some(b), a] = rgba {
            let unit = |p: &Property| match p {
                Property::UChar(c) => f32::from(*c) / 255.0,
                other => as_f64(other).unwrap_or(1.0) as f32,
            };
            colors.push(Vec4::new(unit(r), unit(g), unit(b), a.map_or(1.0, unit)));
        }
    }
    if positions.iter().any(|p| !p.is_finite()) {
        return Err(ImportError::NonFinite("PLY vertex position".into()));
    }
    // Stage 2: faces, fanned into triangles.
    let mut indices = Vec::new();
    for face in ply.payload.get("face").into_iter().flatten() {
        let list = face
            .get("vertex_indices")
            .or_else(|| face.get("vertex_index"))
            .ok_or_else(|| ImportError::Parse {
                format: "PLY",
                reason: "a face has no vertex_indices list".into(),
            })?;
        let polygon = as_index_list(list)?;
        for &i in &polygon {
            if i < 0 || i as usize >= positions.len() {
                return Err(ImportError::IndexOutOfRange {
                    what: "PLY face".into(),
                    index: i as u64,
                    vertices: positions.len(),
                });
            }
        }
        for k in 1..polygon.len().saturating_sub(1) {
            indices.extend([polygon[0], polygon[k], polygon[k + 1]].map(|i| i as u32));
        }
    }
    // An attribute counts only if every vertex has it.
    let complete = |len: usize| len == positions.len() && len > 0;
    let submesh = Submesh {
        normals: complete(normals.len()).then_some(normals),
        uvs: complete(uvs.len()).then_some(uvs),
        colors: complete(colors.len()).then_some(colors),
        positions,
        indices,
        material: None,
    };
    Ok(Imported {
        mesh: single_instance(submesh),
        ..Default::default()
    })
}

fn as_f64(p: &Property) -> Option<f64> {
    Some(match *p {
        Property::Char(v) => f64::from(v),
        Property::UChar(v) => f64::from(v),
        Property::Short(v) => f64::from(v),
        Property::UShort(v) => f64::from(v),
        Property::Int(v) => f64::from(v),
        Property::UInt(v) => f64::from(v),
        Property::Float(v) => f64::from(v),
        Property::Double(v) => v,
        _ => return None,
    })
}

fn as_index_list(p: &Property) -> Result<Vec<i64>, ImportError> {
    Ok(match p {
        Property::ListChar(v) => v.iter().map(|&i| i64::from(i)).collect(),
        Property::ListUChar(v) => v.iter().map(|&i| i64::from(i)).collect(),
        Property::ListShort(v) => v.iter().map(|&i| i64::from(i)).collect(),
        Property::ListUShort(v) => v.iter().map(|&i| i64::from(i)).collect(),
        Property::ListInt(v) => v.iter().map(|&i| i64::from(i)).collect(),
        Property::ListUInt(v) => v.iter().map(|&i| i64::from(i)).collect(),
        _ => {
            return Err(ImportError::Parse {
                format: "PLY",
                reason: "face indices are not an integer list".into(),
            })
        }
    })
}
