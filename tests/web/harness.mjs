// What the browser tests and the viewer benchmark share: a real `horizon serve` on port 0 over
// a world directory, headless Chromium (the system's, driven by playwright-core), seeded views
// and image comparison.
//
// Environment: HORIZON (the horizon binary, default target/release/horizon), PLAYWRIGHT_CORE
// (the playwright-core module directory), CHROMIUM (default /usr/bin/chromium).

import { spawn, execFileSync } from 'node:child_process';
import { createInterface } from 'node:readline';
import path from 'node:path';

export const HORIZON = process.env.HORIZON || 'target/release/horizon';
const { chromium } = await import(path.resolve(process.env.PLAYWRIGHT_CORE || 'node_modules/playwright-core', 'index.mjs'));

/** Starts `horizon serve DIR` on port 0; resolves with `{url, process, stop()}`. */
export async function serve(dir) {
  const child = spawn(HORIZON, ['serve', dir, '--listen', '127.0.0.1:0'], { stdio: ['ignore', 'pipe', 'pipe'] });
  let log = '';
  child.stderr.on('data', (d) => { log = (log + d).slice(-20000); });
  const line = await new Promise((resolve, reject) => {
    const lines = createInterface({ input: child.stdout });
    lines.once('line', resolve);
    child.once('exit', (code) => reject(new Error(`horizon serve exited (${code}): ${log}`)));
  });
  const url = line.replace(/^listening on /, '');
  if (!url.startsWith('http://')) throw new Error(`unexpected first line: ${line}`);
  return {
    url,
    process: child,
    log: () => log,
    stop: () => new Promise((resolve) => {
      if (child.exitCode !== null) return resolve();
      child.once('exit', resolve);
      child.kill('SIGTERM');
    }),
  };
}

/** `horizon token create DIR --user USER`: the token. */
export function createToken(dir, user) {
  return execFileSync(HORIZON, ['token', 'create', dir, '--user', user], { encoding: 'utf8' }).trim();
}

/** Headless Chromium with software WebGL, and no calls to the outside network. */
export function launch() {
  return chromium.launch({
    executablePath: process.env.CHROMIUM || '/usr/bin/chromium',
    args: [
      '--no-sandbox', '--disable-background-networking', '--disable-component-update',
      '--disable-sync', '--disable-quic', '--no-first-run', '--use-angle=swiftshader',
      '--enable-unsafe-swiftshader', '--ignore-gpu-blocklist', '--enable-precise-memory-info',
    ],
  });
}

/** A page of the viewer at `url` with console errors collected in `page.errors`. */
export async function open(browser, url, { width = 960, height = 540 } = {}) {
  const page = await browser.newPage({ viewport: { width, height } });
  page.errors = [];
  page.on('console', (m) => { if (m.type() === 'error') page.errors.push(m.text()); });
  page.on('pageerror', (e) => page.errors.push(`uncaught: ${e.message}`));
  // A page's load event waits for its modules; with two other pages streaming and drawing in
  // SwiftShader on two cores (the impostors test), it once took over the default 30 s.
  await page.goto(url, { timeout: 120000 });
  await page.waitForFunction(() => window.horizon !== undefined, null, { timeout: 60000 });
  return page;
}

/** Waits until the viewer draws every object with nothing left to load or fade. */
export async function settled(page, timeout = 180000) {
  await page.waitForFunction(
    () => window.horizon.complete && window.horizon.pending_assets === 0 && window.horizon.settled,
    null, { timeout, polling: 100 },
  );
}

/** The canvas's pixels: `{width, height, data}` (RGBA). */
export async function pixels(page) {
  const { width, height, b64 } = await page.evaluate(() => window.horizon.pixels());
  return { width, height, data: Buffer.from(b64, 'base64') };
}

