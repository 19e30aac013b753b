#!/usr/bin/env python3
"""Validates the path-traced reference's environment lighting (`render.environment`) and its
several punctual lights (`render.lights`) against Mitsuba 3.

A ground plane (20×20 m, y = 0, open below) and a 1 m box standing on it are rendered by
lightcast's `reference` (raw_indirect: the light leaving each pixel's surface but the punctual
lights' direct light) and by Mitsuba 3 (`scalar_rgb`, `path` integrator) with the same
camera, the same BRDF (lightcast_bsdf.py's Python BSDF at metallic 0, roughness 1) and the
same lighting:

- uniform: Mitsuba `constant` emitter; lightcast with a zero-intensity directional light
  (a frame needs one punctual light);
- sky: lightcast's Preetham map (written by `cargo run -p lightcast-server --example
  environment_map`) as a Mitsuba `envmap`, resampled onto Mitsuba's grid by the exact
  direction of each of its grid points; the sun as a `directional` emitter. The sun's direct
  light at the visible surface, which raw_indirect leaves out, is taken out of Mitsuba's image
  as sun-only(max_depth = B+2) − sun-only(max_depth = 2) rendered with the same seed;
- image: an equirectangular Radiance `.hdr` (a blue gradient above a dim ground and a
  0.3°-wide sun 50,000 times brighter) uploaded with the scene; Mitsuba gets the map lightcast
  keeps (written by the same example) as for the sky;
- area: no environment and no punctual light (`lights: []`): a 1 m panel 2.5 m above the
  box, facing down, emitting 8 per steradian from its front (lightcast's glTF emissive material
  with KHR_materials_emissive_strength, black; Mitsuba's one-sided `area` emitter on a black
  `rectangle`), outside the camera's view, uploaded as a second scene;
- lights: no environment; a point light, a spot light and a sun together (Mitsuba `point`,
  `spot` with a 0.5° transition where ours blends by smoothstep over the same 0.5°, and
  `directional`); their indirect light taken out of Mitsuba's images as above.

Path depth: lightcast's `bounces` B reflects B times after the visible surface; Mitsuba's
max_depth counts segments from the camera, so B + 2 (B + 1 for the emitter of `area`, which
lightcast's paths find by their bounce rays only).

Needs `pip install mitsuba numpy` (the `scalar_rgb` variant needs no LLVM) and the
`environment_map` example (`cargo build -p lightcast-server --example environment_map`).

Usage (a lightcast server must be running; see bench/results/mitsuba-environment.md):
    python3 bench/mitsuba/validate_environment.py --server http://127.0.0.1:18181 --spp 256
"""

import argparse
import json
import math
import multiprocessing as mp
import os
import shutil
import struct
import subprocess
import sys
import tempfile
import time
import urllib.error
import urllib.request

import numpy as np

from lightcast_bsdf import register_bsdf

# ---------------------------------------------------------------------------------------------
# The scene

WIDTH, HEIGHT = 64, 48
CAMERA = {"position": [3.5, 2.5, 4.5], "target": [0.3, 0.4, 0.0], "fov_y_degrees": 40.0}
GROUND = (-10.0, 10.0)  # x and z extent, y = 0
BOX = ((-0.2, 0.0, -0.6), (0.8, 1.0, 0.4))  # min, max corners
GROUND_ALBEDO = (0.6, 0.6, 0.6)
BOX_ALBEDO = (0.8, 0.55, 0.3)


def quads():
    """(name, albedo, [quads as 4 corners counter-clockwise seen from outside, normal])."""
    g0, g1 = GROUND
    ground = [([(g0, 0, g0), (g0, 0, g1), (g1, 0, g1), (g1, 0, g0)], (0, 1, 0))]
    (x0, y0, z0), (x1, y1, z1) = BOX
    box = [
        ([(x1, y0, z0), (x1, y1, z0), (x1, y1, z1), (x1, y0, z1)], (1, 0, 0)),
        ([(x0, y0, z1), (x0, y1, z1), (x0, y1, z0), (x0, y0, z0)], (-1, 0, 0)),
        ([(x0, y1, z0), (x0, y1, z1), (x1, y1, z1), (x1, y1, z0)], (0, 1, 0)),
        ([(x0, y0, z1), (x1, y0, z1), (x1, y1, z1), (x0, y1, z1)], (0, 0, 1)),
        ([(x1, y0, z0), (x0, y0, z0), (x0, y1, z0), (x1, y1, z0)], (0, 0, -1)),
    ]  # no bottom face: it would lie on the ground
    return [("ground", GROUND_ALBEDO, ground), ("box", BOX_ALBEDO, box)]


