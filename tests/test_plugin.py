"""The yarnfit.shell MuJoCo plugin (compiled by `pip install -e .`), run inside MuJoCo: loading
through plain `import mujoco`, forces against an independent implementation of the same discrete
energy, against MuJoCo's own isotropic membrane, rigid motions, and bad configuration."""

import math
import warnings

import mujoco
import numpy as np
import pytest

# A fabric-like material (Pa, m): h s00 = 900 N/m, strong anisotropy and coupling.
MATERIAL = {"s00": 3.0e6, "s01": 6.0e5, "s11": 1.5e6, "s22": 2.0e5, "b00": 1.0e6, "b01": 1.0e5, "b11": 8.0e5,
            "b22": 2.0e5, "thickness": 3.0e-4}
# Central differences of a smooth energy at step 1e-7 m on 0.1 m cells: truncation ~1e-10
# relative, round-off ~ε W / (δ |∇W|) ~ 1e-9; 1e-6 is the bound.
GRADIENT_RTOL = 1e-6
# Same formula evaluated by two codes: a few ulps per term, summed over a handful of triangles.
ROUND_OFF_RTOL = 1e-12
FD_STEP = 1e-7  # m
# Force on a vertex of an unstrained sheet (N): round-off of ε ~ 1e-16 times s h × cell ~ 1e2 N is
# ~1e-14; 1e-9 is far below the ~10 N a 1 % strain gives.
UNSTRAINED_FORCE_ATOL = 1e-9


def scene(material=MATERIAL, angle=0.0, count="5 4 1", dim=2, builtin=None, plugin=True, extra=None) -> str:
    config = "".join(f'<config key="{k}" value="{v!r}"/>' for k, v in {**material, **(extra or {})}.items())
    if angle:
        config += f'<config key="angle" value="{angle!r}"/>'
    inner = f'<plugin plugin="yarnfit.shell">{config}</plugin>' if plugin else ""
    if builtin:
        inner += builtin
    extension = '<extension><plugin plugin="yarnfit.shell"/></extension>' if plugin else ""
    return (f'<mujoco>{extension}<option gravity="0 0 0"/><worldbody>'
            f'<flexcomp name="cloth" type="grid" count="{count}" spacing="0.1 0.08 0.1" dim="{dim}" radius="0.001" '
            f'mass="0.1">{inner}</flexcomp></worldbody></mujoco>')


def elasticity(young, poisson, thickness, elastic2d="stretch", damping=0.0) -> str:
    return (f'<elasticity young="{young!r}" poisson="{poisson!r}" thickness="{thickness!r}" elastic2d="{elastic2d}" '
            f'damping="{damping!r}"/>')


def builtin_keys(young, poisson, thickness) -> dict:
    return {"builtin_young": young, "builtin_poisson": poisson, "builtin_thickness": thickness}


def forces(model, qpos, qvel=None):
    data = mujoco.MjData(model)
    data.qpos[:] = qpos
    if qvel is not None:
        data.qvel[:] = qvel
    mujoco.mj_forward(model, data)
    return data.qfrc_passive.copy(), data.flexvert_xpos.copy()


def vertex_forces(model, qfrc):
    """(V, 3) vertex forces: every vertex is a body with three world-aligned slide joints."""
    return np.stack([qfrc[model.body_dofadr[b]:model.body_dofadr[b] + 3] for b in model.flex_vertbodyid])


