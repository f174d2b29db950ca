#!/usr/bin/env bash
# The Home Assistant installs `make test-ha` runs against, built once and kept under ROOT
# (make's HA_ROOT: ~/.cache/modbus-mqtt-bridge/ha-forky, shared by every clone on the machine): a Debian testing ("forky") chroot made by
# debootstrap, which has both Pythons Home Assistant needs (3.13 for 2025.x: 2025.10 wants
# at least 3.13.2; 3.14 for 2026.x: 2026.11 wants at least 3.14.2), with one venv per
# version in ROOT/opt/ha-VERSION. Needs root (debootstrap, chroot) and Debian's apt.
#
#     tools/ha_env.sh ~/.cache/modbus-mqtt-bridge/ha-forky 2025.10.4 2026.11.0
#
# A version is installed once (ROOT/opt/ha-VERSION/.ready); delete ROOT to start over.
set -euo pipefail
root=$1
shift
mirror=${DEBIAN_MIRROR:-http://deb.debian.org/debian}
python_of() { case $1 in 2025.*) echo python3.13 ;; *) echo python3.14 ;; esac; }
# Pins a version's own requirements leave open and newer releases broke: aiodns 3.5
# (2025.x) fails at import with pycares 5.
pins_of() { case $1 in 2025.*) echo "pycares<5" ;; esac; }

if [ ! -f "$root/.ready" ]; then
  command -v debootstrap >/dev/null 2>&1 || {
    apt-get update -qq && DEBIAN_FRONTEND=noninteractive apt-get install -y -qq debootstrap >/dev/null
  }
  rm -rf "$root"
  mkdir -p "$(dirname "$root")"
  # bookworm's debootstrap has no script named forky: testing is built like sid
  echo "ha_env: debootstrap forky into $root"
  debootstrap --variant=minbase \
    --include=python3.13,python3.13-venv,python3.13-dev,python3.14,python3.14-venv,python3.14-dev,build-essential,ca-certificates \
    forky "$root" "$mirror" /usr/share/debootstrap/scripts/sid >"$root.debootstrap.log" 2>&1 ||
    { tail -20 "$root.debootstrap.log"; exit 1; }
  touch "$root/.ready"
fi
cp /etc/resolv.conf "$root/etc/resolv.conf"
# the host's own certificate authorities (a TLS-inspecting proxy's, say) are trusted inside
# too; commands run with a clean environment (the host's variables name host paths)
run() { chroot "$root" env -i PATH=/usr/sbin:/usr/bin:/sbin:/bin HOME=/root LANG=C.UTF-8 "$@"; }
if compgen -G "/usr/local/share/ca-certificates/*.crt" >/dev/null; then
  cp /usr/local/share/ca-certificates/*.crt "$root/usr/local/share/ca-certificates/"
  run update-ca-certificates >/dev/null 2>&1
fi

# What the integrations the checks use require (mqtt: paho-mqtt; modbus: pymodbus), as their
# manifests in that version name it. A running Home Assistant installs them itself when it
# sets them up, but tools/check_ha_discovery.py imports the mqtt integration first.
integration_requirements() {
  run "/opt/ha-$1/bin/python" -c 'import json, pathlib, homeassistant.components as c
for name in ("mqtt", "modbus"):
    print(*json.loads((pathlib.Path(c.__file__).parent / name / "manifest.json").read_text())["requirements"])'
}

for version in "$@"; do
  venv=/opt/ha-$version
  if [ -f "$root$venv/.ready" ]; then
    # shellcheck disable=SC2046
    run "$venv/bin/pip" install --quiet $(integration_requirements "$version") $(pins_of "$version")
    continue
  fi
  python=$(python_of "$version")
  run test -x /usr/bin/"$python" || run sh -c \
    "apt-get -o Acquire::Check-Valid-Until=false update -qq && DEBIAN_FRONTEND=noninteractive apt-get install -y -qq $python $python-venv $python-dev >/dev/null"
  echo "ha_env: Home Assistant $version on $python in $root$venv"
  rm -rf "$root$venv"
  run "$python" -m venv "$venv"
  run "$venv/bin/pip" install --quiet --upgrade pip
  # shellcheck disable=SC2046
  run "$venv/bin/pip" install --quiet "homeassistant==$version" $(pins_of "$version")
  # shellcheck disable=SC2046
  run "$venv/bin/pip" install --quiet $(integration_requirements "$version") $(pins_of "$version")
  touch "$root$venv/.ready"
done
