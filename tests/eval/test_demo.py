"""The demo (``make demo``): its summary is the episodes' infos, its video is dynamic | static.

The summary is checked on crafted episodes (exact medians and counts) and on one real walker met
by both sides, against the env's final infos; the side-by-side frames against the two sides' own
filmed frames. Only the filmed tests skip, and only when no offscreen GL backend opens.
"""

from __future__ import annotations

import math
import os

os.environ.setdefault("MUJOCO_GL", "egl")

import mujoco  # noqa: E402
import numpy as np  # noqa: E402
import pytest  # noqa: E402

from agents.nonparametric import NonparametricAgent  # noqa: E402
from handover_env.person.synthetic import generate_synthetic  # noqa: E402
from handover_eval.demo import caption, output, report, run  # noqa: E402
from handover_eval.demo.view import ViewSize  # noqa: E402

_NO_GL = (mujoco.FatalError, RuntimeError, OSError, ImportError, AttributeError)
SEED = 37_001  # one of the demo's walkers
SIZE = ViewSize(96, 72)


def _row(side: str, seed: int, outcome: str, t: float | None, first: str = "") -> dict:
    ok = outcome == "success"
    return {"side": side, "seed": seed, "outcome": outcome, "success": ok,
            "first_failure": "" if ok else first,
            "handover_time": t if ok else math.nan,
            "handover_time_with_delay": (t + (2.0 if side == "static" else 0.0)) if ok
            else math.nan,
            "release_force": 8.0, "peak_wrist_force": 9.0, "body_contact_force": 0.0,
            "steps": 10}


def _crafted() -> run.DemoRun:
    dyn = [run.DemoEpisode("dynamic", s, {}, _row("dynamic", s, o, t, f))
           for s, o, t, f in ((1, "success", 1.0, ""), (2, "success", 3.0, ""),
                              (3, "premature_release", None, "premature_release"))]
    sta = [run.DemoEpisode("static", s, {}, _row("static", s, o, t, f))
           for s, o, t, f in ((1, "success", 4.0, ""), (2, "timeout", None, "no_reach"),
                              (3, "unsafe_force", None, "unsafe_force"))]
    return run.DemoRun({"dynamic": dyn, "static": sta}, 0.0, 0.0)


def test_the_summary_counts_and_medians_the_episodes():
    dyn, sta = report.summary(_crafted())
    assert (dyn["side"], dyn["episodes"], dyn["successes"]) == ("dynamic", 3, 2)
    assert dyn["success_rate"] == pytest.approx(2 / 3)
    assert dyn["median_handover_time_s"] == 2.0 == dyn["median_handover_time_with_delay_s"]
    assert dyn["outcomes"] == "success 2, premature_release 1"
    assert dyn["first_failures"] == "premature_release 1"
    assert (sta["successes"], sta["median_handover_time_s"]) == (1, 4.0)
    assert sta["median_handover_time_with_delay_s"] == 6.0
    # first failures in the benchmark's order of checks (unsafe_force before no_reach)
    assert sta["first_failures"] == "unsafe_force 1, no_reach 1"
    text = report.summary_markdown(_crafted())
    assert "| 2/3 | 2.00 | 2.00 |" in text and "| 1/3 | 4.00 | 6.00 |" in text
    assert "timeout (first failure: no_reach)" in text


def test_no_success_has_no_median():
    crafted = _crafted()
    crafted.episodes["dynamic"] = crafted.episodes["dynamic"][2:]
    assert math.isnan(report.summary(crafted)[0]["median_handover_time_s"])


def test_the_caption_names_the_outcome_and_the_first_failure():
    m = run.Moment(time=3.0, wrist_force=2.5, release_time=None, robot_enabled=True,
                   outcome="running")
    assert caption.status_line(m, None)[0] == "handing over ..."
    waiting = run.Moment(1.0, 0.0, None, False, "running")
    assert caption.status_line(waiting, None)[0].startswith("robot waits")
    released = run.Moment(3.0, 9.0, 2.9, True, "running")
    assert caption.status_line(released, None)[0] == "released at 2.90 s"
    ok = caption.status_line(m, _row("dynamic", 1, "success", 2.5))
    assert ok == ("success: handover time 2.50 s", caption.GOOD)
    bad = caption.status_line(m, _row("static", 1, "timeout", None, "no_reach"))
    assert bad == ("timeout  (first failure: no_reach)", caption.BAD)
    lines = caption.caption_lines("Dynamic", m, None, 7.1)
    assert [t for t, _, _ in lines][:2] == [
        "Dynamic", "t =  3.00 s    wrist force   2.5 N (opens above 7.1 N)"]


@pytest.mark.parametrize("width, height", [(15, 72), (96, 71), (96.5, 72), (True, 72)])
def test_a_view_size_must_be_even_pixels(width, height):
    with pytest.raises(ValueError, match="must be an even whole number of pixels"):
        ViewSize(width, height)


