"""The bag holds its parameters: checksummed MCAP records, the yaml mirror, changes at ticks."""
import json
from pathlib import Path

import pytest

from hexapod_control.core.closed_loop import run
from hexapod_metrics.core.analysis import analyze_bag
from hexapod_metrics.core.bag_params import DEFAULTS, FROM_MCAP, bag_params
from hexapod_metrics.bag import open_bag
from hexapod_metrics.bag import BagReadError
from hexapod_metrics.core.indices import INDEX_NAMES, indices_from_obs
from hexapod_metrics.core.recording import PARAMS_KEY, write_run_bag
from hexapod_bringup.core.simulate import simulate
from hexapod_common.core import topics as T
from hexapod_common.core.param_log import ParamRecord, ParamRecordError, timeline
from hexapod_common.core.params import SPECS, load_params

#: One worker runs the module (its module-scoped fixture once): scripts/test.sh uses
#: pytest-xdist's loadgroup distribution.
pytestmark = pytest.mark.xdist_group("test_bag_params")

#: analysis behaviour, not the paper's numbers: model.md's 1e-4 s physics, 1 kHz control
FAST = {"sim.dt": 1e-4, "sim.control_period": 1e-3}
SLOW = {"gait.velocity": 0.8, **FAST}  # T = 1.25 s: wrong defaults would cut cycles elsewhere


@pytest.fixture(scope="module")
def slow_bag(tmp_path_factory):
    p = load_params(**SLOW)
    sim = simulate(p, "pd_pf", 3 * p.cycle_time)
    return write_run_bag(sim.run, tmp_path_factory.mktemp("bags") / "slow"), sim


@pytest.fixture(scope="module")
def changed_bag(tmp_path_factory):
    p = load_params(**FAST)
    r = run(p, "pd_pf", 3.0, param_changes=[(1.5, {"ground.scale": 2.0})])
    return write_run_bag(r, tmp_path_factory.mktemp("bags") / "changed"), r


def test_a_record_round_trips_and_a_flipped_bit_fails_its_checksum():
    rec = ParamRecord("hexapod_sim", "change", 1500, 1_500_000_000,
                      {"ground.scale": 2.0, "actuator.t_max": float("inf")})
    assert ParamRecord.from_map(rec.to_map()) == rec
    m = rec.to_map()
    m["payload"] = m["payload"].replace("2.0", "3.0")
    with pytest.raises(ParamRecordError, match="fails its checksum"):
        ParamRecord.from_map(m)
    with pytest.raises(ParamRecordError, match="kind"):
        ParamRecord("n", "later", 0, 0, {})


def test_timeline_takes_gains_from_their_controller_and_the_rest_from_the_sim():
    sim = ParamRecord("hexapod_sim", "start", 0, 0, {"ground.scale": 1.0, "pd_p.kp1": 1.0})
    ctl = ParamRecord("pd_p_controller", "start", 0, 0, {"ground.scale": 9.0, "pd_p.kp1": 5.0})
    moves = [ParamRecord("hexapod_sim", "change", 7, 7, {"ground.scale": 2.0}),
             ParamRecord("pd_p_controller", "change", 3, 3, {"ground.scale": 8.0}),
             ParamRecord("pd_p_controller", "change", 9, 9, {"pd_p.kp1": 6.0})]
    tl = timeline([sim, ctl, *moves], ["ground.scale", "pd_p.kp1"])
    assert tl.start == {"ground.scale": 1.0, "pd_p.kp1": 5.0}
    assert tl.changes == ((7, "hexapod_sim", "ground.scale", 2.0),
                          (9, "pd_p_controller", "pd_p.kp1", 6.0))
    assert tl.at(8) == {"ground.scale": 2.0, "pd_p.kp1": 5.0}


def test_a_bare_mcap_is_analysed_with_its_own_parameters(slow_bag):
    bag, sim = slow_bag
    mcap = next(Path(bag).glob("*.mcap"))
    with open_bag(mcap) as b:
        assert b.metadata is None  # nothing but the MCAP
        got = bag_params(b)
    assert got.source == FROM_MCAP and got.params == sim.run.params
    a = analyze_bag(mcap)
    assert a.params_source == FROM_MCAP and len(a.cycles) == 3
    for name in INDEX_NAMES:
        assert getattr(a.cycles[-1].indices, name) == pytest.approx(
            getattr(sim.indices, name), rel=1e-12)


