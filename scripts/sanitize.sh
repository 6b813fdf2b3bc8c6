#!/usr/bin/env bash
# Build the three C extensions (engine/_core.c, engine/_input.c, control/osc/_fast.c) with
# AddressSanitizer and UndefinedBehaviorSanitizer in a temporary copy of the checkout (the
# in-place build is left alone), and run the C-facing tests against them: the hostile-API
# tests of issue 31, the engine core, the input ring and the OSC fast path. Any sanitizer
# report, in pytest or in a child process it starts, fails the script.
#
#   scripts/sanitize.sh                 # the default test files, with gcc
#   SANITIZE_CC=clang scripts/sanitize.sh
#   scripts/sanitize.sh tests/engine/test_core_hostile.py -k init   # other tests (pytest arguments)
#   scripts/sanitize.sh -x --durations 10                           # the default tests, more options
set -euo pipefail
cd "$(dirname "$0")/.."
root=$(pwd)
py="$root/.venv/bin/python"
cc=${SANITIZE_CC:-gcc}

# -fsanitize=undefined leaves out float-cast-overflow in gcc (NaN/inf/huge double -> integer):
# asked for by name. -fwrapv (Python's own CFLAGS) stays: signed overflow is defined there.
flags="-fsanitize=address,undefined,float-cast-overflow -fno-sanitize-recover=undefined,float-cast-overflow"
flags="$flags -fno-omit-frame-pointer -g -O1"
case "$cc" in
  clang*)
    flags="$flags -shared-libasan"
    runtime=$("$cc" -print-file-name=libclang_rt.asan-x86_64.so)
    ;;
  *) runtime=$("$cc" -print-file-name=libasan.so) ;;
esac
if [ ! -e "$runtime" ]; then
  echo "sanitize: no ASan runtime for $cc ($runtime)" >&2
  exit 1
fi

tmp=$(mktemp -d "${TMPDIR:-/tmp}/vibsynth-sanitize.XXXXXX")
trap 'rm -rf "$tmp"' EXIT
# The package, the tests and the build files, without the in-place extensions or caches.
tar -cf - --exclude='*.so' --exclude='*.pyd' --exclude=__pycache__ setup.py pyproject.toml vibsynth tests |
  tar -xf - -C "$tmp"
cd "$tmp"
start=$(date +%s)
CC="$cc" LDSHARED="$cc -shared" CFLAGS="$flags" LDFLAGS="$flags" \
  "$py" setup.py -q build_ext --inplace >"$tmp/build.log" 2>&1 || { cat "$tmp/build.log" >&2; exit 1; }

mkdir -p "$tmp/reports"
export LD_PRELOAD="$runtime"
# Python leaks by design (interned objects, module state): no leak report. An ASan report also
# goes to a file per process, so one from a child process fails the run even if its exit status
# were ignored. A UBSan report (gcc's separate runtime ignores log_path) halts its process with
# status 1: pytest (a crashed worker) or run_python (tests/isolated.py) fails on it.
export ASAN_OPTIONS="detect_leaks=0:abort_on_error=1:halt_on_error=1:log_path=$tmp/reports/asan"
export UBSAN_OPTIONS="halt_on_error=1:print_stacktrace=1"
export PYTHONDONTWRITEBYTECODE=1

# The copy's extensions, not the checkout's: the current folder comes first on sys.path.
"$py" - "$tmp" <<'EOF'
import sys
from vibsynth.control.osc import _fast
from vibsynth.engine import _core, _input
for module in (_core, _input, _fast):
    assert module.__file__.startswith(sys.argv[1]), f"{module.__name__} from {module.__file__}"
EOF

# Arguments that start with a test path replace the default files; others (-x, -k ...) add to them.
# (The one test left out starts a whole `vibsynth serve`: Python start-up, 20 s under ASan.)
if [ $# -eq 0 ] || [ ! -e "${1%%::*}" ]; then
  set -- "$@" tests/engine/test_core_hostile.py tests/engine/test_input_hostile.py \
    tests/control/osc/test_fast_hostile.py tests/engine/test_engine.py tests/engine/test_input_ring.py \
    tests/engine/test_layers_voices_tap.py tests/engine/test_trims.py tests/control/osc/test_fast.py \
    tests/control/osc/test_fast_queue.py tests/control/osc/test_monitor_fast.py \
    --deselect tests/control/osc/test_fast.py::test_serve_starts_with_the_longest_prefix_on_the_most_channels
fi
status=0
# --capture=sys: a report written to fd 2 by a halting process reaches the terminal (fd capture
# would lose it); --max-worker-restart 0: a crashed worker ends the run.
"$py" -m pytest -q -p no:cacheprovider -p no:benchmark -n 2 --dist loadfile --max-worker-restart 0 --capture=sys "$@" || status=$?
if compgen -G "$tmp/reports/*" >/dev/null; then
  echo "sanitize: sanitizer reports:" >&2
  cat "$tmp"/reports/* >&2
  status=1
fi
echo "sanitize: $cc ASan+UBSan build and tests: $(($(date +%s) - start)) s, exit $status"
exit $status
