// yarnfit.shell: an orthotropic StVK shell for 2D MuJoCo flexes (mjPLUGIN_PASSIVE), with an optional
// strain-stiffening ridge membrane.
//
// Energy per reference area, in the material frame (weft = first axis, turned by `angle` from the
// flex's first reference axis), with the conventions of yarnfit's docs/design.md §3:
//
//   W = (h/2) eps^T S eps + (h^3/2) kappa^T B kappa,
//   eps = (E00, E11, 2 E01)       Green strain,          S = [[s00, s01, 0], [s01, s11, 0], [0, 0, s22]],
//   kappa = (II00, II11, 2 II01)  second fundamental form, B = [[b00, b01, 0], [b01, b11, 0], [0, 0, b22]].
//
// Signed bending (optional keys `b00_neg`, `b11_neg`, Pa): b00 then applies where kappa0 >= 0 (the
// sheet curving towards its triangles' normal along weft) and b00_neg where kappa0 < 0, b11 and
// b11_neg the same along warp: W_b = (h^3/2) (b00(kappa0) kappa0^2 + 2 b01 kappa0 kappa1 +
// b11(kappa1) kappa1^2 + b22 kappa2^2), C1 (the jump multiplies kappa0 = 0), convex when b01^2 <
// min(b00, b00_neg) min(b11, b11_neg). Absent, each equals b00 (b11): the quadratic above. The side
// is chosen by the elastic curvature; damping uses that side's stiffness.
//
// Membrane: per linear triangle, constant deformation gradient F (3x2) from the rest edges.
// Bending: per triangle, a curvature kappa_t from the dihedral angles theta_e of its three edges
// (hinges shared with the neighbouring triangles). A constant-curvature surface makes, across edge
// e, theta_e = r_e . kappa exactly (to first order in the angles): the jump of its linear
// interpolants' slope, from the two opposite vertices' rest positions along and off the edge. init
// inverts each triangle's three rows (the consistent operator: exact for every constant curvature
// on any mesh); a triangle with a free edge bends with an interior neighbour's kappa; with none,
// or an ill-conditioned map, it keeps the grid operator II_t = sum_e theta_e l_e / (2 A_t) n_e n_e^T
// (what the inverse is on a regular grid). See plugins/README.md.
//
// Ridge membrane (optional key `ridges`: whitespace-separated numbers, five per ridge j, n0 n1 n2
// t c = a unit direction n_j in Voigt strain space, a knot t_j >= 0 and a stiffness c_j in Pa;
// absent or empty: none). The membrane energy per reference area is then
//
//   W_m = h [ (1/2) eps^T S eps + sum_j (1/2) c_j max(n_j . eps - t_j, 0)^2 ],
//
// the stress gains h sum_j c_j max(n_j . eps - t_j, 0) n_j and the tangent h sum_j c_j [n_j . eps >
// t_j] n_j n_j^T. C1: the tangent jumps by c_j n_j n_j^T where n_j . eps crosses t_j. No hysteresis.
// Convex: c_j >= 0, or c_j < 0 (a tangent that falls at a knot) only past positive ones along the
// same direction, so that along every direction the tangent (the sum of c over knots <= x) stays >=
// 0 (check_ridge_tangents); with ridges S (yarnfit writes the ridge membrane's base there) need only
// be positive semi-definite (s00, s11, s22 >= 0, s01^2 <= s00 s11 up to 1e-12 relative round-off),
// without it must be positive definite.
//
// Damping (Kelvin-Voigt, stiffness-proportional, the Rayleigh form of the tangent stiffness):
// stresses use eps + damping * d(eps)/dt and kappa + damping * d(kappa)/dt for the quadratic
// energy; the ridges add damping * h (sum_j c_j [n_j . eps > t_j] n_j n_j^T) d(eps)/dt.
//
// Split with MuJoCo's built-in elasticity: the configuration is always the full material. When
// the flex also carries <elasticity elastic2d="stretch" young poisson thickness>, the keys
// builtin_young, builtin_poisson, builtin_thickness repeat it; init checks them against the
// compiled flex stiffness and the plugin adds only h S - t_b S_iso, so the total is h S (the ridges
// are the plugin's alone, on top of that share, and explicit: yarnfit sizes the built-in share to
// cover half the ridge membrane's largest tangent up to a strain bound). When it
// carries built-in bending too (elastic2d="both"), MuJoCo's hinge operator is linear in the vertex
// positions (f = -K x - beta K v per interior edge, K the 4x4 blocks of mjModel.flex_bending), so
// the plugin adds back exactly that force: the total bending is the plugin's own, to round-off,
// while MuJoCo integrates its isotropic share implicitly.
//
// Rest shape: rest="qpos0" (default) takes it from the flex at qpos0, which must be flat (one
// panel). rest="texcoord" takes each triangle's rest metric and material axes from the texture
// coordinates of its corners (flex texcoord + elemtexcoord: its material coordinates in its
// pattern panel, m), so a garment is one flex of several panels, each with its own grain, sewn by
// shared vertices; qpos0 is only where it starts. MuJoCo computed its built-in elasticity's rest
// from qpos0, so with rest="texcoord" the plugin removes MuJoCo's built-in membrane and bending
// forces exactly (its formulas, read from mjModel at every step, curved reference and damping
// included) and carries the whole material itself; the total is the configured material whatever
// the built-in part's rest. MuJoCo's implicit treatment of its own part still stabilises the step
// (its linearisation enters the step's matrix, not the force): yarnfit.mujoco.garment.
// use_pattern_rest rewrites that part's rest from the pattern, so that it too pulls towards it.
//
// Anisotropic implicit share (optional key implicit_share: six numbers c00 c01 c02 c11 c12 c22, the
// upper triangle of a symmetric positive-definite 3x3 C in Pa per the key thickness, in the
// material frame's Voigt strain (E00, E11, 2 E01)). MuJoCo 4's <elasticity> is isotropic, so a share
// stiff enough for a woven's yarns is as stiff in its shear (1e-3 ... 1e-5 of them) and holds its
// soft modes back (see Returned drag). MuJoCo reads each triangle's built-in membrane from
// mjModel.flex_stiffness at every step (its 3x3 metric over the triangle's edges, energy (1/4)
// Delta^T K Delta, Delta_a = l_a^2 - L_a^2), and that metric can hold any such C: K_ab = 2 A h g_a^T C
// g_b with g_a the Voigt Green strain per unit l_a^2. With the key, init writes that K into the
// flex's flex_stiffness (the <elasticity> then only sizes the bending share and allocates the
// metric), the plugin removes MuJoCo's membrane exactly and carries the whole material, and the
// implicit share follows the material's anisotropy. yarnfit writes C = half the largest tangent the
// membrane reaches within its strain bound, as it sizes the isotropic share.
//
// Returned drag (optional key implicit_drag: "full", the default, or "critical"). Under
// integrator="discrete" MuJoCo steps (M + h^2 K) a = f - h K v with K the built-in elasticity's
// stiffness: the isotropic share, stiff enough for the material's stiffest direction, is as stiff
// in the material's soft modes (a woven's shear, 1e-3 of it), where its drag h K v holds the cloth
// back for ~k_b / k_t steps. With "critical" the plugin adds back h K_r v, K_r <= K the part of the
// built-in membrane's drag that damping each mode critically on the step's inertia does not need
// (build_drag_return): the soft modes settle in ~sqrt(k_b / k_t) steps, the equilibrium unchanged.
// Never more than MuJoCo's drag, so the step stays stable; other integrators have no such drag and
// get nothing back.

#include <ctype.h>
#include <math.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include <mujoco/mujoco.h>

#define YF_NAME "yarnfit.shell"

// Doubles per element in mjModel.flex_stiffness for MuJoCo 4.0 (the upper triangle of a 6x6
// edge-edge matrix; a triangle uses its first 6 entries, measured against our own formula).
#define YF_STIFFNESS_STRIDE 21
// Doubles per edge in mjModel.flex_bending for 2D flexes in MuJoCo 4.0: the 4x4 hinge operator
// over (edge v0, edge v1, flap 0, flap 1), then the curved-reference coefficient (0 for a flat rest).
// Measured: qfrc_passive = -sum_e K_e x_e to 1e-16, and -damping K_e v_e for the damping force.
#define YF_BENDING_STRIDE 17
// Relative agreement demanded between the builtin_* keys and the compiled built-in stiffness:
// both are the same closed form in double precision, so they agree to ~1e-15; a mismatch a user
// makes (a different modulus or Poisson ratio) is far larger.
#define YF_BUILTIN_RTOL 1e-9
// Out-of-plane offset of a rest triangle's edges, relative to their length, still called flat:
// round-off of body frames composed at qpos0 is ~1e-16; a bent mesh is off by its angle.
#define YF_FLAT_RTOL 1e-9
// Largest condition number of a triangle's 3x3 map from its curvature to its three hinge angles
// that the consistent bending operator inverts; beyond it the triangle keeps the grid operator.
// Well-shaped triangles measure 2-20; a sliver's map is near singular.
#define YF_OPERATOR_CONDITION 1e4

// Largest | |n| - 1 | accepted for a ridge direction: yarnfit writes unit vectors with repr (off
// by ~1e-16); a direction off by more than this was not normalised by its writer. Same bound as
// yarnfit.shell.RIDGE_UNIT_RTOL.
#define YF_RIDGE_UNIT_TOL 1e-9
// Round-off admitted in the ridge membrane's semi-definite base, s01^2 <= s00 s11 (1 + this): a
// fitted base of rank one (a knit's) sits on the bound to ~1e-16. yarnfit.shell.RIDGE_BASE_RTOL.
#define YF_RIDGE_BASE_RTOL 1e-12
// Round-off admitted in the tangent along a ridge direction (the sum of the stiffnesses of its
// ridges up to a knot, which must stay >= 0), relative to their largest |c|: yarnfit fits the
// tangent per segment between knots and writes c as their differences, so a tangent fitted on its
// bound of 0 comes back as a sum of ~1e-16 relative errors. yarnfit.shell.RIDGE_CONVEXITY_RTOL.
#define YF_RIDGE_CONVEXITY_RTOL 1e-12
// Numbers per ridge in the `ridges` key: n0 n1 n2 t c.
#define YF_RIDGE_NUMBERS 5
// implicit_drag="critical": in a mode whose material stiffness is r times the built-in share's
// (r = k_t / k_b), MuJoCo's step keeps YF_CRITICAL_DRAG sqrt(r) of its drag h k_b (at most all of
// it). The step's inertia there is m + h^2 k_b, about h^2 k_b where the share is stiff, and the
// drag that damps k_t on that inertia critically is 2 sqrt(k_t h^2 k_b) = h k_b 2 sqrt(r).
#define YF_CRITICAL_DRAG 2.0
// ... and at least YF_LEAST_DRAG of it: a mode with no tangent at all (a ridge membrane, base S zero,
// strained where none of its ridges is engaged in some direction) keeps enough to lose its speed
// in ~1 / YF_LEAST_DRAG steps instead of drifting undamped. Measured on the cotton jersey's 2 x 5
// bias strip at 0.2 % (session 53): no floor, its force at rest within 1000 steps but a vertex
// still drifting at 1.5 times the rest speed after 4000; 0.02, at rest within 1000; 0.1, within
// 1000 but creeping slower after; full drag, at rest after ~5000. Modes with r < (0.02 / 2)^2 =
// 1e-4 are then overdamped (~0.02 / r steps, against 1 / r with the full drag).
#define YF_LEAST_DRAG 0.02

static const char* const kAttributes[] = {
  "s00", "s01", "s11", "s22", "b00", "b01", "b11", "b22", "thickness", "angle", "damping",
  "builtin_young", "builtin_poisson", "builtin_thickness", "ridges", "rest", "membrane", "b00_neg", "b11_neg",
  "implicit_drag", "implicit_share",
};
enum { kNumAttributes = sizeof(kAttributes) / sizeof(kAttributes[0]) };

