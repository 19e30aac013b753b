// Moving a scene's movable nodes by hand: in objects mode a press asks the server what the
// view shows there (`pick`, answered from the frame's G-buffer), and a drag of a movable node
// slides it on the horizontal plane through the point grabbed (shift: up and down instead),
// sent as `nodes` messages. The scene's `nodes` (their rest transforms and bounds) turn the
// drag in world space into a translation in the node's parent's space, kept inside the scene.

const add = (a, b) => [a[0] + b[0], a[1] + b[1], a[2] + b[2]];
const sub = (a, b) => [a[0] - b[0], a[1] - b[1], a[2] - b[2]];
const scale = (a, s) => [a[0] * s, a[1] * s, a[2] * s];
const dot = (a, b) => a[0] * b[0] + a[1] * b[1] + a[2] * b[2];
const cross = (a, b) => [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]];
const clamp = (v, lo, hi) => Math.min(hi, Math.max(lo, v));

/** The ray from `camera` ({position, forward, right, up}, vertical field of view `fovDegrees`)
 * through the point `fx`, `fy` of a view `aspect` wide per unit of height (fractions from the
 * top left), as the server's perspective projects it. */
export function viewRay(camera, fovDegrees, aspect, fx, fy) {
  const h = Math.tan((fovDegrees * Math.PI) / 360);
  const x = (2 * fx - 1) * h * aspect;
  const y = (1 - 2 * fy) * h;
  const d = add(camera.forward, add(scale(camera.right, x), scale(camera.up, y)));
  const n = Math.hypot(...d);
  return { origin: camera.position, direction: scale(d, 1 / n) };
}

/** Where `ray` meets the plane through `point` with `normal`; null when it runs along the plane
 * or the plane is behind it. */
export function hitPlane(ray, point, normal) {
  const along = dot(ray.direction, normal);
  if (Math.abs(along) < 1e-6) return null;
  const t = dot(sub(point, ray.origin), normal) / along;
  return t > 0 ? add(ray.origin, scale(ray.direction, t)) : null;
}

/** The inverse of the 3×3 linear part of a column-major 4×4 matrix, applied to `v`: a world
 * offset in the space the matrix maps from. Identity without a matrix. */
export function intoSpace(world, v) {
  if (!world) return v;
  const c = [0, 4, 8].map((i) => [world[i], world[i + 1], world[i + 2]]);
  const det = dot(c[0], cross(c[1], c[2]));
  if (Math.abs(det) < 1e-12) return v;
  // Rows of the inverse are the cross products of the columns over the determinant.
  const rows = [cross(c[1], c[2]), cross(c[2], c[0]), cross(c[0], c[1])];
  return rows.map((r) => dot(r, v) / det);
}

/** A world offset moved inside what keeps `nodeBounds` (at rest, moved by `offset` already)
 * within `sceneBounds`. */
export function keepInside(delta, offset, nodeBounds, sceneBounds) {
  if (!nodeBounds || !sceneBounds) return delta;
  return delta.map((d, i) => {
    const lo = sceneBounds.min[i] - nodeBounds.min[i] - offset[i];
    const hi = sceneBounds.max[i] - nodeBounds.max[i] - offset[i];
    return lo > hi ? 0 : clamp(d, lo, hi);
  });
}

export class ObjectDrag {
  /**
   * `controls`: the camera controls (basis and field of view); `hooks.pick(fx, fy)` resolves
   * to the server's `picked` event; `hooks.scene()` the scene info; `hooks.pose(id)` the
   * session's pose entry of a node (or undefined); `hooks.onPose(entry)` sends one;
   * `hooks.onSelect(node, picked)` tells which node a press picked (null: nothing movable).
   */
  constructor(canvas, controls, hooks) {
    this.canvas = canvas;
    this.controls = controls;
    this.hooks = hooks;
    this.drag = null;
  }

  fraction(e) {
    const r = this.canvas.getBoundingClientRect();
    return [clamp((e.clientX - r.left) / (r.width || 1), 0, 1), clamp((e.clientY - r.top) / (r.height || 1), 0, 1)];
  }

  down(e) {
    const [fx, fy] = this.fraction(e);
    const drag = { latest: [fx, fy], vertical: e.shiftKey, grab: null };
    this.drag = drag;
    this.hooks.pick(fx, fy).then((picked) => {
      const scene = this.hooks.scene();
      const node = picked.movable !== undefined && scene
        ? (scene.nodes || []).find((n) => n.id === picked.movable) : null;
      this.hooks.onSelect(node || null, picked);
      if (this.drag !== drag || !node || !picked.position) {
        if (this.drag === drag) this.drag = null;
        return;
      }
      const parent = (scene.nodes || []).find((n) => n.id === node.parent);
      const pose = this.hooks.pose(node.id) || {};
      const rest = node.translation || [0, 0, 0];
      const start = pose.translation || rest;
      drag.grab = {
        node,
        parentWorld: parent ? parent.world : null,
        anchor: picked.position,
        start,
        // How far the node already is from rest, in world space (for the scene's bounds).
        offset: parent ? applyLinear(parent.world, sub(start, rest)) : sub(start, rest),
        pose,
        bounds: scene.bounds,
      };
      this.apply();
    }, () => {
      if (this.drag === drag) this.drag = null;
    });
  }

  move(e) {
    if (!this.drag) return;
    this.drag.latest = this.fraction(e);
    this.drag.vertical = e.shiftKey;
    this.apply();
  }

  up() {
    this.drag = null;
  }

  /** Sends the grabbed node's translation for the pointer's latest position. */
  apply() {
    const drag = this.drag;
    if (!drag || !drag.grab) return;
    const g = drag.grab;
    const camera = this.controls.basis();
    const aspect = (this.canvas.clientWidth || 1) / (this.canvas.clientHeight || 1);
    const ray = viewRay(camera, this.controls.orbit.fov, aspect, ...drag.latest);
    let delta;
    if (drag.vertical) {
      // The vertical plane through the grabbed point that faces the camera.
      const facing = [camera.forward[0], 0, camera.forward[2]];
      if (Math.hypot(...facing) < 1e-6) return;
      const hit = hitPlane(ray, g.anchor, facing);
      if (!hit) return;
      delta = [0, hit[1] - g.anchor[1], 0];
    } else {
      const hit = hitPlane(ray, g.anchor, [0, 1, 0]);
      if (!hit) return;
      delta = [hit[0] - g.anchor[0], 0, hit[2] - g.anchor[2]];
    }
    delta = keepInside(delta, g.offset, g.node.bounds, g.bounds);
    const translation = add(g.start, intoSpace(g.parentWorld, delta));
    this.hooks.onPose({ ...g.pose, node: g.node.id, translation });
  }
}

/** The 3×3 linear part of a column-major 4×4 matrix applied to `v`. */
function applyLinear(m, v) {
  return [0, 1, 2].map((r) => m[r] * v[0] + m[4 + r] * v[1] + m[8 + r] * v[2]);
}
