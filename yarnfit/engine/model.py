"""Rod model: rest data of any number of Cosserat rods in flat arrays with offsets.

A :class:`RodModel` is built once from :class:`Rod` descriptions and frozen (its arrays are
read-only); states (:class:`~yarnfit.engine.state.RodState`) and loads
(:class:`~yarnfit.engine.state.Loads`) are separate plain-array objects, and solvers hold only
options and scratch buffers (``docs/design.md`` §9).

Layout: rod ``r`` owns nodes ``rod_node_start[r]:rod_node_start[r+1]``, edges
``rod_edge_start[r]:...`` and joints ``rod_joint_start[r]:...``. An open rod of ``n`` nodes has
``n − 1`` edges and ``n − 2`` joints; a closed loop has ``n`` edges (the last one from the last
node back to the first) and ``n`` joints.

Periodic structures: a model may carry a ``lattice`` of two tile vectors; an edge with integer
tile offset ``(i, j)`` runs to its end node moved by ``i L1 + j L2`` (``edge_offset``). A closed rod
whose offsets add up to a non-zero ``rod_period`` is a yarn that continues through the tiles
(one period of an infinite yarn); contacts then include every periodic image.

A repeat tiled over a curved surface (homogenization) maps each node onto its images by a rigid
motion of its own (:class:`~yarnfit.engine.tiling.CurvedTiling`, attached with
:func:`~yarnfit.engine.tiling.retile`): an edge's end point is then ``edge_end_rotation x +
edge_offset`` and a joint across a tile border compares its first frame with its second frame
turned by ``joint_frame_rotation``. Both are the identity for flat tilings.
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass, field
from typing import NamedTuple, Sequence

import numpy as np

from ..checks import non_negative_number, positive_number
# A quaternion whose norm differs from one by more than this is rejected: callers must pass
# frames normalised to round-off (float32 round trips stay well inside).
UNIT_QUATERNION_TOLERANCE = 1e-6
# A user frame whose third director is further than this (rad) from its edge tangent is rejected:
# the stretch–shear energy assumes d3 is aligned with the edge in the rest state.
FRAME_ALIGNMENT_TOLERANCE = 1e-6
# Same-rod edge pairs closer than this many times (ra + rb) in rest arc length never make contact.
# Straight neighbours are within 2r only when their arc gap is below 2r; a gap of π r is the half
# turn of a yarn bent to its own radius, the tightest physical loop.
CONTACT_EXCLUSION_FACTOR = 0.5 * math.pi


@dataclass(frozen=True)
class RodSection:
    """Rigidities of a rod's cross-section (SI units), each independent of the others.

    A yarn is a bundle of fibres that slide on each other, so its bending and twisting rigidities
    are not those of a solid cylinder of its tensile rigidity (``docs/design.md`` §4,
    :mod:`yarnfit.yarn`). The engine therefore takes the five rigidities directly.

    Attributes:
        tensile_rigidity: EA (N), the axial force per unit strain at zero strain.
        shear_rigidity: GA (N), the transverse shear force per unit shear strain.
        bending_rigidity: (EI1, EI2) (N·m²) about the first and second directors.
        torsional_rigidity: GJ (N·m²).
        mass_per_length: kg/m.
        hardening_tension: H2 (N): the axial force is ``EA ε + ½ H2 ε²`` in tension, i.e. the
            tangent rigidity grows as ``EA + H2 ε`` (the paper's strain hardening, §4.1).
        hardening_compression: H1 (N), the same in compression (``EA + H1 |ε|``).
    """

    tensile_rigidity: float
    shear_rigidity: float
    bending_rigidity: tuple[float, float]
    torsional_rigidity: float
    mass_per_length: float
    hardening_tension: float = 0.0
    hardening_compression: float = 0.0

    def __post_init__(self) -> None:
        for name in ("tensile_rigidity", "shear_rigidity", "torsional_rigidity", "mass_per_length"):
            object.__setattr__(self, name, positive_number(getattr(self, name), name))
        pair = self.bending_rigidity
        # An ordered pair only: a string or a set would unpack silently into the wrong numbers.
        if isinstance(pair, np.ndarray):
            pair = pair.tolist()
        if not isinstance(pair, (tuple, list)) or len(pair) != 2:
            raise ValueError(f"bending_rigidity must be a pair (EI1, EI2), got {self.bending_rigidity!r}")
        ei1, ei2 = pair
        object.__setattr__(self, "bending_rigidity", (positive_number(ei1, "bending_rigidity[0]"),
                                                      positive_number(ei2, "bending_rigidity[1]")))
        for name in ("hardening_tension", "hardening_compression"):
            object.__setattr__(self, name, non_negative_number(getattr(self, name), name))


@dataclass(frozen=True)
class RodMaterial:
    """An isotropic material, for rods that are solid circular cylinders of it (SI units).

    :meth:`section` gives the :class:`RodSection` of a solid cylinder of radius r:
    ``EA = E π r²``, ``GA = G π r²``, ``EI1 = EI2 = E π r⁴/4``, ``GJ = G π r⁴/2``, mass ``ρ π r²``
    per length, hardening ``k π r²``. It is the paper's yarn (§3.2) exactly.

    Attributes:
        young_modulus: E (Pa); for a nonlinear yarn, the modulus at zero strain (E_min).
        poisson_ratio: ν, gives the shear modulus ``G = E / (2 (1 + ν))``.
        density: ρ (kg/m³).
        hardening_tension: k2 (Pa): the tangent modulus grows as ``E + k2 ε`` in tension.
        hardening_compression: k1 (Pa): ``E + k1 |ε|`` in compression.
    """

    young_modulus: float
    poisson_ratio: float = 0.3
    density: float = 1000.0
    hardening_tension: float = 0.0
    hardening_compression: float = 0.0

    def __post_init__(self) -> None:
        positive_number(self.young_modulus, "young_modulus")
        positive_number(self.density, "density")
        nu = float(self.poisson_ratio)
        if not math.isfinite(nu) or not -1.0 < nu < 0.5:
            raise ValueError(f"poisson_ratio must lie in (-1, 0.5), got {self.poisson_ratio!r}")
        for name in ("hardening_tension", "hardening_compression"):
            k = float(getattr(self, name))
            if not math.isfinite(k) or k < 0.0:
                raise ValueError(f"{name} must be a finite number >= 0, got {k!r}")

    @property
    def shear_modulus(self) -> float:
        """G = E / (2 (1 + ν)) (Pa)."""
        return self.young_modulus / (2.0 * (1.0 + self.poisson_ratio))

    def section(self, radius: float) -> RodSection:
        """The :class:`RodSection` of a solid circular cylinder of this material, radius ``radius`` (m)."""
        r = positive_number(radius, "radius")
        area = math.pi * r**2
        inertia = 0.25 * math.pi * r**4
        return RodSection(
            tensile_rigidity=self.young_modulus * area,
            shear_rigidity=self.shear_modulus * area,
            bending_rigidity=(self.young_modulus * inertia, self.young_modulus * inertia),
            torsional_rigidity=self.shear_modulus * 2.0 * inertia,
            mass_per_length=self.density * area,
            hardening_tension=self.hardening_tension * area,
            hardening_compression=self.hardening_compression * area,
        )


@dataclass
class Rod:
    """Description of one rod for :meth:`RodModel.from_rods`.

    Attributes:
        points: node positions ``(n, 3)`` (m); the initial configuration.
        radius: contact radius r (m): two rods touch when their centrelines are ``ra + rb``
            apart. With ``material``, also the radius of the solid section.
        material: a :class:`RodSection` (the rigidities, independent of ``radius``), or a
            :class:`RodMaterial` (a solid circular cylinder of ``radius``, :meth:`RodMaterial.section`).
        closed: a closed loop (an extra edge joins the last node to the first).
        frames: edge frames ``(E, 4)`` as unit quaternions (w, x, y, z) with ``d3`` along the edge;
            default: parallel transport along the polyline.
        rest_lengths: edge rest lengths ``(E,)`` (m); default: the initial edge lengths.
        straight: rest shape is straight and untwisted (rest Darboux vectors zero); default: the
            initial configuration (with ``frames``) is the rest shape.
        pinned_nodes: node indices (local to the rod, negative counts from the end) held fixed.
        pinned_frames: edge indices whose frames are held fixed.
        tile_offsets: ``(E, 2)`` integer tile offsets of the edges (a closed rod of a periodic
            model: the edge from node k runs to node k + 1 of tile ``tile_offsets[k]``); default 0.
        name: label used in error messages.
    """

    points: np.ndarray
    radius: float
    material: RodSection | RodMaterial
    closed: bool = False
    frames: np.ndarray | None = None
    rest_lengths: np.ndarray | None = None
    straight: bool = False
    pinned_nodes: Sequence[int] = field(default_factory=tuple)
    pinned_frames: Sequence[int] = field(default_factory=tuple)
    tile_offsets: np.ndarray | None = None
    name: str = ""


def straight_points(length: float, n_edges: int, start=(0.0, 0.0, 0.0), direction=(1.0, 0.0, 0.0)) -> np.ndarray:
    """``n_edges + 1`` equally spaced points ``(n, 3)`` on a segment of ``length`` (m)."""
    d = np.asarray(direction, dtype=np.float64)
    d = d / np.linalg.norm(d)
    return np.asarray(start, dtype=np.float64) + np.linspace(0.0, length, n_edges + 1)[:, None] * d


def parallel_transport_frames(points: np.ndarray, closed: bool = False, edge_offset: np.ndarray | None = None) -> np.ndarray:
    """Edge frames ``(E, 4)`` with ``d3`` along each edge, transported without twist.

    The first frame takes ``e3`` onto the first tangent by the minimal rotation; each next frame
    is the previous one turned by the minimal rotation between consecutive tangents.
    ``edge_offset (E, 3)`` is added to each edge's end point (periodic rods).
    """
    from ._quat import quat_between, quat_mul

    pts = np.asarray(points, dtype=np.float64)
    seg = np.roll(pts, -1, axis=0) - pts if closed else np.diff(pts, axis=0)
    if edge_offset is not None:
        seg = seg + edge_offset
    tangents = seg / np.linalg.norm(seg, axis=1, keepdims=True)
    frames = np.empty((len(tangents), 4))
    q = quat_between((0.0, 0.0, 1.0), tuple(tangents[0]))
    frames[0] = q
    for i in range(1, len(tangents)):
        q = quat_mul(quat_between(tuple(tangents[i - 1]), tuple(tangents[i])), q)
        q = tuple(np.asarray(q) / np.linalg.norm(q))
        frames[i] = q
    return frames


def aligned_frames(model: "RodModel", position: np.ndarray, quaternion: np.ndarray) -> np.ndarray:
    """Frames ``(E, 4)`` turned by the minimal rotation that puts each ``d3`` along its edge.

    An equilibrium leaves a small shear (``d3`` off the edge by ~force / GA); a rest state needs
    frames along their edges, and this keeps the material directors as close as possible.
    """
    from ._kernels import align_frames

    end = np.einsum("eij,ej->ei", model.edge_end_rotation, position[model.edge_nodes[:, 1]]) + model.edge_offset
    edge = end - position[model.edge_nodes[:, 0]]
    tangent = edge / np.linalg.norm(edge, axis=1, keepdims=True)
    quaternion = np.ascontiguousarray(quaternion, dtype=np.float64)
    out = np.empty_like(quaternion)
    align_frames(quaternion, np.ascontiguousarray(quaternion_d3(quaternion)), tangent, out)
    return out


def quaternion_d1(q: np.ndarray) -> np.ndarray:
    """First directors ``R(q) e1`` of quaternions ``(..., 4)`` → ``(..., 3)``."""
    w, x, y, z = np.moveaxis(np.asarray(q, dtype=np.float64), -1, 0)
    return np.stack([w * w + x * x - y * y - z * z, 2 * (x * y + w * z), 2 * (x * z - w * y)], axis=-1)


def quaternion_d3(q: np.ndarray) -> np.ndarray:
    """Third directors ``R(q) e3`` of quaternions ``(..., 4)`` → ``(..., 3)``."""
    w, x, y, z = np.moveaxis(np.asarray(q, dtype=np.float64), -1, 0)
    return np.stack([2 * (x * z + w * y), 2 * (y * z - w * x), w * w - x * x - y * y + z * z], axis=-1)


def quaternion_conj_mul(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Row-wise ``ā ⊗ b`` of quaternion arrays ``(n, 4)``."""
    aw, ax, ay, az = a[:, 0], -a[:, 1], -a[:, 2], -a[:, 3]
    bw, bx, by, bz = b[:, 0], b[:, 1], b[:, 2], b[:, 3]
    return np.stack(
        [
            aw * bw - ax * bx - ay * by - az * bz,
            aw * bx + ax * bw + ay * bz - az * by,
            aw * by - ax * bz + ay * bw + az * bx,
            aw * bz + ax * by - ay * bx + az * bw,
        ],
        axis=1,
    )


def check_quaternions(q: np.ndarray, what: str) -> None:
    """Raise ``ValueError`` unless every row of ``q (n, 4)`` is a finite unit quaternion."""
    q = np.asarray(q)
    if q.ndim != 2 or q.shape[1] != 4:
        raise ValueError(f"{what} must have shape (n, 4), got {q.shape}")
    bad = ~np.all(np.isfinite(q), axis=1)
    if bad.any():
        raise ValueError(f"{what}: row {int(np.argmax(bad))} is not finite ({q[np.argmax(bad)]})")
    norms = np.linalg.norm(q, axis=1)
    off = np.abs(norms - 1.0) > UNIT_QUATERNION_TOLERANCE
    if off.any():
        i = int(np.argmax(off))
        raise ValueError(f"{what}: row {i} is not a unit quaternion (norm {norms[i]:.9g})")


def check_positions(x: np.ndarray, n: int, what: str) -> None:
    """Raise ``ValueError`` unless ``x`` is a finite ``(n, 3)`` array."""
    x = np.asarray(x)
    if x.shape != (n, 3):
        raise ValueError(f"{what} must have shape ({n}, 3), got {x.shape}")
    bad = ~np.all(np.isfinite(x), axis=1)
    if bad.any():
        raise ValueError(f"{what}: row {int(np.argmax(bad))} is not finite")


def _local_indices(indices: Sequence[int], count: int, what: str, rod_label: str) -> np.ndarray:
    out = []
    for i in indices:
        if isinstance(i, (bool, np.bool_)) or not isinstance(i, (int, np.integer)):
            raise ValueError(f"{rod_label}: {what} index {i!r} is not an integer")
        j = int(i) + count if int(i) < 0 else int(i)
        if not 0 <= j < count:
            raise ValueError(f"{rod_label}: {what} index {int(i)} is out of range for {count} {what}s")
        out.append(j)
    return np.asarray(out, dtype=np.int64)


class RodArrays(NamedTuple):
    """The rest data every rod-energy and projection kernel reads, bundled once per model
    (:attr:`RodModel.arrays`; names, shapes and units as in :class:`RodModel`). A kernel takes it
    as one argument and unpacks it in this order."""

    edge_nodes: np.ndarray
    edge_end_rotation: np.ndarray
    edge_offset: np.ndarray
    edge_rest_length: np.ndarray
    edge_shear_stiffness: np.ndarray
    edge_stretch_stiffness: np.ndarray
    edge_hardening: np.ndarray
    joint_edges: np.ndarray
    joint_frame_rotation: np.ndarray
    joint_rest_darboux: np.ndarray
    joint_rest_length: np.ndarray
    joint_stiffness: np.ndarray


@dataclass(frozen=True, eq=False)
class RodModel:
    """Frozen rest data of a set of rods. Build with :meth:`from_rods`.

    Per node (N): ``node_rest_position (N, 3)`` m, ``node_mass`` kg, ``node_pinned`` bool,
    ``node_rod``. Per edge (E): ``edge_nodes (E, 2)``, ``edge_tile (E, 2)`` int and
    ``edge_offset (E, 3)`` m (``edge_tile @ lattice``, added to the end node; zero except for
    periodic ghost edges), ``edge_end_rotation (E, 3, 3)`` (applied to the end node before the
    offset; the identity unless the tiling is curved), ``edge_chain_tile (E, 2)`` int (tiles crossed along the rod before the
    edge: the edge sits at ``edge_chain_tile`` in the rod's unrolled chain), ``edge_rest_length``
    m, ``edge_radius`` m,
    ``edge_arc_start`` m (rest arc length of the edge's first node along its rod),
    ``edge_rest_quaternion (E, 4)``, ``edge_shear_stiffness`` GA (N), ``edge_stretch_stiffness`` EA
    (N), ``edge_hardening (E, 2)`` = (A k1, A k2) (N), ``edge_inertia`` kg·m² (about a transverse
    axis), ``edge_pinned`` bool, ``edge_rod``. Per joint (J): ``joint_edges (J, 2)``,
    ``joint_frame_rotation (J, 4)`` (quaternion turning the second edge's frame into the first
    edge's tile; the identity unless the tiling is curved), ``joint_rest_darboux (J, 4)``, ``joint_rest_length`` l̄ (m), ``joint_stiffness (J, 3)`` =
    (EI1, EI2, GJ) (N·m²). Per rod (R): ``rod_node_start``, ``rod_edge_start``,
    ``rod_joint_start`` (R + 1 offsets), ``rod_closed``, ``rod_length`` (m), ``rod_period (R, 2)``
    int (tiles a yarn advances per cycle; zero unless periodic), ``rod_names``. ``lattice (2, 3)``
    m: the tile vectors of a periodic model (zero otherwise; for a curved tiling, the tile
    vectors at the repeat's centre, used to size image searches). ``tiling``: the per-node maps of
    a curved tiling, or ``None`` (images are lattice translations).
    """

    node_rest_position: np.ndarray
    node_mass: np.ndarray
    node_pinned: np.ndarray
    node_rod: np.ndarray
    edge_nodes: np.ndarray
    edge_tile: np.ndarray
    edge_offset: np.ndarray
    edge_end_rotation: np.ndarray
    edge_chain_tile: np.ndarray
    edge_rest_length: np.ndarray
    edge_radius: np.ndarray
    edge_arc_start: np.ndarray
    edge_rest_quaternion: np.ndarray
    edge_shear_stiffness: np.ndarray
    edge_stretch_stiffness: np.ndarray
    edge_hardening: np.ndarray
    edge_inertia: np.ndarray
    edge_pinned: np.ndarray
    edge_rod: np.ndarray
    joint_edges: np.ndarray
    joint_frame_rotation: np.ndarray
    joint_rest_darboux: np.ndarray
    joint_rest_length: np.ndarray
    joint_stiffness: np.ndarray
    rod_node_start: np.ndarray
    rod_edge_start: np.ndarray
    rod_joint_start: np.ndarray
    rod_closed: np.ndarray
    rod_length: np.ndarray
    rod_period: np.ndarray
    rod_names: tuple
    lattice: np.ndarray
    tiling: object = None

    def __post_init__(self) -> None:
        for name, value in self.__dict__.items():
            if isinstance(value, np.ndarray):
                value.setflags(write=False)

    # -- sizes ------------------------------------------------------------------------------

    @property
    def n_nodes(self) -> int:
        return self.node_rest_position.shape[0]

    @property
    def n_edges(self) -> int:
        return self.edge_nodes.shape[0]

    @property
    def n_joints(self) -> int:
        return self.joint_edges.shape[0]

    @property
    def n_rods(self) -> int:
        return self.rod_closed.shape[0]

    @property
    def periodic(self) -> bool:
        """The model has a lattice (periodic images exist)."""
        return bool(np.any(self.lattice != 0.0))

    @property
    def curved(self) -> bool:
        """Periodic images are rigid motions of each node rather than translations."""
        return self.tiling is not None

    @functools.cached_property
    def arrays(self) -> RodArrays:
        """The kernels' rest data (:class:`RodArrays`)."""
        return RodArrays(*(getattr(self, name) for name in RodArrays._fields))

    @property
    def node_inv_mass(self) -> np.ndarray:
        """1/m for free nodes, 0 for pinned ones (kg⁻¹)."""
        return np.where(self.node_pinned, 0.0, 1.0 / self.node_mass)

    @property
    def edge_inv_inertia(self) -> np.ndarray:
        """1/I for free frames, 0 for pinned ones (kg⁻¹·m⁻²)."""
        return np.where(self.edge_pinned, 0.0, 1.0 / self.edge_inertia)

    # -- indexing ---------------------------------------------------------------------------

    def node_index(self, rod: int, node: int) -> int:
        """Global index of node ``node`` (negative counts from the end) of rod ``rod``."""
        start, stop = self._range(self.rod_node_start, rod)
        return start + int(_local_indices([node], stop - start, "node", self._label(rod))[0])

    def edge_index(self, rod: int, edge: int) -> int:
        """Global index of edge ``edge`` (negative counts from the end) of rod ``rod``."""
        start, stop = self._range(self.rod_edge_start, rod)
        return start + int(_local_indices([edge], stop - start, "edge", self._label(rod))[0])

    def rod_nodes(self, rod: int) -> slice:
        start, stop = self._range(self.rod_node_start, rod)
        return slice(start, stop)

    def rod_edges(self, rod: int) -> slice:
        start, stop = self._range(self.rod_edge_start, rod)
        return slice(start, stop)

    def _range(self, offsets: np.ndarray, rod: int) -> tuple[int, int]:
        if not -self.n_rods <= rod < self.n_rods:
            raise ValueError(f"rod index {rod} is out of range for {self.n_rods} rods")
        rod %= self.n_rods
        return int(offsets[rod]), int(offsets[rod + 1])

    def _label(self, rod: int) -> str:
        name = self.rod_names[rod % self.n_rods]
        return f"rod {rod % self.n_rods}" + (f" ({name!r})" if name else "")

    # -- construction -----------------------------------------------------------------------

    @classmethod
    def from_rods(cls, rods: Sequence[Rod], lattice: np.ndarray | None = None) -> "RodModel":
        """Validate rod descriptions and build the flat model. Raises ``ValueError`` on bad input.

        ``lattice (2, 3)`` (m) makes the model periodic: the tile vectors that the rods'
        ``tile_offsets`` count.
        """
        if len(rods) == 0:
            raise ValueError("a rod model needs at least one rod")
        lattice = _check_lattice(lattice)
        parts = [_build_rod(i, rod, lattice) for i, rod in enumerate(rods)]
        node_start = np.concatenate([[0], np.cumsum([p["n_nodes"] for p in parts])]).astype(np.int64)
        edge_start = np.concatenate([[0], np.cumsum([p["n_edges"] for p in parts])]).astype(np.int64)
        joint_start = np.concatenate([[0], np.cumsum([p["n_joints"] for p in parts])]).astype(np.int64)

        def cat(key: str) -> np.ndarray:
            return np.ascontiguousarray(np.concatenate([p[key] for p in parts]))

        edge_nodes = np.concatenate([p["edge_nodes"] + node_start[i] for i, p in enumerate(parts)])
        joint_edges = np.concatenate(
            [p["joint_edges"] + edge_start[i] for i, p in enumerate(parts)]
        ).reshape(-1, 2)
        edge_tile = cat("tiles").reshape(-1, 2)
        return cls(
            node_rest_position=cat("points"),
            node_mass=cat("node_mass"),
            node_pinned=cat("node_pinned"),
            node_rod=np.repeat(np.arange(len(parts)), [p["n_nodes"] for p in parts]).astype(np.int64),
            edge_nodes=np.ascontiguousarray(edge_nodes, dtype=np.int64),
            edge_tile=edge_tile,
            edge_offset=np.ascontiguousarray(edge_tile @ lattice),
            edge_end_rotation=np.ascontiguousarray(np.broadcast_to(np.eye(3), (len(edge_tile), 3, 3))),
            edge_chain_tile=cat("chain_tiles").reshape(-1, 2),
            edge_rest_length=cat("rest_lengths"),
            edge_radius=cat("edge_radius"),
            edge_arc_start=cat("arc_start"),
            edge_rest_quaternion=cat("frames"),
            edge_shear_stiffness=cat("shear_stiffness"),
            edge_stretch_stiffness=cat("stretch_stiffness"),
            edge_hardening=cat("hardening"),
            edge_inertia=cat("edge_inertia"),
            edge_pinned=cat("edge_pinned"),
            edge_rod=np.repeat(np.arange(len(parts)), [p["n_edges"] for p in parts]).astype(np.int64),
            joint_edges=np.ascontiguousarray(joint_edges, dtype=np.int64),
            joint_frame_rotation=np.ascontiguousarray(
                np.broadcast_to([1.0, 0.0, 0.0, 0.0], (len(joint_edges), 4))),
            joint_rest_darboux=cat("rest_darboux").reshape(-1, 4),
            joint_rest_length=cat("joint_rest_length"),
            joint_stiffness=cat("joint_stiffness").reshape(-1, 3),
            rod_node_start=node_start,
            rod_edge_start=edge_start,
            rod_joint_start=joint_start,
            rod_closed=np.array([bool(r.closed) for r in rods]),
            rod_length=np.array([p["rest_lengths"].sum() for p in parts]),
            rod_period=np.array([p["tiles"].sum(axis=0) for p in parts], dtype=np.int64).reshape(-1, 2),
            rod_names=tuple(str(r.name) for r in rods),
            lattice=lattice,
        )


def _check_lattice(lattice) -> np.ndarray:
    if lattice is None:
        return np.zeros((2, 3))
    lattice = np.array(lattice, dtype=np.float64)
    if lattice.shape != (2, 3) or not np.all(np.isfinite(lattice)):
        raise ValueError(f"lattice must be a finite (2, 3) array of tile vectors, got shape {lattice.shape}")
    if np.linalg.norm(np.cross(lattice[0], lattice[1])) <= 0.0:
        raise ValueError("lattice vectors must be non-zero and not parallel")
    return lattice


def _build_rod(index: int, rod: Rod, lattice: np.ndarray) -> dict:
    label = f"rod {index}" + (f" ({rod.name!r})" if rod.name else "")
    if not isinstance(rod.material, (RodSection, RodMaterial)):
        raise ValueError(f"{label}: material must be a RodSection or a RodMaterial, got {type(rod.material).__name__}")
    pts = np.asarray(rod.points, dtype=np.float64)
    if pts.ndim != 2 or pts.shape[1] != 3:
        raise ValueError(f"{label}: points must have shape (n, 3), got {pts.shape}")
    min_nodes = 3 if rod.closed else 2
    if pts.shape[0] < min_nodes:
        raise ValueError(f"{label}: needs at least {min_nodes} points, got {pts.shape[0]}")
    check_positions(pts, pts.shape[0], f"{label}: points")
    radius = positive_number(rod.radius, f"{label}: radius")
    n_nodes = pts.shape[0]
    n_edges = n_nodes if rod.closed else n_nodes - 1
    n_joints = n_nodes if rod.closed else n_nodes - 2
    edge_nodes = np.stack([np.arange(n_edges), (np.arange(n_edges) + 1) % n_nodes], axis=1)
    tiles = np.zeros((n_edges, 2), dtype=np.int64)
    if rod.tile_offsets is not None:
        given = np.asarray(rod.tile_offsets)
        if given.shape != (n_edges, 2):
            raise ValueError(f"{label}: tile_offsets must have shape ({n_edges}, 2), got {given.shape}")
        if not np.all(np.isfinite(given)) or np.any(given != np.round(given)):
            raise ValueError(f"{label}: tile_offsets must be integers")
        tiles = given.astype(np.int64)
        if np.any(tiles != 0) and not np.any(lattice != 0.0):
            raise ValueError(f"{label}: tile offsets need a model lattice (RodModel.from_rods(..., lattice=...))")
        if np.any(tiles != 0) and not rod.closed:
            raise ValueError(f"{label}: only a closed rod can continue into other tiles")
    offset = tiles @ lattice
    seg = pts[edge_nodes[:, 1]] + offset - pts[edge_nodes[:, 0]]
    seg_len = np.linalg.norm(seg, axis=1)
    if np.any(seg_len <= 0.0):
        raise ValueError(f"{label}: edge {int(np.argmin(seg_len))} has zero length (repeated point)")
    if rod.rest_lengths is None:
        rest = seg_len.copy()
    else:
        rest = np.asarray(rod.rest_lengths, dtype=np.float64).reshape(-1)
        if rest.shape != (n_edges,):
            raise ValueError(f"{label}: rest_lengths must have shape ({n_edges},), got {rest.shape}")
        bad = ~np.isfinite(rest) | (rest <= 0.0)
        if bad.any():
            i = int(np.argmax(bad))
            raise ValueError(f"{label}: rest length of edge {i} must be positive and finite, got {rest[i]!r}")
    if rod.frames is None:
        frames = parallel_transport_frames(pts, rod.closed, offset)
    else:
        frames = np.array(rod.frames, dtype=np.float64)
        if frames.shape != (n_edges, 4):
            raise ValueError(f"{label}: frames must have shape ({n_edges}, 4), got {frames.shape}")
        check_quaternions(frames, f"{label}: frames")
        frames /= np.linalg.norm(frames, axis=1, keepdims=True)
        misalign = np.linalg.norm(quaternion_d3(frames) - seg / seg_len[:, None], axis=1)
        if np.any(misalign > FRAME_ALIGNMENT_TOLERANCE):
            i = int(np.argmax(misalign))
            raise ValueError(f"{label}: frame {i} has d3 off its edge tangent by {misalign[i]:.3g} rad")
    edges_a = np.arange(n_joints) if rod.closed else np.arange(n_edges - 1)
    joint_edges = np.stack([edges_a, (edges_a + 1) % n_edges], axis=1)
    if rod.straight:
        rest_darboux = np.tile([1.0, 0.0, 0.0, 0.0], (n_joints, 1))
    else:
        rest_darboux = quaternion_conj_mul(frames[joint_edges[:, 0]], frames[joint_edges[:, 1]])

    section = rod.material.section(radius) if isinstance(rod.material, RodMaterial) else rod.material
    node_mass = np.zeros(n_nodes)
    edge_mass = section.mass_per_length * rest
    np.add.at(node_mass, edge_nodes[:, 0], 0.5 * edge_mass)
    np.add.at(node_mass, edge_nodes[:, 1], 0.5 * edge_mass)
    node_pinned = np.zeros(n_nodes, dtype=bool)
    node_pinned[_local_indices(rod.pinned_nodes, n_nodes, "node", label)] = True
    edge_pinned = np.zeros(n_edges, dtype=bool)
    edge_pinned[_local_indices(rod.pinned_frames, n_edges, "edge", label)] = True
    arc = np.concatenate([[0.0], np.cumsum(rest)[:-1]])
    ones_e = np.ones(n_edges)
    ones_j = np.ones(n_joints)
    return {
        "n_nodes": n_nodes,
        "n_edges": n_edges,
        "n_joints": n_joints,
        "points": pts,
        "node_mass": node_mass,
        "node_pinned": node_pinned,
        "edge_nodes": edge_nodes.astype(np.int64),
        "tiles": tiles,
        "chain_tiles": np.cumsum(tiles, axis=0) - tiles,
        "rest_lengths": rest,
        "edge_radius": radius * ones_e,
        "arc_start": arc,
        "frames": frames,
        "shear_stiffness": section.shear_rigidity * ones_e,
        "stretch_stiffness": section.tensile_rigidity * ones_e,
        "hardening": np.stack([section.hardening_compression * ones_e, section.hardening_tension * ones_e], axis=1),
        # A thin cylinder about a transverse axis through its centre, m (l²/12 + r²/4), r the
        # contact radius (XPBD's rotational inertia only; quasi-static solves do not use it).
        "edge_inertia": edge_mass * (rest**2 / 12.0 + radius**2 / 4.0),
        "edge_pinned": edge_pinned,
        "joint_edges": joint_edges.astype(np.int64),
        "rest_darboux": rest_darboux,
        "joint_rest_length": 0.5 * (rest[joint_edges[:, 0]] + rest[joint_edges[:, 1]]),
        "joint_stiffness": np.stack(
            [section.bending_rigidity[0] * ones_j, section.bending_rigidity[1] * ones_j,
             section.torsional_rigidity * ones_j],
            axis=1,
        ),
    }
