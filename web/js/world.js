// The viewer's copy of the cut (DESIGN.md, "Entries and cuts" and "WebSocket messages"), drawn
// with load before drop:
//
// - an entry added by a delta loads its assets; until then, the entries it `replaces` stay
//   drawn (they retire);
// - a retiring entry is dropped once everything that replaces it has loaded: its replacers
//   appear together and it fades out over FADE_MS;
// - an entry removed before it was ever drawn hands what it was replacing on to whatever
//   replaces it, so a chain of quick changes never opens a hole.
//
// An object entry whose own level of detail is not loaded yet is drawn with its model's
// coarsest level (its `preview` asset, fetched first) in the meantime, then swapped.
//
// Placements of one asset are drawn as one InstancedMesh per part of the asset, across all the
// entries that show it; mirrored placements (negative determinant) get their own, under a
// mirroring parent, so that three.js turns the winding round.

import * as THREE from 'three';
import { viewKey } from './assets.js';

export const FADE_MS = 250;

// The mirror that mirrored placements are drawn under; instance matrices get its inverse.
const MIRROR = new THREE.Matrix4().makeScale(-1, 1, 1);

export class World {
  constructor(scene, assets) {
    this.scene = scene;
    this.assets = assets;
    /** @type {Map<string, Entry>} every entry drawn, loading, retiring or fading */
    this.entries = new Map();
    /** ids of the entries in the current cut */
    this.current = new Set();
    this.objects = 0;
    /** additions that reused a held entry's assets and placements */
    this.reused = 0;
    this.generation = null;
    this.published = null;
    this.batches = new Map();
    this.dirty = false;
    this.root = new THREE.Group();
    this.mirrored = new THREE.Group();
    this.mirrored.matrixAutoUpdate = false;
    this.mirrored.matrix.copy(MIRROR);
    this.root.add(this.mirrored);
    this.scene.add(this.root);
    this.failures = 0;
    this.changed = false;
  }

  /** A reset: the whole cut anew. What was drawn stays until all of it has loaded. */
  applyReset(message) {
    this.header(message);
    const old = [...this.current];
    this.current.clear();
    const added = message.entries.map((data) => this.add(data, []));
    for (const id of old) {
      const e = this.entries.get(id);
      if (!e) continue;
      if (e.visible) {
        this.retire(e, added);
      } else {
        this.dispose(e);
      }
    }
    for (const a of added) a.replaces = old.filter((id) => this.entries.get(id)?.state === 'retiring');
    this.settle();
  }

  /** A delta: additions load; removals retire until what replaces them has loaded. */
  applyDelta(message) {
    this.header(message);
    const added = message.add.map((data) => this.add(this.withPlacements(data), data.replaces || []));
    // An id both removed and added is the same content with new counts (an aggregate whose
    // `covers` changed when an object went pending): it was updated in place.
    const again = new Set(message.add.map((a) => a.id));
    for (const { id, reason } of message.remove) {
      if (again.has(id)) continue;
      const e = this.entries.get(id);
      this.current.delete(id);
      if (!e) continue;
      // What stands in for it: the additions that name it, or, if none does (the tree moved
      // under it), everything this delta adds.
      let replacers = added.filter((a) => a.replaces.includes(id));
      if (replacers.length === 0) replacers = added;
      if (reason === 'deleted' || replacers.length === 0) {
        // A deleted object goes at once, as does anything nothing replaces.
        this.handOn(e, []);
        this.dispose(e);
      } else if (!e.visible) {
        this.handOn(e, replacers);
        this.dispose(e);
      } else {
        this.retire(e, replacers);
      }
    }
    this.settle();
  }

  /**
   * An addition's data with its assets and placements: those it sent, or, where it `reuses` a
   * held entry's (instances whose models moved to other levels), that entry's with the named
   * assets renamed.
   */
  withPlacements(data) {
    if (!data.reuses) return data;
    const held = this.entries.get(data.reuses.entry);
    if (!held) throw new Error(`${data.id} reuses the placements of ${data.reuses.entry}, which is not held`);
    this.reused += 1;
    const renamed = new Map(data.reuses.assets.map((r) => [r.from, r]));
    const assets = held.data.assets.map((a) => {
      const r = renamed.get(a.hash);
      return r ? { ...a, hash: r.to, bytes: r.bytes } : a;
    });
    const placements = held.data.placements.map((p) => ({ asset: renamed.get(p.asset)?.to ?? p.asset, matrix: p.matrix }));
    return { ...data, assets, placements };
  }

