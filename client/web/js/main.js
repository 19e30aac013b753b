// The viewer's page: wires the stream, the controls, the parameter form and the numbers
// together. Everything it shows comes from the public API (`/v1/…`) and the session's
// WebSocket; nothing is fetched from anywhere else.

import { ApiError, Unreachable, getJson, request, setToken, takeTokenFromFragment } from './api.js';
import { Connection } from './connection.js';
import { Controls, sunAngles, sunDirection } from './controls.js';
import { FLAG_GI_PENDING, FrameError, decodeFrame } from './frame.js';
import { Panel, patchFor } from './panel.js';
import { Stats } from './stats.js';
import { download, renderStill } from './still.js';
import { H264Decoder, canDecodeH264 } from './video.js';
import { ObjectDrag, intoSpace, quatMul } from './objects.js';

const $ = (id) => document.getElementById(id);
const MAX_MESSAGES = 4;
const RESIZE_DEBOUNCE_MS = 250;
const SCENE_POLL_MS = 500;
// Inputs whose frame never comes (a paused session) are forgotten beyond this many.
const MAX_PENDING_INPUTS = 1000;
// Camera and light messages at most this often, acknowledgements at most every ACK_EVERY_MS:
// together well inside the server's default of 120 control messages per second, also on
// 144 Hz displays and at high fps caps.
const MIN_INPUT_INTERVAL_MS = 16;
const ACK_EVERY_MS = 100;
// A pick is answered by the next frame; lavapipe's can take seconds.
const PICK_TIMEOUT_MS = 30000;

const canvas = $('frame');
const context = canvas.getContext('2d');
const state = {
  server: null,
  scenes: new Map(),
  scene: null,
  params: null,
  connection: null,
  inputId: 0,
  sentInputs: new Map(),
  drawnSeq: 0,
  queued: { camera: null, light: null, nodes: null, animation: null },
  lastFlush: 0,
  lastAck: 0,
  /** The session's punctual lights as this page last sent them, and the selected one's index
   * (`light` is that light: the one the editor and light-mode drags change). */
  lights: [],
  selected: 0,
  light: null,
  sessionId: null,
  /** The scene whose precomputations `watchScene` is polling, if any. */
  watching: null,
  /** Whether this page decodes H.264 (WebCodecs), probed at start. */
  decodesH264: false,
  /** The codecs the server encodes, from `/v1/server` and then each `hello`. */
  serverCodecs: ['jpeg', 'png'],
  /** `pick` messages awaiting their `picked` event, by nonce; nonces start at random, as
   * every page on a session hears every `picked`. */
  picks: new Map(),
  pickNonce: Math.floor(Math.random() * 2 ** 40),
  /** The session's node poses as this page last sent or heard them, by node id. */
  poses: new Map(),
  /** The movable node last picked (its `nodes` entry of the scene), or null, and its pose in
   * the frame that answered the pick. */
  node: null,
  shownPose: null,
};

const stats = new Stats({
  frameCount: $('frame-count'), fps: $('fps'), latency: $('latency'), bandwidth: $('bandwidth'),
  gpu: $('gpu-ms'), readback: $('readback-ms'), encode: $('encode-ms'), decode: $('decode-ms'),
  dropped: $('dropped'),
  frameInfo: $('frame-info'), stageRows: $('stage-rows'), stageChart: $('stage-chart'),
  fpsChart: $('fps-chart'), latencyChart: $('latency-chart'), bandwidthChart: $('bandwidth-chart'),
});
const video = new H264Decoder(paintVideo, (reason) => {
  if (state.connection && state.connection.send({ type: 'keyframe' })) {
    canvas.dataset.keyframeRequests = String(Number(canvas.dataset.keyframeRequests || 0) + 1);
  }
  message(`${reason}: asked the server for a keyframe`, 'info', 4000);
});
const panel = new Panel($('panel'), (patch) => sendUpdate(patch));
const controls = new Controls(canvas, {
  onCamera: (camera) => queueInput('camera', camera),
  onLight: (light) => {
    state.lights[state.selected] = light;
    state.light = light;
    showLight();
    queueInput('light', { index: state.selected, light });
  },
});
controls.objects = new ObjectDrag(canvas, controls, {
  pick: requestPick,
  scene: () => state.scene,
  // The frame's own aspect: the stream's size is clamped per side, the canvas's is not.
  aspect: () => (state.params ? state.params.render.width / state.params.render.height : 1),
  onPose: queuePose,
  onSelect: selectNode,
});

function message(text, kind = 'error', ttlMs = 10000) {
  const box = $('messages');
  const div = document.createElement('div');
  div.className = `message ${kind}`;
  div.textContent = text;
  box.append(div);
  while (box.children.length > MAX_MESSAGES) box.firstElementChild.remove();
  setTimeout(() => div.remove(), ttlMs);
}

