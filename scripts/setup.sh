#!/usr/bin/env bash
# Set up vibsynth on Debian/Ubuntu: system libraries (PortAudio, JACK, liblo tools) and a
# virtual environment in .venv with the package installed in editable mode.
#   scripts/setup.sh [--test]     (--test also installs the test/research extras)
# System packages need root: run as root, or this script uses sudo for apt-get only.
set -euo pipefail
cd "$(dirname "$0")/.."
extras=""
[ "${1:-}" = "--test" ] && extras="[test]"

# gcc + python3-dev build the compiled real-time core (vibsynth/engine/_core.c) at pip install.
apt_packages="libportaudio2 jackd2 liblo-tools python3-venv python3-dev gcc"
# --test: a real browser for the studio's end-to-end tests, mono to compile and run the C# client,
# iproute2 (ip) for the discovery tests' private network namespaces.
[ -n "$extras" ] && apt_packages="$apt_packages chromium chromium-driver mono-mcs mono-runtime iproute2"
# --test: clang and libFuzzer (Debian 12's clang 14 ships it in libclang-rt-14-dev) for scripts/fuzz.sh.
[ -n "$extras" ] && apt_packages="$apt_packages clang libclang-rt-14-dev"
# --test: real sounds for the follow tests (speech, spoken channel names, desktop effects, recorded drum
# loops in lmms-common's samples/beats, and their Ogg decoder).
[ -n "$extras" ] && apt_packages="$apt_packages espeak-ng alsa-utils sound-theme-freedesktop vorbis-tools lmms-common"
# --test: mingw-w64 to cross-build the Windows wheel (scripts/wheels.sh windows; tests/scripts/test_wheels.py).
[ -n "$extras" ] && apt_packages="$apt_packages gcc-mingw-w64-x86-64-win32"
missing=""
for p in $apt_packages; do
  dpkg -s "$p" >/dev/null 2>&1 || missing="$missing $p"
done
if [ -n "$missing" ] && command -v apt-get >/dev/null 2>&1; then
  sudo=""
  [ "$(id -u)" -ne 0 ] && sudo="sudo"
  echo "setup: installing system packages:$missing (apt-get${sudo:+, via sudo})"
  $sudo apt-get update -qq
  # jackd2 asks about real-time priority; answer non-interactively.
  echo "jackd2 jackd/tweak_rt_limits boolean false" | $sudo debconf-set-selections 2>/dev/null || true
  DEBIAN_FRONTEND=noninteractive $sudo apt-get install -y -qq --no-install-recommends $missing >/dev/null
fi

python=${PYTHON:-python3}
if [ ! -x .venv/bin/python ]; then
  # --system-site-packages reuses numpy/scipy already on the machine (faster, works with local wheels).
  "$python" -m venv --system-site-packages .venv
fi
.venv/bin/python -m pip install -q --disable-pip-version-check -e ".${extras}"
echo "setup: ready (.venv/bin/vibsynth)"
