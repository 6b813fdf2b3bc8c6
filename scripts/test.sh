#!/usr/bin/env bash
# Set everything up, then run the whole test suite: unit tests, and end-to-end tests on a
# private JACK dummy server (real PortAudio stream, JACK MIDI, liblo's oscsend/oscdump).
# Extra args go to pytest (one serial run of what they select).
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/setup.sh --test
export VIBSYNTH_E2E_REQUIRED=1       # e2e tests fail (not skip) if JACK or liblo is missing
export MIDO_BACKEND=${MIDO_BACKEND:-mido.backends.rtmidi/UNIX_JACK}
export PYTHONDONTWRITEBYTECODE=1
# Habits first: lint, formatting and types must have no findings (configured in pyproject.toml).
.venv/bin/ruff check vibsynth tests benchmarks scripts fuzz
.venv/bin/ruff format --check --quiet vibsynth tests benchmarks scripts fuzz
# Fuzz the OSC parsers for 30 s in all (libFuzzer + ASan/UBSan on the fast path's datagram parser, atheris on the
# TCP framing; the regression corpus fuzz/corpus/ runs first): a crash fails the suite and names its
# reproducer. Longer on demand: scripts/fuzz.sh --minutes N (docs/osc.md, Fuzzing). Each fuzzer takes
# one core, so they run beside mypy (the other core); their output follows mypy's.
fuzz_log=$(mktemp)
scripts/fuzz.sh --seconds 30 >"$fuzz_log" 2>&1 &
fuzz_pid=$!
trap 'kill "$fuzz_pid" 2>/dev/null || true; rm -f "$fuzz_log"' EXIT
.venv/bin/mypy
# The science, the engine and the settings by mypy's own --strict (imports of the layers above, reached
# through the package's face, are read for their types; their findings belong to the line above).
.venv/bin/mypy --strict --follow-imports=silent --cache-dir .mypy_cache/strict vibsynth/dsp vibsynth/engine vibsynth/settings
fuzz_status=0
wait "$fuzz_pid" || fuzz_status=$?
cat "$fuzz_log"
trap - EXIT
rm -f "$fuzz_log"
[ "$fuzz_status" -eq 0 ] || exit "$fuzz_status"
scripts/sanitize.sh  # the C extensions under ASan/UBSan: the C-facing and hostile-API tests (docs/engine.md)
if [ $# -gt 0 ]; then
  exec scripts/with_jack.sh -- .venv/bin/python -m pytest -q -ra "$@"
fi
# The unit tests on two workers (pytest-xdist; a test file's tests stay on one worker: module
# fixtures and the docs runner's pages are made once; no two files share a file or a port), with
# the end-to-end files that measure no time (PARALLEL_SAFE: browser and client pages on the null
# output); then the other end-to-end tests (marked serial by tests/e2e/conftest.py) one at a time:
# they measure real-time behaviour against a quiet baseline, so nothing else may load the machine.
# Both run to the end; either failing fails. Each lists its 15 slowest tests (the suite must stay under
# 20 min; tests/conftest.py hands the longest files to the workers first).
exec scripts/with_jack.sh -- bash -c '
  status=0
  .venv/bin/python -m pytest -q -ra --durations=15 -n 2 --dist loadfile -m "not serial" tests || status=$?
  .venv/bin/python -m pytest -q -ra --durations=15 -m serial tests/e2e || status=$?
  exit $status'
