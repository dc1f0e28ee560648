"""Sweeps and the tuner: backends agree, rejection rules, a planted optimum is found."""
import math

import numpy as np
import pytest

from hexapod_control.core.closed_loop import Case
from hexapod_bringup.core.experiments import ground_sweep, hip_score, select_best, tune, walking
from hexapod_metrics.core.indices import Indices
from hexapod_bringup.core.parallel import (InlineBackend, MemoBackend, ProcessBackend,
                                          make_backend, run_cases)
from hexapod_bringup.core.simulate import Outcome, simulate
from hexapod_common.core.layout import O_TQ
from hexapod_common.core.params import load_params

#: One worker runs the module (its module-scoped fixture once): scripts/test.sh uses
#: pytest-xdist's loadgroup distribution.
pytestmark = pytest.mark.xdist_group("test_experiments")

PERCENTS = (20.0, 100.0, 500.0)


def _rows(res):
    return [(r["controller"], r["ground.scale"], r["status"], r["eps_xH"], r["E_av"])
            for r in res.rows()]


@pytest.fixture(scope="module")
def pool():
    """One 2-worker process pool for the module's tests (a worker start loads the compiled
    engine: seconds each); every test still runs its own cases on it."""
    backend = ProcessBackend(2)
    yield backend
    backend.close()


def test_sweep_equals_one_by_one_and_processes_equal_inline(pool):
    p = load_params()
    inline = ground_sweep(p, PERCENTS, 170.0, backend=InlineBackend())
    procs = ground_sweep(p, PERCENTS, 170.0, backend=pool)
    assert _rows(inline) == _rows(procs)
    one = simulate(p.with_values(**{"actuator.t_max": 170.0, "ground.scale": 5.0}), "pd_p")
    assert inline.index("pd_p", "eps_xH")[2] == pytest.approx(one.indices.eps_xH, rel=1e-12)


def test_sweep_on_a_local_dask_cluster_equals_local_processes(pool):
    distributed = pytest.importorskip("distributed", reason="dask.distributed not installed")
    p = load_params()
    with distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=True,
                                  dashboard_address=None) as cluster:
        backend = make_backend("dask", cluster.scheduler_address)
        dask = ground_sweep(p, PERCENTS, 400.0, backend=backend)
    local = ground_sweep(p, PERCENTS, 400.0, backend=pool)
    assert _rows(dask) == _rows(local)


def _torque_peak(case):
    """Module level, so that a Dask worker can unpickle it."""
    sim = simulate(case.params, case.controller)
    return float(np.abs(sim.run.obs[:, O_TQ]).max()), sim.indices.eps_xH


def test_local_dask_cluster_spreads_batches_and_single_runs_like_the_process_pool(pool):
    """`--dask local:2`: the backend starts its own 2-worker cluster, runs the batches
    (convergence checks included) and the single runs a report needs (calls), with the
    same numbers as the process pool, and stops the cluster at close()."""
    pytest.importorskip("distributed", reason="dask.distributed not installed")
    p = load_params()
    cases = [Case(p.with_values(**{"ground.scale": s}), c)
             for s in (0.5, 2.0) for c in ("pd_p", "pd_pf")]
    local = ground_sweep(p, PERCENTS[:2], 400.0, backend=pool, check=True)
    local_calls = dict(pool.calls(_torque_peak, cases))
    with make_backend("dask", "local:2") as dask:
        assert dask.workers == 2
        on_dask = ground_sweep(p, PERCENTS[:2], 400.0, backend=dask, check=True)
        dask_calls = dict(dask.calls(_torque_peak, cases))
        cluster = dask._cluster
    assert dask._cluster is None and cluster.status.name == "closed"
    assert _rows(on_dask) == _rows(local)
    assert [r["converged"] for r in on_dask.rows()] == [r["converged"] for r in local.rows()]
    assert dask_calls == local_calls and sorted(dask_calls) == [0, 1, 2, 3]


def test_dask_local_cluster_needs_a_worker_count():
    for bad in ("local:0", "local:two", "local:"):
        with pytest.raises(ValueError, match="local:N with N >= 1"):
            make_backend("dask", bad)


def test_dask_backend_needs_an_address_and_a_reachable_scheduler():
    with pytest.raises(ValueError, match="scheduler address"):
        make_backend("dask")
    with pytest.raises(ValueError, match="unknown backend"):
        make_backend("mpi")


def _outcome(p, eps_x, eps_y=0.03, status="ok"):
    """An outcome whose hip errors are eps_x (its offset-free part trk_xH too) and eps_y."""
    idx = (Indices(1.0, 1.0, 1.0, eps_x, eps_y, 0.0, 0.0, 1.0, trk_xH=eps_x)
           if status == "ok" else None)
    return Outcome(Case(p, "pd_pf"), idx, (2.0, 3.0), status)


