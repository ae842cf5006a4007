"""The benchmark's quick mode runs and reports finite figures (a regression guard: no timing
assertions here, SPEC 8 is judged by `make bench`)."""
import json
import math
import subprocess
import sys
from pathlib import Path

BENCH = Path(__file__).resolve().parent.parent / "bench"


def test_quick_benchmark_reports_finite_figures(tmp_path):
    result = subprocess.run([sys.executable, str(BENCH / "compare.py"), "--quick", "--out", str(tmp_path)],
                            capture_output=True, text=True, timeout=600)
    assert result.returncode == 0, result.stderr[-2000:]
    report = json.loads((tmp_path / "compare_quick.json").read_text())
    ours = [row for row in report["rows"] if row["engine"] == "vplayground"]
    assert {row["scene"] for row in ours} == {"pile of 150", "300 at rest", "10-box tower"}
    for row in report["rows"]:
        assert math.isfinite(row["rtf"]) and row["rtf"] > 0
        assert math.isfinite(row["max_ms"]) and row["max_ms"] > 0
        for phase in ("falling", "resting"):
            if row.get(phase):
                assert all(math.isfinite(v) and v >= 0 for v in row[phase].values())
    stages = report["stages_ms_percent"].values()
    assert all(math.isfinite(ms) and ms >= 0 for ms, _ in stages)
    assert abs(sum(percent for _, percent in stages) - 100.0) < 1.0
