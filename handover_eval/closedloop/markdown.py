"""closed_loop.md: the closed-loop tables rendered as Markdown, with the notes that say what each
number measures (the aggregates and paired rows come from :mod:`.report`)."""

from __future__ import annotations

import math

from handover_eval.closedloop.report import EFFORT, OUTCOMES, QUANTITIES
from handover_eval.reporting import markdown_table
from handover_eval.roster import label

NOTE_SIMULATED = (
    "These results come from the **simulated person** (an articulated, compliant body whose "
    "reaching and grasping are calibrated to the recorded human-human handovers), not from people."
)
NOTE_SETS = (
    "Receiver sets, never pooled across ID and OOD: `walker-id` / `walker-ood` are the scripted "
    "walkers, `replay-id` / `replay-ood` the replayed recordings split by `is_ood`, and "
    "`replay-all` every replay (each replay also counts in its ID or OOD set). The per-episode "
    "CSV has the raw `set` (id, ood, replay) and `is_ood`."
)
NOTE_TIME = (
    "Handover time is the paper's (Sec. V-C): from when the receiver leaves the start point to the "
    "gripper release, successes only; the static baseline's 2 s stabilisation delay is excluded "
    "(`handover_time_with_delay` in the CSV includes it). Scripted walkers start at rest. "
    "Recordings start mid-walk, so on replays it runs from the start of the recording (the "
    "receiver is already moving: departure = 0) to the release. Grasp to release: the shared "
    "hold, from the person's grasp to the gripper opening (in the recordings the giver lets go "
    "about 1.0 s after the transfer, median; see docs/calibration)."
)


def _f(v: float, digits: int) -> str:
    return "–" if v is None or not math.isfinite(v) else f"{v:.{digits}f}"


def med_iqr(row: dict, col: str, digits: int) -> str:
    """'1.23 [1.01, 1.50]' from an aggregate row, '–' when undefined."""
    m = row.get(f"{col}_median", math.nan)
    if not math.isfinite(m):
        return "–"
    return f"{_f(m, digits)} [{_f(row[f'{col}_q25'], digits)}, {_f(row[f'{col}_q75'], digits)}]"


def success_cell(row: dict) -> str:
    """'95 % [88, 98]': the success rate of an aggregate row with its Wilson CI."""
    return (
        f"{100 * row['success_rate']:.0f} % "
        f"[{100 * row['success_low']:.0f}, {100 * row['success_high']:.0f}]"
    )


def outcomes_cell(row: dict) -> str:
    short = {"premature_release": "premature", "unsafe_force": "unsafe"}
    parts = [f"{short.get(o, o)} {row[f'n_{o}']}" for o in OUTCOMES[1:] if row[f"n_{o}"]]
    return ", ".join(parts) or "–"


def _diff_cell(d: dict, digits: int) -> str:
    if not d["n_pairs"]:
        return "–"
    star = " *" if d["ci_excludes_zero"] else ""
    return (
        f"{d['diff']:+.{digits}f} [{d['diff_low']:+.{digits}f}, {d['diff_high']:+.{digits}f}]{star}"
    )


