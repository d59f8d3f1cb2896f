"""The shared receiver motion model: sampling, walking, shoulder and hand."""

from __future__ import annotations

import dataclasses
import math
from pathlib import Path

import numpy as np
import pytest

from handover_env.person import motion as rm
from handover_env.person import trajectory


def _speeds(traj: trajectory.BaseTrajectory) -> np.ndarray:
    return np.linalg.norm(np.diff(traj.xy, axis=0), axis=1) / np.diff(traj.t)


def test_sample_walker_is_seeded() -> None:
    a = rm.sample_walker(np.random.default_rng(3), "ood")
    b = rm.sample_walker(np.random.default_rng(3), "ood")
    c = rm.sample_walker(np.random.default_rng(4), "ood")
    assert a == b
    assert a != c


def test_overrides_fix_fields_and_leave_the_rest() -> None:
    free = rm.sample_walker(np.random.default_rng(7), "id")
    fixed = rm.sample_walker(np.random.default_rng(7), "id", height=1.8, speed=1.0)
    assert fixed.height == 1.8 and fixed.speed == 1.0
    assert fixed.start_xy == free.start_xy and fixed.pass_y == free.pass_y
    assert dataclasses.replace(fixed, height=free.height, speed=free.speed) == free
    pause = rm.sample_walker(np.random.default_rng(7), "ood", ood_mode="pause")
    assert pause.ood_mode == "pause" and pause.is_ood


@pytest.mark.parametrize(
    "kwargs, match",
    [
        ({"speed": 0.0}, "speed"),
        ({"speed": float("nan")}, "finite"),
        ({"ood_mode": "pause"}, "ood_mode"),
        ({"kind": "ood"}, "ood_mode"),
        ({"kind": "walk"}, "kind"),
        ({"height": 3.0}, "height"),
        ({"start_xy": (-1.0, 0.0)}, "end_x"),
    ],
)
def test_walker_params_validation(kwargs: dict, match: str) -> None:
    base = {"kind": "id", "start_xy": (2.0, -0.5), "speed": 0.8, "pass_y": -0.9}
    base.update(kwargs)
    with pytest.raises(ValueError, match=match):
        rm.WalkerParams(**base)


def test_sample_walker_rejects_unknown_names() -> None:
    with pytest.raises(ValueError, match="unknown WalkerParams"):
        rm.sample_walker(np.random.default_rng(0), "id", velocity=1.0)
    with pytest.raises(ValueError, match="kind"):
        rm.sample_walker(np.random.default_rng(0), "crawl")


def test_sampled_distributions_match_calibration() -> None:
    rng = np.random.default_rng(0)
    walkers = [rm.sample_walker(rng, "id") for _ in range(400)]
    start = np.array([w.start_xy for w in walkers])
    speed = np.array([w.speed for w in walkers])
    # Public data (statistics): start x 0.73..3.13, y -1.86..0.17; speed median 0.83 in 0.57..1.13.
    assert 0.7 < start[:, 0].min() and start[:, 0].max() < 3.2
    assert -1.95 < start[:, 1].min() and start[:, 1].max() < 0.25
    assert abs(np.median(speed) - 0.83) < 0.04 and speed.min() >= 0.57 and speed.max() <= 1.13
    assert (
        np.corrcoef(start[:, 0], start[:, 1])[0, 1] > 0.3
    )  # the data's start x and y correlate (0.71)
    ood = [rm.sample_walker(rng, "ood").ood_mode for _ in range(200)]
    assert 60 < ood.count("pause") < 140 and ood.count("wander") == 200 - ood.count("pause")


def test_base_trajectory_walks_from_start_to_end_at_speed() -> None:
    rng = np.random.default_rng(1)
    for _ in range(30):
        p = rm.sample_walker(rng, "id")
        tr = trajectory.base_trajectory(p, rate_hz=30.0)
        assert np.allclose(np.diff(tr.t), 1 / 30)
        assert np.linalg.norm(tr.xy[0] - p.start_xy) < 0.03  # only the gait sway
        assert tr.xy[-1, 0] <= p.end_x + 0.03 and tr.xy[-2, 0] > p.end_x - 0.03
        assert abs(tr.xy[-1, 1] - p.pass_y) < 0.03
        assert abs(np.median(_speeds(tr)) / p.speed - 1.0) < 0.12
        assert np.all(np.abs(np.diff(tr.heading)) < 0.08)  # smooth yaw, < 2.4 rad/s
        assert np.all(np.abs(tr.heading - math.pi) < math.pi / 2)  # toward -x
        assert (
            60 <= len(tr) <= 300
        )  # about the data's 69 .. 287 frames (the generator redraws outliers)


