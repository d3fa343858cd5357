"""The yarn-level stretch test (``yarnfit.validate.swatch``): a strip of straight parallel weft
yarns cut from a synthetic periodic repeat against the closed form, the jaw reaction against the
yarns' internal forces, a small real weave (global balance with contacts), and the recording read
back with its documented paths."""

import dataclasses
import math
import re

import numpy as np
import pytest
import rerun as rr

import yarnfit.validate.swatch as swatch_module
from yarnfit.engine import QuasiStaticOptions, QuasiStaticSolver, Rod, RodMaterial, RodModel, RodState, energy
from yarnfit.engine.model import quaternion_d3
from yarnfit.engine.tiling import cut_rectangle
from yarnfit.validate.strip import centre_line as middle_line
from yarnfit.validate.strip import cut_forces, edge_draw_in, free_side_ends, mid_strain, middle_compression
from yarnfit.validate.swatch import (FRICTION_STRAIN_STEP, STRAIN_TIMELINE, SWATCH_OPTIONS,
                                     UNIFORM_EXTRAPOLATION_RTOL, cut_swatch, read_uniform, stretch_repeat, stretch_swatch,
                                     swatch_curve)

E = 1e9  # Pa
RADIUS = 1e-4  # m
PX, PY = 1e-3, 1.2e-3  # repeat size (m); two weft yarns per repeat, so spacing PY / 2
NODES = 8  # per yarn per repeat (even: the jaw lines at multiples of PX / 2 fall on nodes)
# The solves stop at force residual 1e-6 of the force scale (EA/l0 · strain-sized displacements),
# so the reaction is known to ~1e-6 relative; the closed form is exact for the discrete rod
# (the axial strain |e|/l0 − 1 of a straight edge is the yarn strain), so only that is left.
FORCE_RTOL = 1e-5
# A cut swatch's rest state is its cut shape: its energy is round-off of curvatures and twists
# recomputed from the frames it was built from (~1e-16 rad over 1e-4 m edges, EI ~ 1e-8 N·m²).
REST_ENERGY_ATOL = 1e-20
# The extensometer on a uniformly stretched strip: the nodes between the marks move affinely to the
# solve's force tolerance (1e-8 of the force scale, so ~1e-8 of the strain).
MID_STRAIN_RTOL = 1e-6
# Rest frames along their edges: d3 against the unit tangent, round-off of the frames' transport.
TANGENT_ATOL = 1e-12


def straight_weft_repeat(hardening: float = 0.0, heights=(0.25, 0.75)):
    """Straight periodic weft yarns in a PX × PY repeat, at ``heights`` × PY (two, at y = PY/4 and
    3PY/4, by default)."""
    material = RodMaterial(E, poisson_ratio=0.3, density=1500.0, hardening_tension=hardening,
                           hardening_compression=hardening)
    rods = []
    for y in PY * np.asarray(heights):
        points = np.stack([np.arange(NODES) * PX / NODES, np.full(NODES, y), np.zeros(NODES)], axis=1)
        tiles = np.zeros((NODES, 2), dtype=int)
        tiles[-1] = (1, 0)
        rods.append(Rod(points=points, radius=RADIUS, material=material, closed=True, tile_offsets=tiles))
    model = RodModel.from_rods(rods, lattice=[[PX, 0, 0], [0, PY, 0]])
    return model, material


def axial_force(strain: float, hardening: float = 0.0) -> float:
    """Yarn tension at axial strain ε: N = A (E ε + ½ k ε²) (docs/design.md §4), N."""
    area = math.pi * RADIUS**2
    return area * (E * strain + 0.5 * hardening * strain**2)


def test_cut_rectangle_keeps_the_yarn_runs_inside():
    # Straight wefts at y = ±PY/4, ±3PY/4 about the repeat's centre: a 3 PX × 2 PY cut holds the
    # four, each one run spanning the cut's length (nodes PX/8 apart) at its own height; turned by
    # 90° about z the same yarns run along y; runs shorter than the minimum length are dropped, and
    # a cut narrower than the gap between the yarns holds none.
    model, _ = straight_weft_repeat()
    identity = np.eye(3)
    pieces = cut_rectangle(model, model.node_rest_position, identity, 3 * PX, 2 * PY, min_length=PX)
    assert sorted(round(float(p.points[0, 1]) / PY, 6) for p in pieces) == [-0.75, -0.25, 0.25, 0.75]
    for piece in pieces:
        assert np.all(np.abs(piece.points[:, 0]) <= 1.5 * PX) and np.ptp(piece.points[:, 0]) == pytest.approx(3 * PX)
        np.testing.assert_allclose(piece.rest_lengths, PX / NODES, rtol=1e-12)
        assert piece.frames.shape == (len(piece.points) - 1, 4) and piece.radius == RADIUS
    quarter = np.array([[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]])
    turned = cut_rectangle(model, model.node_rest_position, quarter, 2 * PY, 3 * PX, min_length=PX)
    assert len(turned) == 4
    assert all(np.ptp(p.points[:, 0]) < 1e-12 and np.ptp(p.points[:, 1]) == pytest.approx(3 * PX) for p in turned)
    assert cut_rectangle(model, model.node_rest_position, identity, 3 * PX, 2 * PY, min_length=4 * PX) == []
    assert cut_rectangle(model, model.node_rest_position, quarter, PY / 4, 3 * PX, min_length=PX) == []


