"""Runtime parameter changes as `ros2 param set` sends them, on a running sim and controller.

`ros2 param set NODE NAME TEXT` reads TEXT as YAML 1.1 and calls the node's
``set_parameters`` service with what it got: ``1000000`` arrives as an INTEGER value,
``1e6`` as the STRING ``'1e6'`` (YAML 1.1 has no float without a dot), ``2.5`` as a DOUBLE.
`ros2 param get` and `ros2 param describe` then show the type the node stored.
"""
from __future__ import annotations

from typing import Any

import pytest

from .conftest import call, ros_client

#: One worker runs the module (its module-scoped fixture once): scripts/test.sh uses
#: pytest-xdist's loadgroup distribution.
pytestmark = pytest.mark.xdist_group("test_graph_param_set")


def _value(v: object) -> Any:
    """The ParameterValue `ros2 param set` sends for a value YAML read as ``v``."""
    from rcl_interfaces.msg import ParameterType, ParameterValue

    if isinstance(v, str):
        return ParameterValue(type=ParameterType.PARAMETER_STRING, string_value=v)
    if isinstance(v, int):
        return ParameterValue(type=ParameterType.PARAMETER_INTEGER, integer_value=v)
    return ParameterValue(type=ParameterType.PARAMETER_DOUBLE, double_value=float(v))


class ParamTool:
    """`ros2 param set/get/describe` against one graph, from one client node."""

    def __init__(self, node: Any) -> None:
        self.node = node

    def set(self, target: str, name: str, v: object) -> Any:
        from rcl_interfaces.msg import Parameter
        from rcl_interfaces.srv import SetParameters

        req = SetParameters.Request(parameters=[Parameter(name=name, value=_value(v))])
        return call(self.node, SetParameters, f"/{target}/set_parameters", req).results[0]

    def get(self, target: str, name: str) -> Any:
        from rcl_interfaces.srv import GetParameters

        req = GetParameters.Request(names=[name])
        return call(self.node, GetParameters, f"/{target}/get_parameters", req).values[0]

    def describe(self, target: str, name: str) -> Any:
        from rcl_interfaces.srv import DescribeParameters

        req = DescribeParameters.Request(names=[name])
        return call(self.node, DescribeParameters, f"/{target}/describe_parameters",
                    req).descriptors[0]


@pytest.fixture(scope="module")
def param_tool(make_module_graph):
    """A sim (waiting for nobody, so it takes parameters from its start on) and PD-P's
    controller node, each started with an integer for a double (``-p ground.k_x:=100000``);
    a :class:`ParamTool` on their domain."""
    g = make_module_graph()
    g.start("pd_p_controller", "pd_p.kd1:=250")
    g.start("hexapod_sim", "wait_for:=''", "ground.k_x:=100000")
    g.wait_log("hexapod_sim", "lockstep mode", timeout=120)
    g.wait_log("pd_p_controller", "active", timeout=120)
    with ros_client(g.domain_id) as node:
        yield ParamTool(node)
    assert g.procs["hexapod_sim"].poll() is None and g.procs["pd_p_controller"].poll() is None


@pytest.mark.parametrize("target, name, integer, at_start", [
    ("hexapod_sim", "ground.k_y", 1000000, "ground.k_x"),
    ("pd_p_controller", "pd_p.kp1", 120000, "pd_p.kd1"),
])
def test_an_integer_for_a_double_parameter_is_stored_as_that_double(param_tool, target, name,
                                                                     integer, at_start):
    from rcl_interfaces.msg import ParameterType

    got = param_tool.get(target, at_start)  # the integer given at start
    assert got.type == ParameterType.PARAMETER_DOUBLE and got.double_value.is_integer()
    assert param_tool.describe(target, at_start).type == ParameterType.PARAMETER_DOUBLE
    r = param_tool.set(target, name, integer)  # `ros2 param set NODE NAME 1000000`
    assert r.successful, r.reason
    got = param_tool.get(target, name)
    assert got.type == ParameterType.PARAMETER_DOUBLE and got.double_value == float(integer)
    assert param_tool.describe(target, name).type == ParameterType.PARAMETER_DOUBLE
    r = param_tool.set(target, name, -integer)  # and checked as that double
    assert not r.successful and name in r.reason
    assert param_tool.get(target, name).double_value == float(integer)


@pytest.mark.parametrize("target, name, text", [
    ("hexapod_sim", "ground.k_y", "1e6"),       # `ros2 param set NODE NAME 1e6`
    ("pd_p_controller", "pd_p.kp1", "1.5e5"),  # YAML 1.1 floats need a dot and a signed exponent
])
def test_a_string_that_reads_as_a_number_is_that_number_any_other_a_type_error(
        param_tool, target, name, text):
    from rcl_interfaces.msg import ParameterType

    from hexapod_common.core.params import SPECS

    r = param_tool.set(target, name, text)
    assert r.successful, r.reason
    got = param_tool.get(target, name)
    assert got.type == ParameterType.PARAMETER_DOUBLE and got.double_value == float(text)
    r = param_tool.set(target, name, "soft")
    assert not r.successful
    assert r.reason == (f"parameter '{name}' = 'soft' is invalid: allowed "
                        f"{SPECS[name].allowed()} (a string, where a float is expected)")
    got = param_tool.get(target, name)
    assert got.type == ParameterType.PARAMETER_DOUBLE and got.double_value == float(text)


