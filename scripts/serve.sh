#!/usr/bin/env bash
# Set everything up, then run `vibsynth serve` on the embedded defaults (falls back to a
# silent null output with a warning when there is no sound card). Extra args go to serve.
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/setup.sh
exec .venv/bin/vibsynth serve "$@"