@pytest.mark.parametrize("hardening", [0.0, 5e9])
def test_straight_wefts_match_closed_form(hardening):
    # Force per unit width of n parallel yarns at spacing s: N(ε) / s, ε the gauge strain (the
    # jaws hold everything outside the gauge rigidly); no Poisson contraction (rods do not neck).
    model, material = straight_weft_repeat(hardening)
    swatch = cut_swatch(model, model.node_rest_position, material, direction="weft", gauge=4 * PX, width=2 * PY,
                        clamp=PX)
    assert swatch.model.n_rods == 4  # yarns at y = ±PY/4, ±3PY/4
    out = stretch_swatch(swatch, (0.02, 0.05, 0.10))
    assert out["converged"]
    spacing = PY / 2
    for point in out["points"][1:]:
        expected = axial_force(point["strain"], hardening) / spacing
        assert point["force_n_per_m"] == pytest.approx(expected, rel=FORCE_RTOL)
        assert point["fixed_force_n_per_m"] == pytest.approx(expected, rel=FORCE_RTOL)
        # The middle half of the width (|y| <= PY / 2) holds the yarns at ±PY/4: the same pull.
        assert point["cut_force_n_per_m"] == pytest.approx(expected, rel=FORCE_RTOL)
        assert point["middle_force_n_per_m"] == pytest.approx(expected, rel=FORCE_RTOL)
        assert point["compression_ratio"] == pytest.approx(1.0, abs=1e-9)
        # Uniform between the jaws: the extensometer reads the jaws' strain.
        assert point["mid_strain"] == pytest.approx(point["strain"], rel=MID_STRAIN_RTOL)
        assert point["residual"]["force"] <= 1e-6
        # One solve per level without friction: its one step's reading is the point's own.
        (step,) = point["steps"]
        assert step["strain"] == point["strain"] and step["converged"]
        for key in ("mid_strain", "middle_force_n_per_m", "middle_compression_ratio", "compression_ratio"):
            assert step[key] == point[key]
    # Read off the curve at the strains the middle reached: the closed form again (at a level the
    # reading is that state's; between levels a power law through them, exact for a linear yarn).
    readings = read_uniform(out, (0.02, 0.035, 0.10))
    for read, strain in zip(readings, (0.02, 0.035, 0.10)):
        assert read.strain == strain and read.converged and not read.extrapolated and read.source == "steps"
        assert read.compression_ratio == pytest.approx(1.0, abs=1e-9)
        if hardening == 0.0 or strain in (0.02, 0.10):
            assert read.force_n_per_m == pytest.approx(axial_force(strain, hardening) / spacing, rel=FORCE_RTOL)


def test_the_curve_so_far_is_the_start_of_the_finished_curve():
    # A convergence study writes swatch_curve of the points reached after every strain, so a run
    # stopped part way keeps its levels: that curve must be the finished one's start, read the same.
    model, material = straight_weft_repeat(0.0)
    swatch = cut_swatch(model, model.node_rest_position, material, direction="weft", gauge=4 * PX, width=2 * PY,
                        clamp=PX)
    points, so_far = [], []

    def keep(k, strain, position, point):
        points.append(point)
        so_far.append(swatch_curve(swatch, points))

    out = stretch_swatch(swatch, (0.02, 0.05), on_step=keep)
    assert swatch_curve(swatch, points) == out
    first = so_far[1]  # after the 2 % level
    assert first["strain"] == out["strain"][:2] and first["points"] == out["points"][:2]
    assert first["nodes"] == out["nodes"] and first["converged"]
    (at_two, at_five) = read_uniform(first, (0.02, 0.05))
    assert at_two == read_uniform(out, (0.02,))[0]
    assert at_five is None  # not reached yet


def test_the_extensometer_reads_the_middle_not_the_jaws():
    # Positions made by hand: the middle half of the gauge stretched by 7 %, the rest of the strip
    # by 1 % (as if stiff near its jaws): the marks lie in the middle, so the reading is 7 %
    # whatever the jaws did; a strip too narrow to hold a node in the marks' middle half reads NaN.
    model, material = straight_weft_repeat()
    swatch = cut_swatch(model, model.node_rest_position, material, direction="weft", gauge=8 * PX, width=2 * PY,
                        clamp=PX)
    rest = swatch.position
    mid = 0.5 * (rest[swatch.moving, 0].min() + rest[swatch.fixed, 0].max())
    u = rest[:, 0] - mid
    inner = 0.3 * swatch.gauge  # beyond both marks and their bands
    stretched = np.where(np.abs(u) <= inner, 1.07 * u, np.sign(u) * (1.07 * inner + 1.01 * (np.abs(u) - inner)))
    position = rest.copy()
    position[:, 0] = mid + stretched
    assert mid_strain(swatch, position) == pytest.approx(0.07, rel=1e-12)
    assert mid_strain(swatch, rest) == pytest.approx(0.0, abs=1e-15)
    narrow = cut_swatch(model, model.node_rest_position, material, direction="weft", gauge=8 * PX, width=0.6 * PY,
                        clamp=PX)
    assert narrow.model.n_rods == 2  # the yarns at ±PY/4 lie outside its middle half (±0.15 PY)
    assert math.isnan(mid_strain(narrow, narrow.position))


def test_the_transverse_extensometer_reads_the_middle_half_of_the_width():
    # Wefts at y = ±PY/4, ±3PY/4, ±5PY/4 in a strip 3 PY wide: the marks lie at ±3PY/4 (a quarter
    # width either side of the centre line). Positions made by hand: the middle |y| <= PY drawn in
    # to 0.9 of its width, the rest by 0.7 more (cut sides drawn in): the reading is 0.9 whatever
    # the sides did. A strip whose marks hold no yarn reads NaN; a straight pull does not narrow.
    model, material = straight_weft_repeat()
    swatch = cut_swatch(model, model.node_rest_position, material, direction="weft", gauge=4 * PX, width=3 * PY,
                        clamp=PX)
    rest = swatch.position
    y = rest[:, 1] - middle_line(swatch)
    drawn = np.where(np.abs(y) <= PY, 0.9 * y, np.sign(y) * (0.9 * PY + 0.7 * (np.abs(y) - PY)))
    position = rest.copy()
    position[:, 1] = middle_line(swatch) + drawn
    assert middle_compression(swatch, position) == pytest.approx(0.9, rel=1e-12)
    assert middle_compression(swatch, rest) == pytest.approx(1.0, rel=1e-15)
    two = cut_swatch(model, model.node_rest_position, material, direction="weft", gauge=4 * PX, width=2 * PY,
                     clamp=PX)
    assert math.isnan(middle_compression(two, two.position))  # marks at ±PY/2, yarns at ±PY/4, ±3PY/4
    out = stretch_swatch(swatch, (0.03,))
    assert out["points"][1]["middle_compression_ratio"] == pytest.approx(1.0, abs=1e-9)


