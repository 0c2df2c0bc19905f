/* A hand-written C march of the vddvp scheme (midpoint clock, alpha = 1/2) for separable
 * H = |p|^2/2 + V(q, t): the reference that scripts/benchmarks/bench_march.py times the library against.
 *
 * Interval k: Q = (q_k + q_k+1)/2, P = (p_k + p_k+1)/2, s_k = t_k + tau_k/2,
 *   q_k+1 - q_k - tau_k P = 0,   p_k+1 - p_k + tau_k V_q(Q, s_k) = 0,
 * node k >= 1 (energy equation, at the previous interval's clock s_k-1, plus the drift):
 *   (H(Q_k, P_k, s_k-1) - H(Q_k-1, P_k-1, s_k-1) + drift) / tau_k-1 = 0.
 * Step 0 solves the canonical equations with tau_0 given. Each step: RK4 predictor over the
 * previous step, Newton (|g| <= 1e-14 or |dx| <= 1e-14, at most 30 iterations, dense Gauss
 * elimination with partial pivoting), then the checks the library makes: finite, tau > 0, the
 * unscaled residuals against tol, H at the new node. Compiled by bench_march.py. */
#define _GNU_SOURCE /* sincos */
#include <math.h>
#include <string.h>

#define MAXN 8
#define MAXU (2 * MAXN + 1)

/* 0 paper_pendulum, 1 fpu, 2 henon_heiles */
typedef struct { int kind; int n; double theta[4]; } System;

static void potential(const System* s, const double* q, double t, double* V, double* Vq,
                      double* Vqq, double* Vqt) {
  int n = s->n, i, j;
  for (i = 0; i < n; ++i) { Vq[i] = 0; Vqt[i] = 0; for (j = 0; j < n; ++j) Vqq[i * n + j] = 0; }
  if (s->kind == 0) {
    double eps = s->theta[0], omega = s->theta[1], f = 1 - eps * sin(omega * t);
    *V = (1 - cos(q[0])) * f;
    Vq[0] = sin(q[0]) * f;
    Vqq[0] = cos(q[0]) * f;
    Vqt[0] = sin(q[0]) * (-eps * omega * cos(omega * t));
  } else if (s->kind == 2) {  /* henon_heiles: (x^2 + y^2)/2 + x^2 y - y^3/3 */
    double x = q[0], y = q[1];
    *V = (x * x + y * y) / 2 + x * x * y - y * y * y / 3;
    Vq[0] = x + 2 * x * y;
    Vq[1] = y + x * x - y * y;
    Vqq[0] = 1 + 2 * y; Vqq[1] = 2 * x; Vqq[2] = 2 * x; Vqq[3] = 1 - 2 * y;
  } else {  /* fpu: stiff springs (2i-1, 2i), soft quartic springs (2i, 2i+1), fixed ends */
    double omega = s->theta[0], x[MAXN + 2];
    x[0] = 0; x[n + 1] = 0;
    for (i = 0; i < n; ++i) x[i + 1] = q[i];
    *V = 0;
    for (i = 0; i <= n; ++i) {  /* spring between x[i] and x[i+1] */
      double d = x[i + 1] - x[i], force, stiffness;
      if (i % 2 == 1) { *V += omega * omega / 4 * d * d; force = omega * omega / 2 * d;
                        stiffness = omega * omega / 2; }
      else { *V += d * d * d * d; force = 4 * d * d * d; stiffness = 12 * d * d; }
      if (i >= 1) { Vq[i - 1] -= force; Vqq[(i - 1) * n + i - 1] += stiffness; }
      if (i + 1 <= n) { Vq[i] += force; Vqq[i * n + i] += stiffness; }
      if (i >= 1 && i + 1 <= n) { Vqq[(i - 1) * n + i] -= stiffness;
                                   Vqq[i * n + i - 1] -= stiffness; }
    }
  }
}

static double hamiltonian(const System* s, const double* q, const double* p, double t) {
  double V, Vq[MAXN], Vqq[MAXN * MAXN], Vqt[MAXN], T = 0;
  int i;
  potential(s, q, t, &V, Vq, Vqq, Vqt);
  for (i = 0; i < s->n; ++i) T += p[i] * p[i] / 2;
  return T + V;
}

static void field(const System* s, const double* z, double t, double* dz) {
  double V, Vq[MAXN], Vqq[MAXN * MAXN], Vqt[MAXN];
  int i, n = s->n;
  potential(s, z, t, &V, Vq, Vqq, Vqt);
  for (i = 0; i < n; ++i) { dz[i] = z[n + i]; dz[n + i] = -Vq[i]; }
}

static void rk4(const System* s, const double* z, double t, double h, double* out) {
  double k1[2 * MAXN], k2[2 * MAXN], k3[2 * MAXN], k4[2 * MAXN], y[2 * MAXN];
  int i, m = 2 * s->n;
  field(s, z, t, k1);
  for (i = 0; i < m; ++i) y[i] = z[i] + h / 2 * k1[i];
  field(s, y, t + h / 2, k2);
  for (i = 0; i < m; ++i) y[i] = z[i] + h / 2 * k2[i];
  field(s, y, t + h / 2, k3);
  for (i = 0; i < m; ++i) y[i] = z[i] + h * k3[i];
  field(s, y, t + h, k4);
  for (i = 0; i < m; ++i) out[i] = z[i] + h / 6 * (k1[i] + 2 * k2[i] + 2 * k3[i] + k4[i]);
}

