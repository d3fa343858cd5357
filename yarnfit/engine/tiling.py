"""Periodic images of a repeat: lattice translations, or per-node rigid maps on a curved surface.

A flat periodic model (the relaxation) reaches its images by translations ``T @ lattice``. A repeat
tiled over a deformed mid-surface (homogenization, paper §4.5) cannot: its neighbour in tile ``T``
sits where the surface continues, turned with it. There each node ``i`` reaches its image in tile
``T`` by a rigid map of its own, ``x ↦ Q_iT x + c_iT`` (``Q_iT = R(X_i + T) R(X_i)ᵀ`` with R the
surface frame at the node's reference position ``X_i``: the co-rotated fluctuation of a node equals
that of its images, the paper's ``C_RVE_Γ``). A :class:`CurvedTiling` holds those maps for a set
of tiles; :func:`retile` attaches it to a model, which then maps ghost-edge ends, frames across tile
borders and contact images through it.
"""

from __future__ import annotations

import copy
import functools
from dataclasses import dataclass, replace

import numpy as np
from scipy.spatial.transform import Rotation

from .model import RodModel
from .rotations import as_frames, rotate_frames

# A map's rotation must be orthonormal to this (they come from polar decompositions).
ORTHONORMAL_TOLERANCE = 1e-9
# A flat sample's maps turn nothing but for round-off of the polar decompositions (~1e-16): a turn
# this small moves an image by 1e-12 of its distance, far below any tolerance of the solver.
FLAT_TURN_TOLERANCE = 1e-12


@dataclass(frozen=True, eq=False)
class CurvedTiling:
    """Rigid maps of every node onto its images in a set of tiles.

    Attributes:
        images: ``(K, 2)`` int tile offsets covered; must include ``(0, 0)`` (the identity).
        rotation: ``(N, K, 3, 3)`` rotations ``Q``.
        translation: ``(N, K, 3)`` m, translations ``c``: node ``i``'s image in tile
            ``images[k]`` is ``rotation[i, k] x_i + translation[i, k]``.
    """

    images: np.ndarray
    rotation: np.ndarray
    translation: np.ndarray

    def __post_init__(self) -> None:
        images = np.asarray(self.images)
        n, k = self.rotation.shape[:2]
        if images.shape != (k, 2) or self.rotation.shape != (n, k, 3, 3) or self.translation.shape != (n, k, 3):
            raise ValueError(f"tiling arrays disagree: images {images.shape}, rotation {self.rotation.shape}, "
                             f"translation {self.translation.shape}")
        if len({tuple(t) for t in images.tolist()}) != k:
            raise ValueError("tiling images must be distinct")
        if not (np.all(np.isfinite(self.rotation)) and np.all(np.isfinite(self.translation))):
            raise ValueError("tiling maps must be finite")
        # optimize=True: numpy's plain einsum loops over the N K tiny products ~20x slower.
        gram = np.einsum("nkji,nkjl->nkil", self.rotation, self.rotation, optimize=True)
        if np.abs(gram - np.eye(3)).max(initial=0.0) > ORTHONORMAL_TOLERANCE:
            raise ValueError("tiling rotations must be orthonormal")
        # Dense lookup of image indices over the box of tiles the images span (−1: no map): contact
        # searches look up every edge's tile at every line-search step.
        reach = int(np.abs(images).max())
        lookup = np.full((2 * reach + 1, 2 * reach + 1), -1, dtype=np.int64)
        lookup[images[:, 0] + reach, images[:, 1] + reach] = np.arange(k)
        object.__setattr__(self, "_lookup", lookup)
        home = self.image_index(np.zeros(2, dtype=np.int64))
        if home < 0:
            raise ValueError("tiling images must include the home tile (0, 0)")
        if np.abs(self.rotation[:, home] - np.eye(3)).max() > 0.0 or np.abs(self.translation[:, home]).max() > 0.0:
            raise ValueError("the home tile's maps must be the identity")

    @functools.cached_property
    def turns(self) -> bool:
        """Whether any map turns its image by more than FLAT_TURN_TOLERANCE (a flat tiling's
        maps are translations)."""
        return bool(np.abs(self.rotation - np.eye(3)).max(initial=0.0) > FLAT_TURN_TOLERANCE)

    def translated(self, matrix: np.ndarray) -> CurvedTiling:
        """This tiling of translations with every translation mapped by the linear ``matrix``
        ``(3, 3)``: the images where they are when the whole tiled configuration is mapped by it
        (:func:`transform_images`). Its images and rotations are this tiling's, already checked:
        a search maps one tiling many times, and the checks cost more than the map."""
        if self.turns:
            raise ValueError("only a tiling of translations can be mapped linearly (its maps turn the images)")
        translation = np.ascontiguousarray(self.translation @ np.asarray(matrix, dtype=np.float64).T)
        if not np.all(np.isfinite(translation)):
            raise ValueError("tiling maps must be finite")
        tiling = copy.copy(self)
        object.__setattr__(tiling, "translation", translation)
        return tiling

    @property
    def n_nodes(self) -> int:
        return self.rotation.shape[0]

    def image_index(self, tiles: np.ndarray) -> np.ndarray:
        """Index into ``images`` of each tile ``(..., 2)``, −1 where the tiling has no map."""
        tiles = np.asarray(tiles, dtype=np.int64)
        reach = self._lookup.shape[0] // 2
        inside = np.all(np.abs(tiles) <= reach, axis=-1)
        shifted = np.where(inside[..., None], tiles + reach, 0)
        return np.where(inside, self._lookup[shifted[..., 0], shifted[..., 1]], -1)

    @property
    def reach(self) -> int:
        """Largest tile offset covered along either axis."""
        return int(np.abs(self.images).max())


