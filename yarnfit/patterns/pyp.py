"""Reading and writing HYLC/MADYPG ``.pyp`` periodic yarn patterns.

A ``.pyp`` file is plain text made of blocks. A block starts with a header line ``*Name`` and holds
one row of whitespace-separated numbers per line; text after ``#`` is a comment and blank lines are
ignored. The blocks (any order; the first three are required):

===========  ====================  =================================================================
block        columns               meaning (SI units: m, rad)
===========  ====================  =================================================================
``*pattern`` ``px py radius N``    one row: repeat size (m), yarn radius (m), number of vertices
``*Q``       ``x y z t``           N rows: vertex position (m) and twist angle of its outgoing edge
``*E``       ``v0 v1 dx dy``       N rows: edge from vertex v0 to vertex v1 of the tile (dx, dy)
``*RL``      ``l``                 N rows: rest length of the edge leaving each vertex (m)
``*RK``      ``k1 k2``             N rows: rest curvature at each vertex (1/m)
``*RT``      ``t``                 N rows: rest twist at each vertex (rad)
``*RefD1``   ``x y z``             N rows: reference director of the edge leaving each vertex
``*RefT``    ``t``                 N rows: reference twist at each vertex (rad)
===========  ====================  =================================================================

Every per-row block except ``*E`` is indexed by vertex: row ``i`` belongs to vertex ``i`` (for
``*RL`` and ``*RefD1``, to the edge leaving vertex ``i``), which is the layout of
:class:`~yarnfit.patterns.base.YarnPattern`. ``*E`` rows need not be in vertex order; their order
is kept so that a file read and written back is unchanged.

Every malformed input raises :class:`~yarnfit.patterns.base.PatternError` with a one-line message
``source:line: problem`` (or ``source: problem`` where no single line is to blame).
"""

from __future__ import annotations

import dataclasses
import math
import os
import re
from dataclasses import dataclass, field

import numpy as np

from .base import PatternError, YarnPattern, by_source, edge_vectors, transported_directors

# Block name -> (column labels, header comment written by format_pyp). The order is the order in
# which format_pyp writes the blocks (that of the HYLC files); the comments are stocktiny.pyp's.
_BLOCKS: dict[str, tuple[tuple[str, ...], str]] = {
    "pattern": (("px", "py", "radius", "num_vertedges"), "px py radius num_vertedges"),
    "Q": (("x", "y", "z", "t"), "dofs: x y z t"),
    "E": (("v0", "v1", "dx", "dy"), "edges: v0 v1 dx dy"),
    "RL": (("rest length",), "rest lengths"),
    "RK": (("k1", "k2"), "rest kappas"),
    "RT": (("rest twist",), "rest twists"),
    "RefD1": (("x", "y", "z"), "reference directors"),
    "RefT": (("reference twist",), "reference twists"),
}
_REQUIRED = ("pattern", "Q", "E")

# Columns that hold integers, with the name used when a value is not one.
_INTEGER_COLUMNS: dict[str, dict[int, str]] = {
    "pattern": {3: "num_vertedges"},
    "E": {0: "edge index", 1: "edge index", 2: "tile offset", 3: "tile offset"},
}

# A decimal floating-point literal (what C's printf and Python's repr write). Stricter than
# float(), which would also take "nan", "inf", "1_000" and non-ASCII digits.
_NUMBER = re.compile(r"[+-]?(?:\d+\.?\d*|\.\d+)(?:[eE][+-]?\d+)?")
# Lines end in \n, \r\n or \r; str.splitlines would also split at form feeds and other
# separators, and the line numbers in messages would then disagree with a text editor's.
_LINE_BREAK = re.compile(r"\r\n|\r|\n")


@dataclass
class _Block:
    """One block as read: its header line and its data rows (line number, tokens)."""

    name: str
    line: int
    rows: list[tuple[int, list[str]]] = field(default_factory=list)


class _Reader:
    """Formats ``source:line: message`` errors for one input."""

    def __init__(self, source: str):
        self.source = source

    def error(self, line: int | None, message: str) -> PatternError:
        where = self.source if line is None else f"{self.source}:{line}"
        return PatternError(f"{where}: {message}")


