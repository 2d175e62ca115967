//! meshoptimizer's vertex codec for strides known only at run time.
//!
//! The `meshopt` crate encodes and decodes slices of a type whose size is the stride; glTF
//! strides are any multiple of 4 up to 256 (EXT_meshopt_compression), so each supported stride
//! gets its own byte-array type.

/// A vertex of `N` opaque bytes.
#[derive(Clone, Copy, Debug)]
struct Chunk<const N: usize>([u8; N]);

impl<const N: usize> Default for Chunk<N> {
    fn default() -> Self {
        Self([0; N])
    }
}

fn decode_chunks<const N: usize>(encoded: &[u8], count: usize) -> meshopt::Result<Vec<u8>> {
    let chunks: Vec<Chunk<N>> = meshopt::decode_vertex_buffer(encoded, count)?;
    Ok(chunks.iter().flat_map(|c| c.0).collect())
}

fn encode_chunks<const N: usize>(bytes: &[u8]) -> meshopt::Result<Vec<u8>> {
    let chunks: Vec<Chunk<N>> = bytes
        .chunks_exact(N)
        .map(|c| Chunk(std::array::from_fn(|i| c[i])))
        .collect();
    // Version 0 of the vertex codec is the one EXT_meshopt_compression specifies.
    meshopt::encode_vertex_buffer_level(&chunks, 2, Some(0))
}

macro_rules! by_stride {
    ($stride:expr, $f:ident($($arg:expr),*)) => {
        match $stride {
            4 => $f::<4>($($arg),*), 8 => $f::<8>($($arg),*), 12 => $f::<12>($($arg),*),
            16 => $f::<16>($($arg),*), 20 => $f::<20>($($arg),*), 24 => $f::<24>($($arg),*),
            28 => $f::<28>($($arg),*), 32 => $f::<32>($($arg),*), 36 => $f::<36>($($arg),*),
            40 => $f::<40>($($arg),*), 44 => $f::<44>($($arg),*), 48 => $f::<48>($($arg),*),
            52 => $f::<52>($($arg),*), 56 => $f::<56>($($arg),*), 60 => $f::<60>($($arg),*),
            64 => $f::<64>($($arg),*), 68 => $f::<68>($($arg),*), 72 => $f::<72>($($arg),*),
            76 => $f::<76>($($arg),*), 80 => $f::<80>($($arg),*), 84 => $f::<84>($($arg),*),
            88 => $f::<88>($($arg),*), 92 => $f::<92>($($arg),*), 96 => $f::<96>($($arg),*),
            100 => $f::<100>($($arg),*), 104 => $f::<104>($($arg),*), 108 => $f::<108>($($arg),*),
            112 => $f::<112>($($arg),*), 116 => $f::<116>($($arg),*), 120 => $f::<120>($($arg),*),
            124 => $f::<124>($($arg),*), 128 => $f::<128>($($arg),*), 132 => $f::<132>($($arg),*),
            136 => $f::<136>($($arg),*), 140 => $f::<140>($($arg),*), 144 => $f::<144>($($arg),*),
            148 => $f::<148>($($arg),*), 152 => $f::<152>($($arg),*), 156 => $f::<156>($($arg),*),
            160 => $f::<160>($($arg),*), 164 => $f::<164>($($arg),*), 168 => $f::<168>($($arg),*),
            172 => $f::<172>($($arg),*), 176 => $f::<176>($($arg),*), 180 => $f::<180>($($arg),*),
            184 => $f::<184>($($arg),*), 188 => $f::<188>($($arg),*), 192 => $f::<192>($($arg),*),
            196 => $f::<196>($($arg),*), 200 => $f::<200>($($arg),*), 204 => $f::<204>($($arg),*),
            208 => $f::<208>($($arg),*), 212 => $f::<212>($($arg),*), 216 => $f::<216>($($arg),*),
            220 => $f::<220>($($arg),*), 224 => $f::<224>($($arg),*), 228 => $f::<228>($($arg),*),
            232 => $f::<232>($($arg),*), 236 => $f::<236>($($arg),*), 240 => $f::<240>($($arg),*),
            244 => $f::<244>($($arg),*), 248 => $f::<248>($($arg),*), 252 => $f::<252>($($arg),*),
            256 => $f::<256>($($arg),*),
            other => Err(meshopt::Error::Memory(format!("unsupported vertex stride {other}").into())),
        }
    };
}

/// Decodes `count` vertices of `stride` bytes.
pub(crate) fn decode_vertex_stream(
    encoded: &[u8],
    count: usize,
    stride: usize,
) -> meshopt::Result<Vec<u8>> {
    by_stride!(stride, decode_chunks(encoded, count))
}

/// Encodes tightly packed vertices of `stride` bytes (`bytes.len()` a multiple of it).
pub(crate) fn encode_vertex_stream(bytes: &[u8], stride: usize) -> meshopt::Result<Vec<u8>> {
    by_stride!(stride, encode_chunks(bytes))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn streams_round_trip_for_every_stride_class() {
        // Any bytes survive encode then decode unchanged: the codec is lossless.
        for stride in [4usize, 12, 16, 100, 256] {
            let count = 37;
            let bytes: Vec<u8> = (0..stride * count).map(|i| (i * 7 % 251) as u8).collect();
            let encoded = encode_vertex_stream(&bytes, stride).expect("encodes");
            let decoded = decode_vertex_stream(&encoded, count, stride).expect("decodes");
            assert_eq!(decoded, bytes, "stride {stride}");
        }
    }
}