def mesh_arrays(faces):
    """Flat-shaded triangles: positions, normals (per vertex) and indices."""
    pos, nrm, idx = [], [], []
    for corners, n in faces:
        a, b, c, d = corners
        e1 = np.subtract(b, a)
        e2 = np.subtract(c, a)
        # Wind so that the triangles face their normal.
        flip = np.dot(np.cross(e1, e2), n) < 0
        base = len(pos)
        pos += [a, b, c, d]
        nrm += [n] * 4
        tri = [0, 1, 2, 0, 2, 3] if not flip else [0, 2, 1, 0, 3, 2]
        idx += [base + t for t in tri]
    return (
        np.array(pos, np.float32),
        np.array(nrm, np.float32),
        np.array(idx, np.uint32),
    )


PANEL_CENTRE, PANEL_HALF, PANEL_RADIANCE = (0.3, 2.5, -0.1), 0.5, 8.0


def panel():
    """The `area` case's emitter: (name, corners facing down)."""
    (x, y, z), h = PANEL_CENTRE, PANEL_HALF
    return ("panel", [([(x - h, y, z - h), (x + h, y, z - h), (x + h, y, z + h), (x - h, y, z + h)],
                       (0, -1, 0))])


def gltf_material(name, base, metallic=0.0, roughness=1.0):
    """A two-sided glTF metallic-roughness material."""
    return {
        "name": name,
        "doubleSided": True,
        "pbrMetallicRoughness": {
            "baseColorFactor": list(base) + [1.0],
            "metallicFactor": metallic,
            "roughnessFactor": roughness,
        },
    }


def write_glb(path, with_panel=False):
    """The scene as glTF 2.0 binary: one mesh per material, metallic 0, roughness 1; with the
    emissive panel if asked (black: a black dielectric without its specular lobe,
    KHR_materials_specular's specularFactor 0, reflects nothing, as Mitsuba's black panel)."""
    parts = [(name, gltf_material(name, albedo), faces) for name, albedo, faces in quads()]
    if not with_panel:
        write_glb_parts(path, parts)
        return
    name, faces = panel()
    emissive = {
        "name": name,
        "pbrMetallicRoughness": {
            "baseColorFactor": [0.0, 0.0, 0.0, 1.0],
            "metallicFactor": 0.0,
            "roughnessFactor": 1.0,
        },
        "emissiveFactor": [1.0, 1.0, 1.0],
        "extensions": {
            "KHR_materials_emissive_strength": {"emissiveStrength": PANEL_RADIANCE},
            "KHR_materials_specular": {"specularFactor": 0.0},
        },
    }
    write_glb_parts(
        path,
        parts + [(name, emissive, faces)],
        ["KHR_materials_emissive_strength", "KHR_materials_specular"],
    )


def write_glb_parts(path, parts, extensions_used=()):
    """glTF 2.0 binary of (name, glTF material, faces) parts: one mesh and node each."""
    blob = bytearray()
    views, accessors, meshes, nodes, materials = [], [], [], [], []

    def add(data, target, ctype, kind, count, minmax=None):
        while len(blob) % 4:
            blob.append(0)
        views.append(
            {"buffer": 0, "byteOffset": len(blob), "byteLength": len(data), "target": target}
        )
        blob.extend(data)
        acc = {"bufferView": len(views) - 1, "componentType": ctype, "count": count, "type": kind}
        if minmax:
            acc["min"], acc["max"] = minmax
        accessors.append(acc)
        return len(accessors) - 1

    for k, (name, material, faces) in enumerate(parts):
        p, n, i = mesh_arrays(faces)
        ap = add(p.tobytes(), 34962, 5126, "VEC3", len(p), (p.min(0).tolist(), p.max(0).tolist()))
        an = add(n.tobytes(), 34962, 5126, "VEC3", len(n))
        ai = add(i.tobytes(), 34963, 5125, "SCALAR", len(i))
        materials.append(material)
        meshes.append(
            {
                "name": name,
                "primitives": [
                    {"attributes": {"POSITION": ap, "NORMAL": an}, "indices": ai, "material": k}
                ],
            }
        )
        nodes.append({"mesh": k, "name": name})
    while len(blob) % 4:
        blob.append(0)
    doc = {
        "asset": {"version": "2.0", "generator": "lightcast bench/mitsuba"},
        "scene": 0,
        "scenes": [{"nodes": list(range(len(nodes)))}],
        "nodes": nodes,
        "meshes": meshes,
        "materials": materials,
        "accessors": accessors,
        "bufferViews": views,
        "buffers": [{"byteLength": len(blob)}],
    }
    if extensions_used:
        doc["extensionsUsed"] = list(extensions_used)
    js = json.dumps(doc).encode()
    js += b" " * (-len(js) % 4)
    out = struct.pack("<III", 0x46546C67, 2, 12 + 8 + len(js) + 8 + len(blob))
    out += struct.pack("<II", len(js), 0x4E4F534A) + js
    out += struct.pack("<II", len(blob), 0x004E4942) + bytes(blob)
    with open(path, "wb") as f:
        f.write(out)