def _count(number: int, noun: str) -> str:
    return f"{number} {noun}" if number == 1 else f"{number} {noun}s"


def _show(token: str) -> str:
    """A token quoted for a message: escaped (one line) and cut short if very long."""
    text = repr(token)
    return text if len(text) <= 40 else text[:36] + "...'"


# -- reading ----------------------------------------------------------------------------------------


def read_pyp(path: str | os.PathLike) -> YarnPattern:
    """Read a ``.pyp`` file; the pattern is named after the file stem.

    Raises:
        PatternError: the file is not valid UTF-8 text or not a valid pattern (one-line message
            starting with ``path:line:``).
        OSError: the file cannot be read.
    """
    source = os.fspath(path)
    with open(path, "rb") as stream:
        data = stream.read()
    try:
        text = data.decode("utf-8-sig")
    except UnicodeDecodeError as err:
        raise PatternError(f"{source}: not UTF-8 text ({err.reason} at byte {err.start})") from None
    name = os.path.splitext(os.path.basename(source))[0]
    return parse_pyp(text, name, source)


def parse_pyp(text: str, name: str, source: str = "<string>") -> YarnPattern:
    """Parse the text of a ``.pyp`` file into a validated :class:`YarnPattern`.

    Args:
        text: file contents (any line ending).
        name: the pattern's name.
        source: where the text came from, used as the prefix of error messages.

    Missing optional blocks get the data of the given geometry taken as the rest state: rest
    lengths are the edge lengths (m), rest curvatures and twists zero, reference directors
    parallel transported along each yarn. The family is inferred from the yarns' net offsets
    (see :func:`_infer_family`).

    Raises:
        PatternError: malformed text or an invalid pattern; the one-line message names ``source``,
            the line where that applies, and the problem.
    """
    reader = _Reader(source)
    blocks = _split_blocks(text.lstrip("\ufeff"), reader)
    for key in _REQUIRED:
        if key not in blocks:
            raise reader.error(None, f"missing required block *{key}")

    header = blocks["pattern"]
    if len(header.rows) != 1:
        raise reader.error(header.line, f"block *pattern has {_count(len(header.rows), 'row')}, expected 1")
    line, tokens = header.rows[0]
    px, py, radius = (_float(token, line, reader) for token in tokens[:3])
    n = _integer(tokens[3], line, "num_vertedges", reader)
    for value, what in ((px, "repeat size px"), (py, "repeat size py"), (radius, "radius")):
        if not value > 0.0:
            raise reader.error(line, f"{what} must be positive, got {value!r}")
    if n < 1:
        raise reader.error(line, f"num_vertedges must be at least 1, got {n}")
    if "E" in blocks and len(blocks["E"].rows) < n:
        # Fewer edges than vertices: name the yarn end that goes nowhere.
        listed = _edges(blocks["E"], n, reader)
        free = sorted(set(range(n)) - set(listed[:, 0].tolist()))
        raise reader.error(blocks["E"].line, f"dangling yarn end: vertex {free[0]} starts no edge "
                                             f"(block *E has {_count(len(listed), 'row')} for {n} vertices)")
    for block in blocks.values():
        if block.name != "pattern" and len(block.rows) != n:
            raise reader.error(block.line, f"block *{block.name} has {_count(len(block.rows), 'row')}, header says {n}")

    q = _float_array(blocks["Q"], reader)
    node_position = np.ascontiguousarray(q[:, :3])
    node_twist = np.ascontiguousarray(q[:, 3])
    edges = _edges(blocks["E"], n, reader)
    vectors = edge_vectors(node_position, edges, (px, py))
    lengths = np.linalg.norm(vectors, axis=1)
    # Checked here rather than left to validate() so that the message can name the line, and
    # because the default directors below divide by the edge lengths.
    zero = np.flatnonzero(lengths <= 0.0)
    if zero.size:
        row = int(zero[0])
        v0, v1 = int(edges[row, 0]), int(edges[row, 1])
        raise reader.error(blocks["E"].rows[row][0], f"edge {v0} -> {v1} has zero length (the two vertices coincide)")

    def optional(key: str, default) -> np.ndarray:
        if key not in blocks:
            return default()
        values = _float_array(blocks[key], reader)
        return values[:, 0].copy() if values.shape[1] == 1 else values

    pattern = YarnPattern(
        name=name,
        family="other",  # provisional: the family is inferred from the yarns once they are known
        repeat_size=np.array([px, py]),
        radius=radius,
        node_position=node_position,
        edges=edges,
        node_twist=node_twist,
        rest_length=optional("RL", lambda: by_source(lengths, edges)),
        rest_curvature=optional("RK", lambda: np.zeros((n, 2))),
        rest_twist=optional("RT", lambda: np.zeros(n)),
        reference_director=optional("RefD1", lambda: transported_directors(vectors, edges)),
        reference_twist=optional("RefT", lambda: np.zeros(n)),
    )
    _validate(pattern, reader)
    pattern = dataclasses.replace(pattern, family=_infer_family(pattern))
    _validate(pattern, reader)
    return pattern


