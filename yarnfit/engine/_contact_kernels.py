"""Numba kernels of yarn–yarn contact: segment closest points, a uniform-grid broad phase, the
augmented-Lagrangian contact terms of the quasi-static solve and the XPBD contact projection with
position-based friction.

Only ``@njit`` code lives here. A contact is a pair of edges ``(a, b)``; its gap is
``g = |xa(s) − xb(t)| − (ra + rb)`` at the closest points ``xa(s) = (1 − s) a0 + s a1`` and
``xb(t) = (1 − t) b0 + t b1``; the constraint is unilateral, ``g ≥ 0`` (minimum centreline
distance ``ra + rb``, i.e. ``2r`` for equal yarns). The XPBD projection uses that gap. The
quasi-static terms sample it instead: points along each edge keep ``ra + rb`` from the other
segment. The closest-point gap of two parallel segments has a kink (tilting either way moves the
closest points to opposite ends), so a yarn resting along another made Newton stall with residuals
near 1e-3; point-to-segment distances are C¹, and a line contact spreads over the samples.
"""

import math

import numpy as np
from numba import njit

from ._quat import cross, dot, mat_t_vec, mat_vec, norm, pull_back_block, row3

# Relative size of a·e − b² below which two segments are treated as parallel (their closest
# points are then not unique and the middle of the overlap is used, a continuous choice).
_PARALLEL_TOLERANCE = 1e-12


@njit(cache=True)
def _clamp01(x):
    return 0.0 if x < 0.0 else (1.0 if x > 1.0 else x)


@njit(cache=True)
def segment_closest_points(a0, a1, b0, b1):
    """Closest points of segments ``a0a1`` and ``b0b1``.

    Returns ``(s, t, distance, normal)`` with ``normal`` the unit vector from ``xb(t)`` to
    ``xa(s)`` (a fallback perpendicular when the segments intersect).
    """
    d1 = (a1[0] - a0[0], a1[1] - a0[1], a1[2] - a0[2])
    d2 = (b1[0] - b0[0], b1[1] - b0[1], b1[2] - b0[2])
    r = (a0[0] - b0[0], a0[1] - b0[1], a0[2] - b0[2])
    a = dot(d1, d1)
    e = dot(d2, d2)
    f = dot(d2, r)
    c = dot(d1, r)
    b = dot(d1, d2)
    denom = a * e - b * b
    if denom > _PARALLEL_TOLERANCE * a * e:
        s = _clamp01((b * f - c * e) / denom)
    else:
        # Parallel: middle of the projection of b onto a.
        s = _clamp01(0.5 * ((-c) + (b - c)) / a)
    t = (b * s + f) / e
    if t < 0.0:
        t = 0.0
        s = _clamp01(-c / a)
    elif t > 1.0:
        t = 1.0
        s = _clamp01((b - c) / a)
    xa = (a0[0] + s * d1[0], a0[1] + s * d1[1], a0[2] + s * d1[2])
    xb = (b0[0] + t * d2[0], b0[1] + t * d2[1], b0[2] + t * d2[2])
    diff = (xa[0] - xb[0], xa[1] - xb[1], xa[2] - xb[2])
    dist = norm(diff)
    if dist > 1e-14 * math.sqrt(a + e):
        inv = 1.0 / dist
        return s, t, dist, (diff[0] * inv, diff[1] * inv, diff[2] * inv)
    nrm = cross(d1, d2)
    nn = norm(nrm)
    if nn < 1e-14 * math.sqrt(a * e):
        # Intersecting and parallel: any direction perpendicular to a.
        nrm = cross(d1, (1.0, 0.0, 0.0)) if abs(d1[0]) < 0.9 * math.sqrt(a) else cross(d1, (0.0, 1.0, 0.0))
        nn = norm(nrm)
    return s, t, dist, (nrm[0] / nn, nrm[1] / nn, nrm[2] / nn)


@njit(cache=True)
def _map(rotation, translation, v):
    """``rotation v + translation`` (3×3 and 3-vector rows)."""
    r = mat_vec(rotation, v)
    return (r[0] + translation[0], r[1] + translation[1], r[2] + translation[2])


@njit(cache=True)
def _edge_points(pos, edge_nodes, edge_end_rotation, edge_offset, e):
    """End points of edge ``e`` in its home tile (its end node mapped into the edge's tile)."""
    p0 = row3(pos, edge_nodes[e, 0])
    p1 = _map(edge_end_rotation[e], edge_offset[e], row3(pos, edge_nodes[e, 1]))
    return p0, p1


@njit(cache=True)
def _pair_nodes(edge_nodes, pairs, p):
    """The four nodes ``(a0, a1, b0, b1)`` of pair ``p``."""
    return (edge_nodes[pairs[p, 0], 0], edge_nodes[pairs[p, 0], 1], edge_nodes[pairs[p, 1], 0],
            edge_nodes[pairs[p, 1], 1])


@njit(cache=True)
def _pair_points(pos, edge_nodes, pairs, pair_rotation, pair_translation, p):
    """End points ``(a0, a1, b0, b1)`` of pair ``p``: node ``m`` of the pair mapped by
    ``pair_rotation[p, m] x + pair_translation[p, m]`` (its tile image)."""
    nodes = _pair_nodes(edge_nodes, pairs, p)
    return (_map(pair_rotation[p, 0], pair_translation[p, 0], row3(pos, nodes[0])),
            _map(pair_rotation[p, 1], pair_translation[p, 1], row3(pos, nodes[1])),
            _map(pair_rotation[p, 2], pair_translation[p, 2], row3(pos, nodes[2])),
            _map(pair_rotation[p, 3], pair_translation[p, 3], row3(pos, nodes[3])))


# ---------------------------------------------------------------------------------------------
# Broad phase
# ---------------------------------------------------------------------------------------------


@njit(cache=True)
def _pair_excluded(a, b, image_x, image_y, edge_rod, edge_chain_tile, edge_arc_start, edge_rest_length, edge_radius,
                   rod_length, rod_closed, rod_period, exclusion_factor):
    """Edges ``a`` and ``b`` (at tile image (image_x, image_y)) are neighbours along one yarn.

    Unroll the yarn into one infinite chain: edge ``e`` sits there moved by its ``edge_chain_tile``
    C_e, and its copy ``k`` periods on (period P tiles, length L per period) lies ``k L`` further
    along. Edge b at image I is that copy, seen from edge a, when ``I + C_a − C_b = k P``; any
    other image is another yarn copy. A closed loop that stays in its tile (P = 0) wraps around
    instead. Pairs closer than ``exclusion_factor · (ra + rb)`` in rest arc length never make
    contact.
    """
    r = edge_rod[a]
    if edge_rod[b] != r:
        return False
    shift_x = image_x + edge_chain_tile[a, 0] - edge_chain_tile[b, 0]
    shift_y = image_y + edge_chain_tile[a, 1] - edge_chain_tile[b, 1]
    px = rod_period[r, 0]
    py = rod_period[r, 1]
    sa = edge_arc_start[a]
    la = edge_rest_length[a]
    sb = edge_arc_start[b]
    lb = edge_rest_length[b]
    threshold = exclusion_factor * (edge_radius[a] + edge_radius[b])
    if px == 0 and py == 0:
        if shift_x != 0 or shift_y != 0:
            return False
        gap = _interval_gap(sa, la, sb, lb)
        if rod_closed[r]:
            length = rod_length[r]
            gap = min(gap, _interval_gap(sa, la, sb + length, lb), _interval_gap(sa, la, sb - length, lb))
        return gap < threshold
    # The shift must be a whole number of yarn periods.
    if shift_x * py != shift_y * px:
        return False
    k = (shift_x * px + shift_y * py) // (px * px + py * py)
    if k * px != shift_x or k * py != shift_y:
        return False
    return _interval_gap(sa, la, sb + k * rod_length[r], lb) < threshold