// Per instance: material, the flex it drives, and rest data.
typedef struct {
  double s00, s01, s11, s22, b00, b01, b11, b22, thickness, angle, damping;
  double builtin_young, builtin_poisson, builtin_thickness;
  double b00_neg, b11_neg;  // signed bending: b00 and b11 where the curvature is negative (= b00, b11 if absent)
  int nridge;           // ridges of the ridge membrane: 0 (key absent or empty) keeps it exactly StVK
  double* ridge;        // (nridge x 5) n0 n1 n2 (unit, Voigt strain space), knot t, stiffness c (Pa), as read;
                        // init groups them (below) and frees this
  // The ridges grouped by direction (group_ridges), which is how compute reads them:
  int ndir;             // distinct directions
  double* dir;          // (ndir x 3) each direction n
  int* dir_start;       // (ndir + 1) direction d's ridges are knot[dir_start[d] .. dir_start[d + 1])
  double* knot;         // (nridge) knots t, ascending within a direction
  double* knot_c;       // (nridge) sum of c over the direction's ridges up to and including this one (Pa)
  double* knot_ct;      // (nridge) sum of c t likewise (Pa)
  int node_membrane;    // membrane="node": strains smoothed over each vertex's third of its
                        // triangles (per panel), not constant per triangle; see plugins/README.md
  int ndomain;          // node membrane: smoothing domains (a vertex, or a vertex and panel)
  int* corner_domain;   // (ntri x 3) the domain of each triangle corner
  double* domain_area;  // (ndomain) a third of each of its triangles' rest areas (m^2)
  double* tri_F;        // (ntri x 12) scratch: F0 F1 and their rates per triangle
  double* tri_eps;      // (ntri x 6) scratch: each triangle's Green strain and its rate
  double* domain_eps;   // (ndomain x 6) scratch: the smoothed strains and rates
  double* domain_sig;   // (ndomain x 3) scratch: dW/d(smoothed strain)
  int rest_texcoord;    // rest="texcoord": rest metric and material axes from the flex's texture
                        // coordinates per triangle corner (a garment's panels), not from qpos0
  // rest="texcoord": MuJoCo's built-in membrane on this flex (elastic2d "stretch" or "both"), which
  // compute removes exactly whatever its rest (MuJoCo computed it from qpos0 unless
  // yarnfit.mujoco.garment.use_pattern_rest rewrote it from the pattern):
  const mjtNum* builtin_metric;  // per triangle its 21 flex_stiffness entries, or NULL
  const int* builtin_elemedge;   // (ntri x 3) flex-local edges of each triangle, flex_elemedge order
  const mjtNum* builtin_length0; // (nedge) MuJoCo's rest edge lengths, flexedge_length0
  double* builtin_delta;         // (nedge) scratch: MuJoCo's elongation per edge
  int nedge;
  // implicit_drag="critical": the share of MuJoCo's step drag -h K v (integrator="discrete") that
  // compute gives back, per triangle in MuJoCo's edge space (see drag_returned):
  int has_share;                 // implicit_share given: init writes it into MuJoCo's metric
  double share[9];               // implicit_share's C (Pa, 3x3 row-major, material-frame Voigt)
  int critical_drag;             // 1 with implicit_drag="critical", 0 with "full" (default)
  const int* drag_elemedge;      // (ntri x 3) flex-local edges of each triangle, flex_elemedge order
  double* drag_basis;            // (ntri x 27) K_b^(1/2), K_b^(-1/2) (row-major) and g_0 g_1 g_2
  double* drag_returned;         // (ntri x 6) upper triangle of the returned metric K_r, or NULL
  uint64_t* drag_active;         // (ntri) signature of the ridges K_r was built with engaged
  uint64_t* tri_engaged;         // (ntri) with membrane="triangle": the signature of the ridges engaged
                                 // at each triangle's strain, as membrane_forces found them this step
  double* drag_rate;             // (nedge) scratch: d(l^2)/dt per edge
  double membrane[4];   // the plugin's membrane stiffness h S - t_b S_iso: c00 c01 c11 c22 (N/m)
  double bending[4];    // h^3 B: d00 d01 d11 d22 (N m)
  double bending_neg[2];  // h^3 b00_neg, h^3 b11_neg (N m): d00 and d11 where the curvature is negative
  int flex;
  int nvert;
  int ntri;
  int nhinge;
  int* tri;             // (ntri x 3) flex-local vertex ids
  double* rest_inv;     // (ntri x 4) inverse of the rest edge matrix [e1 e2] in the material frame
  double* area;         // (ntri) rest areas (m^2)
  int* hinge;           // (nhinge x 4) x1 x2 o0 o1: edge x1->x2 as its first triangle (x1 x2 o0) runs
  int* tri_hinge;       // (ntri x 3) hinge of each edge of a triangle, -1 on the boundary
  double* tri_weight;   // (ntri x 9) d kappa / d theta for each edge (the consistent operator, or
                        // on boundary triangles without a source the grid one l/(2A) n n)
  int* tri_source;      // (ntri) triangle whose curvature this one bends with: itself, or for a
                        // boundary triangle an interior neighbour's (constant curvature extrapolated)
  int* vert_dof;        // (nvert) last dof of the vertex body's kinematic chain, -1 if none
  unsigned char* slide_only;  // (nvert) 1 if that chain has only slide joints (Jacobian = axes)
  // Scratch for compute (plugin data is per mjData, so one thread each): kept off the mjData
  // stack, which a large cloth would overflow in a model with a small <size memory>.
  double* grad;         // (nvert x 3) energy gradient
  double* xdot;         // (nvert x 3) vertex velocities
  double* theta;        // (nhinge) dihedral angles
  double* theta_rate;   // (nhinge) damping * d(theta)/dt (zero without damping)
  double* torque;       // (nhinge) dW / d theta
  double* hinge_grad;   // (nhinge x 12) d theta / d (x1, x2, o0, o1)
  // MuJoCo's built-in bending on this flex (elastic2d "bend" or "both"), which compute removes:
  int nbuiltin_hinge;
  int* builtin_hinge;       // (nbuiltin_hinge x 4) flex-local vertices: edge v0 v1, flaps
  const double* builtin_k;  // per built-in hinge, its 16 operator entries (into mjModel.flex_bending)
  int* builtin_edge;        // (nbuiltin_hinge) flex-local edge of each, for builtin_k
  double builtin_damping;   // the flex's damping (s): MuJoCo's bending damping force is -damping K v
} Shell;

// Configuration errors use mju_error: during compilation (where MuJoCo first runs init) it becomes
// the compiler's error message, so the model fails to compile with a message naming the key; a
// returned -1 alone only says "plugin->init failed".

// Parse attribute `key` of instance `instance` as a finite number; fail with a message naming it.
static int read_number(const mjModel* m, int instance, const char* key, double fallback, int required,
                       double* out) {
  const char* text = mj_getPluginConfig(m, instance, key);
  if (!text || !text[0]) {
    if (required) {
      mju_error(YF_NAME ": config key '%s' is required", key);
      return -1;
    }
    *out = fallback;
    return 0;
  }
  char* end = NULL;
  double value = strtod(text, &end);
  while (end && (*end == ' ' || *end == '\t')) end++;
  if (end == text || (end && *end) || !isfinite(value)) {
    mju_error(YF_NAME ": config key '%s' must be a finite number, got '%s'", key, text);
    return -1;
  }
  *out = value;
  return 0;
}

// Parse attribute `key` of instance `instance`, one of two words: `first` (also when absent or
// empty) sets *out to 0, `second` to 1; anything else fails with a message naming both.
static int read_choice(const mjModel* m, int instance, const char* key, const char* first, const char* second,
                       int* out) {
  const char* text = mj_getPluginConfig(m, instance, key);
  if (!text || !text[0] || !strcmp(text, first)) {
    *out = 0;
  } else if (!strcmp(text, second)) {
    *out = 1;
  } else {
    mju_error(YF_NAME ": config key '%s' must be '%s' or '%s', got '%s'", key, first, second, text);
    return -1;
  }
  return 0;
}

// The next whitespace-separated token of *cursor: 0 at the end of the text; else 1, with *cursor
// moved past it, the token at *token (its first *length characters, at most 40, for a message) and
// its value in *value, *finite 0 unless it is a finite number.
static int next_number(const char** cursor, const char** token, int* length, double* value, int* finite) {
  const char* p = *cursor;
  while (*p && isspace((unsigned char)*p)) p++;
  *cursor = p;
  if (!*p) return 0;
  const char* stop = p;
  while (*stop && !isspace((unsigned char)*stop)) stop++;
  char* end = NULL;
  *value = strtod(p, &end);
  *finite = end == stop && isfinite(*value);
  *token = p;
  *length = (int)(stop - p > 40 ? 40 : stop - p);
  *cursor = stop;
  return 1;
}

// The implicit_share key: absent, empty or blank leaves *given 0; else six finite numbers c00 c01
// c02 c11 c12 c22 forming a positive-definite C (Pa), stored in out (3x3 row-major), *given 1.
static int read_share(const mjModel* m, int instance, double out[9], int* given) {
  const char* cursor = mj_getPluginConfig(m, instance, "implicit_share");
  const char* token;
  double value[6], v;
  int n = 0, length, finite;
  for (cursor = cursor ? cursor : ""; next_number(&cursor, &token, &length, &v, &finite); n++) {
    if (!finite) {
      mju_error(YF_NAME ": config key 'implicit_share': number %d of 6 (c00 c01 c02 c11 c12 c22) must be a "
                "finite number, got '%.*s'", n + 1, length, token);
      return -1;
    }
    if (n < 6) value[n] = v;
  }
  *given = n > 0;
  if (!n) return 0;
  if (n != 6) {
    mju_error(YF_NAME ": config key 'implicit_share' must hold six numbers (c00 c01 c02 c11 c12 c22, the upper "
              "triangle of a symmetric 3x3 in Pa), got %d", n);
    return -1;
  }
  const int upper[3][3] = {{0, 1, 2}, {1, 3, 4}, {2, 4, 5}};
  for (int i = 0; i < 3; i++) {
    for (int j = 0; j < 3; j++) out[3 * i + j] = value[upper[i][j]];
  }
  double eigenvalue[3], vector[9], quat[4];
  mju_eig3(eigenvalue, vector, quat, out);
  double least = fmin(eigenvalue[0], fmin(eigenvalue[1], eigenvalue[2]));
  if (!(least > 0)) {
    mju_error(YF_NAME ": config key 'implicit_share' must be positive definite (MuJoCo factorises the step's "
              "matrix with it), got least eigenvalue %g Pa", least);
    return -1;
  }
  return 0;
}

// The `ridges` key of instance `instance`: whitespace-separated numbers, five per ridge (n0 n1 n2 t
// c). With out == NULL, validate each ridge on its own (every number finite, n a unit vector, t >= 0;
// each failure an mju_error naming the key, the ridge and what is wrong) and set *count to the
// number of ridges (0 when the key is absent, empty or blank); else store them in out (count x 5),
// as validated by an earlier call. The signs of the stiffnesses are check_ridge_tangents' to judge.
static int read_ridges(const mjModel* m, int instance, double* out, int* count) {
  const char* cursor = mj_getPluginConfig(m, instance, "ridges");
  const char* token;
  int n = 0, length, finite;  // numbers read
  double ridge[YF_RIDGE_NUMBERS], value;
  for (cursor = cursor ? cursor : ""; next_number(&cursor, &token, &length, &value, &finite); ) {
    int j = n / YF_RIDGE_NUMBERS;
    if (!finite) {
      mju_error(YF_NAME ": config key 'ridges': ridge %d: number %d of 5 (n0 n1 n2 t c) must be a finite number, "
                "got '%.*s'", j, n % YF_RIDGE_NUMBERS + 1, length, token);
      return -1;
    }
    ridge[n % YF_RIDGE_NUMBERS] = value;
    if (++n % YF_RIDGE_NUMBERS) continue;
    if (out) {
      memcpy(out + YF_RIDGE_NUMBERS * j, ridge, sizeof(ridge));
      continue;
    }
    double norm = sqrt(ridge[0] * ridge[0] + ridge[1] * ridge[1] + ridge[2] * ridge[2]);
    if (!(fabs(norm - 1) <= YF_RIDGE_UNIT_TOL)) {
      mju_error(YF_NAME ": config key 'ridges': ridge %d: its direction n = (%.12g, %.12g, %.12g) must be a unit "
                "vector (within %g), got |n| = %.12g", j, ridge[0], ridge[1], ridge[2], YF_RIDGE_UNIT_TOL, norm);
      return -1;
    }
    if (ridge[3] < 0) {
      mju_error(YF_NAME ": config key 'ridges': ridge %d: its knot t must be >= 0, got %g", j, ridge[3]);
      return -1;
    }
  }
  if (n % YF_RIDGE_NUMBERS) {
    mju_error(YF_NAME ": config key 'ridges' must hold five numbers per ridge (n0 n1 n2 t c), got %d numbers: "
              "ridge %d has %d", n, n / YF_RIDGE_NUMBERS, n % YF_RIDGE_NUMBERS);
    return -1;
  }
  *count = n / YF_RIDGE_NUMBERS;
  return 0;
}

static int same_direction(const double* a, const double* b) {
  return a[0] == b[0] && a[1] == b[1] && a[2] == b[2];
}

// Convexity of the ridges (nridge x 5, freed here whatever the outcome: mju_error does not return).
// The ridges along one direction n (the same three numbers) add g(n . eps) to the energy,
// g(x) = sum_j (1/2) c_j max(x - t_j, 0)^2, convex iff its tangent g'' = sum_{t_j < x} c_j is >= 0 at
// every x, i.e. just past each of their knots (within YF_RIDGE_CONVEXITY_RTOL of their largest |c|).
// So a stiffness c >= 0 always passes, and a negative one (a tangent that falls at its knot: yarnfit
// writes c as the differences of the tangents it fits between knots) only past positive ones of
// smaller knots along the same direction. A convex g of a linear map of eps is convex in eps, so the
// ridge membrane is convex for a positive semi-definite S, and its tangent (damping's) is positive
// semi-definite.
static int check_ridge_tangents(double* ridge, int nridge) {
  for (int j = 0; j < nridge; j++) {
    const double* n = ridge + YF_RIDGE_NUMBERS * j;
    int seen = 0;
    for (int i = 0; i < j && !seen; i++) seen = same_direction(ridge + YF_RIDGE_NUMBERS * i, n);
    if (seen) continue;  // its direction was checked with the first ridge along it
    double scale = 0;
    for (int i = j; i < nridge; i++) {
      if (same_direction(ridge + YF_RIDGE_NUMBERS * i, n)) scale = fmax(scale, fabs(ridge[YF_RIDGE_NUMBERS * i + 4]));
    }
    int bad = -1;  // the ridge of least knot past which the tangent is negative
    double bad_tangent = 0;
    for (int i = j; i < nridge; i++) {
      const double* r = ridge + YF_RIDGE_NUMBERS * i;
      if (!same_direction(r, n) || (bad >= 0 && !(r[3] < ridge[YF_RIDGE_NUMBERS * bad + 3]))) continue;
      double tangent = 0;
      for (int l = j; l < nridge; l++) {
        const double* q = ridge + YF_RIDGE_NUMBERS * l;
        if (same_direction(q, n) && q[3] <= r[3]) tangent += q[4];
      }
      if (tangent < -YF_RIDGE_CONVEXITY_RTOL * scale) {
        bad = i;
        bad_tangent = tangent;
      }
    }
    if (bad >= 0) {
      const double* r = ridge + YF_RIDGE_NUMBERS * bad;
      double n0 = r[0], n1 = r[1], n2 = r[2], t = r[3], c = r[4];
      free(ridge);
      mju_error(YF_NAME ": config key 'ridges': ridge %d (stiffness c = %g Pa, knot t = %g) makes the energy "
                "concave: past that knot the ridges along n = (%.12g, %.12g, %.12g) have a tangent of %g Pa < 0 "
                "(the sum of their c with knots <= t must stay >= 0)", bad, c, t, n0, n1, n2, bad_tangent);
      return -1;
    }
  }
  free(ridge);
  return 0;
}