def test_jaw_reaction_equals_sum_of_yarn_forces():
    # The pull on the moving jaw is the sum over the yarns crossing mid-length of their internal
    # axial force EA (|e| / l0 − 1) there (free body of the strip's right half).
    model, material = straight_weft_repeat()
    swatch = cut_swatch(model, model.node_rest_position, material, direction="weft", gauge=3 * PX, width=2 * PY,
                        clamp=PX / 2)
    states = {}
    out = stretch_swatch(swatch, (0.03,), on_step=lambda k, e, pos, point: states.__setitem__(k, pos.copy()))
    position = states[1]
    m = swatch.model
    ends = position[m.edge_nodes[:, 1]]
    starts = position[m.edge_nodes[:, 0]]
    crossing = (starts[:, 0] < 0.0) & (ends[:, 0] >= 0.0)
    assert crossing.sum() == m.n_rods
    length = np.linalg.norm(ends - starts, axis=1)
    tension = m.edge_stretch_stiffness * (length / m.edge_rest_length - 1.0)
    direction_x = (ends - starts)[:, 0] / length
    cut_force = float(np.sum((tension * direction_x)[crossing]))
    assert out["points"][1]["force_n_per_m"] * swatch.width == pytest.approx(cut_force, rel=FORCE_RTOL)


@pytest.mark.parametrize("direction, sign", [("bias", -1.0), ("other bias", 1.0)])
def test_bias_strip_rotates_the_repeat(direction, sign):
    # A bias strip is the repeat turned by 45° (material x goes to world (1, -1)/√2; along the other
    # bias, −45°, to (1, 1)/√2): the straight wefts are cut into diagonal pieces across the strip.
    model, material = straight_weft_repeat()
    swatch = cut_swatch(model, model.node_rest_position, material, direction=direction, gauge=4 * PX,
                        width=2 * PY, clamp=PX)
    assert swatch.angle_deg == -45.0 * sign
    # Every piece lies at 45° in the strip frame: direction (1, ∓1)/√2 or its opposite.
    m = swatch.model
    edge = swatch.position[m.edge_nodes[:, 1]] - swatch.position[m.edge_nodes[:, 0]]
    edge /= np.linalg.norm(edge, axis=1, keepdims=True)
    assert np.allclose(np.abs(edge[:, 0]), math.sqrt(0.5), atol=1e-12)
    assert np.allclose(edge[:, 0] * edge[:, 1], 0.5 * sign, atol=1e-12)


def test_edge_draw_in_is_what_the_narrowing_does_not_explain():
    # A warp strip of straight wefts: every weft piece crosses it with both ends cut at the long
    # sides. Narrowed uniformly, the ends sit where the narrowing puts them (no draw-in); moved in
    # by a further 20 µm, they are drawn in by exactly that. A weft strip's yarns end in the jaws.
    model, material = straight_weft_repeat()
    swatch = cut_swatch(model, model.node_rest_position, material, direction="warp", gauge=4 * PY, width=3 * PX,
                        clamp=PY)
    ends = free_side_ends(swatch)
    assert len(ends) >= 4 and not swatch.model.node_pinned[ends].any()
    rest = swatch.position
    centre = 0.5 * (rest[:, 1].max() + rest[:, 1].min())
    narrowed = rest.copy()
    narrowed[:, 1] = centre + 0.9 * (rest[:, 1] - centre)
    assert edge_draw_in(swatch, rest, 1.0) == 0.0
    assert edge_draw_in(swatch, narrowed, 0.9) == pytest.approx(0.0, abs=1e-18)
    drawn = narrowed.copy()
    drawn[ends, 1] -= np.sign(rest[ends, 1] - centre) * 20e-6
    assert edge_draw_in(swatch, drawn, 0.9) == pytest.approx(20e-6, rel=1e-9)
    weft = cut_swatch(model, model.node_rest_position, material, direction="weft", gauge=4 * PX, width=2 * PY,
                      clamp=PX)
    assert len(free_side_ends(weft)) == 0 and math.isnan(edge_draw_in(weft, weft.position, 1.0))


def test_selvedges_join_the_courses_into_one_force_free_yarn():
    # A warp strip of straight wefts: the wefts run across it. With selvedges, the eight between
    # the jaws become one serpentine yarn turning outside the long sides (even courses at +y, odd
    # at −y, in order along the pull), the jaws' wefts stay as they were, and the joined yarn's
    # rest state is its cut shape with half circles added: no energy, every frame along its edge.
    model, material = straight_weft_repeat()
    dims = dict(direction="warp", gauge=4 * PY, width=3 * PX, clamp=PY / 2)
    cut = cut_swatch(model, model.node_rest_position, material, **dims)
    joined = cut_swatch(model, model.node_rest_position, material, selvedge=True, **dims)
    assert cut.model.n_rods == 10 and joined.model.n_rods == 3
    serpentine = int(np.argmax(np.diff(joined.model.rod_node_start)))
    nodes = np.arange(joined.model.rod_node_start[serpentine], joined.model.rod_node_start[serpentine + 1])
    points = joined.position[nodes]
    outside = np.abs(points[:, 1]) > 1.5 * PX + 1e-12
    turns = np.flatnonzero(np.diff(outside.astype(int)) == 1)
    assert len(turns) == 7  # between eight courses
    assert [math.copysign(1.0, points[t + 1, 1]) for t in turns] == [1.0, -1.0] * 3 + [1.0]
    assert np.all(np.diff(points[~outside][::NODES * 3, 0]) >= 0.0)  # courses in order along the pull
    # Half circles of the course spacing (PY / 2) as diameter: no node beyond PY / 4 outside.
    assert np.abs(points[:, 1]).max() <= 1.5 * PX + PY / 4 + 1e-12
    state = RodState.from_model(joined.model)
    assert energy(joined.model, state).internal == pytest.approx(0.0, abs=REST_ENERGY_ATOL)
    tangents = np.diff(points, axis=0)
    tangents /= np.linalg.norm(tangents, axis=1)[:, None]
    edges = np.arange(joined.model.rod_edge_start[serpentine], joined.model.rod_edge_start[serpentine + 1])
    np.testing.assert_allclose(quaternion_d3(joined.model.edge_rest_quaternion[edges]), tangents, atol=TANGENT_ATOL)


