"""The imitation study (quick run, seed 1): its headline claims, checked against answer keys."""

import json

import numpy as np
import pytest
from study_runs import imitation_quick

from dmpopt import fit_discrete

# Quick-run values (seed 1, 12 demos) measured when these bounds were set: (median, worst)
# reproduction RMSE [mm] per fit and basis count; MARGIN is the factor allowed above them.
MEASURED_RMSE_MM = {
    "position, velocity form (default)": {
        "10": (0.244, 0.501),
        "30": (0.0169, 0.0223),
        "100": (0.00132, 0.00424),
    },
    "position, acceleration form": {
        "10": (0.328, 1.01),
        "30": (0.171, 0.542),
        "100": (0.148, 0.482),
    },
    "least squares on eq. (15)": {
        "10": (0.331, 0.572),
        "30": (0.0178, 0.0242),
        "100": (0.00167, 0.00665),
    },
    "LWR on eq. (15) (paper)": {"10": (1.82, 3.29), "30": (0.300, 0.516), "100": (0.0332, 0.0542)},
}
MARGIN = 1.5


@pytest.fixture(scope="module")
def saved():
    return json.loads((imitation_quick() / "metrics.json").read_text())


def _demos(saved):
    from dmpopt_studies import lasa

    shapes, per_shape = saved["parameters"]["shapes"], saved["parameters"]["demos_per_shape"]
    return [lasa.demonstrations(name)[k] for name in shapes for k in range(per_shape)]


def _rmse(a, b):
    return float(np.sqrt(np.mean(np.sum((a - b) ** 2, axis=1))))


def test_headline_is_what_the_default_call_gives(saved):
    """Answer key: the demos, against the plan of ``fit_discrete(demo)`` with every default
    (the default rollout starts with the demonstrated velocity), the RMSE written out here."""
    errors = []
    for demo in _demos(saved):
        dt = demo.duration / (demo.n_steps - 1)
        plan = fit_discrete(demo).rollout(demo.duration, dt)
        errors.append(_rmse(plan.positions, demo.positions))
    headline = saved["headline"]["rmse_mm"]
    assert saved["n_demos"] == 12 and saved["nonfinite"] == 0
    assert headline["median"] == pytest.approx(np.median(errors), rel=1e-9)
    assert headline["worst"] == pytest.approx(max(errors), rel=1e-9)
    assert headline == saved["rmse_mm"]["position, velocity form (default)"]["30"]
    assert "30 basis functions, position-space fit" in saved["headline"]["call"]


def test_error_by_method_and_basis_count(saved):
    """Every fit at every basis count, within MARGIN of the measured quick run; the error
    falls with the basis count (but for the acceleration form, which levels off), and the
    paper's LWR trails the position-space fit several-fold."""
    rmse = saved["rmse_mm"]
    for label, counts in MEASURED_RMSE_MM.items():
        for n, (median, worst) in counts.items():
            assert rmse[label][n]["median"] <= MARGIN * median, (label, n)
            assert rmse[label][n]["worst"] <= MARGIN * worst, (label, n)
        medians = [rmse[label][n]["median"] for n in ("10", "30", "100")]
        assert medians[0] > medians[1] > medians[2], label
    lwr, default = rmse["LWR on eq. (15) (paper)"], rmse["position, velocity form (default)"]
    for n in ("10", "30", "100"):
        assert lwr[n]["median"] > 5 * default[n]["median"]


def test_lwr_error_is_measured_against_the_demos(saved):
    """Answer key: the worst 10-basis LWR error recomputed from the demos."""
    worst = 0.0
    for demo in _demos(saved):
        dt = demo.duration / (demo.n_steps - 1)
        plan = fit_discrete(demo, 10, method="lwr").rollout(demo.duration, dt)
        worst = max(worst, _rmse(plan.positions, demo.positions))
    assert saved["rmse_mm"]["LWR on eq. (15) (paper)"]["10"]["worst"] == pytest.approx(worst)


def test_automatic_choice_meets_the_tolerance_with_fewer_bases(saved):
    """Each demo's chosen layout, refitted to all samples, is within the tolerance (the
    choice was made on held-out samples); LWR needs more basis functions than the
    position-space fit, and narrower ones than the default layout."""
    adaptive = saved["adaptive"]
    tolerance = adaptive["tolerance_mm"]
    for label in ("position, velocity form (default)", "LWR on eq. (15) (paper)"):
        assert adaptive[label]["met_tolerance"] == 12
        assert adaptive[label]["rmse_mm"]["worst"] <= 1.05 * tolerance
    position, lwr = (
        adaptive["position, velocity form (default)"],
        adaptive["LWR on eq. (15) (paper)"],
    )
    assert lwr["n_basis"]["median"] > position["n_basis"]["median"]
    assert all(float(scale) > 1.0 for scale in lwr["width_scale_counts"])
    assert position["fixed_n_basis_for_every_demo"] == 30
    assert position["n_basis_mean"] < 30