  header(message) {
    this.generation = message.generation;
    this.published = message.published;
    this.objects = message.objects;
    this.stoppedBy = message.stopped_by ?? null;
  }

  add(data, replaces) {
    const existing = this.entries.get(data.id);
    if (existing && existing.state !== 'fading') {
      // The same content, still held (its counts may have changed) or retiring: it is simply
      // current again, with the new counts.
      existing.data = data;
      existing.center = data.center;
      existing.radius = data.radius;
      if (existing.state === 'retiring') existing.state = 'shown';
      existing.replacers = new Set();
      existing.replaces = [];
      this.current.add(data.id);
      return existing;
    }
    if (existing) this.dispose(existing);
    const e = new Entry(data, replaces);
    this.entries.set(e.id, e);
    this.current.add(e.id);
    const hashes = [...new Set(data.assets.filter((a) => a.role !== 'orthoview' && a.role !== 'preview').map((a) => a.hash))];
    // An impostor's assets are its views, each loaded from its three images.
    const views = data.impostor ? data.impostor.views : [];
    for (const view of views) hashes.push(viewKey(view, data.impostor));
    e.waiting = hashes.length;
    e.hashes = hashes;
    // Progressive loading: an object whose own level is not loaded yet is first drawn with its
    // model's coarsest level (the `preview`), fetched before every entry's own level.
    const preview = data.assets.find((a) => a.role === 'preview');
    if (preview && hashes.length === 1 && !this.assets.isLoaded(hashes[0])) {
      e.preview = preview.hash;
      e.placements.set(preview.hash, e.placementsOf(hashes[0]));
      this.assets.want(preview.hash, e, { first: true }).then(
        (record) => {
          if (this.entries.get(e.id) !== e || e.preview !== preview.hash || e.waiting === 0) return;
          e.loaded.set(preview.hash, record);
          if (e.state === 'loading') {
            e.state = 'ready';
            this.settle();
          }
        },
        () => {},
      );
    }
    const viewOf = new Map(views.map((view) => [viewKey(view, data.impostor), view]));
    for (const hash of hashes) {
      const view = viewOf.get(hash);
      const options = view ? { view, box: data.impostor } : {};
      this.assets.want(hash, e, options).then(
        (record) => {
          if (!this.entries.has(e.id) || this.entries.get(e.id) !== e) return;
          e.loaded.set(hash, record);
          e.waiting--;
          if (e.waiting === 0) {
            this.dropPreview(e);
            if (e.state === 'loading') {
              e.state = 'ready';
              this.settle();
            } else if (e.visible && e.state !== 'fading') {
              // Drawn with its preview until now: the batches take its own level.
              this.dirty = true;
              this.changed = true;
            }
          }
        },
        (error) => {
          if (error && error.name === 'AbortError') return;
          this.failures++;
          console.warn(`entry ${e.id}: ${error.message || error}`);
        },
      );
    }
    if (hashes.length === 0) e.state = 'ready';
    return e;
  }

  /** `e` no longer draws its preview (its own level has loaded, or it goes). */
  dropPreview(e) {
    if (!e.preview) return;
    e.loaded.delete(e.preview);
    this.assets.release(e.preview, e);
    e.preview = null;
  }

  retire(e, replacers) {
    e.state = 'retiring';
    e.replacers = new Set(replacers.map((a) => a.id));
    for (const a of replacers) if (!a.replaces.includes(e.id)) a.replaces.push(e.id);
  }

  /** `e` goes without ever having been drawn: what it was to replace waits for `replacers`. */
  handOn(e, replacers) {
    // Its replacers no longer wait on it: it will never be drawn.
    for (const a of replacers) a.replaces = a.replaces.filter((id) => id !== e.id);
    for (const old of this.entries.values()) {
      if (old.state !== 'retiring' || !old.replacers.has(e.id)) continue;
      old.replacers.delete(e.id);
      for (const a of replacers) {
        old.replacers.add(a.id);
        if (!a.replaces.includes(old.id)) a.replaces.push(old.id);
      }
    }
  }