def test_the_middle_pull_counts_the_middle_yarns_only():
    # One weft per repeat, a strip 3 PY wide: yarns at y = −PY, 0 and PY. The middle half of the
    # width (|y| <= 3 PY / 4) holds the centre yarn alone, so the middle pulls N / (1.5 PY) while
    # the whole width pulls 3 N / (3 PY), the jaws' force; every plane across the gauge carries the
    # jaws' force over the whole width (the part before it is a free body).
    model, material = straight_weft_repeat(heights=(0.5,))
    swatch = cut_swatch(model, model.node_rest_position, material, direction="weft", gauge=4 * PX, width=3 * PY,
                        clamp=PX)
    assert sorted(np.unique(np.round(swatch.position[:, 1] / PY, 9))) == [-1.0, 0.0, 1.0]
    solver = QuasiStaticSolver(swatch.model, QuasiStaticOptions(**SWATCH_OPTIONS))
    strain = 0.04
    guess = RodState.from_model(swatch.model)
    guess.node_position[swatch.moving, 0] += strain * swatch.gauge
    result = solver.solve(guess)
    assert result.converged
    cut = cut_forces(swatch, result.state, result.contacts, planes=5)
    pull = float(result.reaction_force[swatch.moving, 0].sum())
    assert pull == pytest.approx(3 * axial_force(strain), rel=FORCE_RTOL)
    np.testing.assert_allclose(cut.whole, pull, rtol=FORCE_RTOL)
    np.testing.assert_allclose(cut.middle, axial_force(strain), rtol=FORCE_RTOL)
    # Quarters of the width from −y: the yarns at −PY, 0 and +PY lie in the first, third and
    # fourth (the centre yarn on the boundary between the inner two falls in the upper one).
    np.testing.assert_allclose(cut.quarters / axial_force(strain), [[1.0, 0.0, 1.0, 1.0]] * 5, atol=FORCE_RTOL)
    assert np.all(np.diff(cut.plane_x) > 0) and np.ptp(cut.plane_x) == pytest.approx(0.5 * (1 + strain) * swatch.gauge)


def test_small_weave_balances_with_contacts():
    # A real relaxed plain weave in a tiny strip: the moving and the fixed jaw pull equally (global
    # balance, contacts included) and it does not widen.
    from yarnfit.fabric import Fabric
    from yarnfit.fibers import get_fiber
    from yarnfit.relax import relax

    from yarnfit.yarn import YarnConstruction

    # The solid rod: its equilibria are stiff enough that a width change below 1e-9 is round-off of
    # the solve (fibre-assembly yarns, 50× softer in bending, move by 1.4e-9 at the same residual).
    fabric = Fabric(name="plain", fiber=get_fiber("cotton"), structure="plain", areal_density=0.2,
                    yarn=YarnConstruction(model="solid"))
    relaxed = relax(fabric)
    out = stretch_repeat(relaxed.model, relaxed.state.node_position, relaxed.yarn.section(), name="plain",
                         directions=("weft",), strains=(0.02,), size={"gauge": 1.5, "width": 1.0, "clamp": 0.5})
    point = out["directions"]["weft"]["points"][1]
    assert point["converged"]
    assert point["fixed_force_n_per_m"] == pytest.approx(point["force_n_per_m"], rel=1e-4)
    assert 0.0 < point["force_n_per_m"]
    assert point["compression_ratio"] <= 1.0 + 1e-9  # wefts crossing mid-length barely move across
    assert point["extent_ratio"] < 1.0  # the cut warp ends do


# The pull across a plane (cut_forces) against the jaws': both are sums of the same gradient over
# the nodes before the plane, apart by the free nodes' residual force, which the swatch solves stop
# at 1e-6 of the force scale; measured 4e-9 (bias, friction) to 2e-8 (weft, frictionless) of it.
CUT_BALANCE_RTOL = 1e-6


