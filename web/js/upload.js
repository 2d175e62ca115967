// Upload by drag and drop: with a token pasted once (kept in this browser's localStorage), a
// GLB dropped on the view is uploaded (`POST /v1/models`) and placed (`POST /v1/objects`) with
// its lowest point on the surface under the cursor. The stream then brings it back as a
// pending object. Every error is the server's message, in words.

import * as THREE from 'three';
import { GLTFLoader } from 'three/addons/loaders/GLTFLoader.js';
import { MeshoptDecoder } from 'three/addons/libs/meshopt_decoder.module.js';

const TOKEN_KEY = 'horizon.token';

export class Upload {
  /**
   * @param {object} options `canvas`, `camera`, `pickables` (a function returning the objects to
   *   pick against), `tokenInput`, `say(text, isError)`
   */
  constructor({ canvas, camera, pickables, tokenInput, say }) {
    this.canvas = canvas;
    this.camera = camera;
    this.pickables = pickables;
    this.say = say;
    this.tokenInput = tokenInput;
    this.loader = new GLTFLoader();
    this.loader.setMeshoptDecoder(MeshoptDecoder);
    this.uploads = 0;
    tokenInput.value = localStorage.getItem(TOKEN_KEY) || '';
    tokenInput.addEventListener('change', () => {
      localStorage.setItem(TOKEN_KEY, tokenInput.value.trim());
      say(tokenInput.value.trim() ? 'token saved in this browser' : 'token cleared');
    });
    addEventListener('dragover', (e) => {
      e.preventDefault();
      document.body.classList.add('dropping');
    });
    addEventListener('dragleave', () => document.body.classList.remove('dropping'));
    addEventListener('drop', (e) => {
      e.preventDefault();
      document.body.classList.remove('dropping');
      const file = e.dataTransfer?.files?.[0];
      if (file) this.place(file, e.clientX, e.clientY).catch((error) => say(error.message, true));
    });
  }

  get token() {
    return this.tokenInput.value.trim();
  }

  /** Uploads `file` and places it under the screen point (x, y). Resolves with the object. */
  async place(file, x, y) {
    if (!this.token) throw new Error('paste a token first: uploads need one (horizon token create)');
    const bytes = await file.arrayBuffer();
    this.say(`uploading ${file.name} (${(bytes.byteLength / 1024).toFixed(0)} KB)…`);
    const model = await this.request('/v1/models', 'model/gltf-binary', bytes);
    const at = this.pointUnder(x, y);
    // Stand the model on the point: lift it by its lowest point, if it can be read here.
    const lowest = await this.lowestPoint(bytes);
    const translation = [at.x, at.y - lowest, at.z];
    const object = await this.request(
      '/v1/objects',
      'application/json',
      JSON.stringify({ model: model.id, translation }),
    );
    this.uploads++;
    this.say(`placed ${file.name} as object ${object.id} (generation ${object.generation})`);
    return object;
  }

  async request(path, type, body) {
    const response = await fetch(path, {
      method: 'POST',
      headers: { 'Content-Type': type, Authorization: `Bearer ${this.token}` },
      body,
    });
    let json = null;
    try {
      json = await response.json();
    } catch {
      // Not JSON: reported below from the status.
    }
    if (!response.ok) {
      const message = json?.error?.message || `HTTP ${response.status}`;
      const code = json?.error?.code ? ` (${json.error.code})` : '';
      throw new Error(`the server refused it: ${message}${code}`);
    }
    return json;
  }

  /** The first surface under the screen point, or the ground plane, or 20 m ahead. */
  pointUnder(x, y) {
    const rect = this.canvas.getBoundingClientRect();
    const ndc = new THREE.Vector2(((x - rect.left) / rect.width) * 2 - 1, -((y - rect.top) / rect.height) * 2 + 1);
    const ray = new THREE.Raycaster();
    ray.setFromCamera(ndc, this.camera);
    const hit = ray.intersectObjects(this.pickables(), true)[0];
    if (hit) return hit.point;
    const ground = new THREE.Plane(new THREE.Vector3(0, 1, 0), 0);
    const point = new THREE.Vector3();
    if (ray.ray.intersectPlane(ground, point) && point.distanceTo(this.camera.position) < 5000) return point;
    return ray.ray.at(20, point);
  }

  async lowestPoint(bytes) {
    try {
      const gltf = await this.loader.parseAsync(bytes.slice(0), '');
      const box = new THREE.Box3().setFromObject(gltf.scene);
      gltf.scene.traverse((n) => n.isMesh && n.geometry.dispose());
      return Number.isFinite(box.min.y) ? box.min.y : 0;
    } catch {
      return 0;
    }
  }
}
