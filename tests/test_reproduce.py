"""`hexapod reproduce --quick`: the report decides every claim with its rule, carries every
number's dt-convergence verdict, and answers E6's control-rate question."""
import json
import subprocess
import sys

from hexapod_bringup.core import claims
from hexapod_metrics.core.indices import REPORTED_NAMES, Indices


def _measured(doc):
    """claims.point() rebuilt from results.json's record of one convergence check."""
    runs = [Indices(**r) if r else None for r in doc["runs"]]
    out = {}
    for n in REPORTED_NAMES:
        vals = [getattr(r, n) for r in runs]
        ok = n not in doc["unconverged"]
        out[n] = claims.Measured(vals[0], min(vals), max(vals), ok)
    return out


def test_reproduce_quick_writes_report_with_all_claims(tmp_path):
    out = tmp_path / "report"
    r = subprocess.run([sys.executable, "-m", "hexapod_bringup.cli", "reproduce", "--quick",
                        "--backend", "inline", "--out", str(out)],
                       capture_output=True, text=True, timeout=900, check=True)
    text = (out / "README.md").read_text()
    # not a terminal: no progress bar even without --no-progress; the output is printed
    assert "ETA" not in r.stderr and "%|" not in r.stderr
    assert f"writing the report into {out}" in r.stdout
    doc = json.loads((out / "results.json").read_text())
    statuses = {c["claim"]: c["status"] for c in doc["claims"]}
    assert set(statuses) == {"C1", "C2", "C3", "C4"}
    for claim, status in statuses.items():
        assert status in ("holds", "fails", "undecided")
        assert f"| {claim} |" in text and f"**{status}**" in text
        assert f"{claim} {status.upper()}" in r.stdout
    # C1 in the report is the rule applied to the recorded base-case numbers
    base = {c: _measured(doc["base"][c]) for c in ("pd_p", "pd_pf")}
    assert claims.c1(base["pd_p"], base["pd_pf"]).status == statuses["C1"]
    assert statuses["C3"] == "holds"  # saturation at 150 N m degrades tracking >10x
    # every table row of E1 carries its dt/2 -> dt/4 change; E6 answers the rate question
    assert "dt/2→dt/4" in text and "dt convergence:" in text
    assert "## E6" in text and "**Answer.**" in text
    assert doc["control_rate_hz"] == 10000.0
    # E8 (uneven ground, intervals) and E5 by CMA-ES next to the grid
    assert "## E8" in text and "### E5 by CMA-ES" in text
    # E7: PD^alpha beside the paper's controllers, at the base case and over the ground
    e7 = text.split("## E7")[1].split("## E8")[0]
    assert "| index | unit | PD-P |" in e7 and "| PD^α |" in e7
    assert set(doc["e7"]["base"]) == {"pd_p", "pd_pf", "pd_alpha"}
    assert [r["pd_alpha.alpha"] for r in doc["e7"]["alpha"]] == [0.75, 1.0, 1.25]
    assert (out / "fig_e7_alpha.png").exists() and (out / "fig_e7_ground_tmax400.png").exists()
    # with alpha = 1 and PD-P's gains, PD^alpha comes within 1 % of PD-P (its rate term is a
    # backward difference of the error instead of the measured rate)
    pp, pa = doc["e7"]["base"]["pd_p"]["runs"][0], doc["e7"]["base"]["pd_alpha"]["runs"][0]
    for n in ("E_av", "T_L", "eps_xH"):
        assert abs(pa[n] - pp[n]) <= 0.01 * abs(pp[n]), n
    assert len(doc["e8"]["points"]) == 4 and doc["e8"]["seeds"] == 3
    for c in ("pd_p", "pd_pf"):
        cma = doc["tuning_cmaes"][c]
        assert cma["cmaes_runs"] <= 16 and cma["grid_best"] == doc["tuning"][c]["score"]
    for n in list(range(4, 18)):
        assert list(out.glob(f"fig{n:02d}_*.png")), f"figure {n} missing"
    assert list(out.glob("fig_e6_map_tmax400.png")) and list(out.glob("fig_e6_eps_xH_*.png"))
    assert doc["pd_p_kp1"]["best"] in doc["pd_p_kp1"]["values"]
    # E6's drive rows: the counts of points within 1 %/1 mm of 10 kHz over topics, as the
    # CSV's numbers give them
    import csv

    rows = list(csv.DictReader((out / "e6_control_rate.csv").open()))
    ref = {(r["actuator.t_max"], r["ground.scale"]): r for r in rows
           if r["force_loop"] == "topic" and r["controller"] == "pd_pf"
           and float(r["rate_hz"]) == 10000.0}
    for rate in (1000.0, 10000.0):
        drive = [r for r in rows if r["force_loop"] == "drive" and float(r["rate_hz"]) == rate]
        assert len(drive) == len(ref)
        within = sum(
            all(abs(float(d[n]) - float(b[n])) <= 0.01 * abs(float(b[n])) for n in ("E_av", "T_L"))
            and all(abs(float(d[n]) - float(b[n])) <= 1e-3
                    for n in ("eps_xH", "eps_yH", "eps_xF", "eps_yF"))
            for d in drive for b in [ref[(d["actuator.t_max"], d["ground.scale"])]])
        hz = f"{rate / 1000:g} kHz"
        table = text.split("**PD-P&F with its force loop in the drive**")[1].splitlines()
        cells = [line.split("|") for line in table if line.startswith(f"| {hz} |")][0]
        assert cells[3].strip() == f"{within}/{len(ref)}", (hz, within, cells)