def test_friction_holds_a_small_weave_stiffer_and_balanced():
    """A small plain weave's bias strip with the fibre's friction at its crossings (lagged per
    strain): the jaws still pull equally (the friction forces are internal), the lagged normal
    forces settle, and the strip is stiffer than without friction (its yarns slide over each
    other as a bias strip shears; measured 1.16 against 0.75 N/m at 2 %)."""
    from yarnfit.fabric import Fabric
    from yarnfit.fibers import get_fiber
    from yarnfit.relax import relax

    cotton = get_fiber("cotton")
    relaxed = relax(Fabric(name="plain", fiber=cotton, structure="plain", areal_density=0.2))
    size = {"gauge": 1.5, "width": 1.0, "clamp": 0.5}
    points = {}
    for mu in (0.0, cotton.friction):
        out = stretch_repeat(relaxed.model, relaxed.state.node_position, relaxed.yarn.section(), name="plain",
                             directions=("bias",), strains=(0.02, 0.05), size=size, friction=mu)
        points[mu] = out["directions"]["bias"]["points"][1:]
    for point, steps in zip(points[cotton.friction], (4, 6)):  # 0 → 2 → 5 % in steps of 0.5 %
        assert point["converged"] and point["load_steps"] == steps and point["friction_passes"] >= 2 * steps
        # Each load step's middle is read; the last step is the point itself.
        assert len(point["steps"]) == steps and all(step["converged"] for step in point["steps"])
        assert point["steps"][-1]["middle_force_n_per_m"] == point["middle_force_n_per_m"]
        assert np.all(np.diff([step["strain"] for step in point["steps"]]) > 0)
        assert point["fixed_force_n_per_m"] == pytest.approx(point["force_n_per_m"], rel=1e-4)
        # The rods, contacts and friction anchors crossing a plane carry the jaws' pull.
        assert point["cut_force_n_per_m"] == pytest.approx(point["force_n_per_m"], rel=CUT_BALANCE_RTOL)
    for frictionless, frictional in zip(points[0.0], points[cotton.friction]):
        assert frictionless["friction_passes"] is None and frictionless["load_steps"] == 1
        assert frictional["force_n_per_m"] > 1.2 * frictionless["force_n_per_m"]
    with pytest.raises(ValueError, match="friction"):
        stretch_repeat(relaxed.model, relaxed.state.node_position, relaxed.yarn.section(), directions=("bias",),
                       strains=(0.02,), size=size, friction=-0.1)


# A frictional pull in load steps of 0.5 % against one in steps of 0.25 %, force per width. Each
# step's equilibrium is one of the nearby ones friction can hold, so paths scatter: measured on the
# plain weave's bias strip 1.3 % at 2 % and 1.9 % at 5 %, the same spread as between steps of 0.5 %
# and 2 % there; on the twill's warp strip 0.7 % up to 3 %, where one step of 2 % was 34 % soft.
LOAD_STEP_RTOL = 0.03


def _plain_weave_strip(direction: str):
    """``(cotton, strip)``: a 200 g/m² cotton plain weave's strip along ``direction``, 1.5 × 1
    repeats between jaws of half a repeat (a frictional pull of it takes seconds)."""
    from yarnfit.fabric import Fabric
    from yarnfit.fibers import get_fiber
    from yarnfit.relax import relax

    cotton = get_fiber("cotton")
    relaxed = relax(Fabric(name="plain", fiber=cotton, structure="plain", areal_density=0.2))
    repeat = max(relaxed.repeat_size)
    return cotton, cut_swatch(relaxed.model, relaxed.state.node_position, relaxed.yarn.section(), direction=direction,
                              gauge=1.5 * repeat, width=repeat, clamp=0.5 * repeat)


def test_a_frictional_pull_is_converged_in_its_load_step():
    cotton, swatch = _plain_weave_strip("bias")
    lines = []
    default = stretch_swatch(swatch, (0.02, 0.05), friction=cotton.friction, step_progress=lines.append)
    finer = stretch_swatch(swatch, (0.02, 0.05), friction=cotton.friction, strain_step=0.5 * FRICTION_STRAIN_STEP)
    for a, b in zip(default["points"][1:], finer["points"][1:]):
        assert a["converged"] and b["converged"] and b["load_steps"] == 2 * a["load_steps"]
        assert a["force_n_per_m"] == pytest.approx(b["force_n_per_m"], rel=LOAD_STEP_RTOL)
    # A line per load step (a large strip's level takes hours), each with the middle's pull then.
    steps = [step for point in default["points"][1:] for step in point["steps"]]
    assert len(lines) == len(steps) == 10
    assert lines[0].startswith("bias 0.5 % (load step 1 of 4 towards 2 %): middle half ")
    for line, step in zip(lines, steps):
        assert f"{step['middle_force_n_per_m']:.5g} N/m" in line and "converged" in line
    for step in (0.0, -0.005, math.nan):
        with pytest.raises(ValueError, match="strain_step"):
            stretch_swatch(swatch, (0.02,), friction=cotton.friction, strain_step=step)


def test_an_interrupted_pull_resumes_from_its_checkpoint_where_it_would_have_gone(tmp_path):
    # A largest strip takes hours a level: stopped after any load step and run again with the same
    # checkpoint file, the pull lands exactly where an uninterrupted one does (the next step starts
    # from the same rods, contacts and strain), and it hands on_step the levels it had finished.
    import json

    from yarnfit.validate.checkpoint import CheckpointError

    cotton, swatch = _plain_weave_strip("bias")
    strains = (0.01, 0.02)
    whole = stretch_swatch(swatch, strains, friction=cotton.friction)

    class Stop(Exception):
        pass

    def stop_at(kind: str, count: int):
        """step_progress / on_step callbacks that stop the pull at their ``count``-th call."""
        calls = []

        def callback(*args):
            calls.append(args)
            if len(calls) == count:
                raise Stop

        return {kind: callback}

    # Stopped after the first level's first step, after the first level (on_step: 0, then 1), and
    # after the second level's first step: the checkpoint holds (level, step) (1, 1), (2, 0), (2, 1).
    for where, (stop, stands) in enumerate([(stop_at("step_progress", 1), (1, 1)), (stop_at("on_step", 2), (2, 0)),
                                            (stop_at("step_progress", 3), (2, 1))]):
        path = tmp_path / f"pull-{where}.npz"
        with pytest.raises(Stop):
            stretch_swatch(swatch, strains, friction=cotton.friction, checkpoint=path, **stop)
        with np.load(path) as data:
            meta = json.loads(str(data["meta"]))
        assert (meta["level"], meta["step"]) == stands
        seen, said = [], []
        resumed = stretch_swatch(swatch, strains, friction=cotton.friction, checkpoint=path, progress=said.append,
                                 on_step=lambda k, strain, position, point: seen.append((k, strain)))
        assert seen == [(0, 0.0), (1, 0.01), (2, 0.02)]
        assert said[0] == f"bias: resumed from {path} after " + {(1, 1): "load step 1 towards 1 %", (2, 0): "1 %",
                                                                  (2, 1): "load step 1 towards 2 %"}[stands]
        timings = ("seconds", "slowest_step_seconds")
        for a, b in zip(whole["points"], resumed["points"], strict=True):
            assert {k: v for k, v in a.items() if k not in timings} == {k: v for k, v in b.items() if k not in timings}
        # Finished, the checkpoint hands the whole curve back without solving.
        again = stretch_swatch(swatch, strains, friction=cotton.friction, checkpoint=path)
        assert again["points"] == resumed["points"]
    with pytest.raises(CheckpointError, match="the checkpoint of another pull"):
        stretch_swatch(swatch, (0.01, 0.03), friction=cotton.friction, checkpoint=tmp_path / "pull-1.npz")


