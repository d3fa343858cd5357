"""A strip cut from the yarn-level swatch (:class:`Swatch`, made by
:func:`yarnfit.validate.swatch.cut_swatch`) and what its tensile test reads off it: its width at
mid-length, the strain and the width of its middle between material marks (as an extensometer
reads them), how far its cut yarn ends were drawn in, and the pull carried across planes by each
quarter of its width. Each is a function of the strip and its positions (or its equilibrium), in
the strip's world frame: x the pull, y across, z the fabric normal."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..engine import RodModel, RodState
from ..engine.contact_lagrangian import ContactSet, contact_gradient
from ..engine.energy import element_forces
from ..engine.friction import FrictionAnchors


@dataclass(frozen=True)
class Swatch:
    """A strip cut from an unrolled repeat, in world coordinates (x pull, y across, z normal).

    Attributes:
        model: open rods (one per cut yarn piece), jaw nodes pinned.
        position: ``(N, 3)`` the rest (relaxed, unstrained) positions (m).
        moving: node indices of the +x jaw; ``fixed``: of the −x jaw.
        length, width, gauge, clamp: strip length, width, free length between the jaws and the
            band of each jaw (m).
        radius: yarn radius (m).
        direction: ``weft``, ``warp``, ``bias`` or an angle name.
        angle_deg: angle of the pull from the weft (degrees).
    """

    model: RodModel
    position: np.ndarray
    moving: np.ndarray
    fixed: np.ndarray
    length: float
    width: float
    gauge: float
    clamp: float
    radius: float
    direction: str
    angle_deg: float


# Edges count towards the mid-length width only if they cross the mid-length plane at more than
# 30° from it (|Δx| ≥ sin 30° |e|); see mid_width.
CROSSING_SLOPE = 0.5
# The extensometer of mid_strain: two marks a quarter of the gauge either side of mid-length (the
# middle half, where a strip 4/3 as long as wide is farthest from its jaws), each the nodes within
# MARK_BAND of the gauge of it at rest (a band, not a plane: a knit's loops put nodes of one course
# at many x) and within the middle half of the width (the cut ends at the long sides splay).
EXTENSOMETER_SPAN = 0.5
MARK_BAND = 0.05
# The pull across the strip is read on this many planes, evenly over the middle half of the gauge
# (cut_forces): a knit's loops and a weave's crossings cross a plane differently at each x, so the
# middle half of the width carries a share of the pull that varies along a repeat; the mean over
# planes spread over two repeats (a 4-repeat gauge) or more is the middle's pull.
CUT_PLANES = 9


def mid_length(swatch: Swatch, position: np.ndarray) -> float:
    """x (m) halfway between the jaws' inner edges at ``position (N, 3)``: where the strip's
    middle is measured."""
    return 0.5 * float(position[swatch.moving, 0].min() + position[swatch.fixed, 0].max())


def centre_line(swatch: Swatch) -> float:
    """y (m) of the strip's centre line at rest, halfway between its long sides."""
    return 0.5 * float(swatch.position[:, 1].max() + swatch.position[:, 1].min())


def mid_width(swatch: Swatch, position: np.ndarray) -> float:
    """Width (m) at mid-length: the span across the strip (y) of the points where yarn centrelines
    pass through the plane halfway between the jaws' current positions, plus one yarn diameter.
    Only edges crossing that plane at more than 30° from it count (``|Δx| ≥ |e| / 2``): yarns
    lying along the plane (a weft strip's warps) would add their cut ends, which splay out at the
    long sides as the strip is pulled (cotton twill, weft strip at 5 %: +6 % width with them)."""
    mid = mid_length(swatch, position)
    a = position[swatch.model.edge_nodes[:, 0]]
    b = position[swatch.model.edge_nodes[:, 1]]
    crossing = (a[:, 0] - mid) * (b[:, 0] - mid) <= 0.0
    crossing &= np.abs(b[:, 0] - a[:, 0]) >= CROSSING_SLOPE * np.linalg.norm(b - a, axis=1)
    crossing &= a[:, 0] != b[:, 0]
    t = (mid - a[crossing, 0]) / (b[crossing, 0] - a[crossing, 0])
    y = a[crossing, 1] + t * (b[crossing, 1] - a[crossing, 1])
    return float(y.max() - y.min() + 2.0 * swatch.radius)


