"""Fixtures shared by every test directory."""
from __future__ import annotations

import io
import os
import subprocess
from contextlib import redirect_stderr, redirect_stdout
from pathlib import Path
from typing import Callable

import pytest


@pytest.fixture
def hexapod() -> Callable[..., subprocess.CompletedProcess]:
    """``hexapod(*args, cwd=None)``: the ``hexapod`` command line's ``main`` run in this
    process (the same parser, commands and one-line error handling as ``scripts/hexapod``,
    without a process start and its imports: seconds per call on a loaded 2-core machine);
    returns its exit code and what it printed, as ``subprocess.run`` would. An exception
    that ``main`` lets through fails the test, as a traceback would."""
    import numpy as np

    from hexapod_bringup.cli import main

    def run(*args: str, cwd: str | os.PathLike[str] | None = None
            ) -> subprocess.CompletedProcess:
        out, err = io.StringIO(), io.StringIO()
        here = Path.cwd()
        numpy_errors = np.geterr()  # main sets np.seterr(all="ignore")
        try:
            if cwd is not None:
                os.chdir(cwd)
            with redirect_stdout(out), redirect_stderr(err):
                try:
                    code = main(list(args))
                except SystemExit as exit_:  # argparse's usage errors
                    code = exit_.code if isinstance(exit_.code, int) else 1
        finally:
            os.chdir(here)
            np.seterr(**numpy_errors)
        return subprocess.CompletedProcess(["hexapod", *args], code, out.getvalue(),
                                           err.getvalue())
    return run


#: Tests (or modules) that take 10 s or more of a worker: scheduled first, so that the last
#: ones a pytest-xdist worker takes are short and the two workers end together (with
#: collection order, `reproduce --quick` came last and one worker ran it alone for 20 s).
LONG_FIRST = ("test_reproduce.py::", "test_graph_reports.py::", "test_graph_join.py::",
              "test_default_graph_records_the_default_simulate_motion",
              "test_graph_bag_kill.py::", "test_fallback_alone_exits_7",
              "test_killed_controller_exits_3", "test_graph_foxglove.py::",
              "test_graph_rates.py::", "test_dask_cluster.py::")


def pytest_collection_modifyitems(items: list[pytest.Item]) -> None:
    items.sort(key=lambda item: not any(k in item.nodeid for k in LONG_FIRST))  # stable