/* Residual and Jacobian of the step from z_a at t_a; x = (z_b, tau) (energy) or z_b (fixed). */
static void residual(const System* s, const double* za, double ta, const double* x, double tau,
                     int energy, double E_prev, double s_prev, double tau_prev, double drift,
                     double* g, double* J) {
  int n = s->n, m = 2 * n + (energy ? 1 : 0), i, j;
  double Q[MAXN], P[MAXN], V, Vq[MAXN], Vqq[MAXN * MAXN], Vqt[MAXN], clock;
  if (energy) tau = x[2 * n];
  for (i = 0; i < n; ++i) { Q[i] = (za[i] + x[i]) / 2; P[i] = (za[n + i] + x[n + i]) / 2; }
  clock = ta + tau / 2;
  potential(s, Q, clock, &V, Vq, Vqq, Vqt);
  memset(J, 0, sizeof(double) * m * m);
  for (i = 0; i < n; ++i) {
    g[i] = x[i] - za[i] - tau * P[i];
    g[n + i] = x[n + i] - za[n + i] + tau * Vq[i];
    J[i * m + i] = 1;
    J[i * m + n + i] = -tau / 2;
    J[(n + i) * m + n + i] = 1;
    for (j = 0; j < n; ++j) J[(n + i) * m + j] = tau / 2 * Vqq[i * n + j];
    if (energy) { J[i * m + 2 * n] = -P[i]; J[(n + i) * m + 2 * n] = Vq[i] + tau / 2 * Vqt[i]; }
  }
  if (energy) {
    double Vs, T = 0;
    potential(s, Q, s_prev, &Vs, Vq, Vqq, Vqt);
    for (i = 0; i < n; ++i) T += P[i] * P[i] / 2;
    g[2 * n] = (T + Vs - E_prev + drift) / tau_prev;
    for (i = 0; i < n; ++i) {
      J[2 * n * m + i] = Vq[i] / 2 / tau_prev;
      J[2 * n * m + n + i] = P[i] / 2 / tau_prev;
    }
  }
}

static void solve(int m, double* J, double* g) {  /* g <- J^-1 g, partial pivoting */
  int c, r, k, best;
  for (c = 0; c < m; ++c) {
    best = c;
    for (r = c + 1; r < m; ++r) if (fabs(J[r * m + c]) > fabs(J[best * m + c])) best = r;
    if (best != c) {
      for (k = 0; k < m; ++k) { double tmp = J[c * m + k]; J[c * m + k] = J[best * m + k];
                                J[best * m + k] = tmp; }
      double tmp = g[c]; g[c] = g[best]; g[best] = tmp;
    }
    for (r = c + 1; r < m; ++r) {
      double f = J[r * m + c] / J[c * m + c];
      if (f == 0) continue;
      for (k = c; k < m; ++k) J[r * m + k] -= f * J[c * m + k];
      g[r] -= f * g[c];
    }
  }
  for (c = m - 1; c >= 0; --c) {
    for (k = c + 1; k < m; ++k) g[c] -= J[c * m + k] * g[k];
    g[c] /= J[c * m + c];
  }
}

static double norm_inf(int m, const double* v) {
  double r = 0; int i;
  for (i = 0; i < m; ++i) r = fmax(r, fabs(v[i]));
  return r;
}

/* March from (t0, z0) until t >= t_end or max_steps; t (max_steps+1), z ((max_steps+1) x 2n),
 * H (max_steps+1). Returns the number of steps taken, or -(step + 1) where a step failed. */
/* The acceptance of a step, the library's (acceptance.py): finite unknowns, tau > 0, the
 * canonical residuals against tol, the energy residual (times the previous step) against tol;
 * adds the step's energy residual to the drift. */
static int accept(int m, int m2, const double* x, const double* g, double tau, double tol,
                  double size, int energy, double tau_prev, double E_prev, double* drift) {
  int i;
  for (i = 0; i < m; ++i) if (!isfinite(x[i])) return 0;
  if (tau <= 0 || norm_inf(m2, g) > tol * size) return 0;
  if (energy) {
    if (fabs(g[m2]) * tau_prev > tol * fmax(1.0, fabs(E_prev))) return 0;
    *drift += g[m2] * tau_prev;
  }
  return 1;
}

/* The system and the first node of a march. */
static void start(System* s, int kind, int n, const double* theta, const double* z0, double t0,
                  double* t, double* z, double* H) {
  int i;
  s->kind = kind; s->n = n;
  for (i = 0; i < 4; ++i) s->theta[i] = theta[i];
  t[0] = t0; memcpy(z, z0, sizeof(double) * 2 * n);
  H[0] = hamiltonian(s, z, z + n, t0);
}

