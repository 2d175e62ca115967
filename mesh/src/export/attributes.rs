//! Accessor data: glTF's component types and buffer view targets, and [`Attribute`], the packed
//! elements of one vertex or instance attribute with what its accessor says about them. Float
//! attributes are built here; the normalized and quantized integer forms in `quantize.rs`.

/// glTF component types and buffer view targets.
pub(super) const FLOAT: u32 = 5126;
pub(super) const UNSIGNED_SHORT: u32 = 5123;
pub(super) const UNSIGNED_INT: u32 = 5125;
pub(super) const BYTE: u32 = 5120;
pub(super) const SHORT: u32 = 5122;
pub(super) const ARRAY_BUFFER: u32 = 34962;
pub(super) const ELEMENT_ARRAY_BUFFER: u32 = 34963;

/// A vertex attribute ready to write: tightly packed elements of `stride` bytes.
pub(super) struct Attribute {
    pub(super) bytes: Vec<u8>,
    pub(super) stride: usize,
    pub(super) component_type: u32,
    pub(super) normalized: bool,
    pub(super) type_name: &'static str,
    pub(super) count: usize,
    pub(super) bounds: Option<(Vec<f32>, Vec<f32>)>,
}

/// Float vectors of any width, tightly packed; with `bounds`, min and max per component.
pub(super) fn float_attribute<const N: usize>(
    values: impl Iterator<Item = [f32; N]>,
    bounds: bool,
) -> Attribute {
    let mut bytes = Vec::new();
    let mut lo = [f32::INFINITY; N];
    let mut hi = [f32::NEG_INFINITY; N];
    let mut count = 0;
    for v in values {
        for c in 0..N {
            bytes.extend_from_slice(&v[c].to_le_bytes());
            lo[c] = lo[c].min(v[c]);
            hi[c] = hi[c].max(v[c]);
        }
        count += 1;
    }
    Attribute {
        bytes,
        stride: 4 * N,
        component_type: FLOAT,
        normalized: false,
        type_name: type_name(N),
        count,
        bounds: (bounds && count > 0).then(|| (lo.to_vec(), hi.to_vec())),
    }
}

/// The accessor type of `n` components.
pub(super) fn type_name(n: usize) -> &'static str {
    match n {
        1 => "SCALAR",
        2 => "VEC2",
        3 => "VEC3",
        _ => "VEC4",
    }
}