def write_obj(path, faces):
    p, _, i = mesh_arrays(faces)
    with open(path, "w") as f:
        for v in p:
            f.write("v %r %r %r\n" % tuple(float(x) for x in v))
        for t in i.reshape(-1, 3):
            f.write("f %d %d %d\n" % tuple(int(x) + 1 for x in t))


# ---------------------------------------------------------------------------------------------
# Camera and the pixels that see one surface only

def camera_rays(px, py):
    """Unit directions through image points (pixels, y down) as lightcast's camera makes them
    (frame_uniforms.rs: look_to_rh from position to target with +Y up, vertical fov)."""
    eye = np.array(CAMERA["position"])
    f = np.array(CAMERA["target"]) - eye
    f /= np.linalg.norm(f)
    r = np.cross(f, [0.0, 1.0, 0.0])
    r /= np.linalg.norm(r)
    u = np.cross(r, f)
    t = math.tan(math.radians(CAMERA["fov_y_degrees"]) / 2)
    x = (px / WIDTH * 2 - 1) * t * WIDTH / HEIGHT
    y = (1 - py / HEIGHT * 2) * t
    d = f + x[..., None] * r + y[..., None] * u
    return eye, d / np.linalg.norm(d, axis=-1, keepdims=True)


def surface_ids(px, py):
    """-1: nothing; 0: ground; 1 + k: box face k (by slab and sign)."""
    eye, d = camera_rays(px, py)
    best = np.full(d.shape[:-1], np.inf)
    ids = np.full(d.shape[:-1], -1)
    with np.errstate(divide="ignore", invalid="ignore"):
        t = -eye[1] / d[..., 1]
        p = eye + t[..., None] * d
        ok = (t > 0) & (np.abs(p[..., 0]) <= GROUND[1]) & (np.abs(p[..., 2]) <= GROUND[1])
        best = np.where(ok, t, best)
        ids = np.where(ok, 0, ids)
        lo, hi = np.array(BOX[0]), np.array(BOX[1])
        t0 = (lo - eye) / d
        t1 = (hi - eye) / d
        tmin = np.minimum(t0, t1)
        tmax = np.maximum(t0, t1)
        tn = tmin.max(-1)
        tf = tmax.min(-1)
        sign = np.take_along_axis(d, tmin.argmax(-1)[..., None], -1)[..., 0] > 0
        face = 1 + tmin.argmax(-1) * 2 + sign
        hit = (tn <= tf) & (tf > 0) & (tn > 0) & (tn < best)
        ids = np.where(hit, face, ids)
    return ids


def interior_mask():
    """Pixels whose centre, corners and edge midpoints all see the same surface: there a
    pixel-centre sample (lightcast) and a pixel-area average (Mitsuba) agree to second order."""
    py, px = np.mgrid[0:HEIGHT, 0:WIDTH].astype(float)
    ref = surface_ids(px + 0.5, py + 0.5)
    ok = ref >= 0
    for dx in (0.02, 0.5, 0.98):
        for dy in (0.02, 0.5, 0.98):
            ok &= surface_ids(px + dx, py + dy) == ref
    return ok, ref


# ---------------------------------------------------------------------------------------------
# lightcast

def http(url, data=None, headers=None, timeout=7200):
    req = urllib.request.Request(url, data=data, headers=headers or {})
    try:
        with urllib.request.urlopen(req, timeout=timeout) as r:
            return r.read(), dict(r.headers)
    except urllib.error.HTTPError as e:
        sys.exit("%s: HTTP %d %s" % (url, e.code, e.read().decode(errors="replace")))