/** Seeded views of a world with bounds `{min, max}`: street level, overhead, outside. */
export function views(bounds, seed = 1, street = 2) {
  let s = seed >>> 0;
  const unit = () => {
    s = (s + 0x6d2b79f5) >>> 0;
    let t = s;
    t = Math.imul(t ^ (t >>> 15), t | 1);
    t ^= t + Math.imul(t ^ (t >>> 7), t | 61);
    return ((t ^ (t >>> 14)) >>> 0) / 4294967296;
  };
  const [x0, y0, z0] = bounds.min, [x1, , z1] = bounds.max;
  const c = [(x0 + x1) / 2, 0, (z0 + z1) / 2];
  const extent = Math.max(x1 - x0, z1 - z0);
  const out = [];
  for (let k = 0; k < street; k++) {
    const eye = [x0 + unit() * (x1 - x0), y0 + 1.7, z0 + unit() * (z1 - z0)];
    const yaw = unit() * 2 * Math.PI;
    out.push({ name: `street-${k + 1}`, eye, target: [eye[0] + Math.cos(yaw), eye[1] - 0.05, eye[2] + Math.sin(yaw)] });
  }
  const yaw = unit() * 2 * Math.PI;
  const ground = [c[0] + (unit() - 0.5) * 0.5 * extent, 0, c[2] + (unit() - 0.5) * 0.5 * extent];
  const height = 0.15 * extent + 1.7;
  const back = height / Math.tan((55 * Math.PI) / 180);
  out.push({ name: 'overhead', eye: [ground[0] - Math.cos(yaw) * back, height, ground[2] - Math.sin(yaw) * back], target: ground });
  const angle = unit() * 2 * Math.PI;
  out.push({ name: 'outside', eye: [c[0] + Math.cos(angle) * 0.9 * extent, 0.2 * extent, c[2] + Math.sin(angle) * 0.9 * extent], target: c });
  return out;
}

/**
 * The one-shot cut (`GET /v1/cut`) at the view the viewer asks for now: its entry ids, without
 * an object's level of detail (`o:<id>@<placed>/<level>`: a stream keeps a level it holds
 * within a margin, where a one-shot cut has none to keep).
 */
export async function cutIds(page, base) {
  const v = await page.evaluate(() => window.horizon.view());
  const q = new URLSearchParams({
    eye: v.eye.join(','),
    min_solid_angle: String(v.min_solid_angle),
    pixel_solid_angle: String(v.pixel_solid_angle),
    max_pixel_error: String(v.max_pixel_error),
    impostors: String(v.impostors),
    instances: String(v.instances),
    max_entries: String(v.budgets.max_entries),
  });
  const response = await fetch(`${base}/v1/cut?${q}`);
  if (!response.ok) throw new Error(`GET /v1/cut: ${response.status} ${await response.text()}`);
  return (await response.json()).entries.map((e) => withoutLevel(e.id)).sort();
}

/** An entry id without its level of detail: an object's `/<level>`, instances' `/<levels hash>`. */
export function withoutLevel(id) {
  if (id.startsWith('o:')) return id.replace(/\/\d+$/, '');
  return id.includes('@i') ? id.replace(/\/[0-9a-f]+$/, '') : id;
}

/** Moves the viewer to a view and waits until it draws exactly the one-shot cut there. */
export async function goTo(page, base, eye, target, timeout = 180000) {
  await page.evaluate(([e, t]) => window.horizon.setView(e, t), [eye, target]);
  const start = Date.now();
  for (;;) {
    await settled(page, Math.max(1000, timeout - (Date.now() - start)));
    const want = await cutIds(page, base);
    const have = (await page.evaluate(() => window.horizon.ids())).map(withoutLevel).sort();
    if (want.length === have.length && want.every((id, i) => id === have[i])) return;
    if (Date.now() - start > timeout) throw new Error(`the viewer's cut never matched /v1/cut (${have.length} vs ${want.length} entries)`);
    await page.waitForTimeout(200);
  }
}
