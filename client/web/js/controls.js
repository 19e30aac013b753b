// Mouse, touch and keyboard on the frame: orbit, pan, zoom and WASD fly for the camera,
// dragging the light (a sun's azimuth/elevation, a spot or point light's position), and in
// objects mode handing one-finger drags to the scene's movable nodes (`objects.js`).
// The camera is kept as an orbit (target, yaw, pitch, radius) and sent as the protocol's
// position/target pair; +Y is up, as in glTF.

const DEG = Math.PI / 180;
const MAX_PITCH = 89 * DEG;
// A drag across the whole canvas turns the orbit by half a turn, whatever the canvas's size
// (a fixed rate per pixel turned a large canvas's short drag into most of a turn).
const ORBIT_PER_CANVAS = Math.PI;
// How far inside its camera region the camera stays, as a share of the region's size.
const REGION_MARGIN = 0.02;
const ZOOM_PER_WHEEL_UNIT = 0.0015;
const FLY_FRACTION_PER_SECOND = 0.35;

const add = (a, b) => [a[0] + b[0], a[1] + b[1], a[2] + b[2]];
const sub = (a, b) => [a[0] - b[0], a[1] - b[1], a[2] - b[2]];
const scale = (a, s) => [a[0] * s, a[1] * s, a[2] * s];
const length = (a) => Math.hypot(a[0], a[1], a[2]);
const normalize = (a) => scale(a, 1 / (length(a) || 1));
const cross = (a, b) => [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]];
const clamp = (v, lo, hi) => Math.min(hi, Math.max(lo, v));

/** Sun angles in degrees of a directional light's travel direction. */
export function sunAngles(direction) {
  const toSun = normalize(scale(direction, -1));
  return {
    azimuth: Math.atan2(toSun[0], toSun[2]) / DEG,
    elevation: Math.asin(clamp(toSun[1], -1, 1)) / DEG,
  };
}

/** The travel direction of a sun at `azimuth`, `elevation` (degrees). */
export function sunDirection(azimuth, elevation) {
  const a = azimuth * DEG;
  const e = elevation * DEG;
  return [-Math.cos(e) * Math.sin(a), -Math.sin(e), -Math.cos(e) * Math.cos(a)];
}

export class Controls {
  /** `onCamera(camera)` and `onLight(light)` are called on every change. */
  constructor(canvas, { onCamera, onLight }) {
    this.canvas = canvas;
    this.onCamera = onCamera;
    this.onLight = onLight;
    this.mode = 'camera';
    /** Takes drags in objects mode (`ObjectDrag`), set by the page. */
    this.objects = null;
    this.orbit = null;
    this.light = null;
    this.sceneSize = 1;
    this.region = null;
    this.pointers = new Map();
    this.keys = new Set();
    this.lastFly = null;

    canvas.addEventListener('pointerdown', (e) => this.pointerDown(e));
    canvas.addEventListener('pointermove', (e) => this.pointerMove(e));
    canvas.addEventListener('pointerup', (e) => this.pointerUp(e));
    canvas.addEventListener('pointercancel', (e) => this.pointerUp(e));
    canvas.addEventListener('wheel', (e) => this.wheel(e), { passive: false });
    canvas.addEventListener('contextmenu', (e) => e.preventDefault());
    window.addEventListener('keydown', (e) => this.key(e, true));
    window.addEventListener('keyup', (e) => this.key(e, false));
    window.addEventListener('blur', () => this.keys.clear());
  }

  setCamera(camera) {
    this.orbit = { target: [...camera.target], fov: camera.fov_y_degrees };
    this.orbitTo(camera.position);
  }

  /** Radius and angles of the orbit that puts the camera at `position` about its target. */
  orbitTo(position) {
    const offset = sub(position, this.orbit.target);
    const radius = length(offset) || this.sceneSize;
    this.orbit.radius = radius;
    this.orbit.yaw = Math.atan2(offset[0], offset[2]);
    // Clamped so that a camera looking straight down keeps a usable right vector.
    this.orbit.pitch = clamp(Math.asin(clamp(offset[1] / radius, -1, 1)), -MAX_PITCH, MAX_PITCH);
  }

