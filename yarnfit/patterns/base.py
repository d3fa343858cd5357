"""Periodic yarn patterns: one repeat of yarn centrelines whose ends connect across tile borders.

The data model follows the HYLC/MADYPG ``.pyp`` format (``yarnfit.patterns.pyp``): every node has
exactly one outgoing edge to a node of the same tile or of a neighbouring ghost tile, so the yarns
are cycles of the periodic structure. Per-node data describes the node's outgoing edge (rest
length, reference director) or the joint at the node (rest curvature and twist).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numpy as np

FAMILIES = ("woven", "knit", "other")
# An edge into a neighbouring tile longer than this many times the yarn's longest edge inside the
# tile is a gap in the tiling. Generated and HYLC repeats stay below 1.5 (their border edges are
# ordinary edges); a repeat size off by a tenth of a period already exceeds 3 for usual edges.
BORDER_EDGE_RATIO = 3.0
_ARRAY_FIELDS = ("repeat_size", "node_position", "edges", "node_twist", "rest_length", "rest_curvature", "rest_twist",
                 "reference_director", "reference_twist")


class PatternError(ValueError):
    """A yarn pattern is malformed (the message names the problem)."""


@dataclass(frozen=True)
class Yarn:
    """One yarn of a pattern: its nodes in order and the tile offset of each node's outgoing edge.

    ``net_offset`` is the sum of the offsets: the tile the yarn reaches after one cycle (a yarn
    running along the weft has ``(1, 0)`` or ``(-1, 0)``).
    """

    nodes: np.ndarray  # (n,) node indices along the yarn
    tiles: np.ndarray  # (n, 2) int: offset of the edge leaving nodes[k]
    net_offset: tuple[int, int]


@dataclass(frozen=True, eq=False)
class YarnPattern:
    """One periodic repeat of a woven or knitted structure (SI units).

    Attributes:
        name: label.
        family: ``"woven"``, ``"knit"`` or ``"other"`` (sets the default shrink factor).
        repeat_size: ``(px, py)`` m, the tile; x is the weft (course) direction, y the warp (wale).
        radius: nominal yarn radius (m).
        node_position: ``(N, 3)`` m.
        edges: ``(N, 4)`` int rows ``(v0, v1, dx, dy)``: the edge from node v0 to node v1 of the tile
            ``(dx, dy)``, i.e. to ``node_position[v1] + (dx px, dy py, 0)``. One row per node; the
            row order is kept as given (for lossless round trips).
        node_twist: ``(N,)`` rad, angle of the material frame of each node's outgoing edge about its
            tangent, measured from ``reference_director``.
        rest_length: ``(N,)`` m, rest length of each node's outgoing edge.
        rest_curvature: ``(N, 2)`` 1/m, rest curvature at each node.
        rest_twist: ``(N,)`` rad, rest twist at each node.
        reference_director: ``(N, 3)``, unit vector normal to each node's outgoing edge.
        reference_twist: ``(N,)`` rad, reference twist at each node.
    """

    name: str
    family: str
    repeat_size: np.ndarray
    radius: float
    node_position: np.ndarray
    edges: np.ndarray
    node_twist: np.ndarray
    rest_length: np.ndarray
    rest_curvature: np.ndarray
    rest_twist: np.ndarray
    reference_director: np.ndarray
    reference_twist: np.ndarray

    def __post_init__(self) -> None:
        # Own read-only copies: a frozen pattern must not change under its users' feet.
        for name in _ARRAY_FIELDS:
            dtype = np.int64 if name == "edges" else np.float64
            value = np.array(getattr(self, name), dtype=dtype)
            value.setflags(write=False)
            object.__setattr__(self, name, value)

    # -- construction -------------------------------------------------------------------------

    @classmethod
    def from_yarns(
        cls,
        name: str,
        family: str,
        repeat_size: tuple[float, float],
        radius: float,
        yarns: list[tuple[np.ndarray, tuple[int, int]]],
    ) -> "YarnPattern":
        """Pattern from yarn polylines, each ``(points (n, 3), net_offset)``.

        The points of a yarn are one period of it; the yarn continues from its last point to its
        first point moved by ``net_offset`` tiles, so the closing edge carries that offset. Rest
        data is that of the given (unrelaxed, straight-rest) geometry: rest lengths are the edge
        lengths, rest curvatures and twists zero, reference directors by parallel transport.
        """
        px, py = (float(v) for v in repeat_size)
        positions, edges = [], []
        start = 0
        for points, net_offset in yarns:
            points = np.asarray(points, dtype=np.float64)
            n = len(points)
            index = start + np.arange(n)
            rows = np.zeros((n, 4), dtype=np.int64)
            rows[:, 0] = index
            rows[:, 1] = np.roll(index, -1)
            rows[-1, 2:] = net_offset
            positions.append(points)
            edges.append(rows)
            start += n
        node_position = np.concatenate(positions)
        edges = np.concatenate(edges)
        vectors = edge_vectors(node_position, edges, (px, py))
        lengths = np.linalg.norm(vectors, axis=1)
        _check_lengths(name, lengths, edges)
        n = len(node_position)
        pattern = cls(
            name=name,
            family=family,
            repeat_size=np.array([px, py]),
            radius=float(radius),
            node_position=node_position,
            edges=edges,
            node_twist=np.zeros(n),
            rest_length=by_source(lengths, edges),
            rest_curvature=np.zeros((n, 2)),
            rest_twist=np.zeros(n),
            reference_director=transported_directors(vectors, edges),
            reference_twist=np.zeros(n),
        )
        pattern.validate()
        return pattern

    # -- derived data -------------------------------------------------------------------------

    @property
    def n_nodes(self) -> int:
        return self.node_position.shape[0]

    @property
    def lattice(self) -> np.ndarray:
        """Tile vectors ``(2, 3)``: ``(px, 0, 0)`` and ``(0, py, 0)``."""
        px, py = self.repeat_size
        return np.array([[px, 0.0, 0.0], [0.0, py, 0.0]])

    def outgoing(self) -> tuple[np.ndarray, np.ndarray]:
        """For every node, the node its outgoing edge reaches and that edge's tile offset:
        ``(next_node (N,), next_tile (N, 2))``."""
        next_node = np.empty(self.n_nodes, dtype=np.int64)
        next_tile = np.empty((self.n_nodes, 2), dtype=np.int64)
        next_node[self.edges[:, 0]] = self.edges[:, 1]
        next_tile[self.edges[:, 0]] = self.edges[:, 2:]
        return next_node, next_tile

    def outgoing_rows(self, nodes: np.ndarray) -> np.ndarray:
        """Row of ``edges`` leaving each of ``nodes``."""
        row = np.empty(self.n_nodes, dtype=np.int64)
        row[self.edges[:, 0]] = np.arange(self.n_nodes)
        return row[np.asarray(nodes, dtype=np.int64)]

    def yarns(self) -> list[Yarn]:
        """The yarns: cycles of the outgoing-edge map, each starting at its lowest node index.
        Needs a valid topology (one edge into and out of every node, see :meth:`validate`)."""
        next_node, next_tile = self.outgoing()
        seen = np.zeros(self.n_nodes, dtype=bool)
        yarns = []
        for first in range(self.n_nodes):
            if seen[first]:
                continue
            nodes = [first]
            seen[first] = True
            node = next_node[first]
            while node != first:
                if seen[node]:
                    raise PatternError(f"pattern {self.name!r}: node {node} lies on two yarns; a yarn cannot branch")
                nodes.append(node)
                seen[node] = True
                node = next_node[node]
            nodes = np.array(nodes, dtype=np.int64)
            tiles = next_tile[nodes]
            net = tiles.sum(axis=0)
            yarns.append(Yarn(nodes, tiles, (int(net[0]), int(net[1]))))
        return yarns

    def yarn_length(self) -> float:
        """Total centreline length of the yarns in one repeat, ``L0`` (m)."""
        return float(np.linalg.norm(edge_vectors(self.node_position, self.edges, self.repeat_size), axis=1).sum())

    # -- transformations ----------------------------------------------------------------------

    def scaled(self, repeat_size: tuple[float, float], radius: float) -> "YarnPattern":
        """The same structure stretched to a new repeat size (x and y scale independently) and
        yarn radius (z scales with the radius). Rest data is reset to the new geometry."""
        sx = repeat_size[0] / self.repeat_size[0]
        sy = repeat_size[1] / self.repeat_size[1]
        sz = radius / self.radius
        position = self.node_position * np.array([sx, sy, sz])
        vectors = edge_vectors(position, self.edges, repeat_size)
        _check_lengths(self.name, np.linalg.norm(vectors, axis=1), self.edges)
        n = self.n_nodes
        pattern = replace(
            self,
            repeat_size=np.array(repeat_size, dtype=np.float64),
            radius=float(radius),
            node_position=position,
            node_twist=np.zeros(n),
            rest_length=by_source(np.linalg.norm(vectors, axis=1), self.edges),
            rest_curvature=np.zeros((n, 2)),
            rest_twist=np.zeros(n),
            reference_director=transported_directors(vectors, self.edges),
            reference_twist=np.zeros(n),
        )
        pattern.validate()
        return pattern

    # -- validation ---------------------------------------------------------------------------

    def validate(self) -> None:
        """Raise :class:`PatternError` unless the pattern is a valid periodic repeat.

        Checks: finite data of consistent shapes; positive repeat size and radius; each node
        exactly one outgoing and one incoming edge (no dangling yarn end, no branch); tile offsets
        in {−1, 0, 1}; no zero-length edge; every yarn crosses the repeat (non-zero net offset);
        and the repeat tiles without gaps: an edge into a neighbouring tile is no longer than
        BORDER_EDGE_RATIO times the yarn's longest edge within the tile (a repeat size that does
        not fit its yarns leaves a jump where the yarn enters the next tile).
        """
        n = self.node_position.shape[0] if self.node_position.ndim == 2 else -1
        if self.family not in FAMILIES:
            raise PatternError(f"pattern {self.name!r}: family must be one of {FAMILIES}, got {self.family!r}")
        shapes = {
            "node_position": (n, 3), "edges": (n, 4), "node_twist": (n,), "rest_length": (n,),
            "rest_curvature": (n, 2), "rest_twist": (n,), "reference_director": (n, 3), "reference_twist": (n,),
        }
        if n < 1:
            raise PatternError(f"pattern {self.name!r}: node_position must have shape (N, 3) with N ≥ 1")
        for key, shape in shapes.items():
            value = getattr(self, key)
            if value.shape != shape:
                raise PatternError(f"pattern {self.name!r}: {key} must have shape {shape}, got {value.shape}")
            if not np.all(np.isfinite(value)):
                raise PatternError(f"pattern {self.name!r}: {key} has non-finite values")
        px, py = (float(v) for v in self.repeat_size)
        if not (px > 0 and py > 0):
            raise PatternError(f"pattern {self.name!r}: repeat size must be positive, got {px!r} × {py!r}")
        if not (math.isfinite(self.radius) and self.radius > 0):
            raise PatternError(f"pattern {self.name!r}: radius must be positive, got {self.radius!r}")
        v0, v1 = self.edges[:, 0], self.edges[:, 1]
        if v0.min() < 0 or v1.min() < 0 or v0.max() >= n or v1.max() >= n:
            raise PatternError(f"pattern {self.name!r}: an edge refers to a node outside 0..{n - 1}")
        out_degree = np.bincount(v0, minlength=n)
        in_degree = np.bincount(v1, minlength=n)
        for degree, what in ((out_degree, "leave"), (in_degree, "enter")):
            bad = np.flatnonzero(degree != 1)
            if bad.size:
                node = int(bad[0])
                if degree[node] == 0:
                    raise PatternError(
                        f"pattern {self.name!r}: dangling yarn end at node {node} (no edge {what}s it)"
                    )
                raise PatternError(f"pattern {self.name!r}: {degree[node]} edges {what} node {node}; a yarn cannot branch")
        if np.abs(self.edges[:, 2:]).max(initial=0) > 1:
            row = int(np.argmax(np.abs(self.edges[:, 2:]).max(axis=1)))
            raise PatternError(f"pattern {self.name!r}: edge {row} jumps more than one tile ({self.edges[row, 2:]})")
        _check_lengths(self.name, np.linalg.norm(edge_vectors(self.node_position, self.edges, (px, py)), axis=1),
                       self.edges)
        for k, yarn in enumerate(self.yarns()):
            if yarn.net_offset == (0, 0):
                raise PatternError(
                    f"pattern {self.name!r}: yarn {k} (node {yarn.nodes[0]}) closes inside the tile; "
                    "every yarn must continue into a neighbouring tile"
                )
        lengths = np.linalg.norm(edge_vectors(self.node_position, self.edges, (px, py)), axis=1)
        for k, yarn in enumerate(self.yarns()):
            crossing = np.any(yarn.tiles != 0, axis=1)
            if crossing.all():
                continue  # every edge crosses a border: nothing inside to compare with
            inside = lengths[self.outgoing_rows(yarn.nodes[~crossing])].max()
            rows = self.outgoing_rows(yarn.nodes[crossing])
            worst = int(rows[np.argmax(lengths[rows])])
            if lengths[worst] > BORDER_EDGE_RATIO * inside:
                raise PatternError(
                    f"pattern {self.name!r}: yarn {k} jumps {lengths[worst]:.3g} m into the next tile at edge "
                    f"{worst} ({int(self.edges[worst, 0])} -> {int(self.edges[worst, 1])}), more than "
                    f"{BORDER_EDGE_RATIO:g} times its longest edge inside the tile ({inside:.3g} m): the repeat "
                    f"size {px:.4g} m × {py:.4g} m does not tile without gaps"
                )


def int_matrix(values, allowed: tuple[int, ...], what: str, meaning: str) -> np.ndarray:
    """``values`` as a non-empty 2D int array whose entries are all in ``allowed``, or
    :class:`PatternError` ``"a <what> must be a 2D matrix of <meaning>"`` / ``"… may only contain
    <meaning>"``."""
    m = np.asarray(values)
    if m.ndim != 2 or m.shape[0] < 1 or m.shape[1] < 1:
        raise PatternError(f"a {what} must be a 2D matrix of {meaning}, got shape {m.shape}")
    if not np.all(np.isin(m, allowed)):
        raise PatternError(f"a {what} may only contain {meaning}")
    return m.astype(np.int64)