@njit(cache=True)
def _interval_gap(start_a, length_a, start_b, length_b):
    """Distance between the intervals [start, start + length] (0 when they touch or overlap)."""
    return max(start_b - (start_a + length_a), start_a - (start_b + length_b), 0.0)


@njit(cache=True)
def edge_boxes(pos, pos_end, edge_nodes, edge_end_rotation, edge_offset, edge_radius, margin, lower, upper):
    """Axis-aligned boxes ``(E, 3)`` of the edges swept from ``pos`` to ``pos_end``, inflated by
    ``radius + margin / 2``."""
    for e in range(edge_nodes.shape[0]):
        p0, p1 = _edge_points(pos, edge_nodes, edge_end_rotation, edge_offset, e)
        q0, q1 = _edge_points(pos_end, edge_nodes, edge_end_rotation, edge_offset, e)
        pad = edge_radius[e] + 0.5 * margin
        for k in range(3):
            lower[e, k] = min(min(p0[k], p1[k]), min(q0[k], q1[k])) - pad
            upper[e, k] = max(max(p0[k], p1[k]), max(q0[k], q1[k])) + pad


@njit(cache=True)
def _virtual_boxes(lower, upper, lattice, image_range):
    """Copies of the edge boxes at every tile image within ``image_range`` that can reach the
    boxes of the home tile. Returns ``(edge, image (M, 2), lower (M, 3), upper (M, 3))``."""
    n_edges = lower.shape[0]
    hull_lo = np.empty(3)
    hull_hi = np.empty(3)
    for k in range(3):
        hull_lo[k] = lower[:, k].min()
        hull_hi[k] = upper[:, k].max()
    nx = 2 * image_range[0] + 1
    ny = 2 * image_range[1] + 1
    count = 0
    for pass_ in range(2):
        if pass_ == 1:
            v_edge = np.empty(count, dtype=np.int64)
            v_image = np.empty((count, 2), dtype=np.int64)
            v_lower = np.empty((count, 3))
            v_upper = np.empty((count, 3))
            count = 0
        for ix in range(nx):
            for iy in range(ny):
                i = ix - image_range[0]
                j = iy - image_range[1]
                shift = (i * lattice[0, 0] + j * lattice[1, 0], i * lattice[0, 1] + j * lattice[1, 1],
                         i * lattice[0, 2] + j * lattice[1, 2])
                for e in range(n_edges):
                    inside = True
                    for k in range(3):
                        if lower[e, k] + shift[k] > hull_hi[k] or upper[e, k] + shift[k] < hull_lo[k]:
                            inside = False
                            break
                    if not inside:
                        continue
                    if pass_ == 1:
                        v_edge[count] = e
                        v_image[count, 0] = i
                        v_image[count, 1] = j
                        for k in range(3):
                            v_lower[count, k] = lower[e, k] + shift[k]
                            v_upper[count, k] = upper[e, k] + shift[k]
                    count += 1
    return v_edge, v_image, v_lower, v_upper


@njit(cache=True)
def mapped_edge_boxes(pos, pos_end, row_edge, start, r0, t0, finish, r1, t1, edge_radius, half_margin, lower, upper):
    """Boxes of edges placed by per-row rigid maps (a curved tiling's images): row ``i`` is edge
    ``row_edge[i]`` with node ``start[i]`` at ``r0[i] x + t0[i]`` and node ``finish[i]`` at
    ``r1[i] x + t1[i]``, at ``pos`` and at ``pos_end``; each box is inflated by the edge's radius
    plus ``half_margin`` (m). Writes ``lower``, ``upper`` ``(rows, 3)``."""
    for i in range(row_edge.shape[0]):
        pad = edge_radius[row_edge[i]] + half_margin
        for k in range(3):
            lower[i, k] = np.inf
            upper[i, k] = -np.inf
        for x in (pos, pos_end):
            for end in range(2):
                node = start[i] if end == 0 else finish[i]
                for k in range(3):
                    if end == 0:
                        v = r0[i, k, 0] * x[node, 0] + r0[i, k, 1] * x[node, 1] + r0[i, k, 2] * x[node, 2] + t0[i, k]
                    else:
                        v = r1[i, k, 0] * x[node, 0] + r1[i, k, 1] * x[node, 1] + r1[i, k, 2] * x[node, 2] + t1[i, k]
                    lower[i, k] = min(lower[i, k], v)
                    upper[i, k] = max(upper[i, k], v)
        for k in range(3):
            lower[i, k] -= pad
            upper[i, k] += pad


@njit(cache=True)
def gather_pair_maps(pairs, row, edge_end_rotation, edge_offset, r0, t0, r1, t1, rotation, translation):
    """Rigid maps of the nodes ``(a0, a1, b0, b1)`` of each pair into ``rotation (P, 4, 3, 3)`` and
    ``translation (P, 4, 3)``: a0 stays, a1 is edge a's end in its tile, b's nodes are read from
    row ``row[p]`` of a curved tiling's image maps (``r0``, ``t0`` its start, ``r1``, ``t1`` its end)."""
    for p in range(pairs.shape[0]):
        a = pairs[p, 0]
        i = row[p]
        for j in range(3):
            for k in range(3):
                rotation[p, 0, j, k] = 1.0 if j == k else 0.0
                rotation[p, 1, j, k] = edge_end_rotation[a, j, k]
                rotation[p, 2, j, k] = r0[i, j, k]
                rotation[p, 3, j, k] = r1[i, j, k]
            translation[p, 0, j] = 0.0
            translation[p, 1, j] = edge_offset[a, j]
            translation[p, 2, j] = t0[i, j]
            translation[p, 3, j] = t1[i, j]