def test_a_frictional_step_that_does_not_settle_is_taken_in_halves(monkeypatch):
    # Here a step longer than 0.3 % never settles: each 0.5 % step is taken as two 0.25 % ones, the
    # pull converges, its middle is read after each, and it is the pull a 0.25 % step takes.
    from yarnfit.validate import swatch as swatch_module

    cotton, swatch = _plain_weave_strip("weft")
    step = swatch_module._swatch_step

    def settling_only_short_steps(swatch, solver, start, low, high, friction):
        taken = step(swatch, solver, start, low, high, friction)
        if high - low < 0.003:
            return taken
        return dataclasses.replace(taken, lagged=dataclasses.replace(taken.lagged, settled=False))

    monkeypatch.setattr(swatch_module, "_swatch_step", settling_only_short_steps)
    halved = stretch_swatch(swatch, (0.01,), friction=cotton.friction)["points"][1]
    fine = stretch_swatch(swatch, (0.01,), friction=cotton.friction, strain_step=0.0025)["points"][1]
    assert halved["converged"] and fine["converged"]
    assert halved["load_steps"] == fine["load_steps"] == 4 and len(halved["steps"]) == 4
    assert [r["strain"] for r in halved["steps"]] == pytest.approx([0.0025, 0.005, 0.0075, 0.01], rel=SAME_STEPS_RTOL)
    assert halved["force_n_per_m"] == pytest.approx(fine["force_n_per_m"], rel=SAME_STEPS_RTOL)
    # It also paid for the two long steps it tried first.
    assert halved["iterations"] > fine["iterations"] and halved["friction_passes"] > fine["friction_passes"]


# Two pulls through the same load steps differ in their targets' last bits only (0.5 (0.005 +
# 0.01) against 3 × 0.01 / 4): round-off, a few ulps of the strains and what follows from them.
SAME_STEPS_RTOL = 1e-9


def _power_law_curve(strains, steps: bool, exponent: float = 1.7, scale: float = 3e4):
    """A curve as :func:`stretch_swatch` writes it whose middle pulls ``scale ε^exponent`` N/m at
    its middle's strain ``ε = 1.3 × the jaws'`` and narrows linearly, with each level's load steps
    (``steps``) or as a curve written before they were kept."""
    def reading(jaws):
        middle = 1.3 * jaws
        return {"strain": jaws, "mid_strain": middle, "middle_force_n_per_m": scale * middle**exponent,
                "middle_compression_ratio": 1.0 - 0.8 * middle, "converged": True}
    points, previous = [{"strain": 0.0}], 0.0
    for strain in strains:
        point = {**reading(strain), "force_n_per_m": 0.0, "compression_ratio": 1.0}
        if steps:
            point["steps"] = [reading(previous + (strain - previous) * j / 4) for j in range(1, 5)]
        points.append(point)
        previous = strain
    return {"points": points}


@pytest.mark.parametrize("steps", [True, False])
def test_the_uniform_part_is_read_at_the_strains_its_middle_reached(steps):
    # A pull that grows as a power of the strain is read exactly between any two states (and below
    # the first, through the origin), whether between load steps or between levels only.
    curve = _power_law_curve((0.02, 0.05, 0.10), steps)
    wanted = (0.01, 0.02, 0.05, 0.10)
    for read, strain in zip(read_uniform(curve, wanted), wanted):
        assert read.strain == strain and read.converged and not read.extrapolated
        assert read.source == ("steps" if steps else "levels")
        assert read.force_n_per_m == pytest.approx(3e4 * strain**1.7, rel=1e-12)
        assert read.compression_ratio == pytest.approx(1.0 - 0.8 * strain, rel=1e-12)
    # The middle reached 13 %: a little beyond it is read on the last stretch's power law and
    # says so; further is not read.
    reached = 1.3 * 0.10
    near, far = read_uniform(curve, (reached * (1 + 0.5 * UNIFORM_EXTRAPOLATION_RTOL),
                                     reached * (1 + 2 * UNIFORM_EXTRAPOLATION_RTOL)))
    assert near.extrapolated and near.force_n_per_m == pytest.approx(3e4 * near.strain**1.7, rel=1e-12)
    assert far is None
    # A state that did not converge makes the readings next to it unconverged.
    curve["points"][2]["converged"] = False
    if steps:
        curve["points"][2]["steps"][-1]["converged"] = False
    assert not read_uniform(curve, (1.3 * 0.05,))[0].converged
    with pytest.raises(ValueError, match="positive"):
        read_uniform(curve, (0.0,))


def documented_paths(directions):
    templates = re.findall(r"``(yarn(?:/[\w<>]+)*)``", swatch_module.__doc__)
    return {t.replace("<direction>", d) for t in templates for d in (directions if "<direction>" in t else [""])}


