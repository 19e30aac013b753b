#!/usr/bin/env python3
"""Validates lightcast's metallic-roughness material model (GGX, separable Smith, Schlick and
the energy-conserving diffuse lobe of bench/mitsuba/lightcast_bsdf.py) against Mitsuba 3, in
the direct light and in the path-traced reference.

validate_environment.py's ground plane and 1 m box, its camera and 64×48 pixels, lit by one
point light and no environment. The light (LIGHT, 60 cd) stands 2.2 m up and 4.5 m beyond the
box as the camera sees it, where the box's top face mirrors it towards the camera: the metal
box's highlight lies in the middle of its top face. So the box's two visible sides face away
from the light (they get indirect light only) and its shadow falls towards the camera. Scenes
(glTF materials with metallicFactor and roughnessFactor, two-sided):

- diffuse: ground 0.6 grey, box (0.8, 0.55, 0.3), both metallic 0, roughness 1;
- glossy: ground a dielectric 0.6 grey at roughness 0.4; box metallic 1, roughness 0.3, base
  (0.95, 0.64, 0.54) (copper-like);
- glossy-sender (issue 34): the diffuse box on a steel ground (metallic 1, roughness 0.3) under
  a sun (SUN, 3 lx) from behind the camera, whose reflection off the ground lights the box's
  visible sides: the glossy senders the RSM-based methods leave out, checked in the reference
  before anything is measured against it;
- glossy-white: glossy with a white metal box (F = 1), which Mitsuba renders with its own
  `roughconductor` (ggx, alpha 0.09, material none: η = 0, k = 1, Fresnel 1; check_bsdf.py
  shows it equals the Python BSDF there to 10⁻⁶): a check of the metal that does not rest on
  the Python BSDF.

Mitsuba (`scalar_rgb`, `path`) renders every other surface with lightcast_bsdf.py's BSDF.

(a) Direct light: lightcast's `gi.method: none` frame as `raw_final` (emission and direct
    light with PCF shadow maps, before exposure) against Mitsuba's `path` at max_depth 2
    traced through each pixel's centre, where lightcast shades: one path per pixel, as a
    point light's direct light is then exact (no noise), where a pixel-area average would
    differ from the centre by 7 % (median) on the highlight. Over the pixels whose whole
    area sees one surface (validate_environment.interior_mask) less shadow edges (pixels
    whose 3×3 neighbourhood holds both lit and unlit Mitsuba pixels of their own surface:
    PCF blurs the shadow there) it reports the relative difference of the means over the lit
    pixels and over all, the per-pixel relative difference of luminance over the lit pixels
    (median, 95th percentile, max) and the pixels lit in one image only (shadow acne or
    light leaks); "all with edges" keeps the shadow edges.
(b) Reference: `gi: {method: reference, spp, bounces: B}` as `raw_indirect` (all but the point
    light's direct light) against Mitsuba at max_depth B + 2 minus Mitsuba at max_depth 2
    rendered with the same seed (the direct light cancels exactly), in two halves of different
    seeds for the noise estimate (validate_environment.stats).

Both tables have a row per scene and surface: all pixels, the ground's, the box's.
Mitsuba's half takes about half an hour at --spp 4096 with 2 workers (2 cores).

Usage (a lightcast server with the metallic-roughness material model must be running, as for
validate_environment.py, e.g. `target/debug/lightcast-server serve --listen 127.0.0.1:18181
--allow-cpu-adapter --max-request-cost 1e15 --max-spp 1024`):
    python3 bench/mitsuba/validate_materials.py --server http://127.0.0.1:18181 --spp 4096 \\
        --lightcast-spp 1024 --bounces 1,3 --workers 2 --json bench/results/mitsuba-materials.json
"""

import argparse
import collections
import json
import multiprocessing as mp
import os
import shutil
import tempfile
import time

import numpy as np

import validate_environment as ve
from lightcast_bsdf import MIN_ROUGHNESS, register_bsdf
from validate_environment import CAMERA, HEIGHT, WIDTH

# ---------------------------------------------------------------------------------------------
# The scenes

# A surface's glTF factors; builtin: Mitsuba renders it with roughconductor, not the Python BSDF.
GltfMaterial = collections.namedtuple(
    "GltfMaterial", "base metallic roughness builtin", defaults=[False]
)