function showError(error, what) {
  // The server's messages usually start with the field; name it only where they do not.
  const field = error.field && !error.message.startsWith(error.field) ? ` (${error.field})` : '';
  message(`${what}: ${error.message}${field}`);
  if (error.field) panel.markError(error.field, error.message);
}

function setStatus(kind, text) {
  const status = $('status');
  status.dataset.state = kind;
  status.textContent = text;
  if (kind === 'unauthorized') askToken(text);
}

// ---- input: at most one message of each kind per animation frame ----

/** Each queued kind's message. */
const INPUT_MESSAGES = {
  camera: (camera) => ({ type: 'camera', camera }),
  // The selected light, by its index (the others stay).
  light: (value) => ({ type: 'light', light: value.light, index: value.index }),
  // One node's pose (the session keeps the others').
  nodes: (pose) => ({ type: 'nodes', nodes: [pose] }),
  animation: (value) => ({ type: 'animation', ...value }),
};

function queueInput(kind, value) {
  const idle = Object.values(state.queued).every((v) => !v);
  state.queued[kind] = value;
  if (idle) requestAnimationFrame(flushInput);
}

function flushInput(now) {
  if (now - state.lastFlush < MIN_INPUT_INTERVAL_MS) {
    requestAnimationFrame(flushInput);
    return;
  }
  state.lastFlush = now;
  for (const [kind, message] of Object.entries(INPUT_MESSAGES)) {
    const value = state.queued[kind];
    if (!value) continue;
    state.queued[kind] = null;
    send(message(value));
  }
}

/** Sends a control message with a fresh input id, remembered to measure input→frame latency. */
function send(msg) {
  const id = ++state.inputId;
  if (state.connection && state.connection.send({ ...msg, input_id: id })) {
    state.sentInputs.set(id, performance.now());
    if (state.sentInputs.size > MAX_PENDING_INPUTS) state.sentInputs.delete(state.sentInputs.keys().next().value);
    // Exposed for tests and for anyone inspecting the page: the newest input sent and the
    // newest one a painted frame shows.
    canvas.dataset.sentInput = String(id);
    return true;
  }
  return false;
}

function sendUpdate(patch) {
  if (!send({ type: 'update', patch })) {
    message('not connected: the change was not sent; try again once the stream is live');
  }
}

// ---- frames ----

async function onFrame(buffer) {
  let frame;
  try {
    frame = decodeFrame(buffer);
  } catch (e) {
    if (e instanceof FrameError) message(`bad frame: ${e.message}`);
    return;
  }
  // Input→frame latency runs from sending the input to painting the first frame showing it.
  let sentAt = null;
  if (frame.inputId && state.sentInputs.has(frame.inputId)) {
    sentAt = state.sentInputs.get(frame.inputId);
    for (const id of state.sentInputs.keys()) if (id <= frame.inputId) state.sentInputs.delete(id);
  }
  if (frame.codec === 'h264') {
    // Painted by the decoder's output callback (`paintVideo`), in order.
    frame.sentAt = sentAt;
    video.decode(frame);
    return;
  }
  const received = performance.now();
  let bitmap;
  try {
    bitmap = await createImageBitmap(new Blob([frame.payload], { type: frame.mime }));
  } catch (e) {
    message(`frame ${frame.seq} could not be decoded: ${e.message}`);
    return;
  }
  paint(bitmap, bitmap.width, bitmap.height, frame, sentAt, performance.now() - received);
  bitmap.close();
}

function paintVideo(picture, frame, decodeMs) {
  paint(picture, picture.displayWidth, picture.displayHeight, frame, frame.sentAt, decodeMs);
  picture.close();
}

/** Paints a decoded frame (an ImageBitmap or a VideoFrame) unless a newer one is showing. */
function paint(image, width, height, frame, sentAt, decodeMs) {
  // Decoding finishes out of order sometimes; never paint an older frame over a newer one.
  if (frame.seq <= state.drawnSeq) return;
  state.drawnSeq = frame.seq;
  // Sized by the decoded image, not the header's claim; a frame rendered smaller while the
  // view moves (`encoding.interactive_scale`) is stretched to the session's full size.
  const full = state.params && state.params.render;
  const reduced = full && width < full.width && height < full.height;
  const size = reduced ? full : { width, height };
  if (canvas.width !== size.width || canvas.height !== size.height) {
    canvas.width = size.width;
    canvas.height = size.height;
  }
  context.drawImage(image, 0, 0, canvas.width, canvas.height);
  const now = performance.now();
  canvas.dataset.shownInput = String(frame.inputId);
  // For tests and anyone inspecting the page: what the painted frame was.
  canvas.dataset.codec = frame.codec;
  canvas.dataset.frameSize = `${width}x${height}`;
  if (reduced) canvas.dataset.reducedFrames = String(Number(canvas.dataset.reducedFrames || 0) + 1);
  stats.frame(frame, sentAt === null ? null : now - sentAt, decodeMs);
  $('hud').dataset.giPending = String((frame.flags & FLAG_GI_PENDING) !== 0);
  if (now - state.lastAck >= ACK_EVERY_MS) {
    state.lastAck = now;
    state.connection.send({ type: 'ack', seq: frame.seq });
  }
}