class ReferenceShell:
    """The plugin's discrete energy, written independently in numpy: per triangle
    A0 (h/2) εᵀ S ε + A0 (h³/2) κᵀ B κ (with ``b00_neg``, ``b11_neg`` in the material, B's
    diagonal on the side of each κ's sign), with κ from the signed dihedral angles θ of the triangle's
    edges. A triangle whose three edges are interior solves θ_e = r_eᵀ κ for κ, r_e the hinge
    angle a quadratic surface of constant curvature κ makes across edge e (the jump of its linear
    interpolant's slope, from the two opposite vertices' positions along and off the edge): exact
    for any such surface on any mesh. A boundary triangle (or one whose 3 × 3 map has condition
    number above 1e4) bends with the κ of its first neighbour that solved its own; with none, with
    II = Σ θ l/(2 A0) n nᵀ over its interior edges (rest edge length l, in-plane edge normal n),
    the same map as the solved one on a regular grid. Rest shape at qpos0, weft = world x in
    the sheet's plane turned by ``angle``; or, given ``corner_uv (T, 3, 2)``, each triangle's own
    rest corners (a garment's pattern, weft along the first axis turned by ``angle``), a hinge's
    far vertex placed by its own triangle's rest distances from the shared edge."""

    def __init__(self, model, material, angle=0.0, corner_uv=None, domains=None):
        self.tri = model.flex_elem.reshape(-1, 3)
        # membrane="node": each triangle corner's smoothing domain (T, 3), or None for triangles.
        self.domains = None if domains is None else np.asarray(domains)
        c, s = math.cos(angle), math.sin(angle)
        if corner_uv is None:
            rest = forces(model, model.qpos0)[1]
            a, b = rest[self.tri[0, 1]] - rest[self.tri[0, 0]], rest[self.tri[0, 2]] - rest[self.tri[0, 0]]
            normal = np.cross(a, b) / np.linalg.norm(np.cross(a, b))
            ref = np.array([1.0, 0.0, 0.0])
            axis0 = ref - (ref @ normal) * normal
            axis0 /= np.linalg.norm(axis0)
            axis1 = np.cross(normal, axis0)
            axes = np.array([c * axis0 + s * axis1, -s * axis0 + c * axis1])
            self.corner = (rest @ axes.T)[self.tri]  # (T, 3, 2) material coordinates
        else:
            self.corner = np.asarray(corner_uv, float) @ np.array([[c, -s], [s, c]])
        h = material["thickness"]
        self.S = h * np.array([[material["s00"], material["s01"], 0], [material["s01"], material["s11"], 0],
                               [0, 0, material["s22"]]])
        self.B = h**3 * np.array([[material["b00"], material["b01"], 0], [material["b01"], material["b11"], 0],
                                  [0, 0, material["b22"]]])
        # The signed bending's negative sides (the positive ones are b00, b11), as B's diagonal.
        self.negative = h**3 * np.array([material.get("b00_neg", material["b00"]),
                                         material.get("b11_neg", material["b11"])])
        self.area = np.array([0.5 * abs(np.linalg.det(np.column_stack([r[1] - r[0], r[2] - r[0]])))
                              for r in self.corner])
        # Interior edges: the two triangles on each, oriented by the first.
        sides = {}
        for i, t in enumerate(self.tri):
            for k in range(3):
                sides.setdefault(frozenset((t[k], t[(k + 1) % 3])), []).append((i, t[k], t[(k + 1) % 3], t[(k + 2) % 3]))
        self.hinges = [(s[0][1], s[0][2], s[0][3], s[1][3], s[0][0], s[1][0]) for s in sides.values() if len(s) == 2]
        # Per triangle: κ = map @ θ over its hinges; a triangle that cannot solve its own angles
        # bends with the first neighbour (in its edge order) that can, else with the grid map.
        hinge_of = {frozenset((x1, x2)): h for h, (x1, x2, *_) in enumerate(self.hinges)}
        own = []
        for t, tri in enumerate(self.tri):
            hinges = [hinge_of.get(frozenset((tri[k], tri[(k + 1) % 3]))) for k in range(3)]
            present = [(k, h) for k, h in enumerate(hinges) if h is not None]
            grid = np.array([self.grid_row(self.hinges[h][0], self.hinges[h][1], t) for _, h in present]).T
            operator, solved = grid, False
            if len(present) == 3:
                rows = np.array([self.exact_row(t, h, tri[k], tri[(k + 1) % 3], tri[(k + 2) % 3]) for k, h in present])
                if np.linalg.cond(rows, np.inf) <= 1e4:
                    operator, solved = np.linalg.inv(rows), True
            own.append(([h for _, h in present], operator, solved))
        self.kappa_maps = []
        for t, (hinges, operator, solved) in enumerate(own):
            source = t
            if not solved:
                for h in hinges:  # in the triangle's edge order
                    x1, x2, o0, o1, ta, tb = self.hinges[h]
                    other = tb if ta == t else ta
                    if own[other][2]:
                        source = other
                        break
            self.kappa_maps.append(own[source][:2])

    def point(self, t, v):
        """Rest material coordinates of vertex ``v`` in triangle ``t``'s frame."""
        return self.corner[t][list(self.tri[t]).index(v)]

    def grid_row(self, x1, x2, t):
        """dκ/dθ of the grid operator: l/(2 A) (n0², n1², 2 n0 n1)."""
        rest_edge = self.point(t, x2) - self.point(t, x1)
        length = np.linalg.norm(rest_edge)
        n = np.array([rest_edge[1], -rest_edge[0]]) / length
        return length / (2 * self.area[t]) * np.array([n[0]**2, n[1]**2, 2 * n[0] * n[1]])

    def exact_row(self, tri, h, x1, x2, own):
        """r with θ = r · κ across edge x1 x2 (hinge ``h``) of triangle ``tri`` whose third vertex is
        ``own``, for z = ½ pᵀ II p, II from κ = (II00, II11, 2 II01): the slope jump of the linear
        interpolants, along the normal from ``own``'s side, is
        ½ [II_nn (d_own + d_other) + II_tt Σ (s² − l²/4)/d + 2 II_tn (s_other − s_own)], s along
        x1 → x2 from the edge's middle and d off it, each side's in its own triangle's rest frame."""
        _, _, o0, o1, ta, tb = self.hinges[h]
        other, tri_other = (o1, tb) if ta == tri else (o0, ta)

        def along_off(t, v):
            p1, p2 = self.point(t, x1), self.point(t, x2)
            tangent = (p2 - p1) / np.linalg.norm(p2 - p1)
            r = self.point(t, v) - 0.5 * (p1 + p2)
            return r @ tangent, abs(r[0] * tangent[1] - r[1] * tangent[0])

        p1, p2 = self.point(tri, x1), self.point(tri, x2)
        length = np.linalg.norm(p2 - p1)
        t = (p2 - p1) / length
        middle = 0.5 * (p1 + p2)
        n = np.array([-t[1], t[0]])
        if n @ (self.point(tri, own) - middle) > 0:
            n = -n
        (s_own, d_own), (s_other, d_other) = along_off(tri, own), along_off(tri_other, other)
        quarter = length**2 / 4
        c_nn = 0.5 * (d_own + d_other)
        c_tt = 0.5 * ((s_own**2 - quarter) / d_own + (s_other**2 - quarter) / d_other)
        c_tn = s_other - s_own

        def entries(u, v):  # u_i II_ij v_j as a row acting on κ
            return np.array([u[0] * v[0], u[1] * v[1], 0.5 * (u[0] * v[1] + u[1] * v[0])])

        return c_nn * entries(n, n) + c_tt * entries(t, t) + c_tn * entries(t, n)

    def strains(self, x):
        """(T, 3) membrane strains ε and (T, 3) bending strains κ at positions x (V, 3)."""
        eps = np.zeros((len(self.tri), 3))
        for i, t in enumerate(self.tri):
            r = self.corner[i]
            D = np.column_stack([r[1] - r[0], r[2] - r[0]])
            F = np.column_stack([x[t[1]] - x[t[0]], x[t[2]] - x[t[0]]]) @ np.linalg.inv(D)
            E = 0.5 * (F.T @ F - np.eye(2))
            eps[i] = E[0, 0], E[1, 1], 2 * E[0, 1]
        theta = np.zeros(len(self.hinges))
        for h, (x1, x2, o0, o1, ta, tb) in enumerate(self.hinges):
            edge = x[x2] - x[x1]
            na, nb = np.cross(edge, x[o0] - x[x1]), np.cross(x[o1] - x[x1], edge)
            na, nb = na / np.linalg.norm(na), nb / np.linalg.norm(nb)
            theta[h] = math.atan2(np.cross(nb, na) @ edge / np.linalg.norm(edge), na @ nb)
        kappa = np.zeros((len(self.tri), 3))
        for t, (hinges, operator) in enumerate(self.kappa_maps):
            if hinges:
                kappa[t] = operator @ theta[hinges]
        return eps, kappa

    def energy(self, x):
        eps, kappa = self.strains(x)
        B = np.repeat(self.B[None], len(kappa), axis=0)
        for k in range(2):
            B[:, k, k] = np.where(kappa[:, k] >= 0, self.B[k, k], self.negative[k])
        bending = 0.5 * float(self.area @ np.einsum("ti,tij,tj->t", kappa, B, kappa))
        if self.domains is None:
            return 0.5 * float(self.area @ np.einsum("ti,ij,tj->t", eps, self.S, eps)) + bending
        # Node-smoothed membrane: ε_d = Σ over the domain's corners of (A_t/3)/A_d ε_t (the
        # triangles' Green strains), energy A_d ½ ε_dᵀ S ε_d per domain.
        share = np.zeros(self.domains.max() + 1)
        np.add.at(share, self.domains.ravel(), np.repeat(self.area / 3, 3))
        smoothed = np.zeros((len(share), 3))
        for k in range(3):
            np.add.at(smoothed, self.domains[:, k], (self.area / 3 / share[self.domains[:, k]])[:, None] * eps)
        return 0.5 * float(share @ np.einsum("di,ij,dj->d", smoothed, self.S, smoothed)) + bending


