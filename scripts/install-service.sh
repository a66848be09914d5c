#!/usr/bin/env bash
# Install RAMP on the robot's SBC as the systemd service `ramp`. Safe to run again: every
# step checks what is already there (the user, the config, the venv) and keeps it.
#
#   sudo scripts/install-service.sh             install from this checkout and start
#   scripts/install-service.sh --dry-run        print the steps, change nothing
#   scripts/install-service.sh --root DIR ...   write under DIR (an SD-card image, a test);
#                                               skips steps that act on the running system
#
# What it does: a `ramp` system user in dialout and plugdev; the checkout copied to
# /opt/ramp with its own venv (`pip install '/opt/ramp[phidget]'`); /etc/ramp/ramp.yaml
# from ramp.yaml and scripts/ramp-service.yaml (MCP over mutual TLS, the flight recorder)
# if absent (yours is never overwritten); the robot's CA and certificate in
# /etc/ramp/certs if absent (`ramp certs init`); a udev rule giving plugdev the Phidgets (USB vendor 06c2); the unit
# in /etc/systemd/system; daemon-reload; enable --now.
set -euo pipefail

SRC="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
DRY_RUN=0
ROOT=""
PYTHON="${PYTHON:-python3}"

usage() {
    sed -n '2,14p' "${BASH_SOURCE[0]}" | sed 's/^# \{0,1\}//'
}

while [ $# -gt 0 ]; do
    case "$1" in
        --dry-run|-n) DRY_RUN=1 ;;
        --root)
            [ $# -ge 2 ] || { echo "install-service.sh: --root needs a directory" >&2; exit 2; }
            ROOT="${2%/}"
            shift ;;
        -h|--help) usage; exit 0 ;;
        *) echo "install-service.sh: unknown option $1 (try --help)" >&2; exit 2 ;;
    esac
    shift
done

APP="$ROOT/opt/ramp"
CONF_DIR="$ROOT/etc/ramp"
UNIT="$ROOT/etc/systemd/system/ramp.service"
RULE="$ROOT/etc/udev/rules.d/60-ramp-phidgets.rules"
# The running system is touched (users, systemctl, udevadm) only without --root.
LIVE=1
[ -z "$ROOT" ] || LIVE=0

step() { printf '==> %s\n' "$*"; }

# Print a command in dry-run mode, run it otherwise.
run() {
    if [ "$DRY_RUN" = 1 ]; then
        printf '    %s\n' "$*"
    else
        "$@"
    fi
}

# Write stdin to a file (mode 0644), or show what would be written.
write_file() {
    local path="$1" content
    content="$(cat)"
    if [ "$DRY_RUN" = 1 ]; then
        printf '    write %s:\n' "$path"
        printf '%s\n' "$content" | sed 's/^/      | /'
    else
        mkdir -p "$(dirname "$path")"
        printf '%s\n' "$content" > "$path"
        chmod 0644 "$path"
    fi
}

if [ "$DRY_RUN" = 0 ] && [ "$LIVE" = 1 ] && [ "$(id -u)" != 0 ]; then
    echo "install-service.sh: run as root (sudo), or use --dry-run" >&2
    exit 1
fi

step "user ramp (groups dialout, plugdev)"
if [ "$LIVE" = 0 ]; then
    echo "    skipped with --root: create it in the target system"
else
    for group in dialout plugdev; do
        if ! getent group "$group" > /dev/null; then
            run groupadd --system "$group"
        fi
    done
    if id ramp > /dev/null 2>&1; then
        run usermod --append --groups dialout,plugdev ramp
    else
        run useradd --system --user-group --home-dir /opt/ramp --no-create-home \
            --shell /usr/sbin/nologin --groups dialout,plugdev ramp
    fi
fi

step "libusb for the Phidget22 library (its wheel does not bundle it)"
# ${Status} below is dpkg-query's field name, not a shell variable.
# shellcheck disable=SC2016
if [ "$LIVE" = 1 ] && command -v apt-get > /dev/null \
        && ! dpkg-query -W -f='${Status}' libusb-1.0-0 2> /dev/null | grep -q 'ok installed'; then
    run apt-get update
    run apt-get install -y libusb-1.0-0
else
    echo "    already installed, not Debian, or --root: nothing to do"
fi

step "copy $SRC to $APP (keeping its .venv)"
run mkdir -p "$APP"
if [ "$DRY_RUN" = 1 ]; then
    printf '    tar -C %s --exclude=.venv --exclude=.git ... -cf - . | tar -C %s -xf -\n' \
        "$SRC" "$APP"
