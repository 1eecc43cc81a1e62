"""The humanoid study's discrete forehand, Fig. 4 step changes, summary table and captions."""

import numpy as np
import pinocchio as pin
import pytest
from dmpopt_robots import load_talos
from dmpopt_studies import humanoid
from dmpopt_studies.humanoid import swing
from dmpopt_studies.humanoid.summary import captions, summary_rows


@pytest.fixture(scope="module")
def talos():
    return load_talos("full")


@pytest.fixture(scope="module")
def dmps():
    return humanoid.learn_drumming(humanoid.demonstrate_drumming())


def test_swing_demonstration_is_two_minimum_jerk_submovements(talos):
    """Answer key: the minimum-jerk polynomial written out; the demonstration starts at the
    ready posture and ends at the follow-through at rest, within the velocity limits."""
    demo = swing.demonstrate_swing(talos)
    ready, back, follow = swing.swing_keyframes(talos)
    t = demo.times
    s1 = np.clip(t / humanoid.parameters.SWING_BACK_SECONDS, 0, 1)
    t2 = t - humanoid.parameters.SWING_FORWARD_START
    s2 = np.clip(t2 / humanoid.parameters.SWING_FORWARD_SECONDS, 0, 1)
    expected = (
        ready
        + np.outer(10 * s1**3 - 15 * s1**4 + 6 * s1**5, back - ready)
        + np.outer(10 * s2**3 - 15 * s2**4 + 6 * s2**5, follow - back)
    )
    np.testing.assert_allclose(demo.positions, expected, atol=1e-12)
    np.testing.assert_allclose(demo.positions[-1], follow, atol=1e-12)
    assert np.abs(demo.velocities[[0, -1]]).max() < 1e-2  # at rest (finite differences)
    limit = talos.model.velocityLimit[talos.velocity_indices(list(swing.SWING_JOINTS))]
    assert (np.abs(demo.velocities) / limit).max() < 0.9
    # the forward swing is the fast part: its peak joint speed is over twice the backswing's
    backswing = t < humanoid.parameters.SWING_FORWARD_START
    assert np.abs(demo.velocities[~backswing]).max() > 2 * np.abs(demo.velocities[backswing]).max()


def test_swing_dmp_reproduces_and_raised_goal_lifts_the_hand(talos):
    """The default discrete fit reproduces the demonstration within 1 mrad; the new goal's
    hand is SWING_FINISH_RAISE higher than the demonstrated goal's (answer key: pinocchio's
    forward kinematics, written here), at the same x and y."""
    demo = swing.demonstrate_swing(talos)
    dmp = swing.learn_swing(demo)
    plan = dmp.rollout(demo.duration, demo.times[1] - demo.times[0])
    assert np.abs(plan.positions - demo.positions).max() < 1e-3
    goal = swing.raised_goal(talos, dmp)
    model, data = talos.model, talos.create_data()
    frame = model.getFrameId(talos.hand_frames[1])
    arm = talos.configuration_indices(list(swing.SWING_JOINTS))
    hands = []
    for posture in (dmp.goal, goal):
        q = humanoid.drumming_posture(talos)
        q[arm] = posture
        pin.framesForwardKinematics(model, data, q)
        hands.append(data.oMf[frame].translation.copy())
    lift = hands[1] - hands[0]
    np.testing.assert_allclose(lift, [0, 0, humanoid.parameters.SWING_FINISH_RAISE], atol=1e-6)
    np.testing.assert_allclose(goal[4:], dmp.goal[4:])  # the wrist as demonstrated


def test_setpoint_step_reaches_the_plan_as_eq5_says(dmps):
    """Answer key: a step of g by SETPOINT_SHIFT moves the elbow plan by the critically
    damped response of eq. (5), ``dg (1 - (1 + w t) e^{-w t})`` with ``w = alpha_z / (2
    tau)`` (the forcing term does not depend on g). A filter on the change would lag it."""
    start = 0.5
    base = humanoid.plan_rollout(dmps, 1.5)
    shift = humanoid.SETPOINT_SHIFT
    elbow = dmps.elbow_index
    step = humanoid.plan_rollout(dmps, 1.5, humanoid.Modification("setpoint", start, 9.0))
    times = step["times"]
    omega = dmps.elbow.alpha_z / (2 * dmps.elbow.tau)
    s = np.clip(times - start, 0, None)
    expected = shift * (1 - (1 + omega * s) * np.exp(-omega * s))
    moved = step["positions"][:, elbow] - base["positions"][:, elbow]
    np.testing.assert_allclose(moved, expected, atol=1e-5 * shift)
    filtered = humanoid.plan_rollout(
        dmps, 1.5, humanoid.Modification("setpoint", start, 9.0, filter=0.1)
    )
    lag = expected - (filtered["positions"][:, elbow] - base["positions"][:, elbow])
    assert lag.max() > 0.1 * shift