  /**
   * Applies load before drop: a ready entry is shown when nothing it replaces still waits for
   * another replacer; a retiring entry whose replacers are all ready starts to fade.
   */
  settle() {
    let changed = true;
    while (changed) {
      changed = false;
      for (const old of this.entries.values()) {
        if (old.state !== 'retiring') continue;
        const waiting = [...old.replacers].some((id) => {
          const a = this.entries.get(id);
          return a && this.current.has(id) && a.state !== 'ready' && a.state !== 'shown';
        });
        if (!waiting) {
          this.fade(old);
          changed = true;
        }
      }
    }
    for (const id of this.current) {
      const e = this.entries.get(id);
      if (e.state !== 'ready') continue;
      const blocked = e.replaces.some((r) => this.entries.get(r)?.state === 'retiring');
      if (!blocked) {
        e.state = 'shown';
        e.visible = true;
        this.dirty = true;
      }
    }
  }

  fade(e) {
    if (!e.visible) {
      this.dispose(e);
      return;
    }
    e.state = 'fading';
    e.fadeStart = performance.now();
    this.dirty = true;
    // A fading entry leaves the batches and is drawn alone, with its own transparent materials.
    e.fadeGroup = new THREE.Group();
    for (const [hash, record] of e.loaded) {
      for (const placement of e.placementsOf(hash)) {
        for (const part of record.parts) {
          const materials = (Array.isArray(part.material) ? part.material : [part.material]).map((m) => {
            const c = m.clone();
            c.transparent = true;
            c.depthWrite = false;
            return c;
          });
          for (const matrix of part.matrices) {
            const mesh = new THREE.Mesh(part.geometry, materials.length === 1 ? materials[0] : materials);
            mesh.matrixAutoUpdate = false;
            mesh.matrix.multiplyMatrices(placement, matrix);
            e.fadeGroup.add(mesh);
          }
        }
      }
    }
    this.root.add(e.fadeGroup);
  }

  dispose(e) {
    if (e.fadeGroup) {
      this.root.remove(e.fadeGroup);
      e.fadeGroup.traverse((m) => {
        if (m.isMesh) (Array.isArray(m.material) ? m.material : [m.material]).forEach((x) => x.dispose());
      });
      e.fadeGroup = null;
    }
    for (const hash of e.hashes) this.assets.release(hash, e);
    this.dropPreview(e);
    if (this.entries.get(e.id) === e) this.entries.delete(e.id);
    // A fading entry is already out of the batches; the picture changes all the same.
    if (e.visible && e.state !== 'fading') this.dirty = true;
    this.changed = true;
    e.visible = false;
    e.state = 'gone';
  }

  /**
   * Per frame: fades advance, finished fades go, batches are rebuilt if anything changed.
   * Returns whether the picture changed since the last call.
   */
  frame(now) {
    let changed = this.changed;
    this.changed = false;
    for (const e of [...this.entries.values()]) {
      if (e.state !== 'fading') continue;
      changed = true;
      const t = (now - e.fadeStart) / FADE_MS;
      if (t >= 1) {
        this.dispose(e);
        continue;
      }
      e.fadeGroup.traverse((m) => {
        if (m.isMesh) (Array.isArray(m.material) ? m.material : [m.material]).forEach((x) => (x.opacity = 1 - t));
      });
    }
    if (this.dirty) {
      this.rebuild();
      changed = true;
    }
    return changed;
  }

