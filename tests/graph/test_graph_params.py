"""A live parameter change in a lockstep graph: recorded with its tick, applied by analyze,
equal to the in-process engine run with the same change."""
from __future__ import annotations

import json
import time

import numpy as np
import pytest

from hexapod_control.core.closed_loop import run
from hexapod_metrics.core.analysis import analyze_bag
from hexapod_metrics.core.bag_params import FROM_MCAP, read_records
from hexapod_metrics.bag import open_bag, read_joint_state_arrays
from hexapod_metrics.core.indices import INDEX_NAMES, indices_from_obs
from hexapod_metrics.core.recording import RECORDS_KEY
from hexapod_common.core import topics as T
from hexapod_common.core.layout import O_TH, O_TQ

from .conftest import (CLIENT_NODE, call, fast_params, finish_recorded_run, ros_client,
                       start_recorded_run)

#: One worker runs the module (its module-scoped fixture once): scripts/test.sh uses
#: pytest-xdist's loadgroup distribution.
pytestmark = pytest.mark.xdist_group("test_graph_params")

DURATION = 4.0


def _clock_watch(node):
    """A best-effort /clock subscription on ``node``; returns ``wait(seconds)``, which spins
    until a /clock of at least ``seconds`` arrived. Made before the sim starts (the sim
    waits for the client node and matches this subscription before tick 0), so a fast run
    cannot be over before the client hears it."""
    from rclpy.executors import SingleThreadedExecutor
    from rclpy.qos import QoSProfile, ReliabilityPolicy
    from rosgraph_msgs.msg import Clock

    seen = [0.0]
    node.create_subscription(
        Clock, T.CLOCK, lambda m: seen.__setitem__(0, m.clock.sec + m.clock.nanosec * 1e-9),
        QoSProfile(depth=1, reliability=ReliabilityPolicy.BEST_EFFORT))

    def wait(seconds: float, timeout: float = 120.0) -> float:
        ex = SingleThreadedExecutor(context=node.context)
        ex.add_node(node)
        end = time.monotonic() + timeout
        while seen[0] < seconds and time.monotonic() < end:
            ex.spin_once(timeout_sec=0.05)
        ex.remove_node(node)
        assert seen[0] >= seconds, f"sim time stayed at {seen[0]} s"
        return seen[0]
    return wait


@pytest.fixture(scope="module")
def live_change(make_module_graph, tmp_path_factory):
    """One recorded 4 s lockstep run with ground.scale set to 2 at about 1 s and hostile
    parameter records: (bag, the sim's log)."""
    from rcl_interfaces.msg import Parameter, ParameterType, ParameterValue
    from rcl_interfaces.srv import SetParameters

    bag = tmp_path_factory.mktemp("live_change") / "bag"
    g = make_module_graph()
    with ros_client(g.domain_id) as node:
        wait_sim_time = _clock_watch(node)
        start_recorded_run(g, bag, DURATION, also_wait_for=(CLIENT_NODE,))
        # The live change first, while the 4 s run surely goes on (a loaded machine may
        # take longer over the hostile part than the run lasts).
        wait_sim_time(1.0)
        value = ParameterValue(type=ParameterType.PARAMETER_DOUBLE, double_value=2.0)
        req = SetParameters.Request(parameters=[Parameter(name="ground.scale", value=value)])
        res = call(node, SetParameters, "/hexapod_sim/set_parameters", req).results[0]
        assert res.successful, res.reason
        # Then hostile input. Signed with the run's key (a buggy node of the graph): a record
        # that fails its checksum, and bytes that do not decode; unsigned (any process on
        # the domain): a well-formed record with a valid checksum.
        from diagnostic_msgs.msg import DiagnosticArray
        from rclpy.serialization import serialize_message

        from hexapod_common.runtime import conversions as C
        from hexapod_common.core.msg_auth import Signer, read_key_file
        from hexapod_common.core.param_log import ParamRecord

        signer = Signer(read_key_file(g.env["HEXAPOD_KEY_FILE"]), T.PARAMETERS)
        forged = ParamRecord("hexapod_sim", "change", 600, 600_000_000, {"ground.scale": 9.0})
        bad = dict(forged.to_map(), sha256="0" * 64)
        pub = node.create_publisher(DiagnosticArray, T.PARAMETERS,
                                    C.TOPIC_QOS[T.PARAMETERS].publisher())
        pub.publish(signer.sign(serialize_message(C.diagnostic_array(600_000_000, [C.Status(
            "hexapod_parameters/hexapod_sim", "ok", "change", bad)]))))
        pub.publish(signer.sign(b"\x00\x01\x00\x00garbage"))
        g.wait_log("metrics", "dropped a /hexapod/parameters message (2 so far)", 60)
        pub.publish(C.diagnostic_array(600_000_000, [C.Status(
            "hexapod_parameters/hexapod_sim", "ok", "change", forged.to_map())]))
        g.wait_log("metrics", "dropped a message on /hexapod/parameters: unauthenticated", 60)
    assert finish_recorded_run(g, 300)["missed"] == 0
    return bag, g.log("hexapod_sim")


