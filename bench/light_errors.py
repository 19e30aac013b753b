#!/usr/bin/env python3
"""Every GI method's indirect-light error against the path-traced reference under the lights
issue 33 adds, each method at the server's default settings for its adapter, one-shot renders
with `compare_to: reference`. Loopback only, standard library only.

    cargo build --release -p lightcast-server
    python3 bench/light_errors.py target/release/lightcast-server --case environment \\
        [--width 128 --height 96 --spp 256] > bench/results/lavapipe-environment-errors.md
    python3 bench/light_errors.py target/release/lightcast-server --case three-lights \\
        > bench/results/lavapipe-three-lights-errors.md
    python3 bench/light_errors.py target/release/lightcast-server --case emitters --spp 1024 \\
        > bench/results/lavapipe-emitters-errors.md
    python3 bench/light_errors.py target/release/lightcast-server --case street --spp 1024 \\
        --width 128 --height 72 > bench/results/lavapipe-street-truth.md
    python3 bench/light_errors.py target/release/lightcast-server --case street --spp 1024 \\
        --width 128 --height 72 --materials authored --senders full,diffuse \\
        > bench/results/lavapipe-street-glossy-senders.md
    python3 bench/light_errors.py target/release/lightcast-server --case street --spp 1024 \\
        --width 128 --height 72 --materials authored --senders full,diffuse --receivers \\
        > bench/results/lavapipe-street-receivers.md
    python3 bench/light_errors.py target/release/lightcast-server --case street-motion \\
        --width 128 --height 72 --spp 512 > bench/results/lavapipe-street-motion.md
    python3 bench/light_errors.py target/release/lightcast-server --case moving \\
        --width 128 --height 96 --spp 256 > bench/results/lavapipe-moving-box.md

`environment` (part 3): with and without an environment, the Cornell box under a uniform sky
(it has no directional light for a daylight sky; its open front lets the sky in) and the
procedural street under the daylight sky around its sun. The reference's indirect buffer holds
the sky's direct light on the visible surfaces; a real-time method's frame reports its
indirect light plus its sky directions' direct light, so both sides hold the same light.

`emitters` (part 4): frames without punctual lights (`lights: []`), lit by the scene's emissive
surfaces alone (`emitters`, on by default without the stand-in light): the built-in Cornell
box (its lamp a bare quad 5 mm under the ceiling) and `tests/data/cornell-box/cornell-box.glb`
(its lamp a thin closed box), each method against the reference from the same emitters. The
reference's own noise (`reference_relative_error`, its estimate of its relative error) is
given per scene: emitters are small, bright and found by bounce rays only.

`street` (issue 34): the street as authored (glass and steel façades, glossy signs) and with
every surface Lambertian (`materials=diffuse`), under its own sun from its own camera (down the
middle street) and from the same camera one street over (60 m along x), each method against
the full reference and (`compare_modelled`) against the reference of the light transport it
models (diffuse senders, where a method has them): on the diffuse street the two are one; the RSM-based methods with
the sun's maps over the whole scene (`light_fit: scene`) and fitted to the view (`view`), and
(`--senders`) with each value of `senders` for the methods that have it: `full`, the default,
sends an RSM texel's glossy lobe on, `diffuse` is the papers' diffuse VALs and VPLs; with
`--receivers` every cell is also split into diffuse and specular receivers (`comparison.receivers`).

`street-motion` (issue 34): how much each method's indirect light changes between frames while
the camera moves sideways down the middle of the Lambertian street (four frames 13 cm apart),
the mean absolute change of a pixel between consecutive frames over the mean, with the sun's
maps over the scene and fitted to the view: a fitted map that slid under the VPLs would make
them flicker. The reference's change (at `--spp`) includes its own noise.

`moving` (issue 35): the Cornell box's short box slid in steps along −x at its fixed light,
one one-shot render per pose (`render.nodes`): each method's error against the reference of
each pose (at rest, and the mean over the path), how much its indirect light changes from
pose to pose over its mean against the reference's change (which includes its own noise),
and its GI time per frame (the report's stages other than the shared ones) at rest and
moving. A method that does not follow moved nodes shows its refusal.

`three-lights` (part 2): the Cornell box lit by three lights of different kinds (its ceiling
spot, a point light low in a back corner, a sun through the open front), each alone and all
together: the single-light errors are the band the three-light error is held against. Errors are the comparison's 8×8-block MAE over the
reference's mean and its bias. Times are left out: one-shot renders time a method's first
frame on the scene, and lavapipe's timestamps under-report some stages (`bench` measures
time).
"""

