// End-to-end test of the browser viewer in Debian's headless Chromium, driven by playwright-core.
//
//   LIGHTCAST_URL=http://127.0.0.1:8080 node tests/viewer.test.mjs
//
// The server must be running (the Rust test `viewer` in tests/tests/service starts one and runs
// this script). Environment: LIGHTCAST_URL (server), LIGHTCAST_ARTIFACTS (where the screenshot
// and the downloaded still go; default ./test-artifacts), CHROMIUM (default /usr/bin/chromium);
// LIGHTCAST_METHODS: {method: {gi, stages}} for every method the server lists (a small setting
// and the method's stage names); LIGHTCAST_UPLOAD_SCENE (optional): a .glb to upload through the page;
// LIGHTCAST_ANIMATED_SCENE (optional): a .glb whose animation `slide` the page plays;
// LIGHTCAST_AUTH_URL and LIGHTCAST_AUTH_TOKEN (optional): a second server with auth on, where
// the page must ask for the token. Exits non-zero with the failing step named.

import { chromium } from 'playwright-core';
import assert from 'node:assert/strict';
import { mkdir, readFile } from 'node:fs/promises';
import path from 'node:path';

const base = process.env.LIGHTCAST_URL || 'http://127.0.0.1:8080';
const artifacts = path.resolve(process.env.LIGHTCAST_ARTIFACTS || 'test-artifacts');
const executablePath = process.env.CHROMIUM || '/usr/bin/chromium';
// lavapipe renders slowly; waits are generous, and each names what it waited for.
const PATIENCE_MS = 120000;

// Chromium on a closed network: no background connections, no GPU, no sandbox (CI runs as root).
const CHROMIUM_ARGS = ['--no-sandbox', '--disable-gpu', '--disable-quic', '--no-first-run',
  '--disable-background-networking', '--disable-component-update', '--disable-sync'];

async function step(name, fn) {
  const started = Date.now();
  process.stdout.write(`viewer test: ${name} … `);
  try {
    const result = await fn();
    // A step may return a measurement to log with its time.
    const detail = typeof result === 'string' ? `${result}, ` : '';
    console.log(`ok (${detail}${((Date.now() - started) / 1000).toFixed(1)} s)`);
    return result;
  } catch (e) {
    console.log('FAILED');
    throw new Error(`step '${name}' failed: ${e.stack || e}`);
  }
}

async function api(method, p) {
  const response = await fetch(`${base}${p}`, { method });
  assert.ok(response.ok, `${method} ${p}: HTTP ${response.status}`);
  return response.status === 204 ? null : response.json();
}

/** The id of the page's session, from its status line. */
async function pageSessionId(page) {
  const status = await page.$eval('#status', (e) => e.textContent);
  const match = status.match(/session (se_[0-9a-f]+)/);
  assert.ok(match, `the status names the session: '${status}'`);
  return match[1];
}

/** The page's session as the server has it. */
const pageSession = async (page) => api('GET', `/v1/sessions/${await pageSessionId(page)}`);

/** Frames painted so far, from the page's counter. */
const frameCount = (page) => page.$eval('#frame-count', (e) => Number(e.dataset.count));

async function waitForFrames(page, atLeast, what) {
  await page.waitForFunction((n) => Number(document.getElementById('frame-count').dataset.count) >= n,
    atLeast, { timeout: PATIENCE_MS, polling: 100 }).catch(() => {
    throw new Error(`${what}: fewer than ${atLeast} frames painted`);
  });
}

/** The canvas as 64×48 grey levels (0–255) plus their mean and standard deviation. */
function snapshot(page) {
  return page.evaluate(() => {
    const source = document.getElementById('frame');
    const small = document.createElement('canvas');
    small.width = 64;
    small.height = 48;
    const ctx = small.getContext('2d');
    ctx.drawImage(source, 0, 0, 64, 48);
    const { data } = ctx.getImageData(0, 0, 64, 48);
    const grey = [];
    for (let i = 0; i < data.length; i += 4) grey.push((data[i] + data[i + 1] + data[i + 2]) / 3);
    const mean = grey.reduce((a, b) => a + b, 0) / grey.length;
    const sd = Math.sqrt(grey.reduce((a, b) => a + (b - mean) ** 2, 0) / grey.length);
    return { grey, mean, sd };
  });
}

const inputIds = (page) => page.$eval('#frame', (c) => ({
  sent: Number(c.dataset.sentInput || 0), shown: Number(c.dataset.shownInput || 0),
}));

/** Waits until the scene picker shows a scene other than `previous`. */
async function waitForSceneSwitch(page, previous) {
  await page.waitForFunction((old) => document.getElementById('scene-select').value !== old,
    previous, { timeout: PATIENCE_MS });
}

/**
 * Runs `act` (which must send input), waits until a painted frame shows the newest input, and
 * returns how much the canvas changed.
 */
async function changeAfter(page, act, what) {
  const before = await snapshot(page);
  const sentBefore = (await inputIds(page)).sent;
  await act();
  // Input is sent once per animation frame; let the last of it go out.
  await page.waitForTimeout(200);
  const { sent } = await inputIds(page);
  assert.ok(sent > sentBefore, `${what} sent no input`);
  await page.waitForFunction((id) => Number(document.getElementById('frame').dataset.shownInput) >= id,
    sent, { timeout: PATIENCE_MS, polling: 50 }).catch(() => {
    throw new Error(`no frame showed the input of ${what}`);
  });
  return meanAbsDiff(before, await snapshot(page));
}

/** Where `point` shows in the session's view, as fractions of the frame from its top left (the
 * server's perspective: vertical field of view, +Y up). */
