"""When is it measured (core/windows.py): where a comparison's sign settles, what counts as
stationary, and how a window-dependent verdict reads."""
from __future__ import annotations

from hexapod_bringup.core.windows import FIRST_WINDOW, settling, stationary
from hexapod_metrics.core.indices import Indices


def _ix(eps_xF: float, trk_xF: float = 0.02) -> Indices:
    return Indices(E_av=1.0, T_L=1.0, F_L=1.0, eps_xH=0.02, eps_yH=0.01, eps_xF=eps_xF,
                   eps_yF=0.01, L=1.0, trk_xF=trk_xF)


def _runs(a_vals, b_vals):
    return [_ix(v) for v in a_vals], [_ix(v) for v in b_vals]


def test_a_sign_that_never_changes_settles_at_the_first_window():
    a, b = _runs([0.1, 0.2, 0.3, 0.4], [0.05, 0.1, 0.2, 0.3])
    s = settling(a, b, "eps_xF")
    assert s.from_cycle == FIRST_WINDOW and s.final == -1
    assert not s.window_dependent()
    assert s.describe("PD-P", "PD-P&F") == "PD-P&F lower in every cycle from 1"


def test_the_growing_errors_of_issue_36_cross_and_the_verdict_names_the_cycle():
    # b starts worse and drifts less: b - a goes +, +, 0-ish, -, -
    a = [0.0226 + 0.0050 * k for k in range(8)]
    b = [0.0271 + 0.0030 * k for k in range(8)]
    s = settling(*_runs(a, b), "eps_xF")
    first_lower = next(k for k in range(8) if b[k] < a[k])
    assert s.from_cycle == first_lower and s.final == -1 and s.window_dependent()
    assert s.describe("PD-P", "PD-P&F") == (
        f"depends on the window: PD-P lower in cycles 1-{first_lower - 1}, PD-P&F lower "
        f"from cycle {first_lower}")


def test_cycle_zero_starts_from_rest_and_does_not_count():
    a, b = _runs([0.1, 0.2, 0.3], [0.5, 0.1, 0.2])  # b worse only in cycle 0
    assert not settling(a, b, "eps_xF").window_dependent()


def test_a_cycle_that_was_not_a_walk_is_no_sign():
    a, b = _runs([0.1, 0.2, 0.3, 0.4], [0.05, 0.1, 0.2, 0.3])
    b[3] = None  # fallen
    s = settling(a, b, "eps_xF")
    assert s.signs[-1] == 0 and s.from_cycle == 3 and s.window_dependent()
    assert settling([], [], "eps_xF").describe("a", "b") == "not scored"


def test_stationary_means_cycles_10_and_20_within_the_dt_tolerance():
    flat = [_ix(0.02, trk_xF=0.02 + 1e-6 * k) for k in range(21)]
    assert stationary(flat, "trk_xF")          # 10 um apart: under 1 mm
    assert stationary(flat, "E_av")
    growing = [_ix(0.02 + 2e-4 * k) for k in range(21)]  # the drift: 2 mm from 10 to 20
    assert not stationary(growing, "eps_xF")
    relative = [Indices(E_av=100.0 * (1 + 0.002 * k), T_L=1.0, F_L=1.0, eps_xH=0.02,
                        eps_yH=0.01, eps_xF=0.02, eps_yF=0.01, L=1.0) for k in range(21)]
    assert not stationary(relative, "E_av")    # 2 % apart: over the 1 % of a non-length
    assert not stationary(flat[:15], "trk_xF")  # cycle 20 never scored
    flat[20] = None
    assert not stationary(flat, "trk_xF")


def _verdict(status: str):
    from hexapod_bringup.core.claims import Verdict
    return Verdict("C1", "statement", status, "rule", "evidence")


def test_a_claim_the_same_in_every_window_says_so():
    from hexapod_bringup.core.windows import over_windows
    w = over_windows(lambda k: _verdict("holds"), 1, 20)
    assert w.status == "holds" and w.text() == "holds in every window (cycles 1-20)"


def test_a_claim_that_changes_names_the_cycles():
    from hexapod_bringup.core.windows import DEPENDS, over_windows
    seq = {1: "fails", 2: "fails", 3: "undecided"}
    w = over_windows(lambda k: _verdict(seq.get(k, "holds")), 1, 20)
    assert w.status == DEPENDS
    assert w.text() == ("depends on the window: fails in cycles 1-2, undecided in cycle 3, "
                        "holds from cycle 4")
    back = over_windows(lambda k: _verdict("fails" if k == 20 else "holds"), 1, 20)
    assert back.text() == "depends on the window: holds in cycles 1-19, fails from cycle 20"


def test_the_claims_decided_on_the_stationary_errors_read_trk_not_eps():
    from hexapod_bringup.core import claims
    from hexapod_bringup.core.convergence import STATIONARY_TRACKING

    def pt(eps_xF: float, trk_xF: float):
        vals = {n: 0.01 for n in ("E_av", "T_L", "eps_xH", "eps_yH", "eps_yF", "trk_xH")}
        vals.update(eps_xF=eps_xF, trk_xF=trk_xF)
        return {n: claims.Measured.exact(v) for n, v in vals.items()}

    pd_p, pd_pf = pt(0.0274, 0.0193), pt(0.0295, 0.0258)
    pd_pf["T_L"] = pd_pf["eps_xH"] = pd_pf["eps_yH"] = pd_pf["eps_yF"] = pd_pf["trk_xH"] = \
        claims.Measured.exact(0.005)
    assert claims.c1(pd_p, pd_pf).status == claims.FAILS
    assert "eps_xF" in claims.c1(pd_p, pd_pf).against[0]
    st = claims.c1(pd_p, pd_pf, STATIONARY_TRACKING)
    assert st.status == claims.FAILS and "trk_xF" in st.against[0]
    pd_pf["trk_xF"] = claims.Measured.exact(0.001)
    assert claims.c1(pd_p, pd_pf, STATIONARY_TRACKING).status == claims.HOLDS