  setLight(light) {
    this.light = structuredClone(light);
  }

  setSceneSize(size) {
    this.sceneSize = size > 0 ? size : 1;
  }

  /** Keeps the camera inside `region` ({min, max}; a scene's `camera_region`), or anywhere
   * when it is null. */
  setRegion(region) {
    if (!region) {
      this.region = null;
      return;
    }
    const margin = [0, 1, 2].map((i) => (region.max[i] - region.min[i]) * REGION_MARGIN);
    this.region = {
      min: region.min.map((v, i) => v + margin[i]),
      max: region.max.map((v, i) => v - margin[i]),
    };
  }

  /** The camera moved back inside the region: the orbit keeps its target and takes the
   * clamped position's distance and angles. */
  keepInRegion() {
    if (!this.region || !this.orbit) return;
    const position = this.camera().position;
    const clamped = position.map((v, i) => clamp(v, this.region.min[i], this.region.max[i]));
    if (clamped.every((v, i) => v === position[i])) return;
    // A camera clamped onto its target would have no view direction.
    if (length(sub(clamped, this.orbit.target)) < this.sceneSize * 1e-3) return;
    this.orbitTo(clamped);
  }

  /** Sends the camera after a change, kept inside the region. */
  moved() {
    this.keepInRegion();
    this.onCamera(this.camera());
  }

  camera() {
    const o = this.orbit;
    const offset = [
      o.radius * Math.cos(o.pitch) * Math.sin(o.yaw),
      o.radius * Math.sin(o.pitch),
      o.radius * Math.cos(o.pitch) * Math.cos(o.yaw),
    ];
    return { position: add(o.target, offset), target: [...o.target], fov_y_degrees: o.fov };
  }

  /** Camera basis: forward (towards the target), right and up, as the server's view matrix
   * has them (`stable_up` in frame_uniforms.rs: +Z for up when looking almost straight up or
   * down). */
  basis() {
    const c = this.camera();
    const forward = normalize(sub(c.target, c.position));
    const up = Math.abs(forward[1]) > 0.999 ? [0, 0, Math.sign(forward[1])] : [0, 1, 0];
    const right = normalize(cross(forward, up));
    return { forward, right, up: cross(right, forward), position: c.position };
  }

  /** World units per CSS pixel at distance `distance` from the camera. */
  worldPerPixel(distance) {
    const height = this.canvas.clientHeight || 1;
    return (2 * distance * Math.tan((this.orbit.fov * DEG) / 2)) / height;
  }

  pointerDown(e) {
    if (!this.orbit) return;
    this.canvas.setPointerCapture(e.pointerId);
    this.pointers.set(e.pointerId, { x: e.clientX, y: e.clientY, button: e.button, shift: e.shiftKey, ctrl: e.ctrlKey });
    this.canvas.focus();
    e.preventDefault();
    if (this.grabsObjects(e.button, e.ctrlKey)) this.objects.down(e);
  }

  /** A left-button or one-finger drag in objects mode moves an object, not the camera (a
   * ctrl-drag moves the light there too). */
  grabsObjects(button, ctrl) {
    return this.mode === 'objects' && this.objects && button === 0 && !ctrl && this.pointers.size === 1;
  }

  pointerUp(e) {
    if (this.mode === 'objects' && this.objects) this.objects.up(e);
    this.pointers.delete(e.pointerId);
  }

  pointerMove(e) {
    const p = this.pointers.get(e.pointerId);
    if (!p) return;
    const dx = e.clientX - p.x;
    const dy = e.clientY - p.y;
    if (this.pointers.size === 2) {
      this.pinch(e.pointerId, e.clientX, e.clientY);
      return;
    }
    p.x = e.clientX;
    p.y = e.clientY;
    if (this.grabsObjects(p.button, p.ctrl)) {
      this.objects.move(e);
    } else if (this.mode === 'light' || p.ctrl) {
      this.dragLight(dx, dy);
    } else if (p.button === 2 || p.button === 1 || p.shift) {
      this.pan(dx, dy);
    } else {
      const perPixel = ORBIT_PER_CANVAS / (this.canvas.clientWidth || 1);
      this.orbit.yaw -= dx * perPixel;
      this.orbit.pitch = clamp(this.orbit.pitch + dy * perPixel, -MAX_PITCH, MAX_PITCH);
      this.moved();
    }
  }

