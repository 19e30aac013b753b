"""Offline checks of deploy/: the Dockerfile and the Helm chart, without a container engine or
a cluster. Run by deploy/ci/check.sh, which installs the pinned tools this takes as arguments.

- deploy/Dockerfile: hadolint, then what the image must do (non-root numeric user, the NVIDIA
  toolkit's capabilities, listen address, cache volume, health check, entrypoint), checked
  against the server's own flags so a renamed flag cannot leave the image behind.
- deploy/helm/lightcast: `helm lint --strict`, then `helm template` with the default values, the
  scaled-out file and a file that switches every optional object on; every object must pass
  kubernetes-validate's strict schemas (unknown fields rejected) for the oldest and newest
  Kubernetes the package knows; the ServiceMonitor (a custom resource without a schema there)
  passes servicemonitor.schema.json. Then the chart must agree with the image and the server
  (user, port, cache path, env names, probe paths, GPU limit, metric names), the ServiceMonitor
  must select the pods' Service alone, every value must be in deploy/README.md's table, and bad
  values must be refused naming the key.
"""

import argparse
import json
import re
import subprocess
import sys
import tempfile
from pathlib import Path

import jsonschema
import kubernetes_validate
import yaml

from dockerfile_stages import Dockerfile

ROOT = Path(__file__).resolve().parents[2]
CHART = ROOT / "deploy/helm/lightcast"
SCALED_OUT = ROOT / "deploy/helm/values-scaled-out.yaml"
ADAPTER_RULES = ROOT / "deploy/helm/prometheus-adapter-rules.yaml"
# The oldest Kubernetes the chart's kubeVersion allows, and the newest kubernetes-validate knows.
KUBERNETES_VERSIONS = ["1.25.0", kubernetes_validate.latest_version()]
# Custom resources the chart may write, each with the schema it is checked against instead.
CUSTOM_SCHEMAS = {
    ("monitoring.coreos.com/v1", "ServiceMonitor"): ROOT / "deploy/ci/servicemonitor.schema.json",
}

# Every optional object on, with values unlike the defaults, so every branch renders once.
EVERYTHING_ON = {
    "replicaCount": 2,
    "runtimeClassName": "nvidia",
    "imagePullSecrets": [{"name": "regcred"}],
    "auth": {"tokens": ["0123456789abcdef", "fedcba9876543210"]},
    "cache": {"persistent": False},
    "server": {"env": {"LIGHTCAST_MAX_FPS": "60", "LIGHTCAST_ENCODE_THREADS": 4}},
    "ingress": {"enabled": True, "className": "nginx",
                "tls": [{"secretName": "t", "hosts": ["lightcast.example.com"]}]},
    "metrics": {"serviceMonitor": {"enabled": True}},
    "autoscaling": {"enabled": True, "minReplicas": 2, "maxReplicas": 3},
    "podLabels": {"team": "render"},
    "podAnnotations": {"note": "x"},
}

# Sessions routed across the pods by the chart's router (issue 14).
ROUTING_ON = {
    "routing": {"enabled": True, "key": "0123456789abcdef0123456789abcdef"},
    "ingress": {"enabled": True, "className": "nginx"},
    "sceneStore": {"enabled": True},
    # With the router's Service beside the pods' two, which the ServiceMonitor must not select.
    "metrics": {"serviceMonitor": {"enabled": True}},
}
ROUTING_RULE = CHART / "files/routing.conf"

# Values the chart must refuse, each with the words its error must contain.
BAD_VALUES = [
    ({"replicas": 3}, "Additional property replicas is not allowed"),
    ({"auth": {"tokens": ["short"]}}, "auth.tokens.0"),
    ({"gpu": {"count": 0}}, "gpu.count"),
    ({"cache": {"size": "lots"}}, "cache.size"),
    ({"server": {"env": {"MAX_FPS": "60"}}}, "server.env"),
    ({"routing": {"enabled": True}}, "routing.existingSecret or routing.key"),
    ({"routing": {"key": "too short"}}, "routing.key"),
    ({"autoscaling": {"enabled": True, "minReplicas": 5, "maxReplicas": 2}},
     "autoscaling.minReplicas (5) is above autoscaling.maxReplicas (2)"),
]

