"""The teardown watchdog of every node's main (hexapod_common.runtime.node_main)."""
from __future__ import annotations

import subprocess
import sys
import textwrap
import time

HANGS = textwrap.dedent("""
    import time
    from hexapod_common.runtime import node_main
    node_main.TEARDOWN_S = 0.3
    node_main._teardown_watchdog("some_node", 7)
    time.sleep(60)  # a teardown that never returns
""")

RETURNS = textwrap.dedent("""
    import time
    from hexapod_common.runtime import node_main
    node_main.TEARDOWN_S = 0.3
    node_main._teardown_watchdog("some_node", 7).cancel()
    time.sleep(0.6)
    print("done")
""")


def test_a_hanging_teardown_ends_the_process_with_the_nodes_exit_code() -> None:
    t0 = time.monotonic()
    r = subprocess.run([sys.executable, "-c", HANGS], capture_output=True, text=True,
                       timeout=30)
    assert r.returncode == 7, r.stderr
    assert time.monotonic() - t0 < 20
    assert r.stderr.strip().splitlines()[-1] == (
        "[some_node] teardown did not end within 0.3 s: exiting (code 7)")


def test_a_teardown_that_returns_cancels_the_watchdog() -> None:
    r = subprocess.run([sys.executable, "-c", RETURNS], capture_output=True, text=True,
                       timeout=30)
    assert (r.returncode, r.stdout.strip(), r.stderr) == (0, "done", "")
