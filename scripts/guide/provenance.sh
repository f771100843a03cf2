# Provenance of a measurement, shared by the scripts that measure for the guide
# (scripts/guide/measure.sh, scripts/guide/verify.sh); sourced, not run:
#
#   . scripts/guide/provenance.sh        # from the repository's root
#   write_provenance DIR/provenance.json COMMAND...
#
# writes a JSON object with the date (UTC), the machine (CPU model, cores, memory, kernel), the
# commit of the sources (COMMIT=... when the binary was built from another commit than this
# clone's HEAD; "with uncommitted changes" when crates/ differs from it), the build (BUILD=...,
# default "release build"), the load average when the measurement started and the command (the
# binary's path in FEMU_BIN, when set, written as `femu`).

provenance_commit=${COMMIT:-$(git rev-parse --short HEAD)$(git diff --quiet HEAD -- crates Cargo.toml Cargo.lock || echo " with uncommitted changes")}
provenance_machine="$(grep -m1 'model name' /proc/cpuinfo | cut -d: -f2 | sed 's/^ *//'), $(nproc) cores, $(awk '/MemTotal/ {printf "%.0f GiB", $2 / 1048576}' /proc/meminfo), $(uname -sr)"

write_provenance() { # FILE COMMAND...
    local file=$1
    shift
    python3 - "$file" "$provenance_machine" "$provenance_commit" "${BUILD:-release build}" "$*" <<'PY'
import datetime, json, os, sys
path, machine, commit, build, command = sys.argv[1:]
femu = os.environ.get("FEMU_BIN", "")
json.dump({
    "date": datetime.datetime.now(datetime.timezone.utc).strftime("%Y-%m-%d %H:%M UTC"),
    "machine": machine, "commit": commit, "build": build,
    "load": "%.1f" % os.getloadavg()[0], "command": command.replace(femu, "femu") if femu else command,
}, open(path, "w"), indent=1)
print(file=open(path, "a"))
PY
}