def central_gradient(function, x, step=FD_STEP):
    gradient = np.zeros_like(x)
    for v in range(len(x)):
        for i in range(3):
            delta = np.zeros_like(x)
            delta[v, i] = step
            gradient[v, i] = (function(x + delta) - function(x - delta)) / (2 * step)
    return gradient


@pytest.fixture(scope="module")
def model():
    return mujoco.MjModel.from_xml_string(scene())


def test_plain_import_mujoco_finds_the_plugin(model):
    assert model.nplugin == 1
    assert repr(MATERIAL["s00"]).encode() in model.plugin_attr.tobytes()


@pytest.mark.parametrize("angle", [0.0, 0.4])
def test_forces_are_minus_the_gradient_of_the_energy(angle):
    model = mujoco.MjModel.from_xml_string(scene(angle=angle))
    rng = np.random.default_rng(7)
    # Out-of-plane noise of a few cells' curvature: bending and membrane forces both matter.
    qpos = model.qpos0 + 0.01 * rng.standard_normal(model.nq)
    qfrc, x = forces(model, qpos)
    reference = ReferenceShell(model, MATERIAL, angle)
    gradient = central_gradient(reference.energy, x)
    np.testing.assert_allclose(vertex_forces(model, qfrc), -gradient, rtol=0,
                               atol=GRADIENT_RTOL * np.abs(gradient).max())
    # The bending part alone is checked too: it is much smaller than the membrane's forces.
    soft = {**MATERIAL, "s00": 1e-6, "s01": 0.0, "s11": 1e-6, "s22": 1e-6}
    model = mujoco.MjModel.from_xml_string(scene(soft, angle=angle))
    qfrc, x = forces(model, qpos)
    gradient = central_gradient(ReferenceShell(model, soft, angle).energy, x)
    assert np.abs(gradient).max() > 1e-5  # N: the bend is real (~7e-4 N here), not round-off
    np.testing.assert_allclose(vertex_forces(model, qfrc), -gradient, rtol=0,
                               atol=GRADIENT_RTOL * np.abs(gradient).max())


