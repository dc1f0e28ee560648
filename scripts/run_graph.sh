#!/usr/bin/env bash
# Run the ROS 2 node graph: simulator, trajectory generator, both controllers and the
# recorder; print the indices of each controller segment and the bag's path.
#
# Default scenario: PD-P&F in charge, handing over to PD-P halfway, base ground, lockstep,
# 6 simulated seconds (3 gait cycles per controller).
#
# Usage: scripts/run_graph.sh [options]
#   --controller pd_p|pd_pf  controller in charge at the start (default pd_pf)
#   --switch-to pd_p|pd_pf   controller to hand over to (default: the other one)
#   --switch-at SECONDS      simulated time of the hand-over (default: half the duration)
#   --no-switch              keep the first controller all along
#   --mode lockstep|realtime graph mode (default lockstep)
#   --duration SECONDS       simulated duration (default 6); 0 = until Ctrl-C
#   --ground-scale X         factor on the four ground parameters (1.0 = 100 %)
#   --t-max N_M              actuator saturation T_max (.inf = ideal actuators)
#   --params FILE            ROS 2 params file (default: the shipped base experiment)
#   --bag DIR                bag directory (default bags/<YYYYmmdd-HHMMSS>); node logs
#                            go to DIR_logs
#   --sim-time               run the other nodes with use_sim_time:=true (they do not need
#                            it: they work on the messages' stamps; costs ~10 % of speed)
#   --markers                also run the markers node: /hexapod/markers (MarkerArray at
#                            30 Hz of sim time) lands in the bag for Foxglove's 3-D panel
#   --foxglove [PORT]        serve the graph's topics live to Foxglove on
#                            ws://localhost:PORT (default 8765); implies --markers;
#                            layout: docs/foxglove/hexapod_layout.json
#   -h, --help               this text
# Environment: ROS_DOMAIN_ID is honoured; discovery stays on this machine unless
# ROS_AUTOMATIC_DISCOVERY_RANGE says otherwise. While it runs, switch controllers with
# scripts/switch_controller.sh pd_p|pd_pf (same ROS_DOMAIN_ID). The graph's messages are
# authenticated with a fresh key per run (a 0600 file in a private directory, removed at
# the end; HEXAPOD_KEY_FILE names it for a node started by hand to join the run).
set -euo pipefail

root="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
controller=pd_pf switch_to="" switch_at="" no_switch=0 mode=lockstep duration=6
ground_scale="" t_max="" params="" bag="" sim_time=0 markers=0 foxglove=""

die() { echo "run_graph: error: $*" >&2; exit 2; }
need() { [[ $# -ge 2 && -n "$2" ]] || die "option $1 needs a value"; }
while [[ $# -gt 0 ]]; do
  case "$1" in
    --controller) need "$@"; controller="$2"; shift 2 ;;
    --switch-to) need "$@"; switch_to="$2"; shift 2 ;;
    --switch-at) need "$@"; switch_at="$2"; shift 2 ;;
    --no-switch) no_switch=1; shift ;;
    --mode) need "$@"; mode="$2"; shift 2 ;;
    --duration) need "$@"; duration="$2"; shift 2 ;;
    --ground-scale) need "$@"; ground_scale="$2"; shift 2 ;;
    --t-max) need "$@"; t_max="$2"; shift 2 ;;
    --params) need "$@"; params="$2"; shift 2 ;;
    --bag) need "$@"; bag="$2"; shift 2 ;;
    --sim-time) sim_time=1; shift ;;
    --markers) markers=1; shift ;;
    --foxglove)
      markers=1 foxglove=8765; shift
      if [[ $# -gt 0 && "$1" =~ ^[0-9]+$ ]]; then foxglove="$1"; shift; fi ;;
    -h|--help) sed -n '2,32p' "${BASH_SOURCE[0]}" | sed 's/^# \{0,1\}//'; exit 0 ;;
    *) die "unknown option '$1' (try --help)" ;;
  esac
