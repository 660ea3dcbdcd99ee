"""``lbwater study NAME --quick``: every study writes its CSV and chart at a tiny size, and the
numbers behave as the physics and the renderer say they must."""

import csv
import math

import numpy as np
import pytest

from app import charts
from app.studies import STUDIES, fit_order, run_study


def _rows(path):
    with open(path, newline="") as fh:
        return list(csv.DictReader(fh))


@pytest.fixture(scope="module")
def out(tmp_path_factory):
    return tmp_path_factory.mktemp("studies")


@pytest.mark.parametrize("name", list(STUDIES))
def test_study_writes_csv_and_chart(rt, out, name):
    csv_path, png_path = run_study(name, out, rt, quick=True, log=lambda m: None)
    rows = _rows(csv_path)
    assert len(rows) >= 2 and all(r["mode"] == "quick" for r in rows)
    assert png_path.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n" and png_path.stat().st_size > 5000
    assert not list(out.glob(".*partial*")), "no temporary file left behind"
    if name == "lbm-resolution":
        stoker = [float(r["error"]) for r in rows if r["case"] == "stoker"]
        seiche = [float(r["error"]) for r in rows if r["case"] == "seiche"]
        assert stoker == sorted(stoker, reverse=True) and stoker[-1] < 0.6 * stoker[0]
        assert seiche[-1] < seiche[0] and seiche[-1] < 5e-3
        assert float(rows[2]["order"]) > 0.5       # the dam break converges
    elif name == "lbm-precision":
        err = {(r["storage"], r["case"]): float(r["error"]) for r in rows}
        assert ("fp32", "stoker") in err and ("fp32", "seiche") in err
        for (storage, case), e in err.items():   # fp16s: the same physics, a little less exact
            assert e <= 5 * err[("fp32", case)] + 1e-5, (storage, case)
    elif name == "spp":
        err = {int(r["value"]): float(r["rmse"]) for r in rows}
        assert err[8] < err[1]
    elif name == "bounces":
        err = {int(r["value"]): float(r["rmse"]) for r in rows}
        assert err[0] > err[1] > err[5]          # depth matters in the glass bunny scene
    elif name == "fresnel":
        assert {r["variant"] for r in rows} == {"exact", "schlick"}
    elif name == "bvh":
        assert {r["bvh"] for r in rows} == {"refit", "rebuild"}
        assert len({r["frame"] for r in rows}) >= 3
        assert all(float(r["update_ms"]) > 0 and float(r["trace_ms"]) > 0 for r in rows)
    elif name == "grid-vs-pixels":
        ppc = [float(r["pixels_per_cell"]) for r in rows]
        assert ppc == sorted(ppc, reverse=True) and ppc[0] > 3 * ppc[-1]
        assert float(rows[0]["diff_to_next"]) > 0
    elif name == "stability":
        _check_stability_map(rows)
    elif name == "caustics-noise":
        err = [float(r["error_vs_reference"]) for r in rows]
        flick = [float(r["flicker"]) for r in rows]
        assert err == sorted(err, reverse=True) and err[-1] < 0.6 * err[0]
        assert flick[-1] < 0.6 * flick[0] and float(rows[0]["flicker"]) > 0
        assert all(float(r["flicker_blended"]) < float(r["flicker"]) for r in rows)


def _check_stability_map(rows):
    """The coarse map has both regions; the guard keeps every run finite, and every case it
    acted on says so in its report with the counts; where it stays idle it changes nothing."""
    assert {r["plain_status"] for r in rows} == {"stable", "blew up"}
    assert all(r["guard_status"] == "stable" for r in rows)           # finite, every one
    acted = [r for r in rows if int(r["guard_cells_limited"]) + int(r["guard_restored"]) > 0]
    assert acted and {r["category"] for r in acted} <= {"saved", "guard_only"}
    for r in acted:
        assert r["guard_report"] and int(r["guard_report_mismatches"]) == 0, r
        assert int(r["guard_reported_cells"]) == int(r["guard_cells_limited"])
        assert int(r["guard_reported_restores"]) == int(r["guard_restored"])
    for r in rows:
        if r["plain_status"] == "stable":
            assert float(r["plain_volume_change"]) == 0.0   # exact volume, to the bit
            assert float(r["guard_budget_error"]) <= 1e-6   # clipped/created book the rest
        if r["category"] == "stable":                       # an idle guard is transparent
            assert float(r["guard_change_l1"]) == 0.0 and not r["guard_report"]
    calm = [r for r in rows if r["kind"] == "dam" and float(r["dam_ratio"]) == 0.5]
    assert calm and all(float(r["guard_stoker_error"]) < 0.05 for r in calm)


def test_fit_order_recovers_a_known_power():
    h = np.array([0.1, 0.05, 0.025])
    assert fit_order(h, 3 * h**2) == pytest.approx(2.0, abs=1e-9)
    assert math.isnan(fit_order([0.1], [0.2]))


def test_chart_save_is_atomic(tmp_path):
    fig, ax = charts.figure("t", "x", "y", log=("x",))
    charts.series(ax, [1, 2, 4], [3, 2, 1], label="a", notes=["p", "q", "r"])
    charts.save(fig, tmp_path / "c.png", source="test")
    assert (tmp_path / "c.png").read_bytes()[:4] == b"\x89PNG"
    assert [p.name for p in tmp_path.iterdir()] == ["c.png"]
