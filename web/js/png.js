// A PNG reader for the orthoview images, which must be read exactly: 16-bit depth and two-byte
// normals that the browser's image decoding would round to 8 bits or premultiply. The browser
// still does the inflating (DecompressionStream); this file only walks the chunks and undoes
// the row filters (PNG spec, sections 5 and 9). Non-interlaced, 8 or 16 bits, grey, grey and
// alpha, RGB or RGBA: what `Orthoview::encode` writes.

const SIGNATURE = [137, 80, 78, 71, 13, 10, 26, 10];
const CHANNELS = { 0: 1, 2: 3, 4: 2, 6: 4 };

/**
 * Decodes `bytes` (an ArrayBuffer or Uint8Array).
 * @returns {Promise<{width: number, height: number, channels: number, bits: number,
 *   data: Uint8Array | Uint16Array}>} samples row by row, channel by channel
 */
export async function decodePng(bytes) {
  const b = bytes instanceof Uint8Array ? bytes : new Uint8Array(bytes);
  if (b.length < 8 || SIGNATURE.some((v, i) => b[i] !== v)) throw new Error('not a PNG');
  const view = new DataView(b.buffer, b.byteOffset, b.byteLength);
  let width = 0, height = 0, bits = 0, type = -1;
  const idat = [];
  for (let at = 8; at + 8 <= b.length; ) {
    const length = view.getUint32(at);
    const name = String.fromCharCode(b[at + 4], b[at + 5], b[at + 6], b[at + 7]);
    const body = b.subarray(at + 8, at + 8 + length);
    if (name === 'IHDR') {
      width = view.getUint32(at + 8);
      height = view.getUint32(at + 12);
      bits = b[at + 16];
      type = b[at + 17];
      if (b[at + 20] !== 0) throw new Error('interlaced PNGs are not read');
    } else if (name === 'IDAT') {
      idat.push(body);
    } else if (name === 'IEND') {
      break;
    }
    at += 12 + length;
  }
  const channels = CHANNELS[type];
  if (!channels || (bits !== 8 && bits !== 16) || width === 0 || height === 0) {
    throw new Error(`PNG of colour type ${type} and ${bits} bits is not read`);
  }
  const raw = await inflate(idat);
  const bpp = channels * (bits / 8);
  const stride = width * bpp;
  if (raw.length < height * (stride + 1)) throw new Error('PNG data is truncated');
  const out = new Uint8Array(height * stride);
  for (let y = 0; y < height; y++) {
    const filter = raw[y * (stride + 1)];
    const src = raw.subarray(y * (stride + 1) + 1, (y + 1) * (stride + 1));
    const row = out.subarray(y * stride, (y + 1) * stride);
    const up = y > 0 ? out.subarray((y - 1) * stride, y * stride) : null;
    for (let i = 0; i < stride; i++) {
      const a = i >= bpp ? row[i - bpp] : 0;
      const c = up && i >= bpp ? up[i - bpp] : 0;
      const u = up ? up[i] : 0;
      let p;
      switch (filter) {
        case 0: p = 0; break;
        case 1: p = a; break;
        case 2: p = u; break;
        case 3: p = (a + u) >> 1; break;
        case 4: {
          const pa = Math.abs(u - c), pb = Math.abs(a - c), pc = Math.abs(a + u - 2 * c);
          p = pa <= pb && pa <= pc ? a : pb <= pc ? u : c;
          break;
        }
        default: throw new Error(`PNG row filter ${filter}`);
      }
      row[i] = (src[i] + p) & 255;
    }
  }
  let data = out;
  if (bits === 16) {
    data = new Uint16Array(out.length / 2);
    for (let i = 0; i < data.length; i++) data[i] = (out[2 * i] << 8) | out[2 * i + 1];
  }
  return { width, height, channels, bits, data };
}

/** The zlib stream of the IDAT chunks, inflated by the browser. */
async function inflate(parts) {
  const stream = new Blob(parts).stream().pipeThrough(new DecompressionStream('deflate'));
  return new Uint8Array(await new Response(stream).arrayBuffer());
}