// ---- session and scene ----

function onSession(session) {
  const first = !state.params || state.params.render.scene !== session.params.render.scene;
  const restarted = state.sessionId !== session.id;
  state.sessionId = session.id;
  state.params = session.params;
  if (restarted) {
    state.drawnSeq = 0;
    stats.resetSequence();
    video.reset();
  }
  stats.setEncoding(session.params.encoding, session.params.fps_cap);
  panel.clearErrors();
  panel.show(session.params);
  $('scene-select').value = session.params.render.scene;
  $('pause').textContent = session.params.paused ? 'Resume' : 'Pause';
  // Poses the page has queued but not sent yet stay; the session's are the rest.
  const queued = state.queued.nodes;
  state.poses = new Map((session.params.render.nodes || []).map((n) => [n.node, n]));
  if (queued) state.poses.set(queued.node, queued);
  if (first) useScene(session.params.render.scene, session.params.render);
  else showAnimation();
}

async function useScene(id, render) {
  let scene;
  try {
    scene = await getJson(`v1/scenes/${encodeURIComponent(id)}`);
  } catch (e) {
    showError(e, `scene ${id}`);
    return;
  }
  // A quicker switch to another scene may have overtaken this one.
  if (!state.params || state.params.render.scene !== id) return;
  state.scene = scene;
  const [min, max] = [scene.bounds.min, scene.bounds.max];
  controls.setSceneSize(Math.hypot(max[0] - min[0], max[1] - min[1], max[2] - min[2]));
  controls.setRegion(scene.camera_region || null);
  const imageOption = document.getElementById('environment-image');
  if (imageOption) {
    const image = scene.environment_image;
    imageOption.disabled = !image;
    imageOption.title = image ? `${image.name}, ${image.width}×${image.height}` : 'upload a .hdr or .exr file with the scene';
  }
  controls.setCamera(render.camera || scene.default_camera);
  state.lights = structuredClone(render.lights || (render.light ? [render.light] : scene.default_lights || [scene.default_light]));
  selectLight(0);
  showObjects(scene);
  watchScene(id);
}

/** One of the scene's precomputations (light caches, BVH) as the scene line shows it. */
function describePrecomputed(p) {
  if (p.state === 'ready') {
    const size = p.units !== null && p.units !== undefined ? `${p.units.toLocaleString()} ${p.unit}` : null;
    // "6,596 light caches", but "BVH of 1,090 triangles" where the unit is not the thing.
    const what = !size ? p.label : p.unit === p.label ? size : `${p.label} of ${size}`;
    return `${what} (${(p.seconds ?? 0).toFixed(1)} s${p.from_store ? ', from the store' : ''})`;
  }
  if (p.state === 'failed') return `${p.label} failed: ${p.error}`;
  const progress = p.progress !== null && p.progress !== undefined ? ` ${(p.progress * 100).toFixed(0)} %` : '';
  return `${p.label} ${p.state}${p.step ? `: ${p.step}` : ''}${progress}`;
}

/** Shows the scene's precomputations until every one is ready or failed. */
async function watchScene(id) {
  if (state.watching === id) return;
  state.watching = id;
  try {
    for (;;) {
      let scene;
      try {
        scene = await getJson(`v1/scenes/${encodeURIComponent(id)}`);
      } catch {
        return;
      }
      if (state.params && state.params.render.scene !== id) return;
      const all = scene.precomputed || [];
      const parts = [`${scene.triangles.toLocaleString()} triangles`, ...all.map(describePrecomputed)];
      $('scene-state').textContent = parts.join(' · ');
      if (all.every((p) => p.state === 'ready' || p.state === 'failed')) return;
      await new Promise((r) => setTimeout(r, SCENE_POLL_MS));
    }
  } finally {
    if (state.watching === id) state.watching = null;
  }
}

async function refreshScenes() {
  const scenes = await getJson('v1/scenes');
  state.scenes = new Map(scenes.map((s) => [s.id, s]));
  const select = $('scene-select');
  select.replaceChildren(...scenes.map((s) => new Option(`${s.name} (${s.id})`, s.id)));
  if (state.params) select.value = state.params.render.scene;
}

function switchScene(id) {
  // Node ids and animation names belong to the scene they came from.
  sendUpdate({ render: { scene: id, camera: null, light: null, lights: null, nodes: null, animation: null } });
}

