"""The scored agent's code runs under a guard: a per-episode time limit, and no silent exit.

A plug-in agent is the user's code (:mod:`.plugin`), run inside the benchmark's processes. What
it may do to the run is bounded by :func:`agent_guard`, around its import, its factory, its
``fit`` and every episode (closed loop: ``reset``/``act`` through one env episode; open loop:
every ``predict`` of one recording):

* **Time.** An episode that runs past the time limit (``evaluate.py benchmark
  --episode-time-limit``, default :data:`DEFAULT_EPISODE_LIMIT_S`) is stopped by ``SIGALRM`` in
  the process that runs it (the main process with ``--workers 1``, else the pool or Ray worker:
  each arms its own timer) and becomes an :class:`AgentError` naming the agent and the episode.
  The alarm raises a ``BaseException`` (a plug-in's ``except Exception`` does not swallow it) and
  fires again every second until the guard has it. Later episodes of the same agent in that
  process fail at once with the same message, so a blocking agent costs one limit per worker, not
  one per episode. The timer interrupts Python code and the blocking calls that return to Python
  on a signal (``time.sleep``, locks, I/O); a C extension that never returns to the interpreter
  cannot be interrupted this way. Where there is no ``SIGALRM`` or the guard does not run in the
  main thread, no limit is armed.
* **Exit.** ``SystemExit`` raised by the agent's code (``sys.exit(0)`` in ``act``, ``exit(3)`` at
  import) is an :class:`AgentError` naming the agent and what it was doing: it never ends the
  benchmark, least of all with status 0.
* **Interrupt.** ``KeyboardInterrupt`` inside the agent's code becomes :class:`AgentInterrupted`
  (still a ``KeyboardInterrupt``) naming the agent and the episode; ``evaluate.py`` stops with one
  line and status 130.

The default, 600 s, is far above any real agent's episode: a closed-loop episode is at most 450
env steps (15 s of simulated time), and a step of the reactive agent costs about 14 ms (a
450-step episode about 6 s; 0.7-1.2 s for the usual 50-70 steps, measured on the 2-core
development machine); paper-scale ACT, the most expensive built-in, predicts in about 13 ms a
frame on one thread (``docs/ray.md``), so its longest episode takes about 12 s. 600 s is 50
times that, and stops a blocked agent within ten minutes.
"""

from __future__ import annotations

import signal
import threading
import time
from collections.abc import Hashable, Iterator
from contextlib import contextmanager
from typing import Any

#: The default per-episode time limit, s (module docstring: how it was chosen).
DEFAULT_EPISODE_LIMIT_S = 600.0
#: The largest limit ``--episode-time-limit`` accepts, s (one day).
MAX_EPISODE_LIMIT_S = 86_400.0
#: After the limit the alarm repeats at this interval, s, until the guard catches it.
REPEAT_S = 1.0


class AgentError(RuntimeError):
    """The scored agent stopped the run (past its time limit, or it raised SystemExit); the
    message names the agent and the episode or step."""


class AgentInterrupted(KeyboardInterrupt):
    """A KeyboardInterrupt inside the agent's code, naming the agent and what it was doing."""


class _TimeLimit(BaseException):
    """Raised by the alarm inside the agent's code; caught by :func:`agent_guard` only."""


#: Agents stopped in this process: key -> the message their next episode fails with.
_STOPPED: dict[Hashable, str] = {}
#: True while a guard's timer is armed: an alarm arriving after it was disarmed does nothing.
_LIVE = [False]


def _on_alarm(signum: int, frame: Any) -> None:
    if _LIVE[0]:
        raise _TimeLimit


class _Alarm:
    """A ``SIGALRM`` timer of ``seconds`` (None: none), restoring any earlier handler and timer."""

    def __init__(self, seconds: float | None) -> None:
        self.armed = (seconds is not None and hasattr(signal, "setitimer")
                      and threading.current_thread() is threading.main_thread())
        if self.armed:
            self.start = time.monotonic()
            self.old_handler = signal.signal(signal.SIGALRM, _on_alarm)
            _LIVE[0] = True
            self.old_timer = signal.setitimer(signal.ITIMER_REAL, seconds, REPEAT_S)

    def disarm(self) -> None:
        if not self.armed:
            return
        _LIVE[0] = self.armed = False
        signal.setitimer(signal.ITIMER_REAL, 0)
        signal.signal(signal.SIGALRM, self.old_handler)
        left, interval = self.old_timer
        if left > 0:  # an outer timer: re-armed with what is left of it
            elapsed = time.monotonic() - self.start
            signal.setitimer(signal.ITIMER_REAL, max(left - elapsed, 1e-3), interval)


@contextmanager
def agent_guard(agent: str, what: str, limit_s: float | None = None,
                key: Hashable | None = None) -> Iterator[None]:
    """Run the agent's code of ``what`` (e.g. ``"closed-loop episode id/walker-3"``) under the
    guard of the module docstring.

    Args:
        agent: the agent's name, for messages.
        what: the episode or step, for messages.
        limit_s: the time limit, s (None: no limit).
        key: identifies the agent in this run; once it was stopped, the next guard with the same
            key fails at once (None: not remembered).

    Raises:
        AgentError: past the limit, SystemExit, or an earlier stop of the same key.
        AgentInterrupted: a KeyboardInterrupt inside.
    """
    if key is not None and key in _STOPPED:
        raise AgentError(_STOPPED[key])
    alarm = _Alarm(limit_s)
    try:
        try:
            yield
        finally:
            alarm.disarm()
    except _TimeLimit:
        _stop(key, f"agent {agent!r}: {what} ran past the per-episode time limit of "
              f"{limit_s:g} s (--episode-time-limit); its later episodes in this process are "
              "not run")
    except SystemExit as exc:
        _stop(key, f"agent {agent!r}: {what} raised SystemExit({exc.code!r}); an agent may not "
              "end the benchmark")
    except AgentInterrupted:
        raise
    except KeyboardInterrupt:
        raise AgentInterrupted(f"agent {agent!r}: interrupted during {what}") from None


def _stop(key: Hashable | None, message: str) -> None:
    if key is not None:
        _STOPPED[key] = message
    raise AgentError(message) from None


def forget_stopped() -> None:
    """Forget the agents stopped in this process (a new run)."""
    _STOPPED.clear()