failures = []


def fail(message):
    failures.append(message)
    print(f"check-deploy: FAIL {message}", file=sys.stderr)


def server_env_names():
    names = set()
    for path in (ROOT / "server").rglob("*.rs"):
        names.update(re.findall(r'env = "(LIGHTCAST_[A-Z0-9_]+)"', path.read_text()))
    if "LIGHTCAST_LISTEN" not in names:
        sys.exit("check-deploy: found no LIGHTCAST_* flags under server/; has the CLI moved?")
    return names


def server_metric_names():
    text = (ROOT / "server/service/src/metrics.rs").read_text()
    return set(re.findall(r'pub const [A-Z_]+: &str = "([a-z_]+)";', text))


def port_of(listen):
    return int(listen.rsplit(":", 1)[1])


def check_dockerfile(hadolint, env_names):
    dockerfile = ROOT / "deploy/Dockerfile"
    run = subprocess.run([hadolint, "--failure-threshold", "style", "--no-color", str(dockerfile)],
                         capture_output=True, text=True)
    if run.returncode != 0:
        fail(f"hadolint deploy/Dockerfile:\n{run.stdout}{run.stderr}")

    parsed = Dockerfile(dockerfile)
    if len(parsed.stages) != 2:
        fail(f"deploy/Dockerfile: expected a build and a runtime stage, found {len(parsed.stages)}")
        return None
    build, runtime = parsed.stages

    rust_version = re.search(r'^rust-version = "([0-9.]+)"', (ROOT / "Cargo.toml").read_text(),
                             re.M).group(1)
    build_from = build[0]["value"]
    if not build_from.startswith(f"rust:{rust_version}-"):
        fail(f"deploy/Dockerfile: the build stage is `{build_from}`, but Cargo.toml's "
             f"rust-version is {rust_version}")

    if not re.match(r"debian:\S*-slim$", runtime[0]["value"]):
        fail(f"deploy/Dockerfile: the runtime stage is `{runtime[0]['value']}`, not a slim Debian")
    packages = parsed.packages()
    if "libvulkan1" not in packages:
        fail("deploy/Dockerfile: the runtime stage does not install libvulkan1")

    user = parsed.last("USER") or "0"
    uid = user.split(":")[0]
    if not uid.isdigit() or int(uid) == 0:
        fail(f"deploy/Dockerfile: USER is `{user}`; it must be a numeric non-root uid "
             "(Kubernetes' runAsNonRoot can only check numbers)")
        return None

    env = parsed.env()
    capabilities = set(env.get("NVIDIA_DRIVER_CAPABILITIES", "").split(","))
    missing = {"graphics", "compute", "utility"} - capabilities
    if missing:
        fail(f"deploy/Dockerfile: NVIDIA_DRIVER_CAPABILITIES lacks {sorted(missing)} "
             "(graphics brings the Vulkan driver)")
    if "NVIDIA_VISIBLE_DEVICES" not in env:
        fail("deploy/Dockerfile: NVIDIA_VISIBLE_DEVICES is not set")
    for name in env:
        if name.startswith("LIGHTCAST_") and name not in env_names:
            fail(f"deploy/Dockerfile: ENV {name} is no flag of the server")
    listen = env.get("LIGHTCAST_LISTEN", "")
    if not listen.startswith("0.0.0.0:"):
        fail(f"deploy/Dockerfile: LIGHTCAST_LISTEN is `{listen}`; outside the container only "
             "0.0.0.0 is reachable")
        return None
    port = port_of(listen)
    if str(port) not in " ".join(parsed.values("EXPOSE")).split():
        fail(f"deploy/Dockerfile: EXPOSE does not name the listen port {port}")
    cache_dir = env.get("LIGHTCAST_CACHE_DIR")
    volumes = " ".join(parsed.values("VOLUME"))
    if not cache_dir or f'"{cache_dir}"' not in volumes:
        fail(f"deploy/Dockerfile: LIGHTCAST_CACHE_DIR ({cache_dir}) is not a VOLUME ({volumes})")
    healthcheck = parsed.last("HEALTHCHECK") or ""
    if f"127.0.0.1:{port}/healthz" not in healthcheck:
        fail(f"deploy/Dockerfile: HEALTHCHECK does not ask /healthz on port {port}: {healthcheck}")
    entrypoint = json.loads(parsed.last("ENTRYPOINT") or "[]")
    copied = [i["value"].split()[-1] for i in runtime
              if i["instruction"] == "COPY" and i["value"].startswith("--from=build ")]
    if not entrypoint or entrypoint[0] not in copied:
        fail(f"deploy/Dockerfile: ENTRYPOINT {entrypoint} is not the binary copied from the "
             f"build stage ({copied})")
    return {"uid": int(uid), "port": port, "cache_dir": cache_dir}


