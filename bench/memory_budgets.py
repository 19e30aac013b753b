#!/usr/bin/env python3
"""Resident memory of a server under its memory budgets: after the worst legal scene upload and
after 16 of them (issue 15, section 2). Loopback only, standard library only.

The worst legal upload under the default limits: a grid of TRIANGLES triangles (default: the
10 M of --max-triangles, indexed, ~180 MB of .glb) textured with 16 solid 4096² PNGs (each
kept at 2048², 16 MiB: 256 MiB decoded, --max-scene-texture-bytes), under the 256 MiB
--max-upload-bytes. Each upload waits for its light caches before the next.

    cargo build -p lightcast-server
    python3 bench/memory_budgets.py target/debug/lightcast-server [TRIANGLES] > table.md

Prints a Markdown table: VmRSS of the server at start, after each upload (accepted or refused
with which error) and after the 16th, with the server's budgets as /v1/server reports them.
"""

import array
import json
import os
import socket
import struct
import subprocess
import sys
import tempfile
import time
import urllib.error
import urllib.request
import zlib

UPLOADS = 16
IMAGES = 16
IMAGE_SIDE = 4096


def png_solid(side):
    """A solid RGBA PNG: tens of kilobytes that decode to 4·side² bytes."""

    def chunk(kind, data):
        body = kind + data
        return struct.pack(">I", len(data)) + body + struct.pack(">I", zlib.crc32(body))

    row = b"\x00" + bytes([180, 120, 60, 255]) * side
    raw = zlib.compress(row * side, 9)
    header = struct.pack(">IIBBBBB", side, side, 8, 6, 0, 0, 0)
    return b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", header) + chunk(b"IDAT", raw) + chunk(b"IEND", b"")


def grid_glb(triangles, png):
    """A square grid of about `triangles` triangles in the XZ plane, IMAGES materials each
    with its own image of the same PNG bytes, as one indexed primitive per material."""
    cells = max(1, int((triangles / 2) ** 0.5))
    n = cells + 1
    positions = array.array("f")
    uvs = array.array("f")
    for j in range(n):
        for i in range(n):
            positions.extend((i / cells * 10.0, 0.0, j / cells * 10.0))
            uvs.extend((i / cells, j / cells))
    # Rows of cells split evenly between the materials.
    indices = [array.array("I") for _ in range(IMAGES)]
    for j in range(cells):
        out = indices[j * IMAGES // cells]
        for i in range(cells):
            a = j * n + i
            out.extend((a, a + n, a + 1, a + 1, a + n, a + n + 1))
    blobs = [positions.tobytes(), uvs.tobytes()] + [ix.tobytes() for ix in indices] + [png]
    views, offset = [], 0
    for blob in blobs:
        views.append({"buffer": 0, "byteOffset": offset, "byteLength": len(blob)})
        offset += (len(blob) + 3) // 4 * 4
    accessors = [
        {"bufferView": 0, "componentType": 5126, "type": "VEC3", "count": n * n,
         "min": [0, 0, 0], "max": [10, 0, 10]},
        {"bufferView": 1, "componentType": 5126, "type": "VEC2", "count": n * n},
    ] + [
        {"bufferView": 2 + k, "componentType": 5125, "type": "SCALAR", "count": len(ix)}
        for k, ix in enumerate(indices) if len(ix)
    ]
    used = [k for k, ix in enumerate(indices) if len(ix)]
    primitives = [
        {"attributes": {"POSITION": 0, "TEXCOORD_0": 1}, "indices": 2 + a, "material": k}
        for a, k in enumerate(used)
    ]
    image_view = len(blobs) - 1
    doc = {
        "asset": {"version": "2.0"},
        "buffers": [{"byteLength": offset}],
        "bufferViews": views,
        "accessors": accessors,
        "images": [{"bufferView": image_view, "mimeType": "image/png"} for _ in range(IMAGES)],
        "textures": [{"source": k} for k in range(IMAGES)],
        "materials": [{"pbrMetallicRoughness": {"baseColorTexture": {"index": k}}}
                      for k in range(IMAGES)],
        "meshes": [{"primitives": primitives}],
        "nodes": [{"mesh": 0}],
    }
    js = json.dumps(doc).encode()
    js += b" " * (-len(js) % 4)
    binary = b"".join(blob + b"\x00" * (-len(blob) % 4) for blob in blobs)
    body = (struct.pack("<I", len(js)) + b"JSON" + js
            + struct.pack("<I", len(binary)) + b"BIN\x00" + binary)
    return b"glTF" + struct.pack("<II", 2, 12 + len(body)) + body, 2 * cells * cells


def rss_mib(pid):
    with open(f"/proc/{pid}/status") as f:
        for line in f:
            if line.startswith("VmRSS:"):
                return int(line.split()[1]) / 1024
    return float("nan")


def request(base, method, path, body=None, content_type=None, timeout=600):
    req = urllib.request.Request(base + path, data=body, method=method)
    if content_type:
        req.add_header("Content-Type", content_type)
    try:
        with urllib.request.urlopen(req, timeout=timeout) as resp:
            return resp.status, json.loads(resp.read() or b"null")
    except urllib.error.HTTPError as e:
        return e.code, json.loads(e.read() or b"null")


def main():
    binary = sys.argv[1]
    triangles = int(sys.argv[2]) if len(sys.argv) > 2 else 10_000_000
    sock = socket.socket()
    sock.bind(("127.0.0.1", 0))
    port = sock.getsockname()[1]
    sock.close()
    base = f"http://127.0.0.1:{port}"
    with tempfile.TemporaryDirectory(prefix="lightcast-membench-") as cache:
        server = subprocess.Popen(
            [binary, "serve", "--listen", f"127.0.0.1:{port}", "--allow-cpu-adapter",
             "--cache-dir", cache, "--request-timeout-ms", "600000"],
            stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
        try:
            for _ in range(600):
                try:
                    if request(base, "GET", "/healthz")[0] == 200:
                        break
                except OSError:
                    time.sleep(0.5)
            limits = request(base, "GET", "/v1/server")[1]["limits"]
            glb, made = grid_glb(triangles, png_solid(IMAGE_SIDE))
            rows = [("start", "", rss_mib(server.pid))]
            for k in range(1, UPLOADS + 1):
                started = time.time()
                status, body = request(base, "POST", "/v1/scenes", glb, "model/gltf-binary")
                outcome = f"{status} {body.get('error', '')}".strip()
                if status == 201:
                    while True:
                        info = request(base, "GET", f"/v1/scenes/{body['id']}")[1]
                        if info["caches"][0]["state"] in ("ready", "failed"):
                            outcome += f", caches {info['caches'][0]['state']}"
                            break
                        time.sleep(0.5)
                outcome += f", {time.time() - started:.0f} s"
                rows.append((f"upload {k}", outcome, rss_mib(server.pid)))
        finally:
            server.terminate()
            server.wait(timeout=60)
    print(f"Upload: {len(glb) / 2**20:.1f} MiB .glb, {made} triangles, "
          f"{IMAGES} × {IMAGE_SIDE}² solid PNG textures.\n")
    print("Budgets: " + ", ".join(f"{k} {limits[k]}" for k in (
        "max_triangles", "max_total_triangles", "max_texture_size", "max_scene_texture_bytes",
        "max_total_texture_bytes", "max_caches_per_set", "max_total_caches", "max_scenes")) + "\n")
    print("| after | answer | VmRSS MiB |\n|---|---|---|")
    for name, outcome, rss in rows:
        print(f"| {name} | {outcome} | {rss:.0f} |")


if __name__ == "__main__":
    main()
