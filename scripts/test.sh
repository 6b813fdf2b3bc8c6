#!/usr/bin/env bash
# Set everything up, then run the whole test suite: unit tests, and end-to-end tests on a
# private JACK dummy server (real PortAudio stream, JACK MIDI, liblo's oscsend/oscdump).
# Extra args go to pytest.
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/setup.sh --test
export VIBSYNTH_E2E_REQUIRED=1       # e2e tests fail (not skip) if JACK or liblo is missing
export MIDO_BACKEND=${MIDO_BACKEND:-mido.backends.rtmidi/UNIX_JACK}
export PYTHONDONTWRITEBYTECODE=1
# Habits first: lint, formatting and types must have no findings (configured in pyproject.toml).
.venv/bin/ruff check vibsynth tests benchmarks scripts
.venv/bin/ruff format --check --quiet vibsynth tests benchmarks scripts
.venv/bin/mypy
exec scripts/with_jack.sh -- .venv/bin/python -m pytest -q -ra "$@"
