"""The primitives study: its quick run, and the measures it reports."""

import numpy as np
import pytest
from dmpopt_studies import primitives


def test_path_length_and_jerk_measures():
    """Answer keys: a 3-4-5 polyline is 5 long; the third difference of t^3 over dt^3 is 6."""
    assert primitives.path_length(np.array([[0.0, 0.0], [3.0, 4.0]])) == pytest.approx(5.0)
    t = np.arange(50) * 0.01
    cubic = np.column_stack([t**3, 0 * t])
    assert primitives.rms_jerk(cubic, 0.01) == pytest.approx(6.0, rel=1e-9)


@pytest.fixture(scope="module")
def quick(tmp_path_factory):
    folder = tmp_path_factory.mktemp("studies") / "primitives"
    return folder, primitives.run(folder, quick=True)


def test_quick_run_writes_metrics_and_figures(quick):
    folder, metrics = quick
    assert {p.name for p in folder.glob("*.png")} == {
        "primitives_promp.png",
        "primitives_obstacles.png",
        "primitives_bimanual.png",
    }
    assert (folder / "metrics.json").is_file()
    promp = metrics["promp"]
    for key in ("lasa_reproduction_mm", "via_point_error_mm", "heldout_loglik", "fit_ms"):
        assert np.isfinite(promp[key])
    for method in primitives.METHODS:
        row = metrics["obstacles"][method]
        assert set(row) >= {"clearance_min_mm", "path_length_ratio", "jerk_ratio", "collisions"}


def test_quick_run_conditioning_is_exact_and_keep_out_clears(quick):
    """Exact conditioning puts the mean on the points up to the rounding of a solve with
    positions of ~100 mm (1e-12 relative, bound 1e-6 mm); the keep-out plans hold the
    disc's radius at every 1 ms sample of the plan (IPOPT's 1e-8 on rows scaled by the 1 m
    extent, bound 1e-5 mm below the surface), while the uncoupled line enters it."""
    _, metrics = quick
    assert metrics["promp"]["via_point_error_mm"] < 1e-6
    for method in ("keep_out", "keep_out_position"):
        row = metrics["obstacles"][method]
        assert row["collisions"] == 0 and row["clearance_min_mm"] > -1e-5
    assert metrics["obstacles"]["keep_out_box"]["collisions"] == 0


def test_quick_run_coupling_holds_the_planned_relative_pose(quick):
    """Quick mode runs the bimanual plans only: coupled, the perturbation (one hand slower,
    told of the new goal later) moves the plans' relative pose by a fraction of what it does
    uncoupled (the static factor alpha beta / (alpha beta + k tau^2) < 0.2 for the carry's
    tau, dmpopt.bimanual)."""
    _, metrics = quick
    coupled, uncoupled = metrics["bimanual"]["coupled"], metrics["bimanual"]["uncoupled"]
    assert coupled["plan_relative_error_mm"] < 0.2 * uncoupled["plan_relative_error_mm"]
