/* The tracker's optional C kernel (see gcs_utm/core/tracking/kernel.py, which puts it and
 * the NumPy reference behind one function each).
 *
 * update_rows(): the common round, in which every measurement of a batch updates its own
 * track: the same checks (out of order, duplicate, gate, a gap after which the track
 * restarts) as Tracker._round and kalman.step's arithmetic per row, the same IEEE double operations in the same order, so the results are
 * equal bit for bit (tests compare the two; build with -ffp-contract=off so that no
 * multiply-add is fused). It changes nothing and returns False as soon as one measurement
 * would not simply update its track, or a division would be by zero (NumPy's inf/nan): the
 * NumPy round decides then.
 *
 * entry_records(): kernel.check_entries.
 *
 * The layouts are those of gcs_utm/core/tracking/layout.py; the module exports its copy as
 * LAYOUT, which kernel.py compares with layout.C_LAYOUT at import.
 *
 * Only the buffer protocol is used (no NumPy headers): the arrays are passed as they are, and
 * their layout is checked against what the tracker keeps (C-contiguous, float64 / intp /
 * int64 / bool).
 */
#define PY_SSIZE_T_CLEAN
#include <Python.h>
#include <math.h>
#include <stdint.h>
#include <string.h>

/* The record layout of layout.py (REC_*). */
enum { C_T = 0, C_E = 1, C_N = 2, C_U = 3, C_VE = 4, C_R = 7, C_RV = 10, C_SRC = 13, C_HV = 14,
       NCOL = 15 };

typedef struct {
    Py_buffer b;
    int held;
} Buf;

static int get(PyObject *o, Buf *buf, const char *name, Py_ssize_t itemsize, Py_ssize_t n,
               int writable) {
    int flags = PyBUF_C_CONTIGUOUS | PyBUF_FORMAT | (writable ? PyBUF_WRITABLE : 0);
    if (PyObject_GetBuffer(o, &buf->b, flags) < 0) return -1;
    buf->held = 1;
    if (buf->b.itemsize != itemsize || (n >= 0 && buf->b.len < n * itemsize)) {
        PyErr_Format(PyExc_ValueError, "update_rows: %s has items of %zd bytes and %zd bytes in "
                     "all, expected %zd-byte items and at least %zd of them",
                     name, buf->b.itemsize, buf->b.len, itemsize, n);
        return -1;
    }
    return 0;
}

static void release(Buf *bufs, int n) {
    for (int i = 0; i < n; i++)
        if (bufs[i].held) PyBuffer_Release(&bufs[i].b);
}

/* kalman.step (positions already predicted) on one row: x[6] (pos, vel per axis), p[9] (pp,
 * pv, vv per axis). Returns 0 when a divisor is zero (nothing written), 1 otherwise. */
static int step_row(double *x, double *p, double dt, const double *q, const double *z,
                    const double *r, const double *zv, double rv) {
    double out_x[6], out_p[9];
    double dt2 = dt * dt;
    double dt4 = dt2 * dt2 / 4.0;
    double dt3 = dt2 * dt / 2.0;
    double two_dt = 2.0 * dt;
    for (int axis = 0; axis < 3; axis++) {
        int i = 2 * axis, j = 3 * axis;
        double pos = x[i], vel = x[i + 1];
        double a = p[j], b = p[j + 1], c = p[j + 2];
        double qa = q[axis], ra = r[axis];
        a = a + two_dt * b + dt2 * c + qa * dt4;
        b = b + dt * c + qa * dt3;
        c = c + qa * dt2;
        if (zv == NULL) {
            double s = a + ra;
            if (s == 0.0) return 0;
            double y = z[axis] - pos;
            double k_vel = b / s;
            out_x[i] = pos + a / s * y;
            out_x[i + 1] = vel + k_vel * y;
            double rs = ra / s;
            out_p[j] = a * rs;
            out_p[j + 1] = b * rs;
            out_p[j + 2] = c - b * k_vel;
            continue;
        }
        double s11 = a + ra;
        double s22 = c + rv;
        double bb = b * b;
        double det = s11 * s22 - bb;
        if (det == 0.0) return 0;
        double k11 = (a * s22 - bb) / det;
        double k12 = (b * s11 - a * b) / det;
        double k21 = (b * s22 - c * b) / det;
        double k22 = (c * s11 - bb) / det;
        double y1 = z[axis] - pos;
        double y2 = zv[axis] - vel;
        out_x[i] = pos + (k11 * y1 + k12 * y2);
        out_x[i + 1] = vel + (k21 * y1 + k22 * y2);
        out_p[j] = k11 * ra;
        out_p[j + 1] = k12 * rv;
        out_p[j + 2] = k22 * rv;
    }
    memcpy(x, out_x, sizeof out_x);
    memcpy(p, out_p, sizeof out_p);
    return 1;
}