  /**
   * One InstancedMesh per (asset, part, handedness) over every shown or retiring entry: each
   * placement times each of the part's own matrices, mirrored ones under the mirror.
   */
  rebuild() {
    this.dirty = false;
    for (const mesh of this.batches.values()) {
      mesh.parent.remove(mesh);
      mesh.dispose();
    }
    this.batches.clear();
    const groups = new Map();
    for (const e of this.entries.values()) {
      if (!e.visible || e.state === 'fading') continue;
      for (const [hash, record] of e.loaded) {
        record.parts.forEach((part, p) => {
          for (const placement of e.placementsOf(hash)) {
            for (const inside of part.matrices) {
              const m = new THREE.Matrix4().multiplyMatrices(placement, inside);
              const mirrored = m.determinant() < 0;
              if (mirrored) m.premultiply(MIRROR);
              const key = `${hash}|${p}|${mirrored ? 'm' : 'p'}`;
              let g = groups.get(key);
              if (!g) groups.set(key, (g = { part, mirrored, matrices: [] }));
              g.matrices.push(m);
            }
          }
        });
      }
    }
    for (const [key, g] of groups) {
      const mesh = new THREE.InstancedMesh(g.part.geometry, g.part.material, g.matrices.length);
      g.matrices.forEach((m, i) => mesh.setMatrixAt(i, m));
      mesh.instanceMatrix.needsUpdate = true;
      mesh.computeBoundingSphere();
      (g.mirrored ? this.mirrored : this.root).add(mesh);
      this.batches.set(key, mesh);
    }
  }

  /**
   * Whether every object of the cut's generation is drawn: every current entry is shown, or
   * still loading while all that it replaces is drawn in its place; and the current entries'
   * `covers` add up to the world's objects. Fading entries do not count.
   */
  get complete() {
    return this.incompleteBecause() === null;
  }

  /** Why the view is not complete, in words; null when it is. */
  incompleteBecause() {
    if (this.generation === null) return 'no cut yet';
    let covers = 0;
    for (const id of this.current) {
      const e = this.entries.get(id);
      covers += e.data.covers;
      if (e.state === 'shown') continue;
      if (e.replaces.length === 0) return `${id} is ${e.state} and replaces nothing drawn`;
      for (const r of e.replaces) {
        const old = this.entries.get(r);
        if (!old || old.state !== 'retiring' || !old.visible) {
          return `${id} is ${e.state} and ${r}, which it replaces, is ${old ? old.state : 'gone'}`;
        }
      }
    }
    return covers === this.objects ? null : `covers add up to ${covers}, not ${this.objects}`;
  }

  /** Entries of the current cut shown as impostors. */
  get impostorsShown() {
    let n = 0;
    for (const id of this.current) {
      const e = this.entries.get(id);
      if (e.data.kind === 'impostor' && e.state === 'shown') n++;
    }
    return n;
  }

  /** Entries retiring or fading: the view is changing over. */
  get transitions() {
    let n = 0;
    for (const e of this.entries.values()) if (e.state === 'retiring' || e.state === 'fading') n++;
    return n;
  }

  /** Assets the current cut still waits for. */
  get pendingAssets() {
    let n = 0;
    for (const id of this.current) n += this.entries.get(id).waiting;
    return n;
  }

  /** The current cut's triangles and draw calls as the server counts them. */
  get cutStats() {
    let triangles = 0, bytes = 0;
    const hashes = new Set();
    for (const id of this.current) {
      const e = this.entries.get(id);
      triangles += e.data.triangles;
      for (const a of e.data.assets) {
        if (!hashes.has(a.hash)) bytes += a.bytes;
        hashes.add(a.hash);
      }
    }
    return { triangles, bytes, assets: hashes.size };
  }
}

class Entry {
  constructor(data, replaces) {
    this.id = data.id;
    this.data = data;
    this.replaces = [...replaces];
    this.replacers = new Set();
    this.state = 'loading';
    this.visible = false;
    this.loaded = new Map();
    this.waiting = 0;
    /** the hash of the preview drawn until the entry's own level loads, if any */
    this.preview = null;
    this.hashes = [];
    this.fadeGroup = null;
    // Users of an asset are ranked by where they are.
    this.center = data.center;
    this.radius = data.radius;
    this.placements = new Map();
    for (const p of data.placements) {
      const m = new THREE.Matrix4();
      const c = p.matrix; // 3x4, column-major
      m.set(c[0], c[3], c[6], c[9], c[1], c[4], c[7], c[10], c[2], c[5], c[8], c[11], 0, 0, 0, 1);
      if (!this.placements.has(p.asset)) this.placements.set(p.asset, []);
      this.placements.get(p.asset).push(m);
    }
  }

  /** Where `hash` is drawn for this entry; an asset without placements is in world space. */
  placementsOf(hash) {
    return this.placements.get(hash) || [IDENTITY];
  }
}

const IDENTITY = new THREE.Matrix4();