// Every attribute validated here, in one place.
static int read_config(const mjModel* m, int instance, Shell* s) {
  struct { const char* key; double* value; int required; double fallback; } keys[] = {
    {"s00", &s->s00, 1, 0}, {"s01", &s->s01, 1, 0}, {"s11", &s->s11, 1, 0}, {"s22", &s->s22, 1, 0},
    {"b00", &s->b00, 1, 0}, {"b01", &s->b01, 1, 0}, {"b11", &s->b11, 1, 0}, {"b22", &s->b22, 1, 0},
    {"thickness", &s->thickness, 1, 0}, {"angle", &s->angle, 0, 0}, {"damping", &s->damping, 0, 0},
    {"builtin_young", &s->builtin_young, 0, 0}, {"builtin_poisson", &s->builtin_poisson, 0, 0},
    {"builtin_thickness", &s->builtin_thickness, 0, 0},
    {"b00_neg", &s->b00_neg, 0, NAN}, {"b11_neg", &s->b11_neg, 0, NAN},
  };
  for (size_t k = 0; k < sizeof(keys) / sizeof(keys[0]); k++) {
    if (read_number(m, instance, keys[k].key, keys[k].fallback, keys[k].required, keys[k].value)) return -1;
  }
  if (isnan(s->b00_neg)) s->b00_neg = s->b00;  // absent: the quadratic bending
  if (isnan(s->b11_neg)) s->b11_neg = s->b11;
  if (read_choice(m, instance, "membrane", "triangle", "node", &s->node_membrane) ||
      read_choice(m, instance, "rest", "qpos0", "texcoord", &s->rest_texcoord) ||
      read_choice(m, instance, "implicit_drag", "full", "critical", &s->critical_drag)) return -1;
  if (read_share(m, instance, s->share, &s->has_share)) return -1;
  if (read_ridges(m, instance, NULL, &s->nridge)) return -1;
  if (s->nridge > 0) {
    double* ridge = malloc(sizeof(double) * YF_RIDGE_NUMBERS * s->nridge);
    if (!ridge) {
      mju_error(YF_NAME ": out of memory reading config key 'ridges' (%d ridges)", s->nridge);
      return -1;
    }
    read_ridges(m, instance, ridge, &s->nridge);
    if (check_ridge_tangents(ridge, s->nridge)) return -1;  // frees ridge
  }
  s->ridge = NULL;  // stored by init, once nothing can fail
  // Without ridges S is the StVK membrane and must be positive definite; with ridges it is the
  // ridge membrane's base, positive semi-definite (the ridges are convex on their own).
  const char* positive[] = {"s00", "s11", "s22", "b00", "b11", "b22", "thickness", "b00_neg", "b11_neg"};
  const double values[] = {s->s00, s->s11, s->s22, s->b00, s->b11, s->b22, s->thickness, s->b00_neg, s->b11_neg};
  for (int k = 0; k < 9; k++) {
    if (s->nridge > 0 && k < 3) {
      if (!(values[k] >= 0)) {
        mju_error(YF_NAME ": config key '%s' must be >= 0 with ridges (the ridge membrane's base S is positive "
                  "semi-definite), got %g", positive[k], values[k]);
        return -1;
      }
    } else if (!(values[k] > 0)) {
      mju_error(YF_NAME ": config key '%s' must be positive, got %g", positive[k], values[k]);
      return -1;
    }
  }
  if (s->nridge > 0) {
    if (s->s01 * s->s01 > s->s00 * s->s11 * (1 + YF_RIDGE_BASE_RTOL)) {
      mju_error(YF_NAME ": membrane matrix S (the ridge membrane's base) is not positive semi-definite: s01^2 = "
                "%.17g > s00*s11 = %.17g", s->s01 * s->s01, s->s00 * s->s11);
      return -1;
    }
  } else if (s->s01 * s->s01 >= s->s00 * s->s11) {
    mju_error(YF_NAME ": membrane matrix S is not positive definite: s01^2 = %g >= s00*s11 = %g",
                s->s01 * s->s01, s->s00 * s->s11);
    return -1;
  }
  if (s->b01 * s->b01 >= s->b00 * s->b11) {
    mju_error(YF_NAME ": bending matrix B is not positive definite: b01^2 = %g >= b00*b11 = %g",
                s->b01 * s->b01, s->b00 * s->b11);
    return -1;
  }
  double least00 = fmin(s->b00, s->b00_neg), least11 = fmin(s->b11, s->b11_neg);
  if (s->b01 * s->b01 >= least00 * least11) {
    mju_error(YF_NAME ": signed bending is not convex: b01^2 = %g >= min(b00, b00_neg)*min(b11, b11_neg) = %g "
              "(config keys 'b00_neg', 'b11_neg')", s->b01 * s->b01, least00 * least11);
    return -1;
  }
  if (s->damping < 0) {
    mju_error(YF_NAME ": config key 'damping' must be >= 0 (s), got %g", s->damping);
    return -1;
  }
  if (s->builtin_young < 0 || s->builtin_thickness < 0) {
    mju_error(YF_NAME ": config keys 'builtin_young' and 'builtin_thickness' must be >= 0, got %g and %g",
              s->builtin_young, s->builtin_thickness);
    return -1;
  }
  if ((s->builtin_young > 0) != (s->builtin_thickness > 0)) {
    mju_error(YF_NAME ": config keys 'builtin_young' and 'builtin_thickness' must both be given "
              "(the flex's <elasticity>) or both be absent");
    return -1;
  }
  if ((s->rest_texcoord || s->node_membrane) && (s->builtin_young > 0 || s->builtin_poisson > 0)) {
    mju_error(YF_NAME ": config keys 'builtin_*' are for rest=\"qpos0\" with membrane=\"triangle\"; with "
              "rest=\"texcoord\" or membrane=\"node\" the plugin removes MuJoCo's built-in elasticity exactly, "
              "whatever its parameters, and carries the whole material itself");
    return -1;
  }
  if (s->has_share && (s->builtin_young > 0 || s->builtin_poisson > 0)) {
    mju_error(YF_NAME ": config keys 'builtin_*' describe an isotropic share the plugin adds to; with "
              "'implicit_share' the plugin writes MuJoCo's share itself, removes it exactly and carries the "
              "whole material");
    return -1;
  }
  if (!(s->builtin_poisson >= 0 && s->builtin_poisson < 0.5)) {
    mju_error(YF_NAME ": config key 'builtin_poisson' must lie in [0, 0.5), got %g", s->builtin_poisson);
    return -1;
  }
  return 0;
}

// World position of body b at qpos0, composed from the model's body frames.
static void body_position0(const mjModel* m, int b, double pos[3], double quat[4]) {
  if (b == 0) {
    pos[0] = pos[1] = pos[2] = 0;
    quat[0] = 1; quat[1] = quat[2] = quat[3] = 0;
    return;
  }
  double ppos[3], pquat[4];
  body_position0(m, m->body_parentid[b], ppos, pquat);
  double offset[3];
  mju_rotVecQuat(offset, m->body_pos + 3 * b, pquat);
  for (int i = 0; i < 3; i++) pos[i] = ppos[i] + offset[i];
  mju_mulQuat(quat, pquat, m->body_quat + 4 * b);
}

// The 2D flex whose vertex bodies carry this plugin instance, or -1.
static int find_flex(const mjModel* m, int instance) {
  for (int f = 0; f < m->nflex; f++) {
    int first = m->flex_vertadr[f];
    int body = m->flex_vertbodyid[first];
    if (body >= 0 && m->body_plugin[body] == instance) return f;
  }
  return -1;
}

static void shell_free(Shell* s) {
  if (!s) return;
  free(s->ridge);
  free(s->dir);
  free(s->dir_start);
  free(s->knot);
  free(s->knot_c);
  free(s->knot_ct);
  free(s->tri);
  free(s->rest_inv);
  free(s->area);
  free(s->hinge);
  free(s->tri_hinge);
  free(s->tri_weight);
  free(s->tri_source);
  free(s->vert_dof);
  free(s->slide_only);
  free(s->grad);
  free(s->xdot);
  free(s->theta);
  free(s->theta_rate);
  free(s->torque);
  free(s->hinge_grad);
  free(s->builtin_hinge);
  free(s->builtin_edge);
  free(s->builtin_delta);
  free(s->drag_basis);
  free(s->drag_returned);
  free(s->drag_active);
  free(s->tri_engaged);
  free(s->drag_rate);
  free(s->corner_domain);
  free(s->domain_area);
  free(s->tri_F);
  free(s->tri_eps);
  free(s->domain_eps);
  free(s->domain_sig);
  free(s);
}

// The Green-strain basis of one triangle: G_k = dE/d(l_k^2) for its edge (local vertices k, k+1),
// with Dinv the inverse rest edge matrix. (2x2 row-major, 3 of them.)
static void strain_basis(const double Dinv[4], double G[3][4]) {
  // dC/d(l^2) for C = [[e1.e1, e1.e2], [e1.e2, e2.e2]]: edge 01 is e1, edge 12 is e2 - e1, edge 20 is e2.
  static const double dC[3][4] = {{1, 0.5, 0.5, 0}, {0, -0.5, -0.5, 0}, {0, 0.5, 0.5, 1}};
  for (int k = 0; k < 3; k++) {
    double tmp[4];  // dC Dinv
    for (int i = 0; i < 2; i++) {
      for (int j = 0; j < 2; j++) tmp[2 * i + j] = dC[k][2 * i] * Dinv[j] + dC[k][2 * i + 1] * Dinv[2 + j];
    }
    for (int i = 0; i < 2; i++) {  // 1/2 Dinv^T tmp
      for (int j = 0; j < 2; j++) G[k][2 * i + j] = 0.5 * (Dinv[i] * tmp[j] + Dinv[2 + i] * tmp[2 + j]);
    }
  }
}

// One triangle's Voigt Green strain per unit squared length of each of its edges, in flex_elemedge
// order: g (3 x 3, row a = (E00, E11, 2 E01) per unit l_a^2 of slot a), from its inverse rest edge
// matrix Dinv and slot_local, the local edge (vertices k, k+1) of each slot.
static void slot_strains(const double Dinv[4], const int slot_local[3], double g[9]) {
  double G[3][4];
  strain_basis(Dinv, G);
  for (int a = 0; a < 3; a++) {
    const double* Ga = G[slot_local[a]];
    g[3 * a] = Ga[0]; g[3 * a + 1] = Ga[3]; g[3 * a + 2] = Ga[1] + Ga[2];
  }
}

// One triangle's membrane metric in MuJoCo's edge space (flex_stiffness, the energy (1/4) Delta^T K
// Delta) for a membrane C (3x3 row-major, Pa, material-frame Voigt strain) over its rest area times
// thickness: the upper triangle (6) of K_ab = 2 A h g_a^T C g_b, g from slot_strains. MuJoCo compiles
// its isotropic <elasticity> as this with C = S_iso (2 g_a^T S_iso g_b = 4 (mu tr(G_a G_b) + lambda*/2
// tr G_a tr G_b)); implicit_share writes it with the key's C.
static void membrane_metric(const double g[9], const double C[9], double area_thickness, double out[6]) {
  double Cg[9];
  for (int a = 0; a < 3; a++) mju_mulMatVec3(Cg + 3 * a, C, g + 3 * a);
  for (int a = 0, n = 0; a < 3; a++) {
    for (int b = a; b < 3; b++, n++) out[n] = 2 * area_thickness * mju_dot3(g + 3 * a, Cg + 3 * b);
  }
}

// Check the builtin_* keys against the flex's compiled built-in membrane stiffness (membrane_metric
// of the isotropic plane-stress S_iso, lambda* = E nu / (1 - nu^2) the plane-stress Lame constant),
static int check_builtin(const mjModel* m, const Shell* s, const int* tri_edge_local) {
  int f = s->flex;
  double E = s->builtin_young, nu = s->builtin_poisson, t = s->builtin_thickness;
  if (m->flex_stiffnessadr[f] < 0) {  // no built-in stretch elasticity on this flex
    if (E > 0) {
      mju_error(YF_NAME ": config key builtin_young=%g is given but flex %d has no built-in stretch "
                "elasticity (<elasticity elastic2d=\"stretch\">)", E, f);
      return -1;
    }
    return 0;
  }
  double mu = E / (2 * (1 + nu)), lambda = E * nu / (1 - nu * nu);
  const double isotropic[9] = {lambda + 2 * mu, lambda, 0, lambda, lambda + 2 * mu, 0, 0, 0, mu};
  const mjtNum* stiffness = m->flex_stiffness + m->flex_stiffnessadr[f];
  for (int tri = 0; tri < s->ntri; tri++) {
    double g[9], expected[6], largest = 0, worst = 0;
    slot_strains(s->rest_inv + 4 * tri, tri_edge_local + 3 * tri, g);
    membrane_metric(g, isotropic, s->area[tri] * t, expected);
    for (int k = 0; k < 6; k++) {
      largest = fmax(largest, fabs(expected[k]));
      double compiled = stiffness[YF_STIFFNESS_STRIDE * tri + k];
      largest = fmax(largest, fabs(compiled));
      worst = fmax(worst, fabs(compiled - expected[k]));
    }
    if (worst > YF_BUILTIN_RTOL * largest) {
      if (E > 0) {
        mju_error(YF_NAME ": config keys builtin_young=%g builtin_poisson=%g builtin_thickness=%g do not "
                  "match flex %d's built-in <elasticity> (triangle %d); they must repeat its young, poisson "
                  "and thickness", E, nu, t, f, tri);
      } else {
        mju_error(YF_NAME ": flex %d carries built-in stretch elasticity: give the plugin builtin_young, "
                  "builtin_poisson and builtin_thickness equal to its <elasticity> so that it adds only "
                  "the remainder", f);
      }
      return -1;
    }
  }
  return 0;
}

