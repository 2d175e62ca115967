//! Textures, images, samplers and materials (glTF's metallic-roughness model, with
//! KHR_texture_transform for UV transforms). Images are stored in the binary chunk in their
//! encoded form; textures with the same wrap modes share a sampler.

use std::collections::BTreeMap;

use serde_json::{json, Map, Value};

use super::json::{number, numbers};
use super::writer::GlbWriter;
use crate::model::{AlphaMode, Material, Texture, Wrap};

impl GlbWriter {
    /// Each texture as an image in the binary chunk, a texture and a sampler shared by the
    /// textures of its wrap modes.
    pub(super) fn write_textures(&mut self, textures: &[Texture]) {
        let mut sampler_of: BTreeMap<(u32, u32), usize> = BTreeMap::new();
        for t in textures {
            self.align_bin();
            let offset = self.bin.len();
            self.bin.extend_from_slice(&t.bytes);
            self.buffer_views.push(json!({
                "buffer": 0, "byteOffset": offset, "byteLength": t.bytes.len(),
            }));
            self.images.push(json!({
                "bufferView": self.buffer_views.len() - 1,
                "mimeType": t.mime_type,
            }));
            let key = (wrap_code(t.wrap_u), wrap_code(t.wrap_v));
            let next = sampler_of.len();
            let sampler = *sampler_of.entry(key).or_insert(next);
            if sampler == self.samplers.len() {
                self.samplers
                    .push(json!({ "wrapS": key.0, "wrapT": key.1 }));
            }
            self.textures.push(json!({
                "source": self.images.len() - 1,
                "sampler": sampler,
            }));
        }
    }

    /// One material, its factors clamped to the ranges glTF allows.
    pub(super) fn write_material(&mut self, m: &Material) {
        let unit = |x: f32| x.clamp(0.0, 1.0);
        let mut pbr = Map::new();
        pbr.insert(
            "baseColorFactor".into(),
            numbers(&m.base_color_factor.to_array().map(unit)),
        );
        if let Some(t) = &m.base_color_texture {
            let mut info = json!({ "index": t.texture });
            if let Some(x) = &t.transform {
                self.extensions_used.insert("KHR_texture_transform");
                info["extensions"] = json!({"KHR_texture_transform": {
                    "offset": numbers(&x.offset.to_array()),
                    "rotation": number(x.rotation),
                    "scale": numbers(&x.scale.to_array()),
                }});
            }
            pbr.insert("baseColorTexture".into(), info);
        }
        pbr.insert("metallicFactor".into(), number(unit(m.metallic_factor)));
        pbr.insert("roughnessFactor".into(), number(unit(m.roughness_factor)));
        let mut out = Map::new();
        if let Some(name) = &m.name {
            out.insert("name".into(), json!(name));
        }
        out.insert("pbrMetallicRoughness".into(), Value::Object(pbr));
        match m.alpha_mode {
            AlphaMode::Opaque => {}
            AlphaMode::Mask { cutoff } => {
                out.insert("alphaMode".into(), json!("MASK"));
                out.insert("alphaCutoff".into(), number(cutoff.max(0.0)));
            }
            AlphaMode::Blend => {
                out.insert("alphaMode".into(), json!("BLEND"));
            }
        }
        if m.double_sided {
            out.insert("doubleSided".into(), json!(true));
        }
        self.materials.push(Value::Object(out));
    }
}

/// A glTF sampler's wrap mode code.
fn wrap_code(w: Wrap) -> u32 {
    match w {
        Wrap::Repeat => 10497,
        Wrap::MirroredRepeat => 33648,
        Wrap::ClampToEdge => 33071,
    }
}
