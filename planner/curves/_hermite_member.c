/* The default member of the PH quintic Hermite family (issue 12's rule), one pass per segment.
 *
 * The rule and why: planner/curves/ph_quintic.py, batch_hermite. Its numpy implementation there
 * (_least_energy_block) is the definition; this is the same arithmetic for one segment at a time, so that the
 * four candidates' inner products and the few Gauss nodes most segments need stay in registers instead of being
 * a numpy array pass each (about 90 passes: the numpy rule cost 1.8 times the former rule's whole C1 fit).
 * The constants and the Gauss rules (weights and the matrices that map inner products to node values) come from
 * ph_quintic, so they are written once. tests/test_member_selection.py checks that both implementations choose
 * the same members.
 *
 * No -ffast-math: a cusp (sigma = 0) must give 1 / 0 = inf and 0 * inf = nan, as in numpy; pyproject.toml also turns
 * off the contraction of a * b + c into fused multiply-adds, as numpy rounds both. The members agree with the numpy
 * rule's to round-off (its sums run in BLAS's order), and so do the choices but for exact ties.
 */
#define PY_SSIZE_T_CLEAN
#include <Python.h>
#include <math.h>
#include <string.h>

/* A Gauss rule: K nodes, weights w (K), Ms (K, 6) maps g00 g01 g02 g11 g12 g22 to sigma, Mw (K, 3) maps
 * u01 u02 u12 to W_u (see ph_quintic._energy_matrices). */
typedef struct {
    Py_ssize_t k;
    const double *w, *ms, *mw;
} Rule;

/* A candidate's inner products: g (6) = <A_p, A_q>, uj, uk (3) = <A_p u, A_q> for u = j, k. */
typedef struct {
    double g[6], uj[3], uk[3];
} Products;

/* ph_quintic._energies_at_nodes for one candidate: 4 int (W_j^2 + W_k^2) / sigma^3 dt + tie int dt / sigma by the
 * rule, inf where that is not a number (a cusp at a node). */
static double estimate(const Products *p, const Rule *r, double tie)
{
    double acc = 0.0, acct = 0.0;
    for (Py_ssize_t n = 0; n < r->k; n++) {
        const double *ms = r->ms + 6 * n, *mw = r->mw + 3 * n;
        double s = ms[0] * p->g[0] + ms[1] * p->g[1] + ms[2] * p->g[2] + ms[3] * p->g[3] + ms[4] * p->g[4]
                   + ms[5] * p->g[5];
        double wj = mw[0] * p->uj[0] + mw[1] * p->uj[1] + mw[2] * p->uj[2];
        double wk = mw[0] * p->uk[0] + mw[1] * p->uk[1] + mw[2] * p->uk[2];
        double inv = 1.0 / fabs(s);
        acc += r->w[n] * ((wj * wj + wk * wk) * (inv * inv * inv));
        acct += r->w[n] * inv;
    }
    double e = 4.0 * acc + tie * acct;
    return e >= 0.0 ? e : INFINITY;
}

static double dot4(const double *p, const double *q)
{
    return p[0] * q[0] + p[1] * q[1] + p[2] * q[2] + p[3] * q[3];
}

/* <p i, q>, <p j, q> and <p k, q>: p i = (-p1, p0, p3, -p2), p j = (-p2, -p3, p0, p1), p k = (-p3, p2, -p1, p0)
 * (ph_quintic._RPERM, _RSIGN) */
static double doti(const double *p, const double *q)
{
    return -p[1] * q[0] + p[0] * q[1] + p[3] * q[2] - p[2] * q[3];
}

static double dotj(const double *p, const double *q)
{
    return -p[2] * q[0] - p[3] * q[1] + p[0] * q[2] + p[1] * q[3];
}

static double dotk(const double *p, const double *q)
{
    return -p[3] * q[0] + p[2] * q[1] - p[1] * q[2] + p[0] * q[3];
}

/* q e^{i phi} (ph_quintic._times_e_i), c = cos phi, s = sin phi */
static void times_e_i(const double *q, double c, double s, double *out)
{
    out[0] = c * q[0] - s * q[1];
    out[1] = c * q[1] + s * q[0];
    out[2] = c * q[2] + s * q[3];
    out[3] = c * q[3] - s * q[2];
}

/* ph_quintic._member: A0 = a0 e^{i phi0}, A2 = a2 e^{i phi0}, A1 = -(3/4)(A0 + A2) + Q / 4, into A (12). */
static void member(const double *a0, const double *a2, const double *q, double c, double s, double *A)
{
    times_e_i(a0, c, s, A);
    times_e_i(a2, c, s, A + 8);
    for (int m = 0; m < 4; m++)
        A[4 + m] = (A[m] + A[8 + m]) * -0.75 + 0.25 * q[m];
}

