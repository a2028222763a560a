#!/usr/bin/env bash
# Runs a command with DISPLAY on a virtual X server of its own (Xvfb picks a
# free display number itself, -displayfd, so tests running in parallel each
# get their own) and passes its exit code on; exits 77 (skip) when Xvfb is
# not installed or does not start.
# Usage: with_xvfb.sh COMMAND [ARGS...]
set -u
command -v Xvfb >/dev/null || { echo "skip: no Xvfb (Debian: xvfb)"; exit 77; }
D=$(mktemp -d)
XPID=
trap '[ -n "$XPID" ] && kill "$XPID" 2>/dev/null; rm -rf "$D"' EXIT
Xvfb -displayfd 3 -screen 0 640x480x24 -nolisten tcp 3>"$D/display" >"$D/log" 2>&1 &
XPID=$!
for _ in $(seq 100); do
    [ -s "$D/display" ] && break
    kill -0 "$XPID" 2>/dev/null || break
    sleep 0.1
done
n=$(head -1 "$D/display" 2>/dev/null)
if [ -z "$n" ] || ! kill -0 "$XPID" 2>/dev/null; then
    echo "skip: Xvfb did not start: $(head -c 300 "$D/log")"
    exit 77
fi
DISPLAY=:$n "$@"