@njit(cache=True)
def flat_pair_maps(pairs, images, edge_nodes, edge_tile, edge_end_rotation, edge_offset, lattice, rotation,
                   translation):
    """Rigid maps of the nodes ``(a0, a1, b0, b1)`` of each pair of a flat (or non-periodic) model
    into ``rotation (P, 4, 3, 3)`` and ``translation (P, 4, 3)``: a0 stays, a1 is edge a's end in
    its tile, b's nodes are translated by ``image @ lattice`` (b1 one edge tile further)."""
    for p in range(pairs.shape[0]):
        a = pairs[p, 0]
        b = pairs[p, 1]
        for j in range(3):
            for k in range(3):
                identity = 1.0 if j == k else 0.0
                rotation[p, 0, j, k] = identity
                rotation[p, 1, j, k] = edge_end_rotation[a, j, k]
                rotation[p, 2, j, k] = identity
                rotation[p, 3, j, k] = identity
            translation[p, 0, j] = 0.0
            translation[p, 1, j] = edge_offset[a, j]
            ix = images[p, 0]
            iy = images[p, 1]
            translation[p, 2, j] = ix * lattice[0, j] + iy * lattice[1, j]
            translation[p, 3, j] = (ix + edge_tile[b, 0]) * lattice[0, j] + (iy + edge_tile[b, 1]) * lattice[1, j]


@njit(cache=True)
def gather_pairs(which, pairs, images, rotation, translation):
    """Pairs ``which`` (indices) of a candidate list with their images and maps, in that order:
    ``(pairs, images, rotation, translation)`` new arrays. One pass over each pair's 52 numbers;
    numpy's fancy indexing, array by array, took 2.7 times as long, and a Newton iteration keeps
    a subset of its neighbour list twice."""
    n = which.shape[0]
    out_pairs = np.empty((n, 2), dtype=np.int64)
    out_images = np.empty((n, 2), dtype=np.int64)
    out_rotation = np.empty((n, 4, 3, 3))
    out_translation = np.empty((n, 4, 3))
    for q in range(n):
        p = which[q]
        for k in range(2):
            out_pairs[q, k] = pairs[p, k]
            out_images[q, k] = images[p, k]
        for m in range(4):
            for j in range(3):
                out_translation[q, m, j] = translation[p, m, j]
                for k in range(3):
                    out_rotation[q, m, j, k] = rotation[p, m, j, k]
    return out_pairs, out_images, out_rotation, out_translation


@njit(cache=True)
def _canonical(a, ia, ja, b, ib, jb):
    """The unique report of a pair of virtual edges: ``(first, second, image of second)`` with the
    first edge in the home tile, ``first < second`` or, for an edge and its own image, the image
    positive in (x, then y); ``first = −1`` when this virtual pair is a translate of the report."""
    if a < b:
        if ia == 0 and ja == 0:
            return a, b, ib, jb
        return -1, -1, 0, 0
    if b < a:
        if ib == 0 and jb == 0:
            return b, a, ia, ja
        return -1, -1, 0, 0
    if ia == 0 and ja == 0 and (ib > 0 or (ib == 0 and jb > 0)):
        return a, a, ib, jb
    if ib == 0 and jb == 0 and (ia > 0 or (ia == 0 and ja > 0)):
        return a, a, ia, ja
    return -1, -1, 0, 0


@njit(cache=True)
def broad_phase(pos, pos_end, edge_nodes, edge_end_rotation, edge_offset, edge_radius, edge_rod, edge_chain_tile,
                edge_arc_start, edge_rest_length, rod_length, rod_closed, rod_period, lattice, image_range, node_free,
                margin, exclusion_factor):
    """Candidate contact pairs whose inflated boxes, swept from ``pos`` to ``pos_end`` (pass the
    same array twice for a static query), overlap, for a flat tiling (images are lattice
    translations; see :func:`pairs_of_boxes`).

    Returns ``pairs (P, 2)`` and ``images (P, 2)``: edge ``pairs[p, 1]`` is taken at the tile image
    ``images[p]`` (moved by ``images[p] @ lattice``); ``image_range (2,)`` bounds the images searched
    (zero for a non-periodic model).
    """
    n_edges = edge_nodes.shape[0]
    lower = np.empty((n_edges, 3))
    upper = np.empty((n_edges, 3))
    edge_boxes(pos, pos_end, edge_nodes, edge_end_rotation, edge_offset, edge_radius, margin, lower, upper)
    v_edge, v_image, v_lower, v_upper = _virtual_boxes(lower, upper, lattice, image_range)
    return pairs_of_boxes(v_edge, v_image, v_lower, v_upper, edge_nodes, edge_rod, edge_chain_tile, edge_arc_start,
                          edge_rest_length, edge_radius, rod_length, rod_closed, rod_period, node_free,
                          exclusion_factor)


@njit(cache=True)
def pairs_of_boxes(v_edge, v_image, v_lower, v_upper, edge_nodes, edge_rod, edge_chain_tile, edge_arc_start,
                   edge_rest_length, edge_radius, rod_length, rod_closed, rod_period, node_free, exclusion_factor):
    """Pairs of virtual edges (edge ``v_edge`` at tile image ``v_image`` with box ``v_lower``,
    ``v_upper``) whose boxes overlap, each physical pair reported once with its first edge in the
    home tile (see :func:`_canonical`).

    Sweep and prune along the axis of the largest extent: boxes sorted by their lower bound there,
    each compared with those starting before it ends. O(M log M) plus the boxes overlapping along
    that axis. (A uniform grid with cells the size of the largest box did a quadratic scan per
    cell where the boxes are as large as the periodic repeat holding them: HYLC's stockinette, 300
    boxes in a few cells, 0.56 ms per query against 0.05 ms for the sweep.) Neighbours along one
    yarn (see :func:`_pair_excluded`) and pairs whose four nodes are all pinned are left out.
    """
    n_virtual = v_edge.shape[0]
    if n_virtual < 2:
        return np.empty((0, 2), dtype=np.int64), np.empty((0, 2), dtype=np.int64)
    axis = 0
    widest = -1.0
    for k in range(3):
        extent = v_upper[:, k].max() - v_lower[:, k].min()
        if extent > widest:
            widest = extent
            axis = k
    order = np.argsort(v_lower[:, axis], kind="mergesort")
    n_pairs = 0
    found = np.empty((16 * n_virtual, 4), dtype=np.int64)  # (a, b, image x, image y), grown by doubling
    for u in range(n_virtual):
        vu = order[u]
        end = v_upper[vu, axis]
        for w in range(u + 1, n_virtual):
            vw = order[w]
            if v_lower[vw, axis] > end:
                break
            overlap = True
            for k in range(3):
                if v_lower[vu, k] > v_upper[vw, k] or v_lower[vw, k] > v_upper[vu, k]:
                    overlap = False
                    break
            if not overlap:
                continue
            a, b, ix, iy = _canonical(v_edge[vu], v_image[vu, 0], v_image[vu, 1],
                                      v_edge[vw], v_image[vw, 0], v_image[vw, 1])
            if a < 0:
                continue
            if not (node_free[edge_nodes[a, 0]] or node_free[edge_nodes[a, 1]]
                    or node_free[edge_nodes[b, 0]] or node_free[edge_nodes[b, 1]]):
                continue
            if _pair_excluded(a, b, ix, iy, edge_rod, edge_chain_tile, edge_arc_start, edge_rest_length,
                              edge_radius, rod_length, rod_closed, rod_period, exclusion_factor):
                continue
            if n_pairs == found.shape[0]:
                grown = np.empty((2 * n_pairs, 4), dtype=np.int64)
                grown[:n_pairs] = found
                found = grown
            found[n_pairs, 0] = a
            found[n_pairs, 1] = b
            found[n_pairs, 2] = ix
            found[n_pairs, 3] = iy
            n_pairs += 1
    return np.ascontiguousarray(found[:n_pairs, :2]), np.ascontiguousarray(found[:n_pairs, 2:])


