"""``lbwater study stability``: where the plain scheme fails and what the guard does there.

A grid of cases, each run twice for the same number of steps on the same lattice: the plain
solver (``ShallowWater(guard=False)``: no limiter, no damping, no restore; a non-finite state is
only reported) and the guarded one (the default). Axes:

* depth: the lake's depth h0 on the lattice the solver chooses for a 0.3 m lake, so g h0/e^2
  runs from 1/6 to just under the limiter's cap 0.6 (in lattice units only g h0/e^2 matters:
  a lake twice as deep on its own lattice is the same run);
* tau: the BGK relaxation time (viscosity nu = (tau - 1/2) e dx / 3);
* disturbance: drops (height a fraction of ``max_drop_height``, the room the depth cap leaves;
  two radii), a dip to 10% of the depth, pushes whose speed is a Froude number u/sqrt(g h0) from
  0.3 to 2.5, and Stoker's wet dam break (h_r/h_0 = 0.5, 0.2, 0.05; supercritical below ~0.14).

Per run: stable or the step it blew up (non-finite, or a depth <= 0), the largest Froude number,
the volume (exact float64 sum of the stored populations: the plain scheme keeps it to the bit
while stable), and for the guarded run what the guard did (cells limited, restores, volume
clipped and created, its report lines). Errors against a reference where one exists: Stoker's
analytic solution for the dam breaks (L1 of h / h0); for every case the guarded run's change
against the plain one where that stayed finite (L1 of h / h0: what the guard's clipping cost).
"""

from __future__ import annotations

import math

import numpy as np

G = 9.81
#: The lake the lattice is chosen for (the solver's own rules): g H/e^2 = 1/3 at H.
DESIGN_DEPTH = 0.3

#: Map categories: (key, label, colour, marker), in legend order.
CATEGORIES = (
    ("stable", "both stable, guard idle", "#009E73", "o"),
    ("guard_only", "plain stable, guard acted", "#0072B2", "s"),
    ("saved", "plain blew up, guard kept it finite", "#E69F00", "^"),
    ("failed", "guard failed (non-finite or error)", "#D55E00", "X"),
    ("refused", "refused by the solver's checks", "0.6", "."),
)


def _sizes(quick: bool) -> dict:
    if quick:
        return {"n": 24, "steps": 160, "chunks": 8, "stoker_n": 64, "depths": (0.3, 0.5),
                "taus": (0.505, 0.8), "drops": ((1.0, 3),), "pushes": (0.5, 1.5, 2.5),
                "ratios": (0.5, 0.05)}
    return {"n": 64, "steps": 600, "chunks": 60, "stoker_n": 200,
            "depths": (0.15, 0.3, 0.45, 0.53), "taus": (0.502, 0.51, 0.55, 0.8),
            "drops": ((0.5, 3), (1.0, 3), (0.5, 8), (1.0, 8)),
            "pushes": (0.3, 0.7, 1.0, 1.5, 2.5), "ratios": (0.5, 0.2, 0.05)}


def cases(quick: bool) -> list[dict]:
    """The disturbances, in map order (each is run at every depth and tau)."""
    sz = _sizes(quick)
    out = [{"kind": "drop", "case": f"drop {f:g} cap, r {r} cells", "fraction": f,
            "radius_cells": r} for f, r in sz["drops"]]
    out.append({"kind": "dip", "case": "dip to 0.1 h0, r 5 cells", "fraction": -0.9,
                "radius_cells": 5})
    out += [{"kind": "push", "case": f"push Fr {fr:g}", "froude": fr} for fr in sz["pushes"]]
    out += [{"kind": "dam", "case": f"dam break hr/h0 {q:g}", "ratio": q} for q in sz["ratios"]]
    return out


def design_speed(dx: float) -> float:
    """The lattice speed e the solver chooses for a lake of DESIGN_DEPTH (m/s)."""
    from lbm.lattice import Options, choose_lattice

    return choose_lattice(dx, DESIGN_DEPTH, 0.0, Options(depth=DESIGN_DEPTH)).e


def _solver(rt, nx, ny, dx, h0, tau, guard):
    import lbm

    e = design_speed(dx)
    return lbm.ShallowWater(nx, ny, dx, "slip", device=rt, guard=guard, depth=h0,
                            lattice_speed=e, viscosity=(tau - 0.5) * e * dx / 3.0,
                            expected_speed=1e-3)


def _stored(sim) -> float:
    """Exact volume of the stored state, as a depth sum (m)."""
    return float(sim.populations().astype(np.float64).sum())


