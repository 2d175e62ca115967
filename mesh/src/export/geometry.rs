//! Geometry: each submesh as a glTF mesh of one primitive, its vertex attributes in a run of its
//! own or shared with other submeshes of its layout (`vertex_runs.rs`), and its indices.
//!
//! Positions are float, or 16-bit integers on their run's grid where the tolerance allows
//! (`quantize.rs`). With short attributes normals are 8-bit, and UVs in [0, 1] and colours
//! 16-bit normalized integers (KHR_mesh_quantization); otherwise floats. A primitive's indices
//! are 16-bit whenever its vertex accessors have at most 65,535 elements.

use glam::{Affine3A, Vec3, Vec4};
use serde_json::{json, Map, Value};

use super::attributes::{
    float_attribute, Attribute, ARRAY_BUFFER, ELEMENT_ARRAY_BUFFER, UNSIGNED_INT, UNSIGNED_SHORT,
};
use super::compression::{optimise_order, Encoding};
use super::quantize::{grid, norm16_attribute, quantized_attribute, snorm8_attribute, Dequantize};
use super::writer::GlbWriter;
use crate::error::ExportError;
use crate::model::Submesh;

/// The vertex accessors of a shared run, where each member's vertices start in them, and how
/// its positions map back to model space.
pub(super) struct SharedRun {
    pub(super) attributes: Map<String, Value>,
    pub(super) bases: Vec<u32>,
    pub(super) count: usize,
    pub(super) dequantize: Dequantize,
}

impl GlbWriter {
    /// Writes one submesh as a glTF mesh and returns how its stored positions map back to model
    /// space.
    pub(super) fn write_submesh(
        &mut self,
        s: &Submesh,
        placed: &[Affine3A],
    ) -> Result<Dequantize, ExportError> {
        // Stage 1: vertex order; compression optimises for the vertex cache and fetch.
        let (indices, order) = if self.compress {
            optimise_order(s)
        } else {
            (s.indices.clone(), (0..s.positions.len() as u32).collect())
        };
        let n = order.len();
        // Stage 2: attributes, positions quantized where the tolerance allows.
        let mut attributes = Map::new();
        let dequantize = self.write_positions(&[(s, &order, placed)], &mut attributes)?;
        self.write_other_attributes(&[(s, &order)], &mut attributes)?;
        // Stage 3: indices and the primitive.
        self.write_primitive(attributes, indices, n, s.material)?;
        Ok(dequantize)
    }

    /// The vertex attributes of `members` (one layout, each with its placements), concatenated
    /// into one accessor each, where each member's vertices start, and the run's
    /// dequantisation.
    pub(super) fn write_shared_vertices(
        &mut self,
        members: &[(&Submesh, &[Affine3A])],
    ) -> Result<SharedRun, ExportError> {
        let mut bases = Vec::with_capacity(members.len());
        let mut count = 0u32;
        for (m, _) in members {
            bases.push(count);
            count += m.positions.len() as u32;
        }
        let orders: Vec<Vec<u32>> = members
            .iter()
            .map(|(m, _)| (0..m.positions.len() as u32).collect())
            .collect();
        let placed: Vec<(&Submesh, &[u32], &[Affine3A])> = members
            .iter()
            .zip(&orders)
            .map(|(&(m, placed), order)| (m, order.as_slice(), placed))
            .collect();
        let parts: Vec<(&Submesh, &[u32])> = placed.iter().map(|&(m, o, _)| (m, o)).collect();
        let mut attributes = Map::new();
        let dequantize = self.write_positions(&placed, &mut attributes)?;
        self.write_other_attributes(&parts, &mut attributes)?;
        Ok(SharedRun {
            attributes,
            bases,
            count: count as usize,
            dequantize,
        })
    }

    /// POSITION of `parts` (one run; each submesh's vertices in the order given, placed by its
    /// transforms), one accessor over all of them: 16-bit integers over the run's box where
    /// that keeps every placed vertex within the tolerance and the dequantisation folds into
    /// every placement without overflowing f32, else floats. Returns the dequantisation.
    fn write_positions(
        &mut self,
        parts: &[(&Submesh, &[u32], &[Affine3A])],
        attributes: &mut Map<String, Value>,
    ) -> Result<Dequantize, ExportError> {
        let positions = || {
            parts
                .iter()
                .flat_map(|&(m, order, _)| order.iter().map(|&v| m.positions[v as usize]))
        };
        // The grid first, from the box alone; the positions are encoded once, on it or as
        // floats.
        let fitting = self.position_tolerance.and_then(|tolerance| {
            let d = grid(positions(), !self.compress);
            parts
                .iter()
                .all(|&(_, _, placed)| d.fits(placed, tolerance))
                .then_some(d)
        });
        let (position, dequantize) = match fitting {
            Some(d) => {
                self.quantized = true;
                (quantized_attribute(positions(), &d), d)
            }
            None => (
                float_attribute(positions().map(|p| p.to_array()), true),
                Dequantize::NONE,
            ),
        };
        let p = self.write_attribute(&position, Some(ARRAY_BUFFER))?;
        attributes.insert("POSITION".into(), json!(p));
        Ok(dequantize)
    }