/* update_rows(rw, a, x, p, t, src_t, updates, gate_fails, stale, q, max_jump, margin,
 *             max_speed, restart_after) -> bool */
static PyObject *update_rows(PyObject *self, PyObject *args) {
    PyObject *o_rw, *o_a, *o_x, *o_p, *o_t, *o_src_t, *o_upd, *o_fails, *o_stale;
    double q[3], max_jump, margin, max_speed, restart_after;
    (void)self;
    if (!PyArg_ParseTuple(args, "OOOOOOOOO(ddd)dddd:update_rows", &o_rw, &o_a, &o_x, &o_p,
                          &o_t, &o_src_t, &o_upd, &o_fails, &o_stale, &q[0], &q[1], &q[2],
                          &max_jump, &margin, &max_speed, &restart_after))
        return NULL;
    Buf bufs[9] = {{{0}}};
    PyObject *result = NULL;
    double *work = NULL;
    if (get(o_rw, &bufs[0], "rw", (Py_ssize_t)sizeof(Py_ssize_t), -1, 0) < 0) goto done;
    Py_ssize_t m = bufs[0].b.len / (Py_ssize_t)sizeof(Py_ssize_t);
    if (get(o_a, &bufs[1], "a", 8, NCOL * m, 0) < 0) goto done;
    if (get(o_t, &bufs[4], "t", 8, -1, 1) < 0) goto done;
    Py_ssize_t cap = bufs[4].b.len / 8;
    if (get(o_x, &bufs[2], "x", 8, 6 * cap, 1) < 0) goto done;
    if (get(o_p, &bufs[3], "p", 8, 9 * cap, 1) < 0) goto done;
    if (get(o_src_t, &bufs[5], "src_t", 8, 3 * cap, 1) < 0) goto done;
    if (get(o_upd, &bufs[6], "updates", 8, cap, 1) < 0) goto done;
    if (get(o_fails, &bufs[7], "gate_fails", 8, cap, 1) < 0) goto done;
    if (get(o_stale, &bufs[8], "stale", 1, cap, 1) < 0) goto done;
    const Py_ssize_t *rw = bufs[0].b.buf;
    const double *a = bufs[1].b.buf;
    double *x = bufs[2].b.buf, *p = bufs[3].b.buf, *t = bufs[4].b.buf, *src_t = bufs[5].b.buf;
    int64_t *upd = bufs[6].b.buf, *fails = bufs[7].b.buf;
    char *stale = bufs[8].b.buf;
    /* a is (NCOL, m): field f of measurement k at a[f * m + k] */
#define A(f, k) a[(Py_ssize_t)(f) * m + (k)]
    work = PyMem_Malloc((size_t)(m > 0 ? m : 1) * 15 * sizeof(double));
    if (work == NULL) {
        PyErr_NoMemory();
        goto done;
    }
    /* First every check, on copies; then the write-back: all or nothing. */
    for (Py_ssize_t k = 0; k < m; k++) {
        Py_ssize_t row = rw[k];
        if (row < 0 || row >= cap) {
            PyErr_Format(PyExc_IndexError, "update_rows: row %zd of %zd", row, cap);
            goto done;
        }
        double tk = A(C_T, k);
        double dt = tk - t[row];
        double src = A(C_SRC, k);
        if (!(src >= 0.0 && src < 3.0)) {
            PyErr_Format(PyExc_ValueError, "update_rows: source index %g", src);
            goto done;
        }
        /* out of order, duplicate, or back after a gap (the track restarts) */
        if (dt < 0.0 || dt > restart_after || tk == src_t[row * 3 + (Py_ssize_t)src])
            goto fallback;
        double *xs = work + k * 15, *ps = xs + 6;
        memcpy(xs, x + row * 6, 6 * sizeof(double));
        memcpy(ps, p + row * 9, 9 * sizeof(double));
        double pe = xs[0] + xs[1] * dt;
        double pn = xs[2] + xs[3] * dt;
        double pu = xs[4] + xs[5] * dt;
        double de = A(C_E, k) - pe;
        double dn = A(C_N, k) - pn;
        double du = A(C_U, k) - pu;
        double allowed = margin + max_speed * dt;
        if (!(allowed < max_jump)) allowed = max_jump; /* np.minimum(max_jump, allowed) */
        if (sqrt(de * de + dn * dn + du * du) > allowed) goto fallback;
        xs[0] = pe;
        xs[2] = pn;
        xs[4] = pu;
        double z[3] = {A(C_E, k), A(C_N, k), A(C_U, k)};
        double r[3] = {A(C_R, k), A(C_R + 1, k), A(C_R + 2, k)};
        int ok;
        if (A(C_HV, k) != 0.0) {
            double zv[3] = {A(C_VE, k), A(C_VE + 1, k), A(C_VE + 2, k)};
            ok = step_row(xs, ps, dt, q, z, r, zv, A(C_RV, k));
        } else {
            ok = step_row(xs, ps, dt, q, z, r, NULL, 0.0);
        }
        if (!ok) goto fallback;
    }
    for (Py_ssize_t k = 0; k < m; k++) {
        Py_ssize_t row = rw[k];
        double tk = A(C_T, k);
        memcpy(x + row * 6, work + k * 15, 6 * sizeof(double));
        memcpy(p + row * 9, work + k * 15 + 6, 9 * sizeof(double));
        t[row] = tk;
        src_t[row * 3 + (Py_ssize_t)A(C_SRC, k)] = tk;
        upd[row] += 1;
        fails[row] = 0;
        stale[row] = 0;
    }
#undef A
    result = Py_True;
    Py_INCREF(result);
    goto done;
fallback:
    result = Py_False;
    Py_INCREF(result);
done:
    PyMem_Free(work);
    release(bufs, 9);
    return result;
}