@njit(cache=True)
def pair_distances(pos, edge_nodes, pairs, pair_rotation, pair_translation, out):
    """Centreline distance of every pair into ``out (P,)`` (m)."""
    for p in range(pairs.shape[0]):
        a0, a1, b0, b1 = _pair_points(pos, edge_nodes, pairs, pair_rotation, pair_translation, p)
        out[p] = segment_closest_points(a0, a1, b0, b1)[2]


# Conservative advancements per pair in tunneling_step_limit, and the fraction of the allowed
# approach left at which a pair closing in counts as arrived (the geometric approach would
# otherwise take ever smaller advances).
CCD_ADVANCES = 64
CCD_CONVERGED = 1e-2


@njit(cache=True)
def _moved_distance(a0, a1, b0, b1, move, alpha):
    """Centreline distance of a pair's segments with their points moved by ``alpha · move (4, 3)``."""
    return segment_closest_points(
        (a0[0] + alpha * move[0, 0], a0[1] + alpha * move[0, 1], a0[2] + alpha * move[0, 2]),
        (a1[0] + alpha * move[1, 0], a1[1] + alpha * move[1, 1], a1[2] + alpha * move[1, 2]),
        (b0[0] + alpha * move[2, 0], b0[1] + alpha * move[2, 1], b0[2] + alpha * move[2, 2]),
        (b1[0] + alpha * move[3, 0], b1[1] + alpha * move[3, 1], b1[2] + alpha * move[3, 2]))[2]


@njit(cache=True)
def _node_move(pos, pos_end, i):
    """How far node ``i`` moves from ``pos`` to ``pos_end`` (m)."""
    return math.sqrt((pos_end[i, 0] - pos[i, 0]) ** 2 + (pos_end[i, 1] - pos[i, 1]) ** 2
                     + (pos_end[i, 2] - pos[i, 2]) ** 2)


@njit(cache=True)
def _segments_within(pos, edge_nodes, pairs, pair_rotation, pair_translation, p, reach):
    """Pair ``p``'s segments at ``pos`` are no further than ``reach`` (m) apart: settled by their
    midpoints' bound where it can, by their closest points otherwise."""
    a0, a1, b0, b1 = _pair_points(pos, edge_nodes, pairs, pair_rotation, pair_translation, p)
    if _midpoint_distance_bound(a0, a1, b0, b1) > reach:
        return False
    return segment_closest_points(a0, a1, b0, b1)[2] <= reach


@njit(cache=True)
def _in_reach(pos, pos_end, edge_nodes, edge_radius, pairs, pair_rotation, pair_translation, margin, p):
    """Pair ``p``'s segments come within ``ra + rb + margin`` (m) of each other at ``pos`` or
    anywhere on the straight way to ``pos_end``: their distance at ``pos`` less the largest move of
    a node of each edge (rigid maps keep a move's length)."""
    travel = 0.0
    for e in (pairs[p, 0], pairs[p, 1]):
        travel += max(_node_move(pos, pos_end, edge_nodes[e, 0]), _node_move(pos, pos_end, edge_nodes[e, 1]))
    reach = edge_radius[pairs[p, 0]] + edge_radius[pairs[p, 1]] + margin + travel
    return _segments_within(pos, edge_nodes, pairs, pair_rotation, pair_translation, p, reach)


@njit(cache=True)
def keep_pairs_in_reach(pos, pos_end, edge_nodes, edge_radius, pairs, images, pair_rotation, pair_translation,
                        margin):
    """Move to the front, in order and in place, the pairs in reach (:func:`_in_reach`); returns
    how many."""
    kept = 0
    for p in range(pairs.shape[0]):
        if not _in_reach(pos, pos_end, edge_nodes, edge_radius, pairs, pair_rotation, pair_translation, margin, p):
            continue
        if kept != p:
            pairs[kept] = pairs[p]
            images[kept] = images[p]
            pair_rotation[kept] = pair_rotation[p]
            pair_translation[kept] = pair_translation[p]
        kept += 1
    return kept


@njit(cache=True)
def pairs_in_reach_near(pos, pos_end, reference, reference_distance, edge_nodes, edge_radius, pairs, pair_rotation,
                        pair_translation, margin):
    """Indices, in order, of the pairs in reach (:func:`_in_reach`), the pairs' centreline distances
    at node positions ``reference`` being ``reference_distance (P,)``: a segment's points move no
    further than its nodes, and rigid maps keep a move's length, so the distance now lies within
    the pair's two largest node moves of it, and only the pairs that bound leaves undecided are
    measured."""
    n = pos.shape[0]
    moved = np.empty(n)
    travel_of = np.empty(n)
    for i in range(n):
        moved[i] = _node_move(reference, pos, i)
        travel_of[i] = _node_move(pos, pos_end, i)
    kept = np.empty(pairs.shape[0], dtype=np.int64)
    count = 0
    for p in range(pairs.shape[0]):
        shift = 0.0
        travel = 0.0
        for e in (pairs[p, 0], pairs[p, 1]):
            i, j = edge_nodes[e, 0], edge_nodes[e, 1]
            shift += max(moved[i], moved[j])
            travel += max(travel_of[i], travel_of[j])
        reach = edge_radius[pairs[p, 0]] + edge_radius[pairs[p, 1]] + margin + travel
        if reference_distance[p] - shift > reach:
            continue
        if reference_distance[p] + shift < reach or _segments_within(pos, edge_nodes, pairs, pair_rotation,
                                                                      pair_translation, p, reach):
            kept[count] = p
            count += 1
    return kept[:count]


@njit(cache=True)
def largest_squared_move(reference, position):
    """Largest squared distance (m²) of a node of ``position (N, 3)`` from its ``reference``."""
    largest = 0.0
    for i in range(reference.shape[0]):
        d = ((position[i, 0] - reference[i, 0]) ** 2 + (position[i, 1] - reference[i, 1]) ** 2
             + (position[i, 2] - reference[i, 2]) ** 2)
        largest = max(largest, d)
    return largest


