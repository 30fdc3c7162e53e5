#!/usr/bin/env bash
# Build and install the clutch_msgs ROS 2 interface package into the venv prefix
# (the venv root is the ROS install prefix of the PyPI ROS wheels; see README.md, "Install").
#
#   tools/build_msgs.sh [--force]        VENV=/path/to/venv overrides .venv
#
# Idempotent: skipped when the stamp in the venv matches the hash of the package
# sources (msg/, CMakeLists.txt, package.xml), requirements.txt and this script,
# and the installed artefacts are present.
set -euo pipefail

SELF="$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)/$(basename "${BASH_SOURCE[0]}")"
REPO="$(dirname "$(dirname "$SELF")")"
VENV="$(cd "${VENV:-$REPO/.venv}" && pwd)"
PKG_SRC="$REPO/msg_defs/clutch_msgs"
BUILD_DIR="$REPO/build/clutch_msgs"
STAMP="$VENV/.clutch_msgs.stamp"
PY="$VENV/bin/python"
FORCE=0
[[ "${1:-}" == "--force" ]] && FORCE=1

[[ -x "$PY" ]] || { echo "build_msgs: no venv python at $PY" >&2; exit 1; }

# ---- up-to-date check (pure bash, no Python start-up) -----------------------
key="$(
  {
    echo "venv=$VENV"
    (cd "$PKG_SRC" && find . -type f \( -name '*.msg' -o -name '*.srv' -o -name '*.action' \
        -o -name 'CMakeLists.txt' -o -name 'package.xml' -o -name '*.cmake' \) | LC_ALL=C sort \
      | while read -r f; do echo "$f $(sha256sum < "$f")"; done)
    if [[ -f "$REPO/requirements.txt" ]]; then sha256sum < "$REPO/requirements.txt"; fi
    sha256sum < "$SELF"
  } | sha256sum | cut -d' ' -f1
)"
site="$(echo "$VENV"/lib/python3*/site-packages)"
installed_ok() {
  [[ -f "$site/clutch_msgs/msg/_clutch_state.py" ]] &&
  compgen -G "$site/clutch_msgs/clutch_msgs_s__rosidl_typesupport_fastrtps_c*.so" > /dev/null &&
  [[ -f "$VENV/lib/libclutch_msgs__rosidl_typesupport_c.so" ]] &&
  [[ -f "$VENV/share/ament_index/resource_index/rosidl_interfaces/clutch_msgs" ]]
}
if [[ $FORCE == 0 && -f "$STAMP" && "$(cat "$STAMP")" == "$key" ]] && installed_ok; then
  echo "build_msgs: clutch_msgs up to date"
  exit 0
fi

echo "build_msgs: building clutch_msgs into $VENV"
command -v cmake > /dev/null || { echo "build_msgs: cmake not found" >&2; exit 1; }

# ---- fix the manylinux include paths baked into the wheels' CMake exports ---
"$PY" - <<'PYEOF'
import glob, os, re, sys, sysconfig
import numpy
venv = sys.prefix
py_inc = sysconfig.get_paths()["include"]
np_inc = numpy.get_include()
pats = [
    # numpy first: it is longer and starts with the python prefix
    (re.compile(r"/opt/python/cp3\d+-cp3\d+/lib/python3\.\d+/site-packages/numpy/(?:_core/|core/)?include"), np_inc),
    (re.compile(r"/opt/python/cp3\d+-cp3\d+/include/python3\.\d+"), py_inc),
]
fixed = 0
for path in glob.glob(os.path.join(venv, "share", "*", "cmake", "*.cmake")):
    with open(path, encoding="utf-8", errors="surrogateescape") as f:
        text = f.read()
    if "/opt/python/" not in text:
        continue
    new = text
    for rx, repl in pats:
        new = rx.sub(lambda m: repl, new)
    if new != text:
        with open(path, "w", encoding="utf-8", errors="surrogateescape") as f:
            f.write(new)
        fixed += 1
print(f"build_msgs: rewrote manylinux include paths in {fixed} CMake file(s)")
PYEOF

# ---- configure, build, install with plain cmake ------------------------------
export PATH="$VENV/bin:$PATH"
export CMAKE_PREFIX_PATH="$VENV"
export AMENT_PREFIX_PATH="$VENV"
unset PYTHONPATH || true
JOBS="$(nproc 2>/dev/null || echo 2)"

rm -f "$STAMP"
mkdir -p "$(dirname "$BUILD_DIR")"
if [[ -f "$BUILD_DIR/CMakeCache.txt" ]] && ! grep -q "^CMAKE_INSTALL_PREFIX:PATH=$VENV\$" "$BUILD_DIR/CMakeCache.txt"; then
  rm -rf "$BUILD_DIR"   # build dir belongs to another venv
fi
cmake -S "$PKG_SRC" -B "$BUILD_DIR" \
  -DCMAKE_INSTALL_PREFIX="$VENV" \
  -DPython3_EXECUTABLE="$PY" \
  -DCMAKE_BUILD_TYPE=Release \
  -DBUILD_TESTING=OFF > "$BUILD_DIR.configure.log" 2>&1 \
  || { cat "$BUILD_DIR.configure.log" >&2; echo "build_msgs: cmake configure failed" >&2; exit 1; }
cmake --build "$BUILD_DIR" -j "$JOBS" > "$BUILD_DIR.build.log" 2>&1 \
  || { tail -50 "$BUILD_DIR.build.log" >&2; echo "build_msgs: build failed (log $BUILD_DIR.build.log)" >&2; exit 1; }
cmake --install "$BUILD_DIR" > "$BUILD_DIR.install.log" 2>&1 \
  || { tail -50 "$BUILD_DIR.install.log" >&2; echo "build_msgs: install failed" >&2; exit 1; }

# ---- verify -----------------------------------------------------------------
installed_ok || { echo "build_msgs: installed files missing after install" >&2; exit 1; }
"$PY" -c "from clutch_msgs.msg import ClutchState; ClutchState()" \
  || { echo "build_msgs: 'from clutch_msgs.msg import ClutchState' fails" >&2; exit 1; }
echo "$key" > "$STAMP"
echo "build_msgs: clutch_msgs installed"