async function uploadScene(files) {
  const form = new FormData();
  for (const f of files) form.append('files', f, f.name);
  await createScene(() => request('POST', 'v1/scenes', { body: form }), [...files].map((f) => f.name).join(', '));
}

async function createScene(post, what) {
  $('scene-state').textContent = `uploading ${what}…`;
  try {
    const scene = await (await post()).json();
    await refreshScenes();
    switchScene(scene.id);
    message(`scene ${scene.name} added as ${scene.id}`, 'info');
  } catch (e) {
    $('scene-state').textContent = '';
    showError(e, `adding ${what}`);
  }
}

// ---- lights ----

const DEGREES = Math.PI / 180;

/** Makes light `index` the one the editor and drags change (none where there are no lights). */
function selectLight(index) {
  flushLight();
  state.selected = Math.max(0, Math.min(index, state.lights.length - 1));
  state.light = state.lights[state.selected] || null;
  controls.setLight(state.light);
  const select = $('light-select');
  select.replaceChildren(...state.lights.map((l, i) => new Option(`${i + 1}: ${l.kind}`, String(i))));
  select.value = String(state.selected);
  select.disabled = state.lights.length === 0;
  $('light-remove').disabled = state.lights.length === 0;
  const max = state.server ? state.server.limits.max_lights : 16;
  $('light-add').disabled = state.lights.length >= max;
  $('light-editor').hidden = !state.light;
  $('no-lights').hidden = Boolean(state.light);
  showLight();
}

/** Sends a queued edit of the selected light now (before the selection or the list changes). */
function flushLight() {
  const queued = state.queued.light;
  if (!queued) return;
  state.queued.light = null;
  send({ type: 'light', light: queued.light, index: queued.index });
}

/** Sends the whole list (lights added or removed) and selects `index`. */
function sendLights(index) {
  state.queued.light = null;
  send({ type: 'lights', lights: structuredClone(state.lights) });
  selectLight(index);
}

/** A new light: the selected one's copy, moved aside, or a point light at the scene's centre. */
function newLight() {
  if (state.light) {
    // A copy moved aside, so the new light shows as a light of its own: a quarter of the scene
    // along x, or a sun turned 60° about the vertical (a sun straight overhead, which that
    // would not move, tilted to 60° elevation instead).
    const copy = structuredClone(state.light);
    if (copy.kind === 'directional') {
      const [x, y, z] = copy.direction;
      const c = Math.cos(60 * DEGREES);
      const s = Math.sin(60 * DEGREES);
      const level = Math.hypot(x, z);
      copy.direction = level > 1e-3 * Math.hypot(x, y, z)
        ? [c * x + s * z, y, c * z - s * x]
        : [c, Math.sign(y || -1) * s, 0];
    } else if (state.scene) {
      const { min, max } = state.scene.bounds;
      copy.position = copy.position.map((v, k) => v + 0.25 * (max[k] - min[k]) * (k === 0 ? 1 : 0));
    }
    return copy;
  }
  const bounds = state.scene ? state.scene.bounds : { min: [0, 0, 0], max: [1, 1, 1] };
  return {
    kind: 'point', position: bounds.min.map((v, k) => (v + bounds.max[k]) / 2), direction: [0, -1, 0],
    color: [1, 1, 1], intensity: 10, inner_cone: 0, outer_cone: 0,
  };
}

/** Linear RGB (0…1) as the colour input's sRGB hex, and back. */
function linearToHex(c) {
  const srgb = (v) => (v <= 0.0031308 ? 12.92 * v : 1.055 * v ** (1 / 2.4) - 0.055);
  return `#${c.map((v) => Math.round(255 * Math.min(1, Math.max(0, srgb(v)))).toString(16).padStart(2, '0')).join('')}`;
}

function hexToLinear(hex) {
  const linear = (v) => (v <= 0.04045 ? v / 12.92 : ((v + 0.055) / 1.055) ** 2.4);
  return [1, 3, 5].map((i) => linear(parseInt(hex.slice(i, i + 2), 16) / 255));
}