@njit(cache=True)
def tunneling_step_limit(pos, dx, edge_nodes, pairs, pair_rotation, pair_translation, fraction):
    """Largest step length ``α ≤ 1`` along node displacements ``dx (N, 3)`` that brings no pair's
    centreline distance below ``(1 − fraction)`` of its current value ``d0``, so no yarn passes
    through another.

    Conservative advancement (additive CCD, Li et al. 2021): with the pair's four mapped
    displacements ``D`` and their mean ``D̄``, the segments' distance changes by at most
    ``ℓ = max_a |D − D̄| + max_b |D − D̄|`` per unit of α, so from a distance ``d`` the step may
    advance ``(d − (1 − fraction) d0) / ℓ`` and the distance is measured again there. A bound on
    the whole step alone (the sum of the largest node moves, as before) cut every step that slid a
    yarn along another at constant distance, to 1/256–1/64 in the twill swatch; the advancement
    lets such a step through and still stops one that closes in. At most CCD_ADVANCES per pair: a
    pair still advancing then limits the step where it got to.
    """
    alpha = 1.0
    move = np.empty((4, 3))
    mean = np.empty(3)
    for p in range(pairs.shape[0]):
        a0, a1, b0, b1 = _pair_points(pos, edge_nodes, pairs, pair_rotation, pair_translation, p)
        nodes = _pair_nodes(edge_nodes, pairs, p)
        mean[:] = 0.0
        for m in range(4):
            d = mat_vec(pair_rotation[p, m], (dx[nodes[m], 0], dx[nodes[m], 1], dx[nodes[m], 2]))
            for k in range(3):
                move[m, k] = d[k]
                mean[k] += 0.25 * d[k]
        spread_a = 0.0
        spread_b = 0.0
        for m in range(4):
            r = math.sqrt((move[m, 0] - mean[0]) ** 2 + (move[m, 1] - mean[1]) ** 2 + (move[m, 2] - mean[2]) ** 2)
            if m < 2:
                spread_a = max(spread_a, r)
            else:
                spread_b = max(spread_b, r)
        bound = spread_a + spread_b
        distance = segment_closest_points(a0, a1, b0, b1)[2]
        floor = (1.0 - fraction) * distance
        if bound * alpha <= distance - floor:
            continue  # the whole (current) step cannot close the pair in that far
        reached = 0.0
        d = distance
        for _ in range(CCD_ADVANCES):
            reached += (d - floor) / bound
            if reached >= alpha:
                reached = alpha
                break
            d = _moved_distance(a0, a1, b0, b1, move, reached)
            if d - floor <= CCD_CONVERGED * (distance - floor):
                break  # closing in on the floor: stop here
        alpha = min(alpha, reached)
    return alpha


# ---------------------------------------------------------------------------------------------
# Augmented-Lagrangian contact terms (quasi-static solve)
# ---------------------------------------------------------------------------------------------


@njit(cache=True)
def _smooth_ramp(t, delta):
    """C¹ ramp ``m(t)`` and its integral ``M(t)``: ``m = 0`` below ``−δ``, ``(t + δ)² / 4δ`` within
    ``±δ``, ``t`` above ``δ`` (so ``M = t² / 2 + δ² / 6`` there)."""
    if t <= -delta:
        return 0.0, 0.0
    if t >= delta:
        return t, 0.5 * t * t + delta * delta / 6.0
    u = t + delta
    return u * u / (4.0 * delta), u * u * u / (12.0 * delta)


@njit(cache=True)
def _point_segment(p, b0, b1):
    """Closest point parameter ``t`` on segment ``b0b1`` to ``p``, the distance and the unit normal
    from the segment to ``p`` (any perpendicular when ``p`` lies on the segment)."""
    d = (b1[0] - b0[0], b1[1] - b0[1], b1[2] - b0[2])
    dd = dot(d, d)
    t = 0.0
    if dd > 0.0:
        t = _clamp01(((p[0] - b0[0]) * d[0] + (p[1] - b0[1]) * d[1] + (p[2] - b0[2]) * d[2]) / dd)
    diff = (p[0] - b0[0] - t * d[0], p[1] - b0[1] - t * d[1], p[2] - b0[2] - t * d[2])
    dist = norm(diff)
    if dist > 0.0:
        return t, dist, (diff[0] / dist, diff[1] / dist, diff[2] / dist)
    nrm = cross(d, (1.0, 0.0, 0.0)) if abs(d[0]) < 0.9 * math.sqrt(dd) else cross(d, (0.0, 1.0, 0.0))
    nn = norm(nrm)
    return t, dist, (nrm[0] / nn, nrm[1] / nn, nrm[2] / nn)


@njit(cache=True)
def _midpoint_distance_bound(a0, a1, b0, b1):
    """A lower bound of two segments' distance (m): their midpoints' distance less both
    half-lengths. Far cheaper than the closest points, and what settles most candidate pairs."""
    half_a = 0.5 * math.sqrt((a1[0] - a0[0]) ** 2 + (a1[1] - a0[1]) ** 2 + (a1[2] - a0[2]) ** 2)
    half_b = 0.5 * math.sqrt((b1[0] - b0[0]) ** 2 + (b1[1] - b0[1]) ** 2 + (b1[2] - b0[2]) ** 2)
    midpoints = math.sqrt((0.5 * (a0[0] + a1[0] - b0[0] - b1[0])) ** 2 + (0.5 * (a0[1] + a1[1] - b0[1] - b1[1])) ** 2
                          + (0.5 * (a0[2] + a1[2] - b0[2] - b1[2])) ** 2)
    return midpoints - half_a - half_b


@njit(cache=True)
def _out_of_reach(multiplier, first, n_samples, stiffness, lowest_gap, delta):
    """Every one of a pair's ``n_samples`` constraints (multipliers from ``first``) is off its ramp
    (``λ − k g ≤ −δ``) already at ``lowest_gap`` (m), the segments' distance less ``ra + rb``, which
    no sample's gap is below."""
    largest_multiplier = 0.0
    for c in range(n_samples):
        largest_multiplier = max(largest_multiplier, multiplier[first + c])
    return largest_multiplier - stiffness * lowest_gap <= -delta


@njit(cache=True)
def _lowest_gap(a0, a1, b0, b1, radius_sum, multiplier, first, n_samples, stiffness, delta):
    """``(out of reach, lowest gap)`` of a pair (see :func:`_pair_sample_terms`): the gap's lower
    bound from the midpoints when that already puts every constraint off its ramp, the segments'
    distance less ``ra + rb`` otherwise."""
    lowest_gap = _midpoint_distance_bound(a0, a1, b0, b1) - radius_sum
    if not _out_of_reach(multiplier, first, n_samples, stiffness, lowest_gap, delta):
        lowest_gap = segment_closest_points(a0, a1, b0, b1)[2] - radius_sum
    return _out_of_reach(multiplier, first, n_samples, stiffness, lowest_gap, delta), lowest_gap


