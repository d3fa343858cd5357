"""The Newton solver's Hessian against central differences of the exact gradient.

The Hessian only steers Newton (the equilibrium is defined by the gradient, which the solver
tests check), so an error here costs iterations, not accuracy; this test keeps it exact.
"""

import numpy as np
import pytest
import scipy.sparse as sp
from scipy.spatial.transform import Rotation

from yarnfit.engine import Loads, QuasiStaticSolver, Rod, RodMaterial, RodModel, RodState, straight_points
from yarnfit.engine import _contact_kernels, _kernels
from yarnfit.engine.contact_lagrangian import ContactSet
from yarnfit.engine.quasistatic import _rotate_frames, _Work

# Central differences of the analytic gradient at step h carry O(h²) truncation and O(ε/h)
# round-off: ~1e-10 relative at the steps below; 1e-7 leaves room and still fails on any wrong term.
HESSIAN_RTOL = 1e-7
# Central differences of the contact energy (~5e-4 J, mostly the constant M(λ) / k) at h = 1e-10 m
# lose ε E / h ~ 1e-9 N to round-off, and inside the smoothing band the ramp's third derivative
# k² / 2δ ~ 1e12 J/m³ adds h² f''' / 6 ~ 2e-9 N: both ~1e-6 of the gradient. A wrong term (a
# missing ½, a sign, the band's offset) errs by O(1).
ENERGY_DIFFERENCE_RTOL = 1e-5
# Tilting a parallel contact by ±1e-6 rad changes its gaps by ~1e-10 m of 1e-5 m penetration: the
# gradient moves by ~1e-5 of itself; a kink would move it by O(1).
PARALLEL_CONTINUITY = 1e-3
# The CSC assembly sums a few O(1) triplets per entry in another order than scipy: ~1e-16 each;
# a dropped, doubled or misplaced triplet errs by O(1).
ASSEMBLY_ATOL = 1e-14


def _two_rods():
    t = np.linspace(0.0, 1.0, 8)
    curved = np.column_stack([0.05 * np.sin(t), 0.05 * (1 - np.cos(t)), 0.01 * t])
    mat = RodMaterial(2e6, 0.35, 1000.0, hardening_tension=8e6, hardening_compression=3e6)
    return RodModel.from_rods([
        Rod(curved, 3e-3, mat, pinned_nodes=[0], pinned_frames=[0]),
        Rod(straight_points(0.05, 5, start=(0.0, 0.02, 0.0)), 2e-3, mat, straight=True),
    ]), 2e-3


def _curved_tiling():
    from curved_tiling import curved_model

    return curved_model(), 1e-4


# Two open rods, and a periodic model on a curved tiling (ghost-edge ends rotated, frames turned
# across tile borders).
@pytest.mark.parametrize("build", [_two_rods, _curved_tiling], ids=["two rods", "curved tiling"])
def test_rod_hessian_matches_differences_of_the_gradient(build):
    rng = np.random.default_rng(4)
    model, jitter = build()
    state = RodState.from_model(model)
    position = state.node_position + jitter * rng.standard_normal(state.node_position.shape)
    quaternion = _rotate_frames(state.edge_quaternion, 0.2 * rng.standard_normal((model.n_edges, 3)))
    solver = QuasiStaticSolver(model)
    work = _Work(position, quaternion)
    hessian = solver._hessian(work)[0].toarray()
    loads = Loads.zeros(model)
    node_force, moment = loads.total_node_force(model), loads.edge_moment

    def gradient(step):
        dx, dtheta = solver._split(step)
        point = (position + dx, _rotate_frames(quaternion, dtheta), 0.0)
        return solver._assess(point, ContactSet.none(), node_force, moment).gradient[solver._free]

    h = 1e-7
    n = hessian.shape[0]
    differences = np.empty((n, n))
    for k in range(n):
        e = np.zeros(n)
        e[k] = h
        differences[:, k] = (gradient(e) - gradient(-e)) / (2 * h)
    # The symmetric part of the derivative of the world torque is the Hessian in the exponential
    # chart (the antisymmetric rest is the chart's own curvature times the torque).
    symmetric = 0.5 * (differences + differences.T)
    # Block by block (positions, rotations): the rotation block is ~1e7 times smaller than the
    # stretch block, so one scale for the whole matrix would hide errors in it.
    free_nodes = int(np.count_nonzero(solver._free < 3 * model.n_nodes))
    blocks = (slice(0, free_nodes), slice(free_nodes, n))
    for rows in blocks:
        for cols in blocks:
            scale = np.abs(hessian[rows, cols]).max()
            assert scale > 0.0
            assert np.abs(hessian[rows, cols] - symmetric[rows, cols]).max() <= HESSIAN_RTOL * scale, (rows, cols)