def test_base_trajectory_is_deterministic_and_rate_aware() -> None:
    p = rm.sample_walker(np.random.default_rng(2), "ood", ood_mode="wander")
    a, b = trajectory.base_trajectory(p), trajectory.base_trajectory(p)
    assert np.array_equal(a.xy, b.xy) and np.array_equal(a.heading, b.heading)
    fast = trajectory.base_trajectory(p, rate_hz=60.0)
    assert abs(fast.t[-1] - a.t[-1]) < 0.05
    with pytest.raises(ValueError, match="rate_hz must be positive and finite"):
        trajectory.base_trajectory(p, rate_hz=0.0)


def test_ood_pause_stops_and_restarts() -> None:
    p = rm.sample_walker(
        np.random.default_rng(5), "ood", ood_mode="pause", pause_time=1.0, pause_duration=1.5
    )
    tr = trajectory.base_trajectory(p)
    v = _speeds(tr)
    still = v < 0.02
    assert still.sum() * (1 / 30) > 1.2  # stood for about pause_duration
    first = int(np.argmax(still))
    assert (
        1.0 < tr.t[first] < 2.2 and v[-10:-1].min() > 0.5 * p.speed
    )  # walking again at the end (last step is partial)
    id_twin = dataclasses.replace(p, kind="id", ood_mode=None)
    assert len(tr) > len(trajectory.base_trajectory(id_twin)) + 30


def test_ood_wander_deviates_laterally_then_rejoins() -> None:
    p = rm.sample_walker(np.random.default_rng(6), "ood", ood_mode="wander", wander_amplitude=0.4)
    twin = dataclasses.replace(p, kind="id", ood_mode=None)
    wander, straight = trajectory.base_trajectory(p), trajectory.base_trajectory(twin)
    grid = np.linspace(p.start_xy[0] - 0.2, 0.0, 50)
    y_w = np.interp(grid, wander.xy[::-1, 0], wander.xy[::-1, 1])
    y_s = np.interp(grid, straight.xy[::-1, 0], straight.xy[::-1, 1])
    assert np.abs(y_w - y_s).max() > 0.2
    assert abs(wander.xy[-1, 1] - straight.xy[-1, 1]) < 0.05


def test_shoulder_and_rest_hand_are_on_the_right_at_body_heights() -> None:
    xy = np.array([[1.0, -0.9], [0.0, -0.9]])
    heading = np.array([math.pi, math.pi])
    sh = trajectory.shoulder_position(xy, heading, 1.72)
    hand = trajectory.hand_position(xy, heading, 1.72, swing_phase=0.0)
    assert sh.shape == (2, 3) and hand.shape == (2, 3)
    assert np.allclose(sh[:, 2], rm.SHOULDER_HEIGHT_RATIO * 1.72)
    assert np.all(sh[:, 1] > xy[:, 1]) and np.all(hand[:, 1] > sh[:, 1])  # right side faces +y
    assert np.allclose(hand[:, 2], rm.HAND_REST_HEIGHT_RATIO * 1.72)
    assert np.all(np.linalg.norm(hand - sh, axis=1) <= trajectory.arm_reach(1.72))
    tall = trajectory.hand_position(xy, heading, 1.9, swing_phase=0.0)
    assert np.all(tall[:, 2] > hand[:, 2])


def test_hand_swings_while_walking() -> None:
    p = rm.sample_walker(np.random.default_rng(8), "id")
    tr = trajectory.base_trajectory(p)
    hand = trajectory.hand_position(tr.xy, tr.heading, p.height, swing_phase=tr.gait_phase)
    default = trajectory.hand_position(tr.xy, tr.heading, p.height)
    fwd = np.stack([np.cos(tr.heading), np.sin(tr.heading)], -1)
    along = np.sum((hand[:, :2] - tr.xy) * fwd, axis=1)
    assert np.ptp(along) > 0.15 and np.ptp(np.sum((default[:, :2] - tr.xy) * fwd, axis=1)) > 0.15