def helm(helm_bin, *args):
    return subprocess.run([helm_bin, *args], capture_output=True, text=True)


def render(helm_bin, values_files):
    args = ["template", "lightcast", str(CHART), "--namespace", "render"]
    for path in values_files:
        args += ["--values", str(path)]
    run = helm(helm_bin, *args)
    if run.returncode != 0:
        return None, run.stderr
    return [d for d in yaml.safe_load_all(run.stdout) if d], None


def validate_objects(name, objects):
    for obj in objects:
        what = f"{name}: {obj.get('kind')}/{obj.get('metadata', {}).get('name')}"
        custom = CUSTOM_SCHEMAS.get((obj.get("apiVersion"), obj.get("kind")))
        if custom:
            errors = list(jsonschema.Draft202012Validator(json.loads(custom.read_text()))
                          .iter_errors(obj))
            for e in errors:
                fail(f"{what} at {'.'.join(map(str, e.absolute_path)) or '(root)'}: {e.message}")
            continue
        for version in KUBERNETES_VERSIONS:
            try:
                kubernetes_validate.validate(obj, version, strict=True)
            except kubernetes_validate.SchemaNotFoundError:
                fail(f"{what}: no Kubernetes {version} schema for {obj.get('apiVersion')}; "
                     "add a schema to CUSTOM_SCHEMAS for a custom resource")
            except kubernetes_validate.ValidationError as e:
                path = ".".join(map(str, e.absolute_path)) or "(root)"
                fail(f"{what} against Kubernetes {version} at {path}: {e.message}")


def by_kind(objects, kind):
    return [o for o in objects if o["kind"] == kind]


def check_default_render(objects, image, env_names):
    (statefulset,) = by_kind(objects, "StatefulSet")
    pod = statefulset["spec"]["template"]["spec"]
    (container,) = pod["containers"]
    limits = container["resources"].get("limits", {})
    if limits.get("nvidia.com/gpu") != 1:
        fail(f"chart: the container's limits {limits} do not ask for nvidia.com/gpu: 1")
    if "nvidia.com/gpu.present" not in pod.get("nodeSelector", {}):
        fail("chart: no nodeSelector for GPU nodes")
    if not any(t.get("key") == "nvidia.com/gpu" for t in pod.get("tolerations", [])):
        fail("chart: no toleration of the nvidia.com/gpu taint")
    for probe, path in [("livenessProbe", "/healthz"), ("startupProbe", "/healthz"),
                        ("readinessProbe", "/readyz")]:
        got = container.get(probe, {}).get("httpGet", {}).get("path")
        if got != path:
            fail(f"chart: {probe} asks {got}, not {path}")
    if pod["securityContext"].get("runAsUser") != image["uid"]:
        fail(f"chart: runAsUser {pod['securityContext'].get('runAsUser')} is not the image's "
             f"user {image['uid']}")
    env = {e["name"]: e.get("value") for e in container["env"]}
    for name in env:
        if name not in env_names:
            fail(f"chart: env {name} is no flag of the server")
    if port_of(env.get("LIGHTCAST_LISTEN", ":0")) != container["ports"][0]["containerPort"]:
        fail("chart: LIGHTCAST_LISTEN's port is not the container port")
    mounts = {m["name"]: m["mountPath"] for m in container["volumeMounts"]}
    if env.get("LIGHTCAST_CACHE_DIR") != image["cache_dir"] or mounts.get("cache") != image[
            "cache_dir"]:
        fail(f"chart: the cache volume ({mounts.get('cache')}) and LIGHTCAST_CACHE_DIR "
             f"({env.get('LIGHTCAST_CACHE_DIR')}) are not the image's volume {image['cache_dir']}")
    if "LIGHTCAST_TOKENS_FILE" not in env:
        fail("chart: auth is on by default, but no LIGHTCAST_TOKENS_FILE is set")
    if not by_kind(objects, "PodDisruptionBudget"):
        fail("chart: no PodDisruptionBudget by default")


