"""The camera model's frame, compiled: :func:`camera_frame` on a
:class:`~handover_env.sensors.camera.Camera`'s state array (the model is that module's docstring:
latency, AR(1) keypoint noise, lost frames).

The state array holds, at the slots below, the time of the last frame (``T_LAST``), the delay in
frames (``DELAY``), the loss chain's probabilities and state (``STAY``, ``START``, ``LOST``), per
keypoint (0: ``"hand"``, 1: ``"pelvis"``, the order the model draws them in) its noise parameters
(``PAR``: sigma, rho, sqrt(1 - rho^2) sigma) and noise state (``NOISE``: its dimension, 0 before
the first draw, and 3 values), the delivered frame (``OUT``) and the last tracked one (``HELD``,
with ``HAVE_HELD``), the pools of random numbers (``Z``: standard normals, ``U``: uniforms, each
with the index of the next one and the count), and the delay queue (``RING``: ``DELAY + 1`` frame
records from ``HEAD`` on, ``COUNT`` of them filled).

A frame record (``REC`` numbers) is ``[t, tracked, dim hand, dim pelvis, hand (3), pelvis (3)]``;
a keypoint not given has dimension 0.

The pools are drawn by the caller (:meth:`~handover_env.sensors.camera.Camera.capture`) when the
kernel reports that the frame needs more than they hold (:data:`NEED_NORMALS`, then
:data:`NEED_UNIFORMS`; the kernel has changed nothing yet): the normals left are kept and a block
of ``BLOCK`` is drawn after them, the uniforms are drawn in a new block of ``BLOCK``. A frame
consumes one normal per coordinate of a noisy keypoint (hand first) and one uniform when the
camera can lose the body, so the Generator's stream is that of drawing the numbers one at a time
from blocks of ``BLOCK``, each block drawn when its first number is needed.
"""

from __future__ import annotations

from handover_env.compiled import kernel

T_LAST, DELAY, STAY, START, LOST, ZI, ZN, UI, UN, HEAD, COUNT, HAVE_HELD = range(12)
PAR = 12  # (sigma, rho, c) per keypoint
NOISE = 18  # (dim, 3 values) per keypoint
R_T, R_TRACKED, R_DIM, R_PTS, REC = 0, 1, 2, 4, 10  # a frame record
OUT = 26
HELD = OUT + REC
BLOCK = 256  # random numbers drawn from the Generator at a time
Z = HELD + REC
U = Z + BLOCK + 8  # a frame uses at most 6 normals: at most 5 are left when a block is drawn
RING = U + BLOCK
N_KEYPOINTS = 2
DONE, NEED_NORMALS, NEED_UNIFORMS = 0, 1, 2


def size(delay: int) -> int:
    """Length of the state array of a camera ``delay`` frames late."""
    return RING + REC * (delay + 1)


@kernel
def _capture(cs, r, k, x):  # type: ignore[no-untyped-def]
    """Keypoint ``k`` of the frame record at ``cs[r:]``: the true point ``x`` (size 0: not given)
    plus its AR(1) noise, ``n = sigma z`` at its first draw (or a change of dimension), then
    ``n = rho n + c z``."""
    dim = x.shape[0]
    cs[r + R_DIM + k] = dim
    p = r + R_PTS + 3 * k
    sigma = cs[PAR + 3 * k]
    if sigma > 0.0:
        rho, c, nz = cs[PAR + 3 * k + 1], cs[PAR + 3 * k + 2], NOISE + 4 * k
        fresh = cs[nz] != dim
        for j in range(dim):
            i = int(cs[ZI])
            cs[ZI] = i + 1
            if fresh:
                n = sigma * cs[Z + i]
            else:
                n = rho * cs[nz + 1 + j] + c * cs[Z + i]
            cs[nz + 1 + j] = n
            cs[p + j] = x[j] + n
        if dim > 0:
            cs[nz] = dim
    else:
        for j in range(dim):
            cs[p + j] = x[j]


@kernel
def _copy(cs, dst, src):  # type: ignore[no-untyped-def]
    for j in range(REC):
        cs[dst + j] = cs[src + j]


@kernel
def camera_frame(cs, t, hand, pelvis):  # type: ignore[no-untyped-def]
    """Capture the true keypoints at ``t`` (``hand``, ``pelvis``: 2 or 3 numbers, or none) and
    put the frame delivered at ``t`` in ``cs[OUT:]``. Returns :data:`DONE`, or
    :data:`NEED_NORMALS` / :data:`NEED_UNIFORMS` with nothing changed (the caller draws and calls
    again)."""
    need = 0
    if cs[PAR] > 0.0:
        need += hand.shape[0]
    if cs[PAR + 3] > 0.0:
        need += pelvis.shape[0]
    if cs[ZI] + need > cs[ZN]:
        return NEED_NORMALS
    draws_loss = cs[START] > 0.0
    if draws_loss and cs[UI] >= cs[UN]:
        return NEED_UNIFORMS
    cs[T_LAST] = t
    delay = int(cs[DELAY])
    head, count = int(cs[HEAD]), int(cs[COUNT])
    if count <= delay:  # the queue keeps the last delay + 1 frames
        r = RING + REC * ((head + count) % (delay + 1))
        count += 1
    else:
        r = RING + REC * head
        head = (head + 1) % (delay + 1)
    cs[HEAD], cs[COUNT] = head, count
    cs[r + R_T] = t
    _capture(cs, r, 0, hand)
    _capture(cs, r, 1, pelvis)
    lost = False
    if draws_loss:  # the two-state chain: P(lost) is STAY after a lost frame, else START
        i = int(cs[UI])
        cs[UI] = i + 1
        lost = cs[U + i] < (cs[STAY] if cs[LOST] != 0.0 else cs[START])
        cs[LOST] = 1.0 if lost else 0.0
    cs[r + R_TRACKED] = 0.0 if lost else 1.0
    first = RING + REC * head  # the oldest frame kept: captured delay frames ago
    if count <= delay:  # nothing delivered yet: the earliest capture, untracked
        _copy(cs, OUT, first)
        cs[OUT + R_TRACKED] = 0.0
    elif cs[first + R_TRACKED] != 0.0:
        _copy(cs, HELD, first)
        cs[HAVE_HELD] = 1.0
        _copy(cs, OUT, first)
    elif cs[HAVE_HELD] != 0.0:  # lost: the last tracked frame again, untracked
        _copy(cs, OUT, HELD)
        cs[OUT + R_TRACKED] = 0.0
    else:
        _copy(cs, OUT, first)
    return DONE