def test_recording_reads_back(tmp_path):
    model, material = straight_weft_repeat()
    path = tmp_path / "straight" / "yarn.rrd"
    strains = (0.02, 0.05)
    out = stretch_repeat(model, model.node_rest_position, material, name="straight", directions=("weft",),
                         strains=strains, size={"gauge_m": 2 * PX, "width_m": PY, "clamp_m": PX / 2},
                         recording_path=path)
    reader = rr.chunk.RrdReader(str(path))
    rows, timelines = {}, {}
    for chunk in reader.stream():
        batch = chunk.to_record_batch()
        names = batch.schema.names
        steps = batch.column(STRAIN_TIMELINE).to_pylist() if STRAIN_TIMELINE in names else [None] * batch.num_rows
        entity = rows.setdefault(chunk.entity_path.lstrip("/"), {})
        for name in (n for n in names if ":" in n):
            entity.setdefault(name, {}).update(zip(steps, batch.column(name).to_pylist()))
        timelines.setdefault(chunk.entity_path.lstrip("/"), set()).update(chunk.timeline_names)
    paths = {p for p in rows if not p.startswith("__")}
    assert paths == documented_paths(["weft"])
    force = rows["yarn/plots/force_weft"]
    (column,) = [c for c in force if c.endswith("scalars")]
    logged = [force[column][k][0] for k in range(len(strains) + 1)]
    assert np.allclose(logged, out["directions"]["weft"]["force_n_per_m"], rtol=1e-6)
    middle = rows["yarn/plots/middle_force_weft"]
    (column,) = [c for c in middle if c.endswith("scalars")]
    assert np.allclose([middle[column][k][0] for k in range(len(strains) + 1)],
                       [p["middle_force_n_per_m"] for p in out["directions"]["weft"]["points"]], rtol=1e-6)
    assert STRAIN_TIMELINE in timelines["yarn/swatch/yarns"]
    text = [v for c, v in rows["yarn/summary"].items() if c.endswith(":text")]
    assert "force (N/m)" in str(text[0][None])


def test_fabric_from_inputs_rebuilds_the_preset():
    # The material file's `inputs` block (yarnfit.fabric_fit.FabricFit.to_dict) names the fabric the
    # swatch is built from; for a preset it must give back that preset.
    from dataclasses import asdict

    from yarnfit.fabric import Fabric
    from yarnfit.material_file import fabric_from_inputs

    from yarnfit.yarn import YarnConstruction

    preset = Fabric.preset("cotton-twill")
    inputs = {"fabric": preset.name, "fiber": asdict(preset.fiber), "pattern": preset.structure, "family": "woven",
              "counts_per_m": list(preset.counts), "areal_density_kg_m2": preset.areal_density,
              "yarn": preset.yarn.to_dict()}
    assert fabric_from_inputs(inputs) == preset
    # A file written before the yarn block was fitted with the paper's solid rod, and is rebuilt so.
    del inputs["yarn"]
    assert fabric_from_inputs(inputs) == Fabric.preset("cotton-twill", yarn=YarnConstruction(model="solid"))
    with pytest.raises(ValueError, match="inputs"):
        fabric_from_inputs({"fabric": "x"})


def test_the_suite_runs_the_yarn_scene_per_direction_and_merges_it(tmp_path):
    # `yarnfit validate` pulls each direction's strip as its own task (side by side on workers),
    # each followed by its shell strip; its summary is one yarn scene, the same curves a single run
    # of both directions gives.
    import json
    from dataclasses import asdict

    import yarnfit
    from fabric_shell import FABRIC
    from yarnfit.fabric import Fabric
    from yarnfit.validate.suite import run_suite
    from yarnfit.validate.swatch import merge_yarn_summaries, run_yarn

    fabric = Fabric.preset("cotton-jersey")  # its quick strips are 150 nodes
    inputs = {"fabric": fabric.name, "fiber": asdict(fabric.fiber), "pattern": fabric.structure, "family": "knit",
              "counts_per_m": list(fabric.counts), "areal_density_kg_m2": fabric.areal_density,
              "yarn": fabric.yarn.to_dict()}
    path = tmp_path / "jersey.json"
    path.write_text(json.dumps({"yarnfit_version": yarnfit.__version__, "inputs": inputs, "shell": FABRIC.to_dict(),
                                "engineering": FABRIC.engineering()}))
    summary, _ = run_suite(path, ("stretch", "yarn"), quick=True, logs=tmp_path / "logs")
    yarn = summary["scenes"]["yarn"]
    # Each direction's shell strip of the swatch's proportions follows its own yarn strip.
    assert set(summary["shell_vs_yarn"]["shell_strips"]) == {"swatch_weft", "swatch_warp"}
    # ... the shell in the swatch's own test: its gauge, width and strains, solved to convergence.
    for direction in ("weft", "warp"):
        strip, curve = summary["shell_vs_yarn"]["shell_strips"][f"swatch_{direction}"], yarn["directions"][direction]
        assert strip["quasi_static"] and all(strip["converged"])
        assert (strip["length_m"], strip["width_m"]) == (curve["gauge_m"], curve["width_m"])
        assert strip["strain"] == [e for e in curve["strain"] if e > 0]
        # ... beside the same shell pulled free, which says how far the jaws hold the strip.
        angle = math.radians(curve["angle_deg"])
        assert strip["free_pull_n_per_m"] == [FABRIC.uniaxial_pull(angle, 1 + e).force_n_per_m for e in strip["strain"]]
        compared = summary["shell_vs_yarn"]["same_proportions"][direction]
        assert len(compared["jaws_hold"]) == len(compared["strain"]) and all(h > 0 for h in compared["jaws_hold"])
    assert set(summary["shell_vs_yarn"]["same_proportions"]) == {"weft", "warp"}
    assert summary["wall_seconds"]["shell_strips_like_swatch"] > 0
    folder = tmp_path / "logs" / fabric.name
    assert list(yarn["directions"]) == ["weft", "warp"] and summary["wall_seconds"]["yarn"] > 0
    assert yarn["recordings"] == [str(folder / "yarn_weft.rrd"), str(folder / "yarn_warp.rrd")]
    assert all((folder / f"yarn_{d}.rrd").is_file() for d in ("weft", "warp")) and "recording" not in yarn
    whole = run_yarn(path, quick=True, recording_path=False).summary()
    for direction, curve in whole["directions"].items():
        assert yarn["directions"][direction]["force_n_per_m"] == curve["force_n_per_m"]
    assert yarn["seconds"] >= sum(c["seconds"] for c in yarn["directions"].values())  # and the cutting
    with pytest.raises(ValueError, match="no yarn"):
        merge_yarn_summaries([])