int c_march(int kind, int n, const double* theta, const double* z0, double t0, double tau0,
            double t_end, int max_steps, double tol, double* t, double* z, double* H) {
  System s; int k, i, it, m2 = 2 * n;
  double g[MAXU], J[MAXU * MAXU], x[MAXU], drift = 0;
  start(&s, kind, n, theta, z0, t0, t, z, H);
  for (k = 0; k < max_steps && t[k] < t_end; ++k) {
    const double* za = z + k * m2;
    int energy = k > 0, m = m2 + (energy ? 1 : 0);
    double tau_prev = energy ? t[k] - t[k - 1] : tau0, s_prev = 0, E_prev = 0;
    if (energy) {  /* the previous interval's energy at its clock */
      const double* zp = z + (k - 1) * m2;
      double Q[MAXN], P[MAXN];
      s_prev = t[k - 1] + tau_prev / 2;
      for (i = 0; i < n; ++i) { Q[i] = (zp[i] + za[i]) / 2; P[i] = (zp[n + i] + za[n + i]) / 2; }
      E_prev = hamiltonian(&s, Q, P, s_prev);
    }
    rk4(&s, za, t[k], tau_prev, x);
    x[m2] = tau_prev;
    for (it = 0; it < 30; ++it) {
      residual(&s, za, t[k], x, tau0, energy, E_prev, s_prev, tau_prev, drift, g, J);
      if (norm_inf(m, g) <= 1e-14) break;
      solve(m, J, g);
      for (i = 0; i < m; ++i) x[i] -= g[i];
      if (norm_inf(m, g) <= 1e-14) break;
    }
    residual(&s, za, t[k], x, tau0, energy, E_prev, s_prev, tau_prev, drift, g, J);
    double tau = energy ? x[m2] : tau0, size = fmax(1.0, norm_inf(m2, za));
    if (!accept(m, m2, x, g, tau, tol, size, energy, tau_prev, E_prev, &drift)) return -(k + 1);
    t[k + 1] = t[k] + tau;
    memcpy(z + (k + 1) * m2, x, sizeof(double) * m2);
    H[k + 1] = hamiltonian(&s, x, x + n, t[k + 1]);
  }
  return k;
}

/* ---------------------------------------------------------------------------------------------
 * c_march_fast: the same equations, the same Newton stop (|g|_inf <= 1e-14 or |dx|_inf <= 1e-14,
 * at most 30 iterations) and the same acceptance (finite, tau > 0, unscaled residuals against
 * tol, H at every new node), written as an engineer who wants speed would write it:
 * - what is fixed during a step is computed once per step: the previous interval's energy at its
 *   clock, V's time factor at that clock (the energy equation's), the scales of the checks;
 * - the predictor is chosen by `predictor`: 0 the RK4 step of c_march, 1 one Stormer-Verlet
 *   step (two force evaluations, the first shared with the node's H), 2 extrapolation from the
 *   last three nodes (no evaluation);
 * - n = 1 (paper_pendulum): a kernel with sincos, the 3 x 3 Newton system solved in closed form
 *   (Cramer's rule); other n: the general residual with one potential call per iteration and
 *   dense Gauss elimination with partial pivoting;
 * - the residual after the last Newton update is evaluated without the Jacobian.
 * Returns the number of steps taken, or -(step + 1) where a step failed; iterations (if not
 * NULL) gets the Newton iterations in all.
 * ------------------------------------------------------------------------------------------- */

static double norm2_inf(double a, double b) { return fmax(fmax(0.0, fabs(a)), fabs(b)); }

/* paper_pendulum, one step's residual (and Jacobian if J != NULL); x = (q1, p1, tau). */
static inline void pendulum_residual(const double* th, double q0, double p0, double ta,
                                     const double* x, double f_prev, double E_prev,
                                     double drift, double tau_prev, double* g, double* J) {
  double eps = th[0], omega = th[1], tau = x[2], Q = (q0 + x[0]) / 2, P = (p0 + x[1]) / 2;
  double sQ, cQ, sw, cw, f;
  sincos(Q, &sQ, &cQ);
  sincos(omega * (ta + tau / 2), &sw, &cw);
  f = 1 - eps * sw;
  g[0] = x[0] - q0 - tau * P;
  g[1] = x[1] - p0 + tau * sQ * f;
  g[2] = (P * P / 2 + (1 - cQ) * f_prev - E_prev + drift) / tau_prev;
  if (J) {
    J[0] = 1; J[1] = -tau / 2; J[2] = -P;
    J[3] = tau / 2 * cQ * f; J[4] = 1; J[5] = sQ * f + tau / 2 * sQ * (-eps * omega * cw);
    J[6] = sQ * f_prev / 2 / tau_prev; J[7] = P / 2 / tau_prev; J[8] = 0;
  }
}

static inline void solve3(const double* J, double* g) {  /* g <- J^-1 g, Cramer's rule */
  double c0 = J[4] * J[8] - J[5] * J[7], c1 = J[5] * J[6] - J[3] * J[8],
         c2 = J[3] * J[7] - J[4] * J[6];
  double det = J[0] * c0 + J[1] * c1 + J[2] * c2;
  double x0 = (g[0] * c0 + J[1] * (J[5] * g[2] - g[1] * J[8]) + J[2] * (g[1] * J[7] - J[4] * g[2]))
              / det;
  double x1 = (J[0] * (g[1] * J[8] - J[5] * g[2]) + g[0] * c1 + J[2] * (J[3] * g[2] - g[1] * J[6]))
              / det;
  double x2 = (J[0] * (J[4] * g[2] - g[1] * J[7]) + J[1] * (g[1] * J[6] - J[3] * g[2]) + g[0] * c2)
              / det;
  g[0] = x0; g[1] = x1; g[2] = x2;
}