import argparse
import json
import os
import socket
import subprocess
import sys
import time
import urllib.error
import urllib.request

SKIPPED = {"none", "reference"}


def free_port():
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def request(url, body=None, method=None):
    data = None if body is None else json.dumps(body).encode()
    req = urllib.request.Request(url, data=data, method=method)
    req.add_header("content-type", "application/json")
    with urllib.request.urlopen(req, timeout=3600) as resp:
        return resp.headers, resp.read()


def cell_of(c):
    """A comparison as "block error / bias"."""
    return (f"{100 * c['indirect_block_mae_relative']:.1f} % / "
            f"{100 * c['indirect_bias_relative']:+.1f} %")


def with_receivers(c):
    """`cell_of` and the same on diffuse and on specular receivers, each with its share of
    the reference's light."""
    kinds = [f"{kind} ({100 * r['reference_share']:.0f} % of the light) {cell_of(r)}"
             for kind, r in c["receivers"].items()]
    return f"{cell_of(c)}; " + "; ".join(kinds)


def compare(base, render, spp, what, noise=False, modelled=False, cell_of=cell_of):
    """`render` compared with the reference: "block error / bias" (and, with `noise`, the
    reference's own estimated per-pixel error in parentheses), or why it was refused. With
    `modelled`, a pair: that and the same against the reference of the transport the method
    models ("-" where it models the full one). `cell_of` formats a comparison."""
    started = time.time()
    body = {"render": render, "format": "png", "compare_to": "reference", "compare_spp": spp}
    if modelled:
        body["compare_modelled"] = True
    try:
        headers, _ = request(base + "/v1/render", body)
    except urllib.error.HTTPError as e:
        refused = f"refused: {e.read().decode()[:120]}"
        return (refused, refused) if modelled else refused
    report = json.loads(headers["x-lightcast-report"])
    c = report["comparison"]
    cell = cell_of(c)
    if noise:
        cell += f" ({100 * c['reference_relative_error']:.0f} %)"
    print(f"{what}: {cell} [{time.time() - started:.0f} s]", file=sys.stderr)
    if modelled:
        m = report.get("comparison_modelled")
        return cell, cell_of(m) if m else "-"
    return cell


def environment_case(base, args, methods):
    _, body = request(base + "/v1/scenes", {"procedural": args.street})
    street = json.loads(body)["id"]
    cases = [
        ("Cornell box", "default", {"kind": "uniform", "intensity": 1.0}, "uniform 1"),
        (f"street ({args.street})", street, {"kind": "sky"}, "sky (0.2 × sun)"),
    ]
    print("| scene | method | no environment: 8×8-block error / bias "
          "| with environment |")
    print("|---|---|---|---|")
    for label, scene, environment, name in cases:
        for method in methods:
            cells = [compare(base, {"scene": scene, "width": args.width, "height": args.height,
                                    "environment": env, "gi": {"method": method}},
                             args.spp, f"{label} {method} environment {env is not None}")
                     for env in (None, environment)]
            print(f"| {label} | `{method}` | {cells[0]} | {cells[1]} ({name}) |")


def emitters_case(base, args, methods):
    glb = os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "tests", "data",
                       "cornell-box", "cornell-box.glb")
    with open(glb, "rb") as f:
        req = urllib.request.Request(base + "/v1/scenes", data=f.read(), method="POST")
    req.add_header("content-type", "model/gltf-binary")
    with urllib.request.urlopen(req, timeout=600) as resp:
        uploaded = json.loads(resp.read())["id"]
    print("| scene | method | 8×8-block error / bias (reference noise) |")
    print("|---|---|---|")
    for label, scene in (("Cornell box (built-in)", "default"), ("cornell-box.glb", uploaded)):
        for method in methods:
            cell = compare(base, {"scene": scene, "width": args.width, "height": args.height,
                                  "lights": [], "gi": {"method": method}},
                           args.spp, f"{label} {method}", noise=True)
            print(f"| {label} | `{method}` | {cell} |")


