#!/usr/bin/env bash
# Builds the spwi image (tag: ${IMAGE:-spwi:latest}) from this checkout: the base image
# if missing (deploy/base-image.sh), the release binaries, then `docker build` on a
# context holding only what the image needs.
#
# Usage: deploy/build-image.sh
set -euo pipefail
cd "$(dirname "$0")/.."
IMAGE="${IMAGE:-spwi:latest}"
export CARGO_TARGET_DIR="${CARGO_TARGET_DIR:-$HOME/.cache/spwi/target}"

deploy/base-image.sh
started=$SECONDS
cargo build --release --quiet -p spwi-agent -p spwi-sim --bins
ctx="$(mktemp -d /tmp/spwi-image.XXXXXX)"
trap 'rm -rf "$ctx"' EXIT
mkdir -p "$ctx/bin" "$ctx/models" "$ctx/config"
cp "$CARGO_TARGET_DIR"/release/{spwi-agent,spwi-sim,spwi-router} "$ctx/bin/"
cp deploy/fleet-entry "$ctx/bin/spwi-fleet-entry"
for set in models/*/; do  # every shipped model set (a folder with a manifest)
  [ -f "$set/manifest.json" ] && cp -r "$set" "$ctx/models/"
done
rm -f "$ctx"/models/*/reference.json  # golden vectors are for the tests, not the fleet
cp -r deploy/zenoh deploy/agent.toml "$ctx/config/"
docker build --quiet -f deploy/Dockerfile -t "$IMAGE" "$ctx" >/dev/null
echo "built $IMAGE in $((SECONDS - started)) s (binaries + image): $(docker image inspect -f '{{.Size}}' "$IMAGE" | awk '{printf "%.0f MB", $1/1e6}')"
