#!/usr/bin/env bash
# The ./fusionloc entry script: --help documents every subcommand it dispatches; unknown
# commands fail with a message; setup is a no-op when everything is installed.
set -uo pipefail
ROOT="$1"
fail() { echo "FAIL: $*"; exit 1; }
help=$("$ROOT/fusionloc" --help) || fail "--help exited non-zero"
# Every subcommand in the dispatcher's case statement is explained in --help.
cmds=$(sed -n '/^main()/,/^}/p' "$ROOT/fusionloc" | grep -oE '^\s+[a-z|-]+\)' | tr -d ' )' | tr '|' '\n' | grep -v -- '^-' | sort -u)
[ -n "$cmds" ] || fail "could not read the subcommands from the script"
for c in $cmds; do
  echo "$help" | grep -qE "^  $c( |$)" || fail "subcommand '$c' is not explained in --help"
done
# `./fusionloc CMD --help` prints that command's help and exits 0 without building anything
# (an empty build folder stays empty) or starting anything.
empty=$(mktemp -d)
for c in $cmds; do
  [ "$c" = help ] && continue
  out=$(FL_BUILD_DIR="$empty/build" "$ROOT/fusionloc" "$c" --help 2>&1) || fail "'$c --help' exited non-zero: $out"
  echo "$out" | grep -qE "^  $c( |$)" || fail "'$c --help' does not show its help: $out"
  [ ! -e "$empty/build" ] || fail "'$c --help' started a build"
done
out=$(FL_BUILD_DIR="$empty/build" "$ROOT/fusionloc" bench laser --help 2>&1) || fail "'bench laser --help' exited non-zero"
echo "$out" | grep -q "laser" || fail "'bench --help' does not list the benchmarks: $out"
rm -rf "$empty"
out=$("$ROOT/fusionloc" no-such-command 2>&1) && fail "unknown command exited 0"
echo "$out" | grep -q "unknown command 'no-such-command'" || fail "no clear error for an unknown command: $out"
out=$("$ROOT/fusionloc" build --bogus 2>&1) && fail "bad build option exited 0"
echo "$out" | grep -q "unknown option '--bogus'" || fail "no clear error for a bad build option"
if [ -z "$(grep -v '^\s*#' "$ROOT/config/debian-packages.txt" | awk 'NF{print $1}' | xargs -n1 sh -c 'dpkg-query -W -f="\${Status}" "$0" 2>/dev/null | grep -q "install ok installed" || echo "$0"')" ]; then
  out=$("$ROOT/fusionloc" setup 2>&1) || fail "setup failed with everything installed: $out"
  echo "$out" | grep -q "packages present" || fail "setup did not report that all packages are present"
fi
echo "ok: subcommands $(echo $cmds)"
