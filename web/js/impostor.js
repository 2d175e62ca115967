// Orthoview impostors (Chaudhuri et al. 2009) as the viewer draws them: every covered pixel of
// an orthoview becomes a square at its depth, perpendicular to the view's direction, lit by
// its stored normal like the geometry (the same lights, a standard material), coloured by its
// pixel. Its area is the pixel's coverage, grown to SPLAT_SCALE pixels across as the pixel
// fills (`splatSide`), so that neighbouring splats, and neighbouring cells, overlap without
// seams while thin features stay thin. The server's
// `Orthoview::splats` builds the same squares for its measurements.
//
// The frame of a view (protocol `ImpostorView`): d = normalize(direction); u = normalize(up x
// d) with up the world's y (z when d is vertical); v = d x u; pixel (0, 0)'s corner at the
// smallest u and v of the box's corners and depth 0 at its smallest d; depth 1..65535 spans
// the box along d.

import * as THREE from 'three';
import { decodePng } from './png.js';

export const SPLAT_SCALE = 1.5;

/**
 * A splat's side in pixels for a pixel covered `alpha` (0..1): of the pixel's covered area,
 * grown towards SPLAT_SCALE as the pixel fills, so that full pixels overlap their neighbours
 * (no cracks seen obliquely) and thin features keep their area.
 */
export function splatSide(alpha) {
  return Math.sqrt(alpha) * (1 + (SPLAT_SCALE - 1) * alpha * alpha);
}

const SRGB = new Float32Array(256).map((_, i) => {
  const c = i / 255;
  return c <= 0.04045 ? c / 12.92 : Math.pow((c + 0.055) / 1.055, 2.4);
});

let material = null;

/** The splats' one material: vertex colours, lit, two-sided. */
function splatMaterial() {
  if (!material) {
    material = new THREE.MeshStandardMaterial({
      vertexColors: true,
      metalness: 0,
      roughness: 1,
      side: THREE.DoubleSide,
    });
  }
  return material;
}

/**
 * Fetches a view's three images and builds its splats: the parts of an asset record (one
 * geometry in world space), and the bytes received.
 * @param {{min: number[], max: number[]}} box the impostor's box
 * @param {object} view a protocol ImpostorView
 * @param {AbortSignal} signal
 */
export async function loadView(box, view, signal) {
  const images = await Promise.all(
    [view.color, view.depth, view.normal].map(async (hash) => {
      const response = await fetch(`/assets/${hash}`, { signal });
      if (!response.ok) throw new Error(`orthoview image ${hash}: HTTP ${response.status}`);
      return response.arrayBuffer();
    }),
  );
  const received = images.reduce((n, b) => n + b.byteLength, 0);
  const [color, depth, normal] = await Promise.all(images.map(decodePng));
  const geometry = splats(box, view, color, depth, normal);
  // The material is shared by every view: disposing of a view keeps it.
  const part = { geometry, material: splatMaterial(), matrices: [new THREE.Matrix4()], shared: true };
  return { parts: [part], received };
}

/** The splats of one decoded view. */
export function splats(box, view, color, depth, normal) {
  const { width, height, pixel } = view;
  if (color.width !== width || depth.width !== width || normal.width !== width ||
      color.height !== height || depth.height !== height || normal.height !== height) {
    throw new Error('an orthoview\'s images differ in size');
  }
  const d = new THREE.Vector3(...view.direction).normalize();
  const helper = Math.abs(d.y) > 0.9 ? new THREE.Vector3(0, 0, 1) : new THREE.Vector3(0, 1, 0);
  const u = new THREE.Vector3().crossVectors(helper, d).normalize();
  const v = new THREE.Vector3().crossVectors(d, u);
  const range = (axis) => {
    let lo = Infinity, hi = -Infinity;
    for (let i = 0; i < 8; i++) {
      const c = new THREE.Vector3(
        i & 1 ? box.max[0] : box.min[0],
        i & 2 ? box.max[1] : box.min[1],
        i & 4 ? box.max[2] : box.min[2],
      );
      const x = c.dot(axis);
      lo = Math.min(lo, x);
      hi = Math.max(hi, x);
    }
    return [lo, hi];
  };
  const [u0] = range(u), [v0] = range(v), [d0, d1] = range(d);
  const extent = Math.max(d1 - d0, 0);
  let count = 0;
  for (let i = 0; i < width * height; i++) if (depth.data[i] !== 0) count++;
  const positions = new Float32Array(count * 12);
  const normals = new Float32Array(count * 12);
  const colors = new Float32Array(count * 12);
  const index = new Uint32Array(count * 6);
  const p = new THREE.Vector3(), n = new THREE.Vector3();
  let k = 0;
  for (let y = 0; y < height; y++) {
    for (let x = 0; x < width; x++) {
      const i = y * width + x;
      const z = depth.data[i];
      if (z === 0) continue;
      const t = ((z - 1) / 65534) * extent;
      p.set(0, 0, 0)
        .addScaledVector(u, u0 + (x + 0.5) * pixel)
        .addScaledVector(v, v0 + (y + 0.5) * pixel)
        .addScaledVector(d, d0 + t);
      octahedral(normal.data[2 * i], normal.data[2 * i + 1], n);
      const alpha = color.data[4 * i + 3] / 255;
      const half = 0.5 * splatSide(alpha) * pixel;
      const corners = [[-1, -1], [1, -1], [1, 1], [-1, 1]];
      for (let c = 0; c < 4; c++) {
        const o = (k * 4 + c) * 3;
        const [su, sv] = corners[c];
        positions[o] = p.x + (u.x * su + v.x * sv) * half;
        positions[o + 1] = p.y + (u.y * su + v.y * sv) * half;
        positions[o + 2] = p.z + (u.z * su + v.z * sv) * half;
        normals[o] = n.x;
        normals[o + 1] = n.y;
        normals[o + 2] = n.z;
        colors[o] = SRGB[color.data[4 * i]];
        colors[o + 1] = SRGB[color.data[4 * i + 1]];
        colors[o + 2] = SRGB[color.data[4 * i + 2]];
      }
      // Wound to face against the direction: towards a viewer looking along it (a back
      // face would have its normal turned round by a two-sided material).
      const b = k * 4;
      index.set([b, b + 2, b + 1, b, b + 3, b + 2], k * 6);
      k++;
    }
  }
  const geometry = new THREE.BufferGeometry();
  geometry.setAttribute('position', new THREE.BufferAttribute(positions, 3));
  geometry.setAttribute('normal', new THREE.BufferAttribute(normals, 3));
  geometry.setAttribute('color', new THREE.BufferAttribute(colors, 3));
  geometry.setIndex(new THREE.BufferAttribute(index, 1));
  geometry.computeBoundingSphere();
  return geometry;
}

/** A unit vector from two octahedral bytes (Cigolle et al. 2014), into `out`. */
function octahedral(a, b, out) {
  const px = (a / 255) * 2 - 1, py = (b / 255) * 2 - 1;
  const z = 1 - Math.abs(px) - Math.abs(py);
  let x = px, y = py;
  if (z < 0) {
    x = (1 - Math.abs(py)) * (px >= 0 ? 1 : -1);
    y = (1 - Math.abs(px)) * (py >= 0 ? 1 : -1);
  }
  out.set(x, y, z);
  if (out.lengthSq() === 0) out.set(0, 1, 0);
  return out.normalize();
}
