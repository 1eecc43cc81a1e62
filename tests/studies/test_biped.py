"""Tests of the planar biped: model, ground contact, heel strikes, phase reset, a short walk."""

import numpy as np
import pytest
from dmpopt_robots import biped as biped_model

from dmpopt.sim import GroundContact, Simulator

GRAVITY = 9.81


@pytest.fixture(scope="module")
def gait():
    from dmpopt_studies.biped import learn_gait

    return learn_gait()


def test_model_matches_its_documented_parameters(biped):
    """7 kg, 0.6 m legs, planar base (x, z, pitch) plus four actuated joints."""
    assert biped.mass == pytest.approx(7.0)
    assert biped_model.leg_length(biped) == pytest.approx(0.6)
    assert biped.model.nq == biped.model.nv == 7
    q = biped_model.configuration(biped, 0.0, 0.6, 0.0, [0.3, 0.0, 0.0, 0.0])
    right, left = biped_model.foot_positions(biped, q)
    assert right == pytest.approx([0.6 * np.sin(0.3), 0.6 - 0.6 * np.cos(0.3)])
    assert left == pytest.approx([0.0, 0.0])


def test_actuator_torques_follow_the_model_order(biped):
    torques = biped_model.actuator_torques(biped, [1.0, 2.0, 3.0, 4.0])
    assert torques[biped.velocity_indices("gait") - 3] == pytest.approx([1, 2, 3, 4])


def test_standing_biped_rests_at_spring_height_with_weight_on_feet(biped):
    """Dropped with locked joints, the feet carry m g and sink by F / k each."""
    ground = GroundContact(stiffness=1e4, damping=150.0, friction=0.8)
    sim = Simulator(biped.model, 1e-3, biped.contact_points, ground)
    assert sim.n_base_dofs == 3
    joints = np.array([0.15, 0.1, -0.15, 0.1])
    q = biped_model.configuration(biped, 0.0, 0.0, 0.0, joints)
    q[1] = 0.05 - biped_model.foot_positions(biped, q)[:, 1].min()
    state = sim.reset(q)
    index = biped.velocity_indices("gait")
    for _ in range(2500):
        torque = 200.0 * (joints - state.q[index]) - 2.0 * state.v[index]
        boom = [0.0, 0.0, -500.0 * state.q[2] - 30.0 * state.v[2]]
        state = sim.step(biped_model.actuator_torques(biped, torque), boom)
    assert state.in_contact.all()
    assert state.contact_forces[:, 2].sum() == pytest.approx(biped.mass * GRAVITY, rel=2e-3)
    sink = -state.contact_positions[:, 2]
    assert sink == pytest.approx(state.contact_forces[:, 2] / 1e4, rel=1e-2, abs=1e-5)
    assert np.abs(state.v).max() < 1e-2


@pytest.mark.parametrize("backend", ["mujoco", "native"])
def test_short_walk_does_not_fall_and_strikes_alternate(biped, gait, backend):
    """Seeded 6 s walk on each simulator: no fall, forward progress, alternating heel strikes
    with the phase reset to 0 (right) or pi (left) as eq. (21) says."""
    from dmpopt_studies.biped import walk

    _, dmp = gait
    log = walk(biped, dmp, duration=6.0, frequency=5.0, adapt=True, seed=0, backend=backend)
    assert not log.fell, log.diverged
    assert log.distance > 1.5
    assert log.positive_work > 0 and log.absolute_work >= log.positive_work
    legs = [leg for _, leg, _ in log.strikes]
    assert len(legs) >= 4
    assert all(a != b for a, b in zip(legs, legs[1:]))
    times = np.array([t for t, _, _ in log.strikes])
    assert np.all(np.diff(times) > 0.1)
    assert len(log.frequencies) == len(log.strikes)


def test_phase_reset_sets_the_dmp_phase_per_eq_21(gait):
    """After a strike of the right leg the shared phase is 0, after the left leg pi."""
    from dmpopt.frequency_adaptation import FrequencyAdaptation, HeelStrike

    _, dmp = gait
    stepper = dmp.stepper(1e-3)
    adaptation = FrequencyAdaptation(frequency=5.0, gain=0.3)
    for _ in range(123):
        stepper.step()
    for time, leg, expected in ((0.123, 1, np.pi), (0.6, 0, 0.0)):
        phase, frequency = adaptation.on_heel_strike(HeelStrike(time, leg, np.zeros(3)))
        stepper.reset_phase(phase)
        stepper.set_tau(1.0 / frequency)
        assert stepper.phase == pytest.approx(expected)
    stepper.step()
    assert stepper.phase == pytest.approx(frequency * 1e-3)


