"""The benchmark suite runs end to end on a small setting and its figures are consistent (not timed)."""

import json
from pathlib import Path

import pytest

from implc.cli.commands import main


@pytest.mark.slow
def test_bench_suite_small(tmp_path, capsys, monkeypatch):
    """Run from another folder without --out: the results go to ./implc-bench there, never into the
    checkout (the README quotes benchmarks/results/)."""
    results = Path(__file__).resolve().parent.parent / "benchmarks" / "results"
    quoted = {p.name: p.read_bytes() for p in results.iterdir()}
    monkeypatch.chdir(tmp_path)
    (tmp_path / "models").mkdir()
    (tmp_path / "models" / "ball.vm").write_text("# --scale 0.5\nx var-x\ny var-y\nz var-z\nx2 square x\n"
                                                  "y2 square y\nz2 square z\ns add x2 y2\nt add s z2\n"
                                                  "r const 2.25\nout sub t r\n")
    status = main(["bench", "--depth", "5", "--workers", "1,2", "--repeats", "1", "--baseline-depths", "5",
                   "--growth-depths", "5,6", "--tightness-scenes", "torus,paper_blobs", "--tightness-depth", "6",
                   "--tightness-models", "ball",
                   "--models-dir", str(tmp_path / "models"), "--models-depths", "5,6", "--solid-depths", "5,6",
                   "--viewer-scenes", "torus", "--viewer-depths", "7", "--scale-scenes", "torus",
                   "--scale-depths", "6,7", "--mesh-scenes", "torus", "--mesh-models", "ball", "--mesh-depths", "5",
                   "--mesh-quality-depth", "5", "--cluster-scene", "torus", "--cluster-depth", "7",
                   "--cluster-big-depth", "8", "--cluster-noop-tasks", "50", "--cluster-plan-depths", "7,9"])
    assert status == 0
    assert "Table 1 at 32³" in capsys.readouterr().out
    assert {p.name: p.read_bytes() for p in results.iterdir()} == quoted
    tmp_path = tmp_path / "implc-bench"
    data = json.loads((tmp_path / "latest.json").read_text())
    assert data["machine"]["cores"] >= 1 and data["machine"]["llvmlite"]
    table = data["table1"]
    assert {r["workers"] for r in table} == {1, 2}
    for scene in {r["scene"] for r in table}:  # the same voxels whatever the worker count
        assert len({r["voxels"] for r in table if r["scene"] == scene}) == 1
    assert [r["scene"] for r in data["tightness"]] == ["torus", "paper_blobs", "ball"]
    for r in data["tightness"]:  # no sign-change cell is ever missed, and the default is never looser
        assert r["natural_ratio"] >= r["default_ratio"] >= 1.0 and r["tightest_ratio"] >= 1.0
    for r in data["baselines"]:
        assert r["voxels"] >= r["numpy_cells"] > 0
        if "symengine llvm_cells" in r:
            assert r["symengine llvm_cells"] == r["numpy_cells"]
    (model,) = data["models"]["rows"]  # the ball of radius 1.5 over [-2, 2]³ (its --scale)
    assert model["model"] == "ball" and model["instructions"] == 10
    assert model["depths"]["6"]["voxels"] > model["depths"]["5"]["voxels"] > 0
    assert model["missed_128"] == 0 and model["voxels_128"] >= model["sign_change_cells_128"] > 0
    assert model["compile_fresh_empty_cache_s"] > 0 and model["compile_fresh_s"] > 0
    for r in data["solids"]:  # the volume of {F < 0} lies in the bounds, which shrink with depth
        assert 0 < r["volume_lo"] < r["volume_hi"] and r["inside_octants"] > 0
    torus = [r for r in data["solids"] if r["scene"] == "torus"]
    assert torus[1]["volume_hi"] - torus[1]["volume_lo"] < torus[0]["volume_hi"] - torus[0]["volume_lo"]
    small, large = data["scale"]  # fresh processes: voxels grow, the peak is the process's, storing is a sliver
    assert large["voxels"] > small["voxels"] > 0 and small["peak_bytes"] > 0 and large["estimated_bytes"] > 0
    assert 0 <= large["storage_s"] < large["wall_s"] and 0 < large["yield"] <= 1.5
    (view,) = data["viewer"]
    assert view["chunks"] >= 1 and view["voxels"] > 0 and (view["points"] is None or view["points"] > 0)
    cluster = data["cluster"]  # both runs timed, the big run measured, the plan grown
    assert cluster["overhead"]["here_s"] > 0 and cluster["overhead"]["voxels"] > 0 and cluster["tasks_per_s"] > 0
    assert cluster["big"]["voxels"] > cluster["overhead"]["voxels"] and all(cluster["big"]["worker_peak_mib"])
    assert [g["depth"] for g in cluster["plan"]] == [7, 9] and cluster["plan"][1]["tasks"] >= 1
    for r in data["mesh"]:  # closed, manifold meshes from implc; marching cubes' figures beside them
        assert r["surface"] in ("torus", "ball") and r["triangles"] > 0
        assert r["unproven_cells"] == 0 < r["crossed_cells"]  # smooth, no singular point: every cell proven
        quality = r["implc"]
        assert (quality["open_edges"], quality["flipped_edges"], quality["degenerate"]) == (0, 0, 0)
        assert quality["manifold3d"] == "NoError" and quality["self_intersecting"] == 0
        assert quality["max_distance_cells"] < 1 and r["marching_cubes"]["triangles"] > 0
        assert r["marching_cubes"]["quality"]["normal_deviation_median_deg"] < 90  # wound outward, as ours
        simplified = r["simplified"]  # nothing flat on a torus or a ball: the same mesh, still valid
        assert simplified["triangles"] == r["triangles"] and simplified["cpu_s"] >= 0
        assert simplified["quality"]["manifold3d"] == "NoError" and simplified["quality"]["self_intersecting"] == 0
    growth = data["growth"]
    assert growth[1]["voxels"] > growth[0]["voxels"]
    assert (tmp_path / "latest.md").read_text().startswith("## implc benchmarks")
