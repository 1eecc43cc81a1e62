"""The constrained study: its paired statistics, its minimum-jerk baseline and its headline claims.

Answer keys: ratios and quantiles written out by hand or recomputed here from the per-shape
records; the bounds' construction (a fraction of the unconstrained plan's peaks) fixes the
unconstrained DMP's limit use; the average speed a rest-to-rest movement needs.
"""

from __future__ import annotations

import numpy as np
import pytest
from dmpopt_studies import constrained


def _case(shape, **methods):
    """A per-shape record with ``end_speed_mm_s`` 0 and the given (duration, shape, jerk)."""
    keys = ("duration", "shape_error", "integrated_squared_jerk")
    metrics = {
        m: dict(zip(keys, values), end_speed_mm_s=0.0, checkpoints_met=0)
        for m, values in methods.items()
    }
    return {"shape": shape, "metrics": metrics}


def test_paired_comparison_uses_the_same_shapes_for_every_method():
    cases = [
        _case("a", base=(1, 1, 1), x=(2, 4, 0.5), y=(1, 2, 8)),
        _case("b", base=(2, 2, 2), x=(2, 6, 4.0), y=(4, 1, 1)),
        _case("c", base=(1, 1, 1), x=(3, 9, 9.0)),  # y infeasible: c leaves every statistic
    ]
    result = constrained.paired_comparison(cases, "base", ("x", "y"))
    assert result["shapes"] == ["a", "b"]
    assert result["feasible"] == {"base": 3, "x": 3, "y": 2}
    assert result["infeasible_shapes"]["y"] == ["c"]
    jerk = result["ratios"]["x"]["integrated_squared_jerk"]  # ratios 0.5 and 2 on a, b
    assert jerk["median"] == pytest.approx(1.25)
    assert jerk["q25"] == pytest.approx(0.875)  # linear interpolation: 0.5 + 0.25 * 1.5
    assert jerk["worst"] == pytest.approx(2.0)
    assert jerk["n"] == 2
    shape = result["ratios"]["y"]["shape_error"]  # ratios 2 and 0.5
    assert shape["median"] == pytest.approx(1.25)
    assert result["ratios"]["y"]["duration"]["worst"] == pytest.approx(2.0)


def test_quantiles_worst_follows_the_direction_of_better():
    assert constrained.quantiles([3, 1, 2])["worst"] == 3
    assert constrained.quantiles([3, 1, 2], higher_is_better=True)["worst"] == 1
    assert constrained.quantiles([])["n"] == 0


def test_checkpoints_are_tried_coarse_to_fine():
    assert constrained._dyadic_order(7) == [3, 1, 5, 0, 2, 4, 6]
    order = constrained._dyadic_order(constrained.N_CHECKPOINTS)
    assert sorted(order) == list(range(constrained.N_CHECKPOINTS))
    assert constrained._checkpoints(33) == list(range(1, 32))  # i / 32 of 32 steps


def _line(n_samples=201, duration=2.0, distance=100.0):
    """The closed-form minimum-jerk movement along x, its times and its peak speed."""
    times = np.linspace(0.0, duration, n_samples)
    s = times / duration
    x = distance * (10 * s**3 - 15 * s**4 + 6 * s**5)
    target = np.column_stack([x, np.zeros_like(x)])
    return times, target, 15 / 8 * distance / duration


def test_minimum_jerk_baseline_takes_every_checkpoint_on_its_own_optimum():
    """Checkpoints on the unbounded optimum itself are all feasible: all 31 are taken."""
    from dmpopt.fitting.constrained import Bounds

    times, target, peak = _line()
    bounds = Bounds(velocity=[1.01 * peak, 1.01 * peak], acceleration=[1e4, 1e4])
    indices = constrained._checkpoints(times.size)
    trajectory, _, n_vias = constrained._strongest_minimum_jerk(
        target[0], target[-1], times[-1], bounds, times, target, indices, 0.5
    )
    assert n_vias == constrained.N_CHECKPOINTS
    assert constrained._met(trajectory.positions, target, indices, 0.5) == n_vias


def test_minimum_jerk_baseline_skips_an_unreachable_checkpoint():
    """A checkpoint 20 mm off the line, reachable only at the speed the bound forbids, is
    left out and the others kept."""
    from dmpopt.fitting.constrained import Bounds

    times, target, peak = _line()
    target = target.copy()
    indices = constrained._checkpoints(times.size)
    target[indices[0], 1] = 20.0  # 1/32 of the way: 20 mm sideways in 0.06 s
    bounds = Bounds(velocity=[1.2 * peak, 1.2 * peak], acceleration=[1e4, 1e4])
    _, _, n_vias = constrained._strongest_minimum_jerk(
        target[0], target[-1], times[-1], bounds, times, target, indices, 0.5
    )
    assert n_vias == constrained.N_CHECKPOINTS - 1


def test_minimum_jerk_baseline_is_infeasible_below_the_average_speed():
    """Rest to rest over 100 mm in 2 s needs 50 mm/s on average: a 45 mm/s bound fails."""
    from dmpopt.exceptions import InfeasibleProblem
    from dmpopt.fitting.constrained import Bounds

    times, target, _ = _line()
    bounds = Bounds(velocity=[45.0, 45.0], acceleration=[1e4, 1e4])
    with pytest.raises(InfeasibleProblem, match="bounds"):
        constrained._strongest_minimum_jerk(
            target[0], target[-1], times[-1], bounds, times, target, [100], 0.5
        )


@pytest.fixture(scope="module")
def quick_run(tmp_path_factory):
    folder = tmp_path_factory.mktemp("constrained")
    return folder, constrained.run(folder, quick=True)


