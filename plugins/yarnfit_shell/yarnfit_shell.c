// yarnfit.shell: an orthotropic StVK shell for 2D MuJoCo flexes (mjPLUGIN_PASSIVE).
//
// WORK IN PROGRESS (issue 5): membrane only. Bending, damping and the split with MuJoCo's
// built-in isotropic elasticity are still to come; see plugins/README.md.
//
// Membrane, per triangle (linear, constant strain): with rest edge vectors in the material frame
// (weft = first axis, turned by `angle` from the flex's first reference axis) the deformation
// gradient F (3x2) maps rest to current edges; Green strain E = (F^T F - I)/2, Voigt
// eps = (E00, E11, 2 E01); energy A0 (h/2) eps^T S eps with S = [[s00, s01, 0], [s01, s11, 0],
// [0, 0, s22]] (Pa) and A0 the rest area. Forces are minus its gradient, accumulated into
// qfrc_passive through the vertex bodies' Jacobians.

#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include <mujoco/mujoco.h>

#define YF_NAME "yarnfit.shell"

static const char* const kAttributes[] = {
  "s00", "s01", "s11", "s22", "b00", "b01", "b11", "b22", "thickness", "angle", "damping",
};
enum { kNumAttributes = sizeof(kAttributes) / sizeof(kAttributes[0]) };

