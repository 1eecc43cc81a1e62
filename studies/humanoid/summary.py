"""The study's opening table and figure captions, formatted from the metrics of the run."""

from __future__ import annotations


def _seconds(value) -> str:
    return "did not settle" if value is None else f"{value:.3f} s"


def _row(claim: str, paper: str, dmpopt: str, anchor: str, verdict: str) -> dict:
    return {"claim": claim, "paper": paper, "dmpopt": dmpopt, "anchor": anchor, "verdict": verdict}


def _fig4_rows(metrics: dict) -> list[dict]:
    fig4, shift = metrics["fig4"], metrics["setpoint_shift_rad"]
    labels = {
        "amplitude": "A -> 2A",
        "frequency": "tau -> tau/2",
        "setpoint": f"g -> g + {shift:g} rad",
    }
    rows = []
    for name, label in labels.items():
        change = fig4[name]
        robot, plan = change["robot"]["onset_s"], change["plan"]["onset_s"]
        measured = (
            f"robot {_seconds(robot)}, DMP alone {_seconds(plan)} to within 5 % of the new "
            f"cycle (a step change, no filter); fell: {change['fell']}"
        )
        if name == "frequency":
            measured += f"; oscillator at 2x in {_seconds(change['frequency_settle_s'])}"
        filtered = _seconds(change["plan_filtered"]["onset_s"])
        anchor = f"the DMP alone with a 0.1 s filter on the change: {filtered}"
        verdict = "reproduced" if robot is not None and not change["fell"] else "fails"
        if name == "setpoint" and robot is not None:
            bound = metrics["setpoint_velocity_bound_s"]
            measured += f"; the elbow's velocity limit allows no less than {bound:.3f} s"
            if verdict == "reproduced" and robot > bound:
                verdict = "reproduced by the DMP; the robot is held back by the elbow's speed limit"
        rows.append(
            _row(
                f"Fig. 4: {label} on the right elbow converges quickly to the new limit cycle",
                "converges quickly (a plot, no number)"
                + ("; g + 1 in the paper's units (none printed)" if name == "setpoint" else ""),
                measured,
                anchor,
                verdict,
            )
        )
    return rows


def summary_rows(metrics: dict) -> list[dict]:
    """Rows of "claim | paper | dmpopt (measured) | best anchor | verdict"."""
    native = metrics["native"]
    rows = [
        _row(
            "Rhythmic DMPs learned by imitation drum on a humanoid through inverse dynamics",
            "bimanual drumming on the 30-DOF DB humanoid, 6 DOF per arm, one canonical system "
            "(no tracking number)",
            f"Talos standing in {metrics['backend']}: joint tracking RMS "
            f"{1e3 * metrics['tracking_rms_rad']:.3f} mrad, max "
            f"{1e3 * metrics['tracking_max_rad']:.3f} mrad; fit to the demonstration "
            f"{1e3 * metrics['dmp_fit_error_rad']:.2f} mrad; fell: {metrics['fell']}",
            f"the same loop on the native simulator: {1e3 * native['tracking_rms_rad']:.3f} mrad "
            f"RMS, fell: {native['fell']}",
            "reproduced" if not metrics["fell"] else "fails: the robot fell",
        ),
        *_fig4_rows(metrics),
    ]
    swing = metrics["discrete_swing"]
    moved = swing["new_goal"]
    rows.append(
        _row(
            "A discrete movement (tennis-like forehand) learned from a demonstration",
            "a tennis swing learned by imitation (no tracking number)",
            f"one 6-DOF discrete DMP ({swing['n_basis']} bases, library defaults) on standing "
            f"Talos: joint tracking RMS {1e3 * swing['joint_tracking_rms_rad']:.2f} mrad (max "
            f"{1e3 * swing['joint_tracking_max_rad']:.2f}); hand path "
            f"{swing['hand_path_rms_mm']:.1f} mm RMS in the world, "
            f"{swing['hand_path_in_pelvis_frame_rms_mm']:.1f} mm in the pelvis frame; peak "
            f"hand speed {swing['peak_hand_speed_m_s']:.2f} m/s (plan "
            f"{swing['peak_hand_speed_plan_m_s']:.2f}); CoM moves "
            f"{swing['com_displacement_max_mm']:.2f} mm; fell: {swing['fell']}",
            "none measured",
            "beyond the paper (executed standing, in simulation)"
            if not swing["fell"]
            else "fails: the robot fell",
        )
    )
    rows.append(
        _row(
            "The same swing to a new goal (a higher follow-through)",
            "not in the paper",
            f"finish {moved['finish_raise_plan_mm']:.0f} mm higher in the plan, "
            f"{moved['finish_raise_executed_mm']:.0f} mm executed; hand path "
            f"{moved['hand_path_rms_mm']:.1f} mm RMS; the contact point moves "
            f"{moved['contact_height_change_mm']:+.0f} mm in height; fell: {moved['fell']}",
            "none measured",
            "beyond the paper",
        )
    )
    rows.append(
        _row(
            "Figure-8 by a task-space rhythmic DMP",
            "figure-8 learned by imitation (no number)",
            f"right hand of standing Talos {metrics['figure8_rms_mm']:.2f} mm RMS, max "
            f"{metrics['figure8_max_mm']:.2f} mm",
            "none measured",
            "reproduced",
        )
    )
    rows.append(
        _row(
            "Real-time control: DMP plan to torques at 1 kHz",
            "real time on the humanoid",
            f"QP tick {metrics['tick_us_median']:.0f} us median, "
            f"{metrics['tick_us_p99']:.0f} us p99 (CPU, nv = 50, two contacts); whole loop "
            f"{metrics['real_time_factor_cpu']:.2f}x real time (CPU)",
            "TSID on the same loop: benchmarks/bench_controller.py (README)",
            "reproduced" if metrics["tick_us_p99"] < 1000 else "trails the paper: over 1 ms",
        )
    )
    if "mujoco" in metrics:
        mujoco = metrics["mujoco"]
        fell_at = mujoco["push_fell_ns"]
        rows.append(
            _row(
                "Drumming survives forward pushes on the pelvis",
                "not in the paper",
                f"survives {mujoco['push_survived_ns']:g} N s"
                + (
                    f", falls at {fell_at:g} N s"
                    if fell_at is not None
                    else " (no fall tried: a lower bound)"
                ),
                "none measured",
                "beyond the paper",
            )
        )
    if "plant" in metrics:
        plant = metrics["plant"]
        rigid = plant["design_ablation"]["rigid_model"]["tracking_rms_rad"]
        realistic = plant["realistic"]["tracking_rms_rad"]
        rows.append(
            _row(
                "Drumming tracks on a plant that is not the controller's model (armature, "
                "friction, damping, delay, noise)",
                "not in the paper",
                f"{1e3 * realistic:.2f} mrad RMS (ideal plant "
                f"{1e3 * plant['ideal']['tracking_rms_rad']:.2f}); the rigid-body controller on "
                f"the same plant {1e3 * rigid:.1f} mrad",
                "issue target: at most 2 mrad",
                "beyond the paper" if realistic <= 2e-3 else "fails the 2 mrad target",
            )
        )
    if "walk" in metrics:
        walk = metrics["walk"]
        rows.append(
            _row(
                "Talos walks on a LIPM/DCM plan with DMP swing feet",
                "not in the paper (its biped is planar)",
                f"{walk['steps_taken']} of {walk['steps_planned']} steps, "
                f"{walk['distance_m']:.3f} m, fell: {walk['fell']}",
                "none measured",
                "beyond the paper" if not walk["fell"] else "fails: the robot fell",
            )
        )
    return rows