/* The general residual: as residual(), but where V does not depend on t (fpu) the energy row
 * reuses the one potential call of the canonical rows (the clock does not matter). */
static void general_residual(const System* s, const double* za, double ta, const double* x,
                             int energy, double tau0, double E_prev, double s_prev,
                             double tau_prev, double drift, double* g, double* J) {
  int n = s->n, m = 2 * n + (energy ? 1 : 0), i, j;
  double Q[MAXN], P[MAXN], V, Vq[MAXN], Vqq[MAXN * MAXN], Vqt[MAXN], tau = tau0, T = 0;
  if (s->kind == 0) {
    residual(s, za, ta, x, tau0, energy, E_prev, s_prev, tau_prev, drift, g, J);
    return;
  }
  if (energy) tau = x[2 * n];
  for (i = 0; i < n; ++i) { Q[i] = (za[i] + x[i]) / 2; P[i] = (za[n + i] + x[n + i]) / 2; }
  potential(s, Q, ta + tau / 2, &V, Vq, Vqq, Vqt);
  for (i = 0; i < n; ++i) {
    g[i] = x[i] - za[i] - tau * P[i];
    g[n + i] = x[n + i] - za[n + i] + tau * Vq[i];
  }
  if (energy) {
    for (i = 0; i < n; ++i) T += P[i] * P[i] / 2;
    g[2 * n] = (T + V - E_prev + drift) / tau_prev;
  }
  if (!J) return;
  memset(J, 0, sizeof(double) * m * m);
  for (i = 0; i < n; ++i) {
    J[i * m + i] = 1;
    J[i * m + n + i] = -tau / 2;
    J[(n + i) * m + n + i] = 1;
    for (j = 0; j < n; ++j) J[(n + i) * m + j] = tau / 2 * Vqq[i * n + j];
    if (energy) {
      J[i * m + 2 * n] = -P[i]; J[(n + i) * m + 2 * n] = Vq[i];
      J[2 * n * m + i] = Vq[i] / 2 / tau_prev; J[2 * n * m + n + i] = P[i] / 2 / tau_prev;
    }
  }
}

static void predict(const System* s, int predictor, const double* t, const double* z, int k,
                    double tau_prev, double* x) {
  int n = s->n, m2 = 2 * n, i;
  const double* za = z + k * m2;
  if (predictor == 0 || k < 2) { rk4(s, za, t[k], tau_prev, x); return; }
  if (predictor == 1) {  /* Stormer-Verlet over tau_prev */
    double V, Vq[MAXN], Vqq[MAXN * MAXN], Vqt[MAXN], h = tau_prev, q1[MAXN], ph[MAXN];
    potential(s, za, t[k], &V, Vq, Vqq, Vqt);
    for (i = 0; i < n; ++i) { ph[i] = za[n + i] - h / 2 * Vq[i]; q1[i] = za[i] + h * ph[i]; }
    potential(s, q1, t[k] + h, &V, Vq, Vqq, Vqt);
    for (i = 0; i < n; ++i) { x[i] = q1[i]; x[n + i] = ph[i] - h / 2 * Vq[i]; }
    return;
  }
  {  /* quadratic through nodes k-2, k-1, k, at t_k + tau_prev */
    const double *z0 = z + (k - 2) * m2, *z1 = z + (k - 1) * m2;
    double t0 = t[k - 2], t1 = t[k - 1], t2 = t[k], T = t2 + tau_prev;
    double l0 = (T - t1) * (T - t2) / ((t0 - t1) * (t0 - t2));
    double l1 = (T - t0) * (T - t2) / ((t1 - t0) * (t1 - t2));
    double l2 = (T - t0) * (T - t1) / ((t2 - t0) * (t2 - t1));
    for (i = 0; i < m2; ++i) x[i] = l0 * z0[i] + l1 * z1[i] + l2 * za[i];
  }
}