def test_bounds_hold_for_the_constrained_dmp_and_not_for_the_unconstrained(quick_run):
    _, metrics = quick_run
    n = metrics["n_shapes"]
    violating = metrics["violating_shapes"]
    assert violating["dmp_constrained"] == violating["dmp_constrained_rest"] == 0
    assert violating["dmp_unconstrained"] == n
    for case in metrics["cases"]:
        # the bounds are 0.8 x its peak speed and 0.6 x its peak acceleration per DOF
        use = case["metrics"]["dmp_unconstrained"]["limit_use"]
        assert use == pytest.approx(1 / constrained.ACCELERATION_FRACTION)
        for method in ("dmp_constrained_rest", "toppra", "tau_scaled", "minimum_jerk"):
            if method in case["metrics"]:
                assert case["metrics"][method]["limit_use"] <= 1 + 1e-6, method


def test_paired_ratios_are_the_quantiles_of_the_per_shape_ratios(quick_run):
    _, metrics = quick_run
    cases = {c["shape"]: c["metrics"] for c in metrics["cases"]}
    for variant, (baseline, methods) in constrained.COMPARISONS.items():
        comparison = metrics["comparisons"][variant]
        common = [s for s, m in cases.items() if all(k in m for k in (baseline, *methods))]
        assert comparison["shapes"] == common
        for method in methods:
            for key in constrained.RATIO_KEYS:
                ratios = [cases[s][method][key] / cases[s][baseline][key] for s in common]
                q = comparison["ratios"][method][key]
                assert q["median"] == pytest.approx(np.median(ratios))
                assert q["worst"] == pytest.approx(max(ratios))
                assert q["n"] == len(common)


def test_end_conditions_and_timing(quick_run):
    _, metrics = quick_run
    rest = metrics["comparisons"]["rest_to_rest"]
    for method, q in rest["end_speed_mm_s"].items():
        assert q["worst"] < 1e-6, method  # every rest-to-rest plan ends still
    motion = metrics["comparisons"]["ending_in_motion"]["end_speed_mm_s"]
    assert motion["dmp_unconstrained"]["worst"] > 0.5  # the defaults end moving [mm/s]
    ratios = rest["ratios"]
    assert ratios["dmp_constrained_rest"]["duration"]["worst"] == pytest.approx(1.0)
    assert ratios["minimum_jerk"]["duration"]["worst"] == pytest.approx(1.0)
    assert ratios["tau_scaled"]["duration"]["q25"] > 1.0  # slowed down to meet the bounds
    # retiming keeps the path: shape error as the unconstrained plan's
    assert ratios["toppra"]["shape_error"]["median"] == pytest.approx(1.0, abs=0.3)
    assert ratios["tau_scaled"]["shape_error"]["worst"] == pytest.approx(1.0, abs=1e-6)


def test_headline_jerk_below_the_unconstrained_dmp_and_toppra(quick_run):
    _, metrics = quick_run
    rest = metrics["comparisons"]["rest_to_rest"]["ratios"]
    assert rest["dmp_constrained_rest"]["integrated_squared_jerk"]["worst"] < 1.0
    assert rest["toppra"]["integrated_squared_jerk"]["median"] > 1.0
    motion = metrics["comparisons"]["ending_in_motion"]["ratios"]
    assert motion["dmp_constrained"]["integrated_squared_jerk"]["median"] < 1.0
    versus = metrics["constrained_dmp_versus"]["toppra"]
    assert versus["integrated_squared_jerk"]["median"] < 0.5
    assert versus["shape_error"]["median"] > 2.0  # toppra keeps the shape better


def test_minimum_jerk_takes_many_via_points_and_meets_them(quick_run):
    _, metrics = quick_run
    assert metrics["minimum_jerk_via_points"]["n_via_points"]["worst"] >= 3
    for case in metrics["cases"]:
        mj = case["metrics"]["minimum_jerk"]
        assert mj["checkpoints_met"] >= mj["n_via_points"]


def test_summary_and_captions_come_from_the_metrics(quick_run):
    folder, metrics = quick_run
    keys = {"claim", "paper", "dmpopt", "anchor", "verdict"}
    assert all(
        set(row) == keys and all(isinstance(row[k], str) for k in keys)
        for row in metrics["summary"]
    )
    jerk = metrics["comparisons"]["rest_to_rest"]["ratios"]["dmp_constrained_rest"]
    median = jerk["integrated_squared_jerk"]["median"]
    assert any(f"{median:.2g}x" in row["dmpopt"] for row in metrics["summary"])
    figures = {p.stem for p in folder.glob("*.png")}
    assert set(metrics["captions"]) == figures
    assert {"constrained_paths", "constrained_violations", "constrained_ratios"} <= figures


@pytest.mark.slow
def test_results_do_not_depend_on_the_runner(quick_run, tmp_path):
    from dmpopt.parallel import Runner

    _, serial = quick_run
    parallel = constrained.run(tmp_path, quick=True, runner=Runner(workers=2))
    assert parallel["parallel"]["workers"] == 2
    assert parallel["summary"] == serial["summary"]
    assert parallel["feasible"] == serial["feasible"]


@pytest.mark.parametrize(
    "options, match",
    [({"seed": -1}, "seed"), ({"seed": 1.5}, "seed"), ({"runner": 2}, "runner")],
)
def test_bad_arguments_are_refused_before_any_work(tmp_path, options, match):
    from dmpopt.exceptions import InvalidInputError

    with pytest.raises(InvalidInputError, match=match):
        constrained.run(tmp_path, quick=True, **options)
