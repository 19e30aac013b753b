"""Runs a lightcast-server binary the way deploy/Dockerfile's runtime stage runs it, on this
Debian machine, where no container engine runs: the stage's packages, user, environment,
entrypoint, volume and health check are read from the Dockerfile itself, so the two cannot drift.

1. This machine runs the image's Debian release and has the stage's packages (they are
   installed where missing), and every shared library the binary links comes from one of them
   or from libc6/libgcc-s1, which every Debian image has.
2. In private network and mount namespaces (so port and paths are the image's without touching
   the machine): the binary at the entrypoint's path, the volume as an empty directory owned by
   the image's user, the process started as that uid/gid with exactly the image's environment.
3. The HEALTHCHECK command, run as that user, passes; /readyz answers 200, or 503 naming the
   software adapter on machines without a GPU; a render leaves a light cache in the volume,
   written by the user; SIGTERM ends the server with status 0.
4. Again with the environment the Helm chart gives the container on top, and the tokens file
   its Secret holds where the chart mounts it, both as rendered with every option on
   (CHART_RUN, written by check_deploy.py): the server accepts every value, /metrics refuses a
   request without a token and, with one of the Secret's, reports the session capacity the
   chart set; SIGTERM ends it with status 0.

Usage (root): runtime_layout.py BINARY CHART_RUN
"""

import json
import os
import re
import shutil
import signal
import subprocess
import sys
import time
import urllib.error
import urllib.request
from pathlib import Path

from dockerfile_stages import Dockerfile

# Libraries of the C runtime, in every Debian image (dependencies of the essential packages).
BASE_PACKAGES = {"libc6", "libgcc-s1"}
# The PATH Debian's images set.
IMAGE_PATH = "/usr/local/sbin:/usr/local/bin:/usr/sbin:/usr/bin:/sbin:/bin"
START_SECONDS = 120
CACHE_SECONDS = 120
STOP_SECONDS = 30


def die(message):
    sys.exit(f"runtime-layout: FAIL {message}")


def say(message):
    print(f"runtime-layout: {message}", file=sys.stderr)


def image_layout():
    parsed = Dockerfile()

    def last(kind):
        value = parsed.last(kind)
        if value is None:
            die(f"deploy/Dockerfile's runtime stage has no {kind}")
        return value

    uid, gid = (int(x) for x in last("USER").split(":"))
    healthcheck = last("HEALTHCHECK")
    return {
        "release": parsed.global_arg("DEBIAN_RELEASE"),
        "packages": parsed.packages(),
        "uid": uid,
        "gid": gid,
        "env": parsed.env(),
        "volume": json.loads(last("VOLUME"))[0],
        "entrypoint": json.loads(last("ENTRYPOINT")),
        "cmd": json.loads(last("CMD")),
        "healthcheck": json.loads(healthcheck[healthcheck.index("CMD") + 3:]),
    }


def check_packages(binary, layout):
    release = dict(
        line.split("=", 1) for line in Path("/etc/os-release").read_text().split()
        if "=" in line
    ).get("VERSION_CODENAME", "").strip('"')
    if release != layout["release"]:
        die(f"this machine runs Debian `{release}`, the image `{layout['release']}`: the "
            "packages would not be the image's")
    missing = [p for p in layout["packages"]
               if subprocess.run(["dpkg", "-s", p], capture_output=True).returncode != 0]
    if missing:
        say(f"installing the image's packages {missing}")
        subprocess.run(["apt-get", "update", "-qq"], check=True)
        subprocess.run(["apt-get", "install", "-y", "-qq", "--no-install-recommends", *missing],
                       check=True, env={**os.environ, "DEBIAN_FRONTEND": "noninteractive"})
    ldd = subprocess.run(["ldd", str(binary)], capture_output=True, text=True, check=True)
    allowed = set(layout["packages"]) | BASE_PACKAGES
    for path in re.findall(r"=> (/\S+)", ldd.stdout):
        owner = subprocess.run(["dpkg", "-S", os.path.realpath(path)], capture_output=True,
                               text=True)
        if owner.returncode != 0:
            owner = subprocess.run(["dpkg", "-S", path], capture_output=True, text=True)
        package = owner.stdout.split(":", 1)[0] if owner.returncode == 0 else None
        if package not in allowed:
            die(f"the binary links {path} (package {package}), which the image does not install")
    say(f"packages {layout['packages']} present; the binary links only those and the C runtime")


def get(url, timeout=10, data=None, headers=None):
    request = urllib.request.Request(url, data=data, method="POST" if data else "GET",
                                     headers=headers or {})
    try:
        with urllib.request.urlopen(request, timeout=timeout) as response:
            return response.status, response.read()
    except urllib.error.HTTPError as e:
        return e.code, e.read()


def as_image_user(layout, env):
    return {"user": layout["uid"], "group": layout["gid"], "extra_groups": [],
            "env": {**env, "PATH": IMAGE_PATH}, "cwd": "/"}