    /// NORMAL, TEXCOORD_0 and COLOR_0 of `parts` (one layout; each submesh's vertices in the
    /// order given), one accessor each over all the parts: floats, or with short attributes
    /// normalized integers. UVs stay float unless every UV of every part is in [0, 1].
    fn write_other_attributes(
        &mut self,
        parts: &[(&Submesh, &[u32])],
        attributes: &mut Map<String, Value>,
    ) -> Result<(), ExportError> {
        if let Some(normals) = concatenated(parts, |m| m.normals.as_ref()) {
            let unit = normals.map(|n| n.try_normalize().unwrap_or(Vec3::Z).to_array());
            let a = self.normal_attribute(unit);
            let i = self.write_attribute(&a, Some(ARRAY_BUFFER))?;
            attributes.insert("NORMAL".into(), json!(i));
        }
        if let Some(uvs) = concatenated(parts, |m| m.uvs.as_ref()) {
            let in_unit = parts
                .iter()
                .all(|(m, _)| m.uvs.iter().flatten().all(|&t| in_unit_square(t)));
            let a = self.unit_attribute(uvs.map(|t| t.to_array()), in_unit);
            let i = self.write_attribute(&a, Some(ARRAY_BUFFER))?;
            attributes.insert("TEXCOORD_0".into(), json!(i));
        }
        if let Some(colors) = concatenated(parts, |m| m.colors.as_ref()) {
            // glTF colours live in [0, 1].
            let values = colors.map(|c| c.clamp(Vec4::ZERO, Vec4::ONE).to_array());
            let a = self.unit_attribute(values, true);
            let i = self.write_attribute(&a, Some(ARRAY_BUFFER))?;
            attributes.insert("COLOR_0".into(), json!(i));
        }
        Ok(())
    }

    /// Unit normals as written: 8-bit signed normalized with short attributes, else floats.
    fn normal_attribute(&mut self, unit: impl Iterator<Item = [f32; 3]>) -> Attribute {
        if self.short_attributes {
            self.quantized = true;
            snorm8_attribute(unit)
        } else {
            float_attribute(unit, false)
        }
    }

    /// Values in [0, 1] (`in_unit`: UVs that may not be) as written: 16-bit unsigned
    /// normalized with short attributes, else floats.
    fn unit_attribute<const N: usize>(
        &mut self,
        values: impl Iterator<Item = [f32; N]>,
        in_unit: bool,
    ) -> Attribute {
        if self.short_attributes && in_unit {
            self.quantized = true;
            norm16_attribute(values, false)
        } else {
            float_attribute(values, false)
        }
    }

    /// One glTF mesh of one primitive: `indices` into vertex accessors of `vertex_count`
    /// elements, 16-bit when every index fits below the primitive-restart value.
    pub(super) fn write_primitive(
        &mut self,
        attributes: Map<String, Value>,
        indices: Vec<u32>,
        vertex_count: usize,
        material: Option<usize>,
    ) -> Result<(), ExportError> {
        let n = vertex_count;
        let wide = n > 65535;
        let bytes: Vec<u8> = if wide {
            indices.iter().flat_map(|i| i.to_le_bytes()).collect()
        } else {
            indices
                .iter()
                .flat_map(|&i| (i as u16).to_le_bytes())
                .collect()
        };
        let view = self.add_view(
            &bytes,
            None,
            Some(ELEMENT_ARRAY_BUFFER),
            Encoding::Triangles {
                indices: &indices,
                vertex_count: n,
            },
        )?;
        let index_accessor = self.add_accessor(
            view,
            &Attribute {
                bytes: Vec::new(),
                stride: 0,
                component_type: if wide { UNSIGNED_INT } else { UNSIGNED_SHORT },
                normalized: false,
                type_name: "SCALAR",
                count: indices.len(),
                bounds: None,
            },
        );
        let mut primitive = Map::new();
        primitive.insert("attributes".into(), Value::Object(attributes));
        primitive.insert("indices".into(), json!(index_accessor));
        if let Some(m) = material {
            primitive.insert("material".into(), json!(m));
        }
        self.meshes.push(json!({ "primitives": [primitive] }));
        Ok(())
    }
}

/// The attribute `get` finds in each of `parts`, each part's vertices in its order, one part
/// after another; `None` when the first part lacks it (all parts share one layout).
fn concatenated<'p, T: Copy + 'p>(
    parts: &'p [(&'p Submesh, &'p [u32])],
    get: impl Fn(&'p Submesh) -> Option<&'p Vec<T>> + Copy + 'p,
) -> Option<impl Iterator<Item = T> + 'p> {
    get(parts.first()?.0)?;
    Some(parts.iter().flat_map(move |&(m, order)| {
        let values = get(m).expect("the parts share one layout");
        order.iter().map(move |&v| values[v as usize])
    }))
}

/// Whether a UV lies in [0, 1]^2, where 16-bit normalized integers can hold it.
fn in_unit_square(t: glam::Vec2) -> bool {
    t.cmpge(glam::Vec2::ZERO).all() && t.cmple(glam::Vec2::ONE).all()
}
