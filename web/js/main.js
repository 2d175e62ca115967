// The Horizon viewer: boots three.js, flies the camera, keeps the cut up to date over the
// standing query, draws it with load before drop, and shows what it costs.
//
// Query parameters: `min_solid_angle` (default 0.001 sr), `max_entries` (default 4000),
// `max_pixel_error` (default 1: the geometric error, in pixels, an object's level of detail may
// show; 0 draws every object at full detail), `impostors=0` (no orthoview impostors: far nodes
// as their aggregates), `instances=0` (no instances entries: nodes of reused models as their
// aggregates too), `cache_mb` (default 768), `antialias=0` (cheaper in software
// rendering), and `full`: draw every object as its model instead of the cut (the reference the
// fidelity test compares with).
//
// `window.horizon` is the surface tests and tools read (DESIGN.md, "Outputs that tools parse").

import * as THREE from 'three';
import { AssetStore } from './assets.js';
import { Fly } from './fly.js';
import { Stream } from './stream.js';
import { Upload } from './upload.js';
import { World } from './world.js';
import { fullWorld } from './full.js';

const params = new URLSearchParams(location.search);
const MIN_SOLID_ANGLE = Number(params.get('min_solid_angle') || 0.001);
const MAX_ENTRIES = Number(params.get('max_entries') || 4000);
const MAX_PIXEL_ERROR = params.has('max_pixel_error') ? Number(params.get('max_pixel_error')) : 1;
const IMPOSTORS = params.get('impostors') !== '0';
const INSTANCES = params.get('instances') !== '0';
const CACHE_MB = Number(params.get('cache_mb') || 768);
const FULL = params.has('full');
const ANTIALIAS = params.get('antialias') !== '0';
const FOV = 60;

const $ = (id) => document.getElementById(id);
const canvas = $('view');
const messageBox = $('message');

function say(text, isError = false) {
  messageBox.textContent = text;
  messageBox.className = isError ? 'error' : '';
  if (isError) console.warn(text);
}

// Stage 1: renderer, scene and camera.
const renderer = new THREE.WebGLRenderer({ canvas, antialias: ANTIALIAS, logarithmicDepthBuffer: true, preserveDrawingBuffer: true });
renderer.setPixelRatio(Math.min(devicePixelRatio, 2));
renderer.info.autoReset = true;
const scene = new THREE.Scene();
scene.background = new THREE.Color(0x9cc3e6);
scene.add(new THREE.HemisphereLight(0xdfefff, 0x6b5f4f, 1.6));
const sun = new THREE.DirectionalLight(0xffffff, 1.8);
sun.position.set(0.4, 1, 0.3);
scene.add(sun);
const camera = new THREE.PerspectiveCamera(FOV, 1, 0.1, 20000);

// Stage 2: the world's extent, for the first view and the far plane.
const info = await fetch('/v1/world').then((r) => r.json());
const bounds = info.bounds || { min: [-50, 0, -50], max: [50, 20, 50] };
const centre = bounds.min.map((v, i) => (v + bounds.max[i]) / 2);
const size = bounds.max.map((v, i) => v - bounds.min[i]);
const extent = Math.max(size[0], size[2], 10);
camera.far = Math.max(20000, 4 * Math.hypot(...size));
camera.updateProjectionMatrix();

// Stage 3: assets, the cut's copy, flying, uploads.
const assets = new AssetStore({ budgetBytes: CACHE_MB << 20, eye: () => camera.position });
const world = new World(scene, assets);
const fly = new Fly(camera, canvas, $('speed'), $('speed-value'));
if (!fly.fromFragment()) {
  fly.lookAt([centre[0], bounds.min[1] + 0.2 * extent, centre[2] + 0.6 * extent], centre);
}
const upload = new Upload({
  canvas,
  camera,
  pickables: () => [world.root],
  tokenInput: $('token'),
  say,
});

// Stage 4: the cut: the standing query, or every object as its model.
let stream = null;
if (FULL) {
  fullWorld(world).catch((error) => say(`full world: ${error.message}`, true));
} else {
  stream = new Stream({
    onReset: (m) => world.applyReset(m),
    onDelta: (m) => world.applyDelta(m),
    onError: (text) => say(`stream: ${text}`, true),
    onState: (text) => say(`stream ${text}`, !text.startsWith('connected')),
  });
}

function view() {
  const fovY = (FOV * Math.PI) / 180;
  const pixel = fovY / Math.max(canvas.clientHeight * renderer.getPixelRatio(), 1);
  const p = camera.position;
  return {
    eye: [p.x, p.y, p.z],
    min_solid_angle: MIN_SOLID_ANGLE,
    pixel_solid_angle: pixel * pixel,
    max_pixel_error: MAX_PIXEL_ERROR,
    impostors: IMPOSTORS,
    instances: INSTANCES,
    budgets: { max_entries: MAX_ENTRIES },
  };
}

