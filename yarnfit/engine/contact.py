"""Contact candidates of a configuration: edge pairs with the periodic image of their second edge.

Both solvers ask :func:`find_pairs` for the pairs near a configuration (or near a motion between
two configurations); the narrow phase and responses live in ``_contact_kernels``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from . import _contact_kernels
from .model import CONTACT_EXCLUSION_FACTOR, RodModel


@dataclass(frozen=True)
class ContactPairs:
    """Candidate pairs: ``pairs (P, 2)`` edge indices, ``images (P, 2)`` int tile image of the second
    edge, ``shift (P, 3)`` m, the translation of that image (``images @ lattice``)."""

    pairs: np.ndarray
    images: np.ndarray
    shift: np.ndarray

    def __len__(self) -> int:
        return len(self.pairs)

    @classmethod
    def empty(cls) -> "ContactPairs":
        return cls(np.empty((0, 2), dtype=np.int64), np.empty((0, 2), dtype=np.int64), np.empty((0, 3)))

    def keys(self, n_edges: int) -> np.ndarray:
        """One integer per pair (edges and image), stable across queries."""
        # Images are bounded by the search range (a few tiles); 64 values per axis leave room.
        return ((self.pairs[:, 0] * n_edges + self.pairs[:, 1]) * 64 + self.images[:, 0] + 32) * 64 + self.images[:, 1] + 32

    def subset(self, mask: np.ndarray) -> "ContactPairs":
        return ContactPairs(self.pairs[mask], self.images[mask], self.shift[mask])


def image_range(model: RodModel, position: np.ndarray, reach: float) -> np.ndarray:
    """Tile images ``(2,)`` to search: enough to cover the configuration's extent along each
    lattice vector plus ``reach`` (m); zero for a non-periodic model."""
    if not model.periodic:
        return np.zeros(2, dtype=np.int64)
    lattice = model.lattice
    # Coordinates of the nodes along the lattice vectors (least squares: the lattice spans the
    # mid-surface plane, nodes also move out of it).
    coords = np.linalg.lstsq(lattice.T, position.T, rcond=None)[0]
    span = coords.max(axis=1) - coords.min(axis=1)
    lengths = np.linalg.norm(lattice, axis=1)
    return np.array([math.ceil(span[k] + reach / lengths[k]) for k in range(2)], dtype=np.int64)


def find_pairs(model: RodModel, position: np.ndarray, margin: float, position_end: np.ndarray | None = None) -> ContactPairs:
    """Candidate pairs near ``position`` or anywhere on the way to ``position_end`` (m), their
    boxes inflated by radius plus ``margin / 2`` (m)."""
    m = model
    end = position if position_end is None else np.ascontiguousarray(position_end)
    reach = 2.0 * float(m.edge_radius.max()) + margin + float(m.edge_rest_length.max())
    if position_end is not None:
        reach += float(np.abs(end - position).max(initial=0.0))
    images_searched = image_range(m, position, reach)
    pairs, images = _contact_kernels.broad_phase(
        position, end, m.edge_nodes, m.edge_offset, m.edge_radius, m.edge_rod, m.edge_chain_tile, m.edge_arc_start,
        m.edge_rest_length, m.rod_length, m.rod_closed, m.rod_period, m.lattice, images_searched, ~m.node_pinned,
        margin, CONTACT_EXCLUSION_FACTOR,
    )
    return ContactPairs(pairs, images, np.ascontiguousarray(images @ m.lattice))


def pair_distances(model: RodModel, position: np.ndarray, pairs: ContactPairs) -> np.ndarray:
    """Centreline distance of every pair (m, ``(P,)``)."""
    out = np.empty(len(pairs))
    _contact_kernels.pair_distances(position, model.edge_nodes, model.edge_offset, pairs.pairs, pairs.shift, out)
    return out


def max_penetration(model: RodModel, position: np.ndarray) -> float:
    """Largest overlap ``(ra + rb − d) / (ra + rb)`` of any two segments, periodic images
    included (0 when none overlap)."""
    pairs = find_pairs(model, position, float(model.edge_radius.min()))
    if len(pairs) == 0:
        return 0.0
    rsum = model.edge_radius[pairs.pairs[:, 0]] + model.edge_radius[pairs.pairs[:, 1]]
    return float(max(0.0, np.max((rsum - pair_distances(model, position, pairs)) / rsum)))