def check_routing_render(objects, env_names):
    """With routing on: pods name themselves and read the key, the router carries the shared
    rule verbatim, the Ingress goes through the router, and no Service of the pods selects it."""
    (statefulset,) = by_kind(objects, "StatefulSet")
    env = {e["name"]: e for e in statefulset["spec"]["template"]["spec"]["containers"][0]["env"]}
    for name in env:
        if name not in env_names:
            fail(f"chart (routing): env {name} is no flag of the server")
    replica = env.get("LIGHTCAST_REPLICA", {}).get("valueFrom", {}).get("fieldRef", {})
    if replica.get("fieldPath") != "metadata.name":
        fail("chart (routing): LIGHTCAST_REPLICA is not the pod's name")
    if "LIGHTCAST_ROUTING_KEY_FILE" not in env:
        fail("chart (routing): no LIGHTCAST_ROUTING_KEY_FILE")
    check_scene_store(objects, statefulset, env)
    routers = [c for c in by_kind(objects, "ConfigMap") if c["metadata"]["name"].endswith("-router")]
    conf = [line.strip() for line in routers[0]["data"]["default.conf"].splitlines()] if routers else []
    missing = [line.strip() for line in ROUTING_RULE.read_text().splitlines()
               if line.strip() and line.strip() not in conf]
    if len(routers) != 1 or missing:
        fail(f"chart (routing): the router's configuration lacks files/routing.conf's {missing}")
    else:
        check_router_config(routers[0]["data"]["default.conf"])
    (ingress,) = by_kind(objects, "Ingress")
    backend = ingress["spec"]["rules"][0]["http"]["paths"][0]["backend"]["service"]["name"]
    if not backend.endswith("-router"):
        fail(f"chart (routing): the Ingress sends to {backend}, not the router")
    (deployment,) = by_kind(objects, "Deployment")
    router_labels = deployment["spec"]["template"]["metadata"]["labels"]
    for service in by_kind(objects, "Service"):
        selector = service["spec"]["selector"]
        selects_router = all(router_labels.get(k) == v for k, v in selector.items())
        if selects_router != service["metadata"]["name"].endswith("-router"):
            fail(f"chart (routing): Service {service['metadata']['name']} selects "
                 f"{'the router' if selects_router else 'not the router'}")


def check_service_monitor(name, objects):
    """The ServiceMonitor selects one Service, the one of the StatefulSet's pods that is not
    headless: each pod is scraped once, and the router's pods (whose /metrics is some pod's)
    not at all."""
    monitors = by_kind(objects, "ServiceMonitor")
    if not monitors:
        return
    (monitor,) = monitors
    wanted = monitor["spec"]["selector"]["matchLabels"]
    (statefulset,) = by_kind(objects, "StatefulSet")
    pod_labels = statefulset["spec"]["template"]["metadata"]["labels"]
    services = by_kind(objects, "Service")
    selected = [s["metadata"]["name"] for s in services
                if all(s["metadata"].get("labels", {}).get(k) == v for k, v in wanted.items())]
    expected = [s["metadata"]["name"] for s in services
                if s["spec"].get("clusterIP") != "None"
                and all(pod_labels.get(k) == v for k, v in s["spec"]["selector"].items())]
    if len(expected) != 1 or selected != expected:
        fail(f"chart ({name}): the ServiceMonitor selects the Services {selected}; it must select "
             f"only the pods' Service {expected}")