function showLight() {
  const light = state.light;
  if (!light) return;
  if (document.activeElement !== $('light-kind')) $('light-kind').value = light.kind;
  if (document.activeElement !== $('light-color')) $('light-color').value = linearToHex(light.color);
  $('light-cone').hidden = light.kind !== 'spot';
  if (light.kind === 'spot') {
    if (document.activeElement !== $('light-outer-cone')) $('light-outer-cone').value = (light.outer_cone / DEGREES).toFixed(1);
    if (document.activeElement !== $('light-inner-cone')) $('light-inner-cone').value = (light.inner_cone / DEGREES).toFixed(1);
  }
  const sun = light.kind === 'directional';
  $('sun-controls').hidden = !sun;
  if (sun) {
    const { azimuth, elevation } = sunAngles(light.direction);
    $('sun-azimuth').value = azimuth.toFixed(0);
    $('sun-elevation').value = elevation.toFixed(0);
    $('sun-azimuth-value').textContent = `${azimuth.toFixed(0)}°`;
    $('sun-elevation-value').textContent = `${elevation.toFixed(0)}°`;
    $('light-position').textContent = 'directional light (sun): drag in light mode, or use the sliders';
  } else {
    $('light-position').textContent = `${light.kind} light at ${light.position.map((v) => v.toFixed(2)).join(', ')}: drag in light mode to move it`;
  }
  if (document.activeElement !== $('light-intensity')) $('light-intensity').value = String(light.intensity);
}

function changeLight(mutate) {
  if (!state.light) return;
  mutate(state.light);
  controls.setLight(state.light);
  showLight();
  $('light-select').options[state.selected].text = `${state.selected + 1}: ${state.light.kind}`;
  queueInput('light', { index: state.selected, light: structuredClone(state.light) });
}

// ---- objects: movable nodes and animations ----

/** Asks the server what the view shows at `fx`, `fy` (fractions from the top left); resolves
 * to its `picked` event. */
function requestPick(fx, fy) {
  // A newer pick replaces one the server has not rendered yet: the older ones end here.
  dropPicks();
  const nonce = ++state.pickNonce;
  return new Promise((resolve, reject) => {
    if (!state.connection || !state.connection.send({ type: 'pick', x: fx, y: fy, nonce })) {
      reject(new Error('not connected'));
      return;
    }
    const timer = setTimeout(() => {
      state.picks.delete(nonce);
      message('no answer to the pick: no frame was rendered for it (is the server busy?)');
      reject(new Error('pick timed out'));
    }, PICK_TIMEOUT_MS);
    state.picks.set(nonce, { resolve, reject, timer });
  });
}

/** Ends every pick still waiting (a newer one, or a frame that failed, answers none of them). */
function dropPicks() {
  for (const { reject, timer } of state.picks.values()) {
    clearTimeout(timer);
    reject(new Error('superseded'));
  }
  state.picks.clear();
}

function onPicked(event) {
  const waiting = state.picks.get(event.nonce);
  if (!waiting) return;
  state.picks.delete(event.nonce);
  clearTimeout(waiting.timer);
  waiting.resolve(event);
}

const nodeName = (node) => `${node.name || 'node'} (node ${node.id})`;

/** Shows what a press picked: a movable node becomes the one the editor turns and resets. */
function selectNode(node, picked) {
  state.node = node;
  // Where the frame showed it (an animation's pose included), for a node this page has not
  // posed itself.
  if (picked.pose) state.shownPose = picked.pose;
  const line = $('node-selected');
  line.dataset.node = node ? String(node.id) : '';
  if (node) line.textContent = `Picked ${nodeName(node)}: drag to move it`;
  else if (picked.position) {
    const seen = state.scene && (state.scene.nodes || []).find((n) => n.id === picked.node);
    line.textContent = `${seen ? nodeName(seen) : 'That surface'} does not move`;
  } else line.textContent = 'Nothing shows there';
  $('node-editor').hidden = !node;
  if (node) $('node-turn').value = String(turnOf(node));
  $('node-turn-value').textContent = `${$('node-turn').value}°`;
}

/** The pose this page knows `node` by: its own entry, else as the picked frame showed it. */
function poseOf(node) {
  const shown = state.shownPose && state.shownPose.node === node.id ? state.shownPose : null;
  return state.poses.get(node.id) || shown;
}

/** A pose entry sent for a node, remembered as the node's current one. */
function queuePose(pose) {
  state.poses.set(pose.node, pose);
  queueInput('nodes', pose);
}

/** The world's vertical in the space of `node`'s parent (what the turn slider turns about). */
function verticalFor(node) {
  const parent = state.scene && (state.scene.nodes || []).find((n) => n.id === node.parent);
  const up = intoSpace(parent ? parent.world : null, [0, 1, 0]);
  const length = Math.hypot(...up) || 1;
  return up.map((v) => v / length);
}

/** A turn of `degrees` about the vertical of `node`'s parent, as a quaternion (x, y, z, w). */
function turnQuat(node, degrees) {
  const s = Math.sin((degrees * DEGREES) / 2);
  return [...verticalFor(node).map((v) => v * s), Math.cos((degrees * DEGREES) / 2)];
}

/** The slider's turn of `node`: its pose's rotation about the vertical relative to its rest
 * rotation (0 when unposed). */
