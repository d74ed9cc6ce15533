"""Figures: valid PNG files, axis labels with units, angle groups in degrees, PCRLB dashed."""

from __future__ import annotations

import math
import struct
from pathlib import Path

import numpy as np
import pytest

from trackkit.report import plots

from . import FILTERS, fake_result

PNG_SIGNATURE = b"\x89PNG\r\n\x1a\n"


def png_size(path: Path) -> tuple[int, int]:
    """Width and height from the IHDR chunk of a PNG file (asserts the signature)."""
    raw = Path(path).read_bytes()
    assert raw[:8] == PNG_SIGNATURE, f"{path} is not a PNG file"
    assert raw[12:16] == b"IHDR"
    return struct.unpack(">II", raw[16:24])


@pytest.mark.parametrize("name", ["geometry", "rmse", "nees"])
def test_each_plot_writes_a_png(tmp_path, name):
    path = getattr(plots, f"plot_{name}")(fake_result(), tmp_path / f"{name}.png")
    assert path == tmp_path / f"{name}.png"
    assert path.stat().st_size > 5_000
    width, height = png_size(path)
    assert width >= 600 and height >= 400


def test_make_plots_without_example_skips_geometry(tmp_path):
    written = plots.make_plots(fake_result(example=False), tmp_path)
    assert set(written) == {"rmse", "nees"}
    assert sorted(p.name for p in tmp_path.iterdir()) == ["nees.png", "rmse.png"]
    assert plots.geometry_figure(fake_result(example=False)) is None


def test_rmse_figure_units_degrees_and_bound():
    r = fake_result()
    fig = plots.rmse_figure(r)
    axes = fig.axes
    assert [ax.get_ylabel() for ax in axes] == [
        "position RMSE [m]", "velocity RMSE [m/s]", "course RMSE [deg]"]
    assert axes[-1].get_xlabel() == "time [s]"
    course = {line.get_label(): line for line in axes[2].get_lines()}
    assert set(FILTERS) | {"PCRLB"} <= set(course)
    np.testing.assert_allclose(course["EKF"].get_ydata(),
                               np.degrees(r.filters["EKF"].rmse["course"]))
    np.testing.assert_allclose(course["PCRLB"].get_ydata(), np.degrees(r.pcrlb["course"]))
    assert course["PCRLB"].get_linestyle() == "--"
    position = {line.get_label(): line for line in axes[0].get_lines()}
    np.testing.assert_allclose(position["EKF"].get_ydata(), r.filters["EKF"].rmse["position"])
    legend = [t.get_text() for t in axes[0].get_legend().get_texts()]
    assert legend[:3] == [*FILTERS, "PCRLB"]


def test_nees_figure_bounds_and_nis_panel():
    r = fake_result()
    fig = plots.nees_figure(r)
    assert [ax.get_ylabel() for ax in fig.axes] == ["average NEES [-]", "average NIS [-]"]
    ax = fig.axes[0]
    assert ax.get_yscale() == "log"
    dashed = [line for line in ax.get_lines() if line.get_linestyle() == "--"]
    lo, hi = r.filters["EKF"].nees_bounds
    assert len(dashed) == 2  # shared bounds drawn once
    np.testing.assert_allclose(dashed[0].get_ydata(), lo)
    np.testing.assert_allclose(dashed[1].get_ydata(), hi)
    for f in r.filters.values():  # no NIS at all: one panel
        f.nis = np.full(r.steps, np.nan)
    assert len(plots.nees_figure(r).axes) == 1


def test_geometry_handles_3d_diverged_and_bad_covariance(tmp_path):
    r = fake_result()
    ex = r.example
    ex.observer = np.column_stack([ex.observer, np.full(r.steps, -50.0)])  # 3-D observer
    means, covs = ex.estimates["UKF"]
    means[30:] = 1e12  # a track running off: the scene must not shrink to a dot
    means[40:] = np.nan
    covs[5, 0, 0] = -1.0  # not PSD: ellipse skipped, no error
    fig = plots.geometry_figure(r)
    ax = fig.axes[0]
    assert ax.get_xlabel() == "east [km]" and ax.get_ylabel() == "north [km]"
    assert ax.get_xlim()[1] < 100 and ax.get_ylim()[1] < 100  # km
    labels = [t.get_text() for t in ax.get_legend().get_texts()]
    assert {"truth", "observer", *FILTERS} <= set(labels)
    assert any("2-sigma" in label for label in labels)
    # an ellipse every 5 steps: 10 for EKF; UKF loses step 5 (not PSD) and 40, 45 (nan)
    assert len(ax.patches) == 10 + 7
    png_size(plots.plot_geometry(r, tmp_path / "g.png"))


def test_ellipse_is_two_sigma():
    cov = np.array([[4.0, 0.0], [0.0, 1.0]])
    e = plots._ellipse(np.zeros(2), cov, 2.0)
    assert math.isclose(e.width, 8.0) and math.isclose(e.height, 4.0)
    assert math.isclose(abs(e.angle) % 180, 0.0, abs_tol=1e-9)