def _disturb(sim, case: dict, h0: float):
    """Apply the case to a fresh solver; for a dam break, the (x, t -> exact h) reference."""
    lx, ly = sim.size
    dx = sim.dx
    if case["kind"] in ("drop", "dip"):
        height = (case["fraction"] * sim.max_drop_height if case["kind"] == "drop"
                  else case["fraction"] * h0)
        sim.add_drop(lx / 2, ly / 2, case["radius_cells"] * dx, height)
        return None
    if case["kind"] == "push":
        sim.push(0.3 * lx, ly / 2, 0.4 * lx, 0.0, case["froude"] * math.sqrt(G * h0),
                 radius=3 * dx)
        return None
    x = (np.arange(sim.nx) + 0.5) * dx
    sim.set_state(np.tile(np.where(x < lx / 2, h0, case["ratio"] * h0), (sim.ny, 1)))
    return x


def _stoker_steps(sim, h0: float, ratio: float, frac: float = 0.8) -> int:
    """Steps until the fastest wave (rarefaction head or shock) has gone ``frac`` of the way
    from the dam to a wall."""
    from lbm.analytic import stoker_middle_celerity

    hr = ratio * h0
    c0 = math.sqrt(G * h0)
    cm = stoker_middle_celerity(h0, hr, G)
    shock = 2 * cm * cm * (c0 - cm) / (cm * cm - G * hr)
    return max(1, round(frac * sim.size[0] / 2 / max(c0, shock) / sim.dt))


class _Said:
    """What the guard's report lines said, call by call of ``stats()``: the cell updates and
    restores they named, and the calls where the counts and the line disagree (the guard acted
    and the line does not say so with its count, or the line speaks of nothing done)."""

    def __init__(self):
        self.cells = self.restores = self.mismatches = 0
        self.last = ""

    def add(self, s: dict) -> None:
        rep, n, r = s["report"], s["cells_limited"], s["restored"]
        names_cells = f"limited {n} cell updates" in rep
        names_restores = f"restored the checkpoint {r}x" in rep
        if (n > 0) != names_cells or (r > 0) != names_restores or ("limited" in rep) != (n > 0):
            self.mismatches += 1
        self.cells += n if names_cells else 0
        self.restores += r if names_restores else 0
        if rep != "ok":
            self.last = rep


