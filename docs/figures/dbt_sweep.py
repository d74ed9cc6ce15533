"""The Q0 x R0 campaign of docs/dbt-comparison.md: its figure and tables from the campaigns'
stored results (run the three commands of the docs first; nothing is run here).

    python docs/figures/dbt_sweep.py OUT_DIR      # the campaigns in OUT_DIR/dbt-approaching,
                                                  # OUT_DIR/dbt-receding, ... (see the docs)

Writes docs/figures/dbt-sweep-amcekf-ekf.png (AMCEKF/EKF position RMSE over the plane for
the three geometries, the paper's ratio dashed) and each campaign's report again (with this
code's report), and prints the tables of the docs in Markdown.
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

import numpy as np

from trackkit.experiments.sweep import parse_param, plan_campaign
from trackkit.report.sweep_report import (
    _frame,
    _label_axes,
    _own_cell,
    _plain_ticks,
    ratio_grids,
    sweep_table,
    write_sweep_report,
)
from trackkit.scenario import load

GEOMETRIES = {"dbt-approaching": "1 approaching", "dbt-receding": "2 receding",
              "dbt-observer-manoeuvre": "3 manoeuvring observer"}
Q = "filters.*.motion.q=x0.1,x1,x10,x100"
R = "filters.*.r0_diag_si=x0.1,x0.5,x1,x2,x10,x100"
RUNS, BLOCK = 100, 50
FIGURE = Path(__file__).with_name("dbt-sweep-amcekf-ekf.png")


def campaign_of(name: str, out: Path):
    c = plan_campaign(load(name), [parse_param(Q), parse_param(R)], runs=RUNS, block=BLOCK)
    docs = [json.loads((out / name / "points" / p.id / "result.json").read_text())
            for p in c.points]
    return c, docs


def grid(c, docs, value) -> tuple[list[str], list[str], np.ndarray]:
    """value(doc) over the plane: rows R factors, columns q factors."""
    qs = [v for v in c.params[0].values]
    rs = [v for v in c.params[1].values]
    m = np.full((len(rs), len(qs)), np.nan)
    for d in docs:
        m[rs.index(d["values"][c.params[1].path]), qs.index(d["values"][c.params[0].path])] = (
            value(d))
    return qs, rs, m


def markdown(title: str, qs, rs, m, fmt="{:.2f}") -> str:
    head = "| R0 / R \\ q0 / q | " + " | ".join(qs) + " |"
    rows = [head, "|---" * (len(qs) + 1) + "|"]
    for i, r in enumerate(rs):
        rows.append(f"| {r} | " + " | ".join(fmt.format(v) for v in m[i]) + " |")
    return f"**{title}**\n\n" + "\n".join(rows) + "\n"


def main(out: Path) -> None:
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.colors import LogNorm
    from matplotlib.figure import Figure

    fig = Figure(figsize=(13.5, 4.2), layout="constrained")
    axes = fig.subplots(1, 3)
    norm = LogNorm(1 / 8, 8)
    image = None
    for ax, name in zip(axes, GEOMETRIES, strict=True):
        c, docs = campaign_of(name, out)
        table = sweep_table(c, docs)
        write_sweep_report(c, docs, out / name)
        (pub,) = c.base.report.published
        m = ratio_grids(c, table, "position", "EKF")["AMCEKF"]
        lx, ly = list(c.params[0].values), list(c.params[1].values)
        image = ax.imshow(m, origin="lower", aspect="auto", cmap="RdBu_r", norm=norm)
        for i in range(m.shape[0]):
            for j in range(m.shape[1]):
                ax.text(j, i, f"{m[i, j]:.2f}", ha="center", va="center", fontsize=7,
                        color="w" if abs(np.log(m[i, j])) > np.log(3) else "k")
        paper = pub.ratio("AMCEKF")
        if np.nanmin(m) < paper < np.nanmax(m):
            cs = ax.contour(np.arange(len(lx)), np.arange(len(ly)), m, levels=[paper],
                            colors="k", linestyles="--", linewidths=1.3)
            ax.clabel(cs, fmt={paper: f"paper {paper:.2f}"}, fontsize=7)
        _frame(ax, _own_cell(c, lx, ly))
        _label_axes(ax, "every filter's q0 / its tuned q", "every filter's R0 / true R",
                    lx, ly)
        own = m[ly.index("x1"), lx.index("x1")]
        ax.set_title(f"{GEOMETRIES[name]}: paper {paper:.2f}, ours {own:.2f} (framed)",
                     fontsize=9)
        print(f"## {name}\n")
        print(markdown("AMCEKF / EKF position RMSE from 600 s", lx, ly, m))
        for f in ("EKF", "AMCEKF", "AEKF"):
            print(markdown(f"{f} position RMSE / PCRLB from 600 s", *grid(
                c, docs, lambda d, f=f: d["filters"][f]["rmse_pcrlb"]["position"]),
                fmt="{:.2f}"))
        div = grid(c, docs, lambda d: max(f["diverged"] for f in d["filters"].values())
                   / d["runs"])
        print(markdown("largest share of runs diverged (any filter)", *div, fmt="{:.2f}"))
        for w in docs[0].get("windows", {}):  # the scenario's error windows, if any
            def ratio(d, w=w):
                f = d["windows"][w]["filters"]
                return f["AMCEKF"]["rmse"]["position"] / f["EKF"]["rmse"]["position"]

            print(markdown(f"AMCEKF / EKF position RMSE, window {w}", *grid(c, docs, ratio)))
    _plain_ticks(fig.colorbar(image, ax=list(axes), label="AMCEKF / EKF position RMSE",
                              shrink=0.9))
    fig.suptitle("AMCEKF / EKF position RMSE from 600 s over every filter's Q0 x R0 "
                 "(100 runs per point; blue: the AMCEKF better; dashed: the paper's ratio)",
                 fontsize=10)
    FigureCanvasAgg(fig)
    fig.savefig(FIGURE, dpi=80, metadata={"Software": None})
    print(f"wrote {FIGURE}")


if __name__ == "__main__":
    main(Path(sys.argv[1]))