@njit(cache=True)
def _pair_sample_terms(a0, a1, b0, b1, samples_a, samples_b, radius_sum, multiplier, first, stiffness, smoothing,
                       out_grad, out_gap, out_force):
    """Augmented-Lagrangian terms of the sampled constraints of one edge pair.

    Each edge carries ``samples ≥ 2`` points at ``s = i / (samples − 1)``, its nodes included (two
    bent yarns touch at their corners: samples only between the nodes would see a corner contact
    from ``h / 2`` away, where the gap has grown linearly with the bend); every point of a keeps
    ``ra + rb`` from segment b and every point of b from segment a (constraint ``c`` of the pair
    has multiplier ``multiplier[first + c]``). Each term is ``(M(λ − k g) − M(λ)) / k`` with the
    smoothed ramp of :func:`_smooth_ramp`, ``δ = smoothing · k · (ra + rb)``. Sets the pair's
    gradient ``out_grad (12,)`` over (a0, a1, b0, b1), writes each constraint's gap (m) and force
    (N) from ``first``; returns the energy (J).

    A pair out of reach (every constraint's ``λ − k g ≤ −δ`` already with ``g`` at a lower bound:
    the midpoints' bound of :func:`_midpoint_distance_bound` or else the segments' distance, less
    ``ra + rb``) exerts no force, and its energy is ``−Σ M(λ) / k`` exactly; its constraints' gaps
    are then written as that lower bound (positive: no penetration, and no force to update a
    multiplier with). Most candidate pairs are: 4 % of a stockinette sample's ~1700 carry force,
    and sampling the rest was the kernel's cost.
    """
    for k in range(12):
        out_grad[k] = 0.0
    delta = smoothing * stiffness * radius_sum
    energy = 0.0
    n_samples = samples_a + samples_b
    out_of_reach, lowest_gap = _lowest_gap(a0, a1, b0, b1, radius_sum, multiplier, first, n_samples, stiffness,
                                           delta)
    if out_of_reach:
        for c in range(n_samples):
            out_gap[first + c] = lowest_gap
            out_force[first + c] = 0.0
            energy -= _smooth_ramp(multiplier[first + c], delta)[1] / stiffness
        return energy
    for c in range(n_samples):
        if c < samples_a:
            s = c / (samples_a - 1)
            point = (a0[0] + s * (a1[0] - a0[0]), a0[1] + s * (a1[1] - a0[1]), a0[2] + s * (a1[2] - a0[2]))
            t, dist, n = _point_segment(point, b0, b1)
        else:
            t = (c - samples_a) / (samples_b - 1)
            point = (b0[0] + t * (b1[0] - b0[0]), b0[1] + t * (b1[1] - b0[1]), b0[2] + t * (b1[2] - b0[2]))
            s, dist, n_ab = _point_segment(point, a0, a1)
            n = (-n_ab[0], -n_ab[1], -n_ab[2])  # from b's point towards a
        gap = dist - radius_sum
        lam = multiplier[first + c]
        force, integral = _smooth_ramp(lam - stiffness * gap, delta)
        _, integral_at_contact = _smooth_ramp(lam, delta)
        energy += (integral - integral_at_contact) / stiffness
        out_gap[first + c] = gap
        out_force[first + c] = force
        if force == 0.0:
            continue
        # ∂ψ/∂x = −force ∂g/∂x, ∂g/∂(a0, a1, b0, b1) = ((1 − s) n, s n, −(1 − t) n, −t n)
        for k in range(3):
            out_grad[k] -= force * (1.0 - s) * n[k]
            out_grad[3 + k] -= force * s * n[k]
            out_grad[6 + k] += force * (1.0 - t) * n[k]
            out_grad[9 + k] += force * t * n[k]
    return energy


@njit(cache=True)
def contact_energy_gradient(pos, edge_nodes, edge_radius, edge_samples, pairs, pair_rotation, pair_translation,
                            constraint_start, multiplier, stiffness, smoothing, node_grad, node_scale, out_gap,
                            out_force):
    """Augmented-Lagrangian contact energy (J) of all pairs' sampled constraints (see
    :func:`_pair_sample_terms`; pair ``p`` owns constraints ``constraint_start[p]:[p + 1]``).

    Adds the gradient into ``node_grad (N, 3)`` and force magnitudes into ``node_scale``; writes
    each constraint's gap (m) and normal force (N).
    """
    local = np.empty(12)
    energy = 0.0
    for p in range(pairs.shape[0]):
        ea = pairs[p, 0]
        eb = pairs[p, 1]
        a0, a1, b0, b1 = _pair_points(pos, edge_nodes, pairs, pair_rotation, pair_translation, p)
        energy += _pair_sample_terms(a0, a1, b0, b1, edge_samples[ea], edge_samples[eb],
                                     edge_radius[ea] + edge_radius[eb], multiplier, constraint_start[p],
                                     stiffness[p], smoothing, local, out_gap, out_force)
        pushing = False  # most candidate pairs are out of reach: nothing to add
        for k in range(12):
            if local[k] != 0.0:
                pushing = True
                break
        if not pushing:
            continue
        nodes = _pair_nodes(edge_nodes, pairs, p)
        for m in range(4):
            g = mat_t_vec(pair_rotation[p, m], (local[3 * m], local[3 * m + 1], local[3 * m + 2]))
            for k in range(3):
                node_grad[nodes[m], k] += g[k]
            node_scale[nodes[m]] += math.sqrt(g[0] * g[0] + g[1] * g[1] + g[2] * g[2])
    return energy


@njit(cache=True)
def pairs_energy(pos, edge_nodes, edge_radius, edge_samples, pairs, pair_rotation, pair_translation, constraint_start,
                 multiplier, stiffness, smoothing, which):
    """The augmented-Lagrangian contact energy (J) of the pairs ``which`` (indices) alone, as
    :func:`contact_energy_gradient` sums it."""
    local = np.empty(12)
    # One pair's gaps and forces, thrown away: its constraints are indexed from 0 in a view of
    # its multipliers.
    scratch_gap = np.empty(2 * edge_samples.max())
    scratch_force = np.empty(2 * edge_samples.max())
    energy = 0.0
    for p in which:
        ea = pairs[p, 0]
        eb = pairs[p, 1]
        a0, a1, b0, b1 = _pair_points(pos, edge_nodes, pairs, pair_rotation, pair_translation, p)
        energy += _pair_sample_terms(a0, a1, b0, b1, edge_samples[ea], edge_samples[eb],
                                     edge_radius[ea] + edge_radius[eb],
                                     multiplier[constraint_start[p]:constraint_start[p + 1]], 0, stiffness[p],
                                     smoothing, local, scratch_gap, scratch_force)
    return energy


