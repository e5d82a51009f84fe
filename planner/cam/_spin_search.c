/* The grid search of spin="reach" (planner/cam/spin_choice.py, _grid_path), compiled: the step costs and the
 * min-plus steps of the dynamic programming in one pass per sample.
 *
 * The numpy implementation (spin_choice._step_costs, then the loop of min-plus steps in _grid_path) is the definition;
 * this is the same arithmetic element by element, without the (n - 1, 8, 2K+1, G) array of step costs (twelve
 * million entries at the NX job's tight frame) and its passes. tests/test_spin_shared.py checks that both give the
 * same paths bit for bit.
 *
 * No -ffast-math, and pyproject.toml turns off the contraction of a * b + c into fused multiply-adds: every operation
 * rounds as numpy's does. No value here is NaN (joints are 0 where not valid), so np.maximum and np.minimum are plain
 * comparisons (fmax and fmin would be library calls).
 */
#define PY_SSIZE_T_CLEAN
#include <Python.h>
#include <math.h>
#include <string.h>

typedef struct {
    double w_travel, w_speed, w_fast, speed_safe, out_of_reach;
} Weights;

/* One min-plus step from sample i to i + 1: D (8, G) the cheapest cost of a path to each node of sample i, Dn
 * those of sample i + 1, back (8, G) the shift index taken. See spin_choice._step_costs for the step cost. */
static void step(Py_ssize_t i, Py_ssize_t n, Py_ssize_t nb, Py_ssize_t G, Py_ssize_t K, const double *q,
                 const unsigned char *valid, const double *node, const double *dt, const double *dX,
                 const double *spin, const double *inv_v, Py_ssize_t free_steps, const Weights *w, const double *D,
                 double *Dn, signed char *back)
{
    const Py_ssize_t S = 2 * K + 1, row = nb * G, joint = n * row;
    const double two_pi = 2.0 * M_PI;
    const int timed = i >= free_steps, stands = dX[i] <= 0.0;
    const double h = dt[i];
    /* top / h > speed_safe needs top > 0.99 speed_safe h (h > 0; rounding is far smaller), top > 1e-9 (h <= 0, where
     * the ratio is inf or 0): the division only where that holds */
    const double screen = h > 0.0 ? 0.99 * w->speed_safe * h : 1e-9;
    for (Py_ssize_t b = 0; b < nb; b++) {
        const double *qa = q + (i + 1) * row + b * G, *qb = q + i * row + b * G;
        const unsigned char *va = valid + (i + 1) * row + b * G, *vb = valid + i * row + b * G;
        double *best = Dn + b * G;
        signed char *kbest = back + b * G;
        for (Py_ssize_t k = 0; k < S; k++) {
            const Py_ssize_t sh = k - K;
            const double sp = timed ? spin[i * S + k] : 0.0;
            const double extra = (stands && k != K) ? w->out_of_reach : 0.0;
            for (Py_ssize_t g = 0; g < G; g++) {
                Py_ssize_t pred = g - sh;
                Py_ssize_t s = pred < 0 ? 0 : (pred > G - 1 ? G - 1 : pred);
                double travel = 0.0, top = 0.0;
                for (int j = 0; j < 6; j++) { /* |dq_j| wrapped: the joints lie in one turn */
                    double d = fabs(qa[j * joint + g] - qb[j * joint + s]);
                    if (d > M_PI)
                        d = two_pi - d;
                    if (j == 3)
                        travel = d;
                    else if (j == 5)
                        travel = travel + d;
                    double r = d * inv_v[j];
                    top = (j == 0 || r > top) ? r : top; /* np.maximum: no NaN here */
                }
                if (!(va[g] && vb[s])) { /* a step from or to a node out of reach costs nothing more than it */
                    travel = travel * 0.0;
                    top = top * 0.0;
                }
                double cost = w->w_travel * travel;
                if (timed) {
                    if (top > screen) {
                        double ratio = h > 0.0 ? top / h : (top > 1e-9 ? INFINITY : 0.0);
                        if (ratio > w->speed_safe) {
                            double m = ratio - w->speed_safe; /* > 0 (np.maximum(0, m) is m) */
                            double speed = w->w_speed * (m * m) + w->w_fast * (ratio > 1.0 ? 1.0 : 0.0);
                            cost = cost + (speed + sp);
                        } else {
                            cost = cost + sp;
                        }
                    } else {
                        cost = cost + sp;
                    }
                }
                cost = cost + extra; /* a shift over a turn in place (x + 0 is x: cost >= 0) */
                if (cost > w->out_of_reach) /* np.minimum: never NaN here */
                    cost = w->out_of_reach;
                if (pred != s)
                    cost = cost + w->out_of_reach;
                double total = D[b * G + s] + cost;
                if (k == 0 || total < best[g]) {
                    best[g] = total;
                    kbest[g] = (signed char)k;
                }
            }
        }
        for (Py_ssize_t g = 0; g < G; g++)
            best[g] = best[g] + node[(i + 1) * row + b * G + g];
    }
}