/* lane_records(values, a, idx, defaults, min_sigma, max_future, max_speed2, north_dir,
 *              min_alt, max_alt) -> (m, invalid, gate)
 *
/* entry_records(values, a, idx, defaults, min_sigma, max_future, max_speed2, north_dir,
 *               min_alt, max_alt[, kinds, has_vel]) -> (m, invalid, gate)
 *
 * kernel.check_entries for each entry in ``values`` (a sequence of k entries of STRIDE
 * numbers, layout.py ENT_*), the same conditions in the same order with the same arithmetic:
 * the i-th entry that passes goes to column i of ``a`` (NCOL, k) and its ENT_SRC value to
 * idx[i]; m of them passed. ``defaults``: (eph, epv, velocity sigma) per source kind;
 * ``kinds`` (intp, k): each entry's source kind (None: all 0); ``has_vel`` (bool, k): whether
 * a velocity was measured (None: all; a missing one is given as zeros); ``north_dir``: (east,
 * north) of true north on the grid. */
enum { L_IDX = 0, L_RCV, L_T, L_LON, L_LAT, L_ALT, L_VN, L_VE, L_VD, L_EPH, L_EPV, STRIDE };
enum { NSRC = 3 }; /* source kinds: layout.N_SOURCES */
enum { C_ARGS_VERSION = 2 }; /* layout.C_ARGS_VERSION: update_rows takes restart_after */