def upload_scene(server, glb, extra=None):
    """The scene, as a `.glb` body or, with `extra` files, as multipart/form-data."""
    with open(glb, "rb") as f:
        data = f.read()
    if not extra:
        body, _ = http(server + "/v1/scenes", data, {"Content-Type": "model/gltf-binary"})
        return json.loads(body)["id"]
    boundary = "lightcast-validate-environment"
    parts = b""
    for path in [glb] + extra:
        with open(path, "rb") as f:
            content = f.read()
        parts += (
            "--%s\r\nContent-Disposition: form-data; name=\"files\"; filename=\"%s\"\r\n"
            "Content-Type: application/octet-stream\r\n\r\n" % (boundary, os.path.basename(path))
        ).encode() + content + b"\r\n"
    parts += ("--%s--\r\n" % boundary).encode()
    body, _ = http(
        server + "/v1/scenes", parts,
        {"Content-Type": "multipart/form-data; boundary=%s" % boundary},
    )
    return json.loads(body)["id"]


def write_rgbe(path, img):
    """A Radiance RGBE file of float RGB `img` (rows from the top), flat scanlines."""
    h, w, _ = img.shape
    peak = img.max(-1)
    exp = np.where(peak > 1e-32, np.floor(np.log2(np.maximum(peak, 1e-32))) + 1, 0)
    scale = np.where(peak > 1e-32, 256.0 / np.exp2(exp), 0)
    rgbe = np.zeros((h, w, 4), np.uint8)
    rgbe[..., :3] = np.clip(img * scale[..., None], 0, 255).astype(np.uint8)
    rgbe[..., 3] = np.where(peak > 1e-32, exp + 128, 0).astype(np.uint8)
    with open(path, "wb") as f:
        f.write(b"#?RADIANCE\nFORMAT=32-bit_rle_rgbe\n\n-Y %d +X %d\n" % (h, w))
        f.write(rgbe.tobytes())


SUN = (slice(60, 63), slice(300, 303))


def sky_image(width=512, height=256):
    """A blue gradient above a dim brown ground, and a sun of 3×3 texels, in the image
    convention of lightcast's `image` environments (Mitsuba's)."""
    theta = np.pi * (np.arange(height) + 0.5) / height
    u = (np.arange(width) + 0.5) / width
    up = np.cos(theta)[:, None] + 0 * u[None, :]
    img = np.where(
        (up > 0)[..., None],
        np.stack([0.25 + 0.3 * (1 - up), 0.45 + 0.3 * (1 - up), 1.0 + 0 * up], -1),
        np.array([0.08, 0.06, 0.04]),
    ) * (1 + 0.3 * np.sin(2 * np.pi * u))[None, :, None]
    img[SUN] = [20000.0, 18000.0, 15000.0]
    return img


def sun(direction, intensity):
    return {
        "kind": "directional", "position": [0, 0, 0], "direction": list(direction),
        "color": [1, 1, 1], "intensity": intensity, "inner_cone": 0, "outer_cone": 0,
    }


def mitsuba_light(light):
    """A lightcast punctual light (protocol `Light`, intensity in lux or candela) as a Mitsuba
    emitter of the same units."""
    import mitsuba as mi

    d = np.array(light["direction"], float)
    d /= np.linalg.norm(d)
    value = {"type": "rgb", "value": [c * light["intensity"] for c in light["color"]]}
    if light["kind"] == "directional":
        return {"type": "directional", "direction": d.tolist(), "irradiance": value}
    if light["kind"] == "point":
        return {"type": "point", "position": light["position"], "intensity": value}
    p = np.array(light["position"], float)
    return {
        "type": "spot", "intensity": value,
        "cutoff_angle": math.degrees(light["outer_cone"]),
        "beam_width": math.degrees(light["inner_cone"]),
        "to_world": mi.ScalarTransform4f().look_at(
            origin=p.tolist(), target=(p + d).tolist(), up=[0, 1, 0] if abs(d[1]) < 0.9 else [1, 0, 0]
        ),
    }


def render_lightcast(server, scene, case, spp):
    req = {
        "render": {
            "scene": scene, "width": WIDTH, "height": HEIGHT, "camera": CAMERA,
            "lights": case["lights"],
            "environment": case["environment"], "exposure": 1.0,
            "gi": {"method": "reference", "spp": spp, "bounces": case["bounces"]},
        },
        "format": "raw_indirect",
    }
    t = time.time()
    body, headers = http(
        server + "/v1/render", json.dumps(req).encode(), {"Content-Type": "application/json"}
    )
    report = json.loads(headers.get("x-lightcast-report", headers.get("X-Lightcast-Report", "{}")))
    img = np.frombuffer(body, "<f4").reshape(HEIGHT, WIDTH, 4)[..., :3].astype(np.float64)
    return img, report, time.time() - t