def mid_strain(swatch: Swatch, position: np.ndarray) -> float:
    """Engineering strain of the strip's middle, read as a tensile tester's extensometer reads it:
    the distance along x between two marks :data:`EXTENSOMETER_SPAN` of the gauge apart about
    mid-length, each the mean x of the nodes that lay within :data:`MARK_BAND` of the gauge of it
    at rest and in the middle half of the width, over that distance at rest, minus 1. Where the
    strip is uniform it is the nominal strain (the jaws' travel over the gauge); near stiff or
    constraining jaws the middle strains more or less than that. NaN where a mark holds no node."""
    rest = swatch.position
    inner = np.abs(rest[:, 1] - centre_line(swatch)) <= 0.25 * swatch.width
    return between_marks(rest, position, 0, mid_length(swatch, rest), 0.5 * EXTENSOMETER_SPAN * swatch.gauge,
                          MARK_BAND * swatch.gauge, inner) - 1.0


def middle_compression(swatch: Swatch, position: np.ndarray) -> float:
    """Width ratio of the strip's middle half, read as a transverse extensometer reads it: the
    distance across the strip (y) between two material marks half the width apart about the
    centre line, each the mean y of the nodes that lay within :data:`MARK_BAND` of the width of
    it at rest and in the middle half of the gauge, over that distance at rest. Where the strip is
    uniform it narrows as the whole width does; a knit's cut sides, drawn in, narrow the whole
    width more (:func:`mid_width`). NaN where a mark holds no node."""
    rest = swatch.position
    inner = np.abs(rest[:, 0] - mid_length(swatch, rest)) <= 0.25 * swatch.gauge
    return between_marks(rest, position, 1, centre_line(swatch), 0.25 * swatch.width, MARK_BAND * swatch.width,
                          inner)


def between_marks(rest: np.ndarray, position: np.ndarray, axis: int, centre: float, offset: float, band: float,
                   inner: np.ndarray) -> float:
    """The distance along ``axis`` between two material marks at ``centre ± offset`` (m, at
    rest), each the mean coordinate of the ``inner`` nodes within ``band`` of it at rest, at
    ``position`` over that at ``rest``; NaN where a mark holds no node."""
    marks = []
    for side in (-1.0, 1.0):
        near = inner & (np.abs(rest[:, axis] - (centre + side * offset)) <= band)
        if not near.any():
            return math.nan
        marks.append((float(rest[near, axis].mean()), float(position[near, axis].mean())))
    return (marks[1][1] - marks[0][1]) / (marks[1][0] - marks[0][0])


def extent_width(swatch: Swatch, position: np.ndarray, band: float) -> float:
    """Width (m) from all nodes within ``band`` of mid-length in x: their span in y plus one
    diameter (loose cut ends at the long sides included)."""
    near = np.abs(position[:, 0] - mid_length(swatch, position)) <= band
    y = position[near, 1]
    return float(y.max() - y.min() + 2.0 * swatch.radius)


def free_side_ends(swatch: Swatch) -> np.ndarray:
    """Indices of the yarn ends cut at the long sides within the middle half of the gauge (where
    :func:`mid_width` measures): the first and last node of every piece, unpinned, at rest within a
    quarter gauge of mid-length."""
    model = swatch.model
    ends = np.unique(np.concatenate([model.rod_node_start[:-1], model.rod_node_start[1:] - 1]))
    ends = ends[~model.node_pinned[ends]]
    x = swatch.position[ends, 0]
    return ends[np.abs(x - mid_length(swatch, swatch.position)) <= 0.25 * swatch.gauge]


def edge_draw_in(swatch: Swatch, position: np.ndarray, compression_ratio: float) -> float:
    """Mean distance (m) the yarn ends cut at the long sides (:func:`free_side_ends`) lie inside
    where the strip's narrowing alone puts them: each end's rest offset from the strip's centre
    line, scaled by ``compression_ratio``, against its offset now. Positive: yarn has slid in from
    the cut sides (a frictionless cut knit feeds its loops from its free ends, which no periodic
    repeat can). NaN when no end is cut there."""
    ends = free_side_ends(swatch)
    if len(ends) == 0:
        return math.nan
    centre = centre_line(swatch)
    offset = swatch.position[ends, 1] - centre
    return float(np.mean(np.sign(offset) * (compression_ratio * offset - (position[ends, 1] - centre))))