def test_the_helper_process_gets_the_filmed_static_walkers_and_every_episode_runs_once():
    seeds = (5, 6, 7)
    here, helper = run.plan(seeds, (5,), film=True)
    pairs = [(j.side, s) for j in here + helper for s in j.seeds]
    assert sorted(pairs) == sorted((side, s) for side in ("dynamic", "static") for s in seeds)
    assert [(j.side, j.seeds, j.film_seeds) for j in helper] == [("static", (5,), (5,))]
    _, helper = run.plan(seeds, (5,), film=False)
    assert [(j.side, j.seeds, j.film_seeds) for j in helper] == [("static", seeds, ())]
    with pytest.raises(ValueError, match="video seeds must be among the seeds"):
        run.run(seeds=(1,), video_seeds=(2,))
    with pytest.raises(ValueError, match="workers must be 1 or 2"):
        run.run(seeds=(1,), workers=3)


def _skip_without_offscreen_gl() -> None:
    try:
        context = mujoco.GLContext(16, 16)
        context.make_current()
        context.free()
    except _NO_GL as exc:
        pytest.skip(f"no offscreen GL backend (MUJOCO_GL={os.environ.get('MUJOCO_GL')}): {exc}")


@pytest.fixture(scope="module")
def filmed(tmp_path_factory):
    """One demo walker met by both sides, filmed at a lower frame rate, with a planner fitted on
    a small synthetic set (the plumbing under test does not depend on the planner's skill)."""
    _skip_without_offscreen_gl()
    planner = NonparametricAgent().fit(generate_synthetic(n=40))
    stride = run.FRAME_STRIDE
    run.FRAME_STRIDE = 6
    try:
        result = run.run(seeds=(SEED,), video_seeds=(SEED,), size=SIZE, workers=1,
                         planner=planner)
    finally:
        run.FRAME_STRIDE = stride
    out = tmp_path_factory.mktemp("demo")
    return result, out, output.write(result, out)


def test_the_summary_is_the_episodes_infos(filmed):
    result, _, _ = filmed
    for side, row in zip(("dynamic", "static"), report.summary(result)):
        (ep,) = result.episodes[side]
        info = ep.info
        assert ep.seed == SEED and row["episodes"] == 1
        assert row["successes"] == int(info["outcome"] == "success") == int(info["is_success"])
        expected = "timeout" if info["outcome"] == "running" else info["outcome"]
        assert row["outcomes"] == f"{expected} 1"
        if info["is_success"]:
            assert row["median_handover_time_s"] == pytest.approx(info["handover_time"])
            assert row["median_handover_time_with_delay_s"] == pytest.approx(
                info["handover_time_with_delay"])
            assert row["first_failures"] == "-"
        else:
            assert math.isnan(row["median_handover_time_s"])
            assert row["first_failures"] == f"{ep.row['first_failure']} 1"
        assert ep.row["steps"] * run.ENV_STEP_S == pytest.approx(info["time"])
        # one frame per FRAME_STRIDE steps, plus the final state
        assert len(ep.frames) == len(ep.moments) == math.ceil(ep.row["steps"] / 6) + (
            (ep.row["steps"] - 1) % 6 != 0)
        assert ep.moments[-1].time == pytest.approx(info["time"])
        assert ep.moments[-1].outcome == info["outcome"]
    # the static robot waits for the raised hand and the delay; the dynamic one never does
    assert all(m.robot_enabled for m in result.episodes["dynamic"][0].moments)
    assert not result.episodes["static"][0].moments[0].robot_enabled


def test_the_video_frames_are_dynamic_left_and_static_right(filmed):
    result, _, _ = filmed
    (dyn,), (sta,) = result.episodes["dynamic"], result.episodes["static"]
    frames = list(report.side_by_side(dyn, sta))
    style = caption.STYLE
    assert len(frames) == max(len(dyn.frames), len(sta.frames)) + report.HOLD_FRAMES
    assert dyn.frames[0].shape == sta.frames[0].shape == (SIZE.height, SIZE.width, 3)
    for frame in frames:
        assert frame.shape == (style.title_height + SIZE.height + style.band_height,
                               2 * SIZE.width, 3)
    top = style.title_height
    for k in (0, len(frames) // 2, len(frames) - 1):
        scene = frames[k][top:top + SIZE.height]
        d, s = min(k, len(dyn.frames) - 1), min(k, len(sta.frames) - 1)
        assert np.array_equal(scene[:, :SIZE.width], dyn.frames[d])
        assert np.array_equal(scene[:, SIZE.width:], sta.frames[s])


def test_the_files_are_written(filmed):
    import imageio.v2 as imageio

    result, out, paths = filmed
    names = sorted(p.name for p in paths)
    assert names == sorted(["demo_summary.md", "demo_summary.csv", "demo_episodes.csv",
                            output.VIDEO, output.STILL])
    assert all((out / n).stat().st_size > 0 for n in names)
    style = caption.STYLE
    height = style.title_height + SIZE.height + style.band_height
    still = imageio.imread(out / output.STILL)
    assert still.shape[:2] == (height, 2 * SIZE.width)
    with imageio.get_reader(out / output.VIDEO) as video:
        first = video.get_data(0)
        assert first.shape[:2] == (height, 2 * SIZE.width)
        assert video.get_meta_data()["fps"] == output.VIDEO_FPS
    rows = (out / "demo_episodes.csv").read_text().splitlines()
    assert len(rows) == 3 and rows[1].startswith(f"dynamic,{SEED},")