# ---------------------------------------------------------------------------------------------
# Mitsuba (in worker processes: a Python BSDF holds the GIL, so processes give the parallelism)

def read_pfm(path):
    with open(path, "rb") as f:
        assert f.readline().strip() == b"PF"
        w, h = map(int, f.readline().split())
        scale = float(f.readline())
        data = np.frombuffer(f.read(), "<f4" if scale < 0 else ">f4").reshape(h, w, 3)
    return data[::-1].astype(np.float64)  # rows from the top (+Y)


def ours_lookup(env, d):
    """lightcast's EnvironmentMap::lookup (piecewise constant) for unit directions d[..., 3]."""
    h, w, _ = env.shape
    theta = np.arccos(np.clip(d[..., 1], -1, 1))
    phi = np.mod(np.arctan2(d[..., 2], d[..., 0]), 2 * np.pi)
    i = np.minimum((phi / (2 * np.pi) * w).astype(int), w - 1)
    j = np.minimum((theta / np.pi * h).astype(int), h - 1)
    return env[j, i]


def box_weights(centres, half, edges, period=None):
    """Row-stochastic weights: how much of the window [c − half, c + half] around each centre
    falls in each interval [edges[k], edges[k+1]] (wrapping by `period` if given)."""
    n = len(edges) - 1
    w = np.zeros((len(centres), n))
    shifts = (-period, 0.0, period) if period else (0.0,)
    for r, c in enumerate(centres):
        for s in shifts:
            lo = np.maximum(edges[:-1] + s, c - half)
            hi = np.minimum(edges[1:] + s, c + half)
            w[r] += np.clip(hi - lo, 0, None)
        w[r] /= w[r].sum()
    return w


def mitsuba_grid(env, width=1024, height=513):
    """Our map on the grid points of Mitsuba's envmap (envmap.cpp): column c at
    u = (c + ½)/W, row r at θ = π r/(H − 1), direction (sin 2πu sin θ, cos θ, −cos 2πu sin θ);
    Mitsuba interpolates bilinearly between them. Each grid value is our map averaged over
    the grid cell around its point (a box window of one grid spacing): bilinear hats over
    such values integrate to our map's integral, where point samples would move a small
    bright feature's edges by up to a grid spacing (±17 % of a 3-texel sun's power)."""
    h, w, _ = env.shape
    # Rows: θ windows (the sin θ weight within a window is left out: second order).
    theta = np.pi * np.arange(height) / (height - 1)
    rows = box_weights(theta, np.pi / (height - 1) / 2, np.pi * np.arange(h + 1) / h)
    # Columns: grid u → our φ = 2πu − π/2 (module doc of scene/src/environment_image.rs).
    phi = 2 * np.pi * (np.arange(width) + 0.5) / width - np.pi / 2
    cols = box_weights(
        phi, np.pi / width, 2 * np.pi * np.arange(w + 1) / w, period=2 * np.pi
    )
    return np.stack([rows @ env[..., k] @ cols.T for k in range(3)], -1).astype(np.float32)


def mitsuba_camera(mi, spp, seed):
    """lightcast's camera (CAMERA, WIDTH × HEIGHT) as a Mitsuba sensor, box-filtered pixels."""
    return {
        "type": "perspective", "fov": CAMERA["fov_y_degrees"], "fov_axis": "y",
        "near_clip": 0.01, "far_clip": 1000.0,
        "to_world": mi.ScalarTransform4f().look_at(
            origin=CAMERA["position"], target=CAMERA["target"], up=[0, 1, 0]
        ),
        "film": {
            "type": "hdrfilm", "width": WIDTH, "height": HEIGHT,
            "rfilter": {"type": "box"}, "pixel_format": "rgb",
        },
        "sampler": {"type": "independent", "sample_count": spp, "seed": seed},
    }