def test_demonstration_puts_both_feet_on_the_ground_at_heel_strike(gait):
    """Retargeted to point feet: both legs reach equally far down at phase 0 and pi."""
    demo, _ = gait

    def reach(hip, knee):  # vertical hip-to-foot distance, thigh and shank 0.3 m
        return 0.3 * np.cos(hip) + 0.3 * np.cos(hip - knee)

    n = (len(demo.times) - 1) // 2
    for k in (0, n // 2):
        right, left = demo.positions[k, :2], demo.positions[k, 2:]
        assert reach(*right) == pytest.approx(reach(*left), abs=2e-3)


def test_adaptation_moves_towards_the_measured_step_rate(biped, gait):
    """From the too-high demonstrated frequency the walker steps slower than pi / omega, so
    eq. (21) lowers omega, every update by K times the measured error."""
    from dmpopt_studies.biped import ADAPTATION_GAIN, walk

    _, dmp = gait
    log = walk(biped, dmp, duration=6.0, frequency=5.0, adapt=True, seed=0, log_every=10**9)
    frequencies = np.asarray(log.frequencies)
    durations = np.diff([t for t, _, _ in log.strikes])
    expected = frequencies[:-1] + ADAPTATION_GAIN * (np.pi / durations - frequencies[:-1])
    assert frequencies[1:] == pytest.approx(expected, rel=1e-12)
    assert frequencies[-1] < 0.9 * frequencies[0]


def test_unknown_backend_is_refused(biped, gait):
    from dmpopt_studies.biped import walk

    from dmpopt.exceptions import InvalidInputError

    with pytest.raises(InvalidInputError, match="backend must be one of .*'native2'"):
        walk(biped, gait[1], duration=1.0, frequency=5.0, backend="native2")


def test_mujoco_fall_height_matches_the_native_one(biped):
    """Both backends get the same fall options: the same thresholds, min height FALL_HEIGHT."""
    from dmpopt_studies.biped.walker import FALL_HEIGHT, make_simulator

    mujoco, native = (make_simulator(biped, b).fall_detector for b in ("mujoco", "native"))
    assert mujoco == native
    assert mujoco.min_height == FALL_HEIGHT


def test_wilson_interval_matches_newcombe_1998():
    """Newcombe (1998), Stat. Med. 17:857, Table I, method 3: 81/263, 15/148, 0/20, 1/29."""
    from dmpopt_studies.biped.analysis import wilson_interval

    for (x, n), expected in (
        ((81, 263), (0.2553, 0.3662)),
        ((15, 148), (0.0624, 0.1605)),
        ((0, 20), (0.0, 0.1611)),
        ((1, 29), (0.0061, 0.1718)),
    ):
        assert wilson_interval(x, n) == pytest.approx(expected, abs=1e-4)
    z2 = 1.959963984540054**2
    assert wilson_interval(50, 50) == pytest.approx((50 / (50 + z2), 1.0))
    assert wilson_interval(0, 50)[0] == 0.0 and wilson_interval(50, 50)[1] == 1.0


@pytest.mark.parametrize("x, n", [(3, 2), (-1, 5), (0, 0), (1, 2.5)])
def test_wilson_interval_refuses_impossible_counts(x, n):
    from dmpopt_studies.biped.analysis import wilson_interval

    from dmpopt.exceptions import InvalidInputError

    with pytest.raises(InvalidInputError, match="successes <= n"):
        wilson_interval(x, n)


def _log(speed=0.4, strikes=(0, 1, 0, 1, 0, 1), height=0.55, fell=False, end=8.0):
    """A hand-made walk: base at ``speed`` m/s and ``height`` m, strikes every end/6 s."""
    from dmpopt_studies.biped.walker import WalkLog

    times = np.arange(0.0, end + 1e-9, 0.01)
    q = [np.array([speed * t, height, 0, 0, 0, 0, 0]) for t in times]
    step = end / len(strikes)
    hits = [((k + 1) * step - 0.01, leg, 0.0) for k, leg in enumerate(strikes)]
    return WalkLog(times=list(times), q=q, strikes=hits, fell=fell, duration=end)


@pytest.mark.parametrize(
    "log, survived",
    [
        (_log(), True),
        (_log(fell=True), False),
        (_log(speed=3.0), False),  # sent flying: not walking on
        (_log(speed=-0.3), False),  # pushed back, walking backwards
        (_log(strikes=(0, 1, 0, 1, 0, 0)), False),  # same leg twice: a stumble
        (_log(strikes=(0, 1, 0)), False),  # stopped stepping in the last 2.5 s
        (_log(height=0.4), False),  # crouched below the fall height + 0.1 m
    ],
)
def test_survival_rule_means_walking_on(log, survived):
    from dmpopt_studies.biped.analysis import SURVIVAL

    assert SURVIVAL.survived(log) is survived


def test_survival_by_arm_counts_outcomes_and_intervals(monkeypatch):
    """Fake walks: the arm with phase resetting survives the pushes up to 2 N s, the others
    none; rates, counts and Wilson intervals follow from the outcomes written here."""
    from dmpopt_studies.biped import analysis
    from dmpopt_studies.biped.walker import Disturbance

    def fake_walk(biped, dmp, duration, frequency, arms, disturbance, **_):
        pushed = disturbance.push_impulse
        return [_log(speed=0.4 if reset and pushed <= 2.0 else 5.0) for reset, _ in arms]

    monkeypatch.setattr(analysis, "walk", fake_walk)
    pushes = [Disturbance(push_impulse=p) for p in (0.5, 1.0, 2.0, 3.0, 4.0)]
    result = analysis.survival_by_arm(None, None, 2.0, pushes)
    assert result["reset_and_adapt"]["survived"] == result["reset_only"]["survived"] == 3
    assert result["neither"]["rate"] == result["adapt_only"]["rate"] == 0.0
    assert result["neither"]["n"] == 5
    assert result["reset_only"]["ci95_wilson"] == pytest.approx(analysis.wilson_interval(3, 5))
    assert result["reset_and_adapt"]["outcomes"] == [True, True, True, False, False]


def test_reset_ablation_pairs_arms_with_the_adaptation_in_the_same_state():
    """Discordant pairs and the exact McNemar p-value written plainly: with 5 trials won only
    by resetting and 1 only without, p = 2 (C(6,0) + C(6,1)) / 2^6 = 14 / 64."""
    from dmpopt_studies.biped.analysis import reset_ablation

    def arm(outcomes):
        rate, interval = sum(outcomes) / len(outcomes), _wilson(sum(outcomes), len(outcomes))
        return {"outcomes": outcomes, "rate": rate, "ci95_wilson": interval}

    survival = {
        "reset_and_adapt": arm([True] * 6 + [False, True]),
        "adapt_only": arm([False] * 5 + [True, True, True]),
        "reset_only": arm([True, False] * 4),
        "neither": arm([True, False] * 4),
    }
    result = reset_ablation(survival)
    on, off = result["adaptation_on"], result["adaptation_off"]
    assert (on["with_reset"], on["without_reset"]) == ("reset_and_adapt", "adapt_only")
    assert (off["with_reset"], off["without_reset"]) == ("reset_only", "neither")
    assert on["survived_only_with_reset"] == 5 and on["survived_only_without_reset"] == 1
    assert on["mcnemar_p"] == pytest.approx(14 / 64)
    assert on["difference"] == pytest.approx(7 / 8 - 3 / 8)
    assert off["mcnemar_p"] == 1.0 and off["difference"] == 0.0


@pytest.mark.parametrize(
    "frequencies, expected",
    [
        ([5.0] + [10.0] * 30, 1),  # settles at the first strike
        ([5.0, 8.0, 9.0] + [10.0, 10.1] * 15, 3),  # 9 is 10 % below, 10.1 within 2 %
        (list(np.linspace(5.0, 10.0, 40)), "at least 40"),  # still rising: only a bound
        ([5.0] * 30 + [10.0] * 15, "at least 30"),  # settled for fewer than 20 strikes
    ],
)
def test_steps_to_within_reports_a_capped_result_as_a_bound(frequencies, expected):
    from dmpopt_studies.biped.analysis import steps_to_within

    assert steps_to_within(frequencies) == expected


def test_sweep_minimum_at_the_edge_of_the_sweep_is_a_bound():
    from dmpopt_studies.biped.analysis import sweep_minimum

    rows = [{"frequency": f, "cost_of_transport": c} for f, c in ((4.0, 0.2), (5.0, 0.3))]
    assert sweep_minimum(rows)["bound"] == "at most 4 rad/s (sweep's edge)"
    rows = [{"frequency": f, "cost_of_transport": c} for f, c in ((4.0, 0.5), (5.0, 0.3))]
    assert sweep_minimum(rows)["bound"] == "at least 5 rad/s (sweep's edge)"
    rows.append({"frequency": 6.0, "cost_of_transport": None})  # fell: still tried
    assert sweep_minimum(rows)["bound"] is None


def test_sweep_minimum_reports_the_flat_band():
    from dmpopt_studies.biped.analysis import sweep_minimum

    rows = [
        {"frequency": f, "cost_of_transport": c}
        for f, c in ((1.0, 0.5), (2.0, 0.30), (2.5, 0.31), (3.0, 0.40), (4.0, None))
    ]
    found = sweep_minimum(rows)
    assert found["min_cost_of_transport_frequency"] == 2.0
    assert found["within_5%_of_min_rad_s"] == [2.0, 2.5]


def test_qp_contacts_switch_on_heel_strikes_not_on_the_dmp_phase(biped):
    """The walk starts at a right heel strike: lift_phase of a step pi / omega later the left
    contact ramps out over the transition time and is gone; the left heel strike puts it
    back, and lift_phase of a step after it the right contact ramps out."""
    from types import SimpleNamespace

    from dmpopt_studies.biped.walker import QP_GAINS, QPControl

    law = QPControl(biped)
    law.frequency = 5.0
    lift = QP_GAINS.lift_phase * np.pi / 5.0  # [s] after a heel strike
    q, v = np.array(biped.reference_configuration), np.zeros(biped.nv)
    reference = q[np.sort(biped.velocity_indices("gait"))]

    def run(times):
        for t in times:
            state = SimpleNamespace(t=t, q=q, v=v, in_contact=np.array([True, True]))
            law.torques(state, reference, np.zeros(4), np.zeros(4))

    run([0.0, 0.9 * lift])
    assert set(law.controller.active_contacts) == {"right_foot", "left_foot"}
    run([lift + k * QP_GAINS.transition_time for k in (0.0, 0.5, 2.0)])
    assert law.controller.active_contacts == ("right_foot",)
    law.on_heel_strike(1, 0.5, 5.0)
    assert set(law.controller.active_contacts) == {"right_foot", "left_foot"}
    run([0.5 + 0.9 * lift])
    assert set(law.controller.active_contacts) == {"right_foot", "left_foot"}
    run([0.5 + lift + k * QP_GAINS.transition_time for k in (0.0, 0.5, 2.0)])
    assert law.controller.active_contacts == ("left_foot",)


@pytest.fixture(scope="module")
def quick_run(tmp_path_factory):
    """One quick run of the study, shared: (output folder, metrics)."""
    from dmpopt_studies import biped as study

    folder = tmp_path_factory.mktemp("biped")
    return folder, study.run(folder, quick=True)


@pytest.fixture(scope="module")
def quick(quick_run):
    return quick_run[1]


def test_quick_study_walks_through_the_qp_and_records_why_not_pd(quick):
    """Fig. 7's walks use the QP without pitch torque because the paper's PD without it falls:
    the quick run's QP walk does not fall, its PD attempt does."""
    fig7 = quick["fig7"]
    assert fig7["controller"] == "qp" and quick["boom_pitch_stiffness_N_m_per_rad"] == 0
    assert quick["main_walk"]["fell"] is False and quick["main_walk"]["steps_walked"] >= 4
    (attempt,) = fig7["pd_without_pitch_torque"]
    assert attempt["fell"] is True and attempt["simulated_s"] < 1.5
    assert "every attempt" in fig7["why_not_pd"]


def test_quick_study_reports_fig7_with_its_controls(quick):
    """The issue's keys: four starts, the four resonance estimates, gravity and leg-length
    scaling (factor 1 is the walk from 12 rad/s), settings beside the baseline, a verdict."""
    fig7 = quick["fig7"]
    assert set(fig7["frequency_final_by_start"]) == {"5", "8", "12", "13.5"}
    assert len(fig7["resonance_estimates_rad_s"]) == 4
    baseline = fig7["frequency_settled_by_start"]["12"]
    assert fig7["gravity_scaling"]["1"] == fig7["leg_length_scaling"]["1"] == baseline
    assert set(fig7["gravity_scaling"]) == {"1", "0.5"}
    assert set(fig7["leg_length_scaling"]) == {"1", "1.25"}
    assert fig7["insensitivity"]["baseline"] == baseline and len(fig7["insensitivity"]) == 3
    assert fig7["verdict"].startswith("eq. (21) settles at")


def test_quick_study_swing_leg_under_qp_is_near_sqrt_of_posture_stiffness(quick):
    """Exact inverse dynamics makes each joint follow qdd = -K_p e: omega = sqrt(K_p), up to
    the coupling through the torso task and the held hip (both modes within 20 %)."""
    from dmpopt_studies.biped.walker import QP_GAINS

    swing = quick["fig7"]["closed_loop_leg_frequencies_rad_s"]
    assert np.asarray(swing["qp_controller"]) == pytest.approx(
        np.sqrt(QP_GAINS.posture_stiffness), rel=0.2
    )


def test_quick_study_reports_survival_per_arm_with_the_undisturbed_evidence(quick):
    """Each arm's survival with its Wilson interval, each arm's undisturbed walks, and the
    verdict undecided exactly when an arm did not walk undisturbed."""
    robustness = quick["reset_robustness"]
    assert set(robustness["arms"]) == {"reset_and_adapt", "adapt_only", "reset_only", "neither"}
    for arm in robustness["arms"].values():
        assert arm["n"] == 1 and arm["rate"] == arm["survived"]
        assert arm["ci95_wilson"][0] <= arm["rate"] <= arm["ci95_wilson"][1]
    walked = robustness["walks_undisturbed_by_seed"]
    assert set(walked) == set(robustness["arms"])
    every = all(all(seeds.values()) for seeds in walked.values())
    assert robustness["all_arms_walk_undisturbed"] == every
    assert robustness["verdict"].startswith("undecided") or every
    assert quick["videos"] == [] and quick["videos_skipped"] == "quick run"


def test_arm_without_resetting_never_resets_the_oscillator(biped, gait, monkeypatch):
    """Real QP walks of one trial per arm (pushed, masses, slope), each arm's switches as a
    trial passes them: the oscillator's phase is reset at heel strikes in the arms with
    resetting, never in ``adapt_only`` and ``neither``. Counts Stepper.reset_phase calls."""
    from dmpopt_studies.biped import analysis
    from dmpopt_studies.biped.walker import Disturbance

    from dmpopt.stepper import Stepper

    calls = []
    reset_phase = Stepper.reset_phase

    def counted(self, phase):
        calls[-1] += 1
        reset_phase(self, phase)

    monkeypatch.setattr(Stepper, "reset_phase", counted)
    _, dmp = gait
    qp = {"controller": "qp", "boom_pitch_stiffness": 0.0, "boom_pitch_damping": 0.0}
    push = Disturbance(push_impulse=1.0, push_time=0.3, slope_deg=1.0, slope_time=0.2)
    rule = analysis.Survival(after=1.0, window=0.5)
    assert list(analysis.ARMS) == ["reset_and_adapt", "adapt_only", "reset_only", "neither"]
    [(_, options)] = analysis.trial_jobs(biped, dmp, 8.0, [push], rule=rule, **qp)
    arms = options.pop("arms")
    assert arms == tuple(analysis.ARMS.values())
    for reset, adapt in arms:
        calls.append(0)
        analysis.walk(**options, reset_phase=reset, adapt=adapt)
    assert calls[1] == calls[3] == 0
    assert min(calls[0], calls[2]) >= 1


def test_a_walk_that_cannot_part_its_arms_fails_instead_of_falling(biped, gait, monkeypatch):
    """A fork refused by the system is an error of the run, never a fall of the walker."""
    from dmpopt_studies import branching
    from dmpopt_studies.biped import walker

    def refused():
        raise OSError("Resource temporarily unavailable")

    monkeypatch.setattr(branching.os, "fork", refused)
    qp = {"controller": "qp", "boom_pitch_stiffness": 0.0, "boom_pitch_damping": 0.0}
    with pytest.raises(walker.BranchFailed, match="could not fork the walk of arm 1"):
        walker.walk(
            biped, gait[1], 0.8, 12.0, arms=((True, True), (False, False)), warmup=0.3,
            log_every=10**9, **qp,
        )  # fmt: skip


def test_arms_of_a_walk_continue_as_separate_walks_to_the_bit(biped, gait):
    """``walk(arms=...)`` simulates the warm-up once and forks one continuation per arm: each
    arm's log is bitwise the log of a separate walk with that arm's switches (pushed, masses,
    slope, QP). Fails if a continuation starts from another state or with other switches."""
    from dmpopt_studies.biped import analysis
    from dmpopt_studies.biped.walker import Disturbance, walk

    _, dmp = gait
    options = {
        "biped": biped,
        "dmp": dmp,
        "duration": 1.1,
        "frequency": 12.0,
        "controller": "qp",
        "boom_pitch_stiffness": 0.0,
        "boom_pitch_damping": 0.0,
        "disturbance": Disturbance(
            push_impulse=1.0, push_time=0.7, mass_scale=(1.05,) * 5, slope_deg=1.0, slope_time=0.6
        ),
        "warmup": 0.5,
        "log_every": 5,
    }
    arms = tuple(analysis.ARMS.values())
    forked = walk(**options, arms=arms)
    assert len(forked) == len(arms)
    for (reset, adapt), log in zip(arms, forked):
        alone = walk(**options, reset_phase=reset, adapt=adapt)
        assert log.strikes == alone.strikes and log.frequencies == alone.frequencies
        assert log.times == alone.times and np.array_equal(log.q, alone.q)
        assert log.fell == alone.fell and log.positive_work == alone.positive_work
        assert log.impact_forces == alone.impact_forces and log.holds == alone.holds
    strikes = [t for t, _, _ in forked[0].strikes]
    assert any(t < 0.5 for t in strikes) and any(t > 0.5 for t in strikes)  # parts mid-walk
    assert forked[0].frequencies != forked[3].frequencies  # the arms did walk apart


def test_quick_study_opens_with_its_summary_and_captions_every_figure(quick_run):
    """Five rows with every column, their numbers formatted from the metrics; a caption for
    each figure written (the quick run writes no plant sweep and no video)."""
    from dmpopt_studies.report import COLUMNS

    folder, quick = quick_run
    figures = {path.stem for path in folder.glob("*.png")}
    assert figures == {
        "biped_frequency",
        "biped_controls",
        "biped_survival",
        "biped_joints",
        "biped_stick_figure",
    }
    assert figures <= set(quick["captions"])
    rows = quick["summary"]
    assert len(rows) == 5 and all(set(row) == set(COLUMNS) for row in rows)
    walk = quick["main_walk"]
    assert f"{walk['steps_walked']} steps in 3 s" in rows[0]["dmpopt"]
    assert rows[2]["dmpopt"] == quick["fig7"]["verdict"]
    on = quick["reset_robustness"]["phase_reset_ablation"]["adaptation_on"]
    assert f"McNemar p = {on['mcnemar_p']:.2g}" in rows[3]["dmpopt"]
    assert quick["fig7"]["verdict"] in quick["captions"]["biped_controls"]


@pytest.mark.parametrize(
    "steps, converged, verdict",
    [
        ({"5": 40, "12": 9}, {"5": 13.2, "12": 13.4}, "reproduced"),
        ({"5": 40, "12": 9}, {"5": 10.0, "12": 13.4}, "not reproduced: the starts settle apart"),
        (
            {"5": "at least 24", "12": 9},
            {"5": 7.8, "12": 13.4},
            "undecided: from 5 rad/s not settled within the walk",
        ),
    ],
)
def test_convergence_verdict_needs_every_start_settled_and_within_5_percent(
    steps, converged, verdict
):
    from dmpopt_studies.biped.summary import _convergence_row

    metrics = {"fig7": {"frequency_settled_by_start": converged}, "steps_to_2pct_by_start": steps}
    row = _convergence_row(metrics)
    assert row["verdict"] == verdict
    assert " / ".join(str(n) for n in steps.values()) in row["dmpopt"]


@pytest.mark.parametrize("factor", [0.8, 1.25, 2.0])
def test_scaled_legs_swing_as_a_pendulum_one_over_sqrt_factor(factor, tmp_path):
    """The straight leg is a compound pendulum about the hip, from the URDF's numbers: thigh
    1 kg at 0.13 m with 0.00939 kg m^2 about its centre, shank 0.5 kg at 0.43 m with
    0.0041 kg m^2; every length x f and every inertia x f^2 gives omega = sqrt(g S / J) with
    S = sum m d f and J = sum (I + m d^2) f^2, so omega(f) = omega(1) / sqrt(f). Masses stay."""
    path = biped_model.scaled_legs_urdf(factor, tmp_path / "legs.urdf")
    scaled = biped_model.load_biped(path)
    masses, levers, inertias = np.array([1.0, 0.5]), np.array([0.13, 0.43]), [0.00939, 0.0041]
    moment = (masses * levers).sum() * factor
    inertia = (np.array(inertias) + masses * levers**2).sum() * factor**2
    assert biped_model.swing_leg_natural_frequency(scaled) == pytest.approx(
        np.sqrt(GRAVITY * moment / inertia), rel=1e-6
    )
    assert biped_model.leg_length(scaled) == pytest.approx(0.6 * factor)
    assert scaled.mass == pytest.approx(7.0)


def test_scaled_legs_and_gravity_refuse_bad_values(tmp_path):
    from dmpopt.exceptions import InvalidInputError

    with pytest.raises(InvalidInputError, match="factor must be a positive"):
        biped_model.scaled_legs_urdf(0.0, tmp_path / "legs.urdf")
    with pytest.raises(InvalidInputError, match="gravity must be positive"):
        biped_model.load_biped(gravity=-9.81)


def test_passive_swing_leg_under_half_gravity_is_sqrt_2_slower():
    """A passive pendulum's omega = sqrt(m g d / I): half the gravity, omega / sqrt(2). The
    model's gravity is what the linearisation sees."""
    from dmpopt.frequency_adaptation import closed_loop_frequencies

    def passive(robot):
        q = biped_model.configuration(robot, 0.0, 0.6, 0.0, [0.0, 0.0, 0.0, 0.0])
        swing = robot.velocity_indices("gait")[:1]  # right hip, knee held straight
        return closed_loop_frequencies(robot.model, q, swing, lambda q, v: np.zeros(1))[0]

    full, half = biped_model.load_biped(), biped_model.load_biped(gravity=GRAVITY / 2)
    assert passive(half) == pytest.approx(passive(full) / np.sqrt(2), rel=1e-6)


def test_simulators_take_the_models_gravity_and_a_scaled_fall_height(tmp_path):
    """MuJoCo simulates the model's gravity; the fall height scales with the leg length."""
    from dmpopt_studies.biped.walker import FALL_HEIGHT, make_simulator

    path = biped_model.scaled_legs_urdf(1.5, tmp_path / "legs.urdf")
    robot = biped_model.load_biped(path, gravity=4.0)
    sim = make_simulator(robot, "mujoco", urdf=path)
    assert sim.mj_model.opt.gravity == pytest.approx([0.0, 0.0, -4.0])
    assert sim.fall_detector.min_height == pytest.approx(1.5 * FALL_HEIGHT)


def _settled_rows(values, fell=()):
    return {k: {"frequency_settled": v, "fell": k in fell} for k, v in values.items()}


def test_scaling_exponent_is_the_slope_of_a_power_law_over_walks_that_did_not_fall():
    from dmpopt_studies.biped.fig7 import scaling_exponent

    rows = _settled_rows({f: 7.0 * f**0.5 for f in (0.5, 0.75, 1.0)})
    assert scaling_exponent(rows) == pytest.approx(0.5, abs=1e-12)
    rows[2.0] = {"frequency_settled": 100.0, "fell": True}
    assert scaling_exponent(rows) == pytest.approx(0.5, abs=1e-12)
    assert scaling_exponent(_settled_rows({1.0: 7.0, 0.5: 3.0}, fell=(0.5,))) is None


@pytest.mark.parametrize(
    "gravity_exponent, leg_exponent, change, outcome",
    [
        (0.5, -0.5, 0.01, "locked to the legs' resonance"),
        (0.45, -0.6, 0.04, "locked to the legs' resonance"),
        (0.1, -0.1, 0.01, "a fixed point of the controller, not of the legs"),
        (0.5, -0.5, 0.15, "a fixed point of the controller, not of the legs"),
        (0.3, -0.5, 0.07, "undecided"),
    ],
)
def test_verdict_follows_the_scaling_exponents_and_the_largest_setting_change(
    gravity_exponent, leg_exponent, change, outcome
):
    """Resonance: g^(1/2), l^(-1/2) within 0.15 and settings within 5 %; controller: gravity
    exponent nearer 0 than 1/2 or a setting moving it over 10 %; otherwise undecided."""
    from dmpopt_studies.biped.fig7 import verdict

    base = 10.0
    gravity = _settled_rows({f: base * f**gravity_exponent for f in (0.5, 1.0)})
    legs = _settled_rows({f: base * f**leg_exponent for f in (0.8, 1.0)})
    settings = _settled_rows({"a": base * (1 + change), "b": base})
    starts = _settled_rows({5.0: base, 12.0: base * 1.01})
    result = verdict(starts, gravity, legs, settings, base)
    assert result["outcome"] == outcome
    assert result["gravity_exponent"] == pytest.approx(gravity_exponent, abs=1e-9)
    assert result["largest_relative_change"] == pytest.approx(change)
    assert result["sentence"].endswith(outcome)


def _wilson(x, n, z=1.959963984540054):
    """The Wilson score interval written out (Wilson 1927; Newcombe 1998, method 3)."""
    p = x / n
    centre, half = p + z * z / (2 * n), z * np.sqrt(p * (1 - p) / n + z * z / (4 * n * n))
    return ((centre - half) / (1 + z * z / n), (centre + half) / (1 + z * z / n))


@pytest.mark.parametrize(
    "with_reset, without, effect",
    [
        # 10/10 -> [0.72, 1]; 2/10 -> [0.06, 0.51]: apart, resetting above
        (10, 2, "raises survival"),
        (2, 10, "lowers survival"),
        # 8/10 -> [0.49, 0.94]; 4/10 -> [0.17, 0.69]: they overlap
        (8, 4, "not resolved"),
        (5, 5, "not resolved"),
    ],
)
def test_reset_verdict_reads_the_wilson_intervals(with_reset, without, effect):
    """Resetting's effect is called only where the two 95 % intervals do not overlap; an arm
    that does not walk undisturbed makes the whole comparison undecided."""
    from dmpopt_studies.biped.analysis import reset_ablation, reset_verdict

    def arm(survived, n=10):
        outcomes = [True] * survived + [False] * (n - survived)
        return {"outcomes": outcomes, "rate": survived / n, "ci95_wilson": _wilson(survived, n)}

    survival = {
        "reset_and_adapt": arm(with_reset),
        "adapt_only": arm(without),
        "reset_only": arm(with_reset),
        "neither": arm(without),
    }
    ablation = reset_ablation(survival)
    assert ablation["adaptation_on"]["effect"] == ablation["adaptation_off"]["effect"] == effect
    walking = dict.fromkeys(survival, True)
    assert reset_verdict(ablation, walking).startswith(effect + ":")
    walking["neither"] = False
    assert reset_verdict(ablation, walking).startswith("undecided: neither")


def test_trial_ranges_put_the_disturbances_after_the_warm_up():
    from dmpopt_studies.biped.analysis import TrialRanges

    from dmpopt.exceptions import InvalidInputError

    with pytest.raises(InvalidInputError, match="^push_time must be a range .* warmup = 3 s"):
        TrialRanges(warmup=3.0, push_time=(2.0, 4.0))
    with pytest.raises(InvalidInputError, match="^slope_time must be a range"):
        TrialRanges(warmup=1.0, push_time=(1.0, 2.0), slope_time=(0.5, 1.5))


def test_warm_up_resets_and_adapts_every_arm_until_it_ends(biped, gait, monkeypatch):
    """A real QP walk of the arm with neither resetting nor adaptation, warm-up 0.8 s: the
    phase is reset once per heel strike before 0.8 s and never after, and the frequency
    changes at strikes before it (eq. (21) with a step duration) and stays put after it."""
    from dmpopt_studies.biped import walker

    from dmpopt.stepper import Stepper

    calls = []
    reset_phase = Stepper.reset_phase

    def counted(self, phase):
        calls.append(phase)
        reset_phase(self, phase)

    monkeypatch.setattr(Stepper, "reset_phase", counted)
    _, dmp = gait
    qp = {"controller": "qp", "boom_pitch_stiffness": 0.0, "boom_pitch_damping": 0.0}
    log = walker.walk(
        biped, dmp, 1.6, 12.0, adapt=False, reset_phase=False, warmup=0.8, log_every=10**9, **qp
    )
    times = np.array([t for t, _, _ in log.strikes])
    before = int(np.sum(times < 0.8))
    assert 2 <= before < times.size  # strikes on both sides of the warm-up's end
    assert len(calls) == before
    # [start, after strike 2, after strike 3, ...]: the first strike has no step duration
    frequencies = np.array(log.frequencies)
    assert np.all(np.diff(frequencies[:before]) != 0.0)
    assert np.all(frequencies[before:] == frequencies[before - 1])


def test_gait_metrics_of_a_regular_walk():
    """Strikes every 0.5 s, 0.3 m apart, from t = 1 s: step/leg 0.3 / 0.6, cadence 2 / s x
    sqrt(l / g), Froude (0.6 m/s)^2 / (g l); impact as recorded, double support over the time
    from the first strike (6 s of the 7 s walk)."""
    from dmpopt_studies.biped.analysis import gait_metrics
    from dmpopt_studies.biped.walker import WalkLog

    log = WalkLog()
    log.strikes = [(1.0 + 0.5 * k, k % 2, 0.3 * k) for k in range(12)]
    log.impact_forces = [2.0 * 7.0 * GRAVITY] * 12
    log.duration, log.double_support_time, log.contact_losses = 7.0, 0.6, 3
    walk = gait_metrics(log, 0.6, 7.0, GRAVITY)["walker"]
    assert walk["step_length_per_leg_length"] == pytest.approx(0.5)
    assert walk["cadence_froude_normalised"] == pytest.approx(2.0 * np.sqrt(0.6 / GRAVITY))
    assert walk["froude_number"] == pytest.approx(0.36 / (GRAVITY * 0.6))
    assert walk["impact_force_per_body_weight"] == pytest.approx(2.0)
    assert walk["double_support_fraction"] == pytest.approx(0.1)
    assert walk["stance_contact_losses_per_step"] == pytest.approx(0.25)


def test_verdict_needs_the_frequency_near_a_physical_resonance_estimate():
    """Scaling and insensitivity of a resonance but 2.5x the nearest estimate: not at the
    legs' resonance; within 10 % of one: locked. Fallen control walks are listed."""
    from dmpopt_studies.biped.fig7 import verdict

    base = 10.0
    gravity = _settled_rows({0.5: base * 0.5**0.5, 1.0: base, 0.25: 1.0}, fell=(0.25,))
    legs = _settled_rows({f: base * f**-0.5 for f in (0.8, 1.0)})
    settings = _settled_rows({"a": base * 1.01})
    starts = _settled_rows({5.0: base})
    far = verdict(starts, gravity, legs, settings, base, {"leg": 4.0, "cost": None})
    assert far["outcome"] == "not at the legs' resonance, nor clearly locked to the controller"
    assert far["ratio_to_nearest_physical_estimate"] == pytest.approx(2.5)
    assert "2.5x the leg (4.0)" in far["sentence"]
    assert far["control_walks_fell"] == ["gravity x0.25"]
    near = verdict(starts, gravity, legs, settings, base, {"leg": 9.5, "cost": 20.0})
    assert near["outcome"] == "locked to the legs' resonance"
    assert near["nearest_physical_estimate"] == "leg"


def test_pd_gains_give_each_leg_joint_the_stated_closed_loop_frequency(biped):
    """K_p = I w^2 and K_d = 2 zeta I w, with the joints' inertias from the URDF by the
    parallel-axis theorem (robots/biped.urdf: thigh 1 kg, shank 0.5 kg, 0.30 m each, centres
    0.13 m below the proximal joint, radii of gyration 0.323 and 0.302 of the length)."""
    from dmpopt_studies.biped.fig7 import pd_gains_from_inertia

    thigh = 1.0 * ((0.323 * 0.3) ** 2 + 0.13**2)
    shank_about_knee = 0.5 * ((0.302 * 0.3) ** 2 + 0.13**2)
    shank_about_hip = 0.5 * ((0.302 * 0.3) ** 2 + (0.3 + 0.13) ** 2)
    hip, knee = thigh + shank_about_hip, shank_about_knee
    gains = pd_gains_from_inertia(biped, 60.0, 0.7)
    assert np.sqrt(gains.hip_stiffness / hip) == pytest.approx(60.0, rel=1e-3)  # URDF 3 digits
    assert np.sqrt(gains.knee_stiffness / knee) == pytest.approx(60.0, rel=1e-3)
    assert gains.hip_damping / (2 * np.sqrt(gains.hip_stiffness * hip)) == pytest.approx(
        0.7, rel=1e-3
    )


def test_demonstration_from_a_walk_is_its_mean_cycle():
    """A hand-made walk whose joints move as sines of period 0.5 s, right heel strikes every
    0.5 s: the demonstration's period is 0.5 s and its angles are the sines at the phase
    (linear interpolation of 1 ms samples: error <= dt^2 w^2 a / 8, far below 1e-4 rad);
    pitch and speed are the log's at the last right heel strike."""
    from dmpopt_studies.biped.gait import demonstration_from_walk
    from dmpopt_studies.biped.walker import WalkLog

    from dmpopt.exceptions import InvalidInputError

    period, omega = 0.5, 2 * np.pi / 0.5
    amplitude, offset = np.array([0.4, 0.5, 0.3, 0.2]), np.array([0.0, 1.0, np.pi, 2.0])
    times = np.arange(0.0, 3.0, 1e-3)
    q = np.zeros((times.size, 7))
    q[:, 0], q[:, 2] = 0.7 * times, 0.2
    gait_index = np.array([3, 4, 5, 6])
    q[:, gait_index] = amplitude * np.sin(omega * times[:, None] + offset)
    strikes = [(k * period / 2, k % 2, 0.0) for k in range(1, 12)]
    log = WalkLog(times=list(times), q=list(q), strikes=strikes)
    demonstration, found, start = demonstration_from_walk(log, gait_index, after=0.9)
    assert found == pytest.approx(period)
    phase = omega * np.asarray(demonstration.times)
    expected = amplitude * np.sin(phase[:, None] + offset)
    assert np.asarray(demonstration.positions) == pytest.approx(expected, abs=1e-4)
    assert start["pitch"] == pytest.approx(0.2) and start["speed"] == pytest.approx(0.7)
    assert start["cycles"] == 3  # right strikes at 1.0, 1.5, 2.0, 2.5 s
    with pytest.raises(InvalidInputError, match="^log has 1 right heel strikes at or after"):
        demonstration_from_walk(log, gait_index, after=2.4)


def test_pd_demonstration_runs_the_claim_test_only_from_enough_starts():
    from dmpopt_studies.biped.fig7 import CLAIM_STARTS, pd_demonstration_summary
    from dmpopt_studies.biped.walker import Gains

    def row(fell):
        return {"fell": fell, "frequency_settled": 10.0}

    start = {"pitch": 0.2, "speed": 0.9, "cycles": 5}
    few = {float(s): row(s > CLAIM_STARTS - 2) for s in range(CLAIM_STARTS + 2)}
    summary = pd_demonstration_summary(few, Gains(), start, 0.5)
    assert summary["walked_from"] == [float(s) for s in range(CLAIM_STARTS - 1)]
    assert summary["claim_test_runs_on_it"] is False
    assert summary["demonstration"]["frequency_rad_s"] == pytest.approx(4 * np.pi)
    enough = {float(s): row(False) for s in range(CLAIM_STARTS)}
    assert pd_demonstration_summary(enough, Gains(), start, 0.5)["claim_test_runs_on_it"]
