"""The benchmark's quick mode runs and reports finite figures (a regression guard: no timing
assertions here, SPEC 8 is judged by `make bench`)."""
import json
import math
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

BENCH = Path(__file__).resolve().parent.parent / "bench"
sys.path.insert(0, str(BENCH))
import compare  # noqa: E402
import scenes  # noqa: E402


def test_quick_benchmark_reports_finite_figures(tmp_path):
    result = subprocess.run([sys.executable, str(BENCH / "compare.py"), "--quick", "--out", str(tmp_path)],
                            capture_output=True, text=True, timeout=600)
    assert result.returncode == 0, result.stderr[-2000:]
    report = json.loads((tmp_path / "compare_quick.json").read_text())
    ours = [row for row in report["rows"] if row["engine"] == "vplayground"]
    assert {row["scene"] for row in ours} == {"loose pile of 150", "300 in columns of two", "300 at rest",
                                              "10-box tower"}
    for row in report["rows"]:
        assert math.isfinite(row["rtf"]) and row["rtf"] > 0
        assert math.isfinite(row["max_ms"]) and row["max_ms"] > 0
        for phase in ("falling", "resting"):
            if row.get(phase):
                assert all(math.isfinite(v) and v >= 0 for v in row[phase].values())
    stages = report["stages_ms_percent"].values()
    assert all(math.isfinite(ms) and ms >= 0 for ms, _ in stages)
    assert abs(sum(percent for _, percent in stages) - 100.0) < 1.0


@pytest.mark.parametrize("peer_class, threads", [(compare.Rapier, 1), (compare.RapierParallel, 2),
                                                 (compare.Jolt, 1), (compare.Jolt, 2)],
                         ids=["rapier", "rapier-parallel-2", "jolt", "jolt-2"])
def test_rust_peer_drops_boxes_onto_the_ground(peer_class, threads):
    """A Rust peer (bench/peers, built by its build.sh, never by the tests) reads the scene the
    bench writes in our frame: four tilted 0.5 m boxes dropped side by side land flat on the ground
    (centres at z = 0.25 m) where they fell, and fall asleep; on the threads it is given."""
    boxes = [scenes.box((0.5, 0.5, 0.5), (x, y, 1.0), scenes.yaw_pitch_roll_quaternion((0.05, -0.05, 0.7)))
             for x, y in ((0, 0), (2, 0), (0, -2), (-2, 2))]
    try:
        peer = peer_class(boxes, threads=threads)
    except compare.PeerMissing:
        pytest.skip(f"{peer_class.program} is not built (bench/peers/build.sh)")
    report = peer.run(steps=4 * compare.RATE, budget_s=10.0)
    assert report["complete"] and not report["errors"]
    assert report["engine"].endswith(f"threads: {threads}") or (threads == 1 and peer_class is compare.Rapier)
    positions = peer.positions()
    np.testing.assert_allclose(positions[:, 2], 0.25, atol=0.01)
    np.testing.assert_allclose(positions[:, :2], [b[1][:2] for b in boxes], atol=0.05)
    assert peer.resting_count() == len(boxes)


def test_falling_phase_bench_reports_finite_figures(tmp_path):
    """bench/falling.py (issue 36.2's and 36.3's figures) on small piles: every engine built
    reports a finite phase, our figures over each peer's are there, and with --threads 2 each
    engine's phase on one and two threads and the speed-ups."""
    result = subprocess.run([sys.executable, str(BENCH / "falling.py"), "--boxes", "40", "--seconds", "0.5",
                             "--runs", "2", "--threads", "2", "--out", str(tmp_path)],
                            capture_output=True, text=True, timeout=600)
    assert result.returncode == 0, result.stderr[-2000:]
    report = json.loads((tmp_path / "falling.json").read_text())
    assert set(report["piles"]) == {"loose", "dense"}
    for rows in report["piles"].values():
        ours = rows["vplayground"]
        for row in rows.values():
            assert 0 < row["median_ms"] <= row["p95_ms"] <= row["max_ms"] <= max(row["runs_longest_ms"])
            assert len(row["runs_longest_ms"]) == 2 and math.isfinite(row["total_ms"])
        assert {key for key in ours if key.startswith("x_")} == {f"x_{name}" for name in rows if name != "vplayground"}
    assert set(report["threads"]) == {"loose", "dense"}
    for rows in report["threads"].values():
        engines = {name for name in rows if name not in ("load_average", "round_trip_ns")}
        assert "vplayground" in engines and engines <= {"vplayground", "rapier-parallel", "jolt"}
        for name in engines:
            one, two, speedup = rows[name]["1"], rows[name]["2"], rows[name]["speedup"]
            for row in (one, two):
                assert 0 < row["median_ms"] <= row["p95_ms"] <= row["max_ms"] <= max(row["runs_longest_ms"])
            assert speedup["total_ms"] == pytest.approx(one["total_ms"] / two["total_ms"])
        assert rows["round_trip_ns"] is None or rows["round_trip_ns"] > 0
        measured = rows["vplayground"]["measured"]  # ours as a World runs by default
        assert 0 < measured["median_ms"] <= measured["p95_ms"] <= measured["max_ms"]
        assert rows["vplayground"]["speedup measured"]["total_ms"] == pytest.approx(
            rows["vplayground"]["1"]["total_ms"] / measured["total_ms"])