# Contact pair geometry for the tests below: two crossing segments 2.45e-4 m apart (radii 1e-4),
# sampled by 7 and 9 points (nodes included).
CONTACT_POINTS = np.array([[-1e-3, 0.0, 0.0], [1e-3, 1e-4, 0.0], [2e-4, -1e-3, 1.9e-4], [-1e-4, 1e-3, 1.95e-4]])
CONTACT_SAMPLES = np.array([7, 9])
CONTACT_STIFFNESS = 4.7e5
CONTACT_SMOOTHING = 1e-3


# A rigid map placing the second edge's nodes (a curved tiling's image): 0.7 rad about a skew axis.
IMAGE_ROTATION = Rotation.from_rotvec(0.7 * np.array([0.3, -0.5, 0.81]) / np.linalg.norm([0.3, -0.5, 0.81])).as_matrix()
IMAGE_TRANSLATION = np.array([2e-3, -1e-3, 5e-4])


def _contact_pair_terms(multiplier, mapped=False):
    """Energy, gradient and Hessian functions of the one-pair contact term (``multiplier`` per
    sampled constraint) over node positions ``(4, 3)``. With ``mapped``, the second edge's nodes are
    placed by IMAGE_ROTATION and IMAGE_TRANSLATION (as a periodic image on a curved surface)."""
    edge_nodes = np.array([[0, 1], [2, 3]])
    radius = np.array([1e-4, 1e-4])
    pairs = np.array([[0, 1]])
    rotation = np.broadcast_to(np.eye(3), (1, 4, 3, 3)).copy()
    translation = np.zeros((1, 4, 3))
    if mapped:
        rotation[0, 2:] = IMAGE_ROTATION
        translation[0, 2:] = IMAGE_TRANSLATION
    n = int(CONTACT_SAMPLES.sum())
    start = np.array([0, n])
    lam, k = np.asarray(multiplier, dtype=float), np.array([CONTACT_STIFFNESS])

    def energy_gradient(x):
        g = np.zeros((4, 3))
        gap = np.empty(n)
        energy = _contact_kernels.contact_energy_gradient(x, edge_nodes, radius, CONTACT_SAMPLES, pairs, rotation,
                                                          translation, start, lam, k, CONTACT_SMOOTHING, g,
                                                          np.zeros(4), gap, np.empty(n))
        return energy, g.ravel(), gap

    def hessian(x):
        rows, cols, vals = np.empty(144, np.int64), np.empty(144, np.int64), np.empty(144)
        count = _contact_kernels.contact_hessian_coo(x, edge_nodes, radius, CONTACT_SAMPLES, pairs, rotation,
                                                     translation, start, lam, k, CONTACT_SMOOTHING, rows, cols,
                                                     vals, 0)
        out = np.zeros((12, 12))
        np.add.at(out, (rows[:count], cols[:count]), vals[:count])
        return out

    return energy_gradient, hessian


def _contact_nodes(mapped):
    """Node positions whose (mapped) points are CONTACT_POINTS."""
    nodes = CONTACT_POINTS.copy()
    if mapped:
        nodes[2:] = (CONTACT_POINTS[2:] - IMAGE_TRANSLATION) @ IMAGE_ROTATION  # Rᵀ (p − t), row-wise
    return nodes


def _contact_multiplier(band_position):
    """Multipliers that put ``λ − k g`` at ``band_position`` half-widths of the smoothing band for
    the constraints near contact (gap below 1e-4 m), zero for the others (separated samples: their
    terms vanish, as they would in a solve)."""
    gap = _contact_pair_terms(np.zeros(int(CONTACT_SAMPLES.sum())))[0](CONTACT_POINTS)[2]
    delta = CONTACT_SMOOTHING * CONTACT_STIFFNESS * 2e-4
    near = gap < 1e-4
    assert near.sum() >= 2
    # (Negative where a sample penetrates and the band position is below −1 + k|g|/δ: the kernels'
    # terms hold for any λ, and it keeps every near constraint at the same place on the ramp.)
    return np.where(near, CONTACT_STIFFNESS * gap + band_position * delta, 0.0)