def check_scene_store(objects, statefulset, env):
    """With the scene store on: every pod mounts the same ReadWriteMany claim where
    LIGHTCAST_SCENE_STORE points."""
    path = env.get("LIGHTCAST_SCENE_STORE", {}).get("value")
    pod = statefulset["spec"]["template"]["spec"]
    mounts = {m["name"]: m["mountPath"] for m in pod["containers"][0]["volumeMounts"]}
    volumes = {v["name"]: v for v in pod["volumes"]}
    claims = {c["metadata"]["name"]: c for c in by_kind(objects, "PersistentVolumeClaim")}
    names = [n for n, p in mounts.items() if p == path]
    if not path or not names:
        fail("chart (scene store): LIGHTCAST_SCENE_STORE is not set to a mounted volume")
        return
    claim_name = volumes.get(names[0], {}).get("persistentVolumeClaim", {}).get("claimName")
    claim = claims.get(claim_name)
    if claim is None or claim["spec"]["accessModes"] != ["ReadWriteMany"]:
        fail(f"chart (scene store): {path} is not on a ReadWriteMany claim the chart makes "
             f"(claim {claim_name})")
    if any(t["metadata"]["name"] == names[0]
           for t in statefulset["spec"].get("volumeClaimTemplates", [])):
        fail("chart (scene store): the store is a per-pod claim, not one shared volume")


def check_router_config(conf):
    """`nginx -t` on the router's configuration as rendered (its resolver pointed at loopback:
    the cluster's DNS name does not resolve here)."""
    nginx = "/usr/sbin/nginx"
    if not Path(nginx).exists():
        fail("chart (routing): nginx is needed to check the router's configuration; install it "
             "(deploy/setup-debian.sh --tests)")
        return
    conf = re.sub(r"^resolver \S+", "resolver 127.0.0.1", conf, flags=re.M)
    with tempfile.TemporaryDirectory() as tmp:
        (Path(tmp) / "default.conf").write_text(conf)
        temp_paths = " ".join(f"{k}_temp_path {tmp}/{k};"
                              for k in ["client_body", "proxy", "fastcgi", "uwsgi", "scgi"])
        (Path(tmp) / "nginx.conf").write_text(
            f"pid {tmp}/nginx.pid;\nerror_log {tmp}/error.log;\nevents {{}}\n"
            f"http {{\n{temp_paths}\ninclude {tmp}/default.conf;\n}}\n")
        result = subprocess.run([nginx, "-t", "-q", "-e", f"{tmp}/error.log", "-c",
                                 f"{tmp}/nginx.conf"], capture_output=True, text=True)
        if result.returncode != 0:
            fail(f"chart (routing): nginx -t refuses the router's configuration:\n"
                 f"{result.stdout}{result.stderr}")


def write_chart_run(objects, path):
    """What runtime_layout.py runs the server with: the container's env and the tokens file the
    chart's Secret holds, as rendered."""
    (statefulset,) = by_kind(objects, "StatefulSet")
    env = statefulset["spec"]["template"]["spec"]["containers"][0]["env"]
    (secret,) = [s for s in by_kind(objects, "Secret") if s["metadata"]["name"].endswith("-tokens")]
    (tokens,) = secret["stringData"].values()
    path.write_text(json.dumps({"env": {e["name"]: e["value"] for e in env},
                                "tokens_file": tokens, "token": EVERYTHING_ON["auth"]["tokens"][0]}))


def check_autoscaling(objects):
    (hpa,) = by_kind(objects, "HorizontalPodAutoscaler")
    metric = hpa["spec"]["metrics"][0]["pods"]["metric"]["name"]
    rules = yaml.safe_load(ADAPTER_RULES.read_text())["rules"]["custom"]
    served = {r["name"]["as"]: r for r in rules}
    if metric not in served:
        fail(f"chart: the HPA scales on {metric}, which {ADAPTER_RULES.name} does not serve")
        return
    exported = server_metric_names()
    used = set(re.findall(r"\b(lightcast_[a-z_]+)\{", served[metric]["metricsQuery"]))
    used |= set(re.findall(r"\b(lightcast_[a-z_]+)\{", served[metric]["seriesQuery"]))
    if not used or used - exported:
        fail(f"{ADAPTER_RULES.name}: {sorted(used - exported) or 'no series'} not among the "
             f"server's metrics {sorted(exported)}")