// MuJoCo's own bending on the flex, if it has any: the interior edges' 4x4 operators, which
// compute adds back with the opposite sign. A nonzero curved-reference coefficient would mean a
// bent rest shape, which init has already refused; it is checked anyway, since the removal
// assumes f = -K x exactly.
static int collect_builtin_bending(const mjModel* m, Shell* s) {
  int f = s->flex;
  if (m->flex_bendingadr[f] < 0) return 0;
  int nedge = m->flex_edgenum[f], eadr = m->flex_edgeadr[f];
  const double* coefficients = m->flex_bending + m->flex_bendingadr[f];
  s->builtin_hinge = malloc(sizeof(int) * 4 * (nedge > 0 ? nedge : 1));
  s->builtin_edge = malloc(sizeof(int) * (nedge > 0 ? nedge : 1));
  if (!s->builtin_hinge || !s->builtin_edge) return -1;
  s->builtin_k = coefficients;
  s->builtin_damping = m->flex_damping[f];
  for (int e = 0; e < nedge; e++) {
    const int* edge = m->flex_edge + 2 * (eadr + e);
    const int* flap = m->flex_edgeflap + 2 * (eadr + e);
    const double* k = coefficients + YF_BENDING_STRIDE * e;
    if (flap[0] < 0 || flap[1] < 0) continue;  // a boundary edge: MuJoCo stores zeros
    if (k[YF_BENDING_STRIDE - 1] != 0 && !s->rest_texcoord) {
      mju_error(YF_NAME ": flex %d's built-in bending has a curved reference (edge %d); the plugin "
                "needs a flat rest shape", f, e);
      return -1;
    }
    int* h = s->builtin_hinge + 4 * s->nbuiltin_hinge;
    h[0] = edge[0]; h[1] = edge[1]; h[2] = flap[0]; h[3] = flap[1];
    s->builtin_edge[s->nbuiltin_hinge++] = e;
  }
  return 0;
}

// implicit_share: write K_ab = 2 A h g_a^T C g_b into each triangle's flex_stiffness block (its
// edges in flex_elemedge order), so that MuJoCo's implicit membrane is C in the material frame.
// mjModel is const to a plugin; its arrays are ordinary heap memory, and MuJoCo reads this block at
// every step (measured: a model whose flex_stiffness was rewritten steps exactly as one compiled
// with that metric), so init rewrites it for every mjData made from the model (the same values each
// time, from the same rest).
static int write_share(const mjModel* m, Shell* s, const int* tri_edge_local) {
  int f = s->flex;
  if (m->flex_stiffnessadr[f] < 0) {
    mju_error(YF_NAME ": config key 'implicit_share' needs flex %d to carry built-in stretch elasticity "
              "(<elasticity elastic2d=\"stretch\"> or \"both\">): it is the metric the key rewrites", f);
    return -1;
  }
  mjtNum* stiffness = (mjtNum*)(m->flex_stiffness + m->flex_stiffnessadr[f]);
  for (int t = 0; t < s->ntri; t++) {
    double g[9];
    slot_strains(s->rest_inv + 4 * t, tri_edge_local + 3 * t, g);
    membrane_metric(g, s->share, s->area[t] * s->thickness, stiffness + YF_STIFFNESS_STRIDE * t);
  }
  return 0;
}

// rest="texcoord": MuJoCo's built-in membrane on the flex, if it has one, for compute to remove.
static int collect_builtin_membrane(const mjModel* m, Shell* s) {
  int f = s->flex;
  if (m->flex_stiffnessadr[f] < 0 || m->flex_stiffness[m->flex_stiffnessadr[f]] == 0) return 0;
  s->builtin_metric = m->flex_stiffness + m->flex_stiffnessadr[f];
  s->builtin_elemedge = m->flex_elemedge + m->flex_elemedgeadr[f];
  s->builtin_length0 = m->flexedge_length0 + m->flex_edgeadr[f];
  s->nedge = m->flex_edgenum[f];
  s->builtin_delta = malloc(sizeof(double) * (s->nedge > 0 ? s->nedge : 1));
  return s->builtin_delta ? 0 : -1;
}

// Add to grad (the energy gradient, so minus the force) the force of one triangle's edge metric:
// scale * (K d)_b (x_q - x_p) on edge b's vertex q and its opposite on p, i.e. scale (1/2) J^T K d
// with J = d(l^2)/dx over its edges (slot: its three flex-local edges in flex_elemedge order,
// edge: the flex's vertex pairs, k: K's upper triangle (6), per_edge: d per flex edge).
static void add_edge_metric_force(double* grad, const double* x, const int* edge, const int* slot, const double* k,
                                  const double* per_edge, double scale) {
  double K[3][3], d[3];
  for (int a = 0, n = 0; a < 3; a++) {
    d[a] = per_edge[slot[a]];
    for (int b = a; b < 3; b++, n++) K[a][b] = K[b][a] = k[n];
  }
  for (int b = 0; b < 3; b++) {
    double c = scale * (K[b][0] * d[0] + K[b][1] * d[1] + K[b][2] * d[2]);
    int p = edge[2 * slot[b]], q = edge[2 * slot[b] + 1];
    double along[3];
    mju_sub3(along, x + 3 * q, x + 3 * p);  // (1/2) grad_q (l^2) = x_q - x_p
    mju_addToScl3(grad + 3 * q, along, -c);
    mju_addToScl3(grad + 3 * p, along, c);
  }
}

// Remove MuJoCo's built-in membrane (rest="texcoord") from the plugin's total: MuJoCo's force is
// minus the gradient of (1/4) Delta^T K Delta per triangle, Delta_a = l_a^2 - L_a^2 + (l_a^2 -
// (l_a - h dl_a/dt)^2) damping / h over its edges (K its flex_stiffness block, L flexedge_length0,
// h the time step: MuJoCo 4.0's Rayleigh damping, measured against qfrc_spring and qfrc_damper to
// 1e-15), so the plugin adds (1/2) sum_b (K Delta)_b grad(l_b^2) to the force.
static void remove_builtin_membrane(const mjModel* m, const mjData* d, Shell* s, const double* x) {
  int f = s->flex, eadr = m->flex_edgeadr[f];
  double h = m->opt.timestep, rate = m->flex_damping[f] / h;
  const mjtNum* length = d->flexedge_length + eadr;
  const mjtNum* speed = d->flexedge_velocity + eadr;
  const int* edge = m->flex_edge + 2 * eadr;
  for (int e = 0; e < s->nedge; e++) {
    double l = length[e], previous = l - speed[e] * h, rest = s->builtin_length0[e];
    s->builtin_delta[e] = l * l - rest * rest + (l * l - previous * previous) * rate;
  }
  for (int t = 0; t < s->ntri; t++) {
    add_edge_metric_force(s->grad, x, edge, s->builtin_elemedge + 3 * t,
                          s->builtin_metric + YF_STIFFNESS_STRIDE * t, s->builtin_delta, 1);
  }
}

// Remove MuJoCo's built-in bending from the plugin's total: add K x + damping K v per built-in
// hinge to the force, i.e. subtract it from s->grad, and with rest="texcoord" MuJoCo's
// curved-reference term too: c (e1 x e2, e2 x e0, e0 x e1 and minus their sum on the edge's first
// vertex), e_i the hinge's vertices from its first, c the 17th coefficient (measured against
// qfrc_spring to 1e-16). xdot may be NULL (no built-in damping).
static void remove_builtin_bending(Shell* s, const double* x, const double* xdot) {
  for (int e = 0; e < s->nbuiltin_hinge; e++) {
    const int* v = s->builtin_hinge + 4 * e;
    const double* k = s->builtin_k + YF_BENDING_STRIDE * s->builtin_edge[e];
    double y[4][3];
    for (int j = 0; j < 4; j++) {
      for (int i = 0; i < 3; i++) {
        y[j][i] = x[3 * v[j] + i] + (xdot ? s->builtin_damping * xdot[3 * v[j] + i] : 0);
      }
    }
    for (int a = 0; a < 4; a++) {
      double* g = s->grad + 3 * v[a];
      for (int b = 0; b < 4; b++) mju_addToScl3(g, y[b], -k[4 * a + b]);
    }
    double curved = k[YF_BENDING_STRIDE - 1];
    if (curved != 0) {
      double e0[3], e1[3], e2[3], c[4][3];
      mju_sub3(e0, x + 3 * v[1], x + 3 * v[0]);
      mju_sub3(e1, x + 3 * v[2], x + 3 * v[0]);
      mju_sub3(e2, x + 3 * v[3], x + 3 * v[0]);
      mju_cross(c[1], e1, e2);
      mju_cross(c[2], e2, e0);
      mju_cross(c[3], e0, e1);
      for (int i = 0; i < 3; i++) c[0][i] = -(c[1][i] + c[2][i] + c[3][i]);
      for (int a = 0; a < 4; a++) mju_addToScl3(s->grad + 3 * v[a], c[a], -curved);
    }
  }
}

// Rest coordinates (2) of flex-local vertex `vertex` of triangle `tri` (3 vertex ids) from its
// rest2d entry (6: the three vertices' material coordinates, the first at the origin).
static void tri_point(const double* rest, const int* tri, int vertex, double out[2]) {
  int k = vertex == tri[0] ? 0 : vertex == tri[1] ? 1 : 2;
  out[0] = rest[2 * k];
  out[1] = rest[2 * k + 1];
}

// Inverse of the row-major 3x3 matrix a into out; returns -1 (out untouched) if its condition
// number in the max-row-sum norm exceeds `condition`.
static int invert3(const double a[9], double out[9], double condition) {
  double c[9] = {
    a[4] * a[8] - a[5] * a[7], a[2] * a[7] - a[1] * a[8], a[1] * a[5] - a[2] * a[4],
    a[5] * a[6] - a[3] * a[8], a[0] * a[8] - a[2] * a[6], a[2] * a[3] - a[0] * a[5],
    a[3] * a[7] - a[4] * a[6], a[1] * a[6] - a[0] * a[7], a[0] * a[4] - a[1] * a[3],
  };
  double det = a[0] * c[0] + a[1] * c[3] + a[2] * c[6];
  if (!(fabs(det) > 0)) return -1;
  double norm_a = 0, norm_inv = 0;
  for (int i = 0; i < 3; i++) {
    norm_a = fmax(norm_a, fabs(a[3 * i]) + fabs(a[3 * i + 1]) + fabs(a[3 * i + 2]));
    norm_inv = fmax(norm_inv, (fabs(c[3 * i]) + fabs(c[3 * i + 1]) + fabs(c[3 * i + 2])) / fabs(det));
  }
  if (norm_a * norm_inv > condition) return -1;
  for (int i = 0; i < 9; i++) out[i] = c[i] / det;
  return 0;
}