def run_case(rt, case: dict, h0: float, tau: float, guard: bool, quick: bool) -> dict:
    """One run: what happened to it (see the module doc), and its final depths ``_h``."""
    from lbm.analytic import stoker

    sz = _sizes(quick)
    dam = case["kind"] == "dam"
    n, dx = (sz["stoker_n"], 2.0 / sz["stoker_n"]) if dam else (sz["n"], 0.02)
    out = {"status": "", "blowup_step": "", "steps": 0, "max_froude": 0.0}
    try:
        sim = _solver(rt, n, 4 if dam else n, dx, h0, tau, guard)
        x = _disturb(sim, case, h0)
    except ValueError as exc:   # the solver's own checks (e.g. a drop above the cap)
        return {**out, "status": "refused", "reason": str(exc)}
    steps = _stoker_steps(sim, h0, case["ratio"]) if dam else sz["steps"]
    chunk = max(1, -(-steps // sz["chunks"]))
    v0 = _stored(sim)
    g0 = sim.guard_record()   # the volume a source's clipping booked before v0
    s = sim.stats()
    peak, said = s["max_froude"], _Said()
    said.add(s)
    try:
        while sim.steps < steps:
            sim.step(min(chunk, steps - sim.steps))
            s = sim.stats()
            said.add(s)
            peak = max(peak, s["max_froude"]) if math.isfinite(s["max_froude"]) else math.inf
            if not guard and (s["nan"] or not s["min_depth"] > 0):
                out.update(status="blew up", blowup_step=sim.steps,
                           reason="non-finite" if s["nan"] else "depth <= 0")
                break
        out["steps"] = sim.steps
        out["max_froude"] = peak
        g = sim.guard_record()
        h = sim.fields()["h"].astype(np.float64)
    except RuntimeError as exc:   # fields() of a guarded run found non-finite values
        return {**out, "status": "failed", "reason": str(exc)}
    if not out["status"]:
        if not np.all(np.isfinite(h)) or h.min() <= 0:
            out.update(status="blew up" if not guard else "failed", blowup_step=sim.steps,
                       reason="non-finite or dry at the end")
        else:
            out["status"] = "stable"
    v1 = _stored(sim) if out["status"] == "stable" else math.nan
    out["volume_change"] = (v1 - v0) / v0 if out["status"] == "stable" else ""
    if guard:
        clipped = float(g["clipped"]) - float(g0["clipped"])
        created = float(g["created"]) - float(g0["created"])
        out.update(cells_limited=int(g["clamped"]), restored=int(g["restored"]),
                   volume_clipped=clipped / v0, volume_created=created / v0,
                   budget_error=(abs(v1 - (v0 - clipped + created)) / v0
                                 if out["status"] == "stable" else ""),
                   reported_cells=said.cells, reported_restores=said.restores,
                   report_mismatches=said.mismatches, report=said.last)
    if dam and out["status"] == "stable":
        exact, _ = stoker(x, sim.time, sim.size[0] / 2, h0, case["ratio"] * h0, G)
        out["stoker_error"] = float(np.mean(np.abs(h[1] - exact))) / h0
    out["_h"] = h if out["status"] == "stable" else None
    return out


def category(plain: dict, guarded: dict) -> str:
    """The map marker of a case: see CATEGORIES."""
    if "refused" in (plain["status"], guarded["status"]):
        return "refused"
    acted = guarded.get("cells_limited", 0) > 0 or guarded.get("restored", 0) > 0
    if guarded["status"] != "stable":
        return "failed"
    if plain["status"] != "stable":
        return "saved" if acted else "failed"
    return "guard_only" if acted else "stable"


def stability(ctx) -> list[dict]:
    sz = _sizes(ctx.quick)
    e = design_speed(0.02)
    rows = []
    for tau in sz["taus"]:
        for h0 in sz["depths"]:
            for case in cases(ctx.quick):
                plain = run_case(ctx.rt, case, h0, tau, False, ctx.quick)
                guarded = run_case(ctx.rt, case, h0, tau, True, ctx.quick)
                change = ""
                if plain.get("_h") is not None and guarded.get("_h") is not None:
                    change = float(np.mean(np.abs(guarded["_h"] - plain["_h"]))) / h0
                row = {"tau": tau, "depth_m": h0, "gh_e2": round(G * h0 / e**2, 4),
                       "case": case["case"], "kind": case["kind"],
                       "froude_asked": case.get("froude", ""),
                       "push_speed_m_s": (round(case["froude"] * math.sqrt(G * h0), 4)
                                          if "froude" in case else ""),
                       "drop_fraction": case.get("fraction", ""),
                       "radius_cells": case.get("radius_cells", ""),
                       "dam_ratio": case.get("ratio", ""),
                       "category": category(plain, guarded)}
                for prefix, r in (("plain", plain), ("guard", guarded)):
                    for k, v in r.items():
                        if not k.startswith("_"):
                            row[f"{prefix}_{k}"] = v
                row["guard_change_l1"] = change
                rows.append(row)
                at = f" @{plain['blowup_step']}" if plain["blowup_step"] else ""
                ctx.log(f"tau {tau:g} h0 {h0:g} m {case['case']:28s}: plain {plain['status']}"
                        f"{at}, guard {guarded['status']} ({row['category']}; limited "
                        f"{guarded.get('cells_limited', '-')}, restored "
                        f"{guarded.get('restored', '-')})")
    return rows


def stability_chart(rows, path, ctx) -> None:
    from app import charts

    taus = list(dict.fromkeys(r["tau"] for r in rows))
    depths = list(dict.fromkeys(r["depth_m"] for r in rows))
    names = list(dict.fromkeys(r["case"] for r in rows))
    fig, axes = charts.panels(
        "Stability map: the plain LBM against the guarded one, same lattice and steps\n"
        "labels: @ step the plain run blew up; Stoker L1(h)/h0 of the guarded dam break",
        len(taus), size=(1.4 + 1.0 * len(depths) * len(taus), 1.6 + 0.34 * len(names)))
    style = {k: (c, m) for k, _, c, m in CATEGORIES}
    gh = {r["depth_m"]: r["gh_e2"] for r in rows}
    for ax, tau in zip(axes, taus, strict=True):
        for r in (r for r in rows if r["tau"] == tau):
            xi, yi = depths.index(r["depth_m"]), names.index(r["case"])
            colour, marker = style[r["category"]]
            ax.scatter([xi], [yi], c=[colour], marker=marker, s=70, edgecolors="none")
            note = []
            if r["plain_blowup_step"] != "":
                note.append(f"@{r['plain_blowup_step']}")
            if r.get("guard_stoker_error", "") not in ("", None):
                note.append(f"{r['guard_stoker_error']:.2g}")
            if note:
                ax.annotate(" ".join(note), (xi, yi), fontsize=6, xytext=(7, -3),
                            textcoords="offset points")
        ax.set_title(f"tau {tau:g}")
        ax.set_xticks(range(len(depths)), [f"{d:g} m\n{gh[d]:.2f}" for d in depths])
        ax.set_xlim(-0.6, len(depths) - 0.1)
        ax.set_ylim(len(names) - 0.5, -0.5)
        ax.set_yticks(range(len(names)), names if ax is axes[0] else [""] * len(names))
        ax.set_xlabel("depth h0 (g h0/e^2)")
        ax.grid(False)
    handles = [charts.marker_handle(c, m, label) for k, label, c, m in CATEGORIES
               if any(r["category"] == k for r in rows)]
    fig.legend(handles=handles, loc="lower center", ncol=min(3, len(handles)), fontsize=7,
               frameon=False)
    charts.save(fig, path, source=ctx.source, bottom=0.06 + 0.03 * math.ceil(len(handles) / 3))