GLOSSY_GROUND = GltfMaterial((0.6, 0.6, 0.6), 0.0, 0.4)
SCENES = {
    "diffuse": {
        "ground": GltfMaterial(ve.GROUND_ALBEDO, 0.0, 1.0),
        "box": GltfMaterial(ve.BOX_ALBEDO, 0.0, 1.0),
    },
    "glossy": {"ground": GLOSSY_GROUND, "box": GltfMaterial((0.95, 0.64, 0.54), 1.0, 0.3)},
    "glossy-white": {"ground": GLOSSY_GROUND, "box": GltfMaterial((1.0, 1.0, 1.0), 1.0, 0.3, True)},
    "glossy-sender": {
        "ground": GltfMaterial((0.78, 0.78, 0.8), 1.0, 0.3),
        "box": GltfMaterial(ve.BOX_ALBEDO, 0.0, 1.0),
    },
}

# The top face's centre (0.3, 1, −0.1) mirrors this point towards the camera.
LIGHT = {
    "kind": "point", "position": [-2.26, 2.2, -3.78], "direction": [0, -1, 0],
    "color": [1.0, 1.0, 1.0], "intensity": 60.0, "inner_cone": 0, "outer_cone": 0,
}
# From above and behind the camera: the ground mirrors it onto the box's +x and +z sides.
SUN = {
    "kind": "directional", "position": [0, 0, 0], "direction": [-0.55, -0.6, -0.58],
    "color": [1.0, 1.0, 1.0], "intensity": 3.0, "inner_cone": 0, "outer_cone": 0,
}
LIGHTS = {"glossy-sender": SUN}


def light_of(scene):
    return LIGHTS.get(scene, LIGHT)


def faces_by_part():
    return {name: faces for name, _, faces in ve.quads()}


def write_scene_glb(path, materials):
    parts = []
    for name, faces in faces_by_part().items():
        m = materials[name]
        parts.append((name, ve.gltf_material(name, m.base, m.metallic, m.roughness), faces))
    ve.write_glb_parts(path, parts)


# ---------------------------------------------------------------------------------------------
# lightcast

def render_lightcast(server, scene, light, gi, fmt, shadow_map_size):
    req = {
        "render": {
            "scene": scene, "width": WIDTH, "height": HEIGHT, "camera": CAMERA,
            "lights": [light], "environment": None, "exposure": 1.0,
            "shadow_map_size": shadow_map_size, "gi": gi,
        },
        "format": fmt,
    }
    t = time.time()
    body, headers = ve.http(
        server + "/v1/render", json.dumps(req).encode(), {"Content-Type": "application/json"}
    )
    report = json.loads(headers.get("x-lightcast-report", headers.get("X-Lightcast-Report", "{}")))
    img = np.frombuffer(body, "<f4").reshape(HEIGHT, WIDTH, 4)[..., :3].astype(np.float64)
    return img, report, time.time() - t


# ---------------------------------------------------------------------------------------------
# Mitsuba (in worker processes: a Python BSDF holds the GIL, so processes give the parallelism)

def mitsuba_bsdf(m):
    if m.builtin:
        assert m.metallic == 1.0 and tuple(m.base) == (1.0, 1.0, 1.0), "roughconductor is F = 1"
        return {
            "type": "roughconductor", "distribution": "ggx", "material": "none",
            "alpha": max(m.roughness, MIN_ROUGHNESS) ** 2,
        }
    return {
        "type": "lightcast", "r": m.base[0], "g": m.base[1], "b": m.base[2],
        "metallic": m.metallic, "roughness": m.roughness,
    }


def mitsuba_scene(mi, workdir, materials, light, depth, spp, seed):
    scene = {"type": "scene", "camera": ve.mitsuba_camera(mi, spp, seed)}
    for name in faces_by_part():
        scene[name] = {
            "type": "obj", "filename": os.path.join(workdir, name + ".obj"), "face_normals": True,
            "bsdf": mitsuba_bsdf(materials[name]),
        }
    scene["light"] = ve.mitsuba_light(light)
    scene["integrator"] = {"type": "path", "max_depth": depth, "rr_depth": 1000}
    return mi.load_dict(scene)


def direct_at_centres(mi, scene):
    """Radiance through each pixel's centre, one path each (exact for direct point light)."""
    sensor = scene.sensors()[0]
    sampler = sensor.sampler().clone()
    integrator = scene.integrator()
    img = np.zeros((HEIGHT, WIDTH, 3))
    for y in range(HEIGHT):
        for x in range(WIDTH):
            sampler.seed(y * WIDTH + x)
            ray, _ = sensor.sample_ray(
                0.0, 0.5, mi.Point2f((x + 0.5) / WIDTH, (y + 0.5) / HEIGHT), mi.Point2f(0.5, 0.5)
            )
            spec, _, _ = integrator.sample(scene, sampler, mi.RayDifferential3f(ray))
            img[y, x] = (spec[0], spec[1], spec[2])
    return img