def node_maps(model: RodModel, nodes: np.ndarray, tiles: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Rigid maps ``(rotation (n, 3, 3), translation (n, 3))`` taking each node to its image in the
    given tile: translations by ``tiles @ lattice`` for a flat model, the tiling's maps otherwise.
    Raises ``ValueError`` for a tile the tiling does not cover."""
    nodes = np.asarray(nodes, dtype=np.int64)
    tiles = np.asarray(tiles, dtype=np.int64).reshape(-1, 2)
    if model.tiling is None:
        rotation = np.broadcast_to(np.eye(3), (len(nodes), 3, 3))
        return np.ascontiguousarray(rotation), np.ascontiguousarray(tiles @ model.lattice)
    index = model.tiling.image_index(tiles)
    if np.any(index < 0):
        missing = tiles[np.flatnonzero(index < 0)[0]]
        raise ValueError(f"tile {tuple(int(v) for v in missing)} lies outside the curved tiling's images "
                         f"(reach {model.tiling.reach})")
    return model.tiling.rotation[nodes, index], model.tiling.translation[nodes, index]


def retile(model: RodModel, tiling: CurvedTiling, lattice: np.ndarray) -> RodModel:
    """``model`` placed on a curved tiling: ghost-edge ends, frames across tile borders and contact
    images follow ``tiling``; ``lattice (2, 3)`` (m) gives the tile vectors at the repeat's centre,
    used to size image searches."""
    if not model.periodic:
        raise ValueError("only a periodic model can be retiled")
    if tiling.n_nodes != model.n_nodes:
        raise ValueError(f"tiling has maps for {tiling.n_nodes} nodes, the model has {model.n_nodes}")
    lattice = np.array(lattice, dtype=np.float64)
    curved = replace(model, tiling=tiling, lattice=lattice)
    end_rotation, end_offset = node_maps(curved, model.edge_nodes[:, 1], model.edge_tile)
    # A joint compares edge a with edge b seen from a's tile: b's frame turned by the map of their
    # shared node into that tile.
    a = model.joint_edges[:, 0]
    joint_rotation, _ = node_maps(curved, model.edge_nodes[a, 1], model.edge_tile[a])
    return replace(curved, edge_end_rotation=np.ascontiguousarray(end_rotation),
                   edge_offset=np.ascontiguousarray(end_offset),
                   joint_frame_rotation=as_frames(Rotation.from_matrix(joint_rotation)))


def transform_images(model: RodModel, matrix: np.ndarray) -> RodModel:
    """``model`` with its periodic images where they are when the whole tiled configuration is
    mapped by the linear ``matrix`` (``(3, 3)``, positions ``x -> matrix x``: a stretch, a shear):
    an image's translation, every ghost edge's end offset and the lattice map with it. Only for
    tilings of translations (flat samples, whose maps turn nothing): a turning map does not commute
    with the map."""
    matrix = np.asarray(matrix, dtype=np.float64)
    if matrix.shape != (3, 3):
        raise ValueError(f"matrix must be (3, 3), got {matrix.shape}")
    if model.tiling is not None:
        model = replace(model, tiling=model.tiling.translated(matrix))  # refuses a tiling that turns
    return replace(model, lattice=model.lattice @ matrix.T, edge_offset=np.ascontiguousarray(model.edge_offset @ matrix.T))


def yarn_strips(model: RodModel, position: np.ndarray, tile=(0, 0)) -> list[np.ndarray]:
    """Each rod's centreline in ``tile`` as a polyline ``(n + 1, 3)`` (m) for drawing: node j
    placed in its chain tile (so a yarn crossing a tile border mid-way stays continuous), and a
    closed rod's first node again, one period on."""
    tile = np.asarray(tile, dtype=np.int64)
    strips = []
    for r in range(model.n_rods):
        nodes = np.arange(model.rod_node_start[r], model.rod_node_start[r + 1])
        edges = np.arange(model.rod_edge_start[r], model.rod_edge_start[r + 1])
        tiles = tile + model.edge_chain_tile[edges[: len(nodes)]]
        if model.rod_closed[r]:
            nodes = np.append(nodes, nodes[0])
            tiles = np.vstack([tiles, tile + model.rod_period[r]])
        rotation, translation = node_maps(model, nodes, tiles)
        strips.append(np.einsum("nij,nj->ni", rotation, position[nodes]) + translation)
    return strips


# -- cutting a piece of fabric out of a flat repeat ----------------------------------------------


@dataclass(frozen=True, eq=False)
class YarnPiece:
    """A run of one yarn inside a cut: ``points (n, 3)`` (m), ``rest_lengths (n − 1,)`` (m),
    ``frames (n − 1, 4)`` (the rest frames, turned as the points) and the yarn's ``radius`` (m)."""

    points: np.ndarray
    rest_lengths: np.ndarray
    frames: np.ndarray
    radius: float


def cut_rectangle(model: RodModel, position: np.ndarray, rotation: np.ndarray, length: float, width: float,
                  min_length: float) -> list[YarnPiece]:
    """The yarns of a flat periodic ``model`` at ``position`` (its rest frames taken as the
    frames) inside a ``length`` × ``width`` rectangle (m) about the repeat's centre at its mean
    height: every copy of every yarn unrolled over the periods the rectangle spans, turned by
    ``rotation`` (3 × 3, world from material coordinates: the rectangle's sides lie along the
    world x and y), and cut into runs of consecutive nodes inside it. Runs of fewer than 3 nodes or
    under ``min_length`` (m) of rest length are dropped."""
    lattice = model.lattice
    centre = 0.5 * (lattice[0] + lattice[1])
    centre[2] = float(np.mean(position[:, 2]))
    corners = np.array([[su * length / 2, sv * width / 2, 0.0] for su in (-1, 1) for sv in (-1, 1)]) @ rotation
    half_extent = np.abs(corners[:, :2]).max(axis=0)
    pieces = []
    for points, rest, frames, radius, _ in _unrolled_yarns(model, position - centre, half_extent):
        world = points @ rotation.T
        inside = (np.abs(world[:, 0]) <= length / 2) & (np.abs(world[:, 1]) <= width / 2)
        if not inside.any():
            continue
        # Runs of consecutive inside nodes.
        flags = np.concatenate([[False], inside, [False]]).astype(np.int8)
        starts = np.flatnonzero(np.diff(flags) == 1)
        stops = np.flatnonzero(np.diff(flags) == -1)
        for a, b in zip(starts, stops):
            if b - a < 3 or rest[a:b - 1].sum() < min_length:
                continue
            pieces.append(YarnPiece(world[a:b], rest[a:b - 1], rotate_frames(rotation, frames[a:b - 1]), radius))
    return pieces


def _unrolled_yarns(model: RodModel, position: np.ndarray, half_extent: np.ndarray):
    """Yield ``(points (n, 3), rest_lengths (n−1,), frames (n−1, 4), radius, material)`` of every copy
    of every yarn of a flat periodic ``model`` that passes within ``half_extent`` (x, y half sizes,
    m) of the origin, unrolled over as many periods as that takes (open polylines)."""
    lattice = model.lattice
    px, py = np.linalg.norm(lattice[0]), np.linalg.norm(lattice[1])
    reach = np.ceil(half_extent / np.array([px, py])).astype(int) + 2
    for r in range(model.n_rods):
        nodes = np.arange(model.rod_node_start[r], model.rod_node_start[r + 1])
        edges = np.arange(model.rod_edge_start[r], model.rod_edge_start[r + 1])
        period = model.rod_period[r]
        if not model.rod_closed[r] or not np.any(period):
            raise ValueError(f"rod {r}: only closed yarns that run through the tiles can be unrolled")
        if period[0] != 0 and period[1] != 0:
            raise ValueError(f"rod {r}: a yarn must run along a tile vector, its period is {period.tolist()}")
        axis = 0 if period[0] != 0 else 1
        step = int(abs(period[axis]))
        chain = model.edge_chain_tile[edges]
        n = len(nodes)
        # Copies: along the yarn's axis, `step` distinct phases; across it, every tile in reach.
        across = 1 - axis
        periods = int(np.ceil((reach[axis] + 1) / step)) + 1
        m = np.arange(-periods, periods + 1)
        for phase in range(step):
            for t in range(-reach[across], reach[across] + 1):
                tile = np.zeros(2, dtype=np.int64)
                tile[axis] = phase
                tile[across] = t
                cells = (chain[None, :, :] + m[:, None, None] * period[None, None, :] + tile).reshape(-1, 2)
                points = np.tile(position[nodes], (len(m), 1)) + cells @ lattice
                if np.all(np.abs(points[:, across]) > half_extent[across] + 2 * max(px, py)):
                    continue
                rest = np.tile(model.edge_rest_length[edges], len(m))[:-1]
                frames = np.tile(model.edge_rest_quaternion[edges], (len(m), 1))[:-1]
                yield points, rest, frames, float(model.edge_radius[edges[0]]), n