# Reference steps (m) of the differences below: 1e-9 m moves λ − k g by 5e-3 of the band's
# half-width δ, fine above and inside the band; at its foot (λ − k g = −0.998 δ, where lightly held
# loops rest and force and stiffness both vanish) that is more than the foot's width, so there
# 1e-12 m (round-off ε |g| / h stays ~1e-11 of the entries: the foot's forces are ~1e-6 δ).
REFERENCE_STEP = {5.0: 1e-9, 0.3: 1e-9, -0.9995: 1e-12}


# Above the band (the quadratic branch), inside it (the parabolic ramp) and at its foot; the second
# edge as itself or as a rotated image. The foot matters: when the solver's Hessian was itself a
# difference of gradients, a stencil of 1e-6 of the radius sum straddled the foot, the stiffness
# came out several times too large, and Newton cycled for tens of thousands of iterations on knits.
@pytest.mark.parametrize("mapped", [False, True])
@pytest.mark.parametrize("band_position", [5.0, 0.3, -0.9995])
def test_contact_hessian_matches_differences_of_the_gradient(band_position, mapped):
    energy_gradient, hessian = _contact_pair_terms(_contact_multiplier(band_position), mapped)
    nodes = _contact_nodes(mapped)
    h = REFERENCE_STEP[band_position]
    differences = np.empty((12, 12))
    for k in range(12):
        x = nodes.ravel().copy()
        x[k] += h
        plus = energy_gradient(x.reshape(4, 3))[1]
        x[k] -= 2 * h
        differences[:, k] = (plus - energy_gradient(x.reshape(4, 3))[1]) / (2 * h)
    exact = hessian(nodes)
    assert np.abs(exact).max() > 0.0
    assert np.abs(exact - 0.5 * (differences + differences.T)).max() <= HESSIAN_RTOL * np.abs(exact).max()


@pytest.mark.parametrize("mapped", [False, True])
@pytest.mark.parametrize("band_position", [5.0, 0.3, -0.7])
def test_contact_gradient_matches_differences_of_the_energy(band_position, mapped):
    energy_gradient, _ = _contact_pair_terms(_contact_multiplier(band_position), mapped)
    nodes = _contact_nodes(mapped)
    _, gradient, _ = energy_gradient(nodes)
    h = 1e-10
    differences = np.empty(12)
    for k in range(12):
        x = nodes.ravel().copy()
        x[k] += h
        plus = energy_gradient(x.reshape(4, 3))[0]
        x[k] -= 2 * h
        differences[k] = (plus - energy_gradient(x.reshape(4, 3))[0]) / (2 * h)
    assert np.abs(gradient).max() > 0.0
    assert np.abs(gradient - differences).max() <= ENERGY_DIFFERENCE_RTOL * np.abs(gradient).max()


def test_parallel_contact_gradient_is_continuous():
    # Two parallel segments pressed together, one tilted by ±1e-6 rad about the contact normal's
    # perpendicular: the sampled contact's gradient changes by O(tilt), where the closest-point
    # gap's would flip its moment arm from one end to the other.
    def points(tilt):
        a = np.array([[0.0, 0.0, 0.0], [1e-4, 0.0, 0.0]])
        b = np.array([[0.0, 0.0, 1.9e-4], [1e-4, 0.0, 1.9e-4 + tilt * 1e-4]])
        return np.vstack([a, b])

    n = int(CONTACT_SAMPLES.sum())
    energy_gradient, _ = _contact_pair_terms(np.zeros(n))
    plus, minus = energy_gradient(points(1e-6))[1], energy_gradient(points(-1e-6))[1]
    assert np.abs(plus).max() > 0.0
    assert np.abs(plus - minus).max() <= PARALLEL_CONTINUITY * np.abs(plus).max()