def markdown(
    agg: list[dict], pairs: list[dict], ghost: list[dict], header: str, footer: str = "",
    reference: str = "reactive",
) -> str:
    """The whole closed_loop.md (``pairs`` against the agent ``reference``)."""

    def lab(r: dict) -> str:
        return label(r["agent"])

    t1 = markdown_table(
        [
            "agent",
            "set",
            "n",
            "success [95 % CI]",
            "other outcomes",
            "handover time (s)",
            "grasp to release (s)",
            "grasp pelvis x (m)",
            "release force (N)",
            "peak body contact (N)",
            "max penetration (mm)",
        ],
        [
            [
                lab(r),
                r["set"],
                r["n"],
                success_cell(r),
                outcomes_cell(r),
                med_iqr(r, "handover_time", 2),
                med_iqr(r, "hold_time", 3),
                med_iqr(r, "transfer_pelvis_x", 2),
                med_iqr(r, "release_force", 1),
                med_iqr(r, "body_contact_force", 1),
                _f(1000 * r["penetration_max"], 1),
            ]
            for r in agg
        ],
    )
    t2 = markdown_table(
        [
            "agent",
            "set",
            "reach (m)",
            "arm extended (s)",
            "time lost (s)",
            "slowest speed",
            "path dev. (m)",
            "pull (N)",
            "jerk RMS (m/s³)",
        ],
        [
            [
                lab(r),
                r["set"],
                *(med_iqr(r, c, QUANTITIES[c][2]) for c in EFFORT),
                med_iqr(r, "robot_jerk_rms", 0),
            ]
            for r in agg
        ],
    )
    text = (
        header + "\n" + NOTE_SIMULATED + "\n\n" + NOTE_SETS
        + "\n\n## Success, outcomes, timing and forces\n\n" + t1
    )
    text += (
        "\nMedian [25 %, 75 %]. "
        + NOTE_TIME
        + "\n\n## Receiver effort and robot smoothness\n\n"
        + t2
    )
    text += (
        "\nAll episodes (a failed handover's effort counts too). Reach: the right shoulder to the "
        "object's centre when the person took it (0 without a grasp), as the recordings' "
        "`object_shoulder_transfer`; arm extended: time with the arm out before the release; "
        "time lost: walking time lost to slowing down; slowest speed: the lowest walking-speed "
        "factor (1 = never slowed); path deviation: how far contact pushed the pelvis off its "
        "path; pull: the largest pull while both held the object; jerk: the robot TCP's jerk "
        "at 30 Hz.\n"
    )
    reps = [r for r in agg if r["set"].startswith("replay") and r.get("n_delta")]
    if reps:
        text += "\n## Simulated vs recorded transfer (replays)\n\n" + markdown_table(
            [
                "agent",
                "set",
                "recordings with a detected transfer",
                "median |Δt| (s)",
                "median |Δx| (m)",
                "median Δt (s)",
                "median Δx (m)",
            ],
            [
                [
                    lab(r),
                    r["set"],
                    r["n_delta"],
                    med_iqr(r, "abs_delta_t", 2),
                    med_iqr(r, "abs_delta_x", 2),
                    _f(r["delta_t_median"], 2),
                    _f(r["delta_x_median"], 2),
                ]
                for r in reps
            ],
        )
        text += (
            "\nΔt = simulated grasp time - recorded transfer time (both from the start of the "
            "recording); Δx = simulated - recorded pelvis x at the grasp. The giver-replay agent "
            "moves the object along the recorded giver's path, so its Δ says whether the "
            "simulated person takes the object when and where the recorded one did.\n"
        )
    if pairs:
        cols = ["success", "handover_time", *EFFORT, "body_contact", "robot_jerk_rms"]
        digits = {
            "success": 2,
            "body_contact": 2,
            "handover_time": 2,
            "pull_force": 1,
            "body_contact_force": 1,
            "robot_jerk_rms": 0,
            "path_deviation": 3,
        }
        by = {(d["agent"], d["set"], d["metric"]): d for d in pairs}
        keys = list(dict.fromkeys((d["agent"], d["set"]) for d in pairs))
        ref = "the reactive agent" if reference == "reactive" else label(reference)
        text += (f"\n## Paired against {ref} (agent - {reference}, same receivers)\n\n")
        text += markdown_table(
            ["agent", "set", "n", *[c.replace("_", " ") for c in cols]],
            [
                [
                    label(a),
                    s,
                    by[(a, s, "success")]["n_pairs"],
                    *(_diff_cell(by[(a, s, c)], digits.get(c, 2)) for c in cols),
                ]
                for a, s in keys
            ],
        )
        text += (
            "\nSuccess and body contact: difference in the share of episodes (successful; with "
            "any robot-body contact); the others: median paired difference (handover time over "
            "the receivers both handed over to); [95 % bootstrap CI over receivers]; * = the CI "
            "excludes 0. `closed_loop_paired.csv` has n per metric, the contact force, and the "
            "mean paired differences with their CIs (more sensitive for zero-inflated measures "
            "such as time lost).\n"
        )
    text += "\n## No ghosts\n\n" + markdown_table(
        [
            "agent",
            "set",
            "episodes",
            "max penetration (mm)",
            "> 1 cm",
            "successes released before the grasp",
            "with body contact",
            "MuJoCo instabilities (of them successes)",
            "body contact q50/q90/q99/max (N)",
            "peak contact q50/q90/q99/max (N)",
        ],
        [
            [
                label(g["agent"]),
                g["set"],
                g["n"],
                _f(1000 * g["max_penetration_m"], 1),
                g["episodes_penetration_over_1cm"],
                g["successes_release_before_grasp"],
                g["episodes_with_body_contact"],
                f"{g['episodes_sim_unstable']} ({g['successes_sim_unstable']})",
                "/".join(_f(g[f"body_contact_force_{q}"], 0) for q in ("q50", "q90", "q99", "max")),
                "/".join(_f(g[f"peak_contact_force_{q}"], 0) for q in ("q50", "q90", "q99", "max")),
            ]
            for g in ghost
        ],
    )
    return (
        text
        + (
            "\nMuJoCo instabilities: episodes in which MuJoCo found the simulation unstable (bad "
            "qpos/qvel/qacc) and reset its state mid-episode; their outcome cannot be trusted.\n"
        )
        + "\n"
        + footer
    )