static void products(const double *A, Products *p)
{
    const double *A0 = A, *A1 = A + 4, *A2 = A + 8;
    p->g[0] = dot4(A0, A0);
    p->g[1] = dot4(A0, A1);
    p->g[2] = dot4(A0, A2);
    p->g[3] = dot4(A1, A1);
    p->g[4] = dot4(A1, A2);
    p->g[5] = dot4(A2, A2);
    p->uj[0] = dotj(A0, A1);
    p->uj[1] = dotj(A0, A2);
    p->uj[2] = dotj(A1, A2);
    p->uk[0] = dotk(A0, A1);
    p->uk[1] = dotk(A0, A2);
    p->uk[2] = dotk(A1, A2);
}

/* ph_quintic._reduced_products for one candidate: its products replaced by those of T A (T 3 x 3, row-major), the
 * Bernstein coefficients of the reduced curve of a member with a zero end tangent (ph_quintic._REDUCE). */
static void reduce_products(Products *p, const double *T)
{
    static const int gp[6][2] = {{0, 0}, {0, 1}, {0, 2}, {1, 1}, {1, 2}, {2, 2}}, up[3][2] = {{0, 1}, {0, 2}, {1, 2}};
    double G[3][3], U[2][3][3];
    for (int q = 0; q < 6; q++)
        G[gp[q][0]][gp[q][1]] = G[gp[q][1]][gp[q][0]] = p->g[q];
    for (int v = 0; v < 2; v++) {
        const double *u = v ? p->uk : p->uj;
        for (int a = 0; a < 3; a++)
            U[v][a][a] = 0.0;
        for (int q = 0; q < 3; q++) {
            U[v][up[q][0]][up[q][1]] = u[q];
            U[v][up[q][1]][up[q][0]] = -u[q];
        }
    }
    for (int q = 0; q < 6; q++) { /* (T G T^T)_jk = sum_ab T_ja T_kb G_ab */
        int j = gp[q][0], k = gp[q][1];
        double acc = 0.0;
        for (int a = 0; a < 3; a++)
            for (int b = 0; b < 3; b++)
                acc += T[3 * j + a] * T[3 * k + b] * G[a][b];
        p->g[q] = acc;
    }
    for (int v = 0; v < 2; v++) {
        double *u = v ? p->uk : p->uj;
        for (int q = 0; q < 3; q++) {
            int j = up[q][0], k = up[q][1];
            double acc = 0.0;
            for (int a = 0; a < 3; a++)
                for (int b = 0; b < 3; b++)
                    acc += T[3 * j + a] * T[3 * k + b] * U[v][a][b];
            u[q] = acc;
        }
    }
}

/* ph_quintic._REDUCE: zero tangent at t = 1, at t = 0, at both */
static const double REDUCE_END[9] = {1.0, 0.0, 0.0, 0.5, 1.0, 0.0, 0.0, 2.0, 0.0};
static const double REDUCE_START[9] = {0.0, 2.0, 0.0, 0.0, 1.0, 0.5, 0.0, 0.0, 1.0};
static const double REDUCE_BOTH[9] = {0.0, 2.0, 0.0, 0.0, 2.0, 0.0, 0.0, 2.0, 0.0};

/* ph_quintic.sqrt_rot for one vector v: Q with Q i Q* = v; returns |v|. */
static void sqrt_rot(const double *v, double *q)
{
    double l = v[0], m = v[1], n = v[2];
    double r = sqrt(l * l + m * m + n * n);
    double h = r + fabs(l);
    double k = 1.0 / sqrt(fmax(h + h, 1e-300));
    double x0 = h * k, x2 = n * -k, x3 = m * k;
    if (l < 0.0) { /* _FLIP */
        q[0] = x2, q[1] = x3, q[2] = x0, q[3] = 0.0;
    } else {
        q[0] = x0, q[1] = 0.0, q[2] = x2, q[3] = x3;
    }
}

typedef struct {
    double screen_factor, tie, axis_fallback, axis_fade, equal;
    Rule screen, screen_lo, full, full_lo;
} Constants;

/* ph_quintic._even_exponent: the even e with x 2^-e in [0.5, 2) for a positive finite x; 0 for 0, inf or nan. */
static int even_exponent(double x)
{
    int e = 0;
    if (isfinite(x))
        frexp(x, &e);
    return e & ~1;
}

