#!/usr/bin/env bash
# Hand control of the running graph to another controller: pd_p or pd_pf.
# Usage: scripts/switch_controller.sh pd_p|pd_pf [--timeout SECONDS]
# The sim makes sure the controller node is lifecycle-active, then sets its run.controller
# and hands over at the next tick boundary (same ROS_DOMAIN_ID).
set -euo pipefail
here="$(cd "$(dirname "$(readlink -f "${BASH_SOURCE[0]}")")" && pwd)"
if [[ $# -lt 1 || "$1" == -h || "$1" == --help ]]; then
  sed -n '2,5p' "${BASH_SOURCE[0]}" | sed 's/^# \{0,1\}//'
  [[ $# -lt 1 ]] && exit 2 || exit 0
fi
# `hexapod switch` (it asks the sim over its local socket: a fraction of a second, no ROS
# context).
exec "$here/hexapod" switch "$@"
