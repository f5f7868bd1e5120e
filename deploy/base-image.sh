#!/usr/bin/env bash
# Builds the base image the Dockerfile starts FROM, offline: a minimal Debian bookworm
# made by debootstrap from Debian's package mirror (the one registry our machines
# reach) and loaded with `docker import`, tagged `debian:bookworm-slim`. Docker uses a
# local image of that name without pulling, so the same Dockerfile builds here (no
# registry) and anywhere else (where the tag is pulled from Docker Hub).
#
# Usage: deploy/base-image.sh            (skips if the tag exists; FORCE=1 rebuilds)
# Needs: root (debootstrap), Docker. Installs debootstrap from Debian if missing.
set -euo pipefail
TAG="${BASE_TAG:-debian:bookworm-slim}"
MIRROR="${DEBIAN_MIRROR:-http://deb.debian.org/debian}"

if [ -z "${FORCE:-}" ] && docker image inspect "$TAG" >/dev/null 2>&1; then
  echo "base image $TAG already present (FORCE=1 to rebuild)"
  exit 0
fi
if ! command -v debootstrap >/dev/null 2>&1; then
  SUDO=""; [ "$(id -u)" -eq 0 ] || SUDO="sudo -n"
  $SUDO env DEBIAN_FRONTEND=noninteractive apt-get install -y -q debootstrap \
    || { $SUDO apt-get update -q && $SUDO env DEBIAN_FRONTEND=noninteractive apt-get install -y -q debootstrap; }
fi

root="$(mktemp -d /tmp/spwi-base.XXXXXX)"
trap 'rm -rf "$root"' EXIT
started=$SECONDS
debootstrap --variant=minbase bookworm "$root" "$MIRROR" >"$root.log" 2>&1 \
  || { tail -n 30 "$root.log"; echo "debootstrap failed (log above)"; exit 1; }
rm -f "$root.log"
# What a slim image leaves out: package caches and lists, documentation.
rm -rf "$root"/var/cache/apt/archives/*.deb "$root"/var/lib/apt/lists/* \
  "$root"/usr/share/doc/* "$root"/usr/share/man/* "$root"/usr/share/info/* "$root"/usr/share/locale/*
tar -C "$root" --numeric-owner -c . | docker import --change 'CMD ["bash"]' - "$TAG" >/dev/null
echo "built $TAG in $((SECONDS - started)) s: $(docker image inspect -f '{{.Size}}' "$TAG" | awk '{printf "%.0f MB", $1/1e6}')"