def test_reach_moves_toward_target_and_is_clipped_to_arm_length() -> None:
    xy, yaw, h = np.array([0.0, -0.9]), math.pi, 1.72
    sh = trajectory.shoulder_position(xy, yaw, h)
    near = sh + np.array([0.0, 0.4, -0.2])  # within reach
    assert np.allclose(trajectory.hand_position(xy, yaw, h, target_xyz=near, reach=1.0), near)
    rest = trajectory.hand_position(xy, yaw, h, target_xyz=near, reach=0.0, swing_phase=0.0)
    half = trajectory.hand_position(xy, yaw, h, target_xyz=near, reach=0.5, swing_phase=0.0)
    assert np.allclose(half, 0.5 * (rest + near))
    far = sh + np.array([0.0, 2.0, 0.0])
    got = trajectory.hand_position(xy, yaw, h, target_xyz=far, reach=1.0)
    assert np.isclose(np.linalg.norm(got - sh), trajectory.arm_reach(h))
    assert np.allclose((got - sh) / np.linalg.norm(got - sh), [0.0, 1.0, 0.0])
    # vectorised over a batch of reach fractions
    batch = trajectory.hand_position(
        np.tile(xy, (5, 1)), np.full(5, yaw), h, target_xyz=near, reach=np.linspace(0, 1, 5)
    )
    assert batch.shape == (5, 3) and np.allclose(batch[-1], near)
    with pytest.raises(ValueError, match="target"):
        trajectory.hand_position(xy, yaw, h, reach=0.5)


# ---------------------------------------------------------------- issue 23: calibrated OOD walkers
DATA = Path(__file__).resolve().parents[2] / "../shared/data/dynamic_handover_dataset/whole_motions"


def test_id_walkers_are_unchanged_by_the_ood_calibration(monkeypatch) -> None:
    # Pinned from the sampler before the OOD calibration (same seed, same fields, same draws).
    w = rm.sample_walker(np.random.default_rng(7), "id")
    assert w.start_xy == (2.4351281765614017, -0.8755787359151858)
    assert (w.speed, w.pass_y) == (0.7465368361542711, -0.8708397770542492)
    assert (w.start_turn, w.wander_amplitude) == (-0.5224211146622331, 0.302331670890105)
    assert w.pause_duration == 0.9555425286071777
    # The OOD tables do not reach an ID walker, and both kinds draw as many numbers (so the env's
    # later draws, e.g. camera noise, stay where they were).
    monkeypatch.setitem(rm.OOD_RANGES, "wander", {"wander_amplitude": (1.0, 1.0)})
    assert rm.sample_walker(np.random.default_rng(7), "id") == w
    a, b = np.random.default_rng(11), np.random.default_rng(11)
    rm.sample_walker(a, "id")
    rm.sample_walker(b, "ood")
    assert a.random() == b.random()


def test_ood_ranges_name_walker_fields_within_their_physical_ranges() -> None:
    for mode, table in rm.OOD_RANGES.items():
        assert mode in rm.OOD_MODES
        for name, (lo, hi) in table.items():
            assert name in rm.FIELD_RANGES and name in rm.OOD_UNIFORM and lo <= hi
            flo, fhi, *_ = rm.FIELD_RANGES[name]
            if name in rm.OOD_SYMMETRIC:
                assert 0 <= lo and hi <= min(-flo, fhi), name
            else:
                assert flo <= lo and hi <= fhi, name


def test_ood_walkers_draw_their_calibrated_ranges_and_keep_away_from_the_giver() -> None:
    closest, turns = [], []
    for seed in range(10_000, 10_120):
        w = rm.sample_walker(np.random.default_rng(seed), "ood")
        for name, (lo, hi) in rm.OOD_RANGES[w.ood_mode].items():
            v = abs(getattr(w, name)) if name in rm.OOD_SYMMETRIC else getattr(w, name)
            assert lo - 1e-12 <= v <= hi + 1e-12, name
        turns.append(w.start_turn)
        tr = trajectory.base_trajectory(w)
        closest.append(np.linalg.norm(tr.xy, axis=1).min())
        # back on the passing line for the handover: the meander is gone past wander_fade_x
        near = tr.xy[:, 0] < w.wander_fade_x - 0.3
        assert np.abs(tr.xy[near, 1] - w.pass_y).max() < 0.8
        assert abs(tr.xy[-1, 1] - w.pass_y) < 0.05
    assert min(closest) > 0.45  # the giver/robot stands at the origin
    assert 0.3 < np.mean(np.array(turns) > 0) < 0.7  # swings out to either side