done
case "$controller" in pd_p|pd_pf) ;; *) die "--controller must be pd_p or pd_pf" ;; esac
case "$mode" in lockstep|realtime) ;; *) die "--mode must be lockstep or realtime" ;; esac
[[ -z "$switch_to" ]] && { [[ $controller == pd_pf ]] && switch_to=pd_p || switch_to=pd_pf; }
case "$switch_to" in pd_p|pd_pf) ;; *) die "--switch-to must be pd_p or pd_pf" ;; esac
[[ "$duration" =~ ^[0-9]+([.][0-9]*)?$ ]] || die "--duration must be a number of seconds"

"$root/scripts/setup.sh" --quiet
# shellcheck source=scripts/env.sh
source "$root/scripts/env.sh"
export ROS_AUTOMATIC_DISCOVERY_RANGE="${ROS_AUTOMATIC_DISCOVERY_RANGE:-LOCALHOST}"
export RMW_FASTRTPS_PUBLICATION_MODE="${RMW_FASTRTPS_PUBLICATION_MODE:-SYNCHRONOUS}"
export PYTHONUNBUFFERED=1

params="${params:-$root/ros_ws/src/hexapod_sim/hexapod_sim/config/hexapod.yaml}"
[[ -f "$params" ]] || die "params file $params not found"
params="$(cd "$(dirname "$params")" && pwd)/$(basename "$params")"
bag="${bag:-$root/bags/$(date +%Y%m%d-%H%M%S)}"
[[ -e "$bag" ]] && die "bag directory $bag already exists"
mkdir -p "$(dirname "$bag")"
bag="$(cd "$(dirname "$bag")" && pwd)/$(basename "$bag")"
logs="${bag}_logs"
mkdir -p "$logs"
# The run's key (hexapod_sim/core/msg_auth.py): only the graph's own nodes hold it.
keydir=""
if [[ "${HEXAPOD_AUTH:-on}" != off && -z "${HEXAPOD_KEY_FILE:-}" ]]; then
  keydir="$(python -c 'from hexapod_sim.core.msg_auth import new_key_file; print(new_key_file().parent)')"
  export HEXAPOD_KEY_FILE="$keydir/key"
fi

common=(--ros-args --params-file "$params" -p "run.controller:=$controller" -p "sim.mode:=$mode")
[[ -n "$ground_scale" ]] && common+=(-p "ground.scale:=$ground_scale")
[[ -n "$t_max" ]] && common+=(-p "actuator.t_max:=$t_max")
if awk "BEGIN{exit !($duration > 0)}"; then
  common+=(-p "run.duration:=$duration")
  sim_extra=(-p stop_at_end:=true)
  if (( ! no_switch )); then
    switch_at="${switch_at:-$(awk "BEGIN{print $duration / 2}")}"
    sim_extra+=(-p "switch_at:=$switch_at" -p "switch_to:=$switch_to")
  fi
else
  sim_extra=()
  (( ! no_switch )) && [[ -n "$switch_at" ]] && sim_extra+=(-p "switch_at:=$switch_at" -p "switch_to:=$switch_to")
fi
sim_time_arg=()
(( sim_time )) && sim_time_arg=(-p use_sim_time:=true)

declare -A pids=()
# start NAME MODULE FUNC [nice] -- extra ros args...
start() {
  local name="$1" module="$2" func="$3" nice="$4"; shift 4
  nice -n "$nice" python -c "import sys; from $module import $func; sys.exit($func())" \
    "${common[@]}" "$@" >"$logs/$name.log" 2>&1 &
  pids[$name]=$!
}

# Stop one process: SIGINT, then SIGTERM, then SIGKILL, each after a grace period.
stop() {
  local name="$1" grace="${2:-10}" pid="${pids[$1]:-}" sig t
  [[ -z "$pid" ]] && return 0
  for sig in INT TERM KILL; do
    kill -0 "$pid" 2>/dev/null || break
    kill -s "$sig" "$pid" 2>/dev/null || true
    for ((t = 0; t < grace * 10; t++)); do
      kill -0 "$pid" 2>/dev/null || break
      sleep 0.1
    done
  done
  wait "$pid" 2>/dev/null || true
  unset "pids[$name]"
}