function project(render, point) {
  const { position, target, fov_y_degrees: fov } = render.camera;
  const sub = (a, b) => a.map((v, i) => v - b[i]);
  const dot = (a, b) => a.reduce((s, v, i) => s + v * b[i], 0);
  const unit = (a) => a.map((v) => v / Math.hypot(...a));
  const cross = (a, b) => [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]];
  const forward = unit(sub(target, position));
  const right = unit(cross(forward, [0, 1, 0]));
  const up = cross(right, forward);
  const d = sub(point, position);
  const h = Math.tan((fov * Math.PI) / 360);
  const x = dot(d, right) / dot(d, forward) / (h * (render.width / render.height));
  const y = dot(d, up) / dot(d, forward) / h;
  return [(x + 1) / 2, (1 - y) / 2];
}

const meanAbsDiff = (a, b) => a.grey.reduce((s, v, i) => s + Math.abs(v - b.grey[i]), 0) / a.grey.length;

/** Every chunk of a PNG file: [type, data]. */
function pngChunks(bytes) {
  assert.deepEqual([...bytes.subarray(0, 8)], [137, 80, 78, 71, 13, 10, 26, 10], 'PNG signature');
  const chunks = [];
  for (let o = 8; o < bytes.length;) {
    const length = bytes.readUInt32BE(o);
    chunks.push([bytes.toString('latin1', o + 4, o + 8), bytes.subarray(o + 8, o + 8 + length)]);
    o += 12 + length;
  }
  return chunks;
}

/** A server with auth on: the page asks for the token, refuses a wrong one, streams with the right one. */
async function withAuth(browser, authBase, goodToken) {
  const context = await browser.newContext({ viewport: { width: 800, height: 600 } });
  const page = await context.newPage();
  try {
    await step('with auth on, the page asks for a token', async () => {
      await page.goto(`${authBase}/?method=none&scale=0.25`);
      await page.waitForSelector('#token-dialog[open]', { timeout: PATIENCE_MS });
    });
    await step('a wrong token is refused with the reason', async () => {
      await page.fill('#token-input', 'not-the-right-token-at-all');
      await page.click('#token-form button[type="submit"]');
      await page.waitForFunction(() => document.getElementById('token-dialog').open
        && document.getElementById('token-reason').textContent.includes('unknown bearer token'), null, { timeout: PATIENCE_MS });
    });
    await step('the right token streams (the WebSocket opens with a ticket)', async () => {
      await page.fill('#token-input', goodToken);
      await page.click('#token-form button[type="submit"]');
      await page.waitForSelector('#status[data-state="live"]', { timeout: PATIENCE_MS });
      await waitForFrames(page, 2, 'frames with auth on');
    });
  } finally {
    await context.close();
  }
}

/** The offline API page renders this server's own OpenAPI and AsyncAPI documents. */
async function apiPage(browser) {
  const context = await browser.newContext({ viewport: { width: 1000, height: 800 } });
  const page = await context.newPage();
  const errors = [];
  page.on('pageerror', (e) => errors.push(e.message));
  page.on('requestfailed', (r) => errors.push(`${r.url()} failed`));
  try {
    await step('the API page lists every endpoint, the WebSocket messages and the types', async () => {
      await page.goto(`${base}/api`);
      await page.waitForSelector('body[data-loaded="true"]', { timeout: PATIENCE_MS });
      const openapi = await api('GET', '/openapi.json');
      const operations = Object.values(openapi.paths).reduce((n, item) => n + Object.keys(item).length, 0);
      assert.equal(await page.locator('#endpoints details').count(), operations);
      await page.click('summary:has-text("/v1/render")');
      assert.ok(await page.isVisible('a[href="#schema-RenderRequest"]'), 'the render body links its type');
      for (const id of ['#message-control', '#message-event', '#message-frame', '#schema-ClientMessage', '#schema-GiParams']) {
        assert.equal(await page.locator(id).count(), 1, `${id} is on the page`);
      }
      assert.deepEqual(errors, [], 'the page loaded nothing from elsewhere and raised nothing');
      await page.screenshot({ path: path.join(artifacts, 'api.png'), fullPage: false });
    });
  } finally {
    await context.close();
  }
}