def test_setpoint_shift_keeps_the_elbow_inside_its_range(talos, dmps):
    """The paper's +1 (in rad) puts the elbow's whole limit cycle inside the joint range."""
    cycle = humanoid.elbow_limit_cycle(dmps)(np.linspace(0, 2 * np.pi, 361))
    index = talos.configuration_indices([humanoid.parameters.ELBOW])[0]
    shifted = cycle + humanoid.SETPOINT_SHIFT
    assert humanoid.SETPOINT_SHIFT == 1.0
    assert talos.position_lower[index] < shifted.min() < shifted.max() < talos.position_upper[index]


def _metrics_stub():
    """The metric keys summary_rows and captions read, with distinct values."""
    change = {
        "robot": {"onset_s": 0.123},
        "plan": {"onset_s": 0.045},
        "plan_filtered": {"onset_s": 0.267},
        "frequency_settle_s": 0.0,
        "fell": False,
    }
    run = {
        "fell": False,
        "joint_tracking_rms_rad": 4.2e-4,
        "joint_tracking_max_rad": 1.4e-3,
        "hand_path_rms_mm": 12.3,
        "hand_path_in_pelvis_frame_rms_mm": 0.98,
        "peak_hand_speed_m_s": 2.34,
        "peak_hand_speed_plan_m_s": 2.47,
        "com_displacement_max_mm": 0.15,
    }
    return {
        "backend": "mujoco",
        "tracking_rms_rad": 1.35e-4,
        "tracking_max_rad": 6.0e-4,
        "dmp_fit_error_rad": 7.6e-4,
        "fell": False,
        "native": {"tracking_rms_rad": 1.69e-4, "fell": False},
        "fig4": {"amplitude": change, "frequency": change, "setpoint": change},
        "setpoint_shift_rad": 1.0,
        "setpoint_velocity_bound_s": 0.218,
        "discrete_swing": {
            **run,
            "n_basis": 30,
            "new_goal": {
                **run,
                "fell": True,
                "finish_raise_plan_mm": 119.6,
                "finish_raise_executed_mm": 117.1,
                "contact_height_change_mm": -3.0,
            },
        },
        "figure8_rms_mm": 1.61,
        "figure8_max_mm": 3.09,
        "tick_us_median": 71.0,
        "tick_us_p99": 150.0,
        "real_time_factor_cpu": 1.3,
    }


def test_summary_rows_format_the_metrics():
    """Every row has the five columns; the numbers are those of the metrics; a fall shows."""
    metrics = _metrics_stub()
    rows = summary_rows(metrics)
    assert all(set(row) == {"claim", "paper", "dmpopt", "anchor", "verdict"} for row in rows)
    text = " ".join(row["dmpopt"] for row in rows)
    for number in ("0.135 mrad", "0.123 s", "0.045 s", "0.218 s", "2.34 m/s", "12.3 mm"):
        assert number in text, number
    assert "-3 mm in height" in text and "1.61 mm" in text
    assert "0.267 s" in " ".join(row["anchor"] for row in rows)
    new_goal = next(row for row in rows if "new goal" in row["claim"])
    assert "fell: True" in new_goal["dmpopt"]
    metrics["fig4"]["setpoint"] = {**metrics["fig4"]["setpoint"], "robot": {"onset_s": None}}
    setpoint = next(row for row in summary_rows(metrics) if "g -> g + 1 rad" in row["claim"])
    assert "did not settle" in setpoint["dmpopt"] and setpoint["verdict"] == "fails"


def test_captions_name_the_swing_numbers():
    text = captions(_metrics_stub())
    assert {"fig4_elbow", "figure8", "swing", "demonstration"} <= set(text)
    assert "120 mm higher" in text["swing"] and "12.3 mm" in text["swing"]


def test_scenarios_do_not_depend_on_the_runner(dmps):
    """Two short MuJoCo scenarios (a heavier model, a push) in series and in two worker
    processes: the same logs, in the order of the inputs (to round-off: the linear algebra
    of another process may sum in another order, 1e-13 rad measured)."""
    from dmpopt_studies.humanoid.robustness import Scenario, run_scenario

    from dmpopt.parallel import Runner, map_runs

    base = Scenario(dmps, duration=0.05)
    scenarios = [Scenario(dmps, 0.05, mass_scale=1.1), Scenario(dmps, 0.05, push_ns=5.0)]
    serial = map_runs(run_scenario, scenarios, Runner())
    parallel = map_runs(run_scenario, scenarios, Runner(2))
    for one, other in zip(serial, parallel):
        np.testing.assert_allclose(one.actual, other.actual, rtol=0, atol=1e-10)
        assert "simulator" not in one.extras  # it does not cross processes
    assert not np.array_equal(serial[0].actual, map_runs(run_scenario, [base])[0].actual)