// Hinges: each interior edge with its two opposite vertices, oriented by its first triangle; and
// per triangle edge the hinge and d kappa / d theta. Needs s->tri, s->area and the rest edges in
// the material frame `rest2d` (ntri x 6: the three vertices' material coordinates relative to the
// first). Returns -1 (after mju_error) on a non-manifold or inconsistently oriented mesh.
static int build_hinges(const mjModel* m, Shell* s, const double* rest2d, int* tri_edge_local) {
  int f = s->flex, nedge = m->flex_edgenum[f];
  const int* edge = m->flex_edge + 2 * m->flex_edgeadr[f];
  const int* elemedge = m->flex_elemedge + m->flex_elemedgeadr[f];
  int* side = malloc(sizeof(int) * 4 * nedge);
  int* edge_hinge = malloc(sizeof(int) * nedge);
  int* tri_edge = malloc(sizeof(int) * 3 * s->ntri);
  if (!side || !edge_hinge || !tri_edge) {
    free(side); free(edge_hinge); free(tri_edge);
    return -1;
  }
  for (int i = 0; i < 4 * nedge; i++) side[i] = -1;
  const char* problem = NULL;
  int bad_tri = -1;
  for (int t = 0; t < s->ntri && !problem; t++) {
    const int* v = s->tri + 3 * t;
    for (int j = 0; j < 3 && !problem; j++) {
      int e = elemedge[3 * t + j], p = edge[2 * e], q = edge[2 * e + 1], k = 0;
      while (k < 3 && !((v[k] == p && v[(k + 1) % 3] == q) || (v[k] == q && v[(k + 1) % 3] == p))) k++;
      if (k == 3) { problem = "an element edge that is not an edge of its triangle"; bad_tri = t; break; }
      int a = v[k], b = v[(k + 1) % 3], o = v[(k + 2) % 3];
      tri_edge[3 * t + k] = e;
      tri_edge_local[3 * t + j] = k;  // flex_elemedge slot j is the triangle's local edge k
      if (side[4 * e] < 0) {
        side[4 * e] = a; side[4 * e + 1] = b; side[4 * e + 2] = o;
      } else if (side[4 * e + 3] < 0 && side[4 * e] == b && side[4 * e + 1] == a) {
        side[4 * e + 3] = o;
      } else {
        problem = "an edge shared by more than two triangles, or neighbouring triangles of opposite "
                  "orientation";
        bad_tri = t;
      }
    }
  }
  if (problem) {
    free(side); free(edge_hinge); free(tri_edge);
    mju_error(YF_NAME ": flex %d (triangle %d) has %s; the bending model needs a consistently oriented "
              "manifold mesh", f, bad_tri, problem);
    return -1;
  }
  s->nhinge = 0;
  for (int e = 0; e < nedge; e++) edge_hinge[e] = side[4 * e + 3] >= 0 ? s->nhinge++ : -1;
  s->hinge = malloc(sizeof(int) * 4 * (s->nhinge > 0 ? s->nhinge : 1));
  if (!s->hinge) { free(side); free(edge_hinge); free(tri_edge); return -1; }
  for (int e = 0; e < nedge; e++) {
    if (edge_hinge[e] >= 0) memcpy(s->hinge + 4 * edge_hinge[e], side + 4 * e, sizeof(int) * 4);
  }
  // Opposite vertex of each hinge side relative to the edge, in that triangle's rest frame:
  // (s along x1 -> x2 from the edge's midpoint, d > 0 its distance from the edge line).
  double* apex = malloc(sizeof(double) * 4 * (s->nhinge > 0 ? s->nhinge : 1));  // sA dA sB dB
  int* hinge_tri = malloc(sizeof(int) * 2 * (s->nhinge > 0 ? s->nhinge : 1));   // its two triangles
  unsigned char* solved = calloc(s->ntri > 0 ? s->ntri : 1, 1);  // the triangle inverted its own map
  if (!apex || !hinge_tri || !solved) {
    free(apex); free(hinge_tri); free(solved); free(side); free(edge_hinge); free(tri_edge);
    return -1;
  }
  for (int t = 0; t < s->ntri; t++) {
    for (int k = 0; k < 3; k++) {
      int h = edge_hinge[tri_edge[3 * t + k]];
      if (h < 0) continue;
      double p1[2], p2[2], po[2], t_e[2], mid[2];
      const int* hv = s->hinge + 4 * h;
      int first = s->tri[3 * t + (k + 2) % 3] == hv[2];  // the hinge's first triangle (x1 x2 o0)
      tri_point(rest2d + 6 * t, s->tri + 3 * t, hv[0], p1);
      tri_point(rest2d + 6 * t, s->tri + 3 * t, hv[1], p2);
      tri_point(rest2d + 6 * t, s->tri + 3 * t, s->tri[3 * t + (k + 2) % 3], po);
      double length = hypot(p2[0] - p1[0], p2[1] - p1[1]);
      t_e[0] = (p2[0] - p1[0]) / length; t_e[1] = (p2[1] - p1[1]) / length;
      mid[0] = 0.5 * (p1[0] + p2[0]); mid[1] = 0.5 * (p1[1] + p2[1]);
      double rx = po[0] - mid[0], ry = po[1] - mid[1];
      hinge_tri[2 * h + (first ? 0 : 1)] = t;
      apex[4 * h + (first ? 0 : 2)] = rx * t_e[0] + ry * t_e[1];
      apex[4 * h + (first ? 1 : 3)] = fabs(rx * t_e[1] - ry * t_e[0]);
    }
  }
  for (int t = 0; t < s->ntri; t++) {
    const double* r = rest2d + 6 * t;  // material coordinates of vertices 0, 1, 2 (vertex 0 at 0)
    double rows[9];                      // theta_k = rows[3k..3k+2] . kappa (consistent operator)
    int interior = 1;
    for (int k = 0; k < 3; k++) {
      int h = edge_hinge[tri_edge[3 * t + k]];
      s->tri_hinge[3 * t + k] = h;
      double d0 = r[2 * ((k + 1) % 3)] - r[2 * k], d1 = r[2 * ((k + 1) % 3) + 1] - r[2 * k + 1];
      double length = sqrt(d0 * d0 + d1 * d1);
      double n0 = d1 / length, n1 = -d0 / length, scale = length / (2 * s->area[t]);
      // The hinge operator of a regular grid (fallback, and boundary triangles).
      s->tri_weight[9 * t + 3 * k + 0] = scale * n0 * n0;
      s->tri_weight[9 * t + 3 * k + 1] = scale * n1 * n1;
      s->tri_weight[9 * t + 3 * k + 2] = scale * 2 * n0 * n1;
      if (h < 0) { interior = 0; continue; }
      // This triangle's side of the hinge: its opposite vertex and the other side's.
      const int* hv = s->hinge + 4 * h;
      int self_first = s->tri[3 * t + (k + 2) % 3] == hv[2];
      double s_self = apex[4 * h + (self_first ? 0 : 2)], d_self = apex[4 * h + (self_first ? 1 : 3)];
      double s_other = apex[4 * h + (self_first ? 2 : 0)], d_other = apex[4 * h + (self_first ? 3 : 1)];
      // Edge tangent along x1 -> x2 and the in-plane normal pointing away from this triangle, in its
      // material frame. The local edge k runs v[k] -> v[k+1]; the triangle is counter-clockwise in
      // its rest frame only up to a reflection, so the normal's side is taken from the opposite vertex.
      double tx = d0 / length, ty = d1 / length;
      if (s->tri[3 * t + k] != hv[0]) { tx = -tx; ty = -ty; }
      double ox = r[2 * ((k + 2) % 3)] - 0.5 * (r[2 * k] + r[2 * ((k + 1) % 3)]);
      double oy = r[2 * ((k + 2) % 3) + 1] - 0.5 * (r[2 * k + 1] + r[2 * ((k + 1) % 3) + 1]);
      double nx = -ty, ny = tx;
      if (nx * ox + ny * oy > 0) { nx = -nx; ny = -ny; }
      double quarter = 0.25 * length * length;
      double c_nn = 0.5 * (d_self + d_other);
      double c_tt = 0.5 * ((s_self * s_self - quarter) / d_self + (s_other * s_other - quarter) / d_other);
      double c_tn = s_other - s_self;
      // II_nn, II_tt and II_tn as functions of kappa = (II00, II11, 2 II01).
      rows[3 * k + 0] = c_nn * nx * nx + c_tt * tx * tx + c_tn * tx * nx;
      rows[3 * k + 1] = c_nn * ny * ny + c_tt * ty * ty + c_tn * ty * ny;
      rows[3 * k + 2] = c_nn * nx * ny + c_tt * tx * ty + c_tn * 0.5 * (tx * ny + ty * nx);
    }
    if (!interior) continue;
    double inverse[9];
    if (invert3(rows, inverse, YF_OPERATOR_CONDITION)) continue;  // ill-conditioned: keep the grid operator
    for (int k = 0; k < 3; k++) {
      for (int i = 0; i < 3; i++) s->tri_weight[9 * t + 3 * k + i] = inverse[3 * i + k];
    }
    solved[t] = 1;
  }
  // A triangle on a free edge has no hinge there, so its own angles cannot tell its curvature:
  // it bends with an interior neighbour's (across one of its hinges), which extrapolates a constant
  // curvature to the edge (a strip bent into a cylinder is uniformly curved up to its free ends).
  // With no consistent neighbour (a corner, a one-triangle-wide strip) it keeps the grid operator
  // over its own hinges.
  for (int t = 0; t < s->ntri; t++) {
    s->tri_source[t] = t;
    for (int k = 0; k < 3 && !solved[t]; k++) {
      int h = s->tri_hinge[3 * t + k];
      if (h < 0) continue;
      int other = hinge_tri[2 * h] == t ? hinge_tri[2 * h + 1] : hinge_tri[2 * h];
      if (solved[other]) { s->tri_source[t] = other; break; }
    }
  }
  free(apex);
  free(hinge_tri);
  free(solved);
  free(side);
  free(edge_hinge);
  free(tri_edge);
  return 0;
}

// Kinematic chain of each vertex body: its last dof, and whether every dof on it is a slide joint
// (then the vertex Jacobian is the joint axes, and forces go straight to those dofs).
static void classify_vertices(const mjModel* m, Shell* s) {
  int vadr = m->flex_vertadr[s->flex];
  for (int v = 0; v < s->nvert; v++) {
    int body = m->flex_vertbodyid[vadr + v];
    while (body > 0 && m->body_dofnum[body] == 0) body = m->body_parentid[body];
    int dof = body > 0 ? m->body_dofadr[body] + m->body_dofnum[body] - 1 : -1;
    s->vert_dof[v] = dof;
    s->slide_only[v] = 1;
    for (int j = dof; j >= 0; j = m->dof_parentid[j]) {
      if (m->jnt_type[m->dof_jntid[j]] != mjJNT_SLIDE) s->slide_only[v] = 0;
    }
  }
}

static int build_domains(const mjModel* m, Shell* s);

// Symmetric 3x3 (row-major) matrix function: V diag(fn(eigenvalues)) V^T.
static void sym3_function(const double a[9], double (*fn)(double), double out[9]) {
  double value[3], vector[9], quat[4];
  mju_eig3(value, vector, quat, a);
  for (int i = 0; i < 3; i++) {
    for (int j = 0; j < 3; j++) {
      out[3 * i + j] = 0;
      for (int k = 0; k < 3; k++) out[3 * i + j] += vector[3 * i + k] * fn(value[k]) * vector[3 * j + k];
    }
  }
}

static double root_of(double value) { return sqrt(value); }
static double inverse_root_of(double value) { return 1 / sqrt(value); }
// The share of the drag given back in a mode of stiffness ratio r (YF_CRITICAL_DRAG).
static double drag_returned_share(double r) {
  return 1 - fmin(1, fmax(YF_LEAST_DRAG, YF_CRITICAL_DRAG * sqrt(fmax(r, 0))));
}

// Group the ridges by direction (the same three numbers, as check_ridge_tangents groups them), each
// group's knots ascending with the running sums of c and c t: along a direction n the ridges
// engaged at strain eps (n . eps - t > 0) are a prefix of its knots, and their stress
// sum_j c_j (n . eps - t_j) n and tangent sum_j c_j n n^T need only that prefix's two sums. So
// compute takes one dot product a direction instead of one a ridge (the cotton twill's fit: 248
// ridges along 48 directions). 0 on success, -1 out of memory.
static int group_ridges(Shell* s) {
  int n = s->nridge;
  s->dir = malloc(sizeof(double) * 3 * (n > 0 ? n : 1));
  s->dir_start = malloc(sizeof(int) * (n + 1));
  s->knot = malloc(sizeof(double) * (n > 0 ? n : 1));
  s->knot_c = malloc(sizeof(double) * (n > 0 ? n : 1));
  s->knot_ct = malloc(sizeof(double) * (n > 0 ? n : 1));
  int* order = malloc(sizeof(int) * (n > 0 ? n : 1));
  if (!s->dir || !s->dir_start || !s->knot || !s->knot_c || !s->knot_ct || !order) {
    free(order);
    return -1;
  }
  int placed = 0;
  s->ndir = 0;
  for (int j = 0; j < n; j++) {
    const double* r = s->ridge + YF_RIDGE_NUMBERS * j;
    int seen = 0;
    for (int i = 0; i < j && !seen; i++) seen = same_direction(s->ridge + YF_RIDGE_NUMBERS * i, r);
    if (seen) continue;
    int d = s->ndir++;
    mju_copy3(s->dir + 3 * d, r);
    s->dir_start[d] = placed;
    for (int i = j; i < n; i++) {
      if (!same_direction(s->ridge + YF_RIDGE_NUMBERS * i, r)) continue;
      // Insertion by knot (a few ridges a direction); equal knots keep their order.
      int k = placed++;
      while (k > s->dir_start[d] && s->ridge[YF_RIDGE_NUMBERS * order[k - 1] + 3] > s->ridge[YF_RIDGE_NUMBERS * i + 3]) {
        order[k] = order[k - 1];
        k--;
      }
      order[k] = i;
    }
    double c = 0, ct = 0;
    for (int k = s->dir_start[d]; k < placed; k++) {
      const double* q = s->ridge + YF_RIDGE_NUMBERS * order[k];
      c += q[4];
      ct += q[4] * q[3];
      s->knot[k] = q[3];
      s->knot_c[k] = c;
      s->knot_ct[k] = ct;
    }
  }
  s->dir_start[s->ndir] = placed;
  free(order);
  return 0;
}

// The last ridge engaged along direction d at x = n . eps (its index in knot, knot_c and knot_ct),
// or -1 when none is: the last of its knots t with x - t > 0. Engaged is what the force, its
// damping and the tangent the returned drag is built for all count (a knot-0 ridge on its own side
// only). A mode with no ridge engaged and no base has no tangent: all but YF_LEAST_DRAG of its drag
// comes back, and that floor is what keeps it from drifting undamped (a cotton jersey's 2 x 5 bias
// strip never came to rest at 0.2 % without it).
static int last_engaged(const Shell* s, int d, double x) {
  int k = s->dir_start[d], end = s->dir_start[d + 1];
  while (k < end && x - s->knot[k] > 0) k++;
  return k > s->dir_start[d] ? k - 1 : -1;
}

// The signature of the ridges engaged at a strain: FNV-1a over each direction's last engaged ridge
// (last_engaged; the last engaged names the prefix), 0 for none. signature_add takes in the next
// direction that has one. A collision only keeps a K_r built for other ridges, still between 0 and K_b.
static uint64_t signature_add(uint64_t hash, int last) {
  if (!hash) hash = 1469598103934665603ULL;
  return (hash ^ (uint64_t)last) * 1099511628211ULL;
}

// The signature of the ridges engaged at strain eps (3, Voigt).
static uint64_t engaged_ridges(const Shell* s, const double eps[3]) {
  uint64_t hash = 0;
  for (int d = 0; d < s->ndir; d++) {
    int last = last_engaged(s, d, mju_dot3(s->dir + 3 * d, eps));
    if (last >= 0) hash = signature_add(hash, last);
  }
  return hash;
}

