#!/usr/bin/env bash
# Runs a command with DISPLAY on a virtual X server of its own (Xvfb, the
# first free display of :90..:99), and passes its exit code on; exits 77
# (skip) when Xvfb is not installed or does not start.
# Usage: with_xvfb.sh COMMAND [ARGS...]
set -u
command -v Xvfb >/dev/null || { echo "skip: no Xvfb (Debian: xvfb)"; exit 77; }
LOG=$(mktemp)
XPID=
trap '[ -n "$XPID" ] && kill "$XPID" 2>/dev/null; rm -f "$LOG"' EXIT
for n in 90 91 92 93 94 95 96 97 98 99; do
    [ -e /tmp/.X$n-lock ] && continue
    Xvfb :$n -screen 0 640x480x24 -nolisten tcp >"$LOG" 2>&1 &
    XPID=$!
    for _ in $(seq 50); do [ -e /tmp/.X11-unix/X$n ] && break; sleep 0.1; done
    if [ -e /tmp/.X11-unix/X$n ] && kill -0 "$XPID" 2>/dev/null; then
        DISPLAY=:$n "$@"
        exit $?
    fi
    kill "$XPID" 2>/dev/null
    XPID=
done
echo "skip: Xvfb did not start: $(head -c 300 "$LOG")"
exit 77
