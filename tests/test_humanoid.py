"""Drumming on Talos with rhythmic DMPs and QP inverse dynamics (studies/humanoid.py, Fig. 4)."""

import json
from types import SimpleNamespace

import numpy as np
import pytest

from dmpopt.exceptions import InvalidInputError, MissingDependency
from robots import load_talos
from studies import humanoid

TRACKING_TOLERANCE = 0.01  # [rad] largest joint tracking error allowed in a short run


@pytest.fixture(scope="module")
def demo():
    return humanoid.demonstrate_drumming()


@pytest.fixture(scope="module")
def dmps(demo):
    return humanoid.learn_drumming(demo)


def test_demonstration_is_periodic_and_exact(demo):
    """The IK reaches every target pose and the joint demonstration closes on itself."""
    positions = demo.joints.positions
    half = (positions.shape[0] - 1) // 2
    assert demo.ik_error < 1e-6
    np.testing.assert_allclose(positions[0], positions[half], atol=1e-6)
    assert positions.shape[1] == 12
    assert np.ptp(positions, axis=0).max() > 0.1  # the arms really move


def test_dmps_reproduce_the_demonstration(dmps, demo):
    """The learned limit cycle matches the demonstrated cycle within 2 mrad."""
    period_steps = int(round(humanoid.PERIOD / humanoid.DT))
    plan = humanoid.plan_rollout(dmps, humanoid.PERIOD)["positions"]
    demo_cycle = demo.joints.positions[: demo.joints.n_steps // 2 + 1]
    index = np.linspace(0, period_steps, demo_cycle.shape[0]).round().astype(int)
    assert np.abs(plan[index] - demo_cycle).max() < 2e-3


@pytest.mark.parametrize("name", ["amplitude", "frequency", "setpoint"])
def test_fig4_modification_converges_to_new_limit_cycle(dmps, name):
    """A x2, tau/2, g + 0.1 rad on the elbow plan: within 5 % of the new cycle within 0.5 s."""
    modification = humanoid.Modification(name, 1.0, 4.0)
    plan = humanoid.plan_rollout(dmps, 6.0, modification)
    times = plan["times"]
    elbow = plan["positions"][:, dmps.elbow_index]
    ideal = humanoid.ideal_elbow(dmps, modification, times, plan["elbow_phase"])
    window = (times >= 1.0) & (times < 4.0)
    tolerance = humanoid.SETTLE_TOLERANCE * np.ptp(ideal[window])
    settle = humanoid.settle_time(times, elbow, ideal, 1.0, 4.0, tolerance)
    assert settle is not None and settle < 0.5
    late = (times >= 2.0) & (times < 4.0)
    assert np.abs(elbow[late] - ideal[late]).max() < 0.01 * np.ptp(ideal[window])
    # The other joints do not notice (one shared oscillator, untouched).
    unmodified = humanoid.plan_rollout(dmps, 6.0)["positions"]
    others = np.arange(12) != dmps.elbow_index
    np.testing.assert_allclose(plan["positions"][:, others], unmodified[:, others], atol=1e-12)
    if name == "amplitude":
        assert np.ptp(elbow[late]) == pytest.approx(
            2 * np.ptp(unmodified[late, dmps.elbow_index]), rel=0.02
        )
    if name == "frequency":
        rate = np.gradient(plan["elbow_phase"], times)
        assert rate[late].mean() == pytest.approx(2 / dmps.elbow.tau, rel=1e-3)


def test_elbow_relocks_to_the_shared_oscillator(dmps):
    """After tau/2 ends, the phase coupling brings the elbow back in phase with the others."""
    plan = humanoid.plan_rollout(dmps, 8.0, humanoid.Modification("frequency", 1.0, 2.0))
    shared = humanoid.plan_rollout(dmps, 8.0)["elbow_phase"]
    difference = np.angle(np.exp(1j * (plan["elbow_phase"] - shared)))
    assert abs(difference[int(1.5 / humanoid.DT)]) > 0.5  # really out of phase
    assert abs(difference[-1]) < 0.01


def test_fixed_base_drumming_tracks(dmps):
    """Fixed-base upper body, 1 s of drumming: every joint within TRACKING_TOLERANCE."""
    log = humanoid.run_drumming(load_talos("full", fixed_base=True), dmps, 1.0)
    error = np.abs(log.actual - log.desired)
    assert error.max() < TRACKING_TOLERANCE
    assert log.n_fallbacks == 0
    assert log.torque_use.max() <= 1.0 + 1e-9


def test_standing_drumming_tracks_and_stays_up(dmps):
    """Floating-base Talos on two feet, 1 s of drumming: tracks, balances, does not fall."""
    log = humanoid.run_drumming(load_talos("full"), dmps, 1.0)
    assert np.abs(log.actual - log.desired).max() < TRACKING_TOLERANCE
    assert not log.fell
    assert np.degrees(np.ptp(log.base[:, 3])) < 0.5  # pelvis roll held by the base task
    assert log.n_fallbacks == 0


def test_quick_study_writes_metrics_and_figures(tmp_path):
    """The quick study runs end to end in MuJoCo (default) and reports its headline claims."""
    metrics = humanoid.run(tmp_path, quick=True)
    assert metrics["backend"] == "mujoco"
    for key in ("tick_us_median", "tick_us_p99", "tracking_rms_rad", "real_time_factor"):
        assert metrics[key] > 0
    assert metrics["fell"] is False
    assert metrics["tracking_rms_rad"] < 0.005
    # the drumming joints stay inside their position limits, by a margin below a half-turn
    assert 0.0 < metrics["position_limit_margin_rad"] < np.pi
    assert metrics["position_limit_margin_joint"] in humanoid.DRUM_JOINTS
    for figure in ("fig4_elbow", "drumming_tracking", "figure8", "base_com", "tick_times"):
        assert (tmp_path / f"{figure}.png").stat().st_size > 10_000

    mujoco, native = metrics["mujoco"], metrics["native"]
    # Nominal MuJoCo drumming: standing, tracking within 5 mrad RMS, as on the native ground.
    assert mujoco["fell"] is False and native["fell"] is False
    assert mujoco["tracking_rms_rad"] < 0.005 and native["tracking_rms_rad"] < 0.005
    assert mujoco["real_time_factor"] > 0 and native["real_time_factor"] > 0
    # The push ladder of the quick run is (10, 60) N s: 10 N s forward is survived.
    tried = [row["impulse_ns"] for row in mujoco["push_tried_ns"]]
    assert tried[0] == 10.0 and mujoco["push_survived_ns"] >= 10.0
    assert mujoco["push_fell_ns"] in (None, 60.0)
    capped = "only a lower bound" in mujoco["push_note"]
    assert capped == (mujoco["push_fell_ns"] is None)  # the note says so only when capped
    # Tight torque limits bind: the QP's torque rows are active on some ticks, and the
    # torques stay within the tightened limits (a fraction of the URDF limits).
    tight = mujoco["scenarios"]["tight_torque_limits"]
    assert mujoco["qp_active_scenario"] == "tight_torque_limits"
    assert mujoco["qp_active_fraction"] == tight["qp_active_fraction"] > 0
    assert tight["torque_limited_fraction"] > 0
    assert tight["torque_limit_use_max"] <= tight["scale_of_urdf_limits"] + 1e-6
    assert tight["scale_of_urdf_limits"] < mujoco["torque_limit_use_max"]
    for name in ("link_masses_x0.9", "link_masses_x1.1", "friction_0.4", "friction_0.7"):
        scenario = mujoco["scenarios"][name]
        assert scenario["fell"] is False and scenario["tracking_rms_rad"] < 0.01, name
    assert metrics["videos"] == [] and metrics["videos_skipped"] == "quick run"
    written = json.loads((tmp_path / "metrics.json").read_text())
    assert written["mujoco"]["push_survived_ns"] == mujoco["push_survived_ns"]


def test_unknown_backend_is_refused(tmp_path):
    with pytest.raises(InvalidInputError, match="backend must be one of .*'bullet'"):
        humanoid.run(tmp_path, quick=True, backend="bullet")


def test_push_search_brackets_the_threshold():
    """Against a robot that falls above 33 N s: ladder up to the first fall, then bisection."""

    def drum(push):
        time, impulse = push
        assert time == humanoid.PUSH_TIME and impulse[1:].tolist() == [0.0, 0.0]
        return SimpleNamespace(fell=impulse[0] > 33.0, diverged=None, impulse=impulse[0])

    result = humanoid.push_search(drum, (10.0, 20.0, 40.0, 80.0), bisections=2)
    assert [row["impulse_ns"] for row in result["tried"]] == [10.0, 20.0, 40.0, 30.0, 35.0]
    assert (result["survived_ns"], result["fell_ns"]) == (30.0, 35.0)
    assert result["log"].impulse == 30.0
    capped = humanoid.push_search(drum, (10.0, 20.0), bisections=2)
    assert (capped["survived_ns"], capped["fell_ns"]) == (20.0, None)


def test_push_search_reports_divergence_apart_from_falls():
    """A run that diverges above 33 N s bounds the search but is no fall in the rows tried."""

    def drum(push):
        diverged = "|v| reached 2e3" if push[1][0] > 33.0 else None
        return SimpleNamespace(fell=False, diverged=diverged, impulse=push[1][0])

    result = humanoid.push_search(drum, (10.0, 20.0, 40.0), bisections=1)
    rows = {row["impulse_ns"]: row for row in result["tried"]}
    assert not any(row["fell"] for row in rows.values())
    assert rows[40.0]["diverged"] == "|v| reached 2e3" and rows[30.0]["diverged"] is None
    assert result["survived_ns"] == 30.0 and result["fell_ns"] == 40.0


def test_scaled_masses_and_torque_limits():
    """Every link x scale (total mass x scale); torque limits x scale; the original untouched."""
    import pinocchio as pin

    robot = load_talos("full")
    mass = pin.computeTotalMass(robot.model)
    heavier = humanoid.with_scaled_masses(robot, 1.1)
    assert pin.computeTotalMass(heavier.model) == pytest.approx(1.1 * mass, rel=1e-12)
    assert pin.computeTotalMass(robot.model) == pytest.approx(mass, rel=1e-12)
    tight = humanoid.with_scaled_torque_limits(robot, 0.5)
    np.testing.assert_allclose(tight.torque_limit, 0.5 * np.asarray(robot.torque_limit))


def test_videos_skipped_with_the_reason(tmp_path, monkeypatch):
    """No OpenGL context: nothing written, the MissingDependency message is the reason."""
    import dmpopt.sim

    def no_gl(*args, **kwargs):
        raise MissingDependency("no OpenGL context for offscreen rendering")

    monkeypatch.setattr(dmpopt.sim, "render_animation", no_gl)
    clips = {"clip": (None, np.zeros((2, 3)), 3.0)}
    assert humanoid.write_videos(tmp_path, clips) == (
        [],
        "no OpenGL context for offscreen rendering",
    )
    assert humanoid.write_videos(tmp_path, clips, "quick run") == ([], "quick run")
    assert list(tmp_path.iterdir()) == []