/* ph_quintic._pure_vector_axis (with _blended_axis) for one segment: (c, s) of delta0; r0, r1 = |a0|^2, |a2|^2.
 * The operands scaled by powers of two as there (exact: every operation rounds as unscaled wherever that neither
 * under- nor overflows, and none does whatever the sizes of the tangents and the chord). */
static void pure_vector_axis(const double *R, double r0, double r1, const double *dp, const Constants *k, double *c,
                             double *s)
{
    int e0 = even_exponent(r0), e1 = even_exponent(r1), e = (e0 + e1) / 2;
    double lam = ldexp(r0, -e0) * ldexp(r1, -e1);
    double sc = ldexp(R[3], -e), ss = ldexp(R[7], -e);
    double s2 = sc * sc + ss * ss;
    if (s2 >= k->axis_fade * lam && s2 > 0.0) {
        double h = 1.0 / sqrt(s2);
        h = copysign(h, fabs(ss) >= fabs(sc) ? -ss : sc);
        *c = -ss * h;
        *s = sc * h;
        return;
    }
    double m = fmax(fabs(dp[0]), fmax(fabs(dp[1]), fabs(dp[2])));
    int f = even_exponent(m);
    double u[3] = {ldexp(dp[0], -f), ldexp(dp[1], -f), ldexp(dp[2], -f)};
    double bc = ldexp(R[0], -e) * u[0] + ldexp(R[1], -e) * u[1] + ldexp(R[2], -e) * u[2];
    double bs = ldexp(R[4], -e) * u[0] + ldexp(R[5], -e) * u[1] + ldexp(R[6], -e) * u[2];
    double w = k->axis_fallback * (1.0 - s2 / (k->axis_fade * lam))
               / (lam * (u[0] * u[0] + u[1] * u[1] + u[2] * u[2]));
    if (!isfinite(w))
        w = 0.0;
    double il = lam > 0.0 ? 1.0 / lam : 0.0;
    double Dx = (ss * ss - sc * sc) * il + (bc * bc - bs * bs) * w;
    double Dy = (-2.0 * il) * ss * sc + (2.0 * w) * bc * bs;
    double r = hypot(Dx, Dy);
    double x = Dx >= 0.0 ? r + Dx : Dy, y = Dx >= 0.0 ? Dy : r - Dx;
    double n = hypot(x, y);
    *c = n > 0.0 ? x / n : 1.0;
    *s = n > 0.0 ? y / n : 0.0;
}

/* ph_quintic._rank_close for one segment: the best candidate among those whose screening estimates est are
 * within the factor of the best one's (index b), by the full rule. */
static int rank_close(const Products *p, const double *est, int b, const Constants *k)
{
    double lim = k->screen_factor * est[b];
    int in[4];
    for (int q = 0; q < 4; q++)
        in[q] = est[q] < lim;
    if (!in[b])
        return 0; /* no candidate within the factor: the best estimate is 0 or infinite */
    double E[4] = {INFINITY, INFINITY, INFINITY, INFINITY};
    E[b] = estimate(p + b, &k->full, k->tie);
    double low = INFINITY;
    for (int q = 0; q < 4; q++)
        if (in[q] && q != b) {
            double lo = estimate(p + q, &k->full_lo, k->tie);
            low = lo < low ? lo : low;
        }
    if (low > E[b] * (1.0 + 1e-9))
        return b;
    for (int q = 0; q < 4; q++)
        if (in[q] && q != b)
            E[q] = estimate(p + q, &k->full, k->tie);
    double least = E[0];
    for (int q = 1; q < 4; q++)
        least = E[q] < least ? E[q] : least;
    least *= 1.0 + k->equal; /* the first of the equal least energies (ph_quintic._EQUAL) */
    for (int q = 0; q < 4; q++)
        if (E[q] <= least)
            return q;
    return 0;
}

/* ph_quintic._screen for one segment. */
static int choose(const Products *p, const Constants *k)
{
    double est[4];
    est[0] = estimate(p, &k->screen, k->tie);
    int open = 0;
    for (int q = 1; q < 4 && !open; q++)
        open = !(estimate(p + q, &k->screen_lo, k->tie) > (k->screen_factor * (1.0 + 1e-9)) * est[0]);
    if (!open)
        return 0;
    for (int q = 1; q < 4; q++)
        est[q] = estimate(p + q, &k->screen, k->tie);
    int b = 0;
    for (int q = 1; q < 4; q++)
        if (est[q] < est[b])
            b = q;
    double others = INFINITY;
    for (int q = 0; q < 4; q++)
        if (q != b && est[q] < others)
            others = est[q];
    if (others > k->screen_factor * est[b])
        return b;
    return rank_close(p, est, b, k);
}