def mesh_model(points, triangles, material=MATERIAL) -> mujoco.MjModel:
    """A free sheet on any triangle mesh (``points (V, 3)`` m, ``triangles (T, 3)``): one body with
    three world-axis slide joints per vertex and the plugin carrying the whole material."""
    spec, _ = mesh_spec(points, triangles, {key: repr(value) for key, value in material.items()})
    return compile_sheet(spec)


def mesh_spec(points, triangles, config: dict) -> tuple[mujoco.MjSpec, mujoco.MjsFlex]:
    """The spec of :func:`mesh_model` with the plugin's ``config`` (key → text) and its flex
    ``sheet``, for callers that add to it before :func:`compile_sheet`."""
    spec = mujoco.MjSpec()
    spec.option.gravity = [0, 0, 0]
    spec.activate_plugin("yarnfit.shell")
    plugin = spec.add_plugin(name="shell", plugin_name="yarnfit.shell", active=True)
    plugin.config = config
    names = []
    for v, point in enumerate(points):
        body = spec.worldbody.add_body(name=f"v{v}", pos=point)
        body.explicitinertial = True
        body.mass, body.ipos, body.iquat, body.inertia = 1e-3, [0, 0, 0], [1, 0, 0, 0], [1e-9] * 3
        for axis in np.eye(3):
            body.add_joint(type=mujoco.mjtJoint.mjJNT_SLIDE, axis=axis)
        body.plugin = plugin
        names.append(body.name)
    flex = spec.add_flex(name="sheet", dim=2, radius=1e-3, vertbody=names, vert=np.zeros(3 * len(points)),
                         elem=np.asarray(triangles).ravel())
    return spec, flex


