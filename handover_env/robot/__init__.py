"""The robot: the UR5e arm with the Robotiq 2F-85 gripper (MuJoCo Menagerie models) and its control.

* :mod:`.scene`: the handover scene (robot, bottle, person) built with ``MjSpec``, and its indices;
* :mod:`.controller`: the Cartesian impedance controller (paper Eq. 1) and inverse kinematics;
* :mod:`.menagerie`: where the Menagerie model files are found.
"""