def test_select_best_rejects_diverged_and_non_walking():
    p = load_params()
    gains = [{"kp1": float(k)} for k in range(5)]
    # not walking: the engine's walking.not_walking said so (tests/test_walking.py)
    outs = [_outcome(p, 0.5), _outcome(p, 0.0, status="diverged"),  # diverged: no score
            _outcome(p, 0.001, status="fallen"),                      # barely moved
            _outcome(p, 0.01, status="fallen"),                       # hips sank
            _outcome(p, 0.2)]                                         # the planted best
    best, scores, diverged, not_walking = select_best(gains, outs, p)
    assert best == 4 and (diverged, not_walking) == (1, 2)
    assert np.isnan(scores[1:4]).all() and scores[4] == pytest.approx(0.23)
    with pytest.raises(ValueError, match="no gain set of 2 walks"):
        select_best(gains[:2], outs[1:3], p)


def test_tuner_finds_the_argmin_of_independent_runs():
    """A 2x2x2 grid around the params file's PD-P&F gains (the others ten times softer or
    derivative-dominated); the tuner's choice must equal the argmin of independent runs.
    (On eps_xH + eps_yH the params file's set was the best; on the stationary trk_xH +
    eps_yH a soft, derivative-dominated set that drifts more is: the objective does not see
    the drift, which E5's tables give beside it.) Rejection is covered above."""
    p = load_params()
    grid = {"kp1": [2050.0, 20500.0], "kp2": [2200.0, 22000.0], "kd1": [110.0, 1e6]}
    res = tune(p, "pd_pf", grid, backend=InlineBackend())
    scores = {}
    for g in res.gains:
        s = simulate(p.with_values(**{f"pd_pf.{k}": v for k, v in g.items()}), "pd_pf")
        scores[tuple(g.values())] = hip_score(s.outcome) if walking(s.outcome, p) else math.inf
    best = min(scores, key=scores.get)
    assert tuple(res.best.values()) == best
    assert res.best_score == pytest.approx(scores[best], rel=1e-9)
    ref = scores[(20500.0, 22000.0, 110.0)]  # the params file's set
    assert res.reference_score == pytest.approx(ref, rel=1e-9)
    assert res.improvement == pytest.approx(1.0 - scores[best] / ref, rel=1e-9)
    assert len(res.gains) == 8 and np.all(np.isfinite(res.scores))


class _Counting:
    """The inline backend, counting the cases it runs."""

    def __init__(self) -> None:
        self.inner = InlineBackend()
        self.ran: list[Case] = []

    def map(self, chunks):
        for chunk in chunks:
            self.ran.extend(chunk[1])
        return self.inner.map(chunks)

    def calls(self, fn, items):
        return self.inner.calls(fn, items)


def test_memo_backend_runs_each_case_once_and_returns_what_a_rerun_gives():
    p = load_params()
    grounds = [p.with_values(**{"ground.scale": s}) for s in (0.5, 2.0)]
    cases = [Case(q, c) for q in grounds for c in ("pd_p", "pd_pf")]
    fresh = run_cases(cases, 1.0, InlineBackend())
    counting = _Counting()
    memo = MemoBackend(counting)
    # a case twice in one call, then again in a later call with a new one
    first = run_cases(cases + cases[:1], 1.0, memo, chunk_size=3)
    later = run_cases([cases[2], Case(p, "pd_p")], 1.0, memo)
    assert [o.indices for o in first] == [o.indices for o in fresh + fresh[:1]]
    assert later[0].indices == fresh[2].indices
    assert counting.ran == cases + [Case(p, "pd_p")]
    assert memo.reused == 2
    # another duration is another run
    run_cases(cases[:1], 1.5, memo)
    assert len(counting.ran) == 6


def test_pool_spawns_while_another_thread_runs():
    """A forked child would inherit the running thread's locks without the thread."""
    import threading

    from hexapod_bringup.core.parallel import pool_start_method

    stop = threading.Event()
    t = threading.Thread(target=stop.wait)
    t.start()
    try:
        assert pool_start_method() == "spawn"
    finally:
        stop.set()
        t.join()