int c_march_fast(int kind, int n, const double* theta, const double* z0, double t0, double tau0,
                 double t_end, int max_steps, double tol, int predictor, double* t, double* z,
                 double* H, long* iterations) {
  System s; int k, i, it, m2 = 2 * n;
  double g[MAXU], J[MAXU * MAXU], x[MAXU], drift = 0;
  long total = 0;
  start(&s, kind, n, theta, z0, t0, t, z, H);
  for (k = 0; k < max_steps && t[k] < t_end; ++k) {
    const double* za = z + k * m2;
    int energy = k > 0, m = m2 + (energy ? 1 : 0), updated = 0;
    double tau_prev = energy ? t[k] - t[k - 1] : tau0, s_prev = 0, E_prev = 0, f_prev = 0;
    double size = fmax(1.0, norm_inf(m2, za));
    if (energy) {  /* the previous interval's energy at its clock: once per step */
      const double* zp = z + (k - 1) * m2;
      double Q[MAXN], P[MAXN];
      s_prev = t[k - 1] + tau_prev / 2;
      for (i = 0; i < n; ++i) { Q[i] = (zp[i] + za[i]) / 2; P[i] = (zp[n + i] + za[n + i]) / 2; }
      E_prev = hamiltonian(&s, Q, P, s_prev);
      if (kind == 0) f_prev = 1 - s.theta[0] * sin(s.theta[1] * s_prev);
    }
    predict(&s, predictor, t, z, k, tau_prev, x);
    x[m2] = tau_prev;
    if (kind == 0 && energy) {
      for (it = 0; it < 30; ++it) {
        pendulum_residual(s.theta, za[0], za[1], t[k], x, f_prev, E_prev, drift, tau_prev, g, J);
        updated = 0;
        if (fmax(norm2_inf(g[0], g[1]), fabs(g[2])) <= 1e-14) break;
        solve3(J, g);
        x[0] -= g[0]; x[1] -= g[1]; x[2] -= g[2]; updated = 1;
        if (fmax(norm2_inf(g[0], g[1]), fabs(g[2])) <= 1e-14) { ++it; break; }
      }
      if (updated)
        pendulum_residual(s.theta, za[0], za[1], t[k], x, f_prev, E_prev, drift, tau_prev, g, 0);
    } else {
      for (it = 0; it < 30; ++it) {
        general_residual(&s, za, t[k], x, energy, tau0, E_prev, s_prev, tau_prev, drift, g, J);
        updated = 0;
        if (norm_inf(m, g) <= 1e-14) break;
        solve(m, J, g);
        for (i = 0; i < m; ++i) x[i] -= g[i];
        updated = 1;
        if (norm_inf(m, g) <= 1e-14) { ++it; break; }
      }
      if (updated)
        general_residual(&s, za, t[k], x, energy, tau0, E_prev, s_prev, tau_prev, drift, g,
                         kind == 0 ? J : 0);
    }
    total += it;
    double tau = energy ? x[m2] : tau0;
    if (!accept(m, m2, x, g, tau, tol, size, energy, tau_prev, E_prev, &drift)) return -(k + 1);
    t[k + 1] = t[k] + tau;
    memcpy(z + (k + 1) * m2, x, sizeof(double) * m2);
    if (kind == 0) {  /* H at the new node: one sin of the clock, one cos of q */
      H[k + 1] = x[1] * x[1] / 2 + (1 - cos(x[0])) * (1 - s.theta[0] * sin(s.theta[1] * t[k + 1]));
    } else {
      H[k + 1] = hamiltonian(&s, x, x + n, t[k + 1]);
    }
  }
  if (iterations) *iterations = total;
  return k;
}

/* ---------------------------------------------------------------------------------------------
 * c_march_checks: what march() does beyond c_march_fast, on the nodes of a finished march (steps
 * intervals, nodes t[0..steps], z), written as fast as the march above, so that a row
 * "c_march_fast + c_march_checks" does the library's work in C:
 * - the recheck: every canonical residual (canonical, steps x 2n, unscaled) and every energy
 *   residual (energy[k], node k = 1..steps-1), recomputed from the nodes;
 * - the accuracy check's estimates (accuracy.local_error_function): per interval one RK4 step of
 *   the exact flow from z_k over t_k+1 - t_k, d = z_k+1 - RK4, delta[k] = |d|_inf,
 *   scale[k] = max(|z_k|, |z_k+1|), and the global error propagated by the RK4 step's tangent,
 *   e <- M e + d, saturated at 2 max(1, scale); global[k] = |e|_inf after the step;
 * - the site-density weight w = f' H_zz f = p' V_qq p + |V_q|^2 at every node (w[0..steps]).
 * For n = 1 a kernel with sincos: interval k's cos Q and clock factor serve its canonical
 * residuals and the energy residuals at nodes k and k + 1, and the RK4 stage at t_k (sin, cos
 * of q_k and the clock factor) also gives w at node k; other n the general potential().
 * ------------------------------------------------------------------------------------------- */

/* The pendulum's clock factor 1 - eps sin(omega t). */
static inline double pendulum_clock(const double* th, double t) {
  return 1 - th[0] * sin(th[1] * t);
}

/* The pendulum's V_q, V_qq and V at q, with the clock factor f: one sincos of q. */
static inline void pendulum_terms(double q, double f, double* V, double* Vq, double* Vqq) {
  double sq, cq;
  sincos(q, &sq, &cq);
  *V = (1 - cq) * f; *Vq = sq * f; *Vqq = cq * f;
}