def compile_sheet(spec: mujoco.MjSpec) -> mujoco.MjModel:
    with warnings.catch_warnings():  # MuJoCo 4.0's "not rigid ... no passive forces": it has the plugin's
        warnings.filterwarnings("ignore", message=r"flex '.*' is not rigid")
        return spec.compile()


@pytest.mark.parametrize("mesh", ["crisscross", "disc"])
def test_bending_on_irregular_meshes_is_minus_the_gradient_of_the_consistent_operator(mesh):
    """On criss-cross cells and an unstructured disc the triangles bend with the consistent
    operator (it differs from the grid one there): the plugin's forces are minus the gradient of
    the reference energy, which solves each interior triangle's three hinge angles for κ."""
    from yarnfit.mujoco.scenes import disc_mesh, grid_mesh

    points, triangles = grid_mesh(4, 4, 0.12, 0.1, crisscross=True) if mesh == "crisscross" else disc_mesh(0.05, 0.02)
    soft = {**MATERIAL, "s00": 1e-6, "s01": 0.0, "s11": 1e-6, "s22": 1e-6}
    model = mesh_model(points, triangles, soft)
    reference = ReferenceShell(model, soft)
    consistent = [t for t, (hinges, _) in enumerate(reference.kappa_maps) if len(hinges) == 3]
    assert consistent  # the case the grid operator does not cover
    qpos = model.qpos0 + 0.005 * np.random.default_rng(2).standard_normal(model.nq)
    qfrc, x = forces(model, qpos)
    gradient = central_gradient(reference.energy, x)
    assert np.abs(gradient).max() > 1e-5  # N: a real bend
    np.testing.assert_allclose(vertex_forces(model, qfrc), -gradient, rtol=0,
                               atol=GRADIENT_RTOL * np.abs(gradient).max())


# A signed bending (b00_neg, b11_neg): each side several times the other's, as a jersey's are.
SIGNED = {"b00_neg": 4.0e6, "b11_neg": 2.0e5}


