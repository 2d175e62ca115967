// Full detail, the fidelity reference (`?full`): every object of the world as its model, read
// a page at a time from `/v1/objects` and `/v1/models`, handed to the same World as one reset
// of object entries, so that it is drawn by exactly the code that draws a cut (instanced per
// model).

import * as THREE from 'three';

export async function fullWorld(world) {
  const models = new Map();
  for await (const m of pages('/v1/models', 'models')) models.set(m.id, m);
  const entries = [];
  for await (const o of pages('/v1/objects', 'objects')) {
    const model = models.get(o.model);
    if (!model) continue;
    const m = new THREE.Matrix4().compose(
      new THREE.Vector3(...o.translation),
      new THREE.Quaternion(...o.rotation),
      new THREE.Vector3(...o.scale),
    );
    const e = m.elements; // column-major 4x4: drop the last row
    entries.push({
      id: `o:${o.id}`,
      kind: 'object',
      assets: [{ hash: model.asset, bytes: model.bytes, role: 'model' }],
      placements: [{ asset: model.asset, matrix: [e[0], e[1], e[2], e[4], e[5], e[6], e[8], e[9], e[10], e[12], e[13], e[14]] }],
      level: 0,
      bytes: model.bytes,
      triangles: model.triangles_expanded,
      draw_calls: model.submeshes,
      center: o.translation,
      radius: 1,
      covers: 1,
    });
  }
  const info = await fetch('/v1/world').then((r) => r.json());
  world.applyReset({
    type: 'reset',
    seq: 1,
    view: 0,
    generation: info.generation,
    published: info.published,
    objects: entries.length,
    entries,
    stopped_by: null,
  });
}

async function* pages(path, key) {
  let after = null;
  for (;;) {
    const url = `${path}?limit=10000${after !== null ? `&after=${after}` : ''}`;
    const response = await fetch(url);
    if (!response.ok) throw new Error(`${url}: HTTP ${response.status}`);
    const page = await response.json();
    yield* page[key];
    if (page.next === null || page.next === undefined) return;
    after = page.next;
  }
}
