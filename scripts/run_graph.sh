#!/usr/bin/env bash
# Run the ROS 2 node graph: simulator, trajectory generator, both controllers and the
# recorder; print the sim's tick counts, the messages dropped and the publishers outside the
# graph (sim and recorder), the indices of each controller segment (a note under a row whose
# cycle spans or follows a live parameter change) and the bag's path.
#
# Default scenario: the params file's (10 kHz control, the one `hexapod simulate` runs),
# PD-P&F in charge, handing over to PD-P halfway, base ground, lockstep, 6 simulated seconds
# (3 gait cycles per controller).
#
# Usage: scripts/run_graph.sh [options]      (--opt value and --opt=value both work)
#   --controller NAME        controller in charge at the start (default pd_pf; a plug-in
#                            such as pd_alpha gets its node; another name waits for a
#                            node that joins)
#   --switch-to pd_p|pd_pf   controller to hand over to (default: the other one)
#   --switch-at SECONDS      simulated time of the hand-over (default: half the duration)
#   --no-switch              keep the first controller all along
#   --mode lockstep|realtime graph mode (default lockstep)
#   --duration SECONDS       simulated duration (default 6); 0 = until Ctrl-C
#   --ground-scale X         factor on the four ground parameters (1.0 = 100 %)
#   --ground-seed K          uneven ground of Monte Carlo seed K (hexapod montecarlo)
#   --ground-spread PCT      its spread in % (sigma of ln factor x 100; default 0)
#   --t-max N_M              actuator saturation T_max (.inf = ideal actuators)
#   --control-rate HZ        control rate (sim.control_period = 1/HZ; default the params
#                            file's 10 kHz; realtime mode: 1 kHz, PD-P&F's force loop in
#                            the drive)
#   --params FILE            ROS 2 params file (default: the shipped base experiment)
#   --set NAME=VALUE         override any parameter by its dotted name (repeatable)
#   --bag DIR                bag directory (default bags/<YYYYmmdd-HHMMSS>); node logs
#                            go to DIR_logs
#   --sim-time               run the other nodes with use_sim_time:=true (they do not need
#                            it: they work on the messages' stamps; costs ~10 % of speed)
#   --markers                also run the markers node: /hexapod/markers (MarkerArray at
#                            30 Hz of sim time) lands in the bag for Foxglove's 3-D panel
#   --foxglove [PORT]        serve the graph's topics live to Foxglove on
#                            ws://localhost:PORT (default 8765); implies --markers;
#                            layout: docs/foxglove/hexapod_layout.json
#   -h, --help               the options
# Exit codes: 0 ok; 2 bad settings (one line naming the option or key, nothing started);
#   3 a node died or exited non-zero; 4 the recorder failed (or the bag lacks states);
#   5 the disk filled up;
#   6 the model diverged; 7 a damping fallback happened (controller in charge silent);
#   130 Ctrl-C/SIGTERM before the end of a run with a duration (with --duration 0,
#   Ctrl-C is the normal end: 0). Ctrl-C always prints the indices so far and the bag.
# Environment: ROS_DOMAIN_ID is honoured; discovery stays on this machine unless
# ROS_AUTOMATIC_DISCOVERY_RANGE says otherwise. While it runs, switch controllers with
# scripts/switch_controller.sh pd_p|pd_pf (same ROS_DOMAIN_ID). The graph's messages are
# authenticated with a fresh key per run (a 0600 file in a private directory, removed at
# the end; HEXAPOD_KEY_FILE names it for a node started by hand to join the run). The
# launcher itself is hexapod_bringup/graph_launcher.py; this script only sets up and hands
# over to it.
set -euo pipefail
root="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
"$root/scripts/setup.sh" --quiet
# shellcheck source=scripts/env.sh
source "$root/scripts/env.sh"
exec python -m hexapod_bringup.graph_launcher "$@"
