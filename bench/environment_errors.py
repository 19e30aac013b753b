#!/usr/bin/env python3
"""Every GI method's indirect-light error against the path-traced reference with and without
an environment (issue 33, part 3): the Cornell box under a uniform sky (it has no directional
light for a daylight sky; its open front lets the sky in) and the procedural street under the
daylight sky around its sun, each method at the server's default settings for its adapter,
one-shot renders with `compare_to: reference`. Loopback only, standard library only.

    cargo build --release -p lightcast-server
    python3 bench/environment_errors.py target/release/lightcast-server \\
        [--width 128 --height 96 --spp 256] > bench/results/lavapipe-environment-errors.md

The reference's indirect buffer holds the sky's direct light on the visible surfaces; a
real-time method's frame reports its indirect light plus its sky directions' direct light,
so both sides hold the same light. Errors are the comparison's 8×8-block MAE over the
reference's mean and its bias. Times are left out: one-shot renders time a method's first
frame on the scene, and lavapipe's timestamps under-report some stages (`bench` measures
time).
"""

import argparse
import json
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


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("server", help="path to lightcast-server")
    ap.add_argument("--width", type=int, default=128)
    ap.add_argument("--height", type=int, default=96)
    ap.add_argument("--spp", type=int, default=256, help="reference samples per pixel")
    ap.add_argument("--street", default="street?blocks=4")
    args = ap.parse_args()

    port = free_port()
    base = f"http://127.0.0.1:{port}"
    server = subprocess.Popen(
        [args.server, "--listen", f"127.0.0.1:{port}", "--allow-cpu-adapter",
         "--max-request-cost", "3600", "--max-frame-cost", "600"],
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
        _, body = request(base + "/v1/scenes", {"procedural": args.street})
        street = json.loads(body)["id"]
        cases = [
            ("Cornell box", "default", {"kind": "uniform", "intensity": 1.0}),
            (f"street ({args.street})", street, {"kind": "sky"}),
        ]
        rows = []
        for label, scene, environment in cases:
            for method in methods:
                cells = []
                for env in (None, environment):
                    render = {"scene": scene, "width": args.width, "height": args.height,
                              "environment": env, "gi": {"method": method}}
                    started = time.time()
                    try:
                        headers, _ = request(base + "/v1/render", {
                            "render": render, "format": "png",
                            "compare_to": "reference", "compare_spp": args.spp})
                    except urllib.error.HTTPError as e:
                        cells.append(f"refused: {e.read().decode()[:120]}")
                        continue
                    report = json.loads(headers["x-lightcast-report"])
                    c = report["comparison"]
                    cells.append(
                        f"{100 * c['indirect_block_mae_relative']:.1f} % / "
                        f"{100 * c['indirect_bias_relative']:+.1f} %")
                    print(f"{label} {method} env={env is not None}: {cells[-1]} "
                          f"[{time.time() - started:.0f} s]", file=sys.stderr)
                rows.append((label, method, *cells))
        print(f"Adapter: {info.get('adapter', '?')}; {args.width}×{args.height}; reference "
              f"{args.spp} spp; each method at the server's defaults for the adapter "
              f"(`/v1/server` `defaults`), environment `directions` 8.\n")
        print("| scene | method | no environment: 8×8-block error / bias "
              "| with environment |")
        print("|---|---|---|---|")
        for label, method, a, b in rows:
            env = "uniform 1" if label.startswith("Cornell") else "sky (0.2 × sun)"
            print(f"| {label} | `{method}` | {a} | {b} ({env}) |")
    finally:
        server.terminate()
        server.wait(timeout=30)


if __name__ == "__main__":
    main()
