"""Gymnasium / SB3 API conformance of both handover envs."""

from __future__ import annotations

import os
import pickle
import subprocess
import sys
import warnings

import gymnasium as gym
import mujoco
import numpy as np
import pytest

import handover_env  # noqa: F401  (registers the ids)

IDS = ["handover_env/DynamicHandover-v0", "handover_env/StaticHandover-v0"]


@pytest.mark.parametrize("env_id", IDS)
def test_gymnasium_and_sb3_checkers_without_warnings(env_id):
    from gymnasium.utils.env_checker import check_env as gym_check
    from stable_baselines3.common.env_checker import check_env as sb3_check

    env = gym.make(env_id)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        # SB3's advice to normalise the action to [-1, 1] is not a dtype/bounds problem: the action
        # is a Cartesian target in metres/radians with finite bounds, which agents rely on.
        warnings.filterwarnings("ignore", message=".*symmetric and normalized.*")
        # The checkers reset unseeded too: a random walker may fall outside the calibrated range,
        # and the env's one documented range warning is then the env working, not an API issue.
        warnings.filterwarnings("ignore", message=".*outside the walks the simulated person was "
                                "calibrated on.*", category=UserWarning)
        gym_check(env.unwrapped, skip_render_check=True)
        sb3_check(env.unwrapped, warn=True)
    env.close()


def test_mujoco_reset_state():
    from gymnasium.envs.mujoco.utils import check_mujoco_reset_state

    env = gym.make(IDS[0])
    check_mujoco_reset_state(env)
    env.close()


def test_fresh_subprocess_make():
    code = (
        "import gymnasium as gym; e = gym.make('handover_env:handover_env/DynamicHandover-v0'); "
        "o, _ = e.reset(seed=0); print(o.shape, e.spec.max_episode_steps)"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert out.returncode == 0, out.stderr
    assert "450" in out.stdout


def test_registration_is_idempotent():
    handover_env.register_envs()
    handover_env.register_envs()
    assert all(i in gym.registry for i in IDS)


def _rollout(env, seed, n=25):
    obs, _ = env.reset(seed=seed, options={"receiver": "id"})
    rng = np.random.default_rng(seed)
    out = [obs]
    for _ in range(n):
        obs, r, term, trunc, info = env.step(env.action_space.sample() * 0 + rng.uniform(
            env.action_space.low, env.action_space.high).astype(np.float32))
        out.append(obs)
        if term or trunc:
            break
    return np.stack(out)


def test_same_seed_same_rollout_and_pickle_round_trip():
    a, b = gym.make(IDS[0]), gym.make(IDS[0])
    np.testing.assert_array_equal(_rollout(a, 3), _rollout(b, 3))
    c = pickle.loads(pickle.dumps(a.unwrapped))
    np.testing.assert_array_equal(_rollout(c, 3), _rollout(a, 3))


def test_observations_do_not_share_memory():
    env = gym.make(IDS[0])
    o1, _ = env.reset(seed=0)
    o2, *_ = env.step(env.action_space.sample())
    assert not np.shares_memory(o1, o2)
    assert o1.dtype == np.float32 and env.observation_space.contains(o1)


def test_options_unknown_ignored_bad_rejected():
    env = gym.make(IDS[0])
    env.reset(seed=0, options={"lerobot_thing": 1, "receiver": "ood"})
    with pytest.raises(ValueError, match="receiver"):
        env.reset(seed=0, options={"receiver": "flying"})
    with pytest.raises(ValueError, match="episode"):
        env.reset(seed=0, options={"receiver": "replay"})
    with pytest.raises(ValueError, match="height"):
        env.reset(seed=0, options={"height": 5.0})
    with pytest.raises(ValueError, match="receiver_xy"):
        env.reset(
            seed=0, options={"receiver": "replay", "episode": {"receiver_xy": np.zeros((5, 3))}}
        )
    with pytest.raises(ValueError, match="action"):
        env.reset(seed=0)
        env.step(np.array([np.nan, 0, 0, 0], dtype=np.float32))


def test_replay_from_arrays():
    env = gym.make(IDS[0], sensing="ideal")  # the exact camera: sees the replayed track
    t = np.arange(150) / 30.0
    xy = np.stack([2.0 - 0.8 * t, np.full_like(t, -0.9)], axis=1)
    obs, info = env.reset(seed=0, options={"receiver": "replay", "episode": {"receiver_xy": xy}})
    assert info["receiver_id"].startswith("replay")
    np.testing.assert_allclose(env.unwrapped.layout.receiver_track(obs)[-1], xy[0], atol=1e-6)


def test_info_keys_on_reset_and_step():
    env = gym.make(IDS[1])
    _, info = env.reset(seed=0)
    keys = {
        "is_success",
        "handover_time",
        "handover_time_with_delay",
        "release_force",
        "peak_contact_force",
        "receiver_id",
        "outcome",
    }
    assert keys <= set(info)
    _, _, _, _, info = env.step(env.action_space.sample())
    assert keys <= set(info)


#: What opening an OpenGL context raises when no backend works: MuJoCo's own error, a missing
#: display or library (``OSError``, ``ImportError``), PyOpenGL's ``None`` platform
#: (``AttributeError``), a GLFW / EGL / OSMesa refusal (``RuntimeError``).
_NO_GL = (mujoco.FatalError, RuntimeError, OSError, ImportError, AttributeError)


def _skip_without_offscreen_gl() -> None:
    """Skip when MuJoCo cannot open an offscreen OpenGL context on this machine (the only reason
    a render test may skip); an error of the env's own rendering then fails the test."""
    try:
        context = mujoco.GLContext(16, 16)
        context.make_current()
        context.free()
    except _NO_GL as exc:
        pytest.skip(f"no offscreen GL backend (MUJOCO_GL={os.environ.get('MUJOCO_GL')}): {exc}")


def test_rgb_array_render_headless():
    _skip_without_offscreen_gl()
    env = gym.make(IDS[0], render_mode="rgb_array", width=160, height=120)
    env.reset(seed=0)
    frame = env.render()
    assert frame.shape == (120, 160, 3) and frame.dtype == np.uint8 and frame.std() > 0


def test_ppo_smoke():
    from stable_baselines3 import PPO

    env = gym.make(IDS[0])
    model = PPO(
        "MlpPolicy", env, n_steps=256, batch_size=64, n_epochs=1, seed=0, device="cpu", verbose=0
    )
    model.learn(total_timesteps=1024)
    action, _ = model.predict(env.reset(seed=1)[0], deterministic=True)
    assert env.action_space.contains(action)


def test_record_video_writes_an_mp4(tmp_path):
    """Gymnasium's RecordVideo (moviepy, from the [video] extra) writes an episode's mp4."""
    from gymnasium.wrappers import RecordVideo

    _skip_without_offscreen_gl()
    env = gym.make(IDS[0], render_mode="rgb_array", width=160, height=120, max_episode_steps=20)
    env = RecordVideo(env, str(tmp_path), episode_trigger=lambda e: True, disable_logger=True)
    env.reset(seed=0)
    done = False
    while not done:
        _, _, term, trunc, _ = env.step(env.action_space.sample())
        done = term or trunc
    env.close()
    videos = list(tmp_path.glob("*.mp4"))
    assert len(videos) == 1 and videos[0].stat().st_size > 1000