def test_signed_bending_is_minus_the_gradient_of_its_energy():
    """With ``b00_neg`` and ``b11_neg`` the stiffness along weft and warp depends on the sign of
    each triangle's curvature: the forces are minus the gradient of the reference energy that
    picks B's diagonal by those signs, on a criss-cross mesh bent both ways in both directions."""
    from yarnfit.mujoco.scenes import grid_mesh

    points, triangles = grid_mesh(5, 5, 0.12, 0.1, crisscross=True)
    soft = {**MATERIAL, **SIGNED, "s00": 1e-6, "s01": 0.0, "s11": 1e-6, "s22": 1e-6}
    model = mesh_model(points, triangles, soft)
    reference = ReferenceShell(model, soft)
    qpos = model.qpos0 + 0.005 * np.random.default_rng(3).standard_normal(model.nq)
    qfrc, x = forces(model, qpos)
    kappa = reference.strains(x)[1]
    bent = np.any(kappa != 0, axis=1)
    for k in range(2):  # both sides of both directions are in it
        assert np.any(kappa[bent, k] > 0) and np.any(kappa[bent, k] < 0)
    gradient = central_gradient(reference.energy, x)
    np.testing.assert_allclose(vertex_forces(model, qfrc), -gradient, rtol=0,
                               atol=GRADIENT_RTOL * np.abs(gradient).max())
    # ... and the signs matter: the symmetric bending's forces differ.
    symmetric, _ = forces(mesh_model(points, triangles, {**soft, "b00_neg": soft["b00"], "b11_neg": soft["b11"]}),
                          qpos)
    assert np.abs(qfrc - symmetric).max() > 0.1 * np.abs(qfrc).max()


@pytest.mark.parametrize("extra, message", [
    ({"b00_neg": -1.0}, r"config key 'b00_neg' must be positive, got -1"),
    ({"b11_neg": 0.0}, r"config key 'b11_neg' must be positive, got 0"),
    ({"b11_neg": math.nan}, r"config key 'b11_neg' must be a finite number, got 'nan'"),
    # b01² = 1e10 < b00·b11 = 8e11, but not below min(b00, b00_neg)·min(b11, b11_neg) = 1e6 · 5e3.
    ({"b11_neg": 5e3}, r"signed bending is not convex: b01\^2 = 1e\+10 >= min\(b00, b00_neg\)\*min\(b11, b11_neg\)"),
])
def test_bad_signed_bending_fails_compilation_naming_the_key(extra, message):
    from yarnfit.mujoco.scenes import grid_mesh

    points, triangles = grid_mesh(3, 3, 0.1, 0.1)
    with pytest.raises(ValueError, match=message):
        mesh_model(points, triangles, {**MATERIAL, **extra})


def test_damping_is_the_stiffness_proportional_strain_rate_stress():
    """With damping β the forces gain −β (Jεᵀ A S Jε + Jκᵀ A B Jκ) v: the stress of the strain
    rate. Reference: the strain rates J v and then Jᵀ(A S J v) by central differences of the
    reference strains."""
    beta = 0.01  # s
    model = mujoco.MjModel.from_xml_string(scene(extra={"damping": beta}))
    rng = np.random.default_rng(11)
    qpos = model.qpos0 + 0.01 * rng.standard_normal(model.nq)
    qvel = rng.standard_normal(model.nv)
    damped, x = forces(model, qpos, qvel)
    elastic, _ = forces(model, qpos)
    reference = ReferenceShell(model, MATERIAL)
    v = vertex_forces(model, qvel)
    step = 1e-6
    plus, minus = reference.strains(x + step * v), reference.strains(x - step * v)
    eps_rate, kappa_rate = ((p - m) / (2 * step) for p, m in zip(plus, minus))
    stress = reference.area[:, None] * (eps_rate @ reference.S)
    moment = reference.area[:, None] * (kappa_rate @ reference.B)

    def work(y):
        eps, kappa = reference.strains(y)
        return float(np.sum(stress * eps) + np.sum(moment * kappa))

    expected = -beta * central_gradient(work, x)
    np.testing.assert_allclose(vertex_forces(model, damped - elastic), expected, rtol=0,
                               atol=GRADIENT_RTOL * np.abs(expected).max())
    assert float(np.sum(vertex_forces(model, damped - elastic) * v)) < 0  # it dissipates