def test_goal_shift_references_are_written_out():
    """Answer keys: ours, the demo multiplied, as complex numbers about its start, by
    (g' - y0) / (g - y0); the paper's, each axis multiplied by its own (g'_d - y0_d) /
    (g_d - y0_d); the new goal moved by 20 % of |g - y0| on each axis."""
    from dmpopt_studies import imitation, lasa

    demo = lasa.demonstrations("Sshape")[2]
    start, goal = demo.positions[0], demo.positions[-1]
    new_goal = imitation.shifted_goal(demo)
    np.testing.assert_allclose(new_goal, goal + 0.2 * np.linalg.norm(goal - start))
    factor = complex(*(new_goal - start)) / complex(*(goal - start))
    offsets = demo.positions - start
    mapped = (offsets[:, 0] + 1j * offsets[:, 1]) * factor
    np.testing.assert_allclose(
        imitation.rotated_and_scaled(demo, new_goal),
        start + np.c_[mapped.real, mapped.imag],
        atol=1e-9 * np.ptp(demo.positions),
    )
    per_axis = [
        start[d] + offsets[:, d] * (new_goal[d] - start[d]) / (goal[d] - start[d]) for d in (0, 1)
    ]
    np.testing.assert_allclose(
        imitation.scaled_per_axis(demo, new_goal), np.c_[per_axis[0], per_axis[1]]
    )


def test_goal_shift_errors_each_against_its_own_reference(saved):
    """Ours: exact invariance (the error is the reproduction error); the paper's: close to
    the demo scaled per axis, refused on the demos where an axis would amplify a goal change
    more than 10-fold (max |y_d - y0_d| / |g_d - y0_d|, written out here)."""
    shift = saved["goal_shift_error_mm"]
    assert shift["ours_invariance"]["worst"] < 1e-9
    assert shift["ours_scaling_counts"] == {"rotation": 12}
    headline = saved["headline"]["rmse_mm"]
    assert shift["ours_vs_rotated_demo"]["worst"] <= 1.5 * headline["worst"]
    refused = 0
    for demo in _demos(saved):
        offsets = demo.positions - demo.positions[0]
        refused += int(np.max(np.abs(offsets).max(axis=0) / np.abs(offsets[-1])) > 10.0)
    assert shift["paper_fits_refused"] == refused
    assert shift["paper_vs_own_invariance"]["worst"] <= 0.05
    assert shift["paper_shape_change_vs_rotated"]["median"] > 1.0  # the shape bends [mm]


def test_summary_and_captions_come_from_the_metrics(saved):
    rows = saved["summary"]
    assert len(rows) == 5
    assert all(set(row) == {"claim", "paper", "dmpopt", "anchor", "verdict"} for row in rows)
    assert f"{saved['headline']['rmse_mm']['median']:.2g} mm median" in rows[0]["dmpopt"]
    lwr = saved["rmse_mm"]["LWR on eq. (15) (paper)"]["30"]
    assert f"{lwr['median']:.2g} mm median" in rows[0]["anchor"]
    assert (
        f"{saved['goal_shift_error_mm']['paper_fits_refused']} of 12 fits refused"
        in rows[4]["dmpopt"]
    )
    figures = sorted(p.stem for p in imitation_quick().glob("*.png"))
    assert figures == sorted(saved["captions"]) == ["new_goals", "reproductions", "rmse_vs_basis"]
    assert all((imitation_quick() / f"{stem}.png").stat().st_size > 10_000 for stem in figures)
    assert saved["parallel"]["runs"] == 12


@pytest.mark.parametrize(
    "options, match",
    [
        ({"quick": "yes"}, "quick must be True or False"),
        ({"seed": -1}, "seed must be"),
        ({"runner": 2}, "runner must be a dmpopt.parallel.Runner or None, got int"),
    ],
)
def test_bad_run_options_are_refused(tmp_path, options, match):
    from dmpopt_studies import imitation

    from dmpopt import InvalidInputError

    with pytest.raises(InvalidInputError, match=match):
        imitation.run(tmp_path, **options)
    assert not any(tmp_path.iterdir())