@njit(cache=True)
def constraint_measures(gap, force, constraint_start, radius_sum, stiffness, smoothing):
    """``(penetration, separation)`` of sampled constraints with gaps ``gap`` (m) and normal forces
    ``force`` (N), pair ``p`` owning ``constraint_start[p]:[p + 1]``: the deepest overlap, and the
    widest gap of a constraint carrying a force above the smoothing band ``smoothing k (ra + rb)``,
    each over the pair's sum of radii ``radius_sum`` (m); ``stiffness`` k (N/m) per pair."""
    penetration = 0.0
    separation = 0.0
    for p in range(constraint_start.shape[0] - 1):
        rsum = radius_sum[p]
        band = smoothing * stiffness[p] * rsum
        for c in range(constraint_start[p], constraint_start[p + 1]):
            penetration = max(penetration, -gap[c] / rsum)
            if force[c] > band:
                separation = max(separation, gap[c] / rsum)
    return penetration, separation


@njit(cache=True)
def _ramp_slope(t, delta):
    """Derivative ``m'(t)`` of the smoothed ramp of :func:`_smooth_ramp`."""
    if t <= -delta:
        return 0.0
    if t >= delta:
        return 1.0
    return (t + delta) / (2.0 * delta)


@njit(cache=True)
def _add_constraint_hessian(points, weight, slide, free, stiffness_term, force, local):
    """Add one sampled constraint's Hessian to ``local (12, 12)`` over the pair's four points
    ``points (4, 3)``.

    The constraint's vector is ``r = Σ_m weight[m] p_m`` (the sample point less its closest point
    on the other segment, or the reverse), ``g = |r| − (ra + rb)``, and the closest point's
    parameter u moves ``weight`` by ``slide`` per unit (``∂w/∂u``). With ``n = r/|r|`` and
    ``P = (I − n nᵀ)/|r|``: ``∂g/∂p_m = w_m n``; at fixed u, ``∂²g/∂p_m∂p_l = w_m w_l P``; a free u
    (inside the segment: ``free``) minimises ``|r|``, which subtracts ``f_pu f_puᵀ / f_uu`` with
    ``f_pu,m = v_m n + w_m P r_u``, ``f_uu = r_uᵀ P r_u``, ``r_u = Σ v_m p_m``. The term's Hessian
    is ``stiffness_term ∂g ∂gᵀ − force ∂²g`` (``k m'`` and ``m`` of the ramp at ``λ − k g``)."""
    r = np.zeros(3)
    ru = np.zeros(3)
    for m in range(4):
        for k in range(3):
            r[k] += weight[m] * points[m, k]
            ru[k] += slide[m] * points[m, k]
    dist = math.sqrt(r[0] * r[0] + r[1] * r[1] + r[2] * r[2])
    if dist == 0.0:
        return
    n = r / dist
    for m in range(4):
        for l in range(4):
            c = stiffness_term * weight[m] * weight[l]
            for i in range(3):
                for j in range(3):
                    local[3 * m + i, 3 * l + j] += c * n[i] * n[j]
    if force == 0.0:
        return
    projector = np.empty((3, 3))
    for i in range(3):
        for j in range(3):
            projector[i, j] = ((1.0 if i == j else 0.0) - n[i] * n[j]) / dist
    for m in range(4):
        for l in range(4):
            c = force * weight[m] * weight[l]
            for i in range(3):
                for j in range(3):
                    local[3 * m + i, 3 * l + j] -= c * projector[i, j]
    if not free:
        return
    p_ru = projector @ ru
    f_uu = ru[0] * p_ru[0] + ru[1] * p_ru[1] + ru[2] * p_ru[2]
    if f_uu <= 0.0:
        return
    f_pu = np.empty(12)
    for m in range(4):
        for k in range(3):
            f_pu[3 * m + k] = slide[m] * n[k] + weight[m] * p_ru[k]
    for a in range(12):
        for b in range(12):
            local[a, b] += force * f_pu[a] * f_pu[b] / f_uu


@njit(cache=True)
def sample_closest_point(c, sa, sb, a0, a1, b0, b1, weight):
    """Constraint ``c`` of a pair whose edges carry ``sa`` and ``sb`` samples: a's sample at
    ``s = c / (sa − 1)`` and its closest point on b at ``u`` (``c < sa``), or b's sample at
    ``t = (c − sa) / (sb − 1)`` and its closest point on a at ``u``. Writes into ``weight (4,)`` the
    weights of the vector from the point on b to the point on a over ``(a0, a1, b0, b1)``; returns
    ``(u, distance, normal)``, the normal from the point on b towards the point on a."""
    if c < sa:
        s = c / (sa - 1)
        point = (a0[0] + s * (a1[0] - a0[0]), a0[1] + s * (a1[1] - a0[1]), a0[2] + s * (a1[2] - a0[2]))
        u, dist, n = _point_segment(point, b0, b1)
        weight[0], weight[1], weight[2], weight[3] = 1.0 - s, s, -(1.0 - u), -u
        return u, dist, n
    t = (c - sa) / (sb - 1)
    point = (b0[0] + t * (b1[0] - b0[0]), b0[1] + t * (b1[1] - b0[1]), b0[2] + t * (b1[2] - b0[2]))
    u, dist, n_ab = _point_segment(point, a0, a1)
    weight[0], weight[1], weight[2], weight[3] = 1.0 - u, u, -(1.0 - t), -t
    return u, dist, (-n_ab[0], -n_ab[1], -n_ab[2])


