"""The claim rules C1-C4 on synthetic inputs: holds, fails and undecided."""
import math

import pytest

from hexapod_bringup.core import claims
from hexapod_bringup.core.claims import Measured, all3, any3, at_least, less

NAMES = ("E_av", "T_L", "F_L", "eps_xH", "eps_yH", "eps_xF", "eps_yF", "L")


def m(value, band=0.0, converged=True):
    return Measured(value, value - band, value + band, converged)


def pt(scale=1.0, band=0.0, converged=True, **over):
    base = dict(E_av=500.0, T_L=380.0, F_L=640.0, eps_xH=0.05, eps_yH=0.035, eps_xF=0.05,
                eps_yF=0.034, L=1.0)
    base.update(over)
    return {n: m(v * (scale if n.startswith("eps") or n == "T_L" else 1.0), band, converged)
            for n, v in base.items()}


def test_three_valued_logic():
    assert all3([True, True]) is True and all3([True, None]) is None
    assert all3([None, False]) is False
    assert any3([False, True]) is True and any3([False, None]) is None
    assert any3([False, False]) is False


def test_less_is_decided_only_outside_the_bands_and_when_converged():
    assert less(m(1.0, 0.1), m(2.0, 0.1)) is True
    assert less(m(2.0, 0.1), m(1.0, 0.1)) is False
    assert less(m(1.0, 0.6), m(2.0, 0.6)) is None              # bands overlap
    assert less(m(1.0, converged=False), m(2.0)) is None        # not dt-converged
    assert less(m(1.0), Measured(math.nan, math.nan, math.nan, True)) is True  # b diverged
    assert at_least(m(3.0, 0.5), 2.0) is True and at_least(m(2.2, 0.5), 2.0) is None
    assert at_least(m(1.0, 0.5), 2.0) is False


def test_c1_holds_fails_and_is_undecided():
    pd_p = pt(scale=1.0)
    assert claims.c1(pd_p, pt(scale=0.5)).status == "holds"
    assert claims.c1(pd_p, pt(scale=0.5, eps_xF=0.2)).status == "fails"
    # PD-P&F better everywhere but one margin lies inside the bands
    undecided = pt(scale=0.5, band=0.0)
    undecided["eps_yF"] = m(0.0339, band=0.001)
    assert claims.c1(pd_p, undecided).status == "undecided"
    unconverged = pt(scale=0.5)
    unconverged["T_L"] = m(190.0, converged=False)
    v = claims.c1(pd_p, unconverged)
    assert v.status == "undecided" and "T_L" in v.evidence and not v.holds


def test_c2_over_a_sweep():
    vals = [0.1, 1.0, 10.0]
    good = {400.0: {"pd_p": [pt()] * 3, "pd_pf": [pt(scale=0.5)] * 3}}
    assert claims.c2(good, vals).status == "holds"
    bad = {400.0: {"pd_p": [pt()] * 3, "pd_pf": [pt(scale=0.5)] * 2 + [pt(scale=2.0)]}}
    v = claims.c2(bad, vals)
    assert v.status == "fails" and "above at 1e+03 %" in v.evidence
    open_ = {400.0: {"pd_p": [pt()] * 3,
                     "pd_pf": [pt(scale=0.5)] * 2 + [pt(scale=0.5, converged=False)]}}
    v = claims.c2(open_, vals)
    assert v.status == "undecided" and "undecided at 1e+03 %" in v.evidence


def test_c3_degradation_factor_with_bands():
    base = {"pd_p": pt(), "pd_pf": pt(scale=0.5)}
    assert claims.c3({"pd_p": pt(scale=10.0), "pd_pf": pt(scale=10.0)}, base, 150).status \
        == "holds"
    assert claims.c3({"pd_p": pt(scale=10.0), "pd_pf": pt(scale=0.6)}, base, 150).status \
        == "fails"
    near = {"pd_p": pt(scale=10.0), "pd_pf": pt(scale=1.0, band=0.01)}  # ratio ~2 +- band
    assert claims.c3(near, base, 150).status == "undecided"


def test_c4_any_sign_of_instability():
    calm = {1.0: {"pd_p": pt(), "pd_pf": pt()}, 3.0: {"pd_p": pt(), "pd_pf": pt()}}
    steps_calm = {3.0: {"pd_p": m(100.0), "pd_pf": m(120.0)}}
    assert claims.c4(calm, steps_calm).status == "fails"
    steps_big = {3.0: {"pd_p": m(100.0), "pd_pf": m(500.0)}}
    assert claims.c4(calm, steps_big).status == "holds"
    steps_open = {3.0: {"pd_p": m(100.0), "pd_pf": m(200.0, band=20.0)}}
    assert claims.c4(calm, steps_open).status == "undecided"
    growing = {1.0: {"pd_p": pt(), "pd_pf": pt()},
               3.0: {"pd_p": pt(), "pd_pf": pt(scale=3.0)}}
    assert claims.c4(growing, steps_calm).status == "holds"


@pytest.mark.parametrize("status", ["holds", "fails", "undecided"])
def test_verdict_holds_only_when_decided(status):
    v = claims.Verdict("C9", "s", status, "r", "e")
    assert v.holds is (status == "holds")
