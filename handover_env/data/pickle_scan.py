"""Static check of a public-dataset pickle before it is unpickled: nothing in it runs, nothing is
allocated.

A recording is a ``dict`` of numpy arrays. Rebuilding one needs a handful of opcodes and three
calls (``numpy._core.multiarray._reconstruct``, ``numpy.dtype``, ``numpy.ndarray.__setstate__``),
or at protocol 5 two (``numpy.dtype`` and ``numpy._core.numeric._frombuffer`` on an in-band
buffer), plus ``numpy._core.multiarray.scalar`` for numpy scalars. :func:`scan_pickle` walks the
opcode stream with :func:`pickletools.genops` (which only parses) and simulates the unpickler's
stack with placeholders, so that before :class:`~handover_env.data.public.SafeUnpickler` runs
anything:

* every global is one of numpy's array-rebuilding functions, and it is called only the way numpy
  calls it (``_reconstruct(ndarray, (0,), b"b")``, ``dtype(code, False, True)`` with a plain
  numeric or string type code, ``scalar(dtype, bytes)``, ``_frombuffer(bytes, dtype, shape,
  "C" or "F")``); ``ndarray`` itself is never called. ``dtype(code, False, False)`` (copy=False)
  is refused: it returns numpy's shared built-in dtype, whose byte order a later ``BUILD`` cannot
  change, so big-endian bytes would be read as little-endian numbers without an error;
* ``BUILD`` sets an array's state (and ``_frombuffer`` takes a shape) only to a shape whose size
  matches bytes that are really in the file (at most
  :data:`~handover_env.data.limits.MAX_ARRAY_BYTES`), and a dtype's state only to a plain one (no
  fields, no names, no sub-array) with a byte order ``<``, ``>``, ``|`` or ``=``, which numpy
  honours;
* tuples, dicts and lists nest at most :data:`~handover_env.data.limits.MAX_PICKLE_DEPTH` deep (a
  tuple nested 200,000 deep crashes CPython when it is hashed as a dict key), dicts and lists are
  never nested in anything (so their depth cannot grow after it was checked), and dict keys are
  strings;
* the memo holds at most :data:`~handover_env.data.limits.MAX_MEMO_ENTRIES` entries at indices
  below that bound (the C unpickler sizes its memo table by the largest index: a 9-byte pickle
  asked it for 1.2 GB), and the stream has at most
  :data:`~handover_env.data.limits.MAX_PICKLE_OPCODES` opcodes.

Protocols 3 to 5 are read (numpy's protocol-2 array pickles call ``_codecs.encode``, which is not
allowed). Any other opcode (sets, ``NEWOBJ``, persistent ids, protocol 5's out-of-band buffers
``NEXT_BUFFER``/``READONLY_BUFFER``, ...) is refused: numpy's in-band array pickles at protocols
3-5 never use one.
"""

from __future__ import annotations

import math
import pickletools
import re
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from handover_env.data.errors import DatasetError
from handover_env.data.limits import (
    MAX_ARRAY_BYTES,
    MAX_MEMO_ENTRIES,
    MAX_PICKLE_DEPTH,
    MAX_PICKLE_OPCODES,
    MAX_RECORD_KEYS,
)


class UnsafePickleError(DatasetError):
    """A pickle referenced a global outside numpy's array rebuilding; nothing in it was run."""


#: The globals a recording may name, by role.
RECONSTRUCT = {
    ("numpy.core.multiarray", "_reconstruct"),
    ("numpy._core.multiarray", "_reconstruct"),
}
SCALAR = {("numpy.core.multiarray", "scalar"), ("numpy._core.multiarray", "scalar")}
#: Protocol 5: ``ndarray.__reduce_ex__(5)`` pickles a contiguous array as
#: ``_frombuffer(PickleBuffer, dtype, shape, order)``; in band, the buffer is a bytearray or bytes.
FROMBUFFER = {("numpy.core.numeric", "_frombuffer"), ("numpy._core.numeric", "_frombuffer")}
NDARRAY = {("numpy", "ndarray")}
DTYPE = {("numpy", "dtype")}
ALLOWED_NAMES = RECONSTRUCT | SCALAR | FROMBUFFER | NDARRAY | DTYPE

