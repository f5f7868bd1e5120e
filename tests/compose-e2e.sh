#!/usr/bin/env bash
# The container fleet end to end: builds the base image (offline, deploy/base-image.sh)
# and the spwi image (deploy/build-image.sh), then runs tests/compose_e2e.py: 4 agents
# agree, a killed one is out within 1.5 s, scaling to 6 adds voters, a cut-off one is
# dropped and rejoins, the router going down stops nothing. `.ci/run` runs this
# whenever a Docker daemon is reachable. Everything is torn down at the end.
set -euo pipefail
cd "$(dirname "$0")/.."
if ! docker info >/dev/null 2>&1; then
  echo "!!!!!!!! SKIPPED: compose end-to-end (no Docker daemon reachable) !!!!!!!!"
  exit 0
fi
deploy/build-image.sh
python3 tests/compose_e2e.py
