"""The agent a benchmark run scores: a built-in name, or a user's factory loaded from their code.

``--agent`` is one of

* a built-in name (:func:`handover_eval.roster.benchmark_agents`, any spelling the roster
  accepts): a method of the open-loop evaluations (``ours``, ``iaal``, ``act``, ``bc_mlp``,
  ``cv``; scored on both tracks), or a closed-loop-only agent (``reactive``, ``null``,
  ``lagging``);
* ``PKG.MODULE:FACTORY``: ``FACTORY`` of an importable module;
* ``path/to/file.py:FACTORY``: ``FACTORY`` of a Python file anywhere (no package needed).

``FACTORY(**config)`` (``--agent-config`` JSON object, default ``{}``; every number in it
finite) must return an :class:`agents.base.Agent`: ``fit(dataset)`` is called with the data the
agent may learn from (Table I's training folds, or all of ``--data``), ``predict_episode``
scores it open-loop, ``reset``/``act`` closed-loop. **Loading a plug-in runs its code**: that is
what naming it asks for, as ``python file.py`` does. The factory is loaded again in every worker
process (an :class:`AgentSource` holds only strings, so it pickles), and must build the same
agent each time for the results to be reproducible. Its import, its factory, its ``fit`` and
each of its episodes run under :func:`.guard.agent_guard`: a per-episode time limit
(:attr:`AgentSource.episode_limit_s`), and a ``SystemExit`` or ``KeyboardInterrupt`` in its code
named as the agent's.
"""

from __future__ import annotations

import hashlib
import importlib
import importlib.util
import json
import math
import re
import sys
import uuid
from collections.abc import Callable
from dataclasses import asdict, dataclass, is_dataclass
from pathlib import Path
from typing import Any

from agents.base import Agent
from handover_eval import roster
from handover_eval.benchmark.guard import (
    DEFAULT_EPISODE_LIMIT_S,
    MAX_EPISODE_LIMIT_S,
    agent_guard,
)

NAME_RE = re.compile(r"[A-Za-z0-9][A-Za-z0-9 _.:+()\-]{0,63}")
IDENT_RE = re.compile(r"[A-Za-z_][A-Za-z0-9_]*")
MAX_CONFIG_CHARS = 10_000


@dataclass(frozen=True)
class AgentSource:
    """A picklable description of the scored agent.

    Attributes:
        name: the name shown in the tables and the leaderboard.
        kind: "method" (a built-in of both tracks), "roster" (a closed-loop-only built-in) or
            "plugin".
        target: the built-in's roster name, or for a plug-in the module name or absolute file
            path.
        factory: a plug-in's factory name ("" for built-ins).
        config: a plug-in's factory keyword arguments as JSON text (sorted keys).
        spec: what ``--agent`` said.
        source_sha256: a plug-in file's SHA-256 (module plug-ins: its file's, when it has one).
        episode_limit_s: the time limit of one episode of this agent, s (``--episode-time-limit``;
            the reference agent of a run gets the scored agent's).
        run_id: a random id of the run that resolved it ("" for built-in constants): a
            plug-in stopped in a worker process is remembered under it, for this run only.
    """

    name: str
    kind: str
    target: str
    factory: str = ""
    config: str = "{}"
    spec: str = ""
    source_sha256: str = ""
    episode_limit_s: float = DEFAULT_EPISODE_LIMIT_S
    run_id: str = ""

    @property
    def guard_key(self) -> tuple[str, str] | None:
        """The key a stop of this agent is remembered under (None without a run id)."""
        return (self.run_id, self.name) if self.run_id else None

    @property
    def tracks(self) -> tuple[str, ...]:
        """The tracks this agent can be scored on."""
        return ("closedloop",) if self.kind == "roster" else ("openloop", "closedloop")

    def kwargs(self) -> dict[str, Any]:
        return json.loads(self.config)