#: dtype codes a recording may use: booleans, integers, floats, and fixed-width strings (which the
#: record validation then refuses with its own message). No objects, voids or structured types.
_DTYPE_CODE = re.compile(r"(b1|[iu][1248]|f[248]|[US][0-9]{1,6})", re.ASCII)
_BYTE_ORDERS = {"<", ">", "|", "="}
_MAX_SHAPE_DIMS = 8
_MAX_DTYPE_ELSIZE = 1 << 20
_MAX_LEAF_CHARS = 4096  # longer strings/bytes are kept by length only (they can name nothing)

_CONSTANTS = {"NONE": None, "NEWTRUE": True, "NEWFALSE": False}
_INTS = {"BININT", "BININT1", "BININT2", "LONG1"}
_STRS = {"SHORT_BINUNICODE", "BINUNICODE", "BINUNICODE8"}
_BYTES = {"SHORT_BINBYTES", "BINBYTES", "BINBYTES8", "SHORT_BINSTRING", "BINSTRING", "BYTEARRAY8"}
_OUT_OF_BAND = {"NEXT_BUFFER", "READONLY_BUFFER"}
_PUTS = {"PUT", "BINPUT", "LONG_BINPUT"}
_GETS = {"GET", "BINGET", "LONG_BINGET"}


@dataclass
class _Item:
    """A placeholder for one object on the simulated stack.

    kind: const, int, float, str, bytes, tuple, dict, list, global, array, dtype, scalar.
    value: the value of small constants, ints, strings and bytes; the items of a tuple; the
        ``(module, name)`` of a global; the type code of a dtype.
    """

    kind: str
    value: Any = None
    depth: int = 0
    size: int = 0  # bytes of a bytes object; entries of a dict or list
    built: bool = False
    itemsize: int = 0  # of a dtype
    extra: dict = field(default_factory=dict)


class _Refused(Exception):
    """Internal: the reason a pickle is refused (turned into a DatasetError naming the file)."""


def scan_pickle(data: bytes, source: str) -> None:
    """Check the opcode stream of a recording pickle; raise if unpickling it could do harm.

    Args:
        data: the whole file.
        source: the file's name, used in error messages.

    Raises:
        UnsafePickleError: the pickle names a global other than numpy's array rebuilding.
        DatasetError: the pickle is truncated or malformed, uses an opcode or a call numpy's
            array pickles never use, or exceeds one of the bounds of
            :mod:`handover_env.data.limits`; the message names the file and the reason.
    """
    try:
        _Scanner(source).run(data)
    except UnsafePickleError:
        raise
    except _Refused as exc:
        raise DatasetError(
            f"{source}: refused to load: {exc}; nothing in the file was run"
        ) from None
    except (ValueError, EOFError) as exc:  # pickletools: truncated argument, unknown opcode
        text = str(exc)
        if "but only" in text or "no newline" in text or "EOF" in text or not data:
            raise DatasetError(
                f"{source}: truncated pickle ({len(data)} bytes; ended early)"
            ) from None
        raise DatasetError(f"{source}: not a readable pickle ({text})") from None