def three_lights_case(base, args, methods):
    scene = json.loads(request(base + "/v1/scenes/default")[1])
    spot = scene["default_light"]
    lo, hi = scene["bounds"]["min"], scene["bounds"]["max"]
    size = [h - l for l, h in zip(lo, hi)]
    camera = scene["default_camera"]
    # Low in the back corner, away from the camera, facing the room.
    view = [t - p for p, t in zip(camera["position"], camera["target"])]
    back = [l + 0.25 * s if v < 0 else h - 0.25 * s for l, h, s, v in zip(lo, hi, size, view)]
    back[1] = lo[1] + 0.3 * size[1]
    point = dict(spot, kind="point", position=back, intensity=spot["intensity"] * 0.5)
    # A sun from over the camera's shoulder, in through the open front and down.
    length = sum(v * v for v in view) ** 0.5
    sun_dir = [v / length for v in view]
    sun_dir[1] -= 0.6
    sun = dict(spot, kind="directional", direction=sun_dir, intensity=spot["intensity"] * 0.02,
               color=[1.0, 0.9, 0.75])
    setups = [("spot", [spot]), ("point", [point]), ("sun", [sun]),
              ("all three", [spot, point, sun])]
    print("| method | " + " | ".join(name for name, _ in setups) + " |")
    print("|---|" + "---|" * len(setups))
    for method in methods:
        cells = [compare(base, {"width": args.width, "height": args.height, "lights": lights,
                                "gi": {"method": method}}, args.spp, f"{method} {name}")
                 for name, lights in setups]
        print(f"| `{method}` | " + " | ".join(cells) + " |")
    print()
    print("Lights (`render.lights`):\n")
    for name, light in zip(("spot", "point", "sun"), (spot, point, sun)):
        print(f"- {name}: `{json.dumps(light)}`")


# The street's blocks repeat every 60 m (`scene::procedural`'s PITCH).
STREET_PITCH = 60.0


def values_to_try(info, method, name, values):
    """`values` of parameter `name` to try for `method` ([None] where it has no such
    parameter)."""
    m = next(m for m in info["gi_methods"] if m["method"] == method)
    return values if any(p["name"] == name for p in m["parameters"]) else [None]


def moved(camera, dx):
    """`camera` moved `dx` metres along x."""
    return dict(camera, position=[camera["position"][0] + dx] + camera["position"][1:],
                target=[camera["target"][0] + dx] + camera["target"][1:])


def street_configs_case(base, args):
    """`--case street --gi-configs`: the given `render.gi` objects on the streets."""
    print("| street | view | `render.gi` | against the reference |\n|---|---|---|---|")
    for materials in args.materials.split(","):
        spec = f"{args.street}&materials={materials}"
        entry = json.loads(request(base + "/v1/scenes", {"procedural": spec})[1])
        own = entry["default_camera"]
        for view, camera in [("down its middle street", own),
                             ("one street over", moved(own, STREET_PITCH))]:
            for gi in json.loads(args.gi_configs):
                render = {"scene": entry["id"], "width": args.width, "height": args.height,
                          "camera": camera, "gi": gi}
                cell = compare(base, render, args.spp, f"{materials} {view} {gi}",
                               cell_of=with_receivers if args.receivers else cell_of)
                print(f"| {materials} | {view} | `{json.dumps(gi)}` | {cell} |", flush=True)


def street_case(base, args, methods, info):
    if args.gi_configs:
        street_configs_case(base, args)
        return
    cell = with_receivers if args.receivers else cell_of
    print("| street | view | method | sun's maps (`light_fit`) | `senders` | against the "
          "reference | against the reference of the transport it models |\n"
          "|---|---|---|---|---|---|---|")
    for materials in args.materials.split(","):
        spec = f"{args.street}&materials={materials}"
        _, body = request(base + "/v1/scenes", {"procedural": spec})
        entry = json.loads(body)
        own = entry["default_camera"]
        over = moved(own, STREET_PITCH)
        for view, camera in [("down its middle street", own), ("one street over", over)]:
            for method in methods:
                for fit in values_to_try(info, method, "light_fit", ["scene", "view"]):
                    for senders in values_to_try(info, method, "senders", args.senders.split(",")):
                        gi = {"method": method}
                        if fit:
                            gi["light_fit"] = fit
                        if senders:
                            gi["senders"] = senders
                        render = {"scene": entry["id"], "width": args.width,
                                  "height": args.height, "camera": camera, "gi": gi}
                        full, modelled = compare(base, render, args.spp,
                                                 f"{materials} {view} {method} {fit} {senders}",
                                                 modelled=True, cell_of=cell)
                        print(f"| {materials} | {view} | `{method}` | {fit or '-'} | "
                              f"{senders or '-'} | {full} | {modelled} |", flush=True)


