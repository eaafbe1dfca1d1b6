#!/usr/bin/env bash
# Installs what a fresh Debian 12 machine lacks to build and test pathtracer with both of its
# Embree backends:
#   * Embree 3 (3.13.5) and libclang (for bindgen): Debian's libembree-dev and libclang-dev;
#   * Embree 4 into third_party/embree4/ (project-local, ignored by git), where build.rs finds it:
#       include/embree4/  the headers of the embree4-sys crate (Embree 4.2.0's), from crates.io;
#       lib/              the shared libraries of the PyPI wheel embreex4 4.4.0.post1 (Embree
#                         4.4.0 and the TBB it needs beside it; RPATH $ORIGIN), and
#                         libembree4.so.4, a link to the library.
# Nothing is downloaded by `cargo build` itself. Without any of this the project still builds;
# the missing backend then says what to install. Idempotent: re-running installs nothing new.
set -euo pipefail
cd "$(dirname "$0")/.."

need=()
for pkg in libembree-dev libclang-dev; do
    dpkg-query -W -f='${Status}' "$pkg" 2>/dev/null | grep -q "install ok installed" || need+=("$pkg")
done
if [ ${#need[@]} -gt 0 ]; then
    if command -v apt-get >/dev/null 2>&1; then
        sudo=""
        if [ "$(id -u)" -ne 0 ]; then sudo="sudo"; fi
        echo "install-deps: installing ${need[*]}" >&2
        export DEBIAN_FRONTEND=noninteractive
        $sudo apt-get update -qq
        $sudo apt-get install -y -qq --no-install-recommends "${need[@]}" >/dev/null
    else
        echo "install-deps: no apt-get here; install Embree 3 and libclang yourself (missing: ${need[*]})" >&2
    fi
fi

e4=third_party/embree4
wheel_version=4.4.0.post1
crate_version=0.0.12
if [ -e "$e4/lib/libembree4.so.4" ] && [ -f "$e4/include/embree4/rtcore.h" ] && [ -f "$e4/VERSIONS" ] \
    && grep -q "embreex4 $wheel_version" "$e4/VERSIONS" && grep -q "embree4-sys $crate_version" "$e4/VERSIONS"; then
    exit 0
fi
echo "install-deps: installing Embree 4 into $e4 (embreex4 $wheel_version from PyPI, embree4-sys $crate_version headers from crates.io)" >&2
tmp="$(mktemp -d)"
trap 'rm -rf "$tmp"' EXIT
rm -rf "$e4"
mkdir -p "$e4/lib" "$e4/include"

# The library: only the wheel's shared libraries, not its Python module.
python3 -m pip download -q --no-deps --only-binary=:all: --python-version 3.11 --platform manylinux_2_28_x86_64 \
    "embreex4==$wheel_version" -d "$tmp/wheel"
python3 - "$tmp/wheel" "$e4/lib" <<'PY'
import glob, os, sys, zipfile
wheel = glob.glob(os.path.join(sys.argv[1], "*.whl"))[0]
out = sys.argv[2]
with zipfile.ZipFile(wheel) as z:
    libs = [n for n in z.namelist() if n.startswith("embreex4.libs/") and ".so" in n]
    for n in libs:
        path = os.path.join(out, os.path.basename(n))
        with open(path, "wb") as f:
            f.write(z.read(n))
        os.chmod(path, 0o755)
embree = [os.path.basename(n) for n in libs if os.path.basename(n).startswith("libembree4")]
if len(embree) != 1:
    sys.exit(f"install-deps: expected one libembree4 in {wheel}, found {embree}")
os.symlink(embree[0], os.path.join(out, "libembree4.so.4"))
PY

# The headers: the embree4-sys crate's copy, fetched through cargo from crates.io.
mkdir -p "$tmp/crate/src"
cat > "$tmp/crate/Cargo.toml" <<EOF
[package]
name = "fetch-embree4-headers"
version = "0.0.0"
edition = "2021"
[dependencies]
embree4-sys = "=$crate_version"
EOF
echo "fn main() {}" > "$tmp/crate/src/main.rs"
(cd "$tmp/crate" && cargo vendor -q --versioned-dirs "$tmp/vendor" >/dev/null)
cp -r "$tmp/vendor/embree4-sys-$crate_version/lib/embree4" "$e4/include/"
cp "$tmp/vendor/embree4-sys-$crate_version/LICENSE" "$e4/include/embree4/LICENSE-embree4-sys" 2>/dev/null || true
printf 'embreex4 %s (PyPI)\nembree4-sys %s (crates.io)\n' "$wheel_version" "$crate_version" > "$e4/VERSIONS"
echo "install-deps: Embree 4 ready in $e4" >&2
