#!/usr/bin/env python3
"""What the costliest legal requests cost (issue 30, part 2): every GI parameter at its
documented maximum (or, for `interleave`, its cheapest-looking minimum), one at a time and all
at once per method, on the default scene (the Cornell box) at the largest legal frame, sent as
one-shot renders while another client streams. Loopback only, standard library only.

    cargo build --release -p lightcast-server -p lightcast-client
    python3 bench/hostile_cost.py target/release/lightcast-server target/release/lightcast \\
        [--width 3840 --height 2160] > bench/hostile-cost.md

For every request: its estimated cost (from the refusal, or the render's report), whether the
server refused it (and the field it named) or rendered it, the request's wall time, and the
longest gap between the streaming client's frames while it ran (`lightcast stream --json`).
The server runs with its default limits on whatever adapter it finds (`--allow-cpu-adapter`).
"""

import argparse
import json
import re
import socket
import subprocess
import sys
import threading
import time
import urllib.error
import urllib.request

# Parameters whose cheapest setting is their largest value: the costliest is their minimum.
CHEAPER_WHEN_LARGER = {"interleave", "indirect_downscale", "surfel_cache_spacing"}
# Parameters that are not costs (weights, thresholds, choices, views).
NOT_COSTS = {"defensive", "cluster_position_weight", "cluster_normal_weight", "blur_distance",
             "blur_normal", "shadow_light", "glossy_exponent", "cache_distance", "cache_angle",
             "emitters", "occlusion", "jitter"}


def free_port():
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def get(base, path):
    with urllib.request.urlopen(base + path, timeout=60) as r:
        return json.load(r)


def post(base, body, timeout):
    request = urllib.request.Request(base + "/v1/render", data=json.dumps(body).encode(),
                                     headers={"content-type": "application/json"})
    started = time.time()
    try:
        with urllib.request.urlopen(request, timeout=timeout) as r:
            r.read()
            report = json.loads(r.headers["x-lightcast-report"])
            return time.time() - started, 200, report.get("estimated_seconds"), None
    except urllib.error.HTTPError as e:
        body = json.loads(e.read() or b"{}")
        message = body.get("message", "")
        m = re.search(r"estimated at ([0-9.]+) s", message)
        return (time.time() - started, e.code, float(m.group(1)) if m else None,
                f"{body.get('field') or body.get('error')}")


def cases(server):
    """(method, label, gi) for every cost parameter at its costliest, then all of them."""
    out = []
    for method in server["gi_methods"]:
        name = method["method"]
        costliest = {}
        for p in method["parameters"]:
            if p["name"] in NOT_COSTS or p["kind"] not in ("integer", "number"):
                continue
            value = p["min"] if p["name"] in CHEAPER_WHEN_LARGER else p["max"]
            if value is None:
                continue
            if p["kind"] == "integer":
                value = int(value)
            costliest[p["name"]] = value
            out.append((name, f"{p['name']} {value}", {"method": name, p["name"]: value}))
        if costliest:
            out.append((name, "all of the above", {"method": name, **costliest}))
        if name == "clustered":
            out.append((name, "all, visibility vpl_shadows",
                        {"method": name, **costliest, "visibility": "vpl_shadows",
                         "paraboloid_size": 32}))
    return out


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("server_binary")
    ap.add_argument("client_binary")
    ap.add_argument("--width", type=int, default=3840)
    ap.add_argument("--height", type=int, default=2160)
    args = ap.parse_args()

    port = free_port()
    base = f"http://127.0.0.1:{port}"
    server = subprocess.Popen([args.server_binary, "serve", "--allow-cpu-adapter",
                               "--listen", f"127.0.0.1:{port}"],
                              stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    try:
        for _ in range(600):
            try:
                get(base, "/healthz")
                break
            except OSError:
                time.sleep(0.5)
        info = get(base, "/v1/server")
        limits = info["limits"]
        print(f"# Costliest legal requests ({time.strftime('%Y-%m-%d')})\n")
        print(f"Adapter: {info['adapter']}. Limits: `--max-request-cost` "
              f"{limits['max_request_seconds']} s at `--adapter-speed` {limits['adapter_speed']}, "
              f"`--max-precompute-cost` {limits['max_precompute_seconds']} s. Frame "
              f"{args.width}×{args.height} on the default scene; the other fields at the "
              f"server's defaults ({info['defaults']['profile']} profile). A second client "
              f"streams 320×240 direct-light frames at up to 30 fps meanwhile.\n")
        print("Command: `python3 bench/hostile_cost.py target/release/lightcast-server "
              f"target/release/lightcast --width {args.width} --height {args.height}`\n")
        # Each method's first render also builds its pipelines (and precomputation): done
        # here, so that the wall times below are the requests' own.
        for method in info["gi_methods"]:
            post(base, {"render": {"width": 32, "height": 32,
                                   "gi": {"method": method["method"]}}}, timeout=900)
        print("Each method rendered once at 32×32 before (its pipelines and precomputation "
              "built); a second client's stream runs during every request, so the wall times "
              "include sharing the 2 cores with it.\n")
        print("| method | request | estimated (s) | answer | wall time (s) | longest stream gap (ms) |")
        print("|---|---|---|---|---|---|")
        for method, label, gi in cases(info):
            body = {"render": {"width": args.width, "height": args.height, "gi": gi}}
            # The stream covers the request: long enough for an accepted one to finish.
            window = 4.0
            stream = subprocess.Popen(
                [args.client_binary, "--server", base, "--json", "stream", "--duration", "600",
                 "--width", "320", "--height", "240", "--gi", "none", "--fps-cap", "30"],
                stdout=subprocess.PIPE, stderr=subprocess.DEVNULL)
            time.sleep(1.5)
            result = {}

            def run():
                result["answer"] = post(base, body, timeout=900)

            worker = threading.Thread(target=run)
            worker.start()
            worker.join()
            time.sleep(window / 2)
            stream.send_signal(2)
            try:
                out, _ = stream.communicate(timeout=30)
                gap = json.loads(out).get("longest_gap_ms") if out else None
            except (subprocess.TimeoutExpired, json.JSONDecodeError):
                stream.kill()
                gap = None
            wall, status, estimated, field = result["answer"]
            answer = "rendered" if status == 200 else f"{status} `{field}`"
            est = f"{estimated:.2f}" if estimated is not None else "–"
            gap_text = f"{gap:.0f}" if gap is not None else "–"
            print(f"| {method} | {label} | {est} | {answer} | {wall:.2f} | {gap_text} |",
                  flush=True)
    finally:
        server.terminate()
        server.wait(timeout=30)


if __name__ == "__main__":
    sys.exit(main())