def _dump(tool: ParamTool, target: str) -> dict[str, Any]:
    """What `ros2 param dump /target` writes: every parameter the node lists, nested at the
    dots, under ``/target: ros__parameters:``."""
    from rcl_interfaces.srv import GetParameters, ListParameters
    from rclpy.parameter import parameter_value_to_python

    names = list(call(tool.node, ListParameters, f"/{target}/list_parameters",
                      ListParameters.Request()).result.names)
    values = call(tool.node, GetParameters, f"/{target}/get_parameters",
                  GetParameters.Request(names=names)).values
    tree: dict[str, Any] = {}
    for name, v in zip(names, values):
        *groups, key = name.split(".")
        d = tree
        for g in groups:
            d = d.setdefault(g, {})
        d[key] = parameter_value_to_python(v)
    return {f"/{target}": {"ros__parameters": tree}}


def test_changes_carry_their_tick_a_no_op_is_none_and_a_dump_loads_back(tmp_path):
    """A change on the idle controller is stamped with the graph's tick (not the last one
    it answered), in its log, the bag's records, indices.json and run_graph's summary; a
    run.controller set to the controller in charge is no change; an unbounded run's
    run.duration reads 0; `ros2 param dump` of the sim is a params file that loads back."""
    import json
    import os
    import re
    import signal

    import yaml

    from hexapod_bringup.graph_launcher import build_parser, settings
    from hexapod_common.core.params import SPECS, load_params
    from hexapod_common.core.switch_channel import request

    from .test_graph_exits import Script

    s = Script(tmp_path, "--duration", "0", "--no-switch", "--set",
               "sim.lockstep_max_rtf=1")
    try:
        s.wait_log("hexapod_sim", "lockstep mode")

        def tick() -> int:
            answer = request("status", s.domain, 30)
            assert answer is not None and answer.startswith("ok "), answer
            return int(json.loads(answer[3:])["status"]["tick"])
        s.wait_for(lambda: tick() > 200, 120, "200 ticks")
        with ros_client(s.domain) as node:
            tool = ParamTool(node)
            assert tool.get("hexapod_sim", "run.duration").double_value == 0.0
            before = tick()
            assert tool.set("pd_p_controller", "pd_p.kp2", 130000.0).successful
            after = tick()
            assert tool.set("hexapod_sim", "run.controller", "pd_pf").successful  # no-op
            dump = _dump(tool, "hexapod_sim")
            dump_pd_p = _dump(tool, "pd_p_controller")
        s.wait_for(lambda: tick() > after + 100, 120, "100 more ticks")
        os.kill(s.proc.pid, signal.SIGINT)
        assert s.wait(180) == 0, s.stderr()
    finally:
        s.kill_all()
    m = re.search(r"parameter change at tick (\d+) \(t = [\d.e+-]+ s\): pd_p.kp2 = 130000.0",
                  s.log("pd_p_controller"))
    assert m and before <= int(m[1]) <= after + 1, (m and m[1], before, after)
    k = int(m[1])
    assert "run.controller" not in "".join(
        line for line in s.log("hexapod_sim").splitlines() if "parameter change" in line)
    report = json.loads((s.bag / "indices.json").read_text())
    assert report["parameter_changes"] == [{"tick": k, "t": k * 1e-3, "node":
                                            "pd_p_controller", "name": "pd_p.kp2",
                                            "value": 130000.0}], report["parameter_changes"]
    assert (f"live parameter changes (each from the tick its node applied it): pd_p.kp2 = "
            f"130000.0 at {k * 1e-3:.3f} s (tick {k}, pd_p_controller)") in s.stdout()

    path = tmp_path / "dump.yaml"
    path.write_text(yaml.safe_dump(dump))
    tree = dump["/hexapod_sim"]["ros__parameters"]
    assert "start_type_description_service" in tree and "use_sim_time" in tree
    loaded = load_params(path).to_flat()
    flat = {f"{g}.{k}": v for g, sub in tree.items() if isinstance(sub, dict)
            for k, v in sub.items() if f"{g}.{k}" in SPECS}
    assert flat and all(loaded[n] == v for n, v in flat.items()), (flat, loaded)
    assert loaded["run.duration"] == 0.0 and "pd_p.kp1" in loaded  # the base fills the rest
    settings(build_parser().parse_args(["--params", str(path)]))  # run_graph.sh takes it
    both = tmp_path / "both.yaml"  # with a controller's dump: its gains as they were set
    both.write_text(yaml.safe_dump({**dump, **dump_pd_p}))
    assert load_params(both).pd_p.kp2 == 130000.0
    settings(build_parser().parse_args(["--params", str(both)]))
