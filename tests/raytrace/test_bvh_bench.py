"""`lbwater bench bvh` runs end to end on a small grid, and its in-run check catches wrong hits."""

import json

import numpy as np
import pytest

from app.bench_bvh import check_grid_hits, rays_incoherent, rays_primary
from app.cli import main
from app.meshes import height_field_grid
from raytrace import intersect


def test_bench_runs_and_writes_results(tmp_path, rt):
    status = main(["bench", "bvh", "--sizes", "17", "--rays", "small", "--reps", "1",
                   "--meshes", "bunny_5k.obj", "--no-embree", "--check-rays", "50",
                   "--out", str(tmp_path)])
    assert status == 0
    res = json.loads((tmp_path / "bvh.json").read_text())
    row = res["grids"][0]
    assert row["tris"] == 2 * 16 * 16 and row["check"] == "ok"
    assert row["primary_hit_agreement"] == 1.0 and row["incoherent_checked"] == 50
    assert row["build_ms"] > 0 and row["primary_Mrays_s"] > 0
    assert row["sort_ours_ms"] > 0                       # the sort comparison ran too
    assert row["sort_ours4_ms"] > 0 and row["sort_ours8_ms"] > 0
    assert row["sort_ours_ms"] == row[f"sort_ours{row['sort_default_radix_bits']}_ms"]
    assert res["meshes"][0]["tris"] == 4968
    assert (tmp_path / "bvh_grids.csv").read_text().startswith("grid,")


def test_bench_pairs_our_runs_with_embree_runs(tmp_path, rt):
    pytest.importorskip("embreex")
    status = main(["bench", "bvh", "--sizes", "17", "--rays", "small", "--reps", "3",
                   "--meshes", "", "--no-sort-compare", "--check-rays", "20",
                   "--out", str(tmp_path)])
    assert status == 0
    row = json.loads((tmp_path / "bvh.json").read_text())["grids"][0]
    for kind in ("primary", "incoherent"):
        assert row[f"{kind}_embree_1t_Mrays_s"] > 0
        assert row[f"{kind}_vs_embree_1t_paired"] > 0
        assert row[f"{kind}_embree_prim_agreement"] > 0.99


def test_bench_check_detects_wrong_hits(rt):
    n = 33
    v, t = height_field_grid(n)
    for o, d in (rays_primary(64, 36), rays_incoherent(3000, np.random.default_rng(1))):
        hits = intersect(v, t, o, d, device=rt)
        good = check_grid_hits(n, v, t, o, d, hits, np.inf, 300)
        assert good["hit_agreement"] == 1.0 and good["prim_or_t_agreement"] == 1.0
        wrong = dict(hits)
        wrong["prim"] = np.where(hits["prim"] >= 0, (hits["prim"] + 7) % len(t), -1)
        wrong["t"] = hits["t"] * 1.01
        bad = check_grid_hits(n, v, t, o, d, wrong, np.inf, 300)
        assert bad["prim_or_t_agreement"] < 0.05
        missing = dict(hits)
        missing["prim"] = np.full_like(hits["prim"], -1)
        assert check_grid_hits(n, v, t, o, d, missing, np.inf, 300)["hit_agreement"] < 0.9


def test_bench_rejects_bad_sizes(capsys):
    assert main(["bench", "bvh", "--sizes", "3,x"]) == 2
    assert "--sizes must be integers" in capsys.readouterr().err
    assert main(["bench", "bvh", "--sizes", "1"]) == 2
