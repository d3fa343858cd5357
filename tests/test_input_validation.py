"""Bad input gets a clear ValueError naming the problem, never a crash or a NaN."""

import numpy as np
import pytest

from yarnfit.engine import (
    ConvergenceWarning,
    Loads,
    QuasiStaticOptions,
    QuasiStaticSolver,
    Rod,
    RodMaterial,
    RodModel,
    RodState,
    XPBDOptions,
    XPBDSolver,
    energy,
    straight_points,
)

MATERIAL = RodMaterial(1e9)
POINTS = straight_points(0.1, 5)


def build(**changes):
    args = {"points": POINTS, "radius": 1e-3, "material": MATERIAL}
    args.update(changes)
    return RodModel.from_rods([Rod(**args)])


@pytest.mark.parametrize("radius", [0.0, -1e-3, float("nan"), float("inf"), None, "thick"])
def test_radius_must_be_positive_and_finite(radius):
    with pytest.raises(ValueError, match="radius"):
        build(radius=radius)


@pytest.mark.parametrize("modulus", [0.0, -5e9, float("nan")])
def test_young_modulus_must_be_positive(modulus):
    with pytest.raises(ValueError, match="young_modulus"):
        RodMaterial(modulus)


@pytest.mark.parametrize(
    "field, value, message",
    [
        ("density", 0.0, "density"),
        ("poisson_ratio", 0.5, "poisson_ratio"),
        ("poisson_ratio", -1.0, "poisson_ratio"),
        ("hardening_tension", -1.0, "hardening_tension"),
        ("hardening_compression", float("nan"), "hardening_compression"),
    ],
)
def test_material_fields_are_checked(field, value, message):
    with pytest.raises(ValueError, match=message):
        RodMaterial(1e9, **{field: value})


@pytest.mark.parametrize("bad", [0.0, -0.02, float("nan")])
def test_rest_lengths_must_be_positive(bad):
    rest = np.full(5, 0.02)
    rest[3] = bad
    with pytest.raises(ValueError, match="rest length of edge 3"):
        build(rest_lengths=rest)


def test_repeated_point_is_a_zero_length_edge():
    points = POINTS.copy()
    points[2] = points[1]
    with pytest.raises(ValueError, match="edge 1 has zero length"):
        build(points=points)


def test_points_must_be_finite_and_shaped():
    points = POINTS.copy()
    points[4, 1] = np.nan
    with pytest.raises(ValueError, match="row 4 is not finite"):
        build(points=points)
    with pytest.raises(ValueError, match="shape"):
        build(points=POINTS[:, :2])
    with pytest.raises(ValueError, match="at least 2 points"):
        build(points=POINTS[:1])


def test_frames_must_be_unit_finite_and_along_the_edges():
    frames = np.tile([np.cos(np.pi / 4), 0.0, np.sin(np.pi / 4), 0.0], (5, 1))  # d3 = +x
    build(frames=frames)  # valid
    scaled = frames.copy()
    scaled[2] *= 1.1
    with pytest.raises(ValueError, match="row 2 is not a unit quaternion"):
        build(frames=scaled)
    with_nan = frames.copy()
    with_nan[1, 0] = np.nan
    with pytest.raises(ValueError, match="row 1 is not finite"):
        build(frames=with_nan)
    with pytest.raises(ValueError, match="d3 off its edge"):
        build(frames=np.tile([1.0, 0.0, 0.0, 0.0], (5, 1)))  # d3 = +z, edges along x


@pytest.mark.parametrize("key, index", [("pinned_nodes", 6), ("pinned_nodes", -7), ("pinned_frames", 5)])
def test_pin_index_out_of_range(key, index):
    with pytest.raises(ValueError, match=f"index {index} is out of range"):
        build(**{key: [0, index]})


def test_pin_index_must_be_an_integer():
    with pytest.raises(ValueError, match="not an integer"):
        build(pinned_nodes=[1.5])


def test_states_with_bad_quaternions_are_rejected_by_every_entry_point():
    model = build(pinned_nodes=[0], pinned_frames=[0])
    loads = Loads.zeros(model)
    for corrupt, message in ((lambda q: q.__setitem__((2, 0), np.nan), "row 2 is not finite"),
                             (lambda q: q.__setitem__(3, q[3] * 0.5), "row 3 is not a unit quaternion")):
        state = RodState.from_model(model)
        corrupt(state.edge_quaternion)
        with pytest.raises(ValueError, match=message):
            energy(model, state)
        with pytest.raises(ValueError, match=message):
            QuasiStaticSolver(model).solve(state, loads)
        with pytest.raises(ValueError, match=message):
            XPBDSolver(model).step(state, loads, 1e-3)


def test_state_and_loads_must_match_the_model():
    model = build()
    state = RodState.from_model(model)
    state.node_position = state.node_position[:-1]
    with pytest.raises(ValueError, match="node_position must have shape"):
        energy(model, state)
    loads = Loads.zeros(model)
    loads.node_force[1, 2] = np.inf
    with pytest.raises(ValueError, match="node_force: row 1 is not finite"):
        energy(model, RodState.from_model(model), loads)
    with pytest.raises(ValueError, match="gravity"):
        energy(model, RodState.from_model(model), Loads(np.array([0.0, np.nan, 0.0]), np.zeros_like(loads.node_force), loads.edge_moment))


def test_solver_options_are_checked():
    with pytest.raises(ValueError, match="force_tolerance"):
        QuasiStaticOptions(force_tolerance=-1.0)
    with pytest.raises(ValueError, match="max_iterations"):
        QuasiStaticOptions(max_iterations=0)
    with pytest.raises(ValueError, match="substeps"):
        XPBDOptions(substeps=0)
    with pytest.raises(ValueError, match="static_friction"):
        XPBDOptions(static_friction=-0.1)


def test_a_problem_without_equilibrium_warns_and_stays_finite():
    # A free rod under gravity has no static equilibrium: the solver must say so, not return NaN.
    model = build()
    with pytest.warns(ConvergenceWarning, match="did not converge"):
        result = QuasiStaticSolver(model, QuasiStaticOptions(max_iterations=20)).solve(
            RodState.from_model(model), Loads.zeros(model, gravity=(0.0, 0.0, -9.81))
        )
    assert not result.converged
    assert np.all(np.isfinite(result.state.node_position))
    assert np.all(np.isfinite(result.state.edge_quaternion))