  /** Two fingers: their distance zooms, their midpoint pans. */
  pinch(id, x, y) {
    const [a, b] = [...this.pointers.entries()];
    const before = { mid: [(a[1].x + b[1].x) / 2, (a[1].y + b[1].y) / 2], dist: Math.hypot(a[1].x - b[1].x, a[1].y - b[1].y) };
    this.pointers.get(id).x = x;
    this.pointers.get(id).y = y;
    const after = { mid: [(a[1].x + b[1].x) / 2, (a[1].y + b[1].y) / 2], dist: Math.hypot(a[1].x - b[1].x, a[1].y - b[1].y) };
    if (before.dist > 0 && after.dist > 0) this.zoom(before.dist / after.dist);
    this.pan(after.mid[0] - before.mid[0], after.mid[1] - before.mid[1]);
  }

  pan(dx, dy) {
    const { right, up } = this.basis();
    const wpp = this.worldPerPixel(this.orbit.radius);
    this.orbit.target = add(this.orbit.target, add(scale(right, -dx * wpp), scale(up, dy * wpp)));
    this.moved();
  }

  zoom(factor) {
    this.orbit.radius = clamp(this.orbit.radius * factor, this.sceneSize * 0.01, this.sceneSize * 20);
    this.moved();
  }

  wheel(e) {
    if (!this.orbit) return;
    e.preventDefault();
    const units = e.deltaMode === 1 ? e.deltaY * 16 : e.deltaY;
    this.zoom(Math.exp(units * ZOOM_PER_WHEEL_UNIT));
  }

  dragLight(dx, dy) {
    const light = this.light;
    if (!light) return;
    if (light.kind === 'directional') {
      const { azimuth, elevation } = sunAngles(light.direction);
      light.direction = sunDirection(azimuth + dx * 0.4, clamp(elevation - dy * 0.4, 1, 89));
    } else {
      const { right, up, position } = this.basis();
      const wpp = this.worldPerPixel(Math.max(length(sub(light.position, position)), this.sceneSize * 0.05));
      light.position = add(light.position, add(scale(right, dx * wpp), scale(up, -dy * wpp)));
    }
    this.onLight(structuredClone(light));
  }

  key(e, down) {
    const k = e.key.toLowerCase();
    if (!down) {
      // Releases count wherever the focus went meanwhile, or the camera would fly on.
      this.keys.delete(k);
      return;
    }
    const target = e.target;
    if (target && (target.tagName === 'INPUT' || target.tagName === 'SELECT' || target.tagName === 'TEXTAREA')) return;
    if (!['w', 'a', 's', 'd', 'q', 'e', 'shift'].includes(k)) return;
    this.keys.add(k);
    if (this.keys.size > 0 && this.lastFly === null) {
      this.lastFly = performance.now();
      requestAnimationFrame((t) => this.fly(t));
    }
  }

  /** WASD moves the camera and its target along the view; Q/E down and up; Shift is faster. */
  fly(now) {
    const moving = [...this.keys].some((k) => k !== 'shift');
    if (!moving || !this.orbit) {
      this.lastFly = null;
      return;
    }
    const dt = Math.min((now - this.lastFly) / 1000, 0.1);
    this.lastFly = now;
    const { forward, right } = this.basis();
    const speed = this.sceneSize * FLY_FRACTION_PER_SECOND * (this.keys.has('shift') ? 4 : 1) * dt;
    let step = [0, 0, 0];
    if (this.keys.has('w')) step = add(step, forward);
    if (this.keys.has('s')) step = sub(step, forward);
    if (this.keys.has('d')) step = add(step, right);
    if (this.keys.has('a')) step = sub(step, right);
    if (this.keys.has('e')) step = add(step, [0, 1, 0]);
    if (this.keys.has('q')) step = sub(step, [0, 1, 0]);
    if (length(step) > 0) {
      this.orbit.target = add(this.orbit.target, scale(normalize(step), speed));
      this.moved();
    }
    requestAnimationFrame((t) => this.fly(t));
  }
}
