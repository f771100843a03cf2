#!/usr/bin/env bash
# Installs (Debian packages munge, slurmctld, slurmd, slurm-client) and starts a one-node Slurm
# on this machine with .ci/slurm/slurm.conf, for the `femu batch --slurm` test. Idempotent: a
# Slurm that already answers is left as it is. Never fails the caller: where Slurm cannot be
# had (not root, no apt, another slurm.conf in place) it says so and the test skips.
set -uo pipefail
here="$(cd "$(dirname "$0")" && pwd)"
say() { echo "slurm: $*"; }

node_state() { sinfo -h -n femu-node -o %T 2>/dev/null | head -n1; }

if command -v sinfo >/dev/null 2>&1 && [ "$(node_state)" = idle ]; then
    say "a Slurm with node femu-node already answers (idle); nothing to do"
    exit 0
fi
if [ "$(id -u)" != 0 ]; then
    say "not root: cannot install or start Slurm; the Slurm test will be skipped"
    exit 0
fi
if ! command -v slurmctld >/dev/null 2>&1 || ! command -v slurmd >/dev/null 2>&1 \
    || ! command -v munged >/dev/null 2>&1 || ! command -v sbatch >/dev/null 2>&1; then
    say "installing munge, slurmctld, slurmd, slurm-client (apt-get)"
    if ! (apt-get update -qq && DEBIAN_FRONTEND=noninteractive apt-get install -y -qq \
        --no-install-recommends munge slurmctld slurmd slurm-client >/dev/null); then
        say "warning: could not install Slurm; the Slurm test will be skipped"
        exit 0
    fi
fi
conf=/etc/slurm/slurm.conf
if [ -f "$conf" ] && ! grep -q '^ClusterName=femu-ci' "$conf"; then
    say "warning: $conf exists and is not femu's CI configuration: left alone; the Slurm test skips unless that Slurm answers"
    exit 0
fi
mkdir -p /etc/slurm /var/spool/slurmctld /var/spool/slurmd /var/log/slurm
cp "$here/slurm.conf" "$conf"

# munge: the authentication daemon Slurm's daemons and clients talk through.
if ! (munge -n | unmunge) >/dev/null 2>&1; then
    say "starting munged"
    mkdir -p /run/munge /var/log/munge /var/lib/munge
    chown munge:munge /run/munge /var/log/munge /var/lib/munge
    [ -s /etc/munge/munge.key ] || { /usr/sbin/mungekey -c -f >/dev/null 2>&1 || true; chown munge:munge /etc/munge/munge.key; }
    runuser -u munge -- /usr/sbin/munged || say "warning: munged did not start"
fi
if ! scontrol ping 2>/dev/null | grep -q 'is UP'; then
    say "starting slurmctld"
    /usr/sbin/slurmctld || say "warning: slurmctld did not start (see /var/log/slurm/slurmctld.log)"
fi
if ! [ -f /run/slurmd.pid ] || ! kill -0 "$(cat /run/slurmd.pid)" 2>/dev/null; then
    say "starting slurmd (node femu-node)"
    /usr/sbin/slurmd -N femu-node || say "warning: slurmd did not start (see /var/log/slurm/slurmd.log)"
fi
for _ in $(seq 1 30); do
    state="$(node_state)"
    case "$state" in
        idle|mixed|allocated) say "node femu-node is $state: Slurm ready"; exit 0 ;;
        down*|drain*) scontrol update nodename=femu-node state=resume >/dev/null 2>&1 || true ;;
    esac
    sleep 1
done
say "warning: node femu-node not ready after 30 s (state '$(node_state)'); the Slurm test will be skipped"
exit 0
