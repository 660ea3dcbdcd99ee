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