/* ph_quintic._least_energy_block for segment i of the rows X (16, n): writes A (3, 4) times rs. */
static void segment(const double *X, Py_ssize_t n, Py_ssize_t i, double rs, const Constants *k, double *out)
{
    double dp[3], base[3], a0[4], a2[4];
    for (int m = 0; m < 3; m++) {
        dp[m] = X[m * n + i];
        base[m] = X[(3 + m) * n + i];
    }
    for (int m = 0; m < 4; m++) {
        a0[m] = X[(6 + m) * n + i];
        a2[m] = X[(10 + m) * n + i];
    }
    double r0 = X[14 * n + i], r1 = X[15 * n + i];
    const double *p = a0, *q = a2;
    double R[8] = { /* rows 0-7 of ph_quintic._PRODUCTS: a0 i a2* (Sc, sc) and a0 a2* (Ss, ss) */
        p[0] * q[0] + p[1] * q[1] - p[2] * q[2] - p[3] * q[3],
        p[1] * q[2] + p[2] * q[1] + p[0] * q[3] + p[3] * q[0],
        p[1] * q[3] + p[3] * q[1] - p[0] * q[2] - p[2] * q[0],
        p[0] * q[1] - p[1] * q[0] + p[3] * q[2] - p[2] * q[3],
        p[1] * q[0] - p[0] * q[1] + p[3] * q[2] - p[2] * q[3],
        p[2] * q[0] - p[0] * q[2] + p[1] * q[3] - p[3] * q[1],
        p[3] * q[0] - p[0] * q[3] + p[2] * q[1] - p[1] * q[2],
        p[0] * q[0] + p[1] * q[1] + p[2] * q[2] + p[3] * q[3],
    };
    double c, s;
    pure_vector_axis(R, r0, r1, dp, k, &c, &s);
    double a2d[2][4]; /* a2 e^{i delta0} and its negative (delta0 + pi) */
    times_e_i(a2, c, s, a2d[0]);
    for (int m = 0; m < 4; m++)
        a2d[1][m] = -a2d[0][m];
    double Q[2][4], cs[2][2];
    for (int j = 0; j < 2; j++) {
        double alpha[3];
        for (int m = 0; m < 3; m++) {
            double S = (R[m] * c + R[4 + m] * s) * 10.0;
            alpha[m] = j ? base[m] - S : base[m] + S;
        }
        sqrt_rot(alpha, Q[j]);
        /* <(a0 + A2's root) e^{i phi0}, Q> = x cos + y sin: the maximum at atan2(y, x) */
        double x = dot4(a0, Q[j]) + dot4(a2d[j], Q[j]), y = doti(a0, Q[j]) + doti(a2d[j], Q[j]);
        double ih = 1.0 / sqrt(x * x + y * y);
        int ok = isfinite(ih);
        cs[j][0] = ok ? x * ih : 1.0;
        cs[j][1] = ok ? y * ih : 0.0;
    }
    double A[4][12];
    Products P[4];
    for (int q4 = 0; q4 < 4; q4++) { /* candidate 2 (delta index) + (phi0 + pi) */
        int j = q4 / 2;
        double sign = q4 % 2 ? -1.0 : 1.0;
        member(a0, a2d[j], Q[j], sign * cs[j][0], sign * cs[j][1], A[q4]);
        products(A[q4], P + q4);
    }
    if (r0 == 0.0 || r1 == 0.0) { /* a zero end tangent: the reduced curves decide (ph_quintic._reduced_products) */
        const double *T = r0 != 0.0 ? REDUCE_END : r1 != 0.0 ? REDUCE_START : REDUCE_BOTH;
        for (int q4 = 0; q4 < 4; q4++)
            reduce_products(P + q4, T);
    }
    int b = choose(P, k);
    for (int m = 0; m < 12; m++)
        out[m] = A[b][m] * rs;
}

