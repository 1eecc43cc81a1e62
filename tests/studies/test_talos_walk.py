"""The Talos walk in MuJoCo (quick mode: one step in place, three forward, one closing).

Answer key: the footstep arithmetic written here (three forward steps of STEP_LENGTH put both
feet 3 x STEP_LENGTH ahead, so the CoM ends that far ahead, centred between them), not the
library's plan; for the pushes, momentum: an impulse J on a robot of mass m changes its CoM
velocity by J / m, and so its DCM by J / (m omega).
"""

import os

import pytest

os.environ.setdefault("MUJOCO_GL", "egl")
pytest.importorskip("mujoco")

from dmpopt_studies import talos_walk  # noqa: E402

from dmpopt.exceptions import InvalidInputError  # noqa: E402


@pytest.fixture(scope="module")
def quick_walk(tmp_path_factory):
    out = tmp_path_factory.mktemp("walk")
    return out, talos_walk.run_walk(out, quick=True)


def test_quick_walk_takes_every_step_without_falling(quick_walk):
    out, metrics = quick_walk
    n_in_place, n_forward = talos_walk.STEPS["quick"]
    assert not metrics["fell"] and metrics["diverged"] is None
    assert metrics["steps_planned"] == n_in_place + n_forward + 1
    assert (metrics["steps_in_place"], metrics["steps_forward"]) == (n_in_place, n_forward + 1)
    assert metrics["steps_taken"] == metrics["steps_planned"]
    assert metrics["distance_m"] == pytest.approx(n_forward * talos_walk.STEP_LENGTH, abs=0.02)
    assert metrics["foothold_error_max_mm"] < 10.0
    # A standing foot stays put (1.9 mm measured), carries most of the weight in single
    # support (83 %) with its CoP inside the sole (3.3 mm), and the CoM and DCM follow the
    # plan in use (22.8 and 34.1 mm at most, 7.5 and 8.9 mm RMS), on the realistic plant.
    # Without the joint loop's restart at each touchdown (Walker._settle) the landed leg
    # pushed the other foot off the floor: 22 mm slip, margin 0, CoM error 147 mm.
    assert metrics["foot_slip_max_mm"] < 5.0
    assert metrics["stance_normal_force_min_fraction"] > 0.8
    assert metrics["stance_cop_margin_min_mm"] > 1.0
    assert metrics["com_error_max_mm"] < 35.0
    assert metrics["dcm_error_max_mm"] < 50.0
    assert metrics["swing_foot_normal_force_max_n"] < 1.0
    assert metrics["qp_answers"]["hold"] == 0  # no tick without a QP answer
    assert metrics["touchdown_from_contact"] is True  # every contact switched on a report
    assert 0.0 < metrics["tick_us_median"] <= metrics["tick_us_p99"]
    assert (out / metrics["figure"]).stat().st_size > 10_000


def test_run_walk_refuses_a_quick_that_is_not_a_bool(tmp_path):
    with pytest.raises(InvalidInputError, match="quick"):
        talos_walk.run_walk(tmp_path, quick="yes")


def test_quick_walk_recovers_from_a_lateral_push_by_stepping(quick_walk):
    """The quick mode's two lateral pushes (20 and 40 N s, towards the swinging foot, 30 % into
    its single support): 40 N s on 90 kg moves the DCM by 40 / (90 x 3.36) = 0.13 m, beyond
    the stance sole's half-width (0.069 m), so only a step can catch it; the walk survives."""
    _, metrics = quick_walk
    push = metrics["push_recovery"]
    assert push["quick"] and push["trials"]["lateral"] == [(20.0, True), (40.0, True)]
    assert push["lateral_ns"] == 40.0
