"""The pattern generators: woven repeats from drafts and knits from stitch charts.

References: the draft itself (which yarn is on top at every crossing), the counts (repeat size and
thread numbers), the periodic contact query (no two yarns overlap in a woven's initial geometry),
and the stitch chart (on which side of the fabric each loop head and sinker lies).
"""

import numpy as np
import pytest

from yarnfit.engine import Rod, RodMaterial, RodModel
from yarnfit.engine.contact import find_pairs, pair_distances
from yarnfit.fabric import pyp_thread_numbers
from yarnfit.patterns import DRAFTS, STITCHES, PatternError, knit, weave
from yarnfit.patterns.knit import SEGMENTS_PER_LOOP
from yarnfit.patterns.weave import SEGMENTS_PER_CROSSING, crossing_separation

# Initial woven geometry must clear 2r; the crossing separation carries a 5 % margin, so the
# closest approach may not fall below the diameter by more than round-off.
CLEARANCE_RTOL = 1e-9


def periodic_model(pattern) -> RodModel:
    rods = [Rod(pattern.node_position[y.nodes], pattern.radius, RodMaterial(1e9), closed=True, tile_offsets=y.tiles)
            for y in pattern.yarns()]
    return RodModel.from_rods(rods, lattice=pattern.lattice)


@pytest.mark.parametrize("name", sorted(DRAFTS))
def test_the_drafted_yarn_is_on_top_at_every_crossing(name):
    draft = DRAFTS[name]
    n_picks, n_ends = draft.shape
    pattern = weave(draft, 3000.0, 2500.0, 6e-5, name=name)
    yarns = pattern.yarns()
    picks, ends = yarns[:n_picks], yarns[n_picks:]
    assert all(y.net_offset == (1, 0) for y in picks) and all(y.net_offset == (0, 1) for y in ends)
    for i in range(n_picks):
        for j in range(n_ends):
            pick_node = picks[i].nodes[j * SEGMENTS_PER_CROSSING]
            end_node = ends[j].nodes[i * SEGMENTS_PER_CROSSING]
            # Both nodes sit at the crossing (x_j, y_i).
            np.testing.assert_allclose(pattern.node_position[pick_node, :2], pattern.node_position[end_node, :2])
            end_on_top = pattern.node_position[end_node, 2] > pattern.node_position[pick_node, 2]
            assert end_on_top == bool(draft[i, j]), (name, i, j)


@pytest.mark.parametrize("name", sorted(DRAFTS))
def test_a_weave_repeats_at_its_counts(name):
    draft = DRAFTS[name]
    pattern = weave(draft, 4000.0, 2000.0, 5e-5, name=name)
    np.testing.assert_allclose(pattern.repeat_size, [draft.shape[1] / 4000.0, draft.shape[0] / 2000.0])
    assert pyp_thread_numbers(pattern) == (draft.shape[1], draft.shape[0])
    assert pattern.family == "woven"


@pytest.mark.parametrize("name", sorted(DRAFTS))
@pytest.mark.parametrize("radius_fraction", [0.2, 0.42])  # of the finer thread spacing; 0.5 is jammed
def test_a_weave_starts_without_overlaps(name, radius_fraction):
    ends, picks = 6000.0, 3000.0  # warp twice as dense, as in a satin
    radius = radius_fraction / ends
    pattern = weave(DRAFTS[name], ends, picks, radius, name=name)
    model = periodic_model(pattern)
    pairs = find_pairs(model, model.node_rest_position, radius)
    assert len(pairs) > 0
    closest = pair_distances(model, model.node_rest_position, pairs).min()
    assert closest >= 2.0 * radius * (1.0 - CLEARANCE_RTOL)


def test_crossing_separation_shares_the_crimp_for_equal_curvature():
    a_pick, a_end = crossing_separation(5e-5, 1.0 / 6000.0, 1.0 / 3000.0)
    # Picks ramp over the end spacing, ends over the pick spacing: A / s² equal.
    assert a_pick * 6000.0**2 == pytest.approx(a_end * 3000.0**2)
    assert a_pick + a_end >= 2.0 * 5e-5


def test_threads_closer_than_a_diameter_cannot_interlace():
    with pytest.raises(PatternError, match="cannot interlace"):
        weave(DRAFTS["plain"], 12000.0, 12000.0, 5e-5)  # 83 µm apart, 100 µm thick


@pytest.mark.parametrize("draft, message", [
    (np.array([[1, 2], [0, 1]]), "only contain 0"),
    (np.array([[1, 1], [0, 1]]), "row 0 never interlaces"),
    (np.array([[1, 0], [1, 0]]), "column 0 never interlaces"),
    (np.array([1, 0]), "2D"),
])
def test_malformed_drafts_are_named(draft, message):
    with pytest.raises(PatternError, match=message):
        weave(draft, 3000.0, 3000.0, 5e-5)


@pytest.mark.parametrize("name", sorted(STITCHES))
def test_a_knit_has_one_yarn_per_course_along_x(name):
    chart = STITCHES[name]
    pattern = knit(chart, 1800.0, 1300.0, 7e-5, name=name)
    yarns = pattern.yarns()
    assert len(yarns) == chart.shape[0]
    assert all(y.net_offset == (1, 0) for y in yarns)
    np.testing.assert_allclose(pattern.repeat_size, [chart.shape[1] / 1300.0, chart.shape[0] / 1800.0])
    assert pyp_thread_numbers(pattern) == chart.shape
    assert pattern.family == "knit"


@pytest.mark.parametrize("name", sorted(STITCHES))
def test_loop_heads_and_sinkers_lie_on_the_side_the_chart_says(name):
    # Head of loop (k, j) on the side of the stitch of course k + 1 (the loop that catches it),
    # its sinkers on the side of its own stitch.
    chart = STITCHES[name]
    n_courses, n_wales = chart.shape
    pattern = knit(chart, 1800.0, 1300.0, 7e-5, name=name)
    for k, yarn in enumerate(pattern.yarns()):
        z = pattern.node_position[yarn.nodes, 2]
        for j in range(n_wales):
            head = z[j * SEGMENTS_PER_LOOP + SEGMENTS_PER_LOOP // 2]
            sinker = z[j * SEGMENTS_PER_LOOP]
            assert np.sign(head) == chart[(k + 1) % n_courses, j], (name, k, j)
            same_as_left = chart[k, j] == chart[k, j - 1]
            # At a knit/purl boundary the sinker crosses the mid-plane between the wales.
            assert np.sign(sinker) == (chart[k, j] if same_as_left else 0), (name, k, j)


@pytest.mark.parametrize("chart, message", [
    (np.array([[1, 0]]), r"\+1 \(knit\) and -1"),
    (np.array([1, -1]), "2D"),
])
def test_malformed_stitch_charts_are_named(chart, message):
    with pytest.raises(PatternError, match=message):
        knit(chart, 1800.0, 1300.0, 7e-5)


def test_a_repeat_size_that_leaves_a_gap_is_named():
    # The same yarns in a tile half a period too wide: each weft yarn jumps half a period where it
    # enters the next tile.
    import dataclasses

    pattern = weave(DRAFTS["plain"], 3000.0, 2500.0, 6e-5, name="plain")
    wide = dataclasses.replace(pattern, repeat_size=pattern.repeat_size * np.array([1.5, 1.0]))
    with pytest.raises(PatternError, match="does not tile without gaps"):
        wide.validate()
