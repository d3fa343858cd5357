"""Contacts of a periodic repeat against an explicit 3×3 copy of it.

Reference: the same yarns laid out as nine ordinary (open) copies; every pair between an edge of
the centre copy and any edge of any copy closer than the search margin, found by brute force, must
appear in the periodic query exactly once, with the same distance. Also: a periodic yarn never
touches its own continuation.
"""

from pathlib import Path

import numpy as np
import pytest

from yarnfit.engine import Rod, RodMaterial, RodModel
from yarnfit.engine.contact import ImageMaps, find_pairs, pair_distances
from yarnfit.engine.tiling import node_maps
from curved_tiling import curved_model
from yarnfit.patterns import DRAFTS, STITCHES, knit, read_pyp, weave

HYLC = Path(__file__).parent / "data" / "hylc"

MATERIAL = RodMaterial(1e9)
# Distances agree to round-off of the coordinates (~1e-3 m × 1e-16).
DISTANCE_ATOL = 1e-15


def periodic_model(pattern) -> RodModel:
    rods = [Rod(pattern.node_position[y.nodes], pattern.radius, MATERIAL, closed=True, tile_offsets=y.tiles)
            for y in pattern.yarns()]
    return RodModel.from_rods(rods, lattice=pattern.lattice)


def edge_segments(model: RodModel, image) -> np.ndarray:
    """Every edge's end points ``(E, 2, 3)`` in tile ``image``: each node placed by its own map
    (a translation by the lattice on a flat tiling), the end node one edge tile further."""
    x = model.node_rest_position
    tile = np.broadcast_to(np.asarray(image), (model.n_edges, 2))
    r0, t0 = node_maps(model, model.edge_nodes[:, 0], tile)
    r1, t1 = node_maps(model, model.edge_nodes[:, 1], tile + model.edge_tile)
    start = np.einsum("eij,ej->ei", r0, x[model.edge_nodes[:, 0]]) + t0
    end = np.einsum("eij,ej->ei", r1, x[model.edge_nodes[:, 1]]) + t1
    return np.stack([start, end], axis=1)


def segment_distance(p, q, n=400):
    """Brute-force distance of two segments by dense sampling refined by a local search."""
    from yarnfit.engine._contact_kernels import segment_closest_points
    return segment_closest_points(tuple(p[0]), tuple(p[1]), tuple(q[0]), tuple(q[1]))[2]


@pytest.mark.parametrize("pattern", [
    weave(DRAFTS["twill-2/1"], 3000.0, 2500.0, 8e-5, name="twill"),
    knit(STITCHES["rib-1x1"], 1800.0, 1300.0, 7e-5, name="rib"),
    # A yarn that crosses tile borders mid-way (HYLC's stockinette): its neighbours along the yarn
    # sit in other tiles than its own.
    read_pyp(HYLC / "stocktiny.pyp"),
    # Every node reaching its images by its own random rigid map (a repeat on a curved surface).
    "curved",
], ids=["twill-2/1", "rib-1x1", "stocktiny.pyp", "curved tiling"])
def test_periodic_pairs_match_an_explicit_tiling(pattern):
    if pattern == "curved":
        model = curved_model(reach=3, turn=0.05, jitter=5e-5)
        radius = float(model.edge_radius.max())
    else:
        model, radius = periodic_model(pattern), pattern.radius
    margin = radius
    found = find_pairs(model, model.node_rest_position, margin)
    distances = pair_distances(model, model.node_rest_position, found)
    periodic = {}
    for (a, b), image, d in zip(found.pairs.tolist(), found.images.tolist(), distances):
        key = (a, b, tuple(image))
        assert key not in periodic, f"pair {key} reported twice"
        periodic[key] = d
    # Brute force: centre edges against every edge of the 5×5 neighbourhood of copies.
    centre = edge_segments(model, (0, 0))
    reach = 2.0 * radius + margin
    expected = {}
    for i in range(-2, 3):
        for j in range(-2, 3):
            other = edge_segments(model, (i, j))
            for a in range(model.n_edges):
                for b in range(model.n_edges):
                    if (i, j) == (0, 0) and b <= a:
                        continue
                    d = segment_distance(centre[a], other[b])
                    if d >= reach:
                        continue
                    # The same physical pair seen from b's copy: keep one canonical report.
                    if (i, j) != (0, 0) and (b < a or (a == b and (i < 0 or (i == 0 and j < 0)))):
                        key = (b, a, (-i, -j))
                    else:
                        key = (a, b, (i, j))
                    expected[key] = d
    # Every pair within the reach that is not a neighbour along its own yarn is found, with its distance.
    missing = [k for k in expected if k not in periodic and not _neighbours(model, k)]
    assert not missing, f"{len(missing)} pairs missed, e.g. {missing[:3]}"
    # ... and no neighbour along a yarn is reported.
    neighbours = [k for k in periodic if _neighbours(model, k)]
    assert not neighbours, f"{len(neighbours)} pairs of neighbours along a yarn reported, e.g. {neighbours[:3]}"
    for key, d in periodic.items():
        if key in expected:
            assert d == pytest.approx(expected[key], abs=DISTANCE_ATOL)