function turnOf(node) {
  const pose = poseOf(node);
  if (!pose || !pose.rotation) return 0;
  const rest = node.rotation || [0, 0, 0, 1];
  // pose = turn · rest, so turn = pose · rest⁻¹.
  const turn = quatMul(pose.rotation, [-rest[0], -rest[1], -rest[2], rest[3]]);
  const along = verticalFor(node).reduce((sum, v, i) => sum + v * turn[i], 0);
  return Math.round((2 * Math.atan2(along, turn[3])) / DEGREES);
}

/** The scene's movable nodes and animations as the Objects section offers them. */
function showObjects(scene) {
  const movable = (scene.nodes || []).some((n) => n.movable);
  const animations = scene.animations || [];
  $('objects-controls').hidden = !movable;
  $('animation-controls').hidden = animations.length === 0;
  $('objects-none').hidden = movable || animations.length > 0;
  selectNode(null, {});
  $('node-selected').textContent = 'No object picked.';
  const select = $('animation-select');
  select.replaceChildren(...animations.map((a) => new Option(`${a.name} (${a.duration.toFixed(2)} s)`, a.name)));
  showAnimation();
}

/** The session's animation (or the selected one, stopped) on the play button and slider. */
function showAnimation() {
  const scene = state.scene;
  const playing = state.params && state.params.render.animation;
  const select = $('animation-select');
  if (playing && document.activeElement !== select) select.value = playing.name;
  const info = scene && (scene.animations || []).find((a) => a.name === select.value);
  if (!info) return;
  const time = playing && playing.name === info.name ? playing.time || 0 : 0;
  $('animation-play').textContent = playing && playing.name === info.name && playing.playing !== false ? 'Pause' : 'Play';
  const slider = $('animation-time');
  slider.max = String(info.duration || 1);
  if (document.activeElement !== slider) slider.value = String(time);
  $('animation-time-value').textContent = `${Number(slider.value).toFixed(2)} s`;
}

// ---- sizing ----

function streamSize() {
  const scale = Number($('resolution-scale').value);
  const limits = state.server.limits;
  // Even sizes: H.264's 4:2:0 chroma halves both sides (the server refuses odd ones for it).
  const even = (v, max) => 2 * Math.floor(Math.max(16, Math.min(max, v)) / 2);
  return {
    width: even(Math.round(canvas.clientWidth * devicePixelRatio * scale), limits.max_width),
    height: even(Math.round(canvas.clientHeight * devicePixelRatio * scale), limits.max_height),
  };
}

let resizeTimer = null;
function onResize() {
  clearTimeout(resizeTimer);
  resizeTimer = setTimeout(() => {
    if (!state.params) return;
    const { width, height } = streamSize();
    if (width !== state.params.render.width || height !== state.params.render.height) {
      sendUpdate({ render: { width, height } });
    }
  }, RESIZE_DEBOUNCE_MS);
}

// ---- start ----

/** Whether frames in `codec` can be both encoded by the server and decoded here. */
function usable(codec) {
  return state.serverCodecs.includes(codec) && (codec !== 'h264' || state.decodesH264);
}

/**
 * The stream's codec: `?codec=` (jpeg, png, h264 or auto, the default), where auto takes H.264
 * when the server encodes it and this page decodes it, else JPEG.
 */
function chooseCodec(asked) {
  if (asked === 'auto' || !asked) return usable('h264') ? 'h264' : 'jpeg';
  if (usable(asked)) return asked;
  message(`codec ${asked} is not available here (${state.decodesH264 ? 'the server does not encode it' : 'this browser has no WebCodecs H.264 decoder, which needs https or localhost'}); streaming JPEG`, 'info');
  return 'jpeg';
}

/**
 * The server's `hello` says which codecs it encodes (a replica behind a router may differ from
 * the one `/v1/server` answered): a session in a codec this page cannot use goes back to JPEG.
 */
function negotiate(hello) {
  if (Array.isArray(hello.codecs) && hello.codecs.length) state.serverCodecs = hello.codecs;
  panel.applyCodecs(['jpeg', 'png', 'h264'].filter(usable));
  const codec = hello.session.params.encoding.codec;
  if (!usable(codec)) {
    message(`the server cannot stream ${codec} to this page; switching to JPEG`, 'info');
    sendUpdate({ encoding: { codec: 'jpeg' } });
  }
}

/**
 * Session parameters of a new viewer: `?scene=&method=&view=&rsm=&fps=&scale=&codec=&interactive=`
 * may preset them, and `?gi.NAME=VALUE` any GI parameter `/v1/server` lists.
 */
