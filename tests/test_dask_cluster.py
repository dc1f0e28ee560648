"""A real Dask cluster: `dask scheduler` and two `dask worker` processes on 127.0.0.1 (the
distributed package's own commands). A ground sweep and a Monte Carlo through
``--dask tcp://127.0.0.1:PORT`` give the process pool's numbers exactly, also when a worker
is killed in the middle of the sweep (the scheduler reruns its tasks elsewhere)."""
import json
import os
import shutil
import signal
import socket
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

distributed = pytest.importorskip("distributed", reason="dask.distributed not installed")

from hexapod_bringup.core.experiments import ground_sweep  # noqa: E402
from hexapod_bringup.core.montecarlo import monte_carlo  # noqa: E402
from hexapod_bringup.core.parallel import ProcessBackend, make_backend  # noqa: E402
from hexapod_common.core.params import load_params  # noqa: E402

#: 32 points x 2 controllers: 8 tasks of 8 cases (parallel.run_cases), so that one is
#: running on each worker when the first ends.
PERCENTS = tuple(float(x) for x in np.geomspace(10.0, 1000.0, 32))


def _dask_command():
    exe = Path(sys.executable).parent / "dask"
    return [str(exe)] if exe.exists() else [shutil.which("dask") or "dask"]


def _free_port():
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


@pytest.fixture
def cluster(tmp_path):
    """(address, {worker name: Popen}) of a scheduler and two single-threaded workers."""
    port = _free_port()
    addr = f"tcp://127.0.0.1:{port}"
    env = dict(os.environ, DASK_DISTRIBUTED__WORKER__PROFILE__ENABLED="False")
    procs = [subprocess.Popen(_dask_command() + ["scheduler", "--host", "127.0.0.1", "--port",
                                                 str(port), "--no-dashboard"],
                              env=env, stdout=subprocess.DEVNULL,
                              stderr=open(tmp_path / "scheduler.log", "w"))]
    workers = {}
    for name in ("wa", "wb"):
        workers[name] = subprocess.Popen(
            _dask_command() + ["worker", addr, "--name", name, "--nthreads", "1",
                               "--nworkers", "1", "--no-dashboard", "--no-nanny",
                               "--local-directory", str(tmp_path / name)],
            env=env, stdout=subprocess.DEVNULL, stderr=open(tmp_path / f"{name}.log", "w"))
        procs.append(workers[name])
    try:
        with distributed.Client(addr, timeout="20s") as client:
            client.wait_for_workers(2, timeout=30)
        yield addr, workers
    finally:
        for p in reversed(procs):
            if p.poll() is None:
                p.send_signal(signal.SIGTERM)
        for p in procs:
            try:
                p.wait(timeout=10)
            except subprocess.TimeoutExpired:
                p.kill()


def _rows(res):
    return [(r["controller"], r["ground.scale"], r["status"], r["eps_xH"], r["E_av"], r["F_L"])
            for r in res.rows()]


def test_sweep_and_monte_carlo_on_a_real_cluster_equal_the_pool_even_if_a_worker_dies(
        cluster):
    addr, workers = cluster
    p = load_params()
    with ProcessBackend(2) as pool:
        local = ground_sweep(p, PERCENTS, 400.0, backend=pool)
        local_mc = monte_carlo(p, ("pd_p", "pd_pf"), [0, 1, 2], 0.3, duration=1.5,
                               backend=pool)
    killed = []
    watcher = distributed.Client(addr, timeout="10s")

    def kill_a_busy_worker(n):
        if killed:
            return
        busy = [a for a, keys in watcher.processing().items() if keys]
        names = {a: w["name"] for a, w in watcher.scheduler_info()["workers"].items()}
        if busy:
            victim = names[busy[0]]
            workers[victim].kill()  # SIGKILL: no goodbye, its task is lost mid-run
            workers[victim].wait()
            killed.append(victim)

    backend = make_backend("dask", addr)
    try:
        on_dask = ground_sweep(p, PERCENTS, 400.0, backend=backend,
                               progress=kill_a_busy_worker)
        # the scheduler saw the worker go (its tasks were rerun on the other one)
        deadline = time.monotonic() + 15.0
        while len(watcher.scheduler_info()["workers"]) > 1 and time.monotonic() < deadline:
            time.sleep(0.2)
        alive = [w["name"] for w in watcher.scheduler_info()["workers"].values()]
        assert killed and alive == [n for n in workers if n not in killed]
    finally:
        backend.close()
        watcher.close()
    assert killed, "no worker was busy when the first task ended"
    assert _rows(on_dask) == _rows(local)
    # the Monte Carlo through the CLI's --dask on the surviving worker
    out = subprocess.run([sys.executable, "-m", "hexapod_bringup.cli", "montecarlo", "--seeds",
                          "3", "--spread", "30", "--t-run", "1.5", "--dask", addr, "--json",
                          "-"], capture_output=True, text=True, timeout=120)
    assert out.returncode == 0, out.stderr
    assert json.loads(out.stdout) == json.loads(json.dumps(local_mc.as_dict()))