// Triangle t's returned metric K_r (build_drag_return) for the material's tangent at strain eps
// (3, Voigt): h S and the ridges engaged there, whose signature (engaged_ridges) is `engaged`.
static void update_returned_drag(Shell* s, int t, const double eps[3], uint64_t engaged) {
  double h = s->thickness;
  double C[9] = {h * s->s00, h * s->s01, 0, h * s->s01, h * s->s11, 0, 0, 0, h * s->s22};
  for (int d = 0; d < s->ndir; d++) {
    const double* n = s->dir + 3 * d;
    int last = last_engaged(s, d, mju_dot3(n, eps));
    if (last < 0) continue;
    for (int a = 0; a < 3; a++) {
      for (int b = 0; b < 3; b++) C[3 * a + b] += h * s->knot_c[last] * n[a] * n[b];
    }
  }
  const double* root = s->drag_basis + 27 * t;
  const double* inverse_root = root + 9;
  const double* g = root + 18;
  double Kt[9], tmp[9], ratio[9], share[9];
  for (int a = 0; a < 3; a++) {
    for (int b = a; b < 3; b++) {
      double cg[3];
      mju_mulMatVec3(cg, C, g + 3 * b);
      Kt[3 * a + b] = Kt[3 * b + a] = 2 * s->area[t] * mju_dot3(g + 3 * a, cg);
    }
  }
  mju_mulMatMat(tmp, inverse_root, Kt, 3, 3, 3);
  mju_mulMatMat(ratio, tmp, inverse_root, 3, 3, 3);
  for (int a = 0; a < 3; a++) {  // symmetrise the round-off before the eigendecomposition
    for (int b = a + 1; b < 3; b++) ratio[3 * a + b] = ratio[3 * b + a] = 0.5 * (ratio[3 * a + b] + ratio[3 * b + a]);
  }
  sym3_function(ratio, drag_returned_share, share);
  mju_mulMatMat(tmp, root, share, 3, 3, 3);
  mju_mulMatMat(share, tmp, root, 3, 3, 3);
  for (int a = 0, n = 0; a < 3; a++) {
    for (int b = a; b < 3; b++, n++) s->drag_returned[6 * t + n] = 0.5 * (share[3 * a + b] + share[3 * b + a]);
  }
  s->drag_active[t] = engaged;
}

// implicit_drag="critical": per triangle, the metric K_r of MuJoCo's drag that compute gives back.
// Under integrator="discrete" MuJoCo steps (M + h^2 K) a = f - h K v, K the built-in elasticity's
// stiffness: per triangle (1/2) J^T K_b J with J = d(l^2)/dx over its edges and K_b its
// flex_stiffness block (edge space, the energy (1/4) Delta^T K_b Delta). In the material's soft
// modes (a woven's shear, 1e-3 of the isotropic share that covers its weft) the drag h K v holds
// the cloth back for k_b / k_t steps. The material's own tangent at the triangle's strain in the
// same edge space, K_t = 2 A g^T C g (g_a the Voigt Green strain per unit l_a^2, C = h S plus the
// ridges engaged), and the generalised eigenproblem of K_t against K_b give each mode's ratio r;
// K_r = K_b^(1/2) Q diag(1 - min(1, max(0.02, 2 sqrt(r)))) Q^T K_b^(1/2) returns what critical
// damping of the mode on the step's inertia does not need. 0 <= K_r <= K_b in every direction: what is returned
// never exceeds MuJoCo's drag, so the step stays as stable as without it (plugins/README.md).
// Here the per-triangle basis (K_b's roots, g) and K_r at rest; compute rebuilds a triangle's K_r
// when the ridges engaged at its strain change (return_drag).
static int build_drag_return(const mjModel* m, Shell* s, const int* tri_edge_local) {
  if (!s->critical_drag) return 0;
  int f = s->flex;
  if (m->flex_stiffnessadr[f] < 0 || m->flex_stiffness[m->flex_stiffnessadr[f]] == 0) {
    mju_error(YF_NAME ": config key implicit_drag=\"critical\" needs flex %d to carry built-in stretch "
              "elasticity (<elasticity elastic2d=\"stretch\"> or \"both\"): without it there is no drag to "
              "return", f);
    return -1;
  }
  s->drag_elemedge = m->flex_elemedge + m->flex_elemedgeadr[f];
  s->nedge = m->flex_edgenum[f];
  s->drag_basis = malloc(sizeof(double) * 27 * s->ntri);
  s->drag_returned = malloc(sizeof(double) * 6 * s->ntri);
  s->drag_active = malloc(sizeof(uint64_t) * s->ntri);
  s->drag_rate = malloc(sizeof(double) * (s->nedge > 0 ? s->nedge : 1));
  if (!s->drag_basis || !s->drag_returned || !s->drag_active || !s->drag_rate) return -1;
  if (!s->node_membrane && s->nridge > 0) {  // membrane_forces finds each triangle's ridges for return_drag
    s->tri_engaged = calloc(s->ntri > 0 ? s->ntri : 1, sizeof(uint64_t));
    if (!s->tri_engaged) return -1;
  }
  const mjtNum* stiffness = m->flex_stiffness + m->flex_stiffnessadr[f];
  const double rest[3] = {0, 0, 0};
  for (int t = 0; t < s->ntri; t++) {
    double Kb[9];
    double* root = s->drag_basis + 27 * t;
    slot_strains(s->rest_inv + 4 * t, tri_edge_local + 3 * t, root + 18);  // (E00, E11, 2 E01) per unit l_a^2
    for (int a = 0, n = 0; a < 3; a++) {
      for (int b = a; b < 3; b++, n++) Kb[3 * a + b] = Kb[3 * b + a] = stiffness[YF_STIFFNESS_STRIDE * t + n];
    }
    double value[3], vector[9], quat[4];
    mju_eig3(value, vector, quat, Kb);
    if (!(value[0] > 0 && value[1] > 0 && value[2] > 0)) {
      mju_error(YF_NAME ": flex %d triangle %d: its built-in stretch stiffness is not positive definite", f, t);
      return -1;
    }
    sym3_function(Kb, root_of, root);
    sym3_function(Kb, inverse_root_of, root + 9);
    update_returned_drag(s, t, rest, engaged_ridges(s, rest));
  }
  return 0;
}

static int shell_init(const mjModel* m, mjData* d, int instance) {
  // Validate before allocating anything: mju_error does not return.
  Shell config = {0};
  if (read_config(m, instance, &config)) return -1;
  int f = find_flex(m, instance);
  if (f < 0) {
    mju_error(YF_NAME ": plugin instance %d is attached to no flex", instance);
    return -1;
  }
  if (m->flex_dim[f] != 2) {
    mju_error(YF_NAME ": needs a 2D flex (triangles), flex %d has dim %d", f, m->flex_dim[f]);
    return -1;
  }
  if (m->flex_interp[f]) {
    mju_error(YF_NAME ": flex %d is interpolated (dof trilinear/quadratic); needs a plain triangle flex", f);
    return -1;
  }
  if (config.rest_texcoord && m->flex_texcoordadr[f] < 0) {
    mju_error(YF_NAME ": config key rest=\"texcoord\" but flex %d has no texture coordinates (give the flex "
              "texcoord, and elemtexcoord per triangle corner: each panel's material coordinates in m)", f);
    return -1;
  }
  Shell* s = calloc(1, sizeof(Shell));
  if (!s) return -1;
  *s = config;
  s->flex = f;
  s->ntri = m->flex_elemnum[f];
  s->nvert = m->flex_vertnum[f];
  s->tri = malloc(sizeof(int) * 3 * s->ntri);
  s->rest_inv = malloc(sizeof(double) * 4 * s->ntri);
  s->area = malloc(sizeof(double) * s->ntri);
  s->tri_hinge = malloc(sizeof(int) * 3 * s->ntri);
  s->tri_weight = malloc(sizeof(double) * 9 * s->ntri);
  s->tri_source = malloc(sizeof(int) * s->ntri);
  s->vert_dof = malloc(sizeof(int) * s->nvert);
  s->slide_only = malloc(s->nvert);
  s->ridge = malloc(sizeof(double) * YF_RIDGE_NUMBERS * (s->nridge > 0 ? s->nridge : 1));
  double* x0 = malloc(sizeof(double) * 3 * s->nvert);
  double* rest2d = malloc(sizeof(double) * 6 * s->ntri);
  int* tri_edge_local = malloc(sizeof(int) * 3 * s->ntri);
  if (!s->tri || !s->rest_inv || !s->area || !s->tri_hinge || !s->tri_weight || !s->tri_source || !s->vert_dof ||
      !s->slide_only || !s->ridge || !x0 || !rest2d || !tri_edge_local) {
    free(x0); free(rest2d); free(tri_edge_local);
    shell_free(s);
    return -1;
  }
  read_ridges(m, instance, s->ridge, &s->nridge);  // validated by read_config: cannot fail
  if (group_ridges(s)) {
    free(x0); free(rest2d); free(tri_edge_local);
    shell_free(s);
    return -1;
  }
  free(s->ridge);
  s->ridge = NULL;

  // Membrane stiffness the plugin carries: h S minus the built-in isotropic t_b S_iso.
  {
    double E = s->builtin_young, nu = s->builtin_poisson, t = s->builtin_thickness;
    double mu = E / (2 * (1 + nu)), lambda = E * nu / (1 - nu * nu), h = s->thickness;
    s->membrane[0] = h * s->s00 - t * (lambda + 2 * mu);
    s->membrane[1] = h * s->s01 - t * lambda;
    s->membrane[2] = h * s->s11 - t * (lambda + 2 * mu);
    s->membrane[3] = h * s->s22 - t * mu;
    double h3 = h * h * h;
    s->bending[0] = h3 * s->b00;
    s->bending[1] = h3 * s->b01;
    s->bending[2] = h3 * s->b11;
    s->bending[3] = h3 * s->b22;
    s->bending_neg[0] = h3 * s->b00_neg;
    s->bending_neg[1] = h3 * s->b11_neg;
  }

  // Rest vertex positions (qpos0) and the flex's reference axes: the first two edges of triangle 0
  // span its plane; the first reference axis is world x projected into that plane, turned by
  // `angle` about the normal to give weft.
  int vadr = m->flex_vertadr[f];
  for (int v = 0; v < s->nvert; v++) {
    double pos[3], quat[4], local[3];
    int body = m->flex_vertbodyid[vadr + v];
    body_position0(m, body, pos, quat);
    mju_rotVecQuat(local, m->flex_vert + 3 * (vadr + v), quat);
    for (int i = 0; i < 3; i++) x0[3 * v + i] = pos[i] + local[i];
  }
  const int* elem = m->flex_elem + m->flex_elemdataadr[f];
  double axis0[3] = {1, 0, 0}, axis1[3] = {0, 1, 0}, normal[3] = {0, 0, 1};
  {
    double a[3], b[3];
    for (int i = 0; i < 3; i++) {
      a[i] = x0[3 * elem[1] + i] - x0[3 * elem[0] + i];
      b[i] = x0[3 * elem[2] + i] - x0[3 * elem[0] + i];
    }
    mju_cross(normal, a, b);
    mju_normalize3(normal);
    // First reference axis: world x projected into the flex plane (world y if x is normal to it).
    double ref[3] = {1, 0, 0};
    if (fabs(normal[0]) > 0.9) { ref[0] = 0; ref[1] = 1; }
    double along = mju_dot3(ref, normal);
    for (int i = 0; i < 3; i++) axis0[i] = ref[i] - along * normal[i];
    mju_normalize3(axis0);
    mju_cross(axis1, normal, axis0);
    double c = cos(s->angle), sn = sin(s->angle), w0[3], w1[3];
    for (int i = 0; i < 3; i++) {
      w0[i] = c * axis0[i] + sn * axis1[i];
      w1[i] = -sn * axis0[i] + c * axis1[i];
    }
    mju_copy3(axis0, w0);
    mju_copy3(axis1, w1);
  }
  int bad = -1, flat = 1;
  for (int t = 0; t < s->ntri && bad < 0; t++) {
    const int* v = elem + 3 * t;
    for (int k = 0; k < 3; k++) s->tri[3 * t + k] = v[k];
    double e1[3], e2[3];
    for (int i = 0; i < 3; i++) {
      e1[i] = x0[3 * v[1] + i] - x0[3 * v[0] + i];
      e2[i] = x0[3 * v[2] + i] - x0[3 * v[0] + i];
    }
    double D00, D01, D10, D11;
    if (s->rest_texcoord) {
      // The pattern: each corner's texture coordinates (u, v) are its material coordinates in its
      // panel (m, weft along u before `angle`); the qpos0 shape is only where the garment starts.
      const int* corner = m->flex_elemtexcoord + m->flex_elemdataadr[f] + 3 * t;
      const float* uv = m->flex_texcoord + 2 * m->flex_texcoordadr[f];
      double c = cos(s->angle), sn = sin(s->angle), du[2], dv[2];
      for (int k = 0; k < 2; k++) {
        du[k] = (double)uv[2 * corner[k + 1]] - (double)uv[2 * corner[0]];
        dv[k] = (double)uv[2 * corner[k + 1] + 1] - (double)uv[2 * corner[0] + 1];
      }
      D00 = c * du[0] + sn * dv[0]; D01 = c * du[1] + sn * dv[1];
      D10 = -sn * du[0] + c * dv[0]; D11 = -sn * du[1] + c * dv[1];
    } else {
      // The rest shape must be flat: the material frame is one plane's, and the bending rest is
      // flat. A vertex off the plane of triangle 0 by more than YF_FLAT_RTOL of the edge length is
      // an error, not a silently foreshortened metric.
      double out = fabs(mju_dot3(e1, normal)) + fabs(mju_dot3(e2, normal));
      if (out > YF_FLAT_RTOL * (mju_norm3(e1) + mju_norm3(e2))) { bad = t; flat = 0; break; }
      // Rest edges in the material frame: D = [[e1.a0, e2.a0], [e1.a1, e2.a1]].
      D00 = mju_dot3(e1, axis0); D01 = mju_dot3(e2, axis0);
      D10 = mju_dot3(e1, axis1); D11 = mju_dot3(e2, axis1);
    }
    double det = D00 * D11 - D01 * D10;
    if (!(fabs(det) > 0)) { bad = t; break; }
    s->rest_inv[4 * t + 0] = D11 / det;
    s->rest_inv[4 * t + 1] = -D01 / det;
    s->rest_inv[4 * t + 2] = -D10 / det;
    s->rest_inv[4 * t + 3] = D00 / det;
    s->area[t] = 0.5 * fabs(det);
    double* r = rest2d + 6 * t;
    r[0] = r[1] = 0;
    r[2] = D00; r[3] = D10; r[4] = D01; r[5] = D11;
  }
  free(x0);
  if (bad >= 0) {
    free(rest2d); free(tri_edge_local);
    shell_free(s);
    if (!flat) {
      mju_error(YF_NAME ": flex %d is not flat at qpos0 (triangle %d leaves the plane of triangle 0); the "
                "plugin needs a flat rest shape (cut garments as flat panels)", f, bad);
    } else {
      mju_error(YF_NAME ": flex %d triangle %d has zero rest area", f, bad);
    }
    return -1;
  }
  int status = build_hinges(m, s, rest2d, tri_edge_local);
  // The split shares the membrane with MuJoCo's isotropic triangles only for triangle strains with
  // the qpos0 rest and no implicit_share; otherwise the plugin removes MuJoCo's part exactly and
  // carries all of it (with implicit_share, after writing that part).
  int exact = s->rest_texcoord || s->node_membrane || s->has_share;
  if (status == 0 && s->has_share) status = write_share(m, s, tri_edge_local);
  if (status == 0 && !exact) status = check_builtin(m, s, tri_edge_local);
  if (status == 0 && exact) status = collect_builtin_membrane(m, s);
  if (status == 0 && s->node_membrane) status = build_domains(m, s);
  if (status == 0) status = collect_builtin_bending(m, s);
  if (status == 0) status = build_drag_return(m, s, tri_edge_local);
  free(rest2d);
  free(tri_edge_local);
  if (status) {
    shell_free(s);
    return -1;
  }
  classify_vertices(m, s);
  int nh = s->nhinge > 0 ? s->nhinge : 1;
  s->grad = malloc(sizeof(double) * 3 * s->nvert);
  s->xdot = malloc(sizeof(double) * 3 * s->nvert);
  s->theta = malloc(sizeof(double) * nh);
  s->theta_rate = malloc(sizeof(double) * nh);
  s->torque = malloc(sizeof(double) * nh);
  s->hinge_grad = malloc(sizeof(double) * 12 * nh);
  if (!s->grad || !s->xdot || !s->theta || !s->theta_rate || !s->torque || !s->hinge_grad) {
    shell_free(s);
    return -1;
  }
  d->plugin_data[instance] = (uintptr_t)s;
  return 0;
}