def mitsuba_job(args):
    """One Mitsuba image: (workdir, materials, light, what ∈ {centres, render}, depth, spp,
    seed)."""
    workdir, materials, light, what, depth, spp, seed = args
    import drjit as dr
    import mitsuba as mi

    mi.set_variant("scalar_rgb")
    dr.set_thread_count(1)
    register_bsdf(mi)
    scene = mitsuba_scene(mi, workdir, materials, light, depth, spp, seed)
    if what == "centres":
        return direct_at_centres(mi, scene)
    return np.array(mi.render(scene, spp=spp, seed=seed), dtype=np.float64)[..., :3]


# ---------------------------------------------------------------------------------------------
# Comparison

def luminance(img):
    return img @ np.array([0.2126, 0.7152, 0.0722])


def shadow_edges(mits, surfaces):
    """Pixels whose 3×3 neighbourhood holds both lit and unlit pixels of `mits` on the same
    surface as theirs (`surfaces`: ids per pixel; geometric edges are interior_mask's)."""
    lit = mits.max(-1) > 0
    pad_lit = np.pad(lit, 1, mode="edge")
    pad_ids = np.pad(surfaces, 1, mode="edge")
    any_lit = np.zeros_like(lit)
    any_unlit = np.zeros_like(lit)
    for dy in range(3):
        for dx in range(3):
            same = pad_ids[dy:dy + HEIGHT, dx:dx + WIDTH] == surfaces
            neighbour = pad_lit[dy:dy + HEIGHT, dx:dx + WIDTH]
            any_lit |= same & neighbour
            any_unlit |= same & ~neighbour
    return any_lit & any_unlit


def direct_stats(ours, mits, mask, edge):
    """(a) over `mask` (see the module docstring)."""
    lit = mits.max(-1) > 0
    keep = mask & ~edge
    lit_keep = keep & lit
    y_o, y_m = luminance(ours), luminance(mits)
    per_pixel = np.abs(y_o[lit_keep] / y_m[lit_keep] - 1)
    lit_ours = y_o > 1e-6 * y_m.max()
    return {
        "pixels": int(mask.sum()), "shadow_edge_pixels": int((mask & edge).sum()),
        "lit_pixels": int(lit_keep.sum()),
        "mean_lightcast_lit": ours[lit_keep].mean(0).tolist(),
        "mean_mitsuba_lit": mits[lit_keep].mean(0).tolist(),
        "rel_diff_lit": (ours[lit_keep].mean(0) / mits[lit_keep].mean(0) - 1).tolist(),
        "rel_diff_all": (ours[keep].mean(0) / mits[keep].mean(0) - 1).tolist(),
        "rel_diff_all_with_edges": (ours[mask].mean(0) / mits[mask].mean(0) - 1).tolist(),
        "pixel_rel_diff_lum": {
            "median": float(np.median(per_pixel)), "p95": float(np.percentile(per_pixel, 95)),
            "max": float(per_pixel.max()),
        },
        "lit_in_lightcast_only": int((keep & lit_ours & ~lit).sum()),
        "lit_in_mitsuba_only": int((keep & lit & ~lit_ours).sum()),
    }