static int rule_from(PyObject *tuple, Rule *r, Py_buffer *views, const char *name)
{
    if (!PyTuple_Check(tuple) || PyTuple_GET_SIZE(tuple) != 3) {
        PyErr_Format(PyExc_TypeError, "%s must be a tuple (w, Ms, Mw)", name);
        return -1;
    }
    for (int m = 0; m < 3; m++)
        if (PyObject_GetBuffer(PyTuple_GET_ITEM(tuple, m), views + m, PyBUF_C_CONTIGUOUS | PyBUF_FORMAT) < 0)
            return -1;
    r->k = views[0].len / (Py_ssize_t)sizeof(double);
    r->w = views[0].buf;
    r->ms = views[1].buf;
    r->mw = views[2].buf;
    if (views[1].len != 6 * views[0].len || views[2].len != 3 * views[0].len) {
        PyErr_Format(PyExc_ValueError, "%s: Ms must be (K, 6) and Mw (K, 3) for K weights", name);
        return -1;
    }
    return 0;
}

PyDoc_STRVAR(least_energy_members_doc,
"least_energy_members(X, root_scale, out, screen_factor, tie, axis_fallback, axis_fade, equal, screen, screen_lo,\n"
"                     full, full_lo)\n\n"
"Writes A (N, 3, 4) of each segment's default member, times root_scale (N,), into out (float64, C order).\n"
"X (16, N): rows dp = p1 - p0 (3), base = 120 dp - 15 (d0 + d1) (3), a0 (4), a2 (4), |d0|, |d1|; the rules\n"
"are (w, Ms, Mw) of ph_quintic._energy_matrices (_SCREEN_RULE, _SCREEN_BOUND, _FULL_RULE, _FULL_BOUND).\n"
"Private: called by ph_quintic.hermite_rows, which checks the shapes.");

static PyObject *least_energy_members(PyObject *self, PyObject *args)
{
    PyObject *x, *rs, *o, *rules[4];
    Constants k;
    if (!PyArg_ParseTuple(args, "OOOdddddOOOO", &x, &rs, &o, &k.screen_factor, &k.tie, &k.axis_fallback,
                          &k.axis_fade, &k.equal, rules, rules + 1, rules + 2, rules + 3))
        return NULL;
    Py_buffer views[15]; /* X, root_scale, out, then (w, Ms, Mw) of each rule; obj NULL where not acquired */
    memset(views, 0, sizeof(views));
    PyObject *result = NULL;
    Rule *targets[4] = {&k.screen, &k.screen_lo, &k.full, &k.full_lo};
    const char *names[4] = {"screen", "screen_lo", "full", "full_lo"};
    if (PyObject_GetBuffer(x, views, PyBUF_C_CONTIGUOUS | PyBUF_FORMAT) < 0
        || PyObject_GetBuffer(rs, views + 1, PyBUF_C_CONTIGUOUS | PyBUF_FORMAT) < 0
        || PyObject_GetBuffer(o, views + 2, PyBUF_C_CONTIGUOUS | PyBUF_FORMAT | PyBUF_WRITABLE) < 0)
        goto done;
    for (int r = 0; r < 4; r++)
        if (rule_from(rules[r], targets[r], views + 3 + 3 * r, names[r]) < 0)
            goto done;
    for (int m = 0; m < 15; m++)
        if (views[m].itemsize != (Py_ssize_t)sizeof(double) || strcmp(views[m].format, "d") != 0) {
            PyErr_SetString(PyExc_TypeError, "least_energy_members: every array must be float64");
            goto done;
        }
    Py_ssize_t n = views[1].len / (Py_ssize_t)sizeof(double);
    if (views[0].len != 16 * views[1].len || views[2].len != 12 * views[1].len) {
        PyErr_SetString(PyExc_ValueError, "least_energy_members: X must be (16, N) and out (N, 3, 4) for N root scales");
        goto done;
    }
    const double *X = views[0].buf, *scale = views[1].buf;
    double *out = views[2].buf;
    Py_BEGIN_ALLOW_THREADS
    for (Py_ssize_t i = 0; i < n; i++)
        segment(X, n, i, scale[i], &k, out + 12 * i);
    Py_END_ALLOW_THREADS
    result = Py_None;
    Py_INCREF(result);
done:
    for (int m = 0; m < 15; m++)
        if (views[m].obj != NULL)
            PyBuffer_Release(views + m);
    return result;
}

static PyMethodDef methods[] = {
    {"least_energy_members", least_energy_members, METH_VARARGS, least_energy_members_doc},
    {NULL, NULL, 0, NULL},
};

static struct PyModuleDef module = {
    PyModuleDef_HEAD_INIT, "_hermite_member",
    "The default member of the PH quintic Hermite family, compiled (see ph_quintic.batch_hermite).", -1, methods,
};

PyMODINIT_FUNC PyInit__hermite_member(void)
{
    return PyModule_Create(&module);
}