function initialParams() {
  const q = new URLSearchParams(location.search);
  // Without `?scale=`, the server's choice: a software adapter streams a quarter of the pixels.
  const serverScale = state.server.defaults && state.server.defaults.viewer_scale;
  if (q.has('scale')) $('resolution-scale').value = q.get('scale');
  else if (serverScale) $('resolution-scale').value = String(serverScale);
  const render = { ...streamSize(), gi: {} };
  if (q.has('scene')) render.scene = q.get('scene');
  if (q.has('method')) render.gi.method = q.get('method');
  if (q.has('view')) render.view = q.get('view');
  if (q.has('rsm')) render.gi.rsm_size = Number(q.get('rsm'));
  // `?gi.surfel_links=16`: numbers and true/false as such, anything else as text; what the
  // server refuses is named and left to its default like any other preset.
  for (const [key, value] of q) {
    if (!key.startsWith('gi.') || key.length === 3) continue;
    const number = value.trim() === '' ? NaN : Number(value);
    render.gi[key.slice(3)] = value === 'true' ? true : value === 'false' ? false
      : Number.isFinite(number) ? number : value;
  }
  // While the view moves, frames at half the size (upscaled here) unless `?interactive=`;
  // a number out of range is the server's to refuse, naming the field.
  let interactive = 0.5;
  if (q.has('interactive')) {
    const asked = Number(q.get('interactive'));
    if (Number.isFinite(asked)) interactive = asked;
    else message(`?interactive=${q.get('interactive')} is not a number (0.25–1); using ${interactive}`);
  }
  const encoding = { codec: chooseCodec(q.get('codec')), interactive_scale: interactive };
  const params = { render, encoding };
  if (q.has('fps')) params.fps_cap = Number(q.get('fps'));
  return params;
}

function askToken(reason) {
  const dialog = $('token-dialog');
  $('token-reason').textContent = reason;
  if (!dialog.open) dialog.showModal();
}

async function boot() {
  takeTokenFromFragment();
  try {
    state.server = await getJson('v1/server');
    await refreshScenes();
    state.decodesH264 = await canDecodeH264();
  } catch (e) {
    if (e instanceof ApiError && e.status === 401) {
      setStatus('unauthorized', e.message);
    } else {
      setStatus(e instanceof Unreachable ? 'unreachable' : 'reconnecting', `${e.message} · retrying in 2 s`);
      setTimeout(boot, 2000);
    }
    return;
  }
  const s = state.server;
  const profile = s.defaults && s.defaults.profile === 'software' ? ' · software defaults (smaller GI, indirect at reduced resolution)' : '';
  $('server-info').textContent = `${s.build} · ${s.adapter}${profile}`;
  stats.setStageNames(s.stages);
  panel.applyLimits(s.limits);
  panel.applyGiMethods(s.gi_methods || []);
  // An older server without `video` streams JPEG and PNG only.
  if (s.video && Array.isArray(s.video.codecs)) state.serverCodecs = s.video.codecs;
  if (s.video) stats.setAutoBitsPerPixel(s.video.auto_bits_per_pixel);
  panel.applyCodecs(['jpeg', 'png', 'h264'].filter(usable));
  document.body.dataset.decodesH264 = String(state.decodesH264);
  state.connection = new Connection(initialParams(), {
    onFrame,
    onSession,
    onStatus: setStatus,
    onEvent: (event) => {
      if (event.type === 'hello') negotiate(event);
      else if (event.type === 'error') showError(event.error, 'refused');
      else if (event.type === 'render_error') {
        showError(event.error, 'render failed');
        dropPicks();
      }
      else if (event.type === 'picked') onPicked(event);
      else if (event.type === 'caches_pending') {
        message(`computing the ${event.what} of ${event.scene}: direct light until ready`, 'info');
        watchScene(event.scene);
      } else if (event.type === 'caches_ready') message(`${event.what} of ${event.scene} ready`, 'info', 4000);
      else if (event.type === 'closing') message(`session ended: ${event.reason}`, 'error');
    },
  });
  state.connection.start();
}

