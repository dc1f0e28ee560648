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