else
    tar -C "$SRC" --exclude=./.venv --exclude=./.git --exclude='__pycache__' \
        --exclude=./.pytest_cache --exclude=./.mypy_cache --exclude=./.ruff_cache \
        --exclude=./.hypothesis -cf - . | tar -C "$APP" --no-same-owner -xf -
fi

step "virtualenv $APP/.venv with ramp[phidget]"
if [ "$LIVE" = 0 ]; then
    # A venv records absolute paths: build it where it will run, not under --root.
    echo "    skipped with --root: run this script on the target to build the venv"
else
    if [ ! -x "$APP/.venv/bin/python" ]; then
        run "$PYTHON" -m venv "$APP/.venv"
    fi
    run "$APP/.venv/bin/python" -m pip install --quiet --upgrade pip
    run "$APP/.venv/bin/python" -m pip install --quiet --upgrade "$APP[phidget]"
fi

step "configuration $CONF_DIR/ramp.yaml"
run mkdir -p "$CONF_DIR"
if [ -e "$CONF_DIR/ramp.yaml" ]; then
    echo "    $CONF_DIR/ramp.yaml exists: kept as it is"
else
    # The robot's wiring without its loopback-only server line, then what the service adds:
    # MCP on every interface over mutual TLS with roles, and the flight recorder.
    if [ "$DRY_RUN" = 1 ]; then
        printf "    grep -v '^server:' %s > %s\n" "$SRC/ramp.yaml" "$CONF_DIR/ramp.yaml"
        printf '    cat %s >> %s\n' "$SRC/scripts/ramp-service.yaml" "$CONF_DIR/ramp.yaml"
    else
        { grep -v '^server:' "$SRC/ramp.yaml"; printf '\n'
          cat "$SRC/scripts/ramp-service.yaml"; } > "$CONF_DIR/ramp.yaml"
        chmod 0644 "$CONF_DIR/ramp.yaml"
    fi
fi

step "certificates $CONF_DIR/certs (mutual TLS on the MCP port)"
if [ -e "$CONF_DIR/certs/ca.crt" ]; then
    echo "    $CONF_DIR/certs has a CA: kept as it is"
else
    # The robot's CA and server certificate, for every name and address clients may use;
    # issue clients with `ramp certs issue $CONF_DIR/certs NAME --role ROLE`.
    if [ "$LIVE" = 1 ]; then RAMP=("$APP/.venv/bin/ramp"); else RAMP=("$PYTHON" -m ramp.cli); fi
    HOSTS=(--host 127.0.0.1 --host "$(hostname)" --host "$(hostname).local")
    for ip in $(hostname -I 2> /dev/null || true); do HOSTS+=(--host "$ip"); done
    run env PYTHONPATH="$SRC" "${RAMP[@]}" certs init "$CONF_DIR/certs" "${HOSTS[@]}"
    if [ "$LIVE" = 1 ]; then
        # The service's user reads its own key; nobody else does.
        run chgrp ramp "$CONF_DIR/certs/robot.key"
        run chmod 0640 "$CONF_DIR/certs/robot.key"
    fi
fi

step "udev rule $RULE"
write_file "$RULE" <<'EOF'
# Phidgets (USB vendor 06c2): readable and writable by group plugdev, so the ramp service
# needs no root. Installed by RAMP's scripts/install-service.sh.
SUBSYSTEM=="usb", ATTRS{idVendor}=="06c2", MODE="0660", GROUP="plugdev"
EOF
if [ "$LIVE" = 1 ] && command -v udevadm > /dev/null; then
    run udevadm control --reload-rules
    run udevadm trigger --subsystem-match=usb --attr-match=idVendor=06c2
fi

step "systemd unit $UNIT"
run install -D -m 0644 "$SRC/scripts/ramp.service" "$UNIT"
if [ "$LIVE" = 1 ]; then
    was_active="$(systemctl is-active ramp.service 2> /dev/null || true)"
    run systemctl daemon-reload
    run systemctl enable --now ramp.service
    if [ "$was_active" = active ]; then
        # enable --now leaves a running service alone: restart it so the new version runs.
        run systemctl restart ramp.service
    fi
else
    echo "    skipped with --root: systemctl daemon-reload, enable --now ramp.service"
fi

step "done"
echo "    status: systemctl status ramp    logs: journalctl -u ramp -f"
echo "    shell:  $APP/.venv/bin/ramp-shell 127.0.0.1:5577"