@njit(cache=True)
def contact_hessian_coo(pos, edge_nodes, edge_radius, edge_samples, pairs, pair_rotation, pair_translation,
                        constraint_start, multiplier, stiffness, smoothing, rows, cols, vals, start):
    """Hessian of the contact terms as COO triplets (144 per pair with a constraint on its ramp)
    from ``start``, exact (see :func:`_add_constraint_hessian`; the closest points' motion
    included). Returns the new entry count.

    It replaced central differences of the pair's gradient (24 evaluations of every sample per
    pair, and a step that had to sit inside the ramp's foot): a fifth of a stockinette
    iteration."""
    local = np.empty((12, 12))
    points = np.empty((4, 3))
    weight = np.empty(4)
    slide = np.empty(4)
    idx = start
    for p in range(pairs.shape[0]):
        ea = pairs[p, 0]
        eb = pairs[p, 1]
        sa = edge_samples[ea]
        sb = edge_samples[eb]
        first = constraint_start[p]
        a0, a1, b0, b1 = _pair_points(pos, edge_nodes, pairs, pair_rotation, pair_translation, p)
        rsum = edge_radius[ea] + edge_radius[eb]
        k = stiffness[p]
        delta = smoothing * k * rsum
        if _lowest_gap(a0, a1, b0, b1, rsum, multiplier, first, sa + sb, k, delta)[0]:
            continue  # every constraint off its ramp: no curvature
        for i in range(3):
            points[0, i] = a0[i]
            points[1, i] = a1[i]
            points[2, i] = b0[i]
            points[3, i] = b1[i]
        local[:, :] = 0.0
        for c in range(sa + sb):
            u, dist, _ = sample_closest_point(c, sa, sb, a0, a1, b0, b1, weight)
            if c < sa:  # a's sample, its closest point on b: u = t slides along b
                slide[0], slide[1], slide[2], slide[3] = 0.0, 0.0, 1.0, -1.0
            else:  # b's sample, its closest point on a: u = s slides along a
                slide[0], slide[1], slide[2], slide[3] = -1.0, 1.0, 0.0, 0.0
            argument = multiplier[first + c] - k * (dist - rsum)
            if argument <= -delta:
                continue
            force, _ = _smooth_ramp(argument, delta)
            _add_constraint_hessian(points, weight, slide, 0.0 < u < 1.0, k * _ramp_slope(argument, delta), force,
                                    local)
        for m in range(4):
            pull_back_block(local, 3 * m, pair_rotation[p, m])
        nodes = _pair_nodes(edge_nodes, pairs, p)
        for i in range(12):
            for j in range(12):
                rows[idx] = 3 * nodes[i // 3] + i % 3
                cols[idx] = 3 * nodes[j // 3] + j % 3
                vals[idx] = 0.5 * (local[i, j] + local[j, i])
                idx += 1
    return idx


# ---------------------------------------------------------------------------------------------
# XPBD contact projection with position-based friction (Müller et al. 2020, "Detailed rigid body
# simulation with extended position based dynamics", §3.5)
# ---------------------------------------------------------------------------------------------


@njit(cache=True)
def _pair_frame(pos, node_inv_mass, edge_nodes, pairs, pair_rotation, pair_translation, p):
    """Closest points of the edges of pair ``p`` (the second at its image) and how their nodes share
    a correction there.

    Returns ``(nodes, coef, w, weight, dist, normal)``: the four nodes (a0, a1, b0, b1), their
    barycentric coefficients signed towards ``normal`` (+ on a, − on b), the coefficient-weighted
    inverse masses ``w_i coef_i``, the generalised inverse mass ``Σ w_i coef_i²`` of the pair, the
    centreline distance and the unit normal from b to a (in the mapped, world frame).
    """
    a0, a1, b0, b1 = _pair_points(pos, edge_nodes, pairs, pair_rotation, pair_translation, p)
    s, t, dist, normal = segment_closest_points(a0, a1, b0, b1)
    nodes = _pair_nodes(edge_nodes, pairs, p)
    coef = (1.0 - s, s, -(1.0 - t), -t)
    w = (node_inv_mass[nodes[0]] * coef[0], node_inv_mass[nodes[1]] * coef[1],
         node_inv_mass[nodes[2]] * coef[2], node_inv_mass[nodes[3]] * coef[3])
    weight = w[0] * coef[0] + w[1] * coef[1] + w[2] * coef[2] + w[3] * coef[3]
    return nodes, coef, w, weight, dist, normal


@njit(cache=True)
def _relative_motion(field, nodes, coef, rotation, normal):
    """Tangential part of ``Σ coef_i R_i field[node_i]`` (for positions or velocities: a's contact
    point relative to b's, each node's vector turned into its image) and its length."""
    r0 = 0.0
    r1 = 0.0
    r2 = 0.0
    for m in range(4):
        v = mat_vec(rotation[m], row3(field, nodes[m]))
        r0 += coef[m] * v[0]
        r1 += coef[m] * v[1]
        r2 += coef[m] * v[2]
    along = r0 * normal[0] + r1 * normal[1] + r2 * normal[2]
    r0 -= along * normal[0]
    r1 -= along * normal[1]
    r2 -= along * normal[2]
    return (r0, r1, r2), math.sqrt(r0 * r0 + r1 * r1 + r2 * r2)


@njit(cache=True)
def _move_nodes(field, nodes, rotation, w, direction, amount):
    """``field[node_m] += w_m R_mᵀ direction · amount``: a correction at the mapped points applied
    to the nodes."""
    for m in range(4):
        d = mat_t_vec(rotation[m], direction)
        for k in range(3):
            field[nodes[m], k] += w[m] * d[k] * amount


@njit(cache=True)
def project_contacts(pos, prev_pos, node_inv_mass, edge_nodes, edge_radius, pairs, pair_rotation, pair_translation,
                     lam_normal, lam_tangent, static_friction):
    """One Gauss–Seidel sweep over the contact pairs (hard unilateral constraints).

    ``lam_normal (P,)`` and ``lam_tangent (P,)`` accumulate the multipliers of the step (kg·m).
    Static friction: when the tangential slip of the contact points since the start of the step
    can be cancelled with a multiplier below ``static_friction · λn``, it is cancelled.
    """
    for p in range(pairs.shape[0]):
        rotation = pair_rotation[p]
        nodes, coef, w, weight, dist, n = _pair_frame(pos, node_inv_mass, edge_nodes, pairs, pair_rotation,
                                                      pair_translation, p)
        if weight == 0.0:
            continue
        c = dist - (edge_radius[pairs[p, 0]] + edge_radius[pairs[p, 1]])
        if c < 0.0:
            dl = -c / weight
            lam_normal[p] += dl
            _move_nodes(pos, nodes, rotation, w, n, dl)
        if lam_normal[p] <= 0.0 or static_friction <= 0.0:
            continue
        # Tangential slip since the step started (the tangential projection is linear).
        now, _ = _relative_motion(pos, nodes, coef, rotation, n)
        before, _ = _relative_motion(prev_pos, nodes, coef, rotation, n)
        slip = (now[0] - before[0], now[1] - before[1], now[2] - before[2])
        slip_norm = math.sqrt(slip[0] ** 2 + slip[1] ** 2 + slip[2] ** 2)
        if slip_norm == 0.0:
            continue
        dlt = slip_norm / weight
        if lam_tangent[p] + dlt < static_friction * lam_normal[p]:
            lam_tangent[p] += dlt
            _move_nodes(pos, nodes, rotation, w, slip, -dlt / slip_norm)


@njit(cache=True)
def apply_kinetic_friction(pos, vel, node_inv_mass, edge_nodes, pairs, pair_rotation, pair_translation, lam_normal,
                           kinetic_friction, dt):
    """Velocity pass: each touching pair loses up to ``μk |Jn|`` of tangential relative momentum,
    with ``Jn = λn / Δt`` the normal impulse of the step."""
    for p in range(pairs.shape[0]):
        if lam_normal[p] <= 0.0:
            continue
        rotation = pair_rotation[p]
        nodes, coef, w, weight, _, n = _pair_frame(pos, node_inv_mass, edge_nodes, pairs, pair_rotation,
                                                   pair_translation, p)
        if weight == 0.0:
            continue
        vt, speed = _relative_motion(vel, nodes, coef, rotation, n)
        if speed == 0.0:
            continue
        dv = min(weight * kinetic_friction * lam_normal[p] / dt, speed)
        _move_nodes(vel, nodes, rotation, w, vt, -dv / (weight * speed))
