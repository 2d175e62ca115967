// The web viewer's benchmark (the web viewer issue): for each world directory given,
//   - time from opening `/` to the first complete view, unthrottled and at 10 Mbit/s
//     (Chromium's network emulation, 20 ms latency), each in a fresh browser context;
//   - the first complete view at 10 Mbit/s again without levels of detail
//     (`?max_pixel_error=0`), the peer of the levels (with LEVELS_ONLY=1, only these);
//   - frames per second on a seeded flight (street level to outside, 12 s, the camera moved
//     every frame), the cut against full detail (`?full`) in the same run, as a ratio of
//     frame times (software rendering here: only the ratio means anything);
//   - peak JS heap, and the asset cache's peak (decoded geometry and textures, the GPU memory
//     estimate) against its budget.
//
//   cargo build --release -p horizon-server
//   HORIZON=target/release/horizon PLAYWRIGHT_CORE=~/.cache/horizon-tools/npm/node_modules/playwright-core \
//     node lab/bench/viewer.mjs /tmp/hf3/village /tmp/hf3/city > lab/results/viewer.md
//
// The worlds must be built (`horizon build`). Prints a Markdown table on stdout.

import { serve, launch, views } from '../../tests/web/harness.mjs';

const dirs = process.argv.slice(2);
if (dirs.length === 0) {
  console.error('usage: node lab/bench/viewer.mjs WORLD_DIR...');
  process.exit(2);
}

const FLIGHT_MS = 12000;
const rows = [];
const browser = await launch();

async function page(url, throttle) {
  const context = await browser.newContext({ viewport: { width: 960, height: 540 } });
  const p = await context.newPage();
  if (throttle) {
    const cdp = await context.newCDPSession(p);
    await cdp.send('Network.enable');
    await cdp.send('Network.emulateNetworkConditions', {
      offline: false, latency: 20, downloadThroughput: (10e6 / 8), uploadThroughput: (10e6 / 8),
    });
  }
  let heap = 0;
  const sample = setInterval(async () => {
    try {
      heap = Math.max(heap, await p.evaluate(() => performance.memory?.usedJSHeapSize || 0));
    } catch { /* closing */ }
  }, 500);
  await p.goto(url);
  await p.waitForFunction(() => window.horizon !== undefined);
  return {
    p,
    heap: () => heap,
    close: async () => { clearInterval(sample); await context.close(); },
  };
}

async function firstComplete(url, throttle) {
  const v = await page(url, throttle);
  await v.p.waitForFunction(() => window.horizon.first_complete_ms !== null, null, { timeout: 900000, polling: 200 });
  const s = await v.p.evaluate(() => ({ ms: window.horizon.first_complete_ms, bytes: window.horizon.bytes, entries: window.horizon.entries }));
  await v.close();
  return s;
}

async function flight(url, a, b) {
  const v = await page(url, false);
  await v.p.evaluate(([e, t]) => window.horizon.setView(e, t), [a.eye, a.target]);
  await v.p.waitForFunction(() => window.horizon.settled, null, { timeout: 900000, polling: 200 });
  const r = await v.p.evaluate(([a, b, ms]) => new Promise((resolve) => {
    const t0 = performance.now();
    const f0 = window.horizon.frames;
    const i0 = window.horizon.incomplete_frames;
    function step(now) {
      const t = (now - t0) / ms;
      if (t >= 1) {
        resolve({ frames: window.horizon.frames - f0, ms: now - t0, incomplete: window.horizon.incomplete_frames - i0 });
        return;
      }
      window.horizon.setView(a.eye.map((x, i) => x + (b.eye[i] - x) * t), a.target.map((x, i) => x + (b.target[i] - x) * t));
      requestAnimationFrame(step);
    }
    requestAnimationFrame(step);
  }), [a, b, FLIGHT_MS]);
  const cache = await v.p.evaluate(() => ({ peak: window.horizon.cache_peak_bytes, budget: window.horizon.cache_budget_bytes }));
  const heap = v.heap();
  await v.close();
  return { ...r, frameMs: r.ms / Math.max(r.frames, 1), heap, cache };
}

for (const dir of dirs) {
  const server = await serve(dir);
  try {
    const bounds = (await (await fetch(`${server.url}/v1/world`)).json()).bounds;
    const open = await firstComplete(`${server.url}/`, false);
    const slow = await firstComplete(`${server.url}/`, true);
    // The peer of levels of detail: every object at level 0, in the same run.
    const flat = await firstComplete(`${server.url}/?max_pixel_error=0`, true);
    if (process.env.LEVELS_ONLY) {
      rows.push({ dir, open, slow, flat });
      console.error(`${dir}: done`);
      continue;
    }
    const [street, , , outside] = views(bounds, 1);
    const cut = await flight(`${server.url}/`, street, outside);
    const full = await flight(`${server.url}/?full`, street, outside);
    rows.push({ dir, open, slow, flat, cut, full });
    console.error(`${dir}: done`);
  } finally {
    await server.stop();
  }
}
await browser.close();

const mb = (b) => `${(b / 1048576).toFixed(1)} MB`;
const s = (ms) => `${(ms / 1000).toFixed(1)} s`;
console.log('| world | first complete view at 10 Mbit/s with levels of detail | without (`?max_pixel_error=0`) | ratio of times | ratio of bytes |');
console.log('|---|---|---|---|---|');
for (const r of rows) {
  console.log(`| ${r.dir} | ${s(r.slow.ms)} (${mb(r.slow.bytes)}) | ${s(r.flat.ms)} (${mb(r.flat.bytes)}) | ${(r.slow.ms / r.flat.ms).toFixed(2)}x | ${(r.slow.bytes / r.flat.bytes).toFixed(2)}x |`);
}
console.log();
if (process.env.LEVELS_ONLY) process.exit(0);
console.log('| world | first complete view | at 10 Mbit/s | flight frame time cut / full (ratio) | incomplete frames in flight | peak JS heap cut / full | asset cache peak / budget |');
console.log('|---|---|---|---|---|---|---|');
for (const r of rows) {
  console.log(`| ${r.dir} | ${s(r.open.ms)} (${mb(r.open.bytes)}, ${r.open.entries} entries) | ${s(r.slow.ms)} (${mb(r.slow.bytes)}) | ${r.cut.frameMs.toFixed(0)} / ${r.full.frameMs.toFixed(0)} ms (${(r.cut.frameMs / r.full.frameMs).toFixed(2)}x) | ${r.cut.incomplete} of ${r.cut.frames} | ${mb(r.cut.heap)} / ${mb(r.full.heap)} | ${mb(r.cut.cache.peak)} / ${mb(r.cut.cache.budget)} (full: ${mb(r.full.cache.peak)}) |`);
}
