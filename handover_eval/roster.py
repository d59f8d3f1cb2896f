"""The one table of built-in agents: what every command, the benchmark and the reports read.

Each :class:`AgentEntry` says who an agent is (name, label, accepted spellings), what it needs
(whether it learns from data, is trained into the checkpoint cache, is an RL policy loaded from a
checkpoint, meets replays only), where it runs (the tracks it is scored on, the env kind) and how
it is built. Adding a built-in agent is one entry of :data:`ROSTER`:

* ``evaluate.py table1`` / ``sample-efficiency`` take the entries of the ``"openloop"`` track
  (:func:`openloop_methods`, Table I's row order);
* ``evaluate.py closed-loop`` / ``theta-sweep`` / ``sensing-sweep`` take the entries of the
  ``"closedloop"`` track (:func:`check_agents`; by default the ``compared`` ones,
  :func:`default_agents`), in roster order in every table;
* ``evaluate.py benchmark --agent`` takes every entry that runs in ``DynamicHandover-v0`` on any
  receiver and needs no RL checkpoint (:func:`benchmark_agents`);
* the reports label an agent by :func:`label`.

Spellings. ``name`` is the one name of an agent: its Table I rows, checkpoint folders and
benchmark results carry it. ``aliases`` are the other spellings accepted on input
(``bc-mlp`` for ``bc_mlp``, ``giver_replay`` for ``giver-replay``). The closed-loop family's files
have always spelled BC-MLP ``bc-mlp``; ``closedloop_name`` keeps that spelling there, so earlier
result files read back and every output stays byte for byte what it was.

Θ: an agent reads the Θ fields it uses (:data:`handover_env.config.AGENT_FIELDS`, t_f); K, B and
f_r are the env's (:func:`handover_eval.episodes.env_for`). A builder receives Θ; a fitted model
gets it from :func:`make_agent`.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable
from dataclasses import dataclass
from typing import TYPE_CHECKING

from agents.base import Policy
from handover_env.config import HandoverParams

if TYPE_CHECKING:
    from handover_eval.methods import MethodOptions

TRACKS = ("openloop", "closedloop")
ENV_KINDS = ("dynamic", "static")
#: s the ``lagging`` agent acts late.
LAG_SECONDS = 0.5
#: A builder: the run's method options and Θ -> a fresh, unfitted agent.
Builder = Callable[["MethodOptions", HandoverParams], Policy]


# ------------------------------------------------------------------------ builders
def _reactive(options: MethodOptions, params: HandoverParams) -> Policy:
    from agents.reactive import ReactiveAgent

    return ReactiveAgent(params)


def _static(options: MethodOptions, params: HandoverParams) -> Policy:
    from agents.static import StaticAgent

    return StaticAgent()


def _nonparametric(exact: bool) -> Builder:
    def build(options: MethodOptions, params: HandoverParams) -> Policy:
        from agents.nonparametric import NonparametricAgent, NonparametricConfig
        from baselines.iaal import IAALAgent

        config = NonparametricConfig(inducing_ratio=options.inducing_ratio,
                                     horizon=options.horizon)
        return IAALAgent(config) if exact else NonparametricAgent(config)

    return build


def _bc_mlp(options: MethodOptions, params: HandoverParams) -> Policy:
    from baselines.bc_mlp import BCMLPAgent, BCMLPConfig

    epochs = options.bc_epochs or (3 if options.quick else None)
    kwargs: dict = {"seed": options.seed, "horizon": options.horizon,
                    "use_giver_state": options.giver_state}
    if epochs:
        kwargs["max_epochs"] = epochs
    return BCMLPAgent(BCMLPConfig(**kwargs))


def _act(options: MethodOptions, params: HandoverParams) -> Policy:
    from baselines.act import ACTAgent, ACTAgentConfig

    steps = options.act_budget
    kwargs: dict = {"seed": options.seed, "horizon": options.horizon,
                    "use_giver_state": options.giver_state, "steps": steps,
                    "eval_every": max(1, steps // 8)}  # 8 validation passes pick the best
    if options.quick:
        kwargs.update(
            policy=dict(dim_model=32, dim_feedforward=64, n_heads=2, n_encoder_layers=1),
            batch_size=32,
        )
    return ACTAgent(ACTAgentConfig(**kwargs))


def _cv(options: MethodOptions, params: HandoverParams) -> Policy:
    from agents.constant_velocity import ConstantVelocityAgent
    from agents.reactive import ReactiveConfig

    return ConstantVelocityAgent(ReactiveConfig(horizon=options.horizon), params=params)


def _giver_replay(options: MethodOptions, params: HandoverParams) -> Policy:
    from agents.giver_replay import GiverReplayAgent

    return GiverReplayAgent(params=params)


def _null(options: MethodOptions, params: HandoverParams) -> Policy:
    from agents.null import NullAgent

    return NullAgent()


def _lagging(options: MethodOptions, params: HandoverParams) -> Policy:
    from agents.null import DelayedAgent
    from agents.reactive import ReactiveAgent

    return DelayedAgent(ReactiveAgent(params), LAG_SECONDS)


def _shipped_rl(options: MethodOptions, params: HandoverParams) -> Policy:
    from baselines.rl.shipped import load_shipped

    return load_shipped(params)


# ------------------------------------------------------------------------ the table
@dataclass(frozen=True)
class AgentEntry:
    """One built-in agent.

    Args:
        name: its one name (Table I's rows, checkpoint folders, benchmark results).
        label: its name in tables and figures.
        build: ``(options, Θ) -> agent``, fresh and unfitted (None: the policy is loaded from a
            checkpoint, ``rl_form``).
        learns: fitted on data: a closed-loop replay of fold f meets the model fitted on the
            other folds (Table I's fold models), a benchmark run fits it on the training folds.
        checkpoints: trained by :mod:`baselines.trainer` into the checkpoint cache and reused
            from it (:func:`handover_eval.methods.fit_agent`).
        tracks: ``"openloop"`` (it predicts: Table I, the figures) and/or ``"closedloop"`` (it
            acts in an env).
        env: ``"dynamic"`` (DynamicHandover-v0) or ``"static"`` (StaticHandover-v0).
        aliases: other spellings accepted on input.
        closedloop_name: the closed-loop files' spelling ("" = ``name``; module docstring).
        rl_form: an RL policy of this form, loaded from ``--rl-checkpoint`` ("" = not RL).
        replays_only: meets replayed recordings only (it replays the recorded giver).
        compared: run by ``evaluate.py closed-loop`` when ``--agents`` is not given (an RL
            agent also needs ``--quick`` or its checkpoint).
    """

    name: str
    label: str
    build: Builder | None
    learns: bool = False
    checkpoints: bool = False
    tracks: tuple[str, ...] = ("closedloop",)
    env: str = "dynamic"
    aliases: tuple[str, ...] = ()
    closedloop_name: str = ""
    rl_form: str = ""
    replays_only: bool = False
    compared: bool = True

    def __post_init__(self) -> None:
        if not self.tracks or set(self.tracks) - set(TRACKS):
            raise ValueError(f"{self.name}: tracks must be among {TRACKS}, got {self.tracks}")
        if self.env not in ENV_KINDS:
            raise ValueError(f"{self.name}: env must be one of {ENV_KINDS}, got {self.env!r}")
        if (self.build is None) != bool(self.rl_form):
            raise ValueError(f"{self.name}: an RL policy (rl_form) is loaded, every other agent "
                             "has a builder")
        if not self.closedloop_name:
            object.__setattr__(self, "closedloop_name", self.name)

    @property
    def spellings(self) -> tuple[str, ...]:
        """Every name this entry answers to."""
        return tuple(dict.fromkeys((self.name, self.closedloop_name, *self.aliases)))

    @property
    def benchmark(self) -> bool:
        """Scored by ``evaluate.py benchmark --agent NAME``: it runs in DynamicHandover-v0, meets
        every receiver and needs no RL checkpoint."""
        return self.env == "dynamic" and not self.replays_only and not self.rl_form


BOTH = ("openloop", "closedloop")
ROSTER: tuple[AgentEntry, ...] = (
    AgentEntry("reactive", "Reactive", _reactive),
    AgentEntry("static", "Static (Meng et al.)", _static, env="static"),
    AgentEntry("ours", "Ours (SPGP)", _nonparametric(exact=False), learns=True, tracks=BOTH),
    AgentEntry("iaal", "IAAL", _nonparametric(exact=True), learns=True, tracks=BOTH),
    AgentEntry("bc_mlp", "BC-MLP", _bc_mlp, learns=True, checkpoints=True, tracks=BOTH,
               aliases=("bc-mlp",), closedloop_name="bc-mlp"),
    AgentEntry("act", "ACT", _act, learns=True, checkpoints=True, tracks=BOTH),
    AgentEntry("cv", "Constant velocity", _cv, tracks=BOTH, compared=False),
    AgentEntry("giver-replay", "Giver replay (ref.)", _giver_replay, aliases=("giver_replay",),
               replays_only=True),
    AgentEntry("null", "Null (holds still)", _null),
    AgentEntry("lagging", "Lagging (reactive +0.5 s)", _lagging),
    AgentEntry("rl", "RL residual on cv (shipped)", _shipped_rl, compared=False),
    AgentEntry("rl-residual", "RL residual", None, rl_form="residual"),
    AgentEntry("rl-scratch", "RL from scratch", None, rl_form="scratch"),
)
#: Table I's rows in the order its files have always listed them; an open-loop entry not named
#: here follows them in roster order.
TABLE1_ROWS = ("ours", "iaal", "act", "bc_mlp", "cv")


def _index() -> dict[str, AgentEntry]:
    found: dict[str, AgentEntry] = {}
    for e in ROSTER:
        for s in e.spellings:
            if found.setdefault(s, e) is not e:
                raise ValueError(f"two roster entries answer to {s!r}")
    return found


def find(name: str) -> AgentEntry | None:
    """The entry that answers to ``name`` (any of its spellings), or None."""
    return _index().get(name)


def entry(name: str) -> AgentEntry:
    """The entry that answers to ``name``; a ValueError naming it and the choices otherwise."""
    found = find(name)
    if found is None:
        raise ValueError(f"unknown agent {name!r}; choose from {[e.name for e in ROSTER]}")
    return found


def names(track: str | None = None) -> tuple[str, ...]:
    """The entries' names (of ``track``), in roster order."""
    return tuple(e.name for e in ROSTER if track is None or track in e.tracks)


def rank(name: str) -> int:
    """Roster position of ``name`` (the tables' agent order); unknown names sort last."""
    found = find(name)
    return ROSTER.index(found) if found is not None else len(ROSTER)


def label(name: str) -> str:
    """The agent's label in tables and figures (``name`` itself when it is no built-in)."""
    found = find(name)
    return found.label if found is not None else name


def env_kind(name: str) -> str:
    """``"static"`` for an agent of StaticHandover-v0, else ``"dynamic"``."""
    found = find(name)
    return found.env if found is not None else "dynamic"


# ------------------------------------------------------------------------ open loop
def openloop_methods() -> tuple[str, ...]:
    """The open-loop methods: Table I's rows (:data:`TABLE1_ROWS`), then any other open-loop
    entry in roster order."""
    mine = names("openloop")
    return tuple([n for n in TABLE1_ROWS if n in mine] + [n for n in mine if n not in TABLE1_ROWS])


def check_methods(given: list[str] | tuple[str, ...]) -> list[str]:
    """Open-loop method names as their entries' names, in the given order without repeats; a
    ValueError naming the unknown ones."""
    methods = openloop_methods()
    found = [find(n) for n in given]
    unknown = [n for n, e in zip(given, found, strict=True)
               if e is None or "openloop" not in e.tracks]
    if unknown:
        raise ValueError(f"unknown method(s) {unknown}; choose from {list(methods)}")
    if not given:
        raise ValueError(f"no method selected; choose from {list(methods)}")
    return list(dict.fromkeys(e.name for e in found if e is not None))


# ------------------------------------------------------------------------ closed loop
def closedloop_agents() -> tuple[str, ...]:
    """The closed-loop agents as the closed-loop files spell them, in roster order."""
    return tuple(e.closedloop_name for e in ROSTER if "closedloop" in e.tracks)


def check_agents(given: list[str] | tuple[str, ...]) -> list[str]:
    """Closed-loop agent names as the closed-loop files spell them (any spelling accepted), in
    the given order without repeats; a ValueError naming the unknown ones."""
    agents = list(closedloop_agents())
    found = [find(n) for n in given]
    unknown = [n for n, e in zip(given, found, strict=True)
               if e is None or "closedloop" not in e.tracks]
    if unknown:
        raise ValueError(f"unknown agent(s) {unknown}; choose from {agents}")
    if not given:
        raise ValueError(f"no agent selected; choose from {agents}")
    return list(dict.fromkeys(e.closedloop_name for e in found if e is not None))


def compared_agents() -> tuple[str, ...]:
    """The closed-loop comparison's agents (the ``compared`` closed-loop entries, RL included),
    as the closed-loop files spell them, in roster order."""
    return tuple(e.closedloop_name for e in ROSTER if "closedloop" in e.tracks and e.compared)


def default_agents(quick: bool, rl_forms: frozenset[str] | set[str] = frozenset()) -> list[str]:
    """``evaluate.py closed-loop``'s agents: :func:`compared_agents`, an RL one only with
    ``quick`` (trained on the spot) or a checkpoint of its form among ``rl_forms``."""
    return [a for a in compared_agents()
            if not entry(a).rl_form or quick or entry(a).rl_form in rl_forms]


def benchmark_agents() -> tuple[str, ...]:
    """The built-ins ``evaluate.py benchmark --agent`` scores: the open-loop methods, then the
    closed-loop-only ones, in roster order."""
    methods = [n for n in openloop_methods() if entry(n).benchmark]
    return tuple(methods + [e.name for e in ROSTER if e.benchmark and e.name not in methods])


# ------------------------------------------------------------------------ building
def build(name: str, options: MethodOptions, params: HandoverParams | None = None,
          inducing_ratio: float | None = None) -> Policy:
    """A fresh, unfitted agent ``name`` with Θ = ``params`` (default Θ̂); ``inducing_ratio``
    overrides ``options.inducing_ratio`` (the trade-off sweep of ``ours``)."""
    e = entry(name)
    if e.build is None:
        raise ValueError(f"{e.name} is an RL policy: it is loaded from its checkpoint "
                         "(handover_eval.closedloop.models.rl_model), not built")
    if inducing_ratio is not None:
        options = dataclasses.replace(options, inducing_ratio=inducing_ratio)
    return e.build(options, params if params is not None else HandoverParams())


def make_agent(name: str | Policy, params: HandoverParams, options: MethodOptions,
               model: Policy | None = None) -> Policy:
    """A ready agent for one chunk of episodes, with Θ = ``params`` (it reads t_f).

    ``name`` is a built-in name (an agent that learns, or an RL policy, needs its fitted
    ``model``; the others are built with ``options``), or an external
    :class:`agents.base.Policy` object, returned as it is with ``params`` set when it has that
    attribute (a :class:`agents.predictive.PredictiveAgent`).
    """
    if isinstance(name, Policy):
        if isinstance(getattr(name, "params", None), HandoverParams):
            name.params = params  # type: ignore[attr-defined]
        return name
    e = entry(name)
    if e.learns or e.rl_form:
        if model is None:
            raise ValueError(f"{e.name} needs its fold model or policy")
        model.params = params  # type: ignore[attr-defined]
        return model
    return build(e.name, options, params)