static void shell_destroy(mjData* d, int instance) {
  shell_free((Shell*)d->plugin_data[instance]);
  d->plugin_data[instance] = 0;
}

// Stress (N/m, Voigt) of the ridges at elastic strain eps and strain rate rate:
// h sum_j c_j [n_j . eps > t_j] (n_j . eps - t_j + damping n_j . rate) n_j, i.e. the ridges' stress
// plus their tangent times damping * rate. With `engaged`, also the signature of the ridges engaged
// at eps (engaged_ridges), found on the way.
static void ridge_stress(const Shell* s, const double eps[3], const double rate[3], double stress[3],
                         uint64_t* engaged) {
  mju_zero3(stress);
  uint64_t hash = 0;
  for (int d = 0; d < s->ndir; d++) {
    const double* n = s->dir + 3 * d;
    double x = mju_dot3(n, eps);
    int last = last_engaged(s, d, x);
    if (last < 0) continue;
    if (engaged) hash = signature_add(hash, last);
    // sum over the engaged j of c_j (x - t_j + damping n . rate)
    double sum = s->knot_c[last] * (x + s->damping * mju_dot3(n, rate)) - s->knot_ct[last];
    mju_addToScl3(stress, n, s->thickness * sum);
  }
  if (engaged) *engaged = hash;
}

// Deformation gradient of one triangle from its rest inverse Dinv and vertex positions x (3 x 3):
// F (12) = its columns F0 (along weft), F1 (along warp), then their rates from the velocities xdot
// (zeros when xdot is NULL).
static void triangle_deformation(const double Dinv[4], const double x[9], const double* xdot, double F[12]) {
  for (int i = 0; i < 3; i++) {
    double e1 = x[3 + i] - x[i], e2 = x[6 + i] - x[i];
    F[i] = e1 * Dinv[0] + e2 * Dinv[2];
    F[3 + i] = e1 * Dinv[1] + e2 * Dinv[3];
    double r1 = xdot ? xdot[3 + i] - xdot[i] : 0, r2 = xdot ? xdot[6 + i] - xdot[i] : 0;
    F[6 + i] = r1 * Dinv[0] + r2 * Dinv[2];
    F[9 + i] = r1 * Dinv[1] + r2 * Dinv[3];
  }
}

// Green strain eps (Voigt: E00, E11, 2 E01) of F (12, columns F0 F1 and their rates), then its
// rate (zeros unless `damped`): eps (6).
static void green_strain(const double F[12], int damped, double eps[6]) {
  const double* F0 = F;
  const double* F1 = F + 3;
  eps[0] = 0.5 * (mju_dot3(F0, F0) - 1);
  eps[1] = 0.5 * (mju_dot3(F1, F1) - 1);
  eps[2] = mju_dot3(F0, F1);
  eps[3] = damped ? mju_dot3(F0, F + 6) : 0;
  eps[4] = damped ? mju_dot3(F1, F + 9) : 0;
  eps[5] = damped ? mju_dot3(F0, F + 9) + mju_dot3(F1, F + 6) : 0;
}

// Membrane stress of a reference area `area` (m^2) at strain eps (6, with its rate): sig (3) =
// area dW/deps for W = (1/2) eps^T C eps (plus the ridges h sum_j (1/2) c_j max(n_j . eps - t_j, 0)^2),
// with the damping stress of the rate added: C times it (so the quadratic part's stress is
// evaluated at eps + damping * rate) and the ridges' tangent times it. With `engaged`, also the
// signature of the ridges engaged at eps (ridge_stress).
static void membrane_stress(const Shell* s, double area, const double eps[6], double sig[3], uint64_t* engaged) {
  const double* c = s->membrane;
  // The quadratic part with its damping, as StVK: C (eps + damping * rate).
  double eps0 = eps[0] + s->damping * eps[3], eps1 = eps[1] + s->damping * eps[4];
  double eps2 = eps[2] + s->damping * eps[5];
  sig[0] = area * (c[0] * eps0 + c[1] * eps1);
  sig[1] = area * (c[1] * eps0 + c[2] * eps1);
  sig[2] = area * c[3] * eps2;
  if (s->nridge > 0) {  // skipped without ridges: the membrane is then StVK to the last bit
    double extra[3];
    ridge_stress(s, eps, eps + 3, extra, engaged);
    mju_addToScl3(sig, extra, area);
  }
}

// G (6) = dW/dF = F P(sig), P = [[sig0, sig2], [sig2, sig1]] (second Piola-Kirchhoff, Voigt order).
static void stress_gradient(const double F[12], const double sig[3], double G[6]) {
  for (int i = 0; i < 3; i++) {
    G[i] = F[i] * sig[0] + F[3 + i] * sig[2];
    G[3 + i] = F[i] * sig[2] + F[3 + i] * sig[1];
  }
}

// Add dW/dx of one triangle's three vertices to grad (3 x 3) from G = dW/dF (6) and its rest
// inverse: dW/de1 = G Dinv^T row 0, dW/de2 = row 1.
static void scatter_gradient(const double Dinv[4], const double G[6], double grad[9]) {
  for (int i = 0; i < 3; i++) {
    double g1 = G[i] * Dinv[0] + G[3 + i] * Dinv[1];
    double g2 = G[i] * Dinv[2] + G[3 + i] * Dinv[3];
    grad[3 + i] += g1;
    grad[6 + i] += g2;
    grad[i] -= g1 + g2;
  }
}

// Membrane forces, into s->grad: per triangle (membrane="triangle"), or per smoothing domain at
// its smoothed strain eps_d = sum over its corners of w eps_t, w = (A_t/3)/A_d, whose stress
// reaches each corner's triangle as w dW/deps_d (membrane="node"). Strains, not deformation
// gradients, are averaged: an average of F over triangles in different tangent planes would see a
// vertex's motion along its triangles' normals (plugins/README.md).
static void membrane_forces(Shell* s, const double* x, const double* xdot) {
  int damped = xdot != NULL;
  for (int t = 0; t < s->ntri; t++) {
    const int* v = s->tri + 3 * t;
    double xt[9], vt[9], F[12], eps[6], sig[3], G[6], gt[9] = {0};
    for (int k = 0; k < 3; k++) {
      mju_copy3(xt + 3 * k, x + 3 * v[k]);
      if (xdot) mju_copy3(vt + 3 * k, xdot + 3 * v[k]);
    }
    double* Ft = s->node_membrane ? s->tri_F + 12 * t : F;
    triangle_deformation(s->rest_inv + 4 * t, xt, xdot ? vt : NULL, Ft);
    green_strain(Ft, damped, s->node_membrane ? s->tri_eps + 6 * t : eps);
    if (s->node_membrane) continue;
    membrane_stress(s, s->area[t], eps, sig, s->tri_engaged ? s->tri_engaged + t : NULL);
    stress_gradient(F, sig, G);
    scatter_gradient(s->rest_inv + 4 * t, G, gt);
    for (int k = 0; k < 3; k++) mju_addTo3(s->grad + 3 * v[k], gt + 3 * k);
  }
  if (!s->node_membrane) return;
  mju_zero(s->domain_eps, 6 * s->ndomain);
  for (int t = 0; t < s->ntri; t++) {
    for (int k = 0; k < 3; k++) {
      int d = s->corner_domain[3 * t + k];
      mju_addToScl(s->domain_eps + 6 * d, s->tri_eps + 6 * t, s->area[t] / (3 * s->domain_area[d]), 6);
    }
  }
  for (int d = 0; d < s->ndomain; d++) {
    membrane_stress(s, s->domain_area[d], s->domain_eps + 6 * d, s->domain_sig + 3 * d, NULL);
  }
  for (int t = 0; t < s->ntri; t++) {
    const int* v = s->tri + 3 * t;
    double G[6], gt[9] = {0}, sig[3] = {0, 0, 0};
    for (int k = 0; k < 3; k++) {
      int d = s->corner_domain[3 * t + k];
      mju_addToScl3(sig, s->domain_sig + 3 * d, s->area[t] / (3 * s->domain_area[d]));
    }
    stress_gradient(s->tri_F + 12 * t, sig, G);
    scatter_gradient(s->rest_inv + 4 * t, G, gt);
    for (int k = 0; k < 3; k++) mju_addTo3(s->grad + 3 * v[k], gt + 3 * k);
  }
}