def print_direct_table(results):
    pct = lambda v: "/".join("%+.2f" % (100 * x) for x in v)  # noqa: E731
    print()
    print("| scene, surface | pixels (edges masked) | lit | mean lightcast, lit (RGB) | mean Mitsuba, lit (RGB) "
          "| mean diff %, lit (R/G/B) | mean diff %, all | mean diff %, all with edges "
          "| pixel luminance diff %, lit: median / p95 / max | lit in lightcast / Mitsuba only |")
    print("|---|---|---|---|---|---|---|---|---|---|")
    for name, r in results.items():
        p = r["pixel_rel_diff_lum"]
        print(
            "| %s | %d (%d) | %d | %s | %s | %s | %s | %s | %.2f / %.2f / %.2f | %d / %d |"
            % (
                name, r["pixels"], r["shadow_edge_pixels"], r["lit_pixels"],
                " ".join("%.4f" % x for x in r["mean_lightcast_lit"]),
                " ".join("%.4f" % x for x in r["mean_mitsuba_lit"]),
                pct(r["rel_diff_lit"]), pct(r["rel_diff_all"]), pct(r["rel_diff_all_with_edges"]),
                100 * p["median"], 100 * p["p95"], 100 * p["max"],
                r["lit_in_lightcast_only"], r["lit_in_mitsuba_only"],
            )
        )


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawTextHelpFormatter)
    ap.add_argument("--server", default="http://127.0.0.1:18181")
    ap.add_argument("--spp", type=int, default=256, help="Mitsuba samples per pixel (two halves)")
    ap.add_argument("--lightcast-spp", type=int, default=1024)
    ap.add_argument("--workers", type=int, default=os.cpu_count())
    ap.add_argument("--bounces", default="1,3")
    ap.add_argument("--scenes", default=",".join(SCENES), help="of " + ", ".join(SCENES))
    ap.add_argument("--shadow-map-size", type=int, default=2048, help="lightcast's (render.shadow_map_size)")
    ap.add_argument("--json", help="write the results here too")
    args = ap.parse_args()
    scenes = args.scenes.split(",")
    bounces = [int(b) for b in args.bounces.split(",")]

    workdir = tempfile.mkdtemp(prefix="lightcast-mitsuba-")
    try:
        for name, faces in faces_by_part().items():
            ve.write_obj(os.path.join(workdir, name + ".obj"), faces)
        scene_ids = {}
        for s in scenes:
            glb = os.path.join(workdir, s + ".glb")
            write_scene_glb(glb, SCENES[s])
            scene_ids[s] = ve.upload_scene(args.server, glb)
        print("scenes", scene_ids, flush=True)
        mask, surfaces = ve.interior_mask()

        # Mitsuba jobs: per scene the pixel centres' direct light, and per half (seed) the
        # direct light and each depth, which share the seed so that the direct light cancels.
        half = args.spp // 2
        jobs, keys = [], []
        for s in scenes:
            jobs.append((workdir, SCENES[s], light_of(s), "centres", 2, 1, 0))
            keys.append((s, "centres"))
            for h, seed in (("a", 1), ("b", 2)):
                for b in [0] + bounces:
                    jobs.append((workdir, SCENES[s], light_of(s), "render", b + 2, half, seed))
                    keys.append((s, h, b))
        t = time.time()
        pool = mp.get_context("spawn").Pool(args.workers)
        pending = pool.map_async(mitsuba_job, jobs)

        ours = {}
        for s in scenes:
            gis = [("direct", {"method": "none"}, "raw_final")] + [
                ("b%d" % b, {"method": "reference", "spp": args.lightcast_spp, "bounces": b},
                 "raw_indirect")
                for b in bounces
            ]
            for what, gi, fmt in gis:
                img, report, secs = render_lightcast(
                    args.server, scene_ids[s], light_of(s), gi, fmt, args.shadow_map_size
                )
                ours[(s, what)] = img
                print("lightcast %s %s: %.1f s, report %s"
                      % (s, what, secs, json.dumps(report)[:400]), flush=True)
        imgs = dict(zip(keys, pending.get()))
        pool.close()
        print("mitsuba: %.1f s for %d images" % (time.time() - t, len(jobs)), flush=True)

        regions = {"all": mask, "ground": mask & (surfaces == 0), "box": mask & (surfaces > 0)}
        direct, reference = {}, {}
        for s in scenes:
            mits = imgs[(s, "centres")]
            edge = shadow_edges(mits, surfaces)
            for region, m in regions.items():
                direct["%s %s" % (s, region)] = direct_stats(ours[(s, "direct")], mits, m, edge)
            np.save(os.path.join(workdir, s + "-direct.ours.npy"), ours[(s, "direct")])
            np.save(os.path.join(workdir, s + "-direct.mitsuba.npy"), mits)
            for b in bounces:
                name = "%s-b%d" % (s, b)
                halves = [imgs[(s, h, b)] - imgs[(s, h, 0)] for h in "ab"]
                for region, m in regions.items():
                    reference["%s %s" % (name, region)] = ve.stats(
                        ours[(s, "b%d" % b)], halves[0], halves[1], m, args.lightcast_spp, args.spp
                    )
                np.save(os.path.join(workdir, name + ".ours.npy"), ours[(s, "b%d" % b)])
                np.save(os.path.join(workdir, name + ".mitsuba.npy"), 0.5 * (halves[0] + halves[1]))
        results = {"direct": direct, "reference": reference}
        print(json.dumps(results, indent=1))
        print("\nDirect light (lightcast gi none, raw_final, against Mitsuba at the pixel centres):")
        print_direct_table(direct)
        print("\nReference (raw_indirect against Mitsuba max_depth B+2 − max_depth 2):")
        ve.print_table(reference, args)
        if args.json:
            with open(args.json, "w") as f:
                json.dump({"args": vars(args), "lights": {s: light_of(s) for s in scenes},
                           "results": results}, f, indent=1)
    finally:
        if os.environ.get("KEEP_WORKDIR"):
            print("kept", workdir)
        else:
            shutil.rmtree(workdir, ignore_errors=True)


if __name__ == "__main__":
    main()