def inside(binary, layout, chart_run):
    """Runs in the private namespaces: nothing done here is seen outside."""
    subprocess.run(["ip", "link", "set", "lo", "up"], check=True)
    entrypoint = Path(layout["entrypoint"][0])
    volume = Path(layout["volume"])
    for directory in (entrypoint.parent, volume.parent):
        subprocess.run(["mount", "-t", "tmpfs", "-o", "mode=0755", "tmpfs", str(directory)],
                       check=True)
    shutil.copy(binary, entrypoint)
    entrypoint.chmod(0o755)
    volume.mkdir()
    os.chown(volume, layout["uid"], layout["gid"])

    user = as_image_user(layout, layout["env"])
    server = subprocess.Popen([*layout["entrypoint"], *layout["cmd"]], **user)
    try:
        wait_healthy(server, layout, user)
        check_image_run(server, layout)
        stop(server)
    finally:
        if server.poll() is None:
            server.kill()

    chart_env = chart_run["env"]
    tokens = Path(chart_env["LIGHTCAST_TOKENS_FILE"])
    subprocess.run(["mount", "-t", "tmpfs", "-o", "mode=0755", "tmpfs", "/run"], check=True)
    tokens.parent.mkdir(parents=True)
    tokens.write_text(chart_run["tokens_file"])
    user = as_image_user(layout, {**layout["env"], **chart_env})
    server = subprocess.Popen([*layout["entrypoint"], *layout["cmd"]], **user)
    try:
        wait_healthy(server, layout, user)
        check_chart_run(layout, chart_env, chart_run["token"])
        stop(server)
    finally:
        if server.poll() is None:
            server.kill()


def wait_healthy(server, layout, user):
    deadline = time.monotonic() + START_SECONDS
    while subprocess.run(layout["healthcheck"], capture_output=True, **user).returncode != 0:
        if server.poll() is not None:
            die(f"the server exited with status {server.returncode} before it was healthy")
        if time.monotonic() > deadline:
            die(f"HEALTHCHECK {layout['healthcheck']} did not pass within {START_SECONDS} s")
        time.sleep(1)
    say(f"HEALTHCHECK passes as uid {layout['uid']}")


def base_url(env):
    return "http://127.0.0.1:" + env["LIGHTCAST_LISTEN"].rsplit(":", 1)[1]


def check_image_run(server, layout):
    base = base_url(layout["env"])
    status, body = get(base + "/readyz", timeout=60)
    if status == 503 and b"CPU (software) adapter" in body:
        say("/readyz: 503, a software adapter (no GPU here)")
    elif status != 200:
        die(f"/readyz answered {status}: {body[:300]!r}")
    else:
        say("/readyz: 200")

    request = json.dumps({"render": {"width": 32, "height": 32, "shadow_map_size": 256,
                                     "gi": {"method": "brsm", "rsm_size": 32,
                                            "view_samples": 16, "val_count": 64}}}).encode()
    volume = Path(layout["volume"])
    deadline = time.monotonic() + CACHE_SECONDS
    while True:
        status, body = get(base + "/v1/render", timeout=60, data=request)
        caches = list(volume.glob("*.lcc"))
        if status == 200 and caches:
            break
        if time.monotonic() > deadline:
            shown = "" if status == 200 else f" {body[:300]!r}"
            die(f"no light cache in the volume {volume} after {CACHE_SECONDS} s "
                f"(last render: {status}{shown})")
        time.sleep(2)
    owners = {(c.stat().st_uid, c.stat().st_gid) for c in caches}
    if owners != {(layout["uid"], layout["gid"])}:
        die(f"light caches in the volume belong to {owners}, not the image's user")
    say(f"a render wrote {caches[0].name} into the volume {volume} as the image's user")


def check_chart_run(layout, chart_env, token):
    base = base_url({**layout["env"], **chart_env})
    status, _ = get(base + "/metrics")
    if status != 401:
        die(f"with the chart's tokens file, /metrics without a token answered {status}, not 401")
    status, body = get(base + "/metrics", headers={"Authorization": f"Bearer {token}"})
    if status != 200:
        die(f"/metrics with a token of the chart's Secret answered {status}: {body[:300]!r}")
    metrics = body.decode()
    capacity = re.search(r"^lightcast_session_capacity (\S+)$", metrics, re.M)
    expected = float(chart_env["LIGHTCAST_MAX_SESSIONS"])
    if not capacity or float(capacity.group(1)) != expected:
        die(f"/metrics reports lightcast_session_capacity "
            f"{capacity.group(1) if capacity else 'nowhere'}, the chart set {expected:g}")
    say(f"with the chart's environment: /metrics needs the token and reports capacity "
        f"{expected:g}")


def stop(server):
    server.send_signal(signal.SIGTERM)
    try:
        status = server.wait(timeout=STOP_SECONDS)
    except subprocess.TimeoutExpired:
        die(f"the server did not stop within {STOP_SECONDS} s of SIGTERM")
    if status != 0:
        die(f"the server exited with status {status} after SIGTERM")
    say("SIGTERM: the server stopped with status 0")


def main():
    if len(sys.argv) == 5 and sys.argv[1] == "--inside":
        inside(Path(sys.argv[2]), json.loads(sys.argv[3]), json.loads(sys.argv[4]))
        return
    if len(sys.argv) != 3:
        sys.exit(__doc__)
    if os.geteuid() != 0:
        die("needs root (namespaces, mounts, another uid)")
    binary = Path(sys.argv[1]).resolve()
    if not binary.is_file():
        die(f"no binary at {binary}")
    chart_run = json.loads(Path(sys.argv[2]).read_text())
    layout = image_layout()
    check_packages(binary, layout)
    run = subprocess.run(["unshare", "--net", "--mount", "--propagation", "private", "--fork",
                          sys.executable, "-B", __file__, "--inside", str(binary), json.dumps(layout),
                          json.dumps(chart_run)])
    if run.returncode != 0:
        sys.exit(run.returncode)
    say("the binary runs with deploy/Dockerfile's runtime layout and the chart's environment")


if __name__ == "__main__":
    main()