def test_pair_out_of_reach_has_only_its_constant():
    """A pair whose segments are farther apart than every constraint's reach ((λ + δ) / k beyond
    contact) takes the kernel's shortcut: no force, energy −Σ M(λ) / k (the ramp integral of each
    multiplier, computed here by hand), gaps at most the true ones."""
    n = int(CONTACT_SAMPLES.sum())
    multiplier = np.linspace(0.0, 2e-3, n)
    energy_gradient, hessian = _contact_pair_terms(multiplier)
    delta = CONTACT_SMOOTHING * CONTACT_STIFFNESS * 2e-4
    reach = (multiplier.max() + delta) / CONTACT_STIFFNESS
    nodes = CONTACT_POINTS.copy()
    lowest_gap = _contact_kernels.segment_closest_points(*nodes)[2] - 2e-4
    nodes[2:, 2] += reach - lowest_gap + 1e-6  # lift the second edge just beyond reach
    energy, gradient, gap = energy_gradient(nodes)

    def ramp_integral(t):
        return np.where(t >= delta, 0.5 * t * t + delta * delta / 6.0, (t + delta) ** 3 / (12.0 * delta))

    assert energy == pytest.approx(-ramp_integral(multiplier).sum() / CONTACT_STIFFNESS, rel=1e-14)
    assert not gradient.any()
    assert not hessian(nodes).any()
    assert np.ptp(gap) == 0.0  # the shortcut writes the one lower bound for every constraint
    a0, a1, b0, b1 = nodes
    for c in range(n):  # every written gap is at most the sampled point's true gap
        if c < CONTACT_SAMPLES[0]:
            s = c / (CONTACT_SAMPLES[0] - 1)
            p, q0, q1 = a0 + s * (a1 - a0), b0, b1
        else:
            t = (c - CONTACT_SAMPLES[0]) / (CONTACT_SAMPLES[1] - 1)
            p, q0, q1 = b0 + t * (b1 - b0), a0, a1
        u = np.clip(np.dot(p - q0, q1 - q0) / np.dot(q1 - q0, q1 - q0), 0.0, 1.0)
        assert gap[c] <= np.linalg.norm(p - q0 - u * (q1 - q0)) - 2e-4 + 1e-15
        assert gap[c] > reach


def test_csc_assembly_matches_scipy_on_random_triplets():
    """The solver's CSC assembly sums duplicates, drops pinned DOFs and explicit zeros off the
    diagonal and stores every diagonal entry, as scipy's COO → CSC conversion (the reference) does
    once a zero diagonal is added and off-diagonal zeros are eliminated."""
    rng = np.random.default_rng(7)
    n_full, count = 40, 600
    rows = rng.integers(0, n_full, count + 10)
    cols = rng.integers(0, n_full, count + 10)
    vals = rng.normal(size=count + 10)
    vals[:50] = 0.0  # explicit zeros, on and off the diagonal
    rows[50:60], cols[50:60], vals[50:55], vals[55:60] = 3, 5, 1.5, -1.5  # a sum that cancels
    dof_map = np.full(n_full, -1)
    free = np.flatnonzero(rng.random(n_full) < 0.8)
    dof_map[free] = np.arange(free.size)
    indptr, indices, data, diagonal = _kernels.assemble_csc(rows, cols, vals, count, dof_map, free.size)
    r, c = dof_map[rows[:count]], dof_map[cols[:count]]
    keep = (r >= 0) & (c >= 0)
    reference = sp.coo_matrix((vals[:count][keep], (r[keep], c[keep])), shape=(free.size, free.size)).toarray()
    ours = sp.csc_matrix((data, indices, indptr), shape=(free.size, free.size))
    # Sums of the same few terms in another order: round-off only.
    np.testing.assert_allclose(ours.toarray(), reference, rtol=0.0, atol=ASSEMBLY_ATOL)
    assert np.all(np.diff(indptr) >= 1)
    assert all(np.all(np.diff(indices[indptr[j]:indptr[j + 1]]) > 0) for j in range(free.size))
    np.testing.assert_array_equal(indices[diagonal], np.arange(free.size))
    off = indices != np.repeat(np.arange(free.size), np.diff(indptr))
    assert np.all(data[off] != 0.0)


