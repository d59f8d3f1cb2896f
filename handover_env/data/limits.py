"""Documented bounds on what a dataset file may declare, checked before anything is allocated.

Every bound is far above the real data (the 875-recording development copy of the public dataset:
largest pickle 0.47 MiB, at most 287 frames per recording, 112,566 frames in all, 47 memo entries
and nesting depth 3 per pickle, coordinates within a few metres of the giver), so no real or
synthetic file comes near them; a crafted file that declares more is refused with an error naming
the file and the bound, before the memory is requested.
"""

from __future__ import annotations

MIB = 1 << 20

#: Frames of one recording or episode (55 min at 30 Hz; the real maximum is 287).
MAX_FRAMES = 100_000
#: Frames of a whole ``.npz`` dataset (about 90 times the real set's 112,566).
MAX_TOTAL_FRAMES = 10_000_000
#: Episodes of one ``.npz`` dataset.
MAX_EPISODES = 1_000_000
#: Characters of an episode id or a dataset name.
MAX_ID_CHARS = 256

#: Size on disk of one public-dataset pickle (the largest real one is 0.47 MiB).
MAX_PICKLE_BYTES = 256 * MIB
#: Bytes of one array a pickle may declare.
MAX_ARRAY_BYTES = 256 * MIB
#: Opcodes in one pickle (a real one has about 200).
MAX_PICKLE_OPCODES = 1_000_000
#: Memo entries and the largest memo index of one pickle (real: 47).
MAX_MEMO_ENTRIES = 4096
#: Nesting depth of tuples, dicts and lists in one pickle (real: 3).
MAX_PICKLE_DEPTH = 16
#: Entries of the recording's dict (real: 4).
MAX_RECORD_KEYS = 64

#: Size on disk of one ``.npz`` dataset file.
MAX_NPZ_BYTES = 4096 * MIB
#: Members of one ``.npz`` (we write 10).
MAX_NPZ_MEMBERS = 64
#: Declared (uncompressed) bytes of one ``.npz`` member we read.
MAX_NPZ_MEMBER_BYTES = 512 * MIB
#: Declared bytes of all the ``.npz`` members we read together.
MAX_NPZ_TOTAL_BYTES = 1536 * MIB

#: Largest absolute coordinate of a position (receiver, hand, giver), metres: a room, not a planet.
MAX_ABS_COORD_M = 100.0
#: Smallest norm of an object quaternion before normalisation.
MIN_QUAT_NORM = 1e-6
#: Shortest bone of a recorded skeleton in any frame, m: a joint to its BODY_34 parent, a
#: segment's bone, or the hip, shoulder and ear lines that turn the pelvis, torso and head. The
#: development copy's shortest is 21 mm (in any frame; 42 mm as a per-recording median), so 5 mm
#: only refuses collapsed (e.g. all-zero) skeletons.
MIN_BONE_M = 0.005
