#!/usr/bin/env bash
# Install a controller plug-in package (a directory with a setup.py or pyproject.toml that
# declares its controllers under the entry point group hexapod.controllers) into the
# project's environment, so that `--controller NAME` works everywhere: hexapod simulate,
# sweep, tune, run_graph.sh (docs/controllers.md, "Engine plug-ins").
# Usage: scripts/install_controller.sh PATH [pip options, e.g. --editable]
# It builds with the venv's own setuptools and wheel (no download: --no-build-isolation);
# `hexapod controllers` lists what is registered; `.venv/bin/python -m pip uninstall NAME`
# removes it.
set -euo pipefail
here="$(cd "$(dirname "$(readlink -f "${BASH_SOURCE[0]}")")" && pwd)"
if [[ $# -lt 1 || "$1" == -h || "$1" == --help ]]; then
  sed -n '2,9p' "${BASH_SOURCE[0]}" | sed 's/^# \{0,1\}//'
  [[ $# -lt 1 ]] && exit 2 || exit 0
fi
"$here/setup.sh" --quiet
# shellcheck source=scripts/env.sh
source "$here/env.sh"
exec python -m pip install --quiet --no-build-isolation "$@"
