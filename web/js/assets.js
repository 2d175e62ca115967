// Immutable, content-addressed assets (`GET /assets/{hash}`): fetched through a small pool of
// concurrent requests, the most visible first; a request nobody wants any more is cancelled;
// what has loaded stays in an LRU cache under a memory budget while nothing draws it.
//
// An asset is a GLB, or an impostor's orthoview (three images, `impostor.js`). Loaded, it is a
// list of parts: a geometry, a material and the part's matrices inside the asset (several when
// the GLB instances it), ready to be instanced at any placement.

import * as THREE from 'three';
import { GLTFLoader } from 'three/addons/loaders/GLTFLoader.js';
import { MeshoptDecoder } from 'three/addons/libs/meshopt_decoder.module.js';
import { loadView } from './impostor.js';

/**
 * The key an impostor's orthoview is kept under: its three images, direction and box (two
 * views may share a colour image and stand elsewhere).
 */
export function viewKey(view, box) {
  return `orthoview:${view.color}:${view.depth}:${view.normal}:${view.direction}:${box.min}:${box.max}`;
}

export class AssetStore {
  /**
   * @param {object} options
   * @param {number} options.concurrency requests in flight at most
   * @param {number} options.budgetBytes memory the cache may hold for assets nothing uses
   * @param {() => {x: number, y: number, z: number}} options.eye where the viewer is, to rank
   */
  constructor({ concurrency = 6, budgetBytes = 768 << 20, eye }) {
    this.concurrency = concurrency;
    this.budgetBytes = budgetBytes;
    this.eye = eye;
    this.loader = new GLTFLoader();
    this.loader.setMeshoptDecoder(MeshoptDecoder);
    /** @type {Map<string, AssetRecord>} */
    this.records = new Map();
    this.active = 0;
    this.bytesReceived = 0;
    this.heldBytes = 0;
    this.peakHeldBytes = 0;
    this.clock = 0;
  }

  /**
   * Asks for `hash` on behalf of `user` (an object with `center` and `radius`, used to rank the
   * request). Resolves with the loaded asset; rejects if it fails or is cancelled.
   */
  want(hash, user, { first = false, view = null, box = null } = {}) {
    let r = this.records.get(hash);
    if (!r) {
      r = new AssetRecord(hash);
      this.records.set(hash, r);
    }
    // An orthoview (asked for by `viewKey`) is built from its images and its impostor's box.
    if (view) {
      r.view = view;
      r.box = box;
    }
    r.users.add(user);
    if (first) r.first = true;
    r.lastUsed = ++this.clock;
    if (r.state === 'failed' || r.state === 'cancelled') {
      r.reset();
    }
    const promise = r.promise;
    this.pump();
    return promise;
  }

  /** Whether `hash` has loaded (and is still held). */
  isLoaded(hash) {
    return this.records.get(hash)?.state === 'ready';
  }

  /** `user` no longer needs `hash`: a request nobody wants is cancelled. */
  release(hash, user) {
    const r = this.records.get(hash);
    if (!r) return;
    r.users.delete(user);
    r.lastUsed = ++this.clock;
    if (r.users.size > 0) return;
    if (r.state === 'queued' || r.state === 'loading') {
      if (r.controller) r.controller.abort();
      r.cancel();
      this.records.delete(hash);
    }
    this.evict();
  }

  /** Requests waiting or in flight. */
  get pending() {
    let n = 0;
    for (const r of this.records.values()) {
      if (r.state === 'queued' || r.state === 'loading') n++;
    }
    return n;
  }

  /** Starts the best-ranked queued requests while the pool has room. */
  pump() {
    while (this.active < this.concurrency) {
      const next = this.best();
      if (!next) return;
      this.start(next);
    }
  }

  /**
   * The queued request whose nearest user looks largest from the eye; previews (asked for with
   * `first`) before everything else.
   */
  best() {
    const eye = this.eye();
    let best = null;
    let bestScore = -Infinity;
    let bestFirst = false;
    for (const r of this.records.values()) {
      if (r.state !== 'queued') continue;
      if (bestFirst && !r.first) continue;
      let score = -Infinity;
      for (const u of r.users) {
        const dx = u.center[0] - eye.x, dy = u.center[1] - eye.y, dz = u.center[2] - eye.z;
        const d2 = Math.max(dx * dx + dy * dy + dz * dz, 1e-6);
        score = Math.max(score, (u.radius * u.radius) / d2);
      }
      if ((r.first && !bestFirst) || score > bestScore) {
        bestScore = score;
        best = r;
        bestFirst = Boolean(r.first);
      }
    }
    return best;
  }