def _swatch_convergence_script(monkeypatch):
    """validation/swatch_convergence.py, imported as a module."""
    import importlib.util
    import sys
    from pathlib import Path

    spec = importlib.util.spec_from_file_location(
        "swatch_convergence", Path(__file__).parent.parent / "validation" / "swatch_convergence.py")
    script = importlib.util.module_from_spec(spec)
    monkeypatch.setitem(sys.modules, spec.name, script)  # its dataclasses look their module up
    spec.loader.exec_module(script)
    return script


def test_the_kept_strip_curves_are_read_back_and_say_what_solved_them(monkeypatch):
    # validation/strips/ keeps the largest strips' curves (hours a level) for --kept: each is read
    # as swatch_convergence.py reads it (its levels a start of the swatch's strains) and says which
    # command and commit solved it, without which a stale curve could not be told.
    import json

    script = _swatch_convergence_script(monkeypatch)
    folder = script.KEPT_STRIPS.parent
    paths = sorted((folder / "strips").glob("*.json"))
    assert paths, "validation/strips/ holds no curve"
    listed = (folder / "strips" / "README.md").read_text()
    for path in paths:
        assert path.name in listed
        for label, curve in json.loads(path.read_text())["curves"].items():
            reached = [point for point in script.level_points(curve) if point is not None]
            assert reached, f"{path.name}: {label} reached no strain"
            assert curve["direction"] == label.split()[0]
            assert re.fullmatch(r"[0-9a-f]{40}", curve["written_by"]["commit"]), f"{path.name}: {label}"
            assert curve["written_by"]["command"].startswith("python validation/swatch_convergence.py")


def test_kept_curves_are_found_by_their_fabric_and_another_fabrics_are_refused(monkeypatch):
    # --kept reads the curves of the material's own fabric; a curve of another fabric, named with
    # --from-json, would judge the shell against someone else's yarns, so it is refused by name.
    import json

    script = _swatch_convergence_script(monkeypatch)
    kept = script.kept_curves("polyester-satin")
    assert {p.rsplit("/", 1)[1] for p in kept} >= {"polyester-satin_weft_8x6.json", "polyester-satin_warp_8x6.json"}
    for path in kept:
        with open(path) as source:
            assert json.load(source)["material"] == "polyester-satin"
    curves = script.read_curves(kept, "polyester-satin")
    assert {"weft 8x6", "warp 8x6"} <= set(curves) and curves["weft 8x6"]["repeats"] == [8, 6]
    # The acceptance cells (weft, warp, bias at 2, 5, 10 %) that no direction's largest strip has
    # reached: a smaller strip's levels do not count, nor does the other bias.
    rest = {"strain": 0.0}

    def curve(direction, nodes, strains):
        return {"direction": direction, "nodes": nodes, "points": [rest] + [{"strain": e} for e in strains]}

    some = {"weft 8x6": curve("weft", 900, (0.02,)), "weft 4x3": curve("weft", 200, (0.02, 0.05, 0.1)),
            "bias 12x4": curve("bias", 500, (0.02, 0.05, 0.1)), "other bias 12x4": curve("other bias", 500, (0.02,))}
    assert script.unreached_cells(some) == ["weft 5 %", "weft 10 %", "warp 2 %", "warp 5 %", "warp 10 %"]
    assert len(script.unreached_cells({})) == 9
    with pytest.raises(ValueError, match="keeps no strip curve of 'no-such-fabric'"):
        script.kept_curves("no-such-fabric")
    with pytest.raises(ValueError, match=r"polyester-satin_\w+\.json: its curves are of 'polyester-satin', "
                                         "not of the material 'cotton-twill'"):
        script.read_curves(kept, "cotton-twill")


def test_the_convergence_table_reads_every_strip_where_it_is_uniform(monkeypatch):
    # Each strip's row carries the reading the verdicts use (the middle half's pull and width at
    # its middle's own 2 / 5 / 10 %), so the table shows that reading converging as the strip
    # grows; its cells line up with the header's.
    script = _swatch_convergence_script(monkeypatch)
    curves = script.read_curves(script.kept_curves("polyester-satin"), "polyester-satin")
    columns = script.table_columns(script.convergence_header())
    n = len(script.STRAINS)
    for label, curve in curves.items():
        cells = [cell.strip() for cell in script.convergence_row(curve).strip().strip("|").split("|")]
        assert len(cells) == columns, label
        readings = read_uniform(curve, script.STRAINS)
        forces, widths = cells[3 + 2 * n:3 + 3 * n], cells[3 + 3 * n:3 + 4 * n]
        for force, width, reading in zip(forces, widths, readings):
            if reading is None:
                assert (force, width) == ("—", "—"), label
            else:  # printed to 4 and 3 significant digits
                assert float(force.split()[0]) == pytest.approx(reading.force_n_per_m, rel=5e-4), label
                assert float(width) == pytest.approx(reading.compression_ratio, abs=5e-4), label
    # The satin's weft strip reached 2 % (at least): its uniform cell there is a number.
    assert read_uniform(curves["weft 8x6"], script.STRAINS)[0] is not None