def test_a_killed_writer_leaves_the_parameter_records_readable(slow_bag, tmp_path):
    bag, sim = slow_bag
    data = next(Path(bag).glob("*.mcap")).read_bytes()
    cut = tmp_path / "cut.mcap"
    cut.write_bytes(data[: len(data) // 2])
    a = analyze_bag(cut)
    assert a.truncated and a.params_source == FROM_MCAP and a.params == sim.run.params




def test_a_flipped_parameter_record_in_the_mcap_is_refused(slow_bag, tmp_path, hexapod):
    bag, _ = slow_bag
    mcap = next(Path(bag).glob("*.mcap"))
    data = mcap.read_bytes()
    # In the Metadata record (written at once) and in the /hexapod/parameters message
    # (in a later chunk); the yaml copies are escaped. Flip the record's.
    needle = b',"gait.velocity":0.8'
    assert data.count(needle) == 2
    at = data.index(needle) + len(needle) - 1
    bad = bytearray(data)
    bad[at] ^= 0x0B  # '8' -> '3': velocity 0.3
    flipped = tmp_path / "flipped.mcap"
    flipped.write_bytes(bytes(bad))
    with pytest.raises(BagReadError, match="fails its checksum"):
        analyze_bag(flipped)
    out = hexapod("analyze", "--no-plots", str(flipped))
    assert out.returncode == 2 and "fails its checksum" in out.stderr
    assert len(out.stderr.strip().splitlines()) == 1 and "Traceback" not in out.stderr


def test_a_metadata_yaml_that_disagrees_with_the_mcap_is_refused(slow_bag, tmp_path, hexapod):
    bag, _ = slow_bag
    import shutil

    copy = tmp_path / "edited"
    shutil.copytree(bag, copy)
    meta = copy / "metadata.yaml"
    text = meta.read_text()
    assert text.count('\\"gait.velocity\\": 0.8') == 1
    meta.write_text(text.replace('\\"gait.velocity\\": 0.8', '\\"gait.velocity\\": 3.0'))
    with pytest.raises(BagReadError, match=f"{PARAMS_KEY} disagrees"):
        analyze_bag(copy)
    out = hexapod("analyze", "--no-plots", str(copy))
    assert out.returncode == 2 and "disagrees" in out.stderr


def test_a_change_is_recorded_and_applied_at_its_tick(changed_bag):
    bag, r = changed_bag
    a = analyze_bag(bag)
    assert a.param_changes == [(1.5, "hexapod simulate", "ground.scale", 2.0)]
    assert [(s.t_start, s.t_end, s.cycles, s.params) for s in a.segments] == [
        (0.0, 1.5, 1, ()), (1.5, 3.0, 1, (("ground.scale", 2.0),))]
    for c in a.cycles:  # each cycle equals the engine's samples, before and after the change
        sl = slice(int(round(c.t_a * 1000)), int(round(c.t_b * 1000)) + 1)
        ref = indices_from_obs(r.obs[sl], r.reference.hip[sl], r.reference.foot[sl], 1e-3)
        assert c.indices.eps_xH == pytest.approx(ref.eps_xH, rel=1e-12)
    # The change acts: the run differs from an unchanged one only from its tick on.
    base = run(load_params(**FAST), "pd_pf", 3.0)
    assert (base.obs[:1500] == r.obs[:1500]).all() and (base.obs[1500] != r.obs[1500]).any()
    with open_bag(bag) as b:
        assert b.topics[T.PARAMETERS].message_count == 2


def test_rosbags_reads_a_bag_with_parameter_records(changed_bag):
    from rosbags.highlevel import AnyReader

    bag, _ = changed_bag
    with AnyReader([Path(bag)]) as reader:
        conns = [c for c in reader.connections if c.topic == T.PARAMETERS]
        msgs = [reader.deserialize(raw, c.msgtype) for c, _, raw in reader.messages(conns)]
    assert [m.header.stamp.sec + m.header.stamp.nanosec * 1e-9 for m in msgs] == [0.0, 1.5]
    values = {kv.key: kv.value for kv in msgs[1].status[0].values}
    rec = ParamRecord.from_map(values)
    assert rec.kind == "change" and rec.tick == 1500 and rec.values == {"ground.scale": 2.0}


def test_the_mcap_library_finds_the_records_through_the_summary(changed_bag):
    from mcap.reader import make_reader

    bag, _ = changed_bag
    with open(next(Path(bag).glob("*.mcap")), "rb") as fh:
        reader = make_reader(fh)
        found = [(m.name, m.metadata) for m in reader.iter_metadata()]
    records = [ParamRecord.from_map(m) for name, m in found if name == "hexapod_parameters"]
    assert [(r.kind, r.tick) for r in records] == [("start", 0), ("change", 1500)]
    assert [name for name, _ in found].count("rosbag2") == 1


def test_a_bag_without_records_says_it_uses_the_defaults(tmp_path):
    from hexapod_metrics.bag import BagWriter

    with BagWriter(tmp_path / "bare") as w:
        w.add_topic(T.JOINT_STATES, "sensor_msgs/msg/JointState")
    with open_bag(tmp_path / "bare") as b:
        got = bag_params(b)
    assert got.source == DEFAULTS and got.timeline is None
    assert set(json.loads(json.dumps(sorted(SPECS)))) == set(SPECS)


def test_the_engine_changes_only_what_a_run_can_change():
    from hexapod_common.core.errors import ParameterError

    p = load_params(**FAST)
    with pytest.raises(ParameterError, match="gait.velocity.*only of ground"):
        run(p, "pd_pf", 1.0, param_changes=[(0.5, {"gait.velocity": 2.0})])
    with pytest.raises(ParameterError, match="ground.scale"):
        run(p, "pd_pf", 1.0, param_changes=[(0.5, {"ground.scale": -1.0})])


def test_simulate_change_writes_the_change_into_its_bag(tmp_path, hexapod):
    bag = tmp_path / "bag"
    out = hexapod("simulate", "--controller", "pd_pf", "--change", "1.5:ground.scale=2.0",
                  "--set", "sim.dt=0.0001", "--set", "sim.control_period=0.001",
                  "--bag", str(bag), "--json")
    assert out.returncode == 0, out.stderr
    a = analyze_bag(bag)
    assert a.param_changes == [(1.5, "hexapod simulate", "ground.scale", 2.0)]
    bad = hexapod("simulate", "--change", "ground.scale")
    assert bad.returncode == 2 and "TIME:NAME=VALUE" in bad.stderr
    assert len(bad.stderr.strip().splitlines()) == 1