void c_march_checks(int kind, int n, const double* theta, int steps, const double* t,
                    const double* z, double* canonical, double* energy, double* delta,
                    double* scale, double* global, double* w) {
  System s;
  int k, i, j, m2 = 2 * n, stage;
  double e[2 * MAXN];
  double cQ_prev = 0, f_prev = 0, T_prev = 0;  /* interval k - 1's cos Q, clock factor, |P|^2/2 */
  double f_node = kind == 0 ? pendulum_clock(theta, t[0]) : 0;  /* the clock factor at t_k */
  s.kind = kind; s.n = n;
  for (i = 0; i < 4; ++i) s.theta[i] = theta[i];
  for (i = 0; i < m2; ++i) e[i] = 0;
  for (k = 0; k < steps; ++k) {
    const double *za = z + k * m2, *zb = za + m2;
    double ta = t[k], tau = t[k + 1] - t[k], clock = ta + tau / 2;
    double Q[MAXN], P[MAXN], V, Vq[MAXN], Vqq[MAXN * MAXN], Vqt[MAXN];
    double y[2 * MAXN], dy[2 * MAXN], kz[4][2 * MAXN], dk[4][2 * MAXN], d[2 * MAXN];
    static const double offset[4] = {0, 0.5, 0.5, 1};
    /* the recheck: interval k's canonical residuals, node k's energy residual (k >= 1) */
    double T = 0, cQ = 0, f_clock = 0;
    for (i = 0; i < n; ++i) { Q[i] = (za[i] + zb[i]) / 2; P[i] = (za[n + i] + zb[n + i]) / 2;
                              T += P[i] * P[i] / 2; }
    if (kind == 0) {  /* one sincos of Q, one sin of the clock: both reused at node k + 1 */
      double sQ;
      sincos(Q[0], &sQ, &cQ);
      f_clock = pendulum_clock(theta, clock);
      Vq[0] = sQ * f_clock;
    } else {
      potential(&s, Q, clock, &V, Vq, Vqq, Vqt);
    }
    for (i = 0; i < n; ++i) {
      canonical[k * m2 + i] = zb[i] - za[i] - tau * P[i];
      canonical[k * m2 + n + i] = zb[n + i] - za[n + i] + tau * Vq[i];
    }
    if (k >= 1) {  /* H of intervals k - 1 and k at interval k - 1's clock */
      double Vp, Vk;
      if (kind == 0) {
        Vk = (1 - cQ) * f_prev; Vp = (1 - cQ_prev) * f_prev;
      } else {
        const double* zp = za - m2;
        double s_prev = (t[k - 1] + t[k]) / 2, Qp[MAXN], Vqd[MAXN], Vqqd[MAXN * MAXN],
               Vqtd[MAXN];
        for (i = 0; i < n; ++i) Qp[i] = (zp[i] + za[i]) / 2;
        potential(&s, Q, s_prev, &Vk, Vqd, Vqqd, Vqtd);
        potential(&s, Qp, s_prev, &Vp, Vqd, Vqqd, Vqtd);
      }
      energy[k] = T + Vk - T_prev - Vp;
    }
    cQ_prev = cQ; f_prev = f_clock; T_prev = T;
    /* RK4 of the exact flow and its tangent applied to e; stage 0 gives w at node k. For the
     * pendulum the stages' clock factors are t_k's (carried), the interval's clock's (stages 1
     * and 2: ta + 0.5 tau is the clock to the bit) and ta + tau's (t_k+1 up to round-off,
     * carried to the next step's stage 0 and w). */
    for (i = 0; i < m2; ++i) { y[i] = za[i]; dy[i] = e[i]; }
    for (stage = 0; stage < 4; ++stage) {
      double ts = ta + offset[stage] * tau, h = offset[stage < 3 ? stage + 1 : 3] * tau;
      if (kind == 0) {
        double f = stage == 0 ? f_node : stage < 3 ? f_clock : pendulum_clock(theta, ts);
        pendulum_terms(y[0], f, &V, Vq, Vqq);
        if (stage == 3) f_node = f;
      } else {
        potential(&s, y, ts, &V, Vq, Vqq, Vqt);
      }
      for (i = 0; i < n; ++i) {
        kz[stage][i] = y[n + i]; kz[stage][n + i] = -Vq[i];
        dk[stage][i] = dy[n + i];
        dk[stage][n + i] = 0;
        for (j = 0; j < n; ++j) dk[stage][n + i] -= Vqq[i * n + j] * dy[j];
      }
      if (stage == 0) {
        double ww = 0;
        for (i = 0; i < n; ++i) {
          ww += Vq[i] * Vq[i];
          for (j = 0; j < n; ++j) ww += za[n + i] * Vqq[i * n + j] * za[n + j];
        }
        w[k] = ww;
      }
      if (stage < 3)
        for (i = 0; i < m2; ++i) { y[i] = za[i] + h * kz[stage][i]; dy[i] = e[i] + h * dk[stage][i]; }
    }
    {
      double dn = 0, en = 0, sa = norm_inf(m2, za), sb = norm_inf(m2, zb), limit, factor;
      for (i = 0; i < m2; ++i) {
        double phi = za[i] + tau / 6 * (kz[0][i] + 2 * kz[1][i] + 2 * kz[2][i] + kz[3][i]);
        d[i] = zb[i] - phi;
        e[i] = e[i] + tau / 6 * (dk[0][i] + 2 * dk[1][i] + 2 * dk[2][i] + dk[3][i]) + d[i];
        dn = fmax(dn, fabs(d[i])); en = fmax(en, fabs(e[i]));
      }
      scale[k] = fmax(sa, sb);
      limit = 2 * fmax(scale[k], 1e-300);
      factor = fmin(1.0, limit / fmax(en, 1e-300));
      for (i = 0; i < m2; ++i) e[i] *= factor;
      delta[k] = dn; global[k] = en * factor;
    }
  }
  {  /* w at the last node */
    const double* zl = z + steps * m2;
    double V, Vq[MAXN], Vqq[MAXN * MAXN], Vqt[MAXN], ww = 0;
    if (kind == 0) pendulum_terms(zl[0], f_node, &V, Vq, Vqq);
    else potential(&s, zl, t[steps], &V, Vq, Vqq, Vqt);
    for (i = 0; i < n; ++i) {
      ww += Vq[i] * Vq[i];
      for (j = 0; j < n; ++j) ww += zl[n + i] * Vqq[i * n + j] * zl[n + j];
    }
    w[steps] = ww;
  }
}

