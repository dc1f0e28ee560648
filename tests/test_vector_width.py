"""vector_width.py: which width numba's code generator is given, by host and by setting.
Each case in a new interpreter (the choice is made once, before anything compiles)."""
import json
import os
import subprocess
import sys

import llvmlite.binding as ll

PROBE = ("import json; from hexapod_common.core import jit; "
         "from hexapod_common.core.vector_width import force_avx2_width, prefer_512_bit; "
         "from numba.core import config; "
         "print(json.dumps([force_avx2_width(), config.CPU_FEATURES]))")


def _run_probe(**env: str) -> subprocess.CompletedProcess:
    full = {k: v for k, v in os.environ.items()
            if k not in ("HEXAPOD_VECTOR_WIDTH", "NUMBA_CPU_NAME", "NUMBA_CPU_FEATURES")}
    return subprocess.run([sys.executable, "-c", PROBE], env={**full, **env},
                          capture_output=True, text=True, check=True)


def _probe(**env: str) -> tuple[bool, str | None]:
    forced, features = json.loads(_run_probe(**env).stdout)
    return forced, features


def test_the_width_follows_the_host_and_a_users_choice_wins():
    host = ll.get_host_cpu_features()
    avx512, avx2 = host.get("avx512f", False), host.get("avx2", False)
    forced, features = _probe()
    assert forced == (avx2 and not avx512)
    assert (features is not None and features.endswith(",-prefer-256-bit")) == avx512
    # forced: the same features under another name (numba's cache key), so code compiled
    # at LLVM's own width is not loaded
    assert (features is not None and features.endswith(",+avx2")) == forced
    # the user's choice wins: LLVM's own width, or numba's CPU named
    assert _probe(HEXAPOD_VECTOR_WIDTH="native") == (False, None)
    forced, _ = _probe(NUMBA_CPU_NAME="generic")
    assert forced is False


def test_an_unknown_width_is_one_warning_line_and_the_default():
    r = _run_probe(HEXAPOD_VECTOR_WIDTH="512bits")
    lines = [line for line in r.stderr.splitlines() if line.strip()]
    assert lines == ["warning: HEXAPOD_VECTOR_WIDTH='512bits' is none of '', '256', "
                     "'native': ignored"], r.stderr
    assert tuple(json.loads(r.stdout)) == _probe()


def test_the_batched_numbers_do_not_depend_on_the_width(tmp_path):
    """A batched sweep gives the same numbers bit for bit at LLVM's own width and at the one
    chosen here (a lane does the same IEEE operations), each compiled afresh."""
    code = ("import json; from hexapod_common.core.params import load_params; "
            "from hexapod_bringup.core.experiments import ground_sweep; "
            "from hexapod_bringup.core.parallel import InlineBackend; "
            "r = ground_sweep(load_params(), [30.0, 300.0], 400.0, "
            "controllers=('pd_p', 'pd_pf'), duration=1.5, backend=InlineBackend()); "
            "print(json.dumps(r.rows(), sort_keys=True, default=repr))")
    outs = []
    for width in ("native", ""):
        env = {**os.environ, "NUMBA_CACHE_DIR": str(tmp_path / f"cache{width}"),
               "HEXAPOD_VECTOR_WIDTH": width}
        outs.append(subprocess.run([sys.executable, "-c", code], env=env,
                                   capture_output=True, text=True, check=True).stdout)
    assert outs[0] == outs[1] and '"E_av"' in outs[0]


def test_a_fresh_compile_prints_no_loop_remarks_and_keeps_other_stderr(tmp_path):
    """A forced width makes LLVM print a remark for every loop it cannot vectorise; none
    reaches the user, and what else goes to stderr while numba compiles still does."""
    code = ("import sys; from hexapod_common.core.jit import njit\n"
            "@njit(cache=True)\n"
            "def first_negative(a):\n"
            "    for i in range(a.size):\n"
            "        if a[i] < 0.0:\n"
            "            return i\n"
            "    return -1\n"
            "import numpy as np\n"
            "print(first_negative(np.array([1.0, -2.0])))\n"
            "print('still here', file=sys.stderr)\n")
    env = {**os.environ, "NUMBA_CACHE_DIR": str(tmp_path / "cache")}
    script = tmp_path / "early_exit.py"
    script.write_text(code)
    r = subprocess.run([sys.executable, str(script)], env=env, capture_output=True, text=True,
                       check=True)
    assert r.stdout.strip() == "1"
    assert "remark:" not in r.stderr and "still here" in r.stderr, r.stderr
