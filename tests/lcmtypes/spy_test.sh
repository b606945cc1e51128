#!/usr/bin/env bash
# lcm-spy, started by `./fusionloc spy` under a virtual display, finds every project type.
set -euo pipefail
ROOT="$1"; BUILD="$2"
expected=$(find "$ROOT/lcmtypes" -name '*.lcm' | wc -l)
command -v xvfb-run >/dev/null || { echo "xvfb-run missing: run ./fusionloc setup"; exit 1; }
out=$(mktemp)
FL_BUILD_DIR="$BUILD" setsid xvfb-run -a "$ROOT/fusionloc" spy memq:// >"$out" 2>&1 &
pid=$!
for _ in $(seq 1 100); do
  grep -q "LCM types" "$out" && break
  sleep 0.2
done
kill -- -"$pid" 2>/dev/null || kill "$pid" 2>/dev/null || true
wait "$pid" 2>/dev/null || true
cat "$out"
if grep -q "Found $expected LCM types" "$out"; then rm -f "$out"; exit 0; fi
rm -f "$out"
echo "FAIL: expected lcm-spy to print 'Found $expected LCM types'"
exit 1