cleaned=0
cleanup() {
  (( cleaned )) && return
  cleaned=1
  trap - INT TERM
  stop hexapod_sim 10
  # The others together (SIGINT to all first), the recorder last: it drains its queues.
  for n in trajectory_generator pd_p_controller pd_pf_controller markers foxglove_bridge; do
    [[ -n "${pids[$n]:-}" ]] && kill -s INT "${pids[$n]}" 2>/dev/null || true
  done
  for n in trajectory_generator pd_p_controller pd_pf_controller markers foxglove_bridge; do
    stop "$n" 5
  done
  stop metrics 30
  [[ -n "$keydir" ]] && rm -rf "$keydir"
  return 0
}
trap 'cleanup' EXIT
trap 'echo "run_graph: interrupted: stopping the graph" >&2; cleanup; exit 130' INT TERM

desc="$mode mode, $controller in charge"
if (( ! no_switch )) && [[ -n "$switch_at" ]]; then desc+=", $switch_to from t = $switch_at s"; fi
if awk "BEGIN{exit !($duration > 0)}"; then desc+=", $duration s"; else desc+=", until Ctrl-C"; fi
echo "run_graph: ROS_DOMAIN_ID=${ROS_DOMAIN_ID:-0}: $desc (node logs in $logs)"
[[ -n "${HEXAPOD_KEY_FILE:-}" ]] && echo "run_graph: run key $HEXAPOD_KEY_FILE"
start metrics hexapod_metrics.metrics_node main 10 -p "bag_path:=$bag" "${sim_time_arg[@]}"
start trajectory_generator hexapod_control.trajectory_node main 0 "${sim_time_arg[@]}"
start pd_p_controller hexapod_control.controller_node main_pd_p 0 "${sim_time_arg[@]}"
start pd_pf_controller hexapod_control.controller_node main_pd_pf 0 "${sim_time_arg[@]}"
if (( markers )); then
  start markers hexapod_metrics.marker_node main 0 "${sim_time_arg[@]}"
  # tick 0 waits for the markers node too, so the markers cover the run from t = 0
  sim_extra+=(-p "wait_for:=trajectory_generator,pd_p_controller,pd_pf_controller,metrics,markers")
fi
if [[ -n "$foxglove" ]]; then
  start foxglove_bridge hexapod_metrics.foxglove_node main 10 -p "port:=$foxglove"
  echo "run_graph: Foxglove live view on ws://localhost:$foxglove (layout: docs/foxglove/hexapod_layout.json)"
fi
start hexapod_sim hexapod_sim.sim_node main 0 "${sim_extra[@]}"

set +e
wait "${pids[hexapod_sim]}"
sim_code=$?
set -e
unset "pids[hexapod_sim]"
grep -h -E "ERROR|stopped at tick|switched" "$logs/hexapod_sim.log" | sed 's/^/  sim: /' || true
if (( sim_code != 0 )); then
  echo "run_graph: hexapod_sim exited with code $sim_code (log: $logs/hexapod_sim.log)" >&2
fi
cleanup
trap - EXIT
# Dropped messages and publishers outside the graph, as each node reported them.
for f in "$logs"/*.log; do
  grep -h -E "publishers on .* not nodes of this graph|inputs: dropped" "$f" \
    | sed "s/^/  $(basename "$f" .log): /" || true
done

if [[ -f "$bag/indices.json" ]]; then
  python - "$bag/indices.json" <<'PY'
import json, sys
doc = json.load(open(sys.argv[1]))
names = doc["index_names"]
print(f"indices per controller segment (last full gait cycle of each):")
print(f"  {'controller':<11} {'segment [s]':<16} {'cycle [s]':<12}" + "".join(f"{n:>11}" for n in names))
for s in doc["segments"]:
    c = s["last_full_cycle"]
    seg = f"[{s['t_start']:g}, {s['t_end']:g}]"
    if c is None:
        print(f"  {s['controller']:<11} {seg:<16} no full gait cycle")
        continue
    row = "".join(f"{c['indices'][n]:>11.4g}" for n in names)
    print(f"  {s['controller']:<11} {seg:<16} {'[%g, %g]' % (c['t_a'], c['t_b']):<12}{row}")
PY
else
  echo "run_graph: no indices.json in $bag (see $logs/metrics.log)" >&2
fi
echo "bag: $bag"
exit "$sim_code"
