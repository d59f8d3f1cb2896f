"""Simulated participants of the user study: a body that walks, traits drawn from a stated
population, and a satisfaction that is a documented function of one episode's measured outcomes.

The paper tuned Theta = {K, B, t_f, f_r} with CoSpar from the preferences of 8 volunteers
(Sec. V-B) and ran its user study (H1-H3) with them. This module models such a volunteer so that
the same protocol can run in the env. It is a **model**, and every number below is either a
statistic of published work or of the recordings (cited), or an assumption (said so).

**Independence from the paper's Theta-hat.** Nothing here mentions Theta. A participant judges
what *happened* in an episode (the env's final ``info``); which Theta produced it is unknown to
them. The population is defined in outcome units (seconds, newtons, metres, m/s^3), never in
parameter units, and this module imports nothing from the env (``tests/agents/test_participants.py``
checks the imports and that no Theta-hat literal appears).

**Body** (:class:`Body`): sex, height, walking speed and the line along which the person passes
the robot; they drive the env's scripted walker through reset options
(:meth:`Participant.walk_options`). The paper's volunteers were in their 20s-30s, 6 male and
2 female, at Korea University. Height: normal per sex, means of South Korean adults born in 1996,
175.7 cm (men) and 162.3 cm (women) (NCD Risk Factor Collaboration, "A century of trends in adult
human height", eLife 5:e13410, 2016); SDs 6.5 / 6.0 cm (assumption: the usual within-sex spread
of adult stature). Walking speed: people walk much slower toward a handover in a lab than the
~1.4 m/s of free comfortable walking (Bohannon, Age Ageing 26:15, 1997): the recordings of this
very protocol have per-recording median pelvis speeds of 0.58-1.12 m/s, median 0.83 m/s
(``handover_env/receiver_motion.py``, statistics of the public dataset). We draw a personal speed
factor from N(1, 0.10) and scale 0.83 m/s by it and by sqrt(height / 1.725 m) (dynamic
similarity: walking speed grows with the square root of leg length, Alexander, Physiol. Rev.
69:1199, 1989). Passing line y: N(-0.92, 0.10) m (recordings: pelvis y at the transfer, median
-0.92; Hall's personal distance 0.45-1.2 m).

**Satisfaction of one episode** (:meth:`Participant.satisfaction`), in *comfort points* on the
Likert scale's own units: ``s = 5 - sum of costs``, each cost >= 0 (:meth:`Participant.costs`):

=================  ================================================================================
cost               definition (``info`` keys; traits in italics are the participant's own)
=================  ================================================================================
failure            *failure_cost* if ``outcome`` is not ``success`` (missed, dropped, premature
                   release, timeout); plus *unsafe_cost* for ``unsafe_force``
waiting            *time_cost* x max(0, T - *expected_time*), T = ``handover_time_with_delay`` (what
                   the person lived through: the static robot's 2 s stabilisation delay included;
                   ``handover_time`` if the former is absent); none on a failure (counted above)
slowing down       *slowdown_cost* x ``time_lost`` (s behind their own walk)
reach              *reach_cost* x max(0, ``reach_distance`` / arm length - *comfort_reach*) / 0.1
arm out            *arm_cost* x max(0, ``arm_extended_time`` - *arm_time*)
pull               *pull_cost* x max(0, log2(``pull_force`` / *preferred_pull*))  (per doubling)
contact            if ``body_contact_force`` > 1 N: *touch_cost* + *contact_cost* x
                   min(2, max over segments of ``contact_force_<segment>`` / ISO/TS 15066 limit)
robot motion       *jerk_cost* x max(0, log2(``robot_jerk_rms`` / *jerk_ref*))  (per doubling)
=================  ================================================================================

**Traits** (:class:`Traits`, drawn by :func:`sample_participant` from :class:`Population`):

* *failure_cost* U(2, 3) points, *unsafe_cost* U(0.5, 1.5) more: a failed handover is the worst
  thing that can happen in one (assumption: it takes a "very comfortable" handover down to 2-3).
* *expected_time* N(2.93, 0.30) s: what a human giver takes on the same walk; in the recordings
  the giver lets go 2.93 s [2.47, 3.47] (median [IQR]) after the receiver sets off
  (``docs/calibration/receiver_calibration.md``, ID recordings). *time_cost* log-normal, median
  0.33 points/s, geometric SD 1.5 (assumption: 3 s of extra waiting costs one point). People
  prefer human-level timing and judge a slow robot less warm (Pan, Knoop, Baecher & Niemeyer,
  IROS 2019); temporal precision matters more to satisfaction than spatial precision (Koene et al.,
  AISB 2014); shorter handovers are judged more fluent (Controzzi et al., Exp. Brain Res. 236:3363,
  2018). *slowdown_cost* log-normal, median 0.5 points/s, GSD 1.5: time lost by breaking one's
  stride is unoccupied waiting, which feels longer (Maister, "The psychology of waiting lines",
  1985) (assumption for the number).
* Arm length = 0.386 x height, shoulder to grip centre (upper arm 0.186 H + forearm 0.146 H + half
  the hand 0.054 H; Drillis & Contini, NYU report 1166-03, 1966). *comfort_reach* N(0.80, 0.05)
  arm lengths: in the recordings the object is taken 0.50 m [0.45, 0.56] from the shoulder, 0.75
  arm lengths of a 1.725 m person; the grip centre lies a few cm beyond the object's centre
  (assumption: comfort ends a little beyond the median human-human reach). *reach_cost*
  log-normal, median 0.5 points per 0.1 arm length, GSD 1.5 (assumption).
* *arm_time* N(1.30, 0.15) s: the arm-extended time of the recorded human-human handovers
  (calibration doc). *arm_cost* log-normal, median 0.15 points/s, GSD 1.5 (assumption: holding
  a hand out for a few seconds is a light effort).
* *preferred_pull* log-normal, median 5 N, GSD 1.6, clipped to [2, 20] N. Robots that let go at a
  3 N pull were taken from by 68 novices, who pulled in different styles (pulling briskly, pulling
  slowly, holding without pulling; Khanna et al., HAI 2023); a release that follows the person's
  pull early was preferred to a force threshold (Han & Yanco, HRI 2019); receivers take over the
  object's load, which sets the scale of the forces (Chan et al., HRI 2012): the 0.4 kg bottle
  weighs 3.9 N. *pull_cost* log-normal, median 0.4 points per doubling, GSD 1.5 (assumption).
* Contact: ISO/TS 15066:2016 Annex A quasi-static limits per body region (skull 130 N, chest
  140, pelvis 180, upper arm 150, lower arm 160, hand 140, thigh 220, lower leg 130); capped at
  twice the limit (the transient limit, beyond which the env ends the episode as unsafe).
  *touch_cost* U(0.3, 1.0) points for being touched at all, *contact_cost* U(1.5, 3.0) points per
  limit (assumptions).
* *jerk_ref* 26 m/s^3: the RMS jerk of a human-like minimum-jerk reach (Flash & Hogan, J.
  Neurosci. 5:1688, 1985) of 0.5 m in 0.8 s (26.8 D / T^3). *jerk_cost* log-normal, median 0.2
  points per doubling, GSD 1.5: faster, jerkier robot motion near people raises anxiety and
  surprise (Kulic & Croft, Robotica 25:13, 2007) (assumption for the number).
* Answers: *answer_noise* U(0.2, 0.4) points is sigma of the paper's Eq. 2,
  P(a > b) = Phi((u(a) - u(b)) / (sqrt(2) sigma)). Likert: *rating_bias* N(0, 0.3) points (some
  people rate high, some low), *rating_noise* 0.35 points.

**Likert comfort rating for Q1** ("The handover process felt comfortable", 1 = not at all,
5 = very much): an ordered-probit response (Liddell & Kruschke, J. Exp. Soc. Psychol. 79:328,
2018): latent = s + *rating_bias* + N(0, *rating_noise*); the rating is the latent rounded to
the nearest of 1..5 (thresholds 1.5, 2.5, 3.5, 4.5).

**Preferences over repeated trials**: a participant who tried a parameter set on several walks
judges it by the mean satisfaction over them (:meth:`Participant.prefers`).

Not modelled: learning and fatigue over a session, order effects, coactive feedback, the
person's own reaching style (every participant reaches as the env's calibrated person does).
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import asdict, dataclass, field

import numpy as np

#: Latent comfort of a handover with nothing wrong ("very much" comfortable).
TOP = 5.0
#: Likert thresholds of the ordered-probit mapping (a latent value rounds to the nearest point).
LIKERT_THRESHOLDS = (1.5, 2.5, 3.5, 4.5)
#: Arm length (shoulder to grip centre) over body height (Drillis & Contini 1966).
ARM_LENGTH_RATIO = 0.186 + 0.146 + 0.054
#: ISO/TS 15066:2016 Annex A quasi-static force limits (N) of the env's body segments' regions.
ISO_LIMITS: dict[str, float] = {
    "pelvis": 180.0, "torso": 140.0, "head": 130.0, "upper_arm_r": 150.0, "forearm_r": 160.0,
    "hand_r": 140.0, "upper_arm_l": 150.0, "forearm_l": 160.0, "hand_l": 140.0, "thigh_r": 220.0,
    "shank_r": 130.0, "thigh_l": 220.0, "shank_l": 130.0,
}
#: A contact counts as a touch above this force, N.
TOUCH_FORCE = 1.0
COST_NAMES = (
    "failure",
    "waiting",
    "slowing",
    "reach",
    "arm_out",
    "pull",
    "contact",
    "robot_motion",
)


@dataclass(frozen=True)
class Population:
    """The stated population distributions (see the module docstring for the sources).

    Normal: (mean, sd); log-normal: (median, geometric sd); uniform: (low, high).
    """

    height_male: tuple[float, float] = (1.757, 0.065)
    height_female: tuple[float, float] = (1.623, 0.060)
    speed_median: float = 0.83
    speed_factor_sd: float = 0.10
    reference_height: float = 1.725
    pass_y: tuple[float, float] = (-0.92, 0.10)
    failure_cost: tuple[float, float] = (2.0, 3.0)
    unsafe_cost: tuple[float, float] = (0.5, 1.5)
    expected_time: tuple[float, float] = (2.93, 0.30)
    time_cost: tuple[float, float] = (0.33, 1.5)
    slowdown_cost: tuple[float, float] = (0.5, 1.5)
    comfort_reach: tuple[float, float] = (0.80, 0.05)
    reach_cost: tuple[float, float] = (0.5, 1.5)
    arm_time: tuple[float, float] = (1.30, 0.15)
    arm_cost: tuple[float, float] = (0.15, 1.5)
    preferred_pull: tuple[float, float] = (5.0, 1.6)
    pull_cost: tuple[float, float] = (0.4, 1.5)
    touch_cost: tuple[float, float] = (0.3, 1.0)
    contact_cost: tuple[float, float] = (1.5, 3.0)
    jerk_ref: float = 26.0
    jerk_cost: tuple[float, float] = (0.2, 1.5)
    answer_noise: tuple[float, float] = (0.2, 0.4)
    rating_bias_sd: float = 0.3
    rating_noise: float = 0.35


@dataclass(frozen=True)
class Body:
    """A participant's body and walk (drives the env's scripted walker).

    Args:
        sex: ``"male"`` or ``"female"``.
        height: body height, m.
        speed: nominal walking speed, m/s.
        pass_y: y of the line along which they pass the robot, m.
    """

    sex: str
    height: float
    speed: float
    pass_y: float

    def __post_init__(self) -> None:
        if self.sex not in ("male", "female"):
            raise ValueError(f"sex must be 'male' or 'female', got {self.sex!r}")
        if not (
            1.2 <= self.height <= 2.2 and 0.1 <= self.speed <= 2.5 and -1.6 <= self.pass_y <= -0.3
        ):
            raise ValueError(
                f"body out of range: height {self.height}, speed {self.speed}, pass_y {self.pass_y}"
            )

    @property
    def arm_length(self) -> float:
        """Shoulder to grip centre, m (Drillis & Contini 1966)."""
        return ARM_LENGTH_RATIO * self.height


@dataclass(frozen=True)
class Traits:
    """What a participant cares about, in comfort points (see the module docstring's table)."""

    failure_cost: float
    unsafe_cost: float
    expected_time: float
    time_cost: float
    slowdown_cost: float
    comfort_reach: float
    reach_cost: float
    arm_time: float
    arm_cost: float
    preferred_pull: float
    pull_cost: float
    touch_cost: float
    contact_cost: float
    jerk_ref: float
    jerk_cost: float
    answer_noise: float
    rating_bias: float
    rating_noise: float

    def __post_init__(self) -> None:
        for name, value in asdict(self).items():
            if not math.isfinite(value):
                raise ValueError(f"trait {name} must be finite, got {value}")
            if name != "rating_bias" and value < 0:
                raise ValueError(f"trait {name} must be >= 0, got {value}")
        if self.answer_noise <= 0 or self.preferred_pull <= 0 or self.jerk_ref <= 0:
            raise ValueError("answer_noise, preferred_pull and jerk_ref must be > 0")


def _info_float(info: Mapping, key: str, default: float = 0.0) -> float:
    value = info.get(key)
    return default if value is None else float(value)


@dataclass
class Participant:
    """One simulated participant: body, traits and a seeded source of answer noise.

    Args:
        pid: identifier (the seed it was drawn with).
        body: :class:`Body`.
        traits: :class:`Traits`.
        seed: seeds the answer and rating noise (deterministic given the order of questions).
    """

    pid: int
    body: Body
    traits: Traits
    seed: int = 0
    rng: np.random.Generator = field(init=False, repr=False)

    def __post_init__(self) -> None:
        self.rng = np.random.default_rng(np.random.SeedSequence([int(self.seed), int(self.pid), 7]))

    def reseed(self, stream: int) -> None:
        """Restart the answer noise on its own stream (so that one part of a study does not depend
        on how many questions an earlier part asked)."""
        self.rng = np.random.default_rng(
            np.random.SeedSequence([int(self.seed), int(self.pid), 7, int(stream)])
        )

    # ------------------------------------------------------------------ the walk
    def walk_options(self, receiver: str = "id") -> dict:
        """Reset options for a scripted walker with this body and path (seeded by
        ``reset(seed)``)."""
        if receiver not in ("id", "ood"):
            raise ValueError(f"a participant walks as an 'id' or 'ood' walker, got {receiver!r}")
        b = self.body
        return {
            "receiver": receiver,
            "height": b.height,
            "speed": b.speed,
            "walker": {"pass_y": b.pass_y},
        }

    def walk_seeds(self, n: int, stream: int = 0) -> list[int]:
        """``n`` walker seeds of this participant; different streams never overlap (tuning: 0,
        study trials: 1, ...)."""
        base = (int(self.pid) % 100_000) * 1_000 + int(stream) * 100
        if not 0 <= n <= 100:
            raise ValueError(f"at most 100 walks per stream, got {n}")
        return [base + k for k in range(n)]

    # ------------------------------------------------------------------ judging one episode
    def costs(self, info: Mapping) -> dict[str, float]:
        """The cost terms (comfort points, >= 0) of one episode's final ``info`` (module
        docstring)."""
        t, b = self.traits, self.body
        outcome = info.get("outcome", "running")
        ok = outcome == "success"
        c = dict.fromkeys(COST_NAMES, 0.0)
        if not ok:
            c["failure"] = t.failure_cost + (t.unsafe_cost if outcome == "unsafe_force" else 0.0)
        else:
            lived = info.get("handover_time_with_delay", info.get("handover_time"))
            if lived is not None:
                c["waiting"] = t.time_cost * max(0.0, float(lived) - t.expected_time)
        c["slowing"] = t.slowdown_cost * max(0.0, _info_float(info, "time_lost"))
        excess_reach = _info_float(info, "reach_distance") / b.arm_length - t.comfort_reach
        c["reach"] = t.reach_cost * max(0.0, excess_reach) / 0.1
        c["arm_out"] = t.arm_cost * max(0.0, _info_float(info, "arm_extended_time") - t.arm_time)
        pull = _info_float(info, "pull_force")
        if pull > t.preferred_pull:
            c["pull"] = t.pull_cost * math.log2(pull / t.preferred_pull)
        if _info_float(info, "body_contact_force") > TOUCH_FORCE:
            ratio = max(_info_float(info, f"contact_force_{seg}") / lim
                        for seg, lim in ISO_LIMITS.items())
            c["contact"] = t.touch_cost + t.contact_cost * min(2.0, ratio)
        jerk = _info_float(info, "robot_jerk_rms")
        if jerk > t.jerk_ref:
            c["robot_motion"] = t.jerk_cost * math.log2(jerk / t.jerk_ref)
        return c

    def satisfaction(self, info: Mapping) -> float:
        """Comfort points of one episode: ``5 - sum(costs(info))`` (deterministic)."""
        return TOP - float(sum(self.costs(info).values()))

    def utility(self, infos: Sequence[Mapping]) -> float:
        """How much they liked a parameter set tried on several walks: mean satisfaction."""
        if not infos:
            raise ValueError("utility needs at least one episode")
        return float(np.mean([self.satisfaction(i) for i in infos]))

    # ------------------------------------------------------------------ answers
    def preference_probability(self, u_a: float, u_b: float) -> float:
        """P(a preferred to b) by the paper's Eq. 2 with this participant's sigma."""
        z = (u_a - u_b) / (math.sqrt(2.0) * self.traits.answer_noise)
        return 0.5 * math.erfc(-z / math.sqrt(2.0))

    def prefers(self, u_a: float, u_b: float) -> bool:
        """Answer "was a better than b?" (probit noise of Eq. 2; draws from :attr:`rng`)."""
        return bool(self.rng.random() < self.preference_probability(u_a, u_b))

    def likert(self, info: Mapping) -> int:
        """Q1 "The handover process felt comfortable", 1-5 (ordered probit; draws from
        :attr:`rng`)."""
        t = self.traits
        latent = (
            self.satisfaction(info) + t.rating_bias + t.rating_noise * self.rng.standard_normal()
        )
        return 1 + int(np.searchsorted(LIKERT_THRESHOLDS, latent))

    def describe(self) -> dict[str, float | str | int]:
        """Flat record of body and traits (for tables)."""
        return {"participant": self.pid, **asdict(self.body), **asdict(self.traits)}


def _lognormal(rng: np.random.Generator, spec: tuple[float, float]) -> float:
    median, gsd = spec
    return float(median * math.exp(math.log(gsd) * rng.standard_normal()))


def sample_participant(
    seed: int, sex: str | None = None, population: Population | None = None
) -> Participant:
    """Draw participant ``seed`` from ``population`` (the stated distributions by default).

    Args:
        seed: the participant's seed (also their id).
        sex: fix the sex (``"male"``/``"female"``); drawn 50/50 when None. The draws of the other
            attributes do not depend on it except through height's distribution.
        population: the distributions (:class:`Population`).
    """
    pop = population or Population()
    if int(seed) != seed or seed < 0:
        raise ValueError(f"participant seed must be a whole number >= 0, got {seed!r}")
    rng = np.random.default_rng(np.random.SeedSequence([int(seed), 1]))
    drawn_sex = "male" if rng.random() < 0.5 else "female"
    sex = drawn_sex if sex is None else sex
    if sex not in ("male", "female"):
        raise ValueError(f"sex must be 'male', 'female' or None, got {sex!r}")
    mu, sd = pop.height_male if sex == "male" else pop.height_female
    height = float(np.clip(mu + sd * rng.standard_normal(), 1.45, 2.05))
    factor = float(np.clip(1.0 + pop.speed_factor_sd * rng.standard_normal(), 0.7, 1.3))
    speed = pop.speed_median * factor * math.sqrt(height / pop.reference_height)
    pass_y = float(np.clip(pop.pass_y[0] + pop.pass_y[1] * rng.standard_normal(), -1.2, -0.6))
    body = Body(sex, round(height, 3), round(speed, 3), round(pass_y, 3))

    def normal(spec: tuple[float, float], low: float) -> float:
        return max(low, spec[0] + spec[1] * float(rng.standard_normal()))

    traits = Traits(
        failure_cost=float(rng.uniform(*pop.failure_cost)),
        unsafe_cost=float(rng.uniform(*pop.unsafe_cost)),
        expected_time=normal(pop.expected_time, 1.5),
        time_cost=_lognormal(rng, pop.time_cost),
        slowdown_cost=_lognormal(rng, pop.slowdown_cost),
        comfort_reach=normal(pop.comfort_reach, 0.5),
        reach_cost=_lognormal(rng, pop.reach_cost),
        arm_time=normal(pop.arm_time, 0.5),
        arm_cost=_lognormal(rng, pop.arm_cost),
        preferred_pull=float(np.clip(_lognormal(rng, pop.preferred_pull), 2.0, 20.0)),
        pull_cost=_lognormal(rng, pop.pull_cost),
        touch_cost=float(rng.uniform(*pop.touch_cost)),
        contact_cost=float(rng.uniform(*pop.contact_cost)),
        jerk_ref=pop.jerk_ref,
        jerk_cost=_lognormal(rng, pop.jerk_cost),
        answer_noise=float(rng.uniform(*pop.answer_noise)),
        rating_bias=pop.rating_bias_sd * float(rng.standard_normal()),
        rating_noise=pop.rating_noise,
    )
    return Participant(pid=int(seed), body=body, traits=traits, seed=int(seed))


def sample_population(n: int, seed: int = 0, male_fraction: float = 0.75,
                      population: Population | None = None) -> list[Participant]:
    """``n`` participants; round(male_fraction * n) of them male (the paper: 6 of 8).

    Participant i has seed ``seed * 1000 + i``.
    """
    if int(n) != n or n < 1:
        raise ValueError(f"need at least one participant, got {n!r}")
    if not 0.0 <= male_fraction <= 1.0:
        raise ValueError(f"male_fraction must be in [0, 1], got {male_fraction}")
    n_male = round(male_fraction * n)
    return [
        sample_participant(seed * 1000 + i, "male" if i < n_male else "female", population)
        for i in range(n)
    ]