def captions(metrics: dict) -> dict:
    """What the reader should see in each figure (file stem -> one or two sentences)."""
    shift = metrics["setpoint_shift_rad"]
    swing = metrics["discrete_swing"]
    return {
        "fig4_elbow": "Fig. 4 right on standing Talos: the right elbow's DMP plan (blue) and the "
        "simulated joint (red) against the unmodified pattern (grey dashes); in the shaded "
        f"window A doubles, tau halves or g moves by {shift:g} rad as steps. The robot "
        "follows A and tau within milliseconds; the setpoint step is limited by the elbow's "
        "velocity limit.",
        "drumming_tracking": "The 12 drumming joints of standing Talos over 3 s: plan (blue) "
        "and simulated joint (red dashes) overlap; the RMS error of each joint is in its "
        "title.",
        "demonstration": "The synthetic drumming demonstration: the task-space stroke of each "
        "wrist (left) and the right arm's six joint angles that inverse kinematics gives "
        "(right).",
        "figure8": "The right hand's figure-8 in the frontal plane: task-space DMP plan and "
        f"simulated hand ({metrics['figure8_rms_mm']:.2f} mm RMS apart).",
        "base_com": "Pelvis orientation and CoM while drumming: with the pelvis task the "
        "pelvis holds within a fraction of a degree; without it (dotted) it rolls.",
        "tick_times": "The controller's CPU time per 1 kHz tick, fixed-base upper body and "
        "standing robot; the black line is the 1 ms budget.",
        "swing": "The forehand: hand path from above and from behind, and the joints over "
        "time, for the demonstrated goal and a follow-through "
        f"{swing['new_goal']['finish_raise_plan_mm']:.0f} mm higher; dots mark the contact "
        "point (peak hand speed). Plan and executed paths differ by the body's balance motion "
        f"({swing['hand_path_rms_mm']:.1f} mm RMS; "
        f"{swing['hand_path_in_pelvis_frame_rms_mm']:.1f} mm in the pelvis frame).",
        "swing_keyframes": "Five frames of the executed forehand (MuJoCo).",
        "talos_walk": "The walk from above and over time: planned and measured CoM and DCM, "
        "the footholds, and the sole heights (grey: single support).",
        "talos_walk_keyframes": "Five frames of the walk (MuJoCo).",
    }