def street_motion_case(base, args, methods, info):
    import numpy as np

    _, body = request(base + "/v1/scenes", {"procedural": f"{args.street}&materials=diffuse"})
    entry = json.loads(body)
    own = entry["default_camera"]

    def frames(gi):
        images = []
        for step in range(4):
            camera = moved(own, 0.13 * step)
            _, raw = request(base + "/v1/render", {
                "render": {"scene": entry["id"], "width": args.width, "height": args.height,
                           "camera": camera, "gi": gi}, "format": "raw_indirect"})
            images.append(np.frombuffer(raw, "<f4").reshape(-1, 4)[:, :3].astype(np.float64))
        change = np.mean([np.abs(b - a).mean() for a, b in zip(images, images[1:])])
        return f"{100 * change / np.mean([i.mean() for i in images]):.2f} %"

    print("| method | sun's maps (`light_fit`) | change between frames / mean |\n|---|---|---|")
    reference = {"method": "reference", "spp": args.spp}
    print(f"| `reference` ({args.spp} spp) | - | {frames(reference)} |")
    for method in methods:
        for fit in values_to_try(info, method, "light_fit", ["scene", "view"]):
            gi = {"method": method}
            if fit:
                gi["light_fit"] = fit
            print(f"| `{method}` | {fit or '-'} | {frames(gi)} |", flush=True)


# The stages every frame runs whatever its GI method (`passes::stages`): the rest is GI time.
SHARED_STAGES = {"shadow_map", "gbuffer", "direct_light", "exposure", "tonemap",
                 "readback_copy", "yuv420"}


