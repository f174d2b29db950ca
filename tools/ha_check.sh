#!/usr/bin/env bash
# tools/check_ha_discovery.py with one Home Assistant version of `make test-ha` (installed
# by tools/ha_env.sh in the chroot ROOT): the discovery snapshots of tests/golden/discovery
# and the extreme state cases (computed here by the bridge's PYTHON) are copied into the
# chroot and checked there.
#
#     tools/ha_check.sh ~/.cache/modbus-mqtt-bridge/ha-forky 2026.11.0 .venv/bin/python
set -euo pipefail
root=$1 version=$2 python=${3:-.venv/bin/python}
work=$(mktemp -d "$root/tmp/check-XXXXXX")
trap 'rm -rf "$work"' EXIT
inside=/tmp/$(basename "$work")
cp tools/check_ha_discovery.py "$work/"
cp -r tests/golden/discovery "$work/discovery"
"$python" -m tests.extreme_states >"$work/cases.json"
chroot "$root" env -i PATH=/usr/bin:/bin HOME=/root LANG=C.UTF-8 \
  sh -c "cd $inside && /opt/ha-$version/bin/python check_ha_discovery.py --states-from cases.json discovery/*.json"
