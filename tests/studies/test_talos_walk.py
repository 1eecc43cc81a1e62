"""The Talos walk in MuJoCo (quick mode: one step in place, three forward, one closing).

Answer key: the footstep arithmetic written here (three forward steps of STEP_LENGTH put both
feet 3 x STEP_LENGTH ahead, so the CoM ends that far ahead, centred between them), not the
library's plan; for the pushes, momentum: an impulse J on a robot of mass m changes its CoM
velocity by J / m, and so its DCM by J / (m omega).
"""

import os

import numpy as np
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


def test_com_height_follows_the_ground_under_the_zmp():
    """The right foot landed 4 cm higher than it started (a box): in the double support in
    which the weight moves onto it, the CoM height offset goes linearly from the left foot's
    ground (0) to the right's (0.04 m), at 0.04 m / the double support's length; it is 0.04 m
    in the single support on the right foot and 0 in the one before, on the left (written
    here from the plan's knot times)."""
    robot, q0 = talos_walk._robot_and_start()
    plan, swing_dmps = talos_walk.build_plan(robot, q0, quick=True)
    walker = talos_walk.Walker(robot, q0, plan, swing_dmps)
    right = robot.foot_frames[1]
    walker._level[right] = walker._ground[right] + 0.04
    i = next(k for k, step in enumerate(plan.footsteps) if k > 0 and step.side == "left")
    start, end = plan.touchdown[i - 1], plan.lift_off[i]  # the double support before step i
    for fraction in (0.0, 0.25, 0.5, 0.99):
        offset, rate = walker._ground_offset(start + fraction * (end - start))
        assert offset == pytest.approx(0.04 * fraction, abs=1e-12)
        assert rate == pytest.approx(0.04 / (end - start), abs=1e-12)
    assert walker._ground_offset(end) == (pytest.approx(0.04, abs=1e-12), 0.0)
    middle = 0.5 * (plan.lift_off[i] + plan.touchdown[i])  # single support, on the right foot
    assert walker._ground_offset(middle) == (pytest.approx(0.04, abs=1e-12), 0.0)
    before = 0.5 * (plan.lift_off[i - 1] + plan.touchdown[i - 1])  # on the left foot
    assert walker._ground_offset(before) == (0.0, 0.0)


def test_a_crossing_step_is_kept_only_where_the_soles_stay_apart():
    """The left foot steps past the right (standing) foot's line by 4 cm: 0.3 m ahead its
    sole (0.21 m long) is 0.09 m clear of the other, more than the 2 cm clearance, and the
    foothold is kept; 0.2 m ahead the soles would overlap, and the foothold goes back to the
    nearest point of the box without crossing, 0.15 m to the left of the standing foot
    (written here from the sole's size)."""
    robot, q0 = talos_walk._robot_and_start()
    plan, swing_dmps = talos_walk.build_plan(robot, q0, quick=True)
    walker = talos_walk.Walker(robot, q0, plan, swing_dmps)
    step = next(s for s in plan.footsteps if s.side == "left")
    right = walker.data.oMf[robot.model.getFrameId(robot.foot_frames[1])].translation[:2]
    clear = right + [0.3, -0.04]
    np.testing.assert_array_equal(walker._uncross(step, clear), clear)
    close = right + [0.2, -0.04]
    expected = [close[0], step.stance[1] + talos_walk.REACH_LATERAL[0]]
    assert walker._uncross(step, close) == pytest.approx(expected, abs=1e-12)


@pytest.mark.slow
@pytest.mark.parametrize("kind", ["step_up", "slope", "step_down"])
def test_unplanned_uneven_ground_is_walked_with_every_foothold_on_target(kind):
    """The quick walk (0.25 m steps) over ground it was not told about: a 4 cm box from
    x = 0.36 m on, a 2-degree slope rising from there, or a 4 cm platform it steps off. It
    does not fall, every touchdown comes from a contact report, and every foot lands within
    2 cm of its (adjusted) target, at the ground's height: the box's 0.04 m, the platform's
    0.04 m below the start, or on the slope tan(2 deg) (x - 0.36) for the last footholds,
    whose x lies in [0.7, 0.9] m (written here, not taken from the walker)."""
    from dmpopt_studies import talos_walk_recovery as recovery

    result = recovery.terrain_trial(kind)
    assert not result["fell"]
    assert result["steps_landed"] == result["steps_planned"] == 5
    assert result["touchdowns_from_contact"] == 5
    assert result["foothold_error_max_mm"] < 20.0
    last = np.array(result["foothold_heights_mm"][-2:])
    if kind == "step_up":
        np.testing.assert_allclose(last, 40.0, atol=5.0)
    elif kind == "step_down":
        np.testing.assert_allclose(last, -40.0, atol=5.0)
    else:
        slope = np.tan(np.radians(2.0))
        assert np.all((1e3 * slope * (0.7 - 0.36) - 3 < last) & (last < 1e3 * slope * 0.54 + 3))


def test_a_push_trial_counts_only_a_robot_standing_still_at_the_end():
    """The survival rule of the push trials: a CoM drifting at 0.1 m/s over the last 0.2 s
    (0.02 m, more than 0.05 m/s x 0.2 s) is not standing; one that moved 5 mm in that
    window (0.025 m/s) is. Written out here: positions x(t) = x0 + v t."""
    from dmpopt_studies import talos_walk_recovery as recovery

    times = np.arange(0.0, 1.0, 0.001)
    for speed, standing in ((0.1, False), (0.025, True), (0.0, True)):
        com = np.zeros((times.size, 3))
        com[:, 0] = 0.3 + speed * times
        assert recovery.stands_still(times, com) is standing
    com[:, 1] = np.where(times > 0.9, 0.5, 0.0)  # a jump of 0.5 m sideways in the window
    assert recovery.stands_still(times, com) is False
    assert recovery.STILL_WINDOW == 0.2 and recovery.STILL_SPEED == 0.05


@pytest.mark.slow
def test_a_forked_push_trial_is_the_walk_pushed_from_the_start():
    """The push trials walk once up to the push and fork one continuation per impulse
    (dmpopt_studies.branching): the trial that continues in the parent gives the same bits
    (CoM, DCM and the plan's references at every tick) as the same push walked from the
    start; the other trial, pushed half as hard, does not."""
    from dmpopt_robots.plants import talos_realistic
    from dmpopt_studies import talos_walk_recovery as recovery
    from dmpopt_studies.branching import Branch

    lateral = np.array(recovery.PUSH_DIRECTIONS["lateral"])

    def pushed(impulse):
        robot, q0 = talos_walk._robot_and_start()
        plan, swing_dmps = talos_walk.build_plan(robot, q0, quick=True)
        plant = talos_realistic(robot)
        walker = talos_walk.Walker(robot, q0, plan, swing_dmps, plant)
        push = (recovery.PUSH_STEP, recovery.PUSH_DELAY, impulse)
        duration = recovery.walk_duration(plan)
        return talos_walk.simulate(robot, q0, walker, duration, 0, plant, push, feet=False)[0]

    alone = pushed(40.0 * lateral)
    branch = Branch(2)
    forked = branch.logs(pushed(lambda: (40.0, 20.0)[branch.arm()] * lateral))
    for name in ("com", "dcm", "reference_com", "reference_dcm"):
        np.testing.assert_array_equal(getattr(forked[0], name), getattr(alone, name))
    assert not np.array_equal(forked[1].com, alone.com)