static PyObject *entry_records(PyObject *self, PyObject *args) {
    PyObject *o_values, *o_a, *o_idx, *o_kinds = Py_None, *o_hv = Py_None;
    double dflt[NSRC][3], min_sigma, max_future, max_speed2, nd_e, nd_n, min_alt, max_alt;
    (void)self;
    if (!PyArg_ParseTuple(args, "OOO((ddd)(ddd)(ddd))ddd(dd)dd|OO:entry_records", &o_values,
                          &o_a, &o_idx, &dflt[0][0], &dflt[0][1], &dflt[0][2], &dflt[1][0],
                          &dflt[1][1], &dflt[1][2], &dflt[2][0], &dflt[2][1], &dflt[2][2],
                          &min_sigma, &max_future, &max_speed2, &nd_e, &nd_n, &min_alt,
                          &max_alt, &o_kinds, &o_hv))
        return NULL;
    PyObject *seq = PySequence_Fast(o_values, "entry_records: values must be a sequence");
    if (seq == NULL) return NULL;
    Buf bufs[4] = {{{0}}};
    PyObject *result = NULL;
    Py_ssize_t n = PySequence_Fast_GET_SIZE(seq);
    if (n % STRIDE) {
        PyErr_Format(PyExc_ValueError, "entry_records: %zd numbers is not a whole number of "
                     "%d-number entries", n, (int)STRIDE);
        goto done;
    }
    Py_ssize_t k = n / STRIDE;
    if (get(o_a, &bufs[0], "a", 8, NCOL * k, 1) < 0) goto done;
    if (get(o_idx, &bufs[1], "idx", (Py_ssize_t)sizeof(Py_ssize_t), k, 1) < 0) goto done;
    const Py_ssize_t *kinds = NULL;
    const char *has_vel = NULL;
    if (o_kinds != Py_None) {
        if (get(o_kinds, &bufs[2], "kinds", (Py_ssize_t)sizeof(Py_ssize_t), k, 0) < 0) goto done;
        kinds = bufs[2].b.buf;
    }
    if (o_hv != Py_None) {
        if (get(o_hv, &bufs[3], "has_vel", 1, k, 0) < 0) goto done;
        has_vel = bufs[3].b.buf;
    }
    double *a = bufs[0].b.buf;
    Py_ssize_t *idx = bufs[1].b.buf;
    PyObject **items = PySequence_Fast_ITEMS(seq);
    /* per source: the defaults' variances, max(default, min_sigma)^2, and vsig^2 */
    double eph2_ds[NSRC], epv2_ds[NSRC], vsig2s[NSRC];
    for (int s = 0; s < NSRC; s++) {
        double e = min_sigma > dflt[s][0] ? min_sigma : dflt[s][0];
        eph2_ds[s] = e * e;
        e = min_sigma > dflt[s][1] ? min_sigma : dflt[s][1];
        epv2_ds[s] = e * e;
        vsig2s[s] = dflt[s][2] * dflt[s][2];
    }
    Py_ssize_t m = 0, invalid = 0, gate = 0;
    for (Py_ssize_t j = 0; j < k; j++) {
        PyObject **it = items + j * STRIDE;
        Py_ssize_t kind = kinds != NULL ? kinds[j] : 0;
        if (kind < 0 || kind >= NSRC) {
            PyErr_Format(PyExc_ValueError, "entry_records: source kind %zd", kind);
            goto done;
        }
        int hv = has_vel != NULL ? has_vel[j] != 0 : 1;
        double eph_d = dflt[kind][0], epv_d = dflt[kind][1];
        double v[STRIDE];
        for (int f = 1; f < STRIDE; f++) {
            v[f] = PyFloat_AsDouble(it[f]);
            if (v[f] == -1.0 && PyErr_Occurred()) goto done;
        }
        Py_ssize_t src = PyNumber_AsSsize_t(it[L_IDX], PyExc_OverflowError);
        if (src == -1 && PyErr_Occurred()) goto done;
        double t = v[L_T], rcv = v[L_RCV], lat = v[L_LAT], lon = v[L_LON], alt = v[L_ALT];
        if (!(isfinite(t) && -90.0 <= lat && lat <= 90.0 && -180.0 <= lon && lon <= 180.0 &&
              min_alt <= alt && alt <= max_alt && !(t - rcv > max_future && isfinite(rcv)))) {
            invalid++;
            continue;
        }
        double eph2, epv2;
        double eph = v[L_EPH], epv = v[L_EPV]; /* nan: unknown (None) */
        if (isnan(eph) && isnan(epv)) {
            eph2 = eph2_ds[kind];
            epv2 = epv2_ds[kind];
        } else {
            if (isnan(eph)) eph = eph_d;
            if (isnan(epv)) epv = epv_d;
            if (!(isfinite(eph) && isfinite(epv) && eph >= 0.0 && epv >= 0.0)) {
                invalid++;
                continue;
            }
            if (min_sigma > eph) eph = min_sigma;
            if (min_sigma > epv) epv = min_sigma;
            eph2 = eph * eph;
            epv2 = epv * epv;
        }
        double vn = v[L_VN], ve = v[L_VE], vd = v[L_VD];
        if (!(vn * vn + ve * ve + vd * vd <= max_speed2)) {
            if (isfinite(vn) && isfinite(ve) && isfinite(vd))
                gate++;
            else
                invalid++;
            continue;
        }
        double rec[NCOL];
        rec[C_T] = t;
        rec[C_E] = lon; /* projected to east/north by the tracker */
        rec[C_N] = lat;
        rec[C_U] = alt;
        rec[C_VE] = hv ? vn * nd_e + ve * nd_n : 0.0;
        rec[C_VE + 1] = hv ? vn * nd_n - ve * nd_e : 0.0;
        rec[C_VE + 2] = hv ? -vd : 0.0;
        rec[C_R] = eph2;
        rec[C_R + 1] = eph2;
        rec[C_R + 2] = epv2;
        rec[C_RV] = rec[C_RV + 1] = rec[C_RV + 2] = vsig2s[kind];
        rec[C_SRC] = (double)kind;
        rec[C_HV] = hv ? 1.0 : 0.0;
        for (int f = 0; f < NCOL; f++) a[(Py_ssize_t)f * k + m] = rec[f];
        idx[m] = src;
        m++;
    }
    result = Py_BuildValue("(nnn)", m, invalid, gate);
done:
    release(bufs, 4);
    Py_DECREF(seq);
    return result;
}