def _split_blocks(text: str, reader: _Reader) -> dict[str, _Block]:
    """Group the data lines into blocks, checking names, column counts and number syntax."""
    blocks: dict[str, _Block] = {}
    block: _Block | None = None
    for line, raw in enumerate(_LINE_BREAK.split(text), start=1):
        content = raw.split("#", 1)[0]
        tokens = content.split()
        if not tokens:
            continue
        if tokens[0].startswith("*"):
            key = tokens[0][1:]
            if key not in _BLOCKS:
                raise reader.error(line, f"unknown block {_show(tokens[0])}")
            if len(tokens) > 1:
                raise reader.error(line, f"unexpected text {_show(tokens[1])} after block name *{key}")
            if key in blocks:
                raise reader.error(line, f"duplicate block *{key} (first on line {blocks[key].line})")
            block = blocks[key] = _Block(key, line)
            continue
        if block is None:
            raise reader.error(line, "data line before any block")
        columns = _BLOCKS[block.name][0]
        if len(tokens) != len(columns):
            raise reader.error(
                line,
                f"*{block.name} row has {_count(len(tokens), 'value')}, expected {len(columns)} ({' '.join(columns)})",
            )
        # Check every value now, so that errors come in line order whatever the block order.
        integer_columns = _INTEGER_COLUMNS.get(block.name, {})
        for column, token in enumerate(tokens):
            if column in integer_columns:
                _integer(token, line, integer_columns[column], reader)
            else:
                _float(token, line, reader)
        block.rows.append((line, tokens))
    return blocks


def _float(token: str, line: int, reader: _Reader) -> float:
    if not _NUMBER.fullmatch(token):
        raise reader.error(line, f"value {_show(token)} is not a number")
    value = float(token)
    if not math.isfinite(value):
        raise reader.error(line, f"value {_show(token)} is out of the floating-point range")
    return value


def _integer(token: str, line: int, what: str, reader: _Reader) -> int:
    """An integer column; an integral decimal such as ``1.0`` is accepted (some writers use
    floating-point formats throughout)."""
    value = _float(token, line, reader)
    if not value.is_integer():
        raise reader.error(line, f"{what} must be an integer, got {_show(token)}")
    return int(value)


def _float_array(block: _Block, reader: _Reader) -> np.ndarray:
    """The block's rows as a float64 ``(rows, columns)`` array."""
    return np.array([[_float(token, line, reader) for token in tokens] for line, tokens in block.rows], dtype=np.float64)


