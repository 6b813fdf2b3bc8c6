#!/usr/bin/env bash
# Fuzz the OSC input paths for a bounded time: the fast path's datagram parser (libFuzzer on
# vibsynth/control/osc/_fast.c, ASan + UBSan, fuzz/fuzz_datagram.c) and the OSC/TCP framing
# (atheris on vibsynth/control/osc/transport.py, fuzz/fuzz_tcp_framing.py). Docs: docs/osc.md#fuzzing.
#
#   scripts/fuzz.sh                      # 60 s in all, building included (what scripts/test.sh runs)
#   scripts/fuzz.sh --minutes 30         # longer, on demand; the corpus grows in build/fuzz/work/
#   scripts/fuzz.sh --seconds 20 --target tcp
#   scripts/fuzz.sh --replay datagram FILE...   # run inputs once (a reproducer, fuzz/corpus/...)
#
# The time (wall clock, building and start-up included) is shared evenly between the targets. Each starts from the seeds fuzz/seeds.py makes
# from docs/osc.md, the regression corpus fuzz/corpus/<target>/ (every crash input found, kept
# after its fix: replayed first by every run) and what earlier runs found (build/fuzz/work/).
# A crash, a sanitizer report or a broken check fails the run and names the reproducer.
set -euo pipefail
cd "$(dirname "$0")/.."

start=$SECONDS
seconds=60
targets="datagram tcp"
replay=""
while [ $# -gt 0 ]; do
  case "$1" in
    --seconds) seconds="$2"; shift 2 ;;
    --minutes) seconds=$(( $2 * 60 )); shift 2 ;;
    --target) targets="$2"; shift 2 ;;
    --replay) replay="$2"; shift 2; break ;;
    -h|--help) sed -n '2,15p' "$0"; exit 0 ;;
    *) echo "fuzz: unknown argument $1 (see --help)" >&2; exit 2 ;;
  esac
done

py=.venv/bin/python
out=build/fuzz
mkdir -p "$out"
export ASAN_OPTIONS="detect_leaks=0:abort_on_error=0:${ASAN_OPTIONS:-}"  # the embedded Python keeps its memory
export UBSAN_OPTIONS="print_stacktrace=1:halt_on_error=1:${UBSAN_OPTIONS:-}"
export PYTHONPATH="$PWD${PYTHONPATH:+:$PYTHONPATH}"  # fuzz_datagram imports vibsynth's OSC decoder

build_datagram() {
  local bin="$out/fuzz_datagram" src=fuzz/fuzz_datagram.c
  if [ -x "$bin" ] && [ "$bin" -nt "$src" ] && [ "$bin" -nt vibsynth/control/osc/_fast.c ] \
     && [ "$bin" -nt vibsynth/engine/_core_api.h ]; then
    return
  fi
  command -v clang >/dev/null || { echo "fuzz: clang is missing (bash scripts/setup.sh --test installs it)" >&2; exit 2; }
  local inc libdir ldver
  inc=$($py -c 'import sysconfig; print(sysconfig.get_paths()["include"])')
  libdir=$($py -c 'import sysconfig; print(sysconfig.get_config_var("LIBDIR"))')
  ldver=$($py -c 'import sysconfig; print(sysconfig.get_config_var("LDVERSION"))')
  clang -g -O1 -fsanitize=fuzzer,address,undefined -fno-sanitize-recover=all -I"$inc" "$src" -o "$bin.tmp" \
    -L"$libdir" -Wl,-rpath,"$libdir" "-lpython$ldver" -lm -ldl
  mv "$bin.tmp" "$bin"
}

# The command that runs a target with libFuzzer's options after it (built first: build_datagram).
runner() {
  case "$1" in
    datagram) echo "$out/fuzz_datagram -dict=$out/seeds/datagram.dict" ;;
    tcp) echo "$py fuzz/fuzz_tcp_framing.py -max_len=512" ;;
    *) echo "fuzz: unknown target $1 (datagram, tcp)" >&2; exit 2 ;;
  esac
}
for target in ${replay:-$targets}; do
  runner "$target" >/dev/null
  [ "$target" = datagram ] && build_datagram
done

rm -rf "$out/seeds"
$py fuzz/seeds.py "$out/seeds" >/dev/null

if [ -n "$replay" ]; then
  # shellcheck disable=SC2046
  exec $(runner "$replay") -runs=1 "$@"
fi
left=$(echo "$targets" | wc -w)
status=0
for target in $targets; do
  cmd=$(runner "$target")
  per=$(( (seconds - (SECONDS - start)) / left - 6 ))  # 6 s: a target's start-up, its corpus's first run, its stats
  [ "$per" -ge 5 ] || per=5
  left=$(( left - 1 ))
  work="$out/work/$target" artifacts="$out/artifacts/$target" log="$out/$target.log"
  mkdir -p "$work" "$artifacts" "fuzz/corpus/$target"
  set +e
  # shellcheck disable=SC2086
  $cmd -max_total_time="$per" -timeout=10 -rss_limit_mb=2048 -print_final_stats=1 \
    -artifact_prefix="$artifacts/" "$work" "$out/seeds/$target" "fuzz/corpus/$target" >"$log" 2>&1
  rc=$?
  set -e
  runs=$(sed -n 's/^stat::number_of_executed_units: *//p' "$log")
  rate=$(sed -n 's/^stat::average_exec_per_sec: *//p' "$log")
  cov=$( (grep -Eo '(INITED|DONE) +cov: [0-9]+ ft: [0-9]+ corp: [0-9]+' "$log" || true) | tail -1 | sed 's/  */ /g')
  if [ "$rc" -ne 0 ]; then
    status=1
    tail -n 40 "$log" >&2
    repro=$(sed -n 's/.*Test unit written to \(.*\)$/\1/p' "$log" | tail -1)
    echo "fuzz: $target FAILED (exit $rc); reproducer: ${repro:-none written, see $log}" >&2
    [ -n "$repro" ] && echo "fuzz: replay: scripts/fuzz.sh --replay $target $repro; after the fix keep it:" \
      "cp $repro fuzz/corpus/$target/" >&2
  else
    echo "fuzz: $target ok: ${runs:-?} runs in ${per} s (${rate:-?} exec/s), ${cov:-?}; log $log"
  fi
done
exit "$status"
