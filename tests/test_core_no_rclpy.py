"""The numerical cores import no rclpy (checked in a fresh interpreter)."""
import subprocess
import sys

import pytest


@pytest.mark.parametrize("module", [
    "hexapod_sim.core.engine", "hexapod_control.core.closed_loop",
    "hexapod_bringup.core.simulate", "hexapod_metrics.core.indices",
    "hexapod_sim.core.tick_machine", "hexapod_common.core.labels", "hexapod_common.core.topics",
    "hexapod_metrics.core.cycles", "hexapod_metrics.core.analysis",
    "hexapod_metrics.core.recording"])
def test_core_imports_no_rclpy(module):
    code = f"import sys, {module}; print('rclpy' in sys.modules)"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         check=True)
    assert out.stdout.strip() == "False"