def test_isotropic_coefficients_give_mujocos_own_membrane():
    """MuJoCo's built-in stretch elasticity carries the isotropic membrane; the plugin, told so by
    its builtin_* keys, carries exactly nothing of it and only its bending. Same forces as the
    plugin carrying both: the two membranes agree to round-off."""
    E, nu, h = 2.0e6, 0.3, 3.0e-4
    s00 = E / (1 - nu**2)
    isotropic = {**MATERIAL, "s00": s00, "s01": nu * s00, "s11": s00, "s22": E / (2 * (1 + nu)), "thickness": h}
    ours = mujoco.MjModel.from_xml_string(scene(isotropic))
    theirs = mujoco.MjModel.from_xml_string(scene(isotropic, builtin=elasticity(E, nu, h),
                                                  extra=builtin_keys(E, nu, h)))
    qpos = ours.qpos0 + 0.01 * np.random.default_rng(3).standard_normal(ours.nq)
    a, b = forces(ours, qpos)[0], forces(theirs, qpos)[0]
    np.testing.assert_allclose(a, b, rtol=0, atol=ROUND_OFF_RTOL * np.abs(b).max())


@pytest.mark.parametrize("builtin", [(1.0e5, 0.0, 3.0e-4), (4.0e6, 0.45, 2.0e-4)])
def test_with_builtin_elasticity_the_total_is_the_configured_material(builtin):
    """The built-in isotropic part (smaller or larger than the material) plus the plugin's
    remainder give the forces of the configured material alone."""
    alone = mujoco.MjModel.from_xml_string(scene())
    split = mujoco.MjModel.from_xml_string(scene(builtin=elasticity(*builtin), extra=builtin_keys(*builtin)))
    qpos = alone.qpos0 + 0.01 * np.random.default_rng(5).standard_normal(alone.nq)
    a, b = forces(alone, qpos)[0], forces(split, qpos)[0]
    np.testing.assert_allclose(b, a, rtol=0, atol=ROUND_OFF_RTOL * np.abs(a).max())


@pytest.mark.parametrize("elastic2d", ["bend", "both"])
@pytest.mark.parametrize("builtin_damping", [0.0, 0.01, 0.05])
def test_with_builtin_bending_the_total_bending_is_the_plugins(elastic2d, builtin_damping):
    """MuJoCo's built-in bending (a hinge operator linear in the positions, integrated implicitly)
    is removed by the plugin exactly: elastic and damping forces equal the plugin's alone, whatever
    the built-in part's modulus, thickness and damping time (only the plugin's damping counts)."""
    beta = 0.01  # s, the plugin's
    alone = mujoco.MjModel.from_xml_string(scene(extra={"damping": beta}))
    E, nu, t = 4.0e6, 0.45, 2.0e-4
    keys = builtin_keys(E, nu, t) if elastic2d == "both" else {}
    split = mujoco.MjModel.from_xml_string(scene(builtin=elasticity(E, nu, t, elastic2d, builtin_damping),
                                                 extra={**keys, "damping": beta}))
    assert split.flex_bendingadr[0] >= 0 and np.abs(split.flex_bending).max() > 0
    rng = np.random.default_rng(7)
    qpos = alone.qpos0 + 0.01 * rng.standard_normal(alone.nq)
    qvel = rng.standard_normal(alone.nv)
    a, b = forces(alone, qpos)[0], forces(split, qpos)[0]
    np.testing.assert_allclose(b, a, rtol=0, atol=ROUND_OFF_RTOL * np.abs(a).max())
    if elastic2d == "bend":  # with built-in stretch the membrane's damping is MuJoCo's own form
        a, b = forces(alone, qpos, qvel)[0], forces(split, qpos, qvel)[0]
        np.testing.assert_allclose(b, a, rtol=0, atol=ROUND_OFF_RTOL * np.abs(a).max())