def mitsuba_job(args):
    """One Mitsuba image: (workdir, case, what ∈ {env, lights_all, lights_direct}, spp, seed)."""
    workdir, case, what, spp, seed = args
    import drjit as dr
    import mitsuba as mi

    mi.set_variant("scalar_rgb")
    dr.set_thread_count(1)
    register_bsdf(mi)
    scene = {"type": "scene", "camera": mitsuba_camera(mi, spp, seed)}
    for name, albedo, _ in quads():
        scene[name] = {
            "type": "obj", "filename": os.path.join(workdir, name + ".obj"), "face_normals": True,
            "bsdf": {"type": "lightcast", "r": albedo[0], "g": albedo[1], "b": albedo[2],
                     "metallic": 0.0, "roughness": 1.0},
        }
    depth = case["bounces"] + 2
    env = case["environment"]
    if what == "area":
        # lightcast's paths find emitters by their bounce rays only, so `bounces` B counts the
        # emitter's light after B − 1 reflections before the visible surface, where a punctual
        # light's (next-event estimation at every vertex) comes after B: depth B + 1 here.
        depth = case["bounces"] + 1
        scene["panel"] = {
            "type": "obj", "filename": os.path.join(workdir, "panel.obj"), "face_normals": True,
            "bsdf": {"type": "diffuse", "reflectance": {"type": "rgb", "value": [0.0, 0.0, 0.0]}},
            "emitter": {"type": "area", "radiance": {"type": "rgb", "value": [PANEL_RADIANCE] * 3}},
        }
    elif what == "env":
        if env["kind"] == "uniform":
            scene["sky"] = {
                "type": "constant",
                "radiance": {"type": "rgb", "value": [c * env["intensity"] for c in env["color"]]},
            }
        else:
            grid = np.load(os.path.join(workdir, case["name"] + ".envgrid.npy"))
            scene["sky"] = {"type": "envmap", "bitmap": mi.Bitmap(grid)}
    else:
        depth = 2 if what == "lights_direct" else depth
        for k, light in enumerate(case["lights"]):
            scene["light%d" % k] = mitsuba_light(light)
    scene["integrator"] = {
        "type": "path", "max_depth": depth, "rr_depth": 1000, "hide_emitters": True,
    }
    s = mi.load_dict(scene)
    img = np.array(mi.render(s, spp=spp, seed=seed), dtype=np.float64)[..., :3]
    return img


# ---------------------------------------------------------------------------------------------
# Comparison

def stats(ours, mits_a, mits_b, mask, spp_ours, spp_mitsuba):
    """Per-channel relative difference of the means over `mask`, block MAE over 8×8 blocks, and
    Mitsuba's noise from its two halves."""
    mits = 0.5 * (mits_a + mits_b)
    half = 0.5 * (mits_a - mits_b)  # same variance as the full Mitsuba image, zero mean
    n = mask.sum()
    mean_o = ours[mask].mean(0)
    mean_m = mits[mask].mean(0)
    sigma_m = np.sqrt((half[mask] ** 2).sum(0)) / n  # std of Mitsuba's mean
    # lightcast's noise: assume the same per-sample variance (both MIS path tracers alike).
    sigma_o = sigma_m * math.sqrt(spp_mitsuba / spp_ours)
    blocks_o, blocks_m, blocks_h = [], [], []
    for by in range(0, HEIGHT, 8):
        for bx in range(0, WIDTH, 8):
            m = mask[by:by + 8, bx:bx + 8]
            if m.sum() < 16:
                continue
            blocks_o.append(ours[by:by + 8, bx:bx + 8][m].mean(0))
            blocks_m.append(mits[by:by + 8, bx:bx + 8][m].mean(0))
            blocks_h.append(half[by:by + 8, bx:bx + 8][m].mean(0))
    blocks_o, blocks_m, blocks_h = map(np.array, (blocks_o, blocks_m, blocks_h))
    mae = np.abs(blocks_o - blocks_m).mean(0) / mean_m
    floor = np.abs(blocks_h).mean(0) / mean_m * math.sqrt(1 + spp_mitsuba / spp_ours)
    return {
        "pixels": int(n), "blocks": len(blocks_o),
        "mean_lightcast": mean_o.tolist(), "mean_mitsuba": mean_m.tolist(),
        "rel_diff": (mean_o / mean_m - 1).tolist(),
        "rel_sigma": (np.sqrt(sigma_m**2 + sigma_o**2) / mean_m).tolist(),
        "block_mae": mae.tolist(), "block_mae_noise": floor.tolist(),
    }


