"""ContactMonitor on real MuJoCo contacts: which pairs are the robot's (envs/contacts.py)."""

from __future__ import annotations

import gymnasium as gym
import mujoco
import numpy as np
import pytest

import handover_env  # noqa: F401 - registers the envs


@pytest.fixture()
def pressed():
    """The env after reset with the object teleported into the person's abdomen."""
    env = gym.make("handover_env/DynamicHandover-v0", sensing="ideal")
    env.reset(seed=0, options={"receiver": "id"})
    u = env.unwrapped
    m, d = u.model, u.data
    d.eq_active[u.ids.eq_gripper] = 0  # let the object go where it is put
    torso = next(g for g in u.ids.receiver_geoms
                 if "abdomen" in (mujoco.mj_id2name(m, mujoco.mjtObj.mjOBJ_GEOM, int(g)) or ""))
    mujoco.mj_forward(m, d)
    adr = u.ids.object_qpos
    d.qpos[adr:adr + 3] = d.geom_xpos[torso]  # centre of the bottle at the torso's centre
    mujoco.mj_forward(m, d)
    yield u
    env.close()


def _object_person_depth(u) -> float:
    d = u.data
    person = set(int(g) for g in u.ids.receiver_geoms)
    obj = int(u.ids.object_geom)
    depths = [-c.dist for c in d.contact[: d.ncon]
              if {int(c.geom1), int(c.geom2)} & person and obj in (int(c.geom1), int(c.geom2))]
    return max(depths, default=0.0)


def test_object_contacts_count_while_the_robot_or_nobody_holds_it(pressed):
    depth = _object_person_depth(pressed)
    assert depth > 0.01  # a real MuJoCo contact, deeper than the 1 cm ghost bound
    mon = pressed.contacts
    mon.reset()
    mon.scan(pressed.data)
    assert mon.touched_object and mon.penetration == pytest.approx(depth)
    assert mon.peak.max() > 0.0


def test_the_persons_own_object_is_not_a_robot_contact(pressed):
    mon = pressed.contacts
    mon.reset()
    mon.count_object = False  # what the env sets once the person alone holds the object
    mon.scan(pressed.data)
    assert not mon.touched_object and mon.penetration == 0.0 and mon.raw_peak == 0.0
    mon.reset()
    assert mon.count_object  # every episode starts counting


def test_env_sets_it_from_who_holds_the_object():
    env = gym.make("handover_env/DynamicHandover-v0", sensing="ideal")
    env.reset(seed=0, options={"receiver": "id"})
    u = env.unwrapped
    states = []
    for _ in range(200):
        _, _, term, trunc, info = env.step(np.array([*u.data.site_xpos[u.ids.tcp_site], -np.pi / 2],
                                                    dtype=np.float32))
        states.append((u._gripper_holds, u.receiver.grip.active, u.contacts.count_object))
        if term or trunc:
            break
    env.close()
    assert all(c == (g or not p) for g, p, c in states)
    assert info["outcome"] == "success"  # the person takes the held-still object
    assert any(not c for *_, c in states)  # ... and then holds it alone


def test_force_and_geom_class_read_the_monitor(pressed):
    from handover_env.envs.contacts import OBJECT, PERSON, ROBOT

    mon = pressed.contacts
    mon.count_object = True
    mon.scan(pressed.data)
    force = mon.force
    abdomen = int(np.argmax(force))
    assert force[abdomen] > 0.0 and np.array_equal(force, mon._force)  # noqa: SLF001
    with pytest.raises(ValueError):
        force[0] = 1.0  # a read-only view: the monitor's filter state cannot be changed
    assert mon.geom_class(int(pressed.ids.object_geom)) == OBJECT
    assert mon.geom_class(int(pressed.ids.receiver_geoms[0])) == PERSON
    assert mon.geom_class(int(pressed.ids.robot_geoms[0])) == ROBOT
    assert mon.geom_class(0) == 0  # the floor