def _check_lengths(name: str, lengths: np.ndarray, edges: np.ndarray) -> None:
    if np.any(lengths <= 0.0):
        row = int(np.argmin(lengths))
        raise PatternError(f"pattern {name!r}: edge {row} ({edges[row, 0]} → {edges[row, 1]}) has zero length")


def edge_vectors(position: np.ndarray, edges: np.ndarray, repeat_size) -> np.ndarray:
    """Edge vectors ``(E, 3)``: ``p[v1] + (dx px, dy py, 0) − p[v0]`` for each row of ``edges``."""
    px, py = repeat_size
    shift = np.column_stack([edges[:, 2] * px, edges[:, 3] * py, np.zeros(len(edges))])
    return position[edges[:, 1]] + shift - position[edges[:, 0]]


def by_source(per_edge: np.ndarray, edges: np.ndarray) -> np.ndarray:
    """Reorder per-edge-row values to per-source-node values (each node has one outgoing edge)."""
    out = np.empty_like(per_edge)
    out[edges[:, 0]] = per_edge
    return out


def transported_directors(vectors: np.ndarray, edges: np.ndarray) -> np.ndarray:
    """Unit directors normal to each edge, parallel transported along each yarn; indexed by the
    edges' source nodes (``(N, 3)``)."""
    n = len(edges)
    tangent = vectors / np.linalg.norm(vectors, axis=1, keepdims=True)
    by_source = np.empty((n, 3))
    next_node = np.empty(n, dtype=np.int64)
    next_node[edges[:, 0]] = edges[:, 1]
    tangent_of = np.empty((n, 3))
    tangent_of[edges[:, 0]] = tangent
    done = np.zeros(n, dtype=bool)
    for first in range(n):
        if done[first]:
            continue
        t = tangent_of[first]
        helper = np.array([1.0, 0.0, 0.0]) if abs(t[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
        d1 = np.cross(t, helper)
        d1 /= np.linalg.norm(d1)
        node = first
        while True:
            by_source[node] = d1
            done[node] = True
            node = next_node[node]
            if node == first or done[node]:
                break
            t_new = tangent_of[node]
            d1 = d1 - t_new * (d1 @ t_new)  # transport: drop the component along the new tangent
            d1 /= np.linalg.norm(d1)
            t = t_new
    return by_source
