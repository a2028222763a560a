# Sourced by the command-line tests (tests/app/test_*.sh) after they set
# T (their temporary folder): the checks they share.
#   expect CODE CMD...   runs CMD, stdout to $T/out, stderr to $T/err; a
#                        failure unless it exits CODE
#   mentions TEXT        a failure unless $T/err holds TEXT
#   fail MESSAGE         counts a failure (the script ends with finish)
#   py ARGS...           python3 as itself: the sanitizer build's preload
#                        (LeakSanitizer) and a version manager's shim left out
#   finish NAME          prints the outcome, exits 1 when anything failed
#   repeat_frame SEQ depth|rgb K
#                        in the TUM folder SEQ, frame K's image becomes a
#                        byte-for-byte copy of frame K-1's (a driver handing
#                        on its last image)
fails=0
fail() { echo "FAIL: $*"; fails=$((fails + 1)); }
expect() {
    local want=$1
    shift
    "$@" >"$T/out" 2>"$T/err"
    local rc=$?
    [ "$rc" = "$want" ] || fail "exit $rc, expected $want: $* ($(head -c 400 "$T/err"))"
}
mentions() { grep -qF -- "$1" "$T/err" || fail "stderr does not mention '$1': $(head -c 400 "$T/err")"; }
command -v python3 >/dev/null || { echo "no python3"; exit 77; }
PY3=$(env -u LD_PRELOAD python3 -c 'import sys; print(sys.executable)') # the interpreter, not a shim
py() { env -u LD_PRELOAD -u ASAN_OPTIONS -u LSAN_OPTIONS "$PY3" "$@"; }
export BITFUSE_PROGRESS=0
# The sanitizer build pins the drivers for LeakSanitizer (pin_drivers.c,
# itself built with ASan) in the program alone: preloaded into every grep, cp
# and head as well, it started ASan's runtime in each, a quarter of a second a
# command, about half of test_cli's time. With BF_TEST_PRELOAD set, B becomes
# a wrapper that preloads it and execs the program (same process, so signals
# sent to its PID reach the program).
if [ -n "${BF_TEST_PRELOAD:-}" ] && [ -n "${B:-}" ]; then
    export BF_TEST_BIN=$B
    printf '#!/bin/sh\nLD_PRELOAD="$BF_TEST_PRELOAD" exec "$BF_TEST_BIN" "$@"\n' >"$T/.bitfuse-preloaded"
    chmod +x "$T/.bitfuse-preloaded"
    B=$T/.bitfuse-preloaded
fi
repeat_frame() {
    local list="$1/$2.txt" k=$3
    local prev cur
    prev=$(awk -v n="$k" '!/^#/ {i++; if (i == n) print $2}' "$list")
    cur=$(awk -v n="$((k + 1))" '!/^#/ {i++; if (i == n) print $2}' "$list")
    cp "$1/$prev" "$1/$cur"
}
finish() {
    if [ "$fails" = 0 ]; then
        echo "$1: all passed"
    else
        echo "$1: $fails failed"
        exit 1
    fi
}