def moving_case(base, args, methods, info):
    """`--case moving` (issue 35): the Cornell box's short box slid along a path at a fixed
    light, one one-shot render per pose."""
    import numpy as np

    scene = json.loads(request(base + "/v1/scenes/default")[1])
    box = next(n for n in scene["nodes"] if n["name"] == "short box")
    lo, hi = box["bounds"]["min"], box["bounds"]["max"]
    centre = [(a + b) / 2 for a, b in zip(lo, hi)]
    path = [[centre[0] - args.step * i, 0.0, centre[2]] for i in range(args.steps)]

    def run(gi, pose):
        """(indirect light, GI ms, comparison) of `gi` with the box at `pose` (None: at
        rest), or the refusal."""
        render = {"width": args.width, "height": args.height, "gi": gi}
        if pose is not None:
            render["nodes"] = [{"node": box["id"], "translation": pose}]
        body = {"render": render, "format": "raw_indirect"}
        if gi["method"] != "reference":
            body.update({"compare_to": "reference", "compare_spp": args.spp})
        try:
            headers, raw = request(base + "/v1/render", body)
        except urllib.error.HTTPError as e:
            return None, None, f"refused: {json.loads(e.read()).get('message', '')[:100]}"
        report = json.loads(headers["x-lightcast-report"])
        gi_ms = sum(s["ms"] for s in report["stages"] if s["stage"] not in SHARED_STAGES)
        image = np.frombuffer(raw, "<f4").reshape(-1, 4)[:, :3].astype(np.float64)
        return image, gi_ms, report.get("comparison")

    def change(images):
        steps = [np.abs(b - a).mean() for a, b in zip(images, images[1:])]
        return 100 * np.mean(steps) / np.mean([i.mean() for i in images])

    print(f"The short box ({box['id']}) slid {args.steps - 1} × {100 * args.step:.0f} cm along "
          f"−x from its place; reference {args.spp} spp per pose.\n")
    print("| method | error at rest (8×8-block / bias) | error moving, mean over the path | "
          "change between poses / mean | reference's change | GI ms at rest (median) | GI ms "
          "moving (median) |\n|---|---|---|---|---|---|---|")
    reference = {"method": "reference", "spp": args.spp}
    ref_images = [run(reference, p)[0] for p in path]
    ref_change = f"{change(ref_images):.2f} %"
    for method in methods:
        gi = {"method": method}
        rest_image, rest_ms, rest_c = run(gi, None)
        if rest_image is None:
            print(f"| `{method}` | {rest_c} | | | | | |", flush=True)
            continue
        # As many renders at rest as moving, so both medians have the same spread.
        rest_ms = np.median([rest_ms] + [run(gi, None)[1] for _ in path[1:]])
        moving = [run(gi, p) for p in path]
        if moving[0][0] is None:
            print(f"| `{method}` | {cell_of(rest_c)} | {moving[0][2]} | | | | |", flush=True)
            continue
        block = np.mean([c["indirect_block_mae_relative"] for _, _, c in moving])
        bias = np.mean([c["indirect_bias_relative"] for _, _, c in moving])
        print(f"| `{method}` | {cell_of(rest_c)} | {100 * block:.1f} % / {100 * bias:+.1f} % | "
              f"{change([m[0] for m in moving]):.2f} % | {ref_change} | {rest_ms:.2f} | "
              f"{np.median([m[1] for m in moving]):.2f} |", flush=True)


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("server", help="path to lightcast-server")
    ap.add_argument("--case", choices=["environment", "emitters", "three-lights", "street",
                                       "street-motion", "moving"],
                    default="environment")
    ap.add_argument("--width", type=int, default=128)
    ap.add_argument("--height", type=int, default=96)
    ap.add_argument("--spp", type=int, default=256, help="reference samples per pixel")
    # `cars=0`: the street as it was before its parked car (issue 35), which the results in
    # bench/results were measured on.
    ap.add_argument("--street", default="street?blocks=4&cars=0")
    ap.add_argument("--materials", default="authored,diffuse",
                    help="street: the streets' `materials`, comma-separated")
    ap.add_argument("--gi-configs",
                    help="street: a JSON list of `render.gi` objects to compare instead of "
                         "every method at its defaults")
    ap.add_argument("--receivers", action="store_true",
                    help="street: each cell also split into diffuse and specular receivers "
                         "(`comparison.receivers`)")
    ap.add_argument("--steps", type=int, default=6, help="moving: poses along the path")
    ap.add_argument("--step", type=float, default=0.05,
                    help="moving: metres between poses")
    ap.add_argument("--senders", default="full",
                    help="street: the `senders` values of the RSM-based methods, comma-separated")
    args = ap.parse_args()

    port = free_port()
    base = f"http://127.0.0.1:{port}"
    server = subprocess.Popen(
        [args.server, "--listen", f"127.0.0.1:{port}", "--allow-cpu-adapter",
         "--max-request-cost", "3600", "--max-frame-cost", "600",
         "--max-spp", str(max(args.spp, 256)), "--max-scenes", "8"],
        stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    try:
        for _ in range(600):
            try:
                request(base + "/healthz")
                break
            except (urllib.error.URLError, ConnectionError):
                time.sleep(0.5)
        info = json.loads(request(base + "/v1/server")[1])
        methods = [m["method"] for m in info["gi_methods"] if m["method"] not in SKIPPED]
        print(f"Adapter: {info.get('adapter', '?')}; {args.width}×{args.height}; reference "
              f"{args.spp} spp; each method at the server's defaults for the adapter "
              f"(`/v1/server` `defaults`)"
              + ("." if args.case == "street-motion"
                 else "; cells: 8×8-block error / bias against the reference.") + "\n")
        if args.case == "environment":
            environment_case(base, args, methods)
        elif args.case == "emitters":
            emitters_case(base, args, methods)
        elif args.case == "street":
            street_case(base, args, methods, info)
        elif args.case == "street-motion":
            street_motion_case(base, args, methods, info)
        elif args.case == "moving":
            moving_case(base, args, methods, info)
        else:
            three_lights_case(base, args, methods)
    finally:
        server.terminate()
        server.wait(timeout=30)


if __name__ == "__main__":
    main()
