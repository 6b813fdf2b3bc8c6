#!/usr/bin/env bash
# Run a command with a private JACK server on the dummy driver (real-time paced, no sound card).
#   scripts/with_jack.sh [--rate HZ] [--period FRAMES] [--playback PORTS] [--capture PORTS] [--async] -- COMMAND...
# The dummy device has 16 playback ports by default (the 4 x 4 vest layout, docs/vr.md), so
# multi-channel outputs open on it, and 8 capture ports (system:capture_1..8, silent), so
# inputs (serve --follow, calibration) open on it too.
# The server gets a unique name (JACK_DEFAULT_SERVER), so several runs can coexist;
# it is stopped only after COMMAND has exited (PortAudio aborts if JACK vanishes under it).
# The server runs in synchronous mode (-S): each cycle ends only when every client has processed
# it, so a client that is late (a Python capture client waiting for the GIL, a PortAudio stream
# whose thread a loaded VM scheduled late) makes the cycle late instead of leaving its previous
# buffer in the graph. What a capture records is then exactly what the streams played, whatever
# the scheduler did; lateness still shows as xruns (PortAudio's underflow count), which only the
# benchmarks measure (docs/engine.md, "What the tests assert"). --async runs JACK's default mode.
set -u
mode=-S
rate=48000; period=128; playback=16; capture=8
while [ $# -gt 0 ]; do
  case "$1" in
    --rate) rate=$2; shift 2;;
    --period) period=$2; shift 2;;
    --playback) playback=$2; shift 2;;
    --capture) capture=$2; shift 2;;
    --async) mode=""; shift;;
    --) shift; break;;
    *) break;;
  esac
done
export JACK_DEFAULT_SERVER="vibsynth-$$"
export JACK_NO_AUDIO_RESERVATION=1
# Free the registry slots of JACK servers that died uncleanly (8 slots per machine; a killed
# private server keeps its slot and jackd then refuses: "Too many servers already active").
python3 "$(dirname "$0")/jack_reclaim.py" || true
jackd -n "$JACK_DEFAULT_SERVER" $mode -R -d dummy -r "$rate" -p "$period" -P "$playback" -C "$capture" >"/tmp/jackd-$JACK_DEFAULT_SERVER.log" 2>&1 &
jack_pid=$!
# Stop the server whatever happens to this script (a killed test run must not leave a
# real-time jackd behind: a stray one steals the CPU from the next run's audio thread).
trap 'kill "$jack_pid" 2>/dev/null; wait "$jack_pid" 2>/dev/null' EXIT
trap 'exit 130' INT TERM
if ! jack_wait -w -t 10 >/dev/null 2>&1; then
  # Without real-time privileges jackd -R can fail: fall back to a non-RT server.
  kill "$jack_pid" 2>/dev/null; wait "$jack_pid" 2>/dev/null
  jackd -n "$JACK_DEFAULT_SERVER" $mode -d dummy -r "$rate" -p "$period" -P "$playback" -C "$capture" >"/tmp/jackd-$JACK_DEFAULT_SERVER.log" 2>&1 &
  jack_pid=$!
  trap 'kill "$jack_pid" 2>/dev/null; wait "$jack_pid" 2>/dev/null' EXIT
  if ! jack_wait -w -t 10 >/dev/null 2>&1; then
    echo "with_jack.sh: jackd did not start; log:" >&2; cat "/tmp/jackd-$JACK_DEFAULT_SERVER.log" >&2
    kill "$jack_pid" 2>/dev/null; exit 1
  fi
fi
export VIBSYNTH_JACK_RATE=$rate VIBSYNTH_JACK_PERIOD=$period
"$@"
exit $?