# Values whose content is free-form (maps and lists the user fills): documented as one key.
FREE_FORM = {"imagePullSecrets", "nodeSelector", "tolerations", "affinity", "resources",
             "server.env", "auth.tokens", "ingress.annotations", "ingress.hosts", "ingress.tls",
             "metrics.serviceMonitor.labels", "metrics.serviceMonitor.tokenSecret", "podLabels",
             "podAnnotations", "routing.router.resources"}


def value_keys(values, prefix=""):
    for key, value in values.items():
        path = prefix + key
        if isinstance(value, dict) and path not in FREE_FORM:
            yield from value_keys(value, path + ".")
        else:
            yield path


def check_values_documented():
    readme = (ROOT / "deploy/README.md").read_text()
    for key in value_keys(yaml.safe_load((CHART / "values.yaml").read_text())):
        if f"`{key}`" not in readme:
            fail(f"deploy/README.md: the value `{key}` of values.yaml is not in the values table")


def check_bad_values(helm_bin):
    with tempfile.TemporaryDirectory() as tmp:
        for values, expected in BAD_VALUES:
            path = Path(tmp) / "bad.yaml"
            path.write_text(yaml.safe_dump(values))
            objects, error = render(helm_bin, [path])
            if objects is not None:
                fail(f"chart: values {values} rendered; they must be refused")
            elif expected not in error:
                fail(f"chart: values {values} were refused without naming `{expected}`:\n{error}")


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--helm", required=True)
    parser.add_argument("--hadolint", required=True)
    parser.add_argument("--chart-run-out", type=Path,
                        help="write the server container's env and tokens file of the "
                             "every-option render here (JSON), for runtime_layout.py")
    args = parser.parse_args()

    env_names = server_env_names()
    image = check_dockerfile(args.hadolint, env_names)

    lint = helm(args.helm, "lint", "--strict", str(CHART))
    if lint.returncode != 0:
        fail(f"helm lint --strict:\n{lint.stdout}{lint.stderr}")

    with tempfile.TemporaryDirectory() as tmp:
        everything = Path(tmp) / "everything-on.yaml"
        everything.write_text(yaml.safe_dump(EVERYTHING_ON))
        routing = Path(tmp) / "routing-on.yaml"
        routing.write_text(yaml.safe_dump(ROUTING_ON))
        renders = {}
        for name, files in [("default values", []), ("values-scaled-out.yaml", [SCALED_OUT]),
                            ("every option on", [everything]), ("routing on", [routing])]:
            objects, error = render(args.helm, files)
            if objects is None:
                fail(f"helm template with {name}:\n{error}")
                continue
            before = len(failures)
            validate_objects(name, objects)
            renders[name] = objects
            verdict = "valid" if len(failures) == before else "INVALID"
            print(f"check-deploy: {name}: {len(objects)} objects "
                  f"({', '.join(sorted(o['kind'] for o in objects))}) {verdict}", file=sys.stderr)

    if image and "default values" in renders:
        check_default_render(renders["default values"], image, env_names)
    if args.chart_run_out and "every option on" in renders:
        write_chart_run(renders["every option on"], args.chart_run_out)
    if "values-scaled-out.yaml" in renders:
        check_autoscaling(renders["values-scaled-out.yaml"])
    if "routing on" in renders:
        check_routing_render(renders["routing on"], env_names)
    for name, objects in renders.items():
        check_service_monitor(name, objects)
    if not any(by_kind(objects, "ServiceMonitor") for objects in renders.values()):
        fail("chart: no render has a ServiceMonitor to check")
    check_bad_values(args.helm)
    check_values_documented()

    if failures:
        sys.exit(f"check-deploy: {len(failures)} problem(s) in deploy/")
    print("check-deploy: deploy/Dockerfile and deploy/helm/lightcast pass", file=sys.stderr)


if __name__ == "__main__":
    main()