@dataclass(frozen=True)
class CutForces:
    """The pull carried across planes across the strip (x = const, current positions), each the
    x force (N) the strip beyond the plane exerts on the part before it.

    Attributes:
        plane_x: ``(K,)`` the planes (m), evenly over the middle half of the gauge.
        quarters: ``(K, 4)`` carried by the rod elements, contact pairs and friction anchors of
            each quarter of the width, from −y to +y (a term belongs to the quarter its nodes'
            mean y at rest lies in; those beyond the strip's sides to the outer quarters).
    """

    plane_x: np.ndarray
    quarters: np.ndarray

    @property
    def whole(self) -> np.ndarray:
        """``(K,)`` over the whole width: the fixed jaw's pull wherever the plane lies, to the
        solve's residual (the part before the plane is a free body held by that jaw)."""
        return self.quarters.sum(axis=1)

    @property
    def middle(self) -> np.ndarray:
        """``(K,)`` over the middle half of the width (the two inner quarters): the strip's own
        pull where it is furthest from its cut sides."""
        return self.quarters[:, 1] + self.quarters[:, 2]


def cut_forces(swatch: Swatch, state: RodState, contacts: ContactSet, anchors: FrictionAnchors | None = None,
               planes: int = CUT_PLANES) -> CutForces:
    """The pull across ``planes`` planes over the middle half of the gauge at ``state`` (an
    equilibrium of the rods, the augmented-Lagrangian ``contacts`` it balances and the friction
    ``anchors`` it was solved with), per quarter of the width (:class:`CutForces`).

    The force a part of the strip receives across a cut is the sum, over the energy terms that
    join nodes on both sides, of minus their gradient at the part's nodes: the stretch–shear
    elements the plane crosses (:func:`~yarnfit.engine.energy.element_forces`; bend–twist
    elements act on frames only), the contact pairs and the friction anchors with nodes on both
    sides. A term with all its nodes on one side adds nothing (its gradient sums to zero there), so
    the sum runs over every term of a band and the plane picks out the crossing ones."""
    model = swatch.model
    if model.periodic:
        raise ValueError("cut forces are measured on a cut (non-periodic) swatch")
    position = np.ascontiguousarray(state.node_position, dtype=np.float64)
    rest_y = swatch.position[:, 1]
    side = centre_line(swatch) - 0.5 * swatch.width

    def quarter(nodes: np.ndarray) -> np.ndarray:
        """The quarter of the width (0–3) each term with ``nodes (T, k)`` belongs to."""
        at = (rest_y[nodes].mean(axis=1) - side) / (0.25 * swatch.width)
        return np.clip(np.floor(at), 0, 3).astype(np.int64)

    element = element_forces(model, position, state.edge_quaternion)
    edge_nodes = model.edge_nodes
    edge_quarter = quarter(edge_nodes)
    pair_quarter = quarter(edge_nodes[contacts.pairs.pairs].reshape(-1, 4))
    anchor_quarter = None if anchors is None else quarter(anchors.nodes)
    gradients = np.zeros((4, *position.shape))
    for band, gradient in enumerate(gradients):
        edges = edge_quarter == band
        np.add.at(gradient, edge_nodes[edges, 0], -element[edges])
        np.add.at(gradient, edge_nodes[edges, 1], element[edges])
        gradient += contact_gradient(model, position, contacts.subset(np.flatnonzero(pair_quarter == band)))
        if anchor_quarter is not None and np.any(anchor_quarter == band):
            gradient += anchors.subset(anchor_quarter == band).energy_gradient(position)[1]
    mid, half = mid_length(swatch, position), 0.25 * float(position[swatch.moving, 0].min()
                                                          - position[swatch.fixed, 0].max())
    plane_x = mid + half * np.linspace(-1.0, 1.0, planes)
    before = position[:, 0][None, :] < plane_x[:, None]
    return CutForces(plane_x, -(before @ gradients[:, :, 0].T))