// membrane="node": the smoothing domains. With rest="qpos0" every triangle has the flex's one
// material frame, so a vertex is one domain. With rest="texcoord" a vertex where panels meet is one
// domain per panel (strains in different panels' material frames cannot be averaged): two triangles sharing an
// edge are in one panel when both its vertices have the same texture coordinates in both and
// their third vertices lie on opposite sides of it in those coordinates (a seam between two
// panels cut from one pattern has equal coordinates but both panels on the same side).
static int build_domains(const mjModel* m, Shell* s) {
  int n = s->ntri, f = s->flex;
  int* panel = malloc(sizeof(int) * (n > 0 ? n : 1));
  s->corner_domain = malloc(sizeof(int) * 3 * (n > 0 ? n : 1));
  s->tri_F = malloc(sizeof(double) * 12 * (n > 0 ? n : 1));
  s->tri_eps = malloc(sizeof(double) * 6 * (n > 0 ? n : 1));
  if (!panel || !s->corner_domain || !s->tri_F || !s->tri_eps) { free(panel); return -1; }
  for (int t = 0; t < n; t++) panel[t] = t;
  if (s->rest_texcoord) {
    int nedge = m->flex_edgenum[f];
    const int* elemedge = m->flex_elemedge + m->flex_elemedgeadr[f];
    const int* corner = m->flex_elemtexcoord + m->flex_elemdataadr[f];
    const float* uv = m->flex_texcoord + 2 * m->flex_texcoordadr[f];
    int* first = malloc(sizeof(int) * (nedge > 0 ? nedge : 1));
    if (!first) { free(panel); return -1; }
    for (int e = 0; e < nedge; e++) first[e] = -1;
    for (int t = 0; t < n; t++) {
      for (int j = 0; j < 3; j++) {
        int e = elemedge[3 * t + j];
        if (first[e] < 0) { first[e] = t; continue; }
        int a = first[e], b = t;
        // The shared vertices' corners in a and b, and each triangle's third corner.
        const int* va = s->tri + 3 * a;
        const int* vb = s->tri + 3 * b;
        int same = 1, ka[2] = {-1, -1}, kb[2] = {-1, -1}, oa = -1, ob = -1, shared = 0;
        for (int i = 0; i < 3; i++) {
          int found = -1;
          for (int l = 0; l < 3; l++) if (vb[l] == va[i]) found = l;
          if (found < 0) { oa = i; continue; }
          ka[shared] = i; kb[shared] = found; shared++;
        }
        for (int l = 0; l < 3; l++) if (l != kb[0] && l != kb[1]) ob = l;
        if (shared != 2) continue;
        for (int q = 0; q < 2; q++) {
          const float* pa = uv + 2 * corner[3 * a + ka[q]];
          const float* pb = uv + 2 * corner[3 * b + kb[q]];
          if (pa[0] != pb[0] || pa[1] != pb[1]) same = 0;
        }
        if (!same) continue;
        const float* p0 = uv + 2 * corner[3 * a + ka[0]];
        const float* p1 = uv + 2 * corner[3 * a + ka[1]];
        const float* qa = uv + 2 * corner[3 * a + oa];
        const float* qb = uv + 2 * corner[3 * b + ob];
        double ex = (double)p1[0] - p0[0], ey = (double)p1[1] - p0[1];
        double side_a = ex * ((double)qa[1] - p0[1]) - ey * ((double)qa[0] - p0[0]);
        double side_b = ex * ((double)qb[1] - p0[1]) - ey * ((double)qb[0] - p0[0]);
        if (side_a * side_b >= 0) continue;  // folded over the edge: two panels
        int ra = a, rb = b;
        while (panel[ra] != ra) ra = panel[ra];
        while (panel[rb] != rb) rb = panel[rb];
        if (ra != rb) panel[ra > rb ? ra : rb] = ra > rb ? rb : ra;
      }
    }
    free(first);
    for (int t = 0; t < n; t++) {
      int r = t;
      while (panel[r] != r) r = panel[r];
      panel[t] = r;
    }
  } else {
    for (int t = 0; t < n; t++) panel[t] = 0;
  }
  // A domain per distinct (vertex, panel): sort-free, through a per-vertex list of panels seen.
  int* head = malloc(sizeof(int) * (s->nvert > 0 ? s->nvert : 1));
  int* next = malloc(sizeof(int) * 3 * (n > 0 ? n : 1));
  int* owner = malloc(sizeof(int) * 3 * (n > 0 ? n : 1));  // domain -> its panel
  if (!head || !next || !owner) { free(panel); free(head); free(next); free(owner); return -1; }
  for (int v = 0; v < s->nvert; v++) head[v] = -1;
  s->ndomain = 0;
  for (int t = 0; t < n; t++) {
    for (int k = 0; k < 3; k++) {
      int v = s->tri[3 * t + k], d = head[v];
      while (d >= 0 && owner[d] != panel[t]) d = next[d];
      if (d < 0) {
        d = s->ndomain++;
        owner[d] = panel[t];
        next[d] = head[v];
        head[v] = d;
      }
      s->corner_domain[3 * t + k] = d;
    }
  }
  free(panel); free(head); free(next); free(owner);
  int nd = s->ndomain > 0 ? s->ndomain : 1;
  s->domain_area = calloc(nd, sizeof(double));
  s->domain_eps = malloc(sizeof(double) * 6 * nd);
  s->domain_sig = malloc(sizeof(double) * 3 * nd);
  if (!s->domain_area || !s->domain_eps || !s->domain_sig) return -1;
  for (int t = 0; t < n; t++) {
    for (int k = 0; k < 3; k++) s->domain_area[s->corner_domain[3 * t + k]] += s->area[t] / 3;
  }
  return 0;
}

// Dihedral angle of hinge (x1 x2 o0 o1), positive when the sheet curves towards its normal, and
// its gradient (4 x 3: x1, x2, o0, o1).
static double hinge_angle(const double* x1, const double* x2, const double* o0, const double* o1, double g[12]) {
  double e[3], a[3], b[3], nA[3], nB[3];
  for (int i = 0; i < 3; i++) {
    e[i] = x2[i] - x1[i];
    a[i] = o0[i] - x1[i];
    b[i] = o1[i] - x1[i];
  }
  mju_cross(nA, e, a);
  mju_cross(nB, b, e);
  double length = mju_norm3(e), cross[3];
  mju_cross(cross, nB, nA);
  double theta = atan2(mju_dot3(cross, e) / length, mju_dot3(nA, nB));
  double qA = mju_dot3(nA, nA), qB = mju_dot3(nB, nB);
  // Projections of the tips onto the edge, measured from x1; from x2 they are less the length.
  double pA1 = mju_dot3(a, e) / length, pB1 = mju_dot3(b, e) / length;
  double pA2 = pA1 - length, pB2 = pB1 - length;
  for (int i = 0; i < 3; i++) {
    double gA = nA[i] / qA, gB = nB[i] / qB;
    g[i] = pA2 * gA + pB2 * gB;
    g[3 + i] = -pA1 * gA - pB1 * gB;
    g[6 + i] = length * gA;
    g[9 + i] = length * gB;
  }
  return theta;
}

// Bending forces: s->grad (nvert x 3) is added to. x, xdot: (nvert x 3) positions and velocities
// (xdot NULL without damping).
static void bending_forces(Shell* s, const double* x, const double* xdot) {
  const double* dm = s->bending;
  for (int h = 0; h < s->nhinge; h++) {
    const int* v = s->hinge + 4 * h;
    double* g = s->hinge_grad + 12 * h;
    s->theta[h] = hinge_angle(x + 3 * v[0], x + 3 * v[1], x + 3 * v[2], x + 3 * v[3], g);
    s->theta_rate[h] = 0;
    if (xdot) {
      double rate = 0;
      for (int k = 0; k < 4; k++) rate += mju_dot3(g + 3 * k, xdot + 3 * v[k]);
      s->theta_rate[h] = s->damping * rate;
    }
    s->torque[h] = 0;
  }
  // dW/dtheta_e = sum over the triangles t bending with e (through their source triangle's
  // operator) of A_t (h^3 B kappa_t) . d kappa_t / d theta_e, B's diagonal on the side of the
  // elastic curvature's sign (signed bending), applied to the curvature plus its damped rate.
  for (int t = 0; t < s->ntri; t++) {
    int src = s->tri_source[t];
    const int* hinge = s->tri_hinge + 3 * src;
    const double* w = s->tri_weight + 9 * src;
    if (hinge[0] < 0 && hinge[1] < 0 && hinge[2] < 0) continue;
    double kappa[3] = {0, 0, 0}, rate[3] = {0, 0, 0};
    for (int k = 0; k < 3; k++) {
      if (hinge[k] < 0) continue;
      for (int i = 0; i < 3; i++) {
        kappa[i] += s->theta[hinge[k]] * w[3 * k + i];
        rate[i] += s->theta_rate[hinge[k]] * w[3 * k + i];
      }
    }
    double d00 = kappa[0] >= 0 ? dm[0] : s->bending_neg[0], d11 = kappa[1] >= 0 ? dm[2] : s->bending_neg[1];
    for (int i = 0; i < 3; i++) kappa[i] += rate[i];
    double moment[3] = {s->area[t] * (d00 * kappa[0] + dm[1] * kappa[1]),
                        s->area[t] * (dm[1] * kappa[0] + d11 * kappa[1]), s->area[t] * dm[3] * kappa[2]};
    for (int k = 0; k < 3; k++) {
      if (hinge[k] >= 0) s->torque[hinge[k]] += mju_dot3(moment, w + 3 * k);
    }
  }
  for (int h = 0; h < s->nhinge; h++) {
    const int* v = s->hinge + 4 * h;
    const double* g = s->hinge_grad + 12 * h;
    for (int k = 0; k < 4; k++) mju_addToScl3(s->grad + 3 * v[k], g + 3 * k, s->torque[h]);
  }
}

// Triangle t's Green strain (Voigt, its rate zero: eps 6) at vertex positions x.
static void triangle_strain(const Shell* s, const double* x, int t, double eps[6]) {
  const int* v = s->tri + 3 * t;
  double xt[9], F[12];
  for (int k = 0; k < 3; k++) mju_copy3(xt + 3 * k, x + 3 * v[k]);
  triangle_deformation(s->rest_inv + 4 * t, xt, NULL, F);
  green_strain(F, 0, eps);
}

// implicit_drag="critical": give back the part K_r of MuJoCo's step drag -h K v that the material's
// soft modes do not need (build_drag_return; a triangle's K_r rebuilt first when the ridges engaged
// at its strain changed): per triangle the force h (1/2) J^T K_r dDelta/dt, dDelta_b/dt = 2 (x_q -
// x_p) . (v_q - v_p), i.e. h (K_r dDelta/dt)_b (x_q - x_p) on edge b's vertex q.
// (mjData.flexedge_velocity is not computed without flex damping.) Only under
// integrator="discrete": the other integrators put no stiffness in the step, so there is no drag.
static void return_drag(const mjModel* m, Shell* s, const double* x, const double* xdot) {
  if (m->opt.integrator != mjINT_DISCRETE) return;
  double h = m->opt.timestep;
  const int* edge = m->flex_edge + 2 * m->flex_edgeadr[s->flex];
  for (int e = 0; e < s->nedge; e++) {
    int p = edge[2 * e], q = edge[2 * e + 1];
    double along[3], speed[3];
    mju_sub3(along, x + 3 * q, x + 3 * p);
    mju_sub3(speed, xdot + 3 * q, xdot + 3 * p);
    s->drag_rate[e] = 2 * mju_dot3(along, speed);
  }
  for (int t = 0; t < s->ntri; t++) {
    if (s->nridge > 0) {
      // The ridges engaged at the triangle's own strain: membrane_forces found them with constant-
      // strain triangles (tri_engaged), its strain is needed again only where they changed.
      double eps[6];
      uint64_t engaged;
      if (s->tri_engaged) {
        engaged = s->tri_engaged[t];
      } else {
        triangle_strain(s, x, t, eps);
        engaged = engaged_ridges(s, eps);
      }
      if (engaged != s->drag_active[t]) {
        if (s->tri_engaged) triangle_strain(s, x, t, eps);
        update_returned_drag(s, t, eps, engaged);
      }
    }
    add_edge_metric_force(s->grad, x, edge, s->drag_elemedge + 3 * t, s->drag_returned + 6 * t, s->drag_rate, h);
  }
}

static void shell_compute(const mjModel* m, mjData* d, int instance, int capability_bit) {
  (void)capability_bit;
  Shell* s = (Shell*)d->plugin_data[instance];
  if (!s) return;
  int vadr = m->flex_vertadr[s->flex], nvert = s->nvert;
  const mjtNum* x = d->flexvert_xpos + 3 * vadr;
  mjtNum* grad = s->grad;
  mju_zero(grad, 3 * nvert);
  mj_markStack(d);
  mjtNum* jac = NULL;
  mjtNum* qfrc = NULL;

  // Vertex velocities, only for damping and the returned drag: sum of slide axes times joint
  // speeds, or the Jacobian.
  int damped = s->damping > 0 || (s->nbuiltin_hinge > 0 && s->builtin_damping > 0);
  mjtNum* xdot = NULL;
  if (damped || s->drag_returned) {
    xdot = s->xdot;
    for (int v = 0; v < nvert; v++) {
      mjtNum* out = xdot + 3 * v;
      mju_zero3(out);
      if (s->slide_only[v]) {
        for (int j = s->vert_dof[v]; j >= 0; j = m->dof_parentid[j]) {
          mju_addToScl3(out, d->xaxis + 3 * m->dof_jntid[j], d->qvel[j]);
        }
      } else {
        if (!jac) jac = mj_stackAllocNum(d, 3 * m->nv);
        mj_jac(m, d, jac, NULL, x + 3 * v, m->flex_vertbodyid[vadr + v]);
        mju_mulMatVec(out, jac, d->qvel, 3, m->nv);
      }
    }
  }

  membrane_forces(s, x, damped ? xdot : NULL);
  if (s->nhinge > 0) bending_forces(s, x, damped ? xdot : NULL);
  if (s->nbuiltin_hinge > 0) remove_builtin_bending(s, x, s->builtin_damping > 0 ? xdot : NULL);
  if (s->builtin_metric) remove_builtin_membrane(m, d, s, x);
  if (s->drag_returned) return_drag(m, s, x, xdot);

  // Forces (minus the gradient) into joint space: slide-only chains directly, others through the
  // vertex Jacobian.
  for (int v = 0; v < nvert; v++) {
    const mjtNum* g = grad + 3 * v;
    if (s->vert_dof[v] < 0) continue;
    if (s->slide_only[v]) {
      for (int j = s->vert_dof[v]; j >= 0; j = m->dof_parentid[j]) {
        d->qfrc_passive[j] -= mju_dot3(d->xaxis + 3 * m->dof_jntid[j], g);
      }
    } else {
      if (!jac) jac = mj_stackAllocNum(d, 3 * m->nv);
      if (!qfrc) qfrc = mj_stackAllocNum(d, m->nv);
      mj_jac(m, d, jac, NULL, x + 3 * v, m->flex_vertbodyid[vadr + v]);
      mju_mulMatTVec(qfrc, jac, g, 3, m->nv);
      mju_subFrom(d->qfrc_passive, qfrc, m->nv);
    }
  }
  mj_freeStack(d);
}

static int shell_nstate(const mjModel* m, int instance) {
  (void)m;
  (void)instance;
  return 0;
}

static void shell_reset(const mjModel* m, mjtNum* plugin_state, void* plugin_data, int instance) {
  (void)m;
  (void)plugin_state;
  (void)plugin_data;
  (void)instance;
}

mjPLUGIN_LIB_INIT(yarnfit_shell) {
  mjpPlugin plugin;
  mjp_defaultPlugin(&plugin);
  plugin.name = YF_NAME;
  plugin.capabilityflags |= mjPLUGIN_PASSIVE;
  plugin.nattribute = kNumAttributes;
  plugin.attributes = kAttributes;
  plugin.nstate = shell_nstate;
  plugin.init = shell_init;
  plugin.destroy = shell_destroy;
  plugin.reset = shell_reset;
  plugin.compute = shell_compute;
  mjp_registerPlugin(&plugin);
}