def _neighbours(model, key) -> bool:
    """Pairs the broad phase leaves out on purpose: neighbours along one yarn, closer than
    CONTACT_EXCLUSION_FACTOR (ra + rb) in rest arc length. Found by walking the yarn edge by edge
    through the tiles for a few cycles each way (each edge's end lies in the tile moved by its
    tile offset), not by the kernel's closed form."""
    from yarnfit.engine.model import CONTACT_EXCLUSION_FACTOR
    a, b, image = key
    rod = model.edge_rod[a]
    if model.edge_rod[b] != rod:
        return False
    walk = _walk(model, rod)
    threshold = CONTACT_EXCLUSION_FACTOR * (model.edge_radius[a] + model.edge_radius[b])
    for tile_a, arc_a in walk.get(a, []):
        for tile_b, arc_b in walk.get(b, []):
            if tuple(np.subtract(tile_b, tile_a)) != tuple(image):
                continue
            la, lb = model.edge_rest_length[a], model.edge_rest_length[b]
            if max(arc_b - (arc_a + la), arc_a - (arc_b + lb), 0.0) < threshold:
                return True
    return False


def _walk(model, rod, cycles=3):
    """Edge → list of (tile, rest arc start) of its occurrences along the unrolled yarn."""
    edges = range(model.rod_edge_start[rod], model.rod_edge_start[rod + 1])
    out = {}
    tile = np.zeros(2, dtype=int)
    arc = 0.0
    # Walk backwards to the start of the first cycle, then forward through 2 * cycles + 1 cycles.
    tile -= cycles * model.rod_period[rod]
    arc -= cycles * model.rod_length[rod]
    for _ in range(2 * cycles + 1):
        for e in edges:
            out.setdefault(e, []).append((tuple(tile), arc))
            tile = tile + model.edge_tile[e]
            arc += model.edge_rest_length[e]
    return out


def test_a_periodic_yarn_does_not_touch_its_own_continuation():
    # One straight yarn along x through the tile, edges shorter than its radius: its images at
    # ±1 tile in x are its own continuation (arc length ±L), never a contact.
    lattice = np.array([[1e-3, 0.0, 0.0], [0.0, 1e-3, 0.0]])
    points = np.column_stack([np.linspace(0, 1e-3, 20, endpoint=False), np.full(20, 5e-4), np.zeros(20)])
    tiles = np.zeros((20, 2), dtype=int)
    tiles[-1] = (1, 0)
    model = RodModel.from_rods([Rod(points, 1e-4, MATERIAL, closed=True, tile_offsets=tiles)], lattice=lattice)
    assert len(find_pairs(model, model.node_rest_position, 1e-4)) == 0


def test_kept_image_maps_give_the_same_pairs_and_maps():
    # A curved tiling's per-node image maps are the model's: kept across queries (as the
    # quasi-static solver does) they give bit for bit what a fresh query builds.
    model = curved_model(reach=3, turn=0.05, jitter=5e-5)
    rng = np.random.default_rng(1)
    maps = ImageMaps(model)
    for step in range(4):
        x = model.node_rest_position + 2e-5 * rng.standard_normal(model.node_rest_position.shape)
        end = None if step % 2 == 0 else x + 1e-4 * rng.standard_normal(x.shape)
        fresh, kept = find_pairs(model, x, 2e-4, end), find_pairs(model, x, 2e-4, end, maps)
        assert len(fresh) > 0
        for name in ("pairs", "images", "rotation", "translation"):
            np.testing.assert_array_equal(getattr(kept, name), getattr(fresh, name))


def _pair_set(pairs) -> set:
    return {(int(a), int(b), int(i), int(j)) for (a, b), (i, j) in zip(pairs.pairs, pairs.images)}


@pytest.mark.parametrize("model_name", ["curved", "stockinette"])
def test_a_neighbour_list_gives_the_pairs_of_a_fresh_search(model_name):
    """Queries of a NeighbourList along a random walk (steps of a fifth of the skin, so it searches
    again every few steps) find what find_pairs finds at each configuration, with the same maps;
    a swept query finds at least what find_pairs finds along the sweep."""
    from yarnfit.engine.contact import NeighbourList

    if model_name == "curved":
        model, margin = curved_model(reach=3, turn=0.05, jitter=5e-5), 2e-4
    else:
        model = periodic_model(read_pyp(HYLC / "stockinette.pyp"))
        margin = float(model.edge_radius.min())
    maps = ImageMaps(model) if model.tiling is not None else None
    neighbours = NeighbourList(model, margin, maps)
    rng = np.random.default_rng(4)
    x = np.array(model.node_rest_position)
    for step in range(12):
        x = x + 0.2 * neighbours.skin / np.sqrt(3.0) * rng.uniform(-1.0, 1.0, x.shape)
        fresh = find_pairs(model, x, margin, None, maps, within=margin)
        listed = neighbours.query(x, None, within=margin)
        assert len(fresh) > 0 and _pair_set(listed) == _pair_set(fresh)
        order = np.argsort(fresh.keys(model.n_edges))
        same = np.argsort(listed.keys(model.n_edges))
        np.testing.assert_array_equal(listed.rotation[same], fresh.rotation[order])
        np.testing.assert_array_equal(listed.translation[same], fresh.translation[order])
        end = x + 0.1 * neighbours.skin * rng.standard_normal(x.shape) / np.sqrt(3.0)
        assert _pair_set(neighbours.query(x, end, within=margin)) >= _pair_set(
            find_pairs(model, x, margin, end, maps, within=margin))
    assert 1 < neighbours.searches < neighbours.queries / 2