PyDoc_STRVAR(grid_search_doc,
"grid_search(q, valid, node, dt, dX, spin, inv_v, free, K, weights, D, back)\n\n"
"The min-plus steps of spin_choice._grid_path over all samples: q (6, n, 8, G) float64 joints (0 where not valid),\n"
"valid (n, 8, G) bool, node (n, 8, G) node costs, dt and dX (n - 1,) time and run-coordinate steps, spin (n - 1,\n"
"2K+1) the spin-rate cost of each step and shift (0 in the first `free` steps), inv_v (6,) 1 / speed limits,\n"
"weights (W_TRAVEL, W_SPEED, W_FAST, SPEED_SAFE, OUT_OF_REACH). D (8, G) float64 holds node[0] and is left\n"
"holding the costs at the last sample; back (n - 1, 8, G) int8 gets the shift index of each step.\n"
"Private: called by spin_choice._grid_path, which makes the arrays.");

static PyObject *grid_search(PyObject *self, PyObject *args)
{
    PyObject *objs[9];
    Py_ssize_t free_steps, K;
    Weights w;
    if (!PyArg_ParseTuple(args, "OOOOOOOnn(ddddd)OO", objs, objs + 1, objs + 2, objs + 3, objs + 4, objs + 5,
                          objs + 6, &free_steps, &K, &w.w_travel, &w.w_speed, &w.w_fast, &w.speed_safe,
                          &w.out_of_reach, objs + 7, objs + 8))
        return NULL;
    Py_buffer v[9]; /* q, valid, node, dt, dX, spin, inv_v, D, back; obj NULL where not acquired */
    memset(v, 0, sizeof(v));
    PyObject *result = NULL;
    for (int m = 0; m < 9; m++) {
        int flags = PyBUF_C_CONTIGUOUS | PyBUF_FORMAT | (m >= 7 ? PyBUF_WRITABLE : 0);
        if (PyObject_GetBuffer(objs[m], v + m, flags) < 0)
            goto done;
        Py_ssize_t size = (m == 1 || m == 8) ? 1 : (Py_ssize_t)sizeof(double);
        if (v[m].itemsize != size) {
            PyErr_SetString(PyExc_TypeError, "grid_search: valid and back must have 1-byte items, the rest float64");
            goto done;
        }
    }
    if (v[0].ndim != 4 || v[0].shape[0] != 6 || v[7].ndim != 2) {
        PyErr_SetString(PyExc_ValueError, "grid_search: q must be (6, n, 8, G) and D (8, G)");
        goto done;
    }
    Py_ssize_t n = v[0].shape[1], nb = v[0].shape[2], G = v[0].shape[3], S = 2 * K + 1;
    if (n < 2 || K < 0 || v[1].len != n * nb * G || v[2].len != 8 * n * nb * G || v[3].len != 8 * (n - 1)
        || v[4].len != 8 * (n - 1) || v[5].len != 8 * (n - 1) * S || v[6].len != 8 * 6 || v[7].len != 8 * nb * G
        || v[8].len != (n - 1) * nb * G || nb > 64 || S > 127) {
        PyErr_SetString(PyExc_ValueError, "grid_search: the arrays' shapes do not agree");
        goto done;
    }
    double *D = v[7].buf;
    double *Dn = PyMem_Malloc(sizeof(double) * nb * G);
    if (Dn == NULL) {
        PyErr_NoMemory();
        goto done;
    }
    Py_BEGIN_ALLOW_THREADS
    for (Py_ssize_t i = 0; i < n - 1; i++) {
        step(i, n, nb, G, K, v[0].buf, v[1].buf, v[2].buf, v[3].buf, v[4].buf, v[5].buf, v[6].buf, free_steps, &w,
             D, Dn, (signed char *)v[8].buf + i * nb * G);
        memcpy(D, Dn, sizeof(double) * nb * G);
    }
    Py_END_ALLOW_THREADS
    PyMem_Free(Dn);
    result = Py_None;
    Py_INCREF(result);
done:
    for (int m = 0; m < 9; m++)
        if (v[m].obj != NULL)
            PyBuffer_Release(v + m);
    return result;
}

static PyMethodDef methods[] = {
    {"grid_search", grid_search, METH_VARARGS, grid_search_doc},
    {NULL, NULL, 0, NULL},
};

static struct PyModuleDef module = {
    PyModuleDef_HEAD_INIT, "_spin_search",
    "The grid search of the spin about an axisymmetric tool, compiled (see spin_choice._grid_path).", -1, methods,
};

PyMODINIT_FUNC PyInit__spin_search(void)
{
    return PyModule_Create(&module);
}