/** A browser without WebCodecs (or on plain http off localhost) streams JPEG instead. */
async function withoutWebCodecs(browser) {
  const context = await browser.newContext({ viewport: { width: 480, height: 360 } });
  const page = await context.newPage();
  await page.addInitScript(() => {
    delete window.VideoDecoder;
    delete window.EncodedVideoChunk;
  });
  try {
    await step('without WebCodecs the page falls back to JPEG', async () => {
      await page.goto(`${base}/?method=none&scale=0.5&fps=10`);
      await page.waitForSelector('#status[data-state="live"]', { timeout: PATIENCE_MS });
      await waitForFrames(page, 3, 'JPEG frames');
      assert.equal(await page.$eval('body', (b) => b.dataset.decodesH264), 'false');
      // The last frame painted is a JPEG, or the PNG still a resting view gets after 300 ms
      // (`still_after_ms`; seen once in ten runs on a loaded machine).
      const painted = await page.$eval('#frame', (c) => c.dataset.codec);
      assert.ok(['jpeg', 'png'].includes(painted), `the page painted ${painted}`);
      assert.equal((await pageSession(page)).params.encoding.codec, 'jpeg');
      const disabled = await page.$eval('select[data-field="encoding.codec"] option[value="h264"]', (o) => o.disabled);
      assert.ok(disabled, 'h264 is not offered where it cannot be decoded');
      const shot = await snapshot(page);
      assert.ok(shot.mean > 3 && shot.sd > 3, `canvas is blank: mean ${shot.mean.toFixed(1)}, sd ${shot.sd.toFixed(1)}`);
    });
    await step('asking for h264 without a decoder streams JPEG and says why', async () => {
      await page.goto(`${base}/?method=none&scale=0.5&fps=10&codec=h264`);
      await page.waitForSelector('#status[data-state="live"]', { timeout: PATIENCE_MS });
      await waitForFrames(page, 2, 'JPEG frames');
      assert.equal((await pageSession(page)).params.encoding.codec, 'jpeg');
      const messages = await page.$eval('#messages', (e) => e.textContent);
      assert.match(messages, /no WebCodecs H\.264 decoder/, `the page says why: '${messages}'`);
    });
    // Not about WebCodecs, but a page of its own is at hand: a session the server refuses
    // is not retried forever with the same bad field.
    await step('a refused parameter in the address is named, and the server default used', async () => {
      // `gi.a.b` is a key with dots of its own (issue 30: the page retried it forever).
      await page.goto(`${base}/?method=none&scale=0.5&fps=10&interactive=5&gi.a.b=1`);
      await page.waitForSelector('#status[data-state="live"]', { timeout: PATIENCE_MS });
      const messages = await page.$eval('#messages', (e) => e.textContent);
      assert.match(messages, /encoding\.interactive_scale/, `the page names the field: '${messages}'`);
      assert.match(messages, /render\.gi\.a\.b/, `the page names the dotted field: '${messages}'`);
      assert.equal((await pageSession(page)).params.render.gi['a.b'], undefined);
      assert.match(messages, /using the server's default/, `the page says what it did: '${messages}'`);
      assert.equal((await pageSession(page)).params.encoding.interactive_scale, 1);
      await waitForFrames(page, 2, 'frames with the default');
    });
  } finally {
    await page.close({ runBeforeUnload: true });
    await context.close();
  }
}

/**
 * Every method `/v1/server` lists, one page each, preset from the address with the small
 * setting its table supplies for tests (`LIGHTCAST_METHODS`, written by the Rust test from the
 * registry: a method without one fails here): the panel shows its parameters and only its,
 * a stage of its own shows in the timings, and each of its debug views streams.
 */
async function everyMethod(browser, methods) {
  const server = await api('GET', '/v1/server');
  assert.deepEqual(server.gi_methods.map((m) => m.method).sort(), Object.keys(methods).sort(),
    'the test has a setting for every method the server lists');
  const everyParam = new Set(server.gi_methods.flatMap((m) => m.parameters.map((p) => p.name)));
  for (const info of server.gi_methods) {
    const { gi, stages } = methods[info.method];
    const context = await browser.newContext({ viewport: { width: 480, height: 360 } });
    const page = await context.newPage();
    const errors = [];
    page.on('pageerror', (e) => errors.push(e.message));
    try {
      await step(`${info.method} preset from the address shows its parameters and its stages`, async () => {
        const preset = Object.entries(gi).filter(([k]) => k !== 'method').map(([k, v]) => `&gi.${k}=${v}`).join('');
        await page.goto(`${base}/?method=${info.method}&scale=0.5&fps=10${preset}`);
        await page.waitForSelector('#status[data-state="live"]', { timeout: PATIENCE_MS });
        const session = (await pageSession(page)).params.render.gi;
        for (const [k, v] of Object.entries(gi)) assert.deepEqual(session[k], v, `the address presets ${k}`);
        const own = new Set(info.parameters.map((p) => p.name));
        for (const name of everyParam) {
          const shown = await page.locator(`[data-field="render.gi.${name}"]`).isVisible();
          assert.equal(shown, own.has(name), `${name} is shown only where ${info.method} reads it`);
        }
        await page.waitForFunction((names) => names.some((n) => document.querySelector(`#stage-rows tr[data-stage="${n}"]`)),
          stages, { timeout: PATIENCE_MS }).catch(() => {
          throw new Error(`none of ${info.method}'s stages ${stages.join(', ')} showed in the timings`);
        });
      });
      if (info.method === 'brsm') {
        // Issue 36: a second viewer of the same scene, light and parameters shares BRSM's
        // light-side stages, and each page's stage table says among how many sessions.
        await step('a second brsm viewer shares its light-side stages and the timings say ÷ 2', async () => {
          // A context of its own, as another viewer's browser.
          const otherContext = await browser.newContext({ viewport: { width: 480, height: 360 } });
          const other = await otherContext.newPage();
          try {
            await other.goto(page.url());
            await other.waitForSelector('#status[data-state="live"]', { timeout: PATIENCE_MS });
            // The stages whose "now" cell ends in "÷ 2", and whether there is one.
            const shared = () => [...document.querySelectorAll('#stage-rows tr')]
              .filter((tr) => /÷ 2$/.test(tr.children[2].textContent)).map((tr) => tr.dataset.stage);
            const anyShared = () => [...document.querySelectorAll('#stage-rows tr')]
              .some((tr) => /÷ 2$/.test(tr.children[2].textContent));
            const rows = (p) => p.$$eval('#stage-rows tr', (trs) => trs.map((tr) => tr.textContent).join(' | '));
            // Either page's table may show it first (the two sessions take turns making the
            // shared stages); polled by time, as a page in the background gets no animation
            // frames.
            const showing = (p) => p.waitForFunction(anyShared, null, { timeout: PATIENCE_MS, polling: 200 })
              .then(() => p);
            const first = await Promise.any([showing(page), showing(other)]).catch(async (e) => {
              throw new Error(`no page showed ÷ 2 (${e.errors.map((x) => x.message).join('; ')}): `
                + `${await rows(page)}; the second's: ${await rows(other)}`);
            });
            const stagesShared = await first.evaluate(shared);
            assert.ok(stagesShared.includes('cache_lighting'), `shared: ${stagesShared.join(', ')}`);
            return `shared (${first === page ? 'first' : 'second'} page): ${stagesShared.join(', ')}`;
          } finally {
            await other.close({ runBeforeUnload: true });
            await otherContext.close();
          }
        });
      }
      for (const { view } of info.views) {
        await step(`${info.method}'s ${view} view streams`, async () => {
          const diff = await changeAfter(page, () => page.selectOption('[data-field="render.view"]', view), `the ${view} view`);
          assert.ok(diff > 4, `the ${view} view looks like the image before it: ${diff.toFixed(2)}`);
          return `changed by ${diff.toFixed(1)} grey levels`;
        });
      }
      assert.deepEqual(errors, [], 'no page errors');
    } finally {
      await page.close({ runBeforeUnload: true });
      await context.close();
    }
  }
}

async function main() {
  await mkdir(artifacts, { recursive: true });
  const browser = await chromium.launch({ executablePath, args: CHROMIUM_ARGS, headless: true });
  const context = await browser.newContext({ viewport: { width: 800, height: 600 }, hasTouch: true, acceptDownloads: true });
  const page = await context.newPage();
  const pageErrors = [];
  page.on('pageerror', (e) => pageErrors.push(e.message));
  page.on('console', (m) => {
    if (m.type() === 'error') pageErrors.push(m.text());
  });

  try {
    // Direct light only at first and a small RSM for when BRSM is switched on: lavapipe is slow.
    await step('the page loads and goes live', async () => {
      await page.goto(`${base}/?method=none&rsm=128&scale=0.5&fps=20`);
      assert.equal(await page.title(), 'lightcast viewer');
      await page.waitForSelector('#status[data-state="live"]', { timeout: PATIENCE_MS });
    });

    await step('frames arrive and paint', async () => {
      await waitForFrames(page, 3, 'first frames');
      const first = await frameCount(page);
      await waitForFrames(page, first + 3, 'frame counter rising');
      const shot = await snapshot(page);
      assert.ok(shot.mean > 3 && shot.sd > 3, `canvas is blank: mean ${shot.mean.toFixed(1)}, sd ${shot.sd.toFixed(1)}`);
    });

    // Chromium decodes H.264 in WebCodecs on http://127.0.0.1 (a secure context), so the page
    // asks for it: every step below runs on an h264 stream.
    await step('the stream is H.264, decoded with WebCodecs', async () => {
      assert.equal(await page.$eval('body', (b) => b.dataset.decodesH264), 'true', 'the page found an H.264 decoder');
      assert.equal((await pageSession(page)).params.encoding.codec, 'h264', 'the session streams h264');
      // Read with the codec in one look: a PNG still may follow the H.264 frames once input
      // rests (under load it once did between two separate reads).
      const info = await (await page.waitForFunction(() => {
        const text = document.getElementById('frame-info').textContent;
        return document.getElementById('frame').dataset.codec === 'h264' && /H\.264/.test(text) && text;
      }, null, { timeout: PATIENCE_MS })).jsonValue();
      assert.match(info, /H\.264.*target \d+\.\d Mbit\/s \(auto\)/, `the frame line names the codec and the automatic bitrate: '${info}'`);
      assert.equal((await pageSession(page)).params.encoding.bitrate_kbps, null, 'the bitrate is automatic by default');
      // A bitrate typed in the panel is the session's; emptying the field makes it automatic again.
      const bitrate = page.locator('[data-field="encoding.bitrate_kbps"]');
      const frameLine = (pattern) => page.waitForFunction((p) => new RegExp(p).test(document.getElementById('frame-info').textContent),
        pattern, { timeout: PATIENCE_MS });
      await bitrate.fill('2500');
      await bitrate.press('Enter');
      await bitrate.blur();
      await frameLine('target 2\\.5 Mbit/s ·');
      assert.equal((await pageSession(page)).params.encoding.bitrate_kbps, 2500);
      await bitrate.fill('');
      await bitrate.press('Enter');
      await bitrate.blur();
      await frameLine('Mbit/s \\(auto\\)');
      assert.equal((await pageSession(page)).params.encoding.bitrate_kbps, null, 'an empty field restores the automatic bitrate');
      await page.waitForFunction(() => Number.isFinite(Number(document.getElementById('decode-ms').textContent)),
        null, { timeout: 5000 }).catch(async () => {
        throw new Error(`decode ms is not shown (got '${await page.$eval('#decode-ms', (e) => e.textContent)}')`);
      });
    });

    await step('a drag changes the image', async () => {
      const box = await page.locator('#frame').boundingBox();
      const [x, y] = [box.x + box.width / 2, box.y + box.height / 2];
      const diff = await changeAfter(page, async () => {
        await page.mouse.move(x, y);
        await page.mouse.down();
        for (let i = 1; i <= 10; i++) await page.mouse.move(x + i * 12, y + i * 3);
        await page.mouse.up();
      }, 'the drag');
      assert.ok(diff > 4, `the image hardly changed after the drag: mean abs diff ${diff.toFixed(2)} grey levels`);
      // interactive_scale 0.5 (the viewer's default): frames while dragging are half size,
      // stretched to the canvas; the still after rest is full size again.
      const reduced = await page.$eval('#frame', (c) => Number(c.dataset.reducedFrames || 0));
      assert.ok(reduced > 0, 'no half-size frame was painted while dragging');
      const full = (await pageSession(page)).params.render;
      await page.waitForFunction((size) => document.getElementById('frame').dataset.frameSize === size,
        `${full.width}x${full.height}`, { timeout: PATIENCE_MS }).catch(async () => {
        throw new Error(`no full-size frame at rest (last ${await page.$eval('#frame', (c) => c.dataset.frameSize)})`);
      });
      // The counters are redrawn four times a second.
      await page.waitForFunction(() => /^\d+ \/ \d+$/.test(document.getElementById('latency').textContent),
        null, { timeout: 5000 }).catch(async () => {
        throw new Error(`input→frame latency is not shown (got '${await page.$eval('#latency', (e) => e.textContent)}')`);
      });
    });

    // Issue 31: a drag across half the canvas turned the default camera out of the room,
    // where every wall is seen from behind, black. Half a canvas is now a quarter turn, and
    // the camera stays in the scene's camera region.
    await step('a long drag keeps the camera where the room is seen from inside', async () => {
      const scene = await api('GET', '/v1/scenes/default');
      const region = scene.camera_region;
      assert.ok(region, 'the built-in Cornell box has a camera region');
      await page.screenshot({ path: path.join(artifacts, 'drag-before.png') });
      const before = await snapshot(page);
      const box = await page.locator('#frame').boundingBox();
      const [x, y] = [box.x + box.width * 0.25, box.y + box.height / 2];
      await changeAfter(page, async () => {
        await page.mouse.move(x, y);
        await page.mouse.down();
        for (let i = 1; i <= 10; i++) await page.mouse.move(x + (i * box.width) / 20, y);
        await page.mouse.up();
      }, 'the long drag');
      const { position } = (await pageSession(page)).params.render.camera;
      position.forEach((v, i) => assert.ok(v >= region.min[i] && v <= region.max[i],
        `camera ${JSON.stringify(position)} left the region ${JSON.stringify(region)}`));
      const after = await snapshot(page);
      await page.screenshot({ path: path.join(artifacts, 'drag-after.png') });
      assert.ok(after.mean > 0.5 * before.mean,
        `the view went dark: mean grey ${before.mean.toFixed(1)} → ${after.mean.toFixed(1)}`);
    });

    await step('shift-drag pans: the camera target moves', async () => {
      const before = (await pageSession(page)).params.render.camera.target;
      const box = await page.locator('#frame').boundingBox();
      const [x, y] = [box.x + box.width / 2, box.y + box.height / 2];
      const diff = await changeAfter(page, async () => {
        await page.keyboard.down('Shift');
        await page.mouse.move(x, y);
        await page.mouse.down();
        for (let i = 1; i <= 6; i++) await page.mouse.move(x + i * 10, y - i * 6);
        await page.mouse.up();
        await page.keyboard.up('Shift');
      }, 'the shift-drag');
      assert.ok(diff > 2, `panning hardly changed the image: ${diff.toFixed(2)}`);
      const after = (await pageSession(page)).params.render.camera.target;
      const moved = Math.hypot(...after.map((v, i) => v - before[i]));
      assert.ok(moved > 0.05, `the target moved by only ${moved.toFixed(3)}`);
    });

    await step('the wheel zooms and W flies forward', async () => {
      const box = await page.locator('#frame').boundingBox();
      const zoom = await changeAfter(page, async () => {
        await page.mouse.move(box.x + box.width / 2, box.y + box.height / 2);
        await page.mouse.wheel(0, 300);
      }, 'the wheel');
      assert.ok(zoom > 4, `the wheel hardly changed the image: ${zoom.toFixed(2)}`);
      const fly = await changeAfter(page, async () => {
        await page.focus('#frame');
        await page.keyboard.down('w');
        await page.waitForTimeout(700);
        await page.keyboard.up('w');
      }, 'the W key');
      assert.ok(fly > 4, `W hardly changed the image: ${fly.toFixed(2)}`);
    });

    await step('touch: one finger orbits, two fingers pinch', async () => {
      const cdp = await page.context().newCDPSession(page);
      const box = await page.locator('#frame').boundingBox();
      const [x, y] = [box.x + box.width / 2, box.y + box.height / 2];
      const touch = (type, points) => cdp.send('Input.dispatchTouchEvent', {
        type, touchPoints: points.map(([px, py], id) => ({ x: px, y: py, id })),
      });
      const orbit = await changeAfter(page, async () => {
        await touch('touchStart', [[x, y]]);
        for (let i = 1; i <= 8; i++) await touch('touchMove', [[x - i * 12, y]]);
        await touch('touchEnd', []);
      }, 'a one-finger drag');
      assert.ok(orbit > 4, `a one-finger drag hardly changed the image: ${orbit.toFixed(2)}`);
      const distance = async () => {
        const { params: { render: { camera } } } = await pageSession(page);
        return Math.hypot(...camera.position.map((p, i) => p - camera.target[i]));
      };
      const before = await distance();
      const pinch = await changeAfter(page, async () => {
        await touch('touchStart', [[x - 20, y], [x + 20, y]]);
        for (let i = 1; i <= 8; i++) await touch('touchMove', [[x - 20 - i * 10, y], [x + 20 + i * 10, y]]);
        await touch('touchEnd', []);
      }, 'a pinch');
      assert.ok(pinch > 4, `a pinch hardly changed the image: ${pinch.toFixed(2)}`);
      const after = await distance();
      assert.ok(after < 0.8 * before, `spreading two fingers moves the camera closer: ${before.toFixed(2)} → ${after.toFixed(2)}`);
      await cdp.detach();
    });

    await step('dragging in light mode moves the light', async () => {
      const before = await pageSession(page);
      assert.equal(before.params.render.light, null, 'the scene lights at first');
      assert.equal(before.params.render.lights, null, 'the scene lights at first');
      await page.check('input[name="drag-mode"][value="light"]');
      const box = await page.locator('#frame').boundingBox();
      const diff = await changeAfter(page, async () => {
        const [x, y] = [box.x + box.width / 2, box.y + box.height / 2];
        await page.mouse.move(x, y);
        await page.mouse.down();
        for (let i = 1; i <= 8; i++) await page.mouse.move(x - i * 10, y + i * 4);
        await page.mouse.up();
      }, 'the light drag');
      assert.ok(diff > 2, `moving the light hardly changed the image: ${diff.toFixed(2)}`);
      const after = await pageSession(page);
      assert.equal(after.params.render.lights.length, 1, 'the session has its own light now (the scene has one)');
      await page.check('input[name="drag-mode"][value="camera"]');
    });

    await step('objects mode: a press picks the short box, a drag slides it along the floor, and it goes back', async () => {
      await page.click('#reset-camera');
      await page.waitForFunction(() => !document.getElementById('objects-controls').hidden, null, { timeout: PATIENCE_MS });
      let session = await pageSession(page);
      for (const started = Date.now(); session.params.render.camera != null; session = await pageSession(page)) {
        assert.ok(Date.now() - started < PATIENCE_MS, 'the camera was never reset');
        await page.waitForTimeout(100);
      }
      const scene = await api('GET', `/v1/scenes/${session.params.render.scene}`);
      const short = scene.nodes.find((n) => n.name === 'short box');
      assert.ok(short && short.movable, JSON.stringify(scene.nodes));
      const { min, max } = short.bounds;
      const top = [(min[0] + max[0]) / 2, max[1], (min[2] + max[2]) / 2];
      const [fx, fy] = project({ ...session.params.render, camera: scene.default_camera }, top);
      const box = await page.locator('#frame').boundingBox();
      const [x, y] = [box.x + fx * box.width, box.y + fy * box.height];
      await page.check('input[name="drag-mode"][value="objects"]');
      const diff = await changeAfter(page, async () => {
        await page.mouse.move(x, y);
        await page.mouse.down();
        await page.waitForFunction((id) => document.getElementById('node-selected').dataset.node === id,
          String(short.id), { timeout: PATIENCE_MS });
        for (let i = 1; i <= 8; i++) await page.mouse.move(x - i * 6, y);
        await page.mouse.up();
      }, 'the object drag');
      assert.ok(diff > 1, `sliding the short box hardly changed the image: ${diff.toFixed(2)}`);
      const moved = (await pageSession(page)).params.render.nodes;
      assert.equal(moved.length, 1, JSON.stringify(moved));
      assert.equal(moved[0].node, short.id);
      const [dx, dy, dz] = moved[0].translation.map((v, i) => v - short.translation[i]);
      // Dragged leftwards on screen: towards −x, on the floor (the camera looks down −z).
      assert.ok(dx < -0.02 && Math.abs(dy) < 1e-4 && Math.abs(dz) < 0.05, `moved by ${[dx, dy, dz]}`);
      assert.match(await page.textContent('#node-selected'), /short box/);
      const back = await changeAfter(page, () => page.click('#node-reset'), 'putting it back');
      assert.ok(back > 1, `putting the box back hardly changed the image: ${back.toFixed(2)}`);
      assert.equal((await pageSession(page)).params.render.nodes, undefined, 'no poses left');
      // A click without a drag picks the box and moves nothing.
      await page.mouse.move(x, y);
      await page.mouse.down();
      await page.waitForFunction(() => /short box/.test(document.getElementById('node-selected').textContent),
        null, { timeout: PATIENCE_MS });
      await page.mouse.up();
      await page.waitForTimeout(300);
      assert.equal((await pageSession(page)).params.render.nodes, undefined, 'a click moved the box');
      // The back wall is the room's: it does not move, and a drag there moves nothing.
      const [wx, wy] = project({ ...session.params.render, camera: scene.default_camera },
        [0, scene.bounds.max[1] * 0.8, scene.bounds.min[2]]);
      await page.mouse.move(box.x + wx * box.width, box.y + wy * box.height);
      await page.mouse.down();
      await page.waitForFunction(() => /does not move/.test(document.getElementById('node-selected').textContent),
        null, { timeout: PATIENCE_MS });
      await page.mouse.move(box.x + wx * box.width + 40, box.y + wy * box.height);
      await page.mouse.up();
      assert.equal((await pageSession(page)).params.render.nodes, undefined, 'the room stayed');
      await page.check('input[name="drag-mode"][value="camera"]');
    });

    await step('a GI parameter change shows up in the timings', async () => {
      assert.equal(await page.locator('#stage-rows tr[data-stage="importance"]').count(), 0, 'no BRSM stage with GI off');
      await page.selectOption('[data-field="render.gi.method"]', 'brsm');
      await page.waitForSelector('#stage-rows tr[data-stage="importance"]', { timeout: PATIENCE_MS });
      await page.waitForSelector('#stage-rows tr[data-stage="cache_lighting"]', { timeout: PATIENCE_MS });
    });

    await step('the parameter panel follows the method and the reference converges', async () => {
      assert.ok(await page.locator('[data-field="render.gi.view_samples"]').isVisible(), 'brsm shows its view samples');
      await page.selectOption('[data-field="render.gi.method"]', 'reference');
      await page.waitForSelector('[data-field="render.gi.spp"]', { state: 'visible', timeout: PATIENCE_MS });
      assert.ok(!(await page.locator('[data-field="render.gi.view_samples"]').isVisible()), 'reference hides BRSM parameters');
      await page.waitForFunction(() => {
        const m = /(\d+) spp/.exec(document.getElementById('frame-info').textContent);
        return m && Number(m[1]) >= 8;
      }, null, { timeout: PATIENCE_MS });
      await page.selectOption('[data-field="render.gi.method"]', 'brsm');
      await page.waitForSelector('[data-field="render.gi.view_samples"]', { state: 'visible', timeout: PATIENCE_MS });
    });

    await step('clustered shows its parameters, its visibility choice and its stages', async () => {
      await page.selectOption('[data-field="render.gi.method"]', 'clustered');
      await page.waitForSelector('[data-field="render.gi.vpl_count"]', { state: 'visible', timeout: PATIENCE_MS });
      const choices = await page.locator('[data-field="render.gi.visibility"] option').allTextContents();
      assert.deepEqual(choices, ['off', 'cssm', 'vpl_shadows'], 'the visibility choices come from /v1/server');
      assert.ok(!(await page.locator('[data-field="render.gi.view_samples"]').isVisible()), 'clustered hides BRSM parameters');
      await page.waitForSelector('#stage-rows tr[data-stage="clustering"]', { timeout: PATIENCE_MS });
      await page.waitForSelector('#stage-rows tr[data-stage="paraboloid_maps"]', { timeout: PATIENCE_MS });
      await page.selectOption('[data-field="render.gi.method"]', 'brsm');
      await page.waitForSelector('[data-field="render.gi.view_samples"]', { state: 'visible', timeout: PATIENCE_MS });
    });

    await step('a debug view shows', async () => {
      // The menu is the server's: final plus every method's views, only the current method's enabled.
      const server = await api('GET', '/v1/server');
      const expected = ['final', ...new Set(server.gi_methods.flatMap((m) => m.views.map((v) => v.view)))];
      const options = await page.$$eval('[data-field="render.view"] option', (os) => os.map((o) => [o.value, o.disabled]));
      assert.deepEqual(options.map(([v]) => v).sort(), expected.sort(), 'the view menu lists the server\'s views');
      const brsm = server.gi_methods.find((m) => m.method === 'brsm').views.map((v) => v.view);
      for (const [view, disabled] of options) {
        assert.equal(disabled, view !== 'final' && !brsm.includes(view), `${view} is offered only if brsm draws it`);
      }
      const diff = await changeAfter(page, () => page.selectOption('[data-field="render.view"]', 'rsm-flux'), 'the RSM flux view');
      assert.ok(diff > 4, `the RSM flux view looks like the frame: ${diff.toFixed(2)}`);
      // A method that does not draw the view brings the final frame back instead of being refused.
      await page.selectOption('[data-field="render.gi.method"]', 'clustered');
      for (let i = 0; ; i++) {
        const render = (await pageSession(page)).params.render;
        if (render.gi.method === 'clustered') {
          assert.equal(render.view, 'final', 'the view went back to final');
          break;
        }
        assert.ok(i < 100, 'the method switch never reached the session');
        await new Promise((r) => setTimeout(r, 100));
      }
      await page.selectOption('[data-field="render.gi.method"]', 'brsm');
      await page.waitForSelector('[data-field="render.gi.view_samples"]', { state: 'visible', timeout: PATIENCE_MS });
    });

    await step('a rejected parameter is shown, naming the field', async () => {
      const limits = (await api('GET', '/v1/server')).limits;
      const control = page.locator('[data-field="render.gi.view_samples"]');
      await control.fill(String(limits.max_view_samples + 1));
      await control.press('Enter');
      await control.blur();
      await page.waitForSelector('[data-field="render.gi.view_samples"].invalid', { timeout: PATIENCE_MS });
      const messages = await page.$eval('#messages', (e) => e.textContent);
      assert.match(messages, /view_samples/, `the message names the field: '${messages}'`);
    });

    await step('the still downloads as PNG with its timing report', async () => {
      const [download] = await Promise.all([
        page.waitForEvent('download', { timeout: PATIENCE_MS }),
        page.click('#still'),
      ]);
      const file = path.join(artifacts, 'still.png');
      await download.saveAs(file);
      const chunks = pngChunks(await readFile(file));
      const itxt = chunks.find(([type, data]) => type === 'iTXt' && data.toString('latin1').startsWith('lightcast-report\0'));
      assert.ok(itxt, `the PNG has a lightcast-report chunk (chunks: ${chunks.map((c) => c[0]).join(' ')})`);
      const report = JSON.parse(itxt[1].subarray('lightcast-report'.length + 5).toString('utf8'));
      assert.match(report.request_hash, /^[0-9a-f]{64}$/);
      assert.ok(report.stages.some((s) => s.stage === 'importance'), 'the still was rendered with BRSM');
      await page.waitForSelector('#still-report:not([hidden])');
    });

    await step('a deleted session is replaced by itself', async () => {
      const session = await pageSession(page);
      await api('DELETE', `/v1/sessions/${session.id}`);
      await page.waitForFunction(() => document.getElementById('messages').textContent.includes('session ended'),
        null, { timeout: PATIENCE_MS });
      await page.waitForFunction((old) => {
        const status = document.getElementById('status');
        return status.dataset.state === 'live' && !status.textContent.includes(old);
      }, session.id, { timeout: PATIENCE_MS });
      const replacement = await pageSession(page);
      assert.notEqual(replacement.id, session.id);
      assert.equal(replacement.params.render.gi.method, 'brsm', 'the new session keeps the parameters');
      const count = await frameCount(page);
      await waitForFrames(page, count + 2, 'frames of the new session');
    });

    assert.deepEqual(pageErrors, [], 'the page logged errors');

    await step('an unreachable server is reported, and the viewer comes back by itself', async () => {
      // Every API request of the page now fails as if the server were down; ending the session
      // makes the page reconnect into that.
      await page.route('**/v1/**', (route) => route.abort('connectionrefused'));
      const session = await pageSession(page);
      await api('DELETE', `/v1/sessions/${session.id}`);
      await page.waitForFunction(() => {
        const status = document.getElementById('status');
        return status.dataset.state === 'unreachable' && /cannot be reached.*retrying/.test(status.textContent);
      }, null, { timeout: PATIENCE_MS });
      await page.unroute('**/v1/**');
      await page.waitForSelector('#status[data-state="live"]', { timeout: PATIENCE_MS });
      const count = await frameCount(page);
      await waitForFrames(page, count + 2, 'frames after coming back');
    });

    await step('a procedural street scene built from the page, its sun turned by the slider', async () => {
      const previous = await page.inputValue('#scene-select');
      await changeAfter(page, async () => {
        await page.fill('#procedural-spec', 'street?blocks=2');
        await page.click('#procedural-form button[type="submit"]');
        await waitForSceneSwitch(page, previous);
      }, 'switching to the street');
      await page.waitForSelector('#sun-controls:not([hidden])', { timeout: PATIENCE_MS });
      const diff = await changeAfter(page, async () => {
        const slider = page.locator('#sun-elevation');
        await slider.fill(Number(await slider.inputValue()) > 45 ? '10' : '80');
      }, 'the sun elevation slider');
      assert.ok(diff > 4, `turning the sun hardly changed the street: ${diff.toFixed(2)}`);
      const session = await pageSession(page);
      assert.equal(session.params.render.lights[0].kind, 'directional');
    });

    await step('the sky menu turns the daylight sky on around the sun, and off', async () => {
      const environment = '[data-field="render.environment"]';
      const on = await changeAfter(page, () => page.selectOption(environment, 'sky'), 'turning the sky on');
      assert.ok(on > 4, `the sky hardly changed the street: ${on.toFixed(2)}`);
      await page.waitForSelector('#environment-controls:not([hidden])', { timeout: PATIENCE_MS });
      assert.ok(await page.locator('#environment-turbidity').isVisible(), 'a sky shows its turbidity');
      assert.equal((await pageSession(page)).params.render.environment.kind, 'sky');
      const off = await changeAfter(page, () => page.selectOption(environment, 'none'), 'turning the sky off');
      assert.ok(off > 4, `turning the sky off hardly changed the street: ${off.toFixed(2)}`);
      assert.equal((await pageSession(page)).params.render.environment, null);
      assert.ok(await page.locator('#environment-controls').isHidden(), 'no sky, no sky settings');
    });

    await step('the light list adds a light, recolours it and removes it', async () => {
      const before = (await pageSession(page)).params.render.lights.length;
      const added = await changeAfter(page, () => page.click('#light-add'), 'adding a light');
      assert.ok(added > 4, `a second sun hardly changed the street: ${added.toFixed(2)}`);
      let lights = (await pageSession(page)).params.render.lights;
      assert.equal(lights.length, before + 1);
      assert.equal(await page.inputValue('#light-select'), String(before), 'the new light is selected');
      const recoloured = await changeAfter(page, () => page.fill('#light-color', '#ff0000'), 'recolouring it');
      assert.ok(recoloured > 4, `a red sun hardly changed the street: ${recoloured.toFixed(2)}`);
      lights = (await pageSession(page)).params.render.lights;
      assert.ok(lights[before].color[0] > 0.99 && lights[before].color[1] < 0.01, JSON.stringify(lights[before]));
      const removed = await changeAfter(page, () => page.click('#light-remove'), 'removing it');
      assert.ok(removed > 4, `removing the red sun hardly changed the street: ${removed.toFixed(2)}`);
      assert.equal((await pageSession(page)).params.render.lights.length, before);
    });

    if (process.env.LIGHTCAST_UPLOAD_SCENE) {
      await step('a scene uploaded from the page streams', async () => {
        // The new scene starts from its own camera, so the orbited view changes.
        const previous = await page.inputValue('#scene-select');
        const diff = await changeAfter(page, async () => {
          await page.setInputFiles('#scene-upload', process.env.LIGHTCAST_UPLOAD_SCENE);
          await waitForSceneSwitch(page, previous);
        }, 'switching to the uploaded scene');
        assert.ok(diff > 4, `the uploaded scene looks like the orbited default scene: ${diff.toFixed(2)}`);
        const session = await pageSession(page);
        assert.equal(session.params.render.scene, await page.inputValue('#scene-select'), 'the session switched to the upload');
        assert.notEqual(session.params.render.scene, previous);
        await page.waitForFunction(() => /\d light caches/.test(document.getElementById('scene-state').textContent),
          null, { timeout: PATIENCE_MS });
      });
    }

    if (process.env.LIGHTCAST_ANIMATED_SCENE) {
      await step('an animated scene plays, pauses and scrubs from the Objects section', async () => {
        const previous = await page.inputValue('#scene-select');
        await page.setInputFiles('#scene-upload', process.env.LIGHTCAST_ANIMATED_SCENE);
        await waitForSceneSwitch(page, previous);
        await page.waitForFunction(() => !document.getElementById('animation-controls').hidden, null, { timeout: PATIENCE_MS });
        const animation = async () => (await pageSession(page)).params.render.animation;
        const until = async (test, what) => {
          for (const started = Date.now(); Date.now() - started < PATIENCE_MS; await page.waitForTimeout(100)) {
            const a = await animation();
            if (test(a)) return a;
          }
          throw new Error(`the session's animation never ${what}: ${JSON.stringify(await animation())}`);
        };
        await page.click('#animation-play');
        await until((a) => a && a.name === 'slide' && a.playing !== false, 'played');
        await page.waitForFunction(() => document.getElementById('animation-play').textContent === 'Pause', null, { timeout: PATIENCE_MS });
        await page.click('#animation-play');
        await until((a) => a && a.playing === false, 'paused');
        await page.$eval('#animation-time', (e) => { e.value = '1.5'; e.dispatchEvent(new Event('input')); });
        const scrubbed = await until((a) => a && Math.abs(a.time - 1.5) < 1e-3, 'scrubbed to 1.5 s');
        assert.equal(scrubbed.playing, false);
      });
    }

    await step('screenshot', () => page.screenshot({ path: path.join(artifacts, 'viewer.png') }));
    const unexpected = pageErrors.filter((e) => !e.includes('ERR_CONNECTION_REFUSED'));
    assert.deepEqual(unexpected, [], 'the page logged errors other than the refused requests of the outage');

    await step('closing the page ends its session', async () => {
      const id = await pageSessionId(page);
      await page.close({ runBeforeUnload: true });
      const deadline = Date.now() + 10000;
      do {
        if ((await fetch(`${base}/v1/sessions/${id}`)).status === 404) return;
        await new Promise((r) => setTimeout(r, 200));
      } while (Date.now() < deadline);
      throw new Error(`session ${id} is left after the page closed`);
    });
    await withoutWebCodecs(browser);
    await everyMethod(browser, JSON.parse(process.env.LIGHTCAST_METHODS));
    await apiPage(browser);
    if (process.env.LIGHTCAST_AUTH_URL) await withAuth(browser, process.env.LIGHTCAST_AUTH_URL, process.env.LIGHTCAST_AUTH_TOKEN);
  } catch (e) {
    if (!page.isClosed()) await page.screenshot({ path: path.join(artifacts, 'viewer-failure.png') }).catch(() => {});
    throw e;
  } finally {
    await browser.close();
  }
  console.log(`viewer test: passed; screenshot and still in ${artifacts}`);
}

main().catch((e) => {
  console.error(e.message);
  process.exit(1);
});