/* ---------------------------------------------------------------------------------------------
 * c_march_sphere: the spherical pendulum in angles (q = (theta, phi), issue 49's 2-dof system
 * with trigonometric terms), H = p1^2/2 + p2^2/(2 sin^2 q1) - cos q1, marched by the same
 * vddvp equations (midpoint, autonomous: interval k's energy at its midpoint equals interval
 * k-1's, plus the drift), the same Newton as the library's chunk (at most 30 iterations; stop
 * when |g|_inf <= 1e-14, or after an update with |dx|_inf <= max(1e-14, 4 eps |x|_inf), the
 * library's test relative to the iterate's round-off, chain_newton.small_update) and the same
 * acceptance (finite, tau > 0, unscaled residuals against tol, H at every new node), written
 * for speed:
 * - one sincos of the midpoint angle per residual, H's derivatives in closed form, the new
 *   interval's H sharing the canonical rows' terms; the previous interval's H once per step;
 * - the 5 x 5 Newton system (4 x 4 for step 0) solved by its pattern (sphere_solve: p2's row
 *   and q2's column eliminated by hand, a 3 x 3 system by Cramer's rule); the residual after
 *   the last update without the Jacobian;
 * - predictor 0: RK4 over the previous step (as the library), 2: extrapolation from the last
 *   three nodes (no evaluation).
 * Returns the number of steps taken, or -(step + 1) where a step failed; iterations (if not
 * NULL) gets the Newton updates in all.
 * ------------------------------------------------------------------------------------------- */

/* H of the spherical pendulum at (q1, p1, p2) given sin and cos of q1. */
static inline double sphere_energy(double s, double c, double p1, double p2) {
  return p1 * p1 / 2 + p2 * p2 / (2 * s * s) - c;
}

/* The Hamiltonian vector field at z = (q1, q2, p1, p2). */
static inline void sphere_field(const double* z, double* dz) {
  double s, c, u;
  sincos(z[0], &s, &c);
  u = 1 / (s * s);
  dz[0] = z[2]; dz[1] = z[3] * u;
  dz[2] = z[3] * z[3] * c * u / s - s; dz[3] = 0;
}

/* One step's residual (and Jacobian, row-major m x m, if J != NULL) from za; x = (z_b, tau)
 * with the energy row (energy != 0), else x = z_b with tau given. */
static inline void sphere_residual(const double* za, const double* x, double tau, int energy,
                                   double E_prev, double drift, double tau_prev, double* g,
                                   double* J) {
  double Q1 = (za[0] + x[0]) / 2, P1 = (za[2] + x[2]) / 2, P2 = (za[3] + x[3]) / 2;
  double s, c, u, Hq1, Hp2;
  int m = energy ? 5 : 4;
  if (energy) tau = x[4];
  sincos(Q1, &s, &c);
  u = 1 / (s * s);
  Hp2 = P2 * u;
  Hq1 = s - P2 * Hp2 * c / s;  /* -p2^2 cos / sin^3 + sin */
  g[0] = x[0] - za[0] - tau * P1;
  g[1] = x[1] - za[1] - tau * Hp2;
  g[2] = x[2] - za[2] + tau * Hq1;
  g[3] = x[3] - za[3];
  if (energy) g[4] = (P1 * P1 / 2 + P2 * Hp2 / 2 - c - E_prev + drift) / tau_prev;
  if (!J) return;
  {
    double Hq1q1 = P2 * P2 * u * (1 + 3 * c * c * u) + c, Hq1p2 = -2 * Hp2 * c / s,
           Hp2q1 = -2 * Hp2 * c / s, h = tau / 2;
    memset(J, 0, sizeof(double) * m * m);
    J[0] = 1; J[2] = -h;
    J[m + 0] = -h * Hp2q1; J[m + 1] = 1; J[m + 3] = -h * u;
    J[2 * m + 0] = h * Hq1q1; J[2 * m + 2] = 1; J[2 * m + 3] = h * Hq1p2;
    J[3 * m + 3] = 1;
    if (energy) {
      J[4] = -P1; J[m + 4] = -Hp2; J[2 * m + 4] = Hq1;
      J[4 * m + 0] = Hq1 / 2 / tau_prev; J[4 * m + 2] = P1 / 2 / tau_prev;
      J[4 * m + 3] = Hp2 / 2 / tau_prev;
    }
  }
}