def parse_config(text: str | None) -> str:
    """``--agent-config``: a JSON object with identifier keys, as canonical JSON text."""
    if text is None:
        return "{}"
    if len(text) > MAX_CONFIG_CHARS:
        raise ValueError(f"--agent-config is longer than {MAX_CONFIG_CHARS} characters")
    try:
        obj = json.loads(text, parse_constant=_no_constant)
    except json.JSONDecodeError as exc:
        raise ValueError(f"--agent-config is not JSON: {exc.msg} (char {exc.pos})") from None
    except RecursionError:
        raise ValueError("--agent-config is nested too deeply") from None
    if not isinstance(obj, dict):
        raise ValueError("--agent-config must be a JSON object of keyword arguments")
    bad = [k for k in obj if not IDENT_RE.fullmatch(k)]
    if bad:
        raise ValueError(f"--agent-config keys must be Python identifiers, got {bad[:3]}")
    _check_finite(obj, "")
    return json.dumps(obj, sort_keys=True, allow_nan=False)


def _no_constant(name: str) -> None:
    raise ValueError(f"--agent-config: {name} is not allowed")


def _check_finite(value: Any, where: str) -> None:
    """Refuse a number that is not finite anywhere in ``value`` (``1e999`` parses as inf, as
    NaN and Infinity are refused by name)."""
    if isinstance(value, float) and not math.isfinite(value):
        raise ValueError(f"--agent-config: {where or 'a value'} is {value} (a number too large "
                         "for a float); every number must be finite")
    if isinstance(value, dict):
        for k, v in value.items():
            _check_finite(v, f"{where}.{k}" if where else k)
    elif isinstance(value, list):
        for i, v in enumerate(value):
            _check_finite(v, f"{where}[{i}]")


def episode_limit(seconds: float) -> float:
    """``--episode-time-limit``: a finite number of seconds in (0, MAX_EPISODE_LIMIT_S]."""
    if (isinstance(seconds, bool) or not isinstance(seconds, (int, float))
            or not (math.isfinite(seconds) and 0 < seconds <= MAX_EPISODE_LIMIT_S)):
        raise ValueError(f"--episode-time-limit must be a number of seconds in (0, "
                         f"{MAX_EPISODE_LIMIT_S:g}], got {seconds!r}")
    return float(seconds)


def check_name(name: str) -> str:
    if not isinstance(name, str) or not NAME_RE.fullmatch(name):
        raise ValueError(
            f"agent name {name!r}: 1-64 characters of letters, digits, space and _ . : + - ( ), "
            "starting with a letter or digit"
        )
    return name


def resolve(spec: str, name: str | None = None, config: str | None = None,
            episode_limit_s: float = DEFAULT_EPISODE_LIMIT_S) -> AgentSource:
    """The :class:`AgentSource` of ``--agent spec`` (a clear ValueError when it is malformed),
    with a fresh run id and the per-episode time limit ``episode_limit_s``."""
    limit, run_id = episode_limit(episode_limit_s), uuid.uuid4().hex
    spec = spec.strip()
    if ":" not in spec:
        if config not in (None, "{}"):
            raise ValueError("--agent-config is for plug-in factories, not built-in agents")
        found = roster.find(spec)
        if found is not None and found.benchmark:
            kind = "method" if "openloop" in found.tracks else "roster"
            return AgentSource(check_name(name or found.name), kind, found.name, spec=spec,
                               episode_limit_s=limit, run_id=run_id)
        raise ValueError(
            f"--agent {spec!r}: not a built-in ({list(roster.benchmark_agents())}) and "
            "not MODULE:FACTORY or path/to/file.py:FACTORY"
        )
    target, factory = spec.rsplit(":", 1)
    if not IDENT_RE.fullmatch(factory):
        raise ValueError(f"--agent {spec!r}: the factory {factory!r} is not a Python name")
    if target.endswith(".py") or "/" in target or "\\" in target:
        path = Path(target).expanduser()
        if not path.is_file():
            raise ValueError(f"--agent {spec!r}: no such file {target}")
        path = path.resolve()
        digest = hashlib.sha256(path.read_bytes()).hexdigest()
        default = f"{path.stem}:{factory}"
        target = str(path)
    else:
        if not all(IDENT_RE.fullmatch(p) for p in target.split(".")):
            raise ValueError(f"--agent {spec!r}: {target!r} is not a module name")
        found = importlib.util.find_spec(target.split(".")[0])
        if found is None:
            raise ValueError(f"--agent {spec!r}: no module named {target.split('.')[0]!r}")
        digest = ""
        default = f"{target.rsplit('.', 1)[-1]}:{factory}"
    return AgentSource(
        check_name(name or default), "plugin", target, factory, parse_config(config), spec, digest,
        limit, run_id,
    )


