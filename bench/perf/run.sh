#!/usr/bin/env bash
# Performance figures of femu, the current binary side by side with a previous one:
#   bench/perf/run.sh [PREVIOUS_FEMU_BINARY] [run.py options ...]
# Without a previous binary, a release build of commit d9ac6d3 is made once into /tmp/femu_prev.
# Writes bench/perf/results.md (see run.py for the figures and the options).
set -euo pipefail
here="$(cd "$(dirname "$0")" && pwd)"
if [ $# -gt 0 ] && [ "${1#-}" = "$1" ]; then
    prev="$1"
    shift
    exec python3 "$here/run.py" --prev "$prev" "$@"
fi
exec python3 "$here/run.py" "$@"