static void sphere_predict(int predictor, const double* t, const double* z, int k, double h,
                           double* x) {
  const double* za = z + 4 * k;
  int i;
  if (predictor == 2 && k >= 2) {  /* quadratic through nodes k-2, k-1, k at t_k + h */
    const double *z0 = za - 8, *z1 = za - 4;
    double t0 = t[k - 2], t1 = t[k - 1], t2 = t[k], T = t2 + h;
    double l0 = (T - t1) * (T - t2) / ((t0 - t1) * (t0 - t2));
    double l1 = (T - t0) * (T - t2) / ((t1 - t0) * (t1 - t2));
    double l2 = (T - t0) * (T - t1) / ((t2 - t0) * (t2 - t1));
    for (i = 0; i < 4; ++i) x[i] = l0 * z0[i] + l1 * z1[i] + l2 * za[i];
    return;
  }
  {
    double k1[4], k2[4], k3[4], k4[4], y[4];
    sphere_field(za, k1);
    for (i = 0; i < 4; ++i) y[i] = za[i] + h / 2 * k1[i];
    sphere_field(y, k2);
    for (i = 0; i < 4; ++i) y[i] = za[i] + h / 2 * k2[i];
    sphere_field(y, k3);
    for (i = 0; i < 4; ++i) y[i] = za[i] + h * k3[i];
    sphere_field(y, k4);
    for (i = 0; i < 4; ++i) x[i] = za[i] + h / 6 * (k1[i] + 2 * k2[i] + 2 * k3[i] + k4[i]);
  }
}

/* g <- J^-1 g for the Jacobian of sphere_residual, by its pattern: row 3 gives dp2; column 1
 * (q2) has one entry, so dq2 is solved last; rows 0, 2, 4 leave a 3 x 3 system in (q1, p1,
 * tau) (2 x 2 in (q1, p1) without the energy row), solved by Cramer's rule. */
static inline void sphere_solve(int energy, const double* J, double* g) {
  int m = energy ? 5 : 4;
  double dp2 = g[3], b0 = g[0], b2 = g[2] - J[2 * m + 3] * dp2, dq1, dp1, dtau = 0;
  if (energy) {
    double A[9] = {J[0], J[2], J[4], J[2 * m + 0], J[2 * m + 2], J[2 * m + 4],
                   J[4 * m + 0], J[4 * m + 2], 0}, b[3] = {b0, b2, g[4] - J[4 * m + 3] * dp2};
    solve3(A, b);
    dq1 = b[0]; dp1 = b[1]; dtau = b[2];
  } else {
    double det = J[0] * J[2 * m + 2] - J[2] * J[2 * m + 0];
    dq1 = (b0 * J[2 * m + 2] - J[2] * b2) / det;
    dp1 = (J[0] * b2 - J[2 * m + 0] * b0) / det;
  }
  g[1] = g[1] - J[m + 0] * dq1 - J[m + 3] * dp2 - (energy ? J[m + 4] * dtau : 0);
  g[0] = dq1; g[2] = dp1; g[3] = dp2;
  if (energy) g[4] = dtau;
}

int c_march_sphere(const double* z0, double t0, double tau0, double t_end, int max_steps,
                   double tol, int predictor, double* t, double* z, double* H,
                   long* iterations) {
  int k, i, it;
  double g[5], J[25], x[5], drift = 0, unit = 4 * 2.220446049250313e-16;
  long total = 0;
  double s0, c0;
  t[0] = t0; memcpy(z, z0, sizeof(double) * 4);
  sincos(z0[0], &s0, &c0);
  H[0] = sphere_energy(s0, c0, z0[2], z0[3]);
  for (k = 0; k < max_steps && t[k] < t_end; ++k) {
    const double* za = z + 4 * k;
    int energy = k > 0, m = energy ? 5 : 4, updated = 0;
    double tau_prev = energy ? t[k] - t[k - 1] : tau0, E_prev = 0, size = fmax(1.0, norm_inf(4, za));
    if (energy) {  /* the previous interval's energy at its midpoint: once per step */
      const double* zp = za - 4;
      double s, c;
      sincos((zp[0] + za[0]) / 2, &s, &c);
      E_prev = sphere_energy(s, c, (zp[2] + za[2]) / 2, (zp[3] + za[3]) / 2);
    }
    sphere_predict(predictor, t, z, k, tau_prev, x);
    x[4] = tau_prev;
    for (it = 0; it < 30; ++it) {
      sphere_residual(za, x, tau0, energy, E_prev, drift, tau_prev, g, J);
      updated = 0;
      if (norm_inf(m, g) <= 1e-14) break;
      {
        double before = norm_inf(m, x);
        sphere_solve(energy, J, g);
        for (i = 0; i < m; ++i) x[i] -= g[i];
        updated = 1;
        if (norm_inf(m, g) <= fmax(1e-14, unit * before)) { ++it; break; }
      }
    }
    if (updated) sphere_residual(za, x, tau0, energy, E_prev, drift, tau_prev, g, 0);
    total += it;
    {
      double tau = energy ? x[4] : tau0, s, c;
      if (!accept(m, 4, x, g, tau, tol, size, energy, tau_prev, E_prev, &drift)) return -(k + 1);
      t[k + 1] = t[k] + tau;
      memcpy(z + 4 * (k + 1), x, sizeof(double) * 4);
      sincos(x[0], &s, &c);
      H[k + 1] = sphere_energy(s, c, x[2], x[3]);
    }
  }
  if (iterations) *iterations = total;
  return k;
}