// The test and tool surface.
const stats = { frames: 0, incompleteFrames: 0, firstCompleteMs: null, drawCalls: 0, triangles: 0, fps: 0 };
window.horizon = {
  get complete() { return world.complete; },
  get entries() { return world.current.size; },
  /** Entries of the current cut drawn as orthoview impostors. */
  get impostors() { return world.impostorsShown; },
  get generation() { return world.generation; },
  get published() { return world.published; },
  get objects() { return world.objects; },
  get pending_assets() { return world.pendingAssets; },
  get bytes() { return assets.bytesReceived; },
  get frames() { return stats.frames; },
  get incomplete_frames() { return stats.incompleteFrames; },
  /** Why the last incomplete frame was incomplete. */
  get incomplete_why() { return stats.incompleteWhy ?? null; },
  get first_complete_ms() { return stats.firstCompleteMs; },
  get latency_ms() { return stream ? stream.latencyMs : null; },
  get draw_calls() { return stats.drawCalls; },
  get triangles() { return stats.triangles; },
  get cache_bytes() { return assets.heldBytes; },
  get cache_peak_bytes() { return assets.peakHeldBytes; },
  get cache_budget_bytes() { return assets.budgetBytes; },
  get failures() { return world.failures; },
  /** Additions that reused a held entry's assets and placements (instances at new levels). */
  get reused() { return world.reused; },
  get message() { return messageBox.textContent; },
  get message_is_error() { return messageBox.className === 'error'; },
  /** Nothing to load or fade: the frame is what the cut the viewer holds draws. */
  get settled() {
    return world.complete && world.pendingAssets === 0 && world.transitions === 0 && !world.dirty;
  },
  /** The view the viewer asks for now (the body of a `view` message, without its id). */
  view() { return view(); },
  setView(eye, target) { fly.lookAt(eye, target); },
  /** The last frame's pixels, RGBA rows from the top, base64. */
  pixels() {
    // Batches rebuilt since the last animation frame are drawn too.
    world.frame(performance.now());
    renderer.render(scene, camera);
    const copy = document.createElement('canvas');
    copy.width = canvas.width;
    copy.height = canvas.height;
    const context = copy.getContext('2d');
    context.drawImage(canvas, 0, 0);
    const data = context.getImageData(0, 0, copy.width, copy.height).data;
    let text = '';
    for (let i = 0; i < data.length; i += 0x8000) text += String.fromCharCode.apply(null, data.subarray(i, i + 0x8000));
    return { width: copy.width, height: copy.height, b64: btoa(text) };
  },
  place(file, x, y) { return upload.place(file, x, y); },
  ids() { return [...world.current]; },
};

// Stage 5: the frame loop.
function resize() {
  const w = canvas.clientWidth, h = canvas.clientHeight;
  if (canvas.width !== Math.floor(w * renderer.getPixelRatio()) || canvas.height !== Math.floor(h * renderer.getPixelRatio())) {
    renderer.setSize(w, h, false);
    camera.aspect = w / Math.max(h, 1);
    camera.updateProjectionMatrix();
    fly.moved = true;
    return true;
  }
  return false;
}

let last = performance.now();
let lastRender = 0;
let hudAt = 0;
let frameTimes = [];
function frame(now) {
  const dt = Math.min((now - last) / 1000, 0.1);
  last = now;
  const resized = resize();
  fly.update(dt, now);
  const moved = fly.moved;
  fly.moved = false;
  if (moved && stream) stream.setView(view());
  const changed = world.frame(now);
  // Draw when something changed, and once a second regardless: a still view costs nothing.
  if (moved || changed || resized || now - lastRender > 1000) {
    lastRender = now;
    renderer.render(scene, camera);
    stats.drawCalls = renderer.info.render.calls;
    stats.triangles = renderer.info.render.triangles;
    stats.frames++;
    frameTimes.push(dt);
  }
  const complete = world.complete;
  if (complete && stats.firstCompleteMs === null) {
    stats.firstCompleteMs = now;
    $('progress').classList.add('done');
  } else if (!complete && stats.firstCompleteMs !== null) {
    stats.incompleteFrames++;
    stats.incompleteWhy = world.incompleteBecause();
  }
  if (now - hudAt > 250) {
    hudAt = now;
    // Frames drawn per second over the last quarter second (a still view draws one a second).
    stats.fps = (frameTimes.length * 1000) / Math.max(now - (stats.fpsSince || now - 250), 1);
    stats.fpsSince = now;
    frameTimes = [];
    hud();
  }
  requestAnimationFrame(frame);
}

function hud() {
  const mb = (b) => `${(b / 1048576).toFixed(1)} MB`;
  const k = (n) => (n >= 1e6 ? `${(n / 1e6).toFixed(2)}M` : n >= 1e4 ? `${(n / 1e3).toFixed(0)}k` : String(n));
  let aggregates = 0, instances = 0, shown = 0;
  for (const id of world.current) {
    const e = world.entries.get(id);
    if (e.data.kind === 'aggregate') aggregates++;
    if (e.data.kind === 'instances') instances++;
    if (e.state === 'shown') shown++;
  }
  const latency = stream && stream.latencyMs !== null ? `${stream.latencyMs.toFixed(0)} ms` : '-';
  $('stats').textContent = [
    `generation ${world.generation ?? '-'} (published ${world.published ?? '-'}) · ${world.objects} objects`,
    `entries ${world.current.size} (${aggregates} aggregates, ${instances} instances)${world.stoppedBy ? ` · stopped by ${world.stoppedBy}` : ''}`,
    `draw calls ${stats.drawCalls} · triangles ${k(stats.triangles)}`,
    `downloaded ${mb(assets.bytesReceived)} · assets pending ${world.pendingAssets}`,
    `cache ${mb(assets.heldBytes)} of ${mb(assets.budgetBytes)}`,
    `view to delta ${latency} · ${stats.fps.toFixed(0)} fps${FULL ? ' · full detail' : ''}`,
  ].join('\n');
  if (stats.firstCompleteMs === null) {
    const n = world.current.size;
    const fraction = n ? shown / n : 0;
    $('progress-bar').style.width = `${(fraction * 100).toFixed(0)}%`;
    $('progress-text').textContent = n
      ? `loading ${shown} of ${n} entries, ${world.pendingAssets} assets pending`
      : 'waiting for the first cut';
  }
}

requestAnimationFrame(frame);
