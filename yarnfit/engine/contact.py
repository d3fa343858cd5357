"""Contact candidates of a configuration: edge pairs with the periodic image of their second edge.

Both solvers ask :func:`find_pairs` for the pairs near a configuration (or near a motion between
two configurations); the quasi-static solver asks through a :class:`NeighbourList`, which reuses
one search while the nodes stay near where it was made. The narrow phase and responses live in
``_contact_kernels``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from . import _contact_kernels
from .model import CONTACT_EXCLUSION_FACTOR, RodModel
from .tiling import node_maps

# Skin of a NeighbourList, in units of its search margin: its candidates are the pairs a search
# with the margin widened by the skin finds, kept while no node is further than half the skin from
# where that search was made. HYLC's stockinette samples (margin one radius; a Newton step moves
# nodes 0.01–0.4 radii): a query took 1.76 ms searching every time, 1.07 ms with a skin of 1 (its
# 2230 candidates against 1244 boxes and 694 pairs in reach), 1.05 with 0.5, 1.39 with 2.
NEIGHBOUR_SKIN = 1.0


@dataclass(frozen=True)
class ContactPairs:
    """Candidate pairs: ``pairs (P, 2)`` edge indices, ``images (P, 2)`` int tile image of the second
    edge, and the rigid maps that place the pair's four nodes ``(a0, a1, b0, b1)``:
    ``rotation (P, 4, 3, 3)``, ``translation (P, 4, 3)`` m (node ``m`` of pair ``p`` sits at
    ``rotation[p, m] x + translation[p, m]``; translations only, for a flat tiling)."""

    pairs: np.ndarray
    images: np.ndarray
    rotation: np.ndarray
    translation: np.ndarray

    def __len__(self) -> int:
        return len(self.pairs)

    @classmethod
    def empty(cls) -> "ContactPairs":
        return cls(np.empty((0, 2), dtype=np.int64), np.empty((0, 2), dtype=np.int64), np.empty((0, 4, 3, 3)),
                   np.empty((0, 4, 3)))

    def keys(self, n_edges: int) -> np.ndarray:
        """One integer per pair (edges and image), stable across queries."""
        # Images are bounded by the search range (a few tiles); 64 values per axis leave room.
        return ((self.pairs[:, 0] * n_edges + self.pairs[:, 1]) * 64 + self.images[:, 0] + 32) * 64 + self.images[:, 1] + 32

    def subset(self, which: np.ndarray) -> "ContactPairs":
        """The pairs ``which`` selects (a boolean mask, or indices in the order wanted)."""
        which = np.asarray(which)
        index = np.flatnonzero(which) if which.dtype == np.bool_ else which.astype(np.int64, copy=False)
        return ContactPairs(*_contact_kernels.gather_pairs(index, self.pairs, self.images, self.rotation,
                                                           self.translation))

    def transformed(self, matrix: np.ndarray) -> "ContactPairs":
        """The pairs with their maps where they are when the whole tiled configuration is mapped by
        the linear ``matrix`` (``(3, 3)``): the translations map, the rotations stay. Only for maps
        that turn nothing (a flat tiling's), as :func:`~yarnfit.engine.tiling.transform_images`."""
        return ContactPairs(self.pairs, self.images, self.rotation,
                            np.ascontiguousarray(self.translation @ np.asarray(matrix, dtype=np.float64).T))

    def kernel_args(self) -> tuple:
        """``(pairs, rotation, translation)`` as the contact kernels take them."""
        return self.pairs, self.rotation, self.translation


class TilingReachError(ValueError):
    """A configuration's contacts reach tiles a curved tiling has no maps for."""


def image_range(model: RodModel, position: np.ndarray, reach: float) -> np.ndarray:
    """Tile images ``(2,)`` to search: enough to cover the configuration's extent along each
    lattice vector plus ``reach`` (m); zero for a non-periodic model. A curved tiling caps it at the
    tiles its maps cover (less one, as an edge's end lies a tile further)."""
    if not model.periodic:
        return np.zeros(2, dtype=np.int64)
    lattice = model.lattice
    # Coordinates of the nodes along the lattice vectors (least squares: the lattice spans the
    # mid-surface plane, nodes also move out of it).
    coords = np.linalg.lstsq(lattice.T, position.T, rcond=None)[0]
    span = coords.max(axis=1) - coords.min(axis=1)
    lengths = np.linalg.norm(lattice, axis=1)
    needed = np.array([math.ceil(span[k] + reach / lengths[k]) for k in range(2)], dtype=np.int64)
    if model.tiling is not None:
        cap = model.tiling.reach - 1
        if np.any(needed > cap):
            raise TilingReachError(f"contacts reach {tuple(int(v) for v in needed)} tiles but the curved tiling covers only "
                             f"{cap} beyond the home tile; build it with a larger reach")
    return needed


class ImageMaps:
    """The rigid maps that carry every edge's two nodes to every tile image a contact search of a
    curved tiling looks at, per search range ``(si, sj)`` (tiles ``|i| ≤ si``, ``|j| ≤ sj``).

    They depend on the model alone, but a query used to rebuild them for every edge at every tile
    (and the pairs' maps again after it), twice per Newton iteration: a fifth of a HYLC
    stockinette sample's time. Keep one per model and pass it to :func:`find_pairs`; the maps are
    the same numbers either way, so the pairs and their maps are too.
    """

    def __init__(self, model: RodModel):
        self.model = model
        self._rows: dict[tuple[int, int], _ImageRows] = {}

    def rows(self, searched: np.ndarray) -> "_ImageRows":
        key = (int(searched[0]), int(searched[1]))
        rows = self._rows.get(key)
        if rows is None:
            rows = self._rows[key] = _image_rows(self.model, *key)
        return rows


@dataclass(frozen=True)
class _ImageRows:
    """Every edge at every tile of a search range, tile-major (row ``k E + e``: edge e in tile
    ``tiles[k]``): its start node mapped into the tile (``r0``, ``t0``), its end node into the tile
    plus the edge's own tile offset (``r1``, ``t1``)."""

    si: int
    sj: int
    n_edges: int
    edge: np.ndarray
    image: np.ndarray
    start: np.ndarray
    finish: np.ndarray
    r0: np.ndarray
    t0: np.ndarray
    r1: np.ndarray
    t1: np.ndarray
    home: np.ndarray

    def row(self, edges: np.ndarray, images: np.ndarray) -> np.ndarray:
        """Rows of ``edges`` at tile ``images (P, 2)``."""
        tile = (images[:, 0] + self.si) * (2 * self.sj + 1) + (images[:, 1] + self.sj)
        return tile * self.n_edges + edges


def _image_rows(model: RodModel, si: int, sj: int) -> _ImageRows:
    m = model
    tiles = np.array([(i, j) for i in range(-si, si + 1) for j in range(-sj, sj + 1)], dtype=np.int64)  # (T, 2)
    edge = np.tile(np.arange(m.n_edges), len(tiles))
    image = np.repeat(tiles, m.n_edges, axis=0)
    start, finish = m.edge_nodes[edge, 0], m.edge_nodes[edge, 1]
    r0, t0 = node_maps(m, start, image)
    r1, t1 = node_maps(m, finish, image + m.edge_tile[edge])
    return _ImageRows(si, sj, m.n_edges, edge, image, start, finish, r0, t0, r1, t1, np.all(image == 0, axis=1))


def find_pairs(model: RodModel, position: np.ndarray, margin: float, position_end: np.ndarray | None = None,
               maps: ImageMaps | None = None, within: float | None = None) -> ContactPairs:
    """Candidate pairs near ``position`` or anywhere on the way to ``position_end`` (m), their
    boxes inflated by radius plus ``margin / 2`` (m). ``maps``: the model's :class:`ImageMaps`
    (curved tilings; built for this query when not given). ``within`` (m): keep only the pairs
    whose segments come within ``ra + rb + within`` of each other on the way (boxes overlap far
    beyond that: a dense weave's strip, 25,600 candidates of which 15,600 within a radius)."""
    m = model
    end = position if position_end is None else np.ascontiguousarray(position_end)
    reach = 2.0 * float(m.edge_radius.max()) + margin + float(m.edge_rest_length.max())
    if position_end is not None:
        reach += float(np.abs(end - position).max(initial=0.0))
    searched = image_range(m, position, reach)
    if m.tiling is None:
        pairs, images = _contact_kernels.broad_phase(
            position, end, m.edge_nodes, m.edge_end_rotation, m.edge_offset, m.edge_radius, m.edge_rod,
            m.edge_chain_tile, m.edge_arc_start, m.edge_rest_length, m.rod_length, m.rod_closed, m.rod_period,
            m.lattice, searched, ~m.node_pinned, margin, CONTACT_EXCLUSION_FACTOR,
        )
        return _within(m, position, end, ContactPairs(pairs, images, *_pair_maps(m, pairs, images)), within)
    rows = (maps if maps is not None else ImageMaps(m)).rows(searched)
    boxes = _curved_virtual_boxes(m, rows, position, end, margin)
    pairs, images = _contact_kernels.pairs_of_boxes(
        *boxes, m.edge_nodes, m.edge_rod, m.edge_chain_tile, m.edge_arc_start, m.edge_rest_length, m.edge_radius,
        m.rod_length, m.rod_closed, m.rod_period, ~m.node_pinned, CONTACT_EXCLUSION_FACTOR,
    )
    return _within(m, position, end, ContactPairs(pairs, images, *_pair_maps(m, pairs, images, rows)), within)


def _within(model: RodModel, position, end, pairs: ContactPairs, within: float | None) -> ContactPairs:
    """``pairs`` cut to those within reach (see :func:`find_pairs`), without copying them."""
    if within is None or len(pairs) == 0:
        return pairs
    kept = _contact_kernels.keep_pairs_in_reach(position, end, model.edge_nodes, model.edge_radius, pairs.pairs,
                                                pairs.images, pairs.rotation, pairs.translation, float(within))
    return ContactPairs(pairs.pairs[:kept], pairs.images[:kept], pairs.rotation[:kept], pairs.translation[:kept])


def _pair_maps(model: RodModel, pairs: np.ndarray, images: np.ndarray,
               rows: _ImageRows | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Rigid maps of the nodes ``(a0, a1, b0, b1)`` of each pair: a0 stays, a1 is edge a's end in
    its tile, b's nodes go to their images in tile ``image`` (b1 one edge tile further; read from
    ``rows`` when given, the images' maps of a curved tiling)."""
    n = len(pairs)
    rotation = np.empty((n, 4, 3, 3))
    translation = np.empty((n, 4, 3))
    a, b = pairs[:, 0], pairs[:, 1]
    if rows is not None:
        _contact_kernels.gather_pair_maps(pairs, rows.row(b, images), model.edge_end_rotation, model.edge_offset,
                                          rows.r0, rows.t0, rows.r1, rows.t1, rotation, translation)
        return rotation, translation
    if model.tiling is None:
        _contact_kernels.flat_pair_maps(pairs, images, model.edge_nodes, model.edge_tile, model.edge_end_rotation,
                                        model.edge_offset, model.lattice, rotation, translation)
        return rotation, translation
    rotation[:, 0] = np.eye(3)
    translation[:, 0] = 0.0
    rotation[:, 1] = model.edge_end_rotation[a]
    translation[:, 1] = model.edge_offset[a]
    rotation[:, 2], translation[:, 2] = node_maps(model, model.edge_nodes[b, 0], images)
    rotation[:, 3], translation[:, 3] = node_maps(model, model.edge_nodes[b, 1], images + model.edge_tile[b])
    return rotation, translation


def _curved_virtual_boxes(model: RodModel, rows: _ImageRows, position, end, margin):
    """Boxes of every edge at every tile image of ``rows`` that can reach the home tile's boxes,
    each edge's nodes placed by their own maps: ``(edge, image, lower, upper)``."""
    m = model
    lower = np.empty((len(rows.edge), 3))
    upper = np.empty((len(rows.edge), 3))
    _contact_kernels.mapped_edge_boxes(position, end, rows.edge, rows.start, rows.r0, rows.t0, rows.finish, rows.r1,
                                       rows.t1, m.edge_radius, 0.5 * margin, lower, upper)
    # Keep only boxes that overlap the hull of the home tile's boxes.
    hull_lo, hull_hi = lower[rows.home].min(axis=0), upper[rows.home].max(axis=0)
    keep = np.all((lower <= hull_hi) & (upper >= hull_lo), axis=1)
    return (np.ascontiguousarray(rows.edge[keep]), np.ascontiguousarray(rows.image[keep]),
            np.ascontiguousarray(lower[keep]), np.ascontiguousarray(upper[keep]))


class NeighbourList:
    """Contact candidates of one model reused across queries (Verlet lists: L. Verlet, Phys. Rev.
    159 (1967) 98). The candidates are the pairs whose boxes overlap with ``margin`` widened by
    ``skin`` (m; default :data:`NEIGHBOUR_SKIN` margins) at reference positions. While every node
    lies within ``skin / 2`` of its reference position (at both ends of a swept query), each box of
    a search with the plain margin lies inside its box of the widened search, so every pair such a
    search finds is a candidate; a query keeps the candidates within ``ra + rb + within`` (as
    :func:`find_pairs` with ``within``) without searching again. A query beyond the skin searches
    anew at its start; one whose sweep alone outruns the skin, or whose widened search would reach
    beyond a curved tiling's maps, is a plain :func:`find_pairs`. Same pairs as
    :func:`find_pairs` for a configuration (a swept query may keep a few more: pairs whose boxes
    miss but whose distance less their travel does not); their order is the widened search's.
    ``searches`` counts the searches made (widened or plain) and ``queries`` the queries."""

    def __init__(self, model: RodModel, margin: float, maps: ImageMaps | None = None, skin: float | None = None):
        self.model = model
        self.margin = float(margin)
        self.skin = NEIGHBOUR_SKIN * self.margin if skin is None else float(skin)
        self.maps = maps if maps is not None or model.tiling is None else ImageMaps(model)
        self._reference: np.ndarray | None = None
        self._candidates = ContactPairs.empty()
        self._distance = np.empty(0)
        self.searches = 0
        self.queries = 0

    def query(self, position: np.ndarray, position_end: np.ndarray | None, within: float) -> ContactPairs:
        """The pairs within ``ra + rb + within`` (m) of each other at ``position`` or on the way to
        ``position_end`` (``None``: at ``position`` only); ``within`` at most the list's margin."""
        if not within <= self.margin:
            raise ValueError(f"within ({within!r} m) must not exceed the neighbour list's margin ({self.margin!r} m)")
        self.queries += 1
        end = position if position_end is None else position_end
        if not self._covers(position, end):
            self._search(position)
            if not self._covers(position, end):
                self.searches += 1
                return find_pairs(self.model, position, self.margin, position_end, self.maps, within=within)
        c = self._candidates
        if len(c) == 0:
            return c
        kept = _contact_kernels.pairs_in_reach_near(position, end, self._reference, self._distance,
                                                    self.model.edge_nodes, self.model.edge_radius, c.pairs, c.rotation,
                                                    c.translation, float(within))
        return c.subset(kept)

    def _covers(self, position: np.ndarray, end: np.ndarray) -> bool:
        if self._reference is None:
            return False
        limit = (0.5 * self.skin) ** 2
        return bool(_contact_kernels.largest_squared_move(self._reference, position) <= limit
                    and (end is position or _contact_kernels.largest_squared_move(self._reference, end) <= limit))

    def _search(self, position: np.ndarray) -> None:
        self.searches += 1
        try:
            candidates = find_pairs(self.model, position, self.margin + self.skin, None, self.maps)
        except TilingReachError:
            # The widened search reaches further than the maps; plain searches may not.
            self._reference = None
            return
        # A pair further apart than ra + rb + margin + 3 skins now cannot be in reach of a covered
        # query: its nodes move by half a skin each, and a sweep's nodes by a skin more.
        distance = pair_distances(self.model, position, candidates)
        near = distance <= self.model.edge_radius[candidates.pairs].sum(axis=1) + self.margin + 3.0 * self.skin
        self._candidates = candidates.subset(near)
        self._distance = distance[near]
        self._reference = np.array(position)


def pair_distances(model: RodModel, position: np.ndarray, pairs: ContactPairs) -> np.ndarray:
    """Centreline distance of every pair (m, ``(P,)``)."""
    out = np.empty(len(pairs))
    _contact_kernels.pair_distances(position, model.edge_nodes, *pairs.kernel_args(), out)
    return out


def max_penetration(model: RodModel, position: np.ndarray) -> float:
    """Largest overlap ``(ra + rb − d) / (ra + rb)`` of any two segments, periodic images
    included (0 when none overlap)."""
    pairs = find_pairs(model, position, float(model.edge_radius.min()))
    if len(pairs) == 0:
        return 0.0
    rsum = model.edge_radius[pairs.pairs[:, 0]] + model.edge_radius[pairs.pairs[:, 1]]
    return float(max(0.0, np.max((rsum - pair_distances(model, position, pairs)) / rsum)))