class _Scanner:
    def __init__(self, source: str) -> None:
        self.source = source
        self.stack: list[_Item] = []
        self.marks: list[int] = []
        self.memo: dict[int, _Item] = {}

    # ------------------------------------------------------------------ stack helpers
    def fence(self) -> int:
        """Stack height at the innermost MARK (nothing below it may be popped)."""
        return self.marks[-1] if self.marks else 0

    def pop(self, op: str) -> _Item:
        if len(self.stack) <= self.fence():
            raise _Refused(f"{op} on an empty stack or past a MARK")
        return self.stack.pop()

    def pop_mark(self, op: str) -> list[_Item]:
        if not self.marks:
            raise _Refused(f"{op} without a MARK")
        start = self.marks.pop()
        items = self.stack[start:]
        del self.stack[start:]
        return items

    def push(self, item: _Item) -> None:
        if item.depth > MAX_PICKLE_DEPTH:
            raise _Refused(f"objects nested {item.depth} deep (at most {MAX_PICKLE_DEPTH})")
        self.stack.append(item)

    @staticmethod
    def child(item: _Item, where: str) -> _Item:
        if item.kind in ("dict", "list"):
            raise _Refused(f"a {item.kind} inside {where} (a recording nests no dicts or lists)")
        return item

    def tuple_of(self, items: list[_Item]) -> _Item:
        items = [self.child(i, "a tuple") for i in items]
        depth = 1 + max((i.depth for i in items), default=0)
        return _Item("tuple", tuple(items), depth=depth)

    # ------------------------------------------------------------------ the walk
    def run(self, data: bytes) -> None:
        if not data:
            raise _Refused("empty stream")
        stopped = False
        for count, (opcode, arg, pos) in enumerate(pickletools.genops(data), start=1):
            if count > MAX_PICKLE_OPCODES:
                raise _Refused(f"more than {MAX_PICKLE_OPCODES:,} opcodes")
            name = opcode.name
            if count == 1 and name != "PROTO":
                raise ValueError(
                    f"it does not start with a pickle protocol header (first opcode {name})"
                )
            try:
                self.step(name, arg)
            except _Refused as exc:
                raise _Refused(f"{exc} (opcode {name} at byte {pos})") from None
            if name == "STOP":
                stopped = True
                break
        if not stopped:
            raise EOFError("EOF before STOP")

    def step(self, name: str, arg: Any) -> None:
        if name == "PROTO":
            if not 3 <= int(arg) <= 5:
                raise _Refused(f"pickle protocol {arg} (this loader reads 3 to 5)")
        elif name == "FRAME":
            pass
        elif name in _OUT_OF_BAND:
            raise _Refused(
                f"an out-of-band buffer ({name}); a file must hold its arrays' bytes in band"
            )
        elif name == "STOP":
            if len(self.stack) != 1 or self.marks:
                raise _Refused("the stream does not end with exactly one object")
        elif name == "MARK":
            self.marks.append(len(self.stack))
        elif name in _CONSTANTS:
            self.push(_Item("const", _CONSTANTS[name]))
        elif name in _INTS:
            if name == "LONG1" and abs(int(arg)).bit_length() > 64:
                raise _Refused("an integer wider than 64 bits")
            self.push(_Item("int", int(arg)))
        elif name == "BINFLOAT":
            self.push(_Item("float", float(arg)))
        elif name in _STRS:
            self.push(_Item("str", arg if len(arg) <= _MAX_LEAF_CHARS else None, size=len(arg)))
        elif name in _BYTES:
            raw = arg.encode("latin-1") if isinstance(arg, str) else bytes(arg)
            self.push(_Item("bytes", raw if len(raw) <= _MAX_LEAF_CHARS else None, size=len(raw)))
        elif name == "EMPTY_TUPLE":
            self.push(_Item("tuple", (), depth=1))
        elif name in ("TUPLE1", "TUPLE2", "TUPLE3"):
            n = int(name[-1])
            items = [self.pop(name) for _ in range(n)][::-1]
            self.push(self.tuple_of(items))
        elif name == "TUPLE":
            self.push(self.tuple_of(self.pop_mark(name)))
        elif name in ("EMPTY_DICT", "EMPTY_LIST"):
            self.push(_Item(name[6:].lower(), depth=1))
        elif name == "DICT":
            container = _Item("dict", depth=1)
            self._fill(container, self.pop_mark(name), name)
            self.push(container)
        elif name == "LIST":
            container = _Item("list", depth=1)
            self._fill(container, self.pop_mark(name), name)
            self.push(container)
        elif name in ("SETITEM", "APPEND"):
            n = 2 if name == "SETITEM" else 1
            items = [self.pop(name) for _ in range(n)][::-1]
            self._fill(self._container(name), items, name)
        elif name in ("SETITEMS", "APPENDS"):
            items = self.pop_mark(name)
            self._fill(self._container(name), items, name)
        elif name == "GLOBAL":
            module, _, attr = str(arg).partition(" ")
            self.push(self._global(module, attr))
        elif name == "STACK_GLOBAL":
            attr, module = self.pop(name), self.pop(name)
            if (
                module.kind != "str"
                or attr.kind != "str"
                or module.value is None
                or attr.value is None
            ):
                raise _Refused("STACK_GLOBAL on something other than two short strings")
            self.push(self._global(module.value, attr.value))
        elif name == "REDUCE":
            args, func = self.pop(name), self.pop(name)
            self.push(self._reduce(func, args))
        elif name == "BUILD":
            state = self.pop(name)
            target = self.pop(name)
            self._build(target, state)
            self.push(target)
        elif name == "MEMOIZE":
            self._put(len(self.memo))
        elif name in _PUTS:
            self._put(int(arg))
        elif name in _GETS:
            index = int(arg)
            if index not in self.memo:
                raise _Refused(f"memo index {index} read before it was written")
            self.push(self.memo[index])
        else:
            raise _Refused(f"opcode {name}, which numpy's array pickles never use")

    # ------------------------------------------------------------------ containers and memo
    def _container(self, op: str) -> _Item:
        top = self.stack[-1] if len(self.stack) > self.fence() else None
        if top is None or top.kind not in ("dict", "list"):
            raise _Refused(f"{op} on a {top.kind if top else 'missing'} object")
        if (op.startswith("SET")) != (top.kind == "dict"):
            raise _Refused(f"{op} on a {top.kind}")
        return top

    def _fill(self, container: _Item, items: list[_Item], op: str) -> None:
        if container.kind == "dict":
            if len(items) % 2:
                raise _Refused(f"{op} with an odd number of items")
            keys, values = items[0::2], items[1::2]
            for key in keys:
                if key.kind != "str":
                    raise _Refused(f"a dict key of kind {key.kind} (recording keys are strings)")
            children = values
        else:
            children = items
        for c in children:
            self.child(c, f"a {container.kind}")
        container.size += len(children)
        if container.size > MAX_RECORD_KEYS:
            raise _Refused(f"a {container.kind} of more than {MAX_RECORD_KEYS} entries")
        container.depth = max(container.depth, 1 + max((c.depth for c in children), default=0))
        if container.depth > MAX_PICKLE_DEPTH:
            raise _Refused(f"objects nested {container.depth} deep (at most {MAX_PICKLE_DEPTH})")

    def _put(self, index: int) -> None:
        if len(self.stack) <= self.fence():
            raise _Refused("memo write with nothing to store")
        if not 0 <= index < MAX_MEMO_ENTRIES:
            raise _Refused(f"memo index {index} (at most {MAX_MEMO_ENTRIES - 1})")
        if len(self.memo) >= MAX_MEMO_ENTRIES and index not in self.memo:
            raise _Refused(f"more than {MAX_MEMO_ENTRIES} memo entries")
        self.memo[index] = self.stack[-1]

    # ------------------------------------------------------------------ calls
    def _global(self, module: str, attr: str) -> _Item:
        if (module, attr) not in ALLOWED_NAMES:
            raise UnsafePickleError(
                f"{self.source}: refused to load: the pickle references the global "
                f"{module}.{attr}, which is not one of numpy's array-rebuilding functions; "
                f"nothing in the file was run"
            )
        return _Item("global", (module, attr))

    def _reduce(self, func: _Item, args: _Item) -> _Item:
        if func.kind != "global":
            raise _Refused(f"REDUCE calls a {func.kind}")
        if args.kind != "tuple":
            raise _Refused("REDUCE with arguments that are not a tuple")
        key, a = func.value, args.value
        if key in RECONSTRUCT:
            if not (len(a) == 3 and a[0].kind == "global" and a[0].value in NDARRAY
                    and a[1].kind == "tuple" and [i.value for i in a[1].value] == [0]
                    and a[1].value[0].kind == "int" and a[2].kind in ("bytes", "str")
                    and a[2].size <= 8):
                raise _Refused(
                    "_reconstruct called other than as _reconstruct(ndarray, (0,), b'b')"
                )
            return _Item("array")
        if key in DTYPE:
            if not (len(a) == 3 and a[0].kind == "str" and a[0].value is not None
                    and _DTYPE_CODE.fullmatch(a[0].value)
                    and a[1].kind == a[2].kind == "const" and isinstance(a[1].value, bool)
                    and isinstance(a[2].value, bool)):
                code = a[0].value if a and a[0].kind == "str" else "?"
                raise _Refused(f"dtype({code!r}, ...): only plain numeric and string dtypes")
            if a[1].value is not False or a[2].value is not True:
                raise _Refused(
                    f"dtype({a[0].value!r}, align={a[1].value}, copy={a[2].value}): numpy pickles "
                    "dtype(code, False, True); with copy=False the byte order in the dtype's "
                    "state is ignored and the array's bytes would be misread"
                )
            return _Item("dtype", a[0].value, itemsize=np.dtype(a[0].value).itemsize)
        if key in FROMBUFFER:
            if not (len(a) == 4 and a[0].kind == "bytes" and a[1].kind == "dtype" and a[1].built
                    and a[2].kind == "tuple" and a[3].kind == "str" and a[3].value in ("C", "F")):
                raise _Refused(
                    "_frombuffer called other than as _frombuffer(bytes, dtype, shape, 'C' or 'F')"
                )
            self._check_shape(a[2], a[1].itemsize, a[0].size)
            return _Item("array", built=True)
        if key in SCALAR:
            if not (len(a) == 2 and a[0].kind == "dtype" and a[1].kind == "bytes"
                    and a[1].size == a[0].itemsize and a[0].itemsize <= 64):
                raise _Refused("scalar called other than as scalar(dtype, bytes of its size)")
            return _Item("scalar")
        raise _Refused(f"REDUCE calls {key[0]}.{key[1]}, which numpy never calls when unpickling")

    def _build(self, target: _Item, state: _Item) -> None:
        if target.built:
            raise _Refused(f"BUILD on a {target.kind} twice")
        if target.kind == "dtype":
            self._build_dtype(target, state)
        elif target.kind == "array":
            self._build_array(state)
        else:
            raise _Refused(f"BUILD on a {target.kind}")
        target.built = True

    def _build_dtype(self, target: _Item, state: _Item) -> None:
        s = state.value if state.kind == "tuple" else ()
        ok = (
            len(s) == 8
            and s[0].kind == "int" and s[0].value == 3
            and s[1].kind == "str" and s[1].value in _BYTE_ORDERS
            and all(i.kind == "const" and i.value is None for i in s[2:5])
            and all(i.kind == "int" and abs(i.value) <= _MAX_DTYPE_ELSIZE for i in s[5:8])
        )
        if not ok:
            raise _Refused(
                f"a dtype state with fields, names or a sub-array (dtype {target.value!r}); "
                "recordings use plain dtypes"
            )
        elsize = s[5].value
        if elsize > 0:  # flexible types (strings) carry their size in the state
            target.itemsize = elsize

    def _build_array(self, state: _Item) -> None:
        s = state.value if state.kind == "tuple" else ()
        if not (len(s) == 5 and s[0].kind == "int" and s[0].value == 1 and s[1].kind == "tuple"
                and s[2].kind == "dtype" and s[3].kind == "const" and isinstance(s[3].value, bool)
                and s[4].kind == "bytes"):
            raise _Refused("an array state other than (1, shape, dtype, fortran, bytes)")
        self._check_shape(s[1], s[2].itemsize, s[4].size)

    @staticmethod
    def _check_shape(shape_item: _Item, itemsize: int, held: int) -> None:
        """Refuse a shape that is not a few sizes >= 0 whose bytes are exactly the ``held``."""
        dims = shape_item.value
        if len(dims) > _MAX_SHAPE_DIMS or any(d.kind != "int" or d.value < 0 for d in dims):
            raise _Refused(f"an array shape that is not {_MAX_SHAPE_DIMS} or fewer sizes >= 0")
        shape = tuple(d.value for d in dims)
        declared = math.prod(shape) * itemsize
        if declared > MAX_ARRAY_BYTES:
            raise _Refused(
                f"an array of shape {shape} ({declared:,} bytes; at most {MAX_ARRAY_BYTES:,})"
            )
        if declared != held:
            raise _Refused(
                f"an array of shape {shape} declares {declared:,} bytes but the file holds "
                f"{held:,} for it"
            )
