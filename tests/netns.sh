#!/usr/bin/env bash
# Run one command in a private network namespace with loopback up, so that the real PX4 and
# ArduPilot SITL (fixed ports) cannot collide with anything else on the machine.
# Usage: bash tests/netns.sh .venv/bin/python -m pytest tests/autopilot -q
# Needs root (or user namespaces) and iproute2; without them the command runs as it is and
# the real-autopilot tests skip, saying why.
set -euo pipefail
if [ "${GCS_UTM_NETNS:-}" != "1" ] && unshare --net true 2>/dev/null && command -v ip >/dev/null; then
    exec unshare --net env GCS_UTM_NETNS=1 bash -c 'ip link set lo up && exec "$@"' netns "$@"
fi
[ "${GCS_UTM_NETNS:-}" = "1" ] || echo "netns.sh: no private network namespace here: running as is" >&2
exec "$@"