// Per instance: material, the flex it drives, and per-triangle rest data.
typedef struct {
  double s00, s01, s11, s22, b00, b01, b11, b22, thickness, angle, damping;
  int flex;
  int ntri;
  int* tri;          // (ntri x 3) flex-local vertex ids
  double* rest_inv;  // (ntri x 4) inverse of the rest edge matrix [e1 e2] in the material frame
  double* area;      // (ntri) rest areas (m^2)
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

// Every attribute validated here, in one place.
static int read_config(const mjModel* m, int instance, Shell* s) {
  struct { const char* key; double* value; int required; double fallback; } keys[] = {
    {"s00", &s->s00, 1, 0}, {"s01", &s->s01, 1, 0}, {"s11", &s->s11, 1, 0}, {"s22", &s->s22, 1, 0},
    {"b00", &s->b00, 1, 0}, {"b01", &s->b01, 1, 0}, {"b11", &s->b11, 1, 0}, {"b22", &s->b22, 1, 0},
    {"thickness", &s->thickness, 1, 0}, {"angle", &s->angle, 0, 0}, {"damping", &s->damping, 0, 0},
  };
  for (size_t k = 0; k < sizeof(keys) / sizeof(keys[0]); k++) {
    if (read_number(m, instance, keys[k].key, keys[k].fallback, keys[k].required, keys[k].value)) return -1;
  }
  const char* positive[] = {"s00", "s11", "s22", "b00", "b11", "b22", "thickness"};
  const double values[] = {s->s00, s->s11, s->s22, s->b00, s->b11, s->b22, s->thickness};
  for (int k = 0; k < 7; k++) {
    if (!(values[k] > 0)) {
      mju_error(YF_NAME ": config key '%s' must be positive, got %g", positive[k], values[k]);
      return -1;
    }
  }
  if (s->s01 * s->s01 >= s->s00 * s->s11) {
    mju_error(YF_NAME ": membrane matrix S is not positive definite: s01^2 = %g >= s00*s11 = %g",
                s->s01 * s->s01, s->s00 * s->s11);
    return -1;
  }
  if (s->b01 * s->b01 >= s->b00 * s->b11) {
    mju_error(YF_NAME ": bending matrix B is not positive definite: b01^2 = %g >= b00*b11 = %g",
                s->b01 * s->b01, s->b00 * s->b11);
    return -1;
  }
  if (s->damping < 0) {
    mju_error(YF_NAME ": config key 'damping' must be >= 0 (s), got %g", s->damping);
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
  free(s->tri);
  free(s->rest_inv);
  free(s->area);
  free(s);
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
  Shell* s = calloc(1, sizeof(Shell));
  if (!s) return -1;
  *s = config;
  s->flex = f;
  s->ntri = m->flex_elemnum[f];
  s->tri = malloc(sizeof(int) * 3 * s->ntri);
  s->rest_inv = malloc(sizeof(double) * 4 * s->ntri);
  s->area = malloc(sizeof(double) * s->ntri);
  if (!s->tri || !s->rest_inv || !s->area) { shell_free(s); return -1; }

  // Rest vertex positions (qpos0) and the flex's reference axes: the first two edges of triangle 0
  // span its plane; the first reference axis is the direction of the flex's first edge, turned by
  // `angle` about the normal to give weft.
  int nvert = m->flex_vertnum[f], vadr = m->flex_vertadr[f];
  double* x0 = malloc(sizeof(double) * 3 * nvert);
  if (!x0) { shell_free(s); return -1; }
  for (int v = 0; v < nvert; v++) {
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
  for (int t = 0; t < s->ntri; t++) {
    const int* v = elem + 3 * t;
    for (int k = 0; k < 3; k++) s->tri[3 * t + k] = v[k];
    double e1[3], e2[3];
    for (int i = 0; i < 3; i++) {
      e1[i] = x0[3 * v[1] + i] - x0[3 * v[0] + i];
      e2[i] = x0[3 * v[2] + i] - x0[3 * v[0] + i];
    }
    // Rest edges in the material frame: D = [[e1.a0, e2.a0], [e1.a1, e2.a1]].
    double D00 = mju_dot3(e1, axis0), D01 = mju_dot3(e2, axis0);
    double D10 = mju_dot3(e1, axis1), D11 = mju_dot3(e2, axis1);
    double det = D00 * D11 - D01 * D10;
    if (!(fabs(det) > 0)) {
      free(x0);
      shell_free(s);
      mju_error(YF_NAME ": flex %d triangle %d has zero rest area", f, t);
      return -1;
    }
    s->rest_inv[4 * t + 0] = D11 / det;
    s->rest_inv[4 * t + 1] = -D01 / det;
    s->rest_inv[4 * t + 2] = -D10 / det;
    s->rest_inv[4 * t + 3] = D00 / det;
    s->area[t] = 0.5 * fabs(det);
  }
  free(x0);
  d->plugin_data[instance] = (uintptr_t)s;
  return 0;
}

static void shell_destroy(mjData* d, int instance) {
  shell_free((Shell*)d->plugin_data[instance]);
  d->plugin_data[instance] = 0;
}

// Membrane energy of one triangle and its gradient with respect to the three vertex positions.
// x: (3 x 3) current vertex positions; grad: (3 x 3) out, added to.
static double membrane_triangle(const Shell* s, int t, const double x[9], double grad[9]) {
  const double* Dinv = s->rest_inv + 4 * t;
  double e1[3], e2[3], F0[3], F1[3];
  for (int i = 0; i < 3; i++) {
    e1[i] = x[3 + i] - x[i];
    e2[i] = x[6 + i] - x[i];
  }
  // F = [e1 e2] Dinv: columns F0 (along weft), F1 (along warp).
  for (int i = 0; i < 3; i++) {
    F0[i] = e1[i] * Dinv[0] + e2[i] * Dinv[2];
    F1[i] = e1[i] * Dinv[1] + e2[i] * Dinv[3];
  }
  double E00 = 0.5 * (mju_dot3(F0, F0) - 1), E11 = 0.5 * (mju_dot3(F1, F1) - 1), E01 = 0.5 * mju_dot3(F0, F1);
  double eps0 = E00, eps1 = E11, eps2 = 2 * E01;
  double sig0 = s->s00 * eps0 + s->s01 * eps1, sig1 = s->s01 * eps0 + s->s11 * eps1, sig2 = s->s22 * eps2;
  double scale = s->area[t] * s->thickness;
  double energy = 0.5 * scale * (eps0 * sig0 + eps1 * sig1 + eps2 * sig2);
  // dW/dF = scale * F P, P = [[sig0, sig2], [sig2, sig1]] (second Piola-Kirchhoff in Voigt order).
  double G0[3], G1[3];
  for (int i = 0; i < 3; i++) {
    G0[i] = scale * (F0[i] * sig0 + F1[i] * sig2);
    G1[i] = scale * (F0[i] * sig2 + F1[i] * sig1);
  }
  // dW/de1 = G Dinv^T row 0, dW/de2 = row 1.
  for (int i = 0; i < 3; i++) {
    double g1 = G0[i] * Dinv[0] + G1[i] * Dinv[1];
    double g2 = G0[i] * Dinv[2] + G1[i] * Dinv[3];
    grad[3 + i] += g1;
    grad[6 + i] += g2;
    grad[i] -= g1 + g2;
  }
  return energy;
}

static void shell_compute(const mjModel* m, mjData* d, int instance, int capability_bit) {
  (void)capability_bit;
  const Shell* s = (const Shell*)d->plugin_data[instance];
  if (!s) return;
  int f = s->flex, vadr = m->flex_vertadr[f], nvert = m->flex_vertnum[f];
  mj_markStack(d);
  // Vertex forces first, then one Jacobian per vertex (not one per triangle corner).
  mjtNum* force = mj_stackAllocNum(d, 3 * nvert);
  mjtNum* jac = mj_stackAllocNum(d, 3 * m->nv);
  mjtNum* qfrc = mj_stackAllocNum(d, m->nv);
  mju_zero(force, 3 * nvert);
  for (int t = 0; t < s->ntri; t++) {
    double x[9], grad[9] = {0};
    for (int k = 0; k < 3; k++) mju_copy3(x + 3 * k, d->flexvert_xpos + 3 * (vadr + s->tri[3 * t + k]));
    membrane_triangle(s, t, x, grad);
    for (int k = 0; k < 3; k++) {
      for (int i = 0; i < 3; i++) force[3 * s->tri[3 * t + k] + i] -= grad[3 * k + i];
    }
  }
  for (int v = 0; v < nvert; v++) {
    mj_jac(m, d, jac, NULL, d->flexvert_xpos + 3 * (vadr + v), m->flex_vertbodyid[vadr + v]);
    mju_mulMatTVec(qfrc, jac, force + 3 * v, 3, m->nv);
    mju_addTo(d->qfrc_passive, qfrc, m->nv);
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