  async start(r) {
    r.state = 'loading';
    r.controller = new AbortController();
    this.active++;
    try {
      if (r.view) {
        const { parts, received } = await loadView(r.box, r.view, r.controller.signal);
        this.bytesReceived += received;
        if (r.state !== 'loading') {
          disposeParts(parts);
          return;
        }
        this.finish(r, parts);
        return;
      }
      const response = await fetch(`/assets/${r.hash}`, { signal: r.controller.signal });
      if (!response.ok) throw new Error(`asset ${r.hash}: HTTP ${response.status}`);
      const buffer = await response.arrayBuffer();
      this.bytesReceived += buffer.byteLength;
      if (r.state !== 'loading') return;
      const gltf = await this.loader.parseAsync(buffer, '');
      if (r.state !== 'loading') {
        disposeParts(partsOf(gltf.scene));
        return;
      }
      this.finish(r, partsOf(gltf.scene));
    } catch (error) {
      if (r.state === 'loading') {
        r.state = 'failed';
        r.reject(error);
      }
    } finally {
      this.active--;
      this.evict();
      this.pump();
    }
  }

  /** `r` has loaded as `parts`. */
  finish(r, parts) {
    r.parts = parts;
    r.bytes = memoryOf(r.parts);
    r.state = 'ready';
    this.heldBytes += r.bytes;
    this.peakHeldBytes = Math.max(this.peakHeldBytes, this.heldBytes);
    r.resolve(r);
  }

  /** Frees the least recently used assets nothing draws until the cache is under budget. */
  evict() {
    if (this.heldBytes <= this.budgetBytes) return;
    const idle = [...this.records.values()]
      .filter((r) => r.state === 'ready' && r.users.size === 0)
      .sort((a, b) => a.lastUsed - b.lastUsed);
    for (const r of idle) {
      if (this.heldBytes <= this.budgetBytes) break;
      disposeParts(r.parts);
      this.heldBytes -= r.bytes;
      this.records.delete(r.hash);
    }
  }
}

class AssetRecord {
  constructor(hash) {
    this.hash = hash;
    this.users = new Set();
    this.parts = null;
    this.bytes = 0;
    this.lastUsed = 0;
    this.controller = null;
    this.view = null;
    this.box = null;
    this.reset();
  }

  reset() {
    this.state = 'queued';
    this.promise = new Promise((resolve, reject) => {
      this.resolve = resolve;
      this.reject = reject;
    });
    // A cancelled or failed request rejects; whoever still listens handles it.
    this.promise.catch(() => {});
  }

  cancel() {
    this.state = 'cancelled';
    this.reject(new DOMException('no longer in the cut', 'AbortError'));
  }
}

/**
 * The meshes of a loaded glTF scene, each with its matrices within the scene: one per node, or
 * one per instance of a node instanced by EXT_mesh_gpu_instancing (an aggregate's repeated
 * parts), which GLTFLoader reads as an InstancedMesh.
 */
function partsOf(scene) {
  scene.updateMatrixWorld(true);
  const parts = [];
  const instance = new THREE.Matrix4();
  scene.traverse((node) => {
    if (!node.isMesh) return;
    const matrices = [];
    if (node.isInstancedMesh) {
      for (let i = 0; i < node.count; i++) {
        node.getMatrixAt(i, instance);
        matrices.push(new THREE.Matrix4().multiplyMatrices(node.matrixWorld, instance));
      }
    } else {
      matrices.push(node.matrixWorld.clone());
    }
    parts.push({ geometry: node.geometry, material: node.material, matrices });
  });
  return parts;
}

/** An estimate of what parts hold in memory: vertex and index buffers, textures with mips. */
function memoryOf(parts) {
  let bytes = 0;
  const seen = new Set();
  for (const p of parts) {
    if (!seen.has(p.geometry)) {
      seen.add(p.geometry);
      for (const a of Object.values(p.geometry.attributes)) bytes += a.array.byteLength;
      if (p.geometry.index) bytes += p.geometry.index.array.byteLength;
    }
    for (const t of texturesOf(p.material)) {
      if (seen.has(t)) continue;
      seen.add(t);
      const image = t.image;
      if (image && image.width) bytes += Math.round(image.width * image.height * 4 * 4 / 3);
    }
  }
  return bytes;
}

function texturesOf(material) {
  const materials = Array.isArray(material) ? material : [material];
  const out = [];
  for (const m of materials) {
    for (const v of Object.values(m)) {
      if (v && v.isTexture) out.push(v);
    }
  }
  return out;
}

function disposeParts(parts) {
  if (!parts) return;
  for (const p of parts) {
    p.geometry.dispose();
    if (p.shared) continue;
    for (const t of texturesOf(p.material)) t.dispose();
    (Array.isArray(p.material) ? p.material : [p.material]).forEach((m) => m.dispose());
  }
}
