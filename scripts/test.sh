#!/usr/bin/env bash
# Run the whole test suite: set up what is missing, lint (ruff) and type-check
# (mypy, strict on every core/ package; settings in pyproject.toml), then pytest
# over tests/ and each package's own test/ directory. Extra arguments go to
# pytest (naming a test path runs only that, serially, without the lint and type
# checks); the exit code is the first failing step's. The whole suite runs on
# HEXAPOD_TEST_WORKERS (default 2) pytest-xdist workers (a module marked xdist_group on one
# worker, its module-scoped fixture once), the "realtime" tests after it.
set -euo pipefail
root="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
"$root/scripts/setup.sh"
# shellcheck source=scripts/env.sh
source "$root/scripts/env.sh"
# Default targets (absolute: relative arguments stay relative to the caller's
# cwd), unless an argument already names a test path.
dirs=("$root/tests")
for d in "$root"/ros_ws/src/*/test; do
  if [[ -d "$d" ]]; then dirs+=("$d"); fi
done
for arg in "$@"; do
  if [[ "$arg" != -* && -e "${arg%%::*}" ]]; then dirs=(); break; fi
done
if (( ${#dirs[@]} )); then
  (cd "$root" && ruff check ros_ws/src scripts tests)
  (cd "$root" && mypy --python-executable "$(command -v python)" \
    ros_ws/src/hexapod_common/hexapod_common/core ros_ws/src/hexapod_sim/hexapod_sim/core \
    ros_ws/src/hexapod_control/hexapod_control/core ros_ws/src/hexapod_metrics/hexapod_metrics/core \
    ros_ws/src/hexapod_metrics/hexapod_metrics/bag ros_ws/src/hexapod_bringup/hexapod_bringup/core)
fi
if (( ${#dirs[@]} )); then
  # The whole suite: everything but the wall-clock-paced graphs on two workers (each graph
  # test on its own ROS_DOMAIN_ID per worker: tests/graph/conftest.py), then those alone
  # (marker "realtime": their ticks are due by the wall clock, so they get the machine).
  workers="${HEXAPOD_TEST_WORKERS:-2}"
  phase() {  # pytest exit 5 = no test selected (e.g. -k matched none of this phase's)
    local rc=0
    python -m pytest --rootdir "$root" -q "$@" || rc=$?
    if (( rc != 0 && rc != 5 )); then exit "$rc"; fi
  }
  phase -n "$workers" --dist loadgroup -m "not realtime" "${dirs[@]}" "$@"
  phase -m realtime "${dirs[@]}" "$@"
  exit 0
fi
exec python -m pytest --rootdir "$root" -q "$@"