FORKED_POOL = """
import json
from hexapod_bringup.core.experiments import ground_sweep
from hexapod_bringup.core.parallel import InlineBackend, ProcessBackend
from hexapod_common.core.params import load_params

if __name__ == "__main__":
    p = load_params()
    with ProcessBackend(2) as pool:
        pool.start()
        procs = ground_sweep(p, (20.0, 500.0), 170.0, backend=pool)
        method = pool.start_method
    inline = ground_sweep(p, (20.0, 500.0), 170.0, backend=InlineBackend())
    print(json.dumps({"method": method, "same": procs.rows() == inline.rows()}))
"""


def test_pool_is_forked_from_a_threadless_command_and_agrees_with_inline(tmp_path):
    """What `hexapod sweep` does: its pool starts before any other thread, so the workers
    are forked (no new interpreter), and their numbers equal this process's."""
    import json
    import subprocess
    import sys

    script = tmp_path / "forked_pool.py"
    script.write_text(FORKED_POOL)
    out = subprocess.run([sys.executable, str(script)], capture_output=True, text=True,
                         timeout=300)
    assert out.returncode == 0, out.stderr
    assert json.loads(out.stdout.strip().splitlines()[-1]) == {"method": "fork", "same": True}


def test_an_inline_chunk_gives_every_numba_thread_blocks_to_run():
    """A chunk of 8 was one compiled block: `--backend inline` ran on one thread."""
    import numba

    from hexapod_bringup.core.parallel import CHUNK_CASES, chunk_size_of
    from hexapod_control.core.batch_loop import block_plan

    threads = numba.get_num_threads()
    size = chunk_size_of(InlineBackend())
    assert size == 2 * CHUNK_CASES * threads
    assert chunk_size_of(MemoBackend(InlineBackend())) == size
    assert chunk_size_of(ProcessBackend(2)) == CHUNK_CASES  # one thread per worker
    assert len(block_plan(np.full(size, 2), threads)) >= 2 * threads


def test_worker_chunks_are_wide_but_leave_every_worker_the_same_number():
    """Single-threaded workers get chunks of up to 32 cases (a block of 32 runs faster a
    case), the same number for every worker: two each where each keeps 8 cases, else one."""
    from hexapod_bringup.core.parallel import MAX_CHUNK_CASES, chunk_size_of, run_cases

    assert chunk_size_of(ProcessBackend(2), 256) == MAX_CHUNK_CASES == 32
    assert chunk_size_of(ProcessBackend(2), 42) == 11  # the default 21-point sweep: 4 chunks
    assert chunk_size_of(ProcessBackend(2), 36) == 9  # 4 chunks
    assert chunk_size_of(ProcessBackend(2), 20) == 10  # 2 chunks, not 8, 8 and 4
    assert chunk_size_of(ProcessBackend(2), 17) == 9  # 9 and 8, not 8, 8 and 1
    assert chunk_size_of(ProcessBackend(2), 9) == 5  # 5 and 4, not 8 and 1
    assert chunk_size_of(ProcessBackend(2), 1) == 1
    assert chunk_size_of(ProcessBackend(8), 256) == 16
    assert chunk_size_of(MemoBackend(ProcessBackend(2)), 256) == 32

    class Counting(InlineBackend):
        chunk_size = None  # type: ignore[assignment]
        workers = 2
        sizes: list[int] = []

        def map(self, chunks):  # type: ignore[no-untyped-def]
            self.sizes += [len(c[1]) for c in chunks]
            return super().map(chunks)

    p = load_params(**{"sim.control_period": 0.001})
    cases = [Case(p.with_values(**{"ground.scale": 1.0 + k / 100}), "pd_p") for k in range(42)]
    backend = Counting()
    outs = run_cases(cases, 1.0, backend)
    assert backend.sizes == [11, 11, 11, 9]
    assert [o.case for o in outs] == cases


@pytest.mark.parametrize("controller", ["pd_p", "pd_pf"])
def test_the_tuned_gains_are_the_same_at_10_and_20_cycles(controller):
    """E5's objective (trk_xH + eps_yH) does not grow with the run: the grid's best set
    scored on cycle 10 is the one scored on cycle 20, and its score moves by < 1 mm."""
    from hexapod_bringup.core.experiments import HIP_OBJECTIVE
    from hexapod_common.core.params import load_params

    assert HIP_OBJECTIVE == ("trk_xH", "eps_yH")
    p = load_params(**{"actuator.t_max": 400.0})
    g = p.gains(controller)
    grid = {"kp1": [g.kp1 * f for f in (0.75, 1.0, 1.25)],
            "kd1": [g.kd1 * f for f in (0.75, 1.0, 1.25)]}
    at10, at20 = tune(p, controller, grid, duration=11.0), tune(p, controller, grid, duration=21.0)
    assert at10.best == at20.best
    assert abs(at10.best_score - at20.best_score) < 1e-3