def _edges(block: _Block, n: int, reader: _Reader) -> np.ndarray:
    """The ``*E`` rows as an ``(n, 4)`` int64 array in file order, after checking that they form
    a permutation of the vertices (every vertex starts one edge and ends one) with offsets of at
    most one tile."""
    edges = np.empty((len(block.rows), 4), dtype=np.int64)
    starts: dict[int, int] = {}  # vertex -> line of the edge leaving it
    ends: dict[int, int] = {}  # vertex -> line of the edge entering it
    for row, (line, tokens) in enumerate(block.rows):
        names = _INTEGER_COLUMNS["E"]
        v0, v1, dx, dy = (_integer(token, line, names[column], reader) for column, token in enumerate(tokens))
        for vertex in (v0, v1):
            if not 0 <= vertex < n:
                raise reader.error(line, f"edge index {vertex} out of range 0..{n - 1}")
        for offset in (dx, dy):
            if abs(offset) > 1:
                raise reader.error(line, f"tile offset {offset} out of range -1..1 (an edge reaches a neighbouring tile at most)")
        # With n rows, unique sources and unique targets make the edges a permutation: no dangling
        # yarn end can remain, so these are the only connectivity errors a file can have.
        if v0 in starts:
            raise reader.error(line, f"vertex {v0} starts a second edge (first on line {starts[v0]}); a yarn cannot branch")
        if v1 in ends:
            raise reader.error(line, f"vertex {v1} ends a second edge (first on line {ends[v1]}); a yarn cannot branch")
        starts[v0] = ends[v1] = line
        edges[row] = (v0, v1, dx, dy)
    return edges


def _validate(pattern: YarnPattern, reader: _Reader) -> None:
    """``pattern.validate()``, with the source prefixed to its message."""
    try:
        pattern.validate()
    except PatternError as err:
        raise reader.error(None, str(err)) from err


def _infer_family(pattern: YarnPattern) -> str:
    """``"woven"`` if some yarn runs along x (net offset ``(±1, 0)``) and some along y
    (``(0, ±1)``); ``"knit"`` if every yarn runs along x (the course direction); else
    ``"other"``. The pattern must be valid (its edges a permutation of the nodes)."""
    offsets = {yarn.net_offset for yarn in pattern.yarns()}
    along_x = {(1, 0), (-1, 0)}
    along_y = {(0, 1), (0, -1)}
    if offsets & along_x and offsets & along_y:
        return "woven"
    if offsets <= along_x:
        return "knit"
    return "other"


# -- writing ----------------------------------------------------------------------------------------


def format_pyp(pattern: YarnPattern) -> str:
    """The ``.pyp`` text of a pattern: all eight blocks, one row per line, edges in the pattern's
    row order.

    Floats are written as Python's shortest round-trip representation, so reading the text back
    gives bit-identical arrays. The family is not stored (the format has no field for it); reading
    infers it from the yarns.

    Raises:
        PatternError: the pattern is invalid (a file that could not be read back is never written).
    """
    pattern.validate()
    px, py = pattern.repeat_size
    n = pattern.n_nodes
    rows = {
        "pattern": [(_f(px), _f(py), _f(pattern.radius), str(n))],
        "Q": _float_rows(np.column_stack([pattern.node_position, pattern.node_twist])),
        "E": [tuple(str(int(v)) for v in edge) for edge in pattern.edges],
        "RL": _float_rows(pattern.rest_length[:, None]),
        "RK": _float_rows(pattern.rest_curvature),
        "RT": _float_rows(pattern.rest_twist[:, None]),
        "RefD1": _float_rows(pattern.reference_director),
        "RefT": _float_rows(pattern.reference_twist[:, None]),
    }
    parts = []
    for key, (_, comment) in _BLOCKS.items():
        lines = [f"*{key} # {comment}"]
        lines += [" ".join(row) for row in rows[key]]
        parts.append("\n".join(lines) + "\n")
    return "\n".join(parts)


def write_pyp(pattern: YarnPattern, path: str | os.PathLike) -> None:
    """Write a pattern to a ``.pyp`` file (see :func:`format_pyp`); ``\\n`` line endings."""
    text = format_pyp(pattern)
    with open(path, "w", encoding="utf-8", newline="\n") as stream:
        stream.write(text)


def _f(value) -> str:
    # repr of a Python float is the shortest string that parses back to the same double.
    return repr(float(value))


def _float_rows(values: np.ndarray) -> list[tuple[str, ...]]:
    return [tuple(_f(v) for v in row) for row in values]
