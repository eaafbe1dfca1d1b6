#!/usr/bin/env bash
# Installs what a fresh Debian 12 machine lacks to build and test pathtracer
# with its Embree backend: Debian's Embree 3 and libclang (for bindgen).
# Without them the project still builds; the embree backend is then disabled.
set -euo pipefail
need=()
for pkg in libembree-dev libclang-dev; do
    dpkg-query -W -f='${Status}' "$pkg" 2>/dev/null | grep -q "install ok installed" || need+=("$pkg")
done
if [ ${#need[@]} -eq 0 ]; then
    exit 0
fi
if ! command -v apt-get >/dev/null 2>&1; then
    echo "install-deps: no apt-get here; install Embree 3 or 4 and libclang yourself (missing: ${need[*]})" >&2
    exit 0
fi
sudo=""
if [ "$(id -u)" -ne 0 ]; then
    sudo="sudo"
fi
echo "install-deps: installing ${need[*]}" >&2
export DEBIAN_FRONTEND=noninteractive
$sudo apt-get update -qq
$sudo apt-get install -y -qq --no-install-recommends "${need[@]}" >/dev/null
