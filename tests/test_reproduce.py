"""`hexapod reproduce --quick`: the report states every claim with its numbers."""
import json
import subprocess
import sys


def test_reproduce_quick_writes_report_with_all_claims(tmp_path):
    out = tmp_path / "report"
    r = subprocess.run([sys.executable, "-m", "hexapod_metrics.cli", "reproduce", "--quick",
                        "--backend", "inline", "--no-progress", "--out", str(out)],
                       capture_output=True, text=True, timeout=600, check=True)
    text = (out / "README.md").read_text()
    for claim in ("C1", "C2", "C3", "C4"):
        assert f"| {claim} |" in text
        assert claim in r.stdout
    doc = json.loads((out / "results.json").read_text())
    verdicts = {c["claim"]: c["holds"] for c in doc["claims"]}
    assert verdicts["C1"] is True and verdicts["C3"] is True   # PD-P&F tracks better at base
    for n in list(range(4, 18)):
        assert list(out.glob(f"fig{n:02d}_*.png")), f"figure {n} missing"
    assert doc["pd_p_kp1"]["best"] in doc["pd_p_kp1"]["values"]