$('token-form').addEventListener('submit', () => {
  setToken($('token-input').value.trim());
  if (state.connection) state.connection.start();
  else boot();
});
document.querySelectorAll('input[name="drag-mode"]').forEach((r) => r.addEventListener('change', () => {
  controls.mode = r.value;
}));
$('reset-camera').addEventListener('click', () => {
  if (!state.scene) return;
  controls.setCamera(state.scene.default_camera);
  sendUpdate(patchFor('render.camera', null));
});
$('pause').addEventListener('click', () => {
  const paused = state.params && state.params.paused;
  sendUpdate({ paused: !paused });
});
$('scene-select').addEventListener('change', (e) => switchScene(e.target.value));
$('scene-upload').addEventListener('change', (e) => {
  if (e.target.files.length) uploadScene(e.target.files);
  e.target.value = '';
});
$('procedural-form').addEventListener('submit', (e) => {
  e.preventDefault();
  const spec = $('procedural-spec').value.trim();
  createScene(() => request('POST', 'v1/scenes', { json: { procedural: spec } }), spec);
});
$('sun-azimuth').addEventListener('input', () => changeLight((l) => {
  l.direction = sunDirection(Number($('sun-azimuth').value), Number($('sun-elevation').value));
}));
$('sun-elevation').addEventListener('input', () => changeLight((l) => {
  l.direction = sunDirection(Number($('sun-azimuth').value), Number($('sun-elevation').value));
}));
$('light-intensity').addEventListener('change', () => {
  const v = Number($('light-intensity').value);
  if (Number.isFinite(v) && v >= 0) changeLight((l) => { l.intensity = v; });
  else message('light intensity: enter a number ≥ 0');
});
$('light-select').addEventListener('change', () => selectLight(Number($('light-select').value)));
$('light-add').addEventListener('click', () => {
  state.lights.push(newLight());
  sendLights(state.lights.length - 1);
});
$('light-remove').addEventListener('click', () => {
  state.lights.splice(state.selected, 1);
  sendLights(state.selected - 1);
});
$('light-kind').addEventListener('change', () => changeLight((l) => {
  l.kind = $('light-kind').value;
  if (l.kind === 'spot' && !(l.outer_cone > 0)) {
    l.outer_cone = 30 * DEGREES;
    l.inner_cone = 25 * DEGREES;
  }
  if (l.kind === 'directional' && !l.direction.some((v) => v !== 0)) l.direction = [0, -1, 0];
}));
$('light-color').addEventListener('input', () => changeLight((l) => { l.color = hexToLinear($('light-color').value); }));
for (const id of ['light-outer-cone', 'light-inner-cone']) {
  $(id).addEventListener('change', () => {
    const outer = Number($('light-outer-cone').value);
    const inner = Number($('light-inner-cone').value);
    if (!(outer > 0 && outer < 90 && inner >= 0 && inner < outer)) {
      message('spot cone: the full-inside angle must be below the cone, and the cone within 0…90°');
      return;
    }
    changeLight((l) => { l.outer_cone = outer * DEGREES; l.inner_cone = inner * DEGREES; });
  });
}
$('node-turn').addEventListener('input', () => {
  const node = state.node;
  if (!node) return;
  const degrees = Number($('node-turn').value);
  $('node-turn-value').textContent = `${degrees}°`;
  const rotation = quatMul(turnQuat(node, degrees), node.rotation || [0, 0, 0, 1]);
  queuePose({ ...(poseOf(node) || {}), node: node.id, rotation });
});
$('node-reset').addEventListener('click', () => {
  if (!state.node) return;
  state.poses.delete(state.node.id);
  state.queued.nodes = null;
  send({ type: 'nodes', nodes: [{ node: state.node.id }] });
  selectNode(state.node, {});
});
$('nodes-reset').addEventListener('click', () => {
  state.queued.nodes = null;
  state.poses.clear();
  sendUpdate({ render: { nodes: null } });
  if (state.node) selectNode(state.node, {});
});
$('animation-select').addEventListener('change', showAnimation);
$('animation-play').addEventListener('click', () => {
  const name = $('animation-select').value;
  if (!name) return;
  const current = state.params && state.params.render.animation;
  const playing = Boolean(current && current.name === name && current.playing !== false);
  // A paused animation goes on from where it stopped; another starts from its beginning.
  send({ type: 'animation', name, playing: !playing });
});
$('animation-time').addEventListener('input', () => {
  const name = $('animation-select').value;
  if (!name) return;
  const time = Number($('animation-time').value);
  $('animation-time-value').textContent = `${time.toFixed(2)} s`;
  queueInput('animation', { name, time, playing: false });
});
$('resolution-scale').addEventListener('change', onResize);
new ResizeObserver(onResize).observe(canvas);
$('still').addEventListener('click', async () => {
  if (!state.params) return;
  const button = $('still');
  button.disabled = true;
  button.textContent = 'Rendering still…';
  try {
    const render = { ...state.params.render, camera: controls.camera(), light: null, lights: structuredClone(state.lights) };
    const { png, report } = await renderStill(render);
    const stamp = new Date().toISOString().replace(/[:.]/g, '-');
    download(png, `lightcast-${render.scene}-${stamp}.png`, 'image/png');
    const json = JSON.stringify(report, null, 2);
    $('still-report-text').textContent = json;
    $('still-report-link').href = `data:application/json;charset=utf-8,${encodeURIComponent(json)}`;
    $('still-report').hidden = false;
  } catch (e) {
    showError(e, 'still');
  } finally {
    button.disabled = false;
    button.textContent = 'Download lossless still';
  }
});
window.addEventListener('pagehide', () => state.connection && state.connection.stop());
// A page restored from the back/forward cache had its session ended on the way out.
window.addEventListener('pageshow', (e) => {
  if (e.persisted && state.connection) state.connection.start();
});

boot();