static PyMethodDef methods[] = {
    {"entry_records", entry_records, METH_VARARGS,
     "entry_records(values, a, idx, defaults, min_sigma, max_future, max_speed2, north_dir, "
     "min_alt, max_alt[, kinds, has_vel]) -> (m, invalid, gate): the checks and records of "
     "entries (see the module source)."},
    {"update_rows", update_rows, METH_VARARGS,
     "update_rows(rw, a, x, p, t, src_t, updates, gate_fails, stale, q, max_jump, margin, "
     "max_speed) -> bool: the common round (see the module source)."},
    {NULL, NULL, 0, NULL},
};

static struct PyModuleDef module = {
    PyModuleDef_HEAD_INIT, "_kalman_c",
    "The tracker's optional C kernel (bit for bit as the NumPy reference).", -1, methods,
    NULL, NULL, NULL, NULL,
};

PyMODINIT_FUNC PyInit__kalman_c(void) {
    PyObject *mod = PyModule_Create(&module);
    if (mod == NULL) return NULL;
    /* The layouts as this build knows them, in the order of layout.C_LAYOUT, then the
     * version of the functions' arguments (layout.C_ARGS_VERSION). */
    PyObject *layout = Py_BuildValue(
        "(iiiiiiiiiiiiiiiiiiiiiiii)", C_T, C_E, C_N, C_U, C_VE, C_R, C_RV, C_SRC, C_HV, NCOL,
        L_IDX, L_RCV, L_T, L_LON, L_LAT, L_ALT, L_VN, L_VE, L_VD, L_EPH, L_EPV, STRIDE, NSRC,
        C_ARGS_VERSION);
    if (layout == NULL || PyModule_AddObject(mod, "LAYOUT", layout) < 0) {
        Py_XDECREF(layout);
        Py_DECREF(mod);
        return NULL;
    }
    return mod;
}
