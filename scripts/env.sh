# shellcheck shell=bash
# Source me (bash): `source scripts/env.sh` from any directory.
# Activates .venv and the ros_ws overlay, and makes the pip-installed ROS 2
# wheels usable without their self re-exec. Safe under `set -u`; run
# scripts/setup.sh first.

_hx_root="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
if [[ ! -f "$_hx_root/.venv/bin/activate" || ! -f "$_hx_root/ros_ws/install/local_setup.bash" ]]; then
  echo "env.sh: not set up yet: run $_hx_root/scripts/setup.sh" >&2
  unset _hx_root
  return 1
fi

# The venv's and colcon's scripts read unset variables: relax nounset meanwhile.
_hx_u=0; [[ $- == *u* ]] && _hx_u=1
set +u

# shellcheck source=/dev/null
source "$_hx_root/.venv/bin/activate"

# Prepend $1 to the path list named $2, once.
_hx_prepend() {
  local cur="${!2:-}"
  case ":$cur:" in *":$1:"*) ;; *) export "$2=$1${cur:+:$cur}" ;; esac
}

# The wheels keep share/ament_index and share/<pkg> under the venv prefix, but
# nothing puts it on AMENT_PREFIX_PATH (ament_index_python lookups need it).
_hx_prepend "$VIRTUAL_ENV" AMENT_PREFIX_PATH

# The wheels' native libraries live in <prefix>/lib and site-packages/ros_*.libs.
# Their .pth bootstrapper re-execs every Python start to set LD_LIBRARY_PATH;
# doing it here once (and setting its guard) saves that second start.
for _hx_d in "$VIRTUAL_ENV"/lib/python3.*/site-packages/ros_*.libs "$VIRTUAL_ENV/lib"; do
  [[ -d "$_hx_d" ]] && _hx_prepend "$_hx_d" LD_LIBRARY_PATH
done
export _ROS_WHEELS_BOOTSTRAP_COMPLETE=1

# The workspace overlay (local_setup: this workspace only, no recorded underlays).
# shellcheck source=/dev/null
source "$_hx_root/ros_ws/install/local_setup.bash"

# numba caches compiled functions on disk but does not notice when a function it
# calls from another module changed: key the cache directory on the sources.
_hx_src_hash="$(find "$_hx_root/ros_ws/src" -path '*/core/*.py' -print0 | LC_ALL=C sort -z \
  | xargs -0 cat | sha256sum | cut -c1-16)"
export NUMBA_CACHE_DIR="$_hx_root/.numba_cache/$_hx_src_hash"

# Isolation: discovery stays on this machine unless the caller says otherwise;
# ROS_DOMAIN_ID is left as the caller set it.
export ROS_AUTOMATIC_DISCOVERY_RANGE="${ROS_AUTOMATIC_DISCOVERY_RANGE:-LOCALHOST}"

(( _hx_u )) && set -u
unset -f _hx_prepend
unset _hx_root _hx_u _hx_d _hx_src_hash