def test_a_live_ground_change_is_recorded_applied_by_analyze_and_equals_the_engine(
        live_change):
    bag, _ = live_change
    # The bag holds every node's start values and the change, checksummed, yaml mirrored.
    with open_bag(bag) as b:
        records = read_records(b)
        custom = b.metadata["custom_data"]
        js = read_joint_state_arrays(b, T.JOINT_STATES)
    starts = {r.node for r in records if r.kind == "start"}
    assert {"hexapod_sim", "trajectory_generator", "pd_pf_controller", "metrics"} <= starts
    change = [r for r in records if r.kind == "change"]
    assert len(change) == 1 and change[0].node == "hexapod_sim"
    assert change[0].values == {"ground.scale": 2.0}
    k = change[0].tick
    assert 1000 <= k < 4000 and change[0].stamp_ns == k * 1_000_000
    assert json.loads(custom[RECORDS_KEY]) == [r.to_map() for r in records]

    report = json.loads((bag / "indices.json").read_text())
    assert report["dropped_parameter_messages"] == 2
    assert report["parameter_records"] == len(records)

    # analyze applies it at its tick: segments split there, the later ones name it.
    a = analyze_bag(bag)
    assert a.params_source == FROM_MCAP and not a.truncated
    assert a.param_changes == [(pytest.approx(k * 1e-3), "hexapod_sim", "ground.scale", 2.0)]
    assert a.segments[0].params == () and a.segments[-1].params == (("ground.scale", 2.0),)
    assert a.segments[-1].t_start == pytest.approx(k * 1e-3)

    # The engine with the same change at the same tick gives the same samples and indices.
    r = run(fast_params(), "pd_pf", DURATION, param_changes=[(k * 1e-3, {"ground.scale": 2.0})])
    n = r.obs.shape[0]
    assert np.array_equal(js.stamps, np.arange(n) * 1_000_000)
    np.testing.assert_allclose(js.effort.reshape(-1, 6, 2), r.obs[:, O_TQ], rtol=0, atol=1e-9)
    np.testing.assert_allclose(js.position.reshape(-1, 6, 2), r.obs[:, O_TH], rtol=0, atol=1e-9)
    assert len(a.cycles) == 4
    for c in a.cycles:
        sl = slice(int(round(c.t_a * 1000)), int(round(c.t_b * 1000)) + 1)
        ref = indices_from_obs(r.obs[sl], r.reference.hip[sl], r.reference.foot[sl], 1e-3)
        for name in INDEX_NAMES:
            assert getattr(c.indices, name) == pytest.approx(getattr(ref, name), rel=1e-12)
    # ... and differs from a run without it (the change acted).
    base = run(fast_params(), "pd_pf", DURATION)
    assert not np.allclose(base.obs[k + 10:], r.obs[k + 10:])


def test_the_change_is_logged_with_its_tick_and_the_printed_segment_says_so(live_change):
    from hexapod_bringup.graph_launcher import indices_lines

    bag, sim_log = live_change
    report = json.loads((bag / "indices.json").read_text())
    [change] = report["parameter_changes"]
    k = change["tick"]
    assert change == {"tick": k, "t": pytest.approx(k * 1e-3), "node": "hexapod_sim",
                      "name": "ground.scale", "value": 2.0}
    # the sim's log line says the tick the change took effect at (as the bag's record)
    assert f"parameter change at tick {k} (t = {k * 1e-3:.6g} s): ground.scale = 2.0" in sim_log
    assert "parameter ground.scale = 2.0\n" not in sim_log  # no line without its tick
    # run_graph's table: the one segment's per-cycle mean over its cycles 0-3 spans the
    # change: the row says so (hexapod analyze splits the segment there)
    lines = indices_lines(bag / "indices.json")
    notes = [line for line in lines if line.strip().startswith("^")]
    what = f"ground.scale = 2.0 at {k * 1e-3:.3f} s"
    assert notes == [f"    ^ these cycles span a live parameter change (hexapod analyze "
                     f"splits the segment there): {what}"], lines
