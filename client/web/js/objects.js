// Moving a scene's movable nodes by hand: in objects mode a press asks the server what the
// view shows there (`pick`, answered from the frame's G-buffer with the node's pose in that
// frame), and a drag of a movable node slides it on the horizontal plane through the point
// grabbed (shift: up and down instead), sent as `nodes` messages. The scene's `nodes` (their
// rest transforms and bounds) turn the drag in world space into a translation in the node's
// parent's space, kept inside the scene.

const add = (a, b) => [a[0] + b[0], a[1] + b[1], a[2] + b[2]];
const sub = (a, b) => [a[0] - b[0], a[1] - b[1], a[2] - b[2]];
const scale = (a, s) => [a[0] * s, a[1] * s, a[2] * s];
const dot = (a, b) => a[0] * b[0] + a[1] * b[1] + a[2] * b[2];
const cross = (a, b) => [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]];
const clamp = (v, lo, hi) => Math.min(hi, Math.max(lo, v));
// A press becomes a drag once the pointer has moved this many CSS pixels: a click moves nothing.
const DRAG_THRESHOLD_PX = 3;

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

/** A world offset moved inside what keeps `nodeBounds` (where the node is now) within
 * `sceneBounds`. */
export function keepInside(delta, nodeBounds, sceneBounds) {
  if (!nodeBounds || !sceneBounds) return delta;
  return delta.map((d, i) => {
    const lo = sceneBounds.min[i] - nodeBounds.min[i];
    const hi = sceneBounds.max[i] - nodeBounds.max[i];
    return lo > hi ? 0 : clamp(d, lo, hi);
  });
}

/** `v` turned by the unit quaternion `q` (x, y, z, w). */
export function rotate(q, v) {
  const u = [q[0], q[1], q[2]];
  const t = scale(cross(u, v), 2);
  return add(v, add(scale(t, q[3]), cross(u, t)));
}

/** The box around `bounds` (at rest) turned by `turn` about `origin` and moved by `offset`. */
export function movedBounds(bounds, origin, turn, offset) {
  const corners = [0, 1, 2, 3, 4, 5, 6, 7].map((k) => [0, 1, 2].map((i) => ((k >> i) & 1 ? bounds.max[i] : bounds.min[i])));
  const moved = corners.map((c) => add(add(origin, rotate(turn, sub(c, origin))), offset));
  return {
    min: [0, 1, 2].map((i) => Math.min(...moved.map((c) => c[i]))),
    max: [0, 1, 2].map((i) => Math.max(...moved.map((c) => c[i]))),
  };
}

export class ObjectDrag {
  /**
   * `controls`: the camera controls (basis and field of view); `hooks.pick(fx, fy)` resolves
   * to the server's `picked` event; `hooks.scene()` the scene info; `hooks.aspect()` the
   * frame's width over its height; `hooks.onPose(entry)` sends a node's pose;
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
    const drag = { press: [fx, fy], at: [e.clientX, e.clientY], moved: false, latest: [fx, fy], vertical: e.shiftKey, grab: null };
    this.drag = drag;
    this.hooks.pick(fx, fy).then((picked) => {
      const scene = this.hooks.scene();
      const node = picked.movable !== undefined && scene
        ? (scene.nodes || []).find((n) => n.id === picked.movable) : null;
      this.hooks.onSelect(node || null, picked);
      if (this.drag !== drag || !node || !picked.position || !picked.pose) {
        if (this.drag === drag) this.drag = null;
        return;
      }
      const parent = (scene.nodes || []).find((n) => n.id === node.parent);
      // The node as that frame showed it (an animation's pose included), and how far that is
      // from rest in world space; the parent's rotation is taken as none for the bounds.
      const pose = picked.pose;
      const rest = node.translation || [0, 0, 0];
      const restRotation = node.rotation || [0, 0, 0, 1];
      const turn = quatMul(pose.rotation, [-restRotation[0], -restRotation[1], -restRotation[2], restRotation[3]]);
      const offset = parent ? applyLinear(parent.world, sub(pose.translation, rest)) : sub(pose.translation, rest);
      const origin = [node.world[12], node.world[13], node.world[14]];
      drag.grab = {
        node,
        parentWorld: parent ? parent.world : null,
        grabbed: picked.position,
        pose,
        bounds: node.bounds ? movedBounds(node.bounds, origin, turn, offset) : null,
        sceneBounds: scene.bounds,
      };
      this.apply();
    }, () => {
      if (this.drag === drag) this.drag = null;
    });
  }

  move(e) {
    const drag = this.drag;
    if (!drag) return;
    drag.latest = this.fraction(e);
    drag.vertical = e.shiftKey;
    if (Math.hypot(e.clientX - drag.at[0], e.clientY - drag.at[1]) >= DRAG_THRESHOLD_PX) drag.moved = true;
    this.apply();
  }

  ray(fx, fy) {
    return viewRay(this.controls.basis(), this.controls.orbit.fov, this.hooks.aspect(), fx, fy);
  }

  up() {
    this.drag = null;
  }

  /** Sends the grabbed node's pose for the pointer's latest position: moved by what the
   * pointer moved on the drag's plane since the press (a press alone sends nothing). */
  apply() {
    const drag = this.drag;
    if (!drag || !drag.grab || !drag.moved) return;
    const g = drag.grab;
    // The horizontal plane through the grabbed point, or the vertical one facing the camera.
    const forward = this.controls.basis().forward;
    const normal = drag.vertical ? [forward[0], 0, forward[2]] : [0, 1, 0];
    if (Math.hypot(...normal) < 1e-6) return;
    const from = hitPlane(this.ray(...drag.press), g.grabbed, normal);
    const to = hitPlane(this.ray(...drag.latest), g.grabbed, normal);
    if (!from || !to) return;
    const moved = sub(to, from);
    let delta = drag.vertical ? [0, moved[1], 0] : [moved[0], 0, moved[2]];
    delta = keepInside(delta, g.bounds, g.sceneBounds);
    const translation = add(g.pose.translation, intoSpace(g.parentWorld, delta));
    this.hooks.onPose({ ...g.pose, node: g.node.id, translation });
  }
}

/** The product of two quaternions (x, y, z, w): `a` after `b`. */
export function quatMul([ax, ay, az, aw], [bx, by, bz, bw]) {
  return [
    aw * bx + ax * bw + ay * bz - az * by,
    aw * by - ax * bz + ay * bw + az * bx,
    aw * bz + ax * by - ay * bx + az * bw,
    aw * bw - ax * bx - ay * by - az * bz,
  ];
}

/** The 3×3 linear part of a column-major 4×4 matrix applied to `v`. */
function applyLinear(m, v) {
  return [0, 1, 2].map((r) => m[r] * v[0] + m[4 + r] * v[1] + m[8 + r] * v[2]);
}