def check_envmap_mapping(workdir):
    """A map with one bright quadrant (φ ∈ [0, π/2), upper hemisphere) in our convention must be
    bright in Mitsuba's envmap for the same directions, and only there."""
    import mitsuba as mi

    mi.set_variant("scalar_rgb")
    env = np.zeros((64, 128, 3))
    env[:32, :32] = 1.0
    emitter = mi.load_dict({"type": "envmap", "bitmap": mi.Bitmap(mitsuba_grid(env))})
    rng = np.random.default_rng(1)
    bad = 0
    for _ in range(2000):
        d = rng.normal(size=3)
        d /= np.linalg.norm(d)
        theta, phi = math.acos(d[1]), math.atan2(d[2], d[0]) % (2 * math.pi)
        # Stay clear of the quadrant's edges (Mitsuba blends across them by 1/16 texel).
        edge = min(abs(theta - math.pi / 2), phi, abs(phi - math.pi / 2), 2 * math.pi - phi)
        if edge < 0.03:
            continue
        si = mi.SurfaceInteraction3f()
        si.wi = mi.Vector3f(*(-d))
        got = float(emitter.eval(si)[0])
        want = float(ours_lookup(env, d[None])[0, 0])
        bad += abs(got - want) > 1e-3
    return bad


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawTextHelpFormatter)
    ap.add_argument("--server", default="http://127.0.0.1:18181")
    ap.add_argument("--spp", type=int, default=256, help="Mitsuba samples per pixel (two halves)")
    ap.add_argument("--lightcast-spp", type=int, default=1024)
    ap.add_argument("--workers", type=int, default=os.cpu_count())
    ap.add_argument("--bounces", default="1,3")
    ap.add_argument("--cases", default="uniform,sky,image,area,lights")
    ap.add_argument(
        "--env-tool", default="target/debug/examples/environment_map",
        help="the environment_map example (cargo build -p lightcast-server --example environment_map)",
    )
    ap.add_argument("--json", help="write the results here too")
    args = ap.parse_args()

    sun_dir = np.array([0.4, -0.6, 0.3])
    sun_dir = (sun_dir / np.linalg.norm(sun_dir)).tolist()
    all_cases = {
        "uniform": {
            "environment": {"kind": "uniform", "intensity": 2.0, "color": [0.5, 0.7, 1.0]},
            "lights": [sun(sun_dir, 0.0)],
        },
        "sky": {
            "environment": {"kind": "sky", "intensity": 0.2, "turbidity": 3.0, "color": [1, 1, 1]},
            "lights": [sun(sun_dir, 3.0)],
        },
        "image": {
            "environment": {"kind": "image", "intensity": 1.0, "color": [1, 1, 1]},
            "lights": [sun(sun_dir, 0.0)],
        },
        "area": {"environment": None, "lights": [], "area": True},
        "lights": {
            "environment": None,
            "lights": [
                {
                    "kind": "point", "position": [1.8, 1.6, 1.2], "direction": [0, -1, 0],
                    "color": [1.0, 0.8, 0.6], "intensity": 3.0, "inner_cone": 0, "outer_cone": 0,
                },
                {
                    "kind": "spot", "position": [-1.5, 2.8, 1.8], "direction": [0.55, -0.7, -0.6],
                    "color": [0.6, 0.8, 1.0], "intensity": 12.0,
                    "inner_cone": math.radians(29.5), "outer_cone": math.radians(30.0),
                },
                sun(sun_dir, 1.0),
            ],
        },
    }
    cases = []
    for kind in args.cases.split(","):
        for b in map(int, args.bounces.split(",")):
            cases.append(dict(all_cases[kind], name="%s-b%d" % (kind, b), kind=kind, bounces=b))

    workdir = tempfile.mkdtemp(prefix="lightcast-mitsuba-")
    try:
        for name, _, faces in quads():
            write_obj(os.path.join(workdir, name + ".obj"), faces)
        write_glb(os.path.join(workdir, "scene.glb"))
        write_glb(os.path.join(workdir, "panel.glb"), with_panel=True)
        write_obj(os.path.join(workdir, "panel.obj"), panel()[1])
        write_rgbe(os.path.join(workdir, "sky.hdr"), sky_image())
        bad = check_envmap_mapping(workdir)
        print("envmap mapping check: %d of the sampled directions disagree" % bad, flush=True)
        if bad:
            sys.exit("the envmap mapping is wrong")
        for c in cases:
            if c["kind"] in ("sky", "image"):
                pfm = os.path.join(workdir, c["name"] + ".pfm")
                e, d = c["environment"], c["lights"][0]["direction"]
                extra = (
                    ["--turbidity", str(e["turbidity"])] if c["kind"] == "sky"
                    else ["--image", os.path.join(workdir, "sky.hdr")]
                )
                subprocess.run(
                    [
                        args.env_tool, "--kind", c["kind"], "--intensity", str(e["intensity"]),
                        "--sun-direction=%r,%r,%r" % tuple(d),
                        "--sun-intensity", str(c["lights"][0]["intensity"]), "--output", pfm,
                    ] + extra,
                    check=True,
                )
                np.save(os.path.join(workdir, c["name"] + ".envgrid.npy"), mitsuba_grid(read_pfm(pfm)))

        scene = upload_scene(
            args.server, os.path.join(workdir, "scene.glb"), [os.path.join(workdir, "sky.hdr")]
        )
        panel_scene = upload_scene(args.server, os.path.join(workdir, "panel.glb"))
        print("scenes", scene, panel_scene, flush=True)
        mask, ids = interior_mask()

        # Mitsuba jobs: each case's halves A and B (different seeds); the punctual lights' pair
        # shares a seed so that their direct light cancels exactly.
        half = args.spp // 2
        jobs, keys = [], []
        for c in cases:
            for h, seed in (("a", 1), ("b", 2)):
                if c["environment"]:
                    jobs.append((workdir, c, "env", half, seed))
                    keys.append((c["name"], h, "env"))
                if c.get("area"):
                    jobs.append((workdir, c, "area", half, seed))
                    keys.append((c["name"], h, "area"))
                if any(light["intensity"] > 0 for light in c["lights"]):
                    for what in ("lights_all", "lights_direct"):
                        jobs.append((workdir, c, what, half, 100 + seed))
                        keys.append((c["name"], h, what))
        t = time.time()
        pool = mp.get_context("spawn").Pool(args.workers)
        pending = pool.map_async(mitsuba_job, jobs)

        ours = {}
        for c in cases:
            img, report, secs = render_lightcast(
                args.server, panel_scene if c.get("area") else scene, c, args.lightcast_spp
            )
            ours[c["name"]] = img
            print("lightcast %s: %.1f s, report %s" % (c["name"], secs, json.dumps(report)[:400]), flush=True)
        imgs = dict(zip(keys, pending.get()))
        pool.close()
        print("mitsuba: %.1f s for %d images" % (time.time() - t, len(jobs)), flush=True)

        results = {}
        for c in cases:
            o = ours[c["name"]]
            halves = []
            for h in "ab":
                m = imgs.get((c["name"], h, "env"), 0.0) + imgs.get((c["name"], h, "area"), 0.0)
                if (c["name"], h, "lights_all") in imgs:
                    m = m + imgs[(c["name"], h, "lights_all")] - imgs[(c["name"], h, "lights_direct")]
                halves.append(m)
            # Pixels where the camera model sees the sky must be black in raw_indirect, and
            # only those (a zero surface pixel can be a fact of the lighting, so it is counted
            # only where an environment lights every surface).
            bg_ours = np.all(o == 0, -1)
            bg_model = ids < 0
            r = stats(o, halves[0], halves[1], mask, args.lightcast_spp, args.spp)
            if c["environment"]:
                r["background_mismatch_px"] = int((bg_ours != bg_model).sum())
            results[c["name"]] = r
            np.save(os.path.join(workdir, c["name"] + ".ours.npy"), o)
            np.save(os.path.join(workdir, c["name"] + ".mitsuba.npy"), 0.5 * (halves[0] + halves[1]))
        print(json.dumps(results, indent=1))
        print_table(results, args)
        if args.json:
            with open(args.json, "w") as f:
                json.dump({"args": vars(args), "results": results}, f, indent=1)
    finally:
        if os.environ.get("KEEP_WORKDIR"):
            print("kept", workdir)
        else:
            shutil.rmtree(workdir, ignore_errors=True)


def print_table(results, args):
    pct = lambda v: "/".join("%+.2f" % (100 * x) for x in v)
    print()
    print("| case | pixels | mean lightcast (RGB) | mean Mitsuba (RGB) | mean diff % (R/G/B) | 1σ noise % | 8×8 block MAE % | block MAE noise floor % |")
    print("|---|---|---|---|---|---|---|---|")
    for name, r in results.items():
        print(
            "| %s | %d | %s | %s | %s | %s | %s | %s |"
            % (
                name, r["pixels"],
                " ".join("%.4f" % x for x in r["mean_lightcast"]),
                " ".join("%.4f" % x for x in r["mean_mitsuba"]),
                pct(r["rel_diff"]),
                "/".join("%.2f" % (100 * x) for x in r["rel_sigma"]),
                "/".join("%.2f" % (100 * x) for x in r["block_mae"]),
                "/".join("%.2f" % (100 * x) for x in r["block_mae_noise"]),
            )
        )


if __name__ == "__main__":
    main()