def test_walk_statistics_of_crafted_walks() -> None:
    from handover_eval.calibration.walks import PAUSE_SPEED, walk_statistics

    t = np.arange(0, 4.0, 1 / 30)
    straight = np.stack([2.0 - 0.8 * t, np.full_like(t, -0.9)], axis=-1)
    s = walk_statistics(straight)
    assert s["heading_change"] < 1.0 and abs(s["detour"]) < 0.01 and s["pauses"] == 0
    assert abs(s["speed_median"] - 0.8) < 0.01 and s["speed_cv"] < 0.02
    assert s["turn_back_time"] == 0 and abs(s["duration"] - 4.0) < 0.05
    # A 1.5 s stop in the middle: one pause of about 1.5 s (the 1 Hz low-pass rounds it off).
    x = np.concatenate([2.0 - 0.8 * t[:60], np.full(45, 2.0 - 0.8 * t[60]),
                        2.0 - 0.8 * t[60] - 0.8 * t[1:61]])
    paused = walk_statistics(np.stack([x, np.full_like(x, -0.9)], axis=-1))
    assert paused["pauses"] == 1 and 1.1 < paused.pause_durations[0] < 1.8
    assert paused["slowest_speed"] < 0.05 < PAUSE_SPEED and paused["speed_cv"] > 0.3
    # One full circle of radius 0.5 m on the way: about 360 deg more turning, pi m more path.
    phi = np.linspace(0, 2 * np.pi, 120)
    loop = np.concatenate([
        straight[:45],
        straight[45] + 0.5 * np.stack([-np.sin(phi), 1 - np.cos(phi)], axis=-1)[1:],
        straight[46:],
    ])
    looped = walk_statistics(loop)
    assert 300 < looped["heading_change"] < 420
    assert abs(looped["detour"] - np.pi * 1.0 / 3.2) < 0.15  # 3.14 m more over 3.2 m net
    assert looped["turn_back_time"] > 0.5
    with pytest.raises(ValueError, match="nowhere"):
        walk_statistics(np.zeros((50, 2)))
    with pytest.raises(ValueError, match="T >= "):
        walk_statistics(np.zeros((5, 2)))
    with pytest.raises(ValueError, match="NaN"):
        walk_statistics(np.full((50, 2), np.nan))


def test_scripted_ood_walks_differ_from_id_walks_as_the_recordings_do() -> None:
    from handover_eval.calibration.walks_report import measure_walkers, summary_of

    ident = summary_of(measure_walkers("id", 60, progress=False)[0])
    ood_walks, modes = measure_walkers("ood", 60, progress=False)
    ood = summary_of(ood_walks)
    assert set(modes) == set(rm.OOD_MODES) and sum(modes.values()) == 60
    assert ood["heading_change"]["median"] > 2.5 * ident["heading_change"]["median"]
    assert ood["detour"]["median"] > 5 * ident["detour"]["median"]
    assert ood["speed_cv"]["median"] > 4 * ident["speed_cv"]["median"]
    assert ident["pause_share"]["median"] == 0 and 0.35 < ood["pause_share"]["median"] < 0.8
    assert 0.5 < ood["pause_duration"]["median"] < 0.9


@pytest.mark.skipif(not DATA.is_dir(), reason="public dataset copy not found at ../shared/data")
def test_scripted_ood_walkers_match_the_recorded_ood_walks_within_20_percent(tmp_path) -> None:
    from handover_eval.calibration.walks_report import CHOSEN, run_walk_stats

    summary, written = run_walk_stats(DATA, tmp_path, walkers=400, progress=False)
    assert summary["recordings"] == 875 and summary["counts"]["recorded/calibration/ood"] == 40
    table = {r["statistic"]: r for r in summary["table"]}
    for name in CHOSEN:
        assert table[name]["within"], (name, table[name]["ratio"])
        rec_id = summary["groups"]["recorded/calibration/id"][name]["median"]
        rec_ood = summary["groups"]["recorded/calibration/ood"][name]["median"]
        assert rec_ood > 1.5 * rec_id  # chosen because the recordings separate ID and OOD
    text = (tmp_path / "walkers.md").read_text()
    assert "All chosen statistics within 20 %: **yes**" in text
    assert {p.name for p in written} == {"walkers.json", "walkers.md", "walkers.png"}