def load_factory(source: AgentSource) -> Callable[..., Any]:
    """The plug-in's factory (imports the module or executes the file: runs its code, under
    :func:`.guard.agent_guard`: a SystemExit at import is an AgentError naming the agent)."""
    if source.kind != "plugin":
        raise ValueError(f"{source.name} is a built-in agent, not a plug-in")
    with agent_guard(source.name, f"importing {source.target}"):
        return _load_factory(source)


def _load_factory(source: AgentSource) -> Callable[..., Any]:
    if source.target.endswith(".py") and Path(source.target).is_absolute():
        mod_name = "handover_plugin_" + hashlib.sha1(source.target.encode()).hexdigest()[:12]
        module = sys.modules.get(mod_name)
        if module is None:
            spec = importlib.util.spec_from_file_location(mod_name, source.target)
            if spec is None or spec.loader is None:
                raise ValueError(f"--agent: cannot load {source.target}")
            module = importlib.util.module_from_spec(spec)
            sys.modules[mod_name] = module  # dataclasses and pickling look the module up
            try:
                spec.loader.exec_module(module)
            except BaseException:
                del sys.modules[mod_name]
                raise
    else:
        module = importlib.import_module(source.target)
    factory = getattr(module, source.factory, None)
    if not callable(factory):
        raise ValueError(f"--agent {source.spec}: {source.factory!r} is not a callable of it")
    return factory


def build_plugin(source: AgentSource) -> Agent:
    """A fresh plug-in agent: ``FACTORY(**config)``, checked to be an :class:`Agent`."""
    factory = load_factory(source)
    with agent_guard(source.name, f"{source.factory}()"):
        agent = factory(**source.kwargs())
    if not isinstance(agent, Agent):
        raise ValueError(
            f"--agent {source.spec}: {source.factory}() returned {type(agent).__name__}, not an "
            "agents.base.Agent (subclass it, or agents.predictive.PredictiveAgent)"
        )
    horizon = getattr(agent, "horizon", None)
    if not isinstance(horizon, int) or horizon < 1:
        raise ValueError(f"--agent {source.spec}: agent.horizon must be a positive int")
    return agent


def fit_plugin(source: AgentSource, train: Any) -> Agent:
    """A fresh plug-in agent fitted on ``train`` (what ``fit`` returns, if an Agent, else the
    agent itself); its ``fit`` runs under :func:`.guard.agent_guard` (no time limit: a fit may
    take long)."""
    agent = build_plugin(source)
    with agent_guard(source.name, "fit()", key=source.guard_key):
        fitted = agent.fit(train)
    return fitted if isinstance(fitted, Agent) else agent


def jsonable(value: Any) -> Any:
    """``value`` as JSON-safe data: dataclasses as dicts, tuples as lists, non-finite floats as
    None, anything else unknown as its type name (never its repr: no addresses)."""
    if is_dataclass(value) and not isinstance(value, type):
        return jsonable(asdict(value))
    if isinstance(value, dict):
        return {str(k): jsonable(v) for k, v in sorted(value.items(), key=lambda kv: str(kv[0]))}
    if isinstance(value, (list, tuple)):
        return [jsonable(v) for v in value]
    if isinstance(value, bool) or value is None or isinstance(value, str):
        return value
    if isinstance(value, int):
        return int(value)
    if isinstance(value, float):
        return float(value) if math.isfinite(value) else None
    try:
        import numpy as np

        if isinstance(value, np.generic):
            return jsonable(value.item())
    except ImportError:  # pragma: no cover - numpy is a dependency
        pass
    return f"<{type(value).__name__}>"


def agent_config(source: AgentSource, agent: Agent | None) -> dict:
    """What result.json records of the agent's configuration: the factory's keyword arguments
    and the agent's ``config`` dataclass (when it has one)."""
    config = getattr(agent, "config", None) if agent is not None else None
    return {
        "kwargs": source.kwargs(),
        "config": jsonable(config) if is_dataclass(config) else None,
        "horizon": getattr(agent, "horizon", None) if agent is not None else None,
    }