def test_rest_and_rigid_motions_carry_no_force(model):
    qfrc, _ = forces(model, model.qpos0)
    assert np.abs(qfrc).max() < UNSTRAINED_FORCE_ATOL
    rotation = np.array([[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]]) @ np.array(
        [[1.0, 0.0, 0.0], [0.0, math.cos(0.7), -math.sin(0.7)], [0.0, math.sin(0.7), math.cos(0.7)]])
    rest = np.array([model.body_pos[b] for b in model.flex_vertbodyid])
    qpos = (rest @ rotation.T + [0.1, -0.2, 0.3] - rest).ravel()
    qfrc, _ = forces(model, qpos)
    assert np.abs(qfrc).max() < UNSTRAINED_FORCE_ATOL


BAD = {
    "negative": ({**MATERIAL, "s11": -1.0}, "config key 's11' must be positive"),
    "not a number": ({**MATERIAL, "b22": "soft"}, "config key 'b22' must be a finite number"),
    "infinite": ({**MATERIAL, "thickness": "inf"}, "config key 'thickness' must be a finite number"),
    "indefinite S": ({**MATERIAL, "s01": 3.0e6}, "membrane matrix S is not positive definite"),
    "indefinite B": ({**MATERIAL, "b01": -1.0e6}, "bending matrix B is not positive definite"),
    "missing key": ({k: v for k, v in MATERIAL.items() if k != "s22"}, "config key 's22' is required"),
    "negative damping": ({**MATERIAL, "damping": -0.1}, "config key 'damping' must be >= 0"),
}
# Built-in elasticity and the builtin_* keys out of step: (extra keys, <elasticity>, message).
BAD_SPLIT = {
    "keys differ": (builtin_keys(1.0e6, 0.3, 3.0e-4), elasticity(1.0e6, 0.2, 3.0e-4), "do not match flex 0"),
    "keys missing": ({}, elasticity(1.0e6, 0.3, 3.0e-4), "carries built-in stretch elasticity"),
    "no elasticity": (builtin_keys(1.0e6, 0.3, 3.0e-4), None, "has no built-in stretch elasticity"),
    "poisson out of range": (builtin_keys(1.0e6, 0.5, 3.0e-4), elasticity(1.0e6, 0.3, 3.0e-4),
                             "'builtin_poisson' must lie in"),
    "half given": ({"builtin_young": 1.0e6}, elasticity(1.0e6, 0.0, 3.0e-4), "must both be given"),
}


@pytest.mark.parametrize("case", sorted(BAD))
def test_bad_configuration_fails_compilation_naming_the_problem(case):
    material, message = BAD[case]
    with pytest.raises(ValueError, match=message):
        mujoco.MjModel.from_xml_string(scene(material))


@pytest.mark.parametrize("case", sorted(BAD_SPLIT))
def test_builtin_elasticity_must_match_the_keys(case):
    keys, builtin, message = BAD_SPLIT[case]
    with pytest.raises(ValueError, match=message):
        mujoco.MjModel.from_xml_string(scene(builtin=builtin, extra=keys))


def test_a_curved_rest_mesh_fails_compilation():
    """A flexcomp cylinder: its triangles leave the plane of the first one."""
    config = "".join(f'<config key="{k}" value="{v!r}"/>' for k, v in MATERIAL.items())
    xml = ('<mujoco><extension><plugin plugin="yarnfit.shell"/></extension><worldbody>'
           '<flexcomp name="tube" type="cylinder" count="8 8 3" spacing="0.1 0.1 0.1" dim="2" radius="0.001" mass="0.1">'
           f'<plugin plugin="yarnfit.shell">{config}</plugin></flexcomp></worldbody></mujoco>')
    with pytest.raises(ValueError, match="is not flat at qpos0"):
        mujoco.MjModel.from_xml_string(xml)


def test_a_plugin_on_a_1d_flex_fails_compilation():
    with pytest.raises(ValueError, match="needs a 2D flex"):
        mujoco.MjModel.from_xml_string(scene(count="6 1 1", dim=1))