def test_fixed_pattern_assembly_matches_scipy_on_random_triplets():
    """The rods' triplets go into a fixed pattern (csc_slots once, scatter_add at every iterate) and
    the contacts' are added to it (add_csc): the sum is scipy's COO → CSC of all of them, with
    every diagonal entry stored and no explicit zero off it, also where a rod entry is zero now
    and where the two parts cancel."""
    rng = np.random.default_rng(11)
    n_full, n_rod, n_pair = 40, 500, 200
    rows, cols = rng.integers(0, n_full, n_rod), rng.integers(0, n_full, n_rod)
    p_rows, p_cols = rng.integers(0, n_full, n_pair), rng.integers(0, n_full, n_pair)
    dof_map = np.full(n_full, -1)
    free = np.flatnonzero(rng.random(n_full) < 0.8)
    dof_map[free] = np.arange(free.size)
    indptr, indices, slot = _kernels.csc_slots(rows, cols, n_rod, dof_map, free.size)
    data = np.empty(indices.size)
    r, c = dof_map[rows], dof_map[cols]
    keep = (r >= 0) & (c >= 0)
    assert np.all((slot >= 0) == keep)
    for trial in range(3):  # one pattern, new values each time
        vals = rng.normal(size=n_rod)
        vals[:40] = 0.0  # rod entries that are zero at this iterate
        p_vals = rng.normal(size=n_pair)
        p_rows[:5], p_cols[:5], p_vals[:5] = rows[keep][-1], cols[keep][-1], 0.0  # adds nothing ...
        p_rows[5], p_cols[5] = rows[keep][-2], cols[keep][-2]  # ... and cancels a rod entry
        same = (rows[keep] == rows[keep][-2]) & (cols[keep] == cols[keep][-2])
        p_vals[5] = -vals[keep][same].sum()
        _kernels.scatter_add(slot, vals, n_rod, data)
        pairs = _kernels.assemble_csc(p_rows, p_cols, p_vals, n_pair, dof_map, free.size)[:3]
        s_indptr, s_indices, s_data, diagonal = _kernels.add_csc(indptr, indices, data, *pairs)
        pr, pc = dof_map[p_rows], dof_map[p_cols]
        p_keep = (pr >= 0) & (pc >= 0)
        reference = (sp.coo_matrix((vals[keep], (r[keep], c[keep])), shape=(free.size, free.size))
                     + sp.coo_matrix((p_vals[p_keep], (pr[p_keep], pc[p_keep])), shape=(free.size, free.size)))
        ours = sp.csc_matrix((s_data, s_indices, s_indptr), shape=(free.size, free.size))
        np.testing.assert_allclose(ours.toarray(), reference.toarray(), rtol=0.0, atol=ASSEMBLY_ATOL)
        assert all(np.all(np.diff(s_indices[s_indptr[j]:s_indptr[j + 1]]) > 0) for j in range(free.size))
        np.testing.assert_array_equal(s_indices[diagonal], np.arange(free.size))
        off = s_indices != np.repeat(np.arange(free.size), np.diff(s_indptr))
        assert np.all(s_data[off] != 0.0)


def test_node_block_assembly_matches_scipy_on_random_groups():
    """The contact and friction Hessians' triplets (groups of 144: a 12 × 12 block over four nodes'
    positions, row-major) summed by node blocks are scipy's COO → CSC of the same triplets, also
    where a group names one node twice (a pair with its own image), groups share blocks, and
    pinned DOFs and the frames' DOFs (which no group touches) are in the map."""
    rng = np.random.default_rng(5)
    n_nodes, n_edges, n_groups = 12, 11, 30
    nodes = rng.integers(0, n_nodes, (n_groups, 4))
    nodes[0] = [3, 3, 5, 7]  # one node twice
    nodes[1] = nodes[2]  # the same blocks twice
    i = np.arange(12)
    rows = (3 * nodes[:, i // 3] + i % 3)[:, :, None].repeat(12, axis=2).reshape(-1)
    cols = (3 * nodes[:, i // 3] + i % 3)[:, None, :].repeat(12, axis=1).reshape(-1)
    vals = rng.normal(size=rows.size)
    n_full = 3 * (n_nodes + n_edges)
    dof_map = np.full(n_full, -1)
    free = np.flatnonzero(rng.random(n_full) < 0.8)
    dof_map[free] = np.arange(free.size)
    count = 144 * (n_groups - 1)  # the last group not counted
    indptr, indices, data = _kernels.assemble_node_blocks(rows, cols, vals, count, dof_map, free.size, n_nodes)
    r, c = dof_map[rows[:count]], dof_map[cols[:count]]
    keep = (r >= 0) & (c >= 0)
    reference = sp.coo_matrix((vals[:count][keep], (r[keep], c[keep])), shape=(free.size, free.size)).toarray()
    ours = sp.csc_matrix((data, indices, indptr), shape=(free.size, free.size))
    np.testing.assert_allclose(ours.toarray(), reference, rtol=0.0, atol=ASSEMBLY_ATOL)
    assert indptr[-1] == indices.size and np.all(np.diff(indptr) >= 0)
    assert all(np.all(np.diff(indices[indptr[j]:indptr[j + 1]]) > 0) for j in range(free.size))
