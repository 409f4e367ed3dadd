/*
 * Python binding of the standalone core (c/cf_core.h, c/cf_core.c): the compiled twin of
 * cf_estimator/core/step.py. The filter step, its batch loop and the covariance model's rows
 * are the core's (plain C99, no Python); this file only wraps them: argument parsing, buffers,
 * the Params/State objects and their members, the GIL released over cf_run. Beside them, one
 * helper of the bulk replay (pipeline/bulk.py): rpy_rows, roll/pitch/yaw as Python's math.atan2
 * and math.asin give them; pipeline logic that reproduces Python's math module, so it stays
 * here, out of the core.
 *
 * Module cf_estimator.core._kernel:
 *   Params(view)  the parameter view of step_params() (FilterParams fields), frozen;
 *   State()       the filter state: one attribute per StepState field (same names, units and
 *                 frames: q* = q_world(ENU)_from_sensor, b* gyro bias [rad/s, sensor], ...), and
 *     .run(params, gyro, accel, mag|None, dt, start, q_out, extra_out|None)
 *                                                        = Pair's update for rows start..N-1
 *                                                          of C-contiguous float64 arrays
 *     .copy()
 *   Pair(learning, params, null|None, null_params|None)
 *                 ComplementaryFilter's update once initialised, as a callable:
 *                 (gyro, accel, dt, mag=None) -> (q, the published State)
 *   covariance_rows(...), rpy_rows(q, out)  (see below)
 */
#define PY_SSIZE_T_CLEAN
#include <Python.h>
#include <structmember.h>
#include <math.h>
#include <string.h>

#include "cf_core.h"

static const char *GYRO_PROBLEM[] = {"", "gyro sample is not finite",
                                     "gyro sample beyond 1e+09 rad/s"};

/* ---- Python: Params ------------------------------------------------------------------------ */
typedef struct {
    PyObject_HEAD
    cf_params p;
} ParamsObject;

static int Params_init(ParamsObject *self, PyObject *args, PyObject *kwds)
{
    PyObject *view;
    static char *kwlist[] = {"view", NULL};
    if (!PyArg_ParseTupleAndKeywords(args, kwds, "O", kwlist, &view)) return -1;
    for (const cf_param_field *f = cf_param_fields; f->name != NULL; f++) {
        PyObject *v = PyObject_GetAttrString(view, f->name);
        if (v == NULL) return -1;
        char *dst = (char *)&self->p + f->offset;
        if (f->is_bool) {
            int b = PyObject_IsTrue(v);
            Py_DECREF(v);
            if (b < 0) return -1;
            *(int *)dst = b;
        } else {
            double d = PyFloat_AsDouble(v);
            Py_DECREF(v);
            if (d == -1.0 && PyErr_Occurred()) return -1;
            *(double *)dst = d;
        }
    }
    PyObject *frame = PyObject_GetAttrString(view, "world_frame");
    if (frame == NULL) return -1;
    int ned = PyUnicode_Check(frame) && PyUnicode_CompareWithASCIIString(frame, "ned") == 0;
    Py_DECREF(frame);
    self->p.ned = ned;
    return 0;
}

static PyTypeObject ParamsType = {
    PyVarObject_HEAD_INIT(NULL, 0).tp_name = "cf_estimator.core._kernel.Params",
    .tp_basicsize = sizeof(ParamsObject),
    .tp_flags = Py_TPFLAGS_DEFAULT,
    .tp_doc = "Filter parameters for the compiled step (from step_params(FilterParams)).",
    .tp_new = PyType_GenericNew,
    .tp_init = (initproc)Params_init,
};

/* ---- Python: State ------------------------------------------------------------------------- */
typedef struct {
    PyObject_HEAD
    cf_state s;
} StateObject;

static PyTypeObject StateType;

static PyObject *State_new(PyTypeObject *type, PyObject *args, PyObject *kwds)
{
    StateObject *self = (StateObject *)type->tp_alloc(type, 0);
    if (self != NULL) cf_state_init(&self->s);
    return (PyObject *)self;
}

/* Read a 3-vector of floats. 1: read; 0: not 3 long (nothing read); -1: error set. */
static int read3(PyObject *o, double *v)
{
    if (PyTuple_CheckExact(o) || PyList_CheckExact(o)) {
        if (Py_SIZE(o) != 3) return 0;
        PyObject **items = PyTuple_CheckExact(o) ? ((PyTupleObject *)o)->ob_item
                                                 : ((PyListObject *)o)->ob_item;
        for (int i = 0; i < 3; i++) {
            if (PyFloat_CheckExact(items[i])) { /* the common case, without the call */
                v[i] = PyFloat_AS_DOUBLE(items[i]);
                continue;
            }
            v[i] = PyFloat_AsDouble(items[i]);
            if (v[i] == -1.0 && PyErr_Occurred()) return -1;
        }
        return 1;
    }
    if (PyObject_CheckBuffer(o)) { /* e.g. a NumPy float64 row */
        Py_buffer b;
        if (PyObject_GetBuffer(o, &b, PyBUF_FORMAT | PyBUF_STRIDES) == 0) {
            int ok = b.ndim == 1 && b.itemsize == 8 && b.format != NULL &&
                     strcmp(b.format, "d") == 0;
            if (ok && b.shape[0] == 3) {
                for (int i = 0; i < 3; i++)
                    memcpy(&v[i], (char *)b.buf + i * b.strides[0], sizeof(double));
            }
            Py_ssize_t len = b.ndim == 1 ? b.shape[0] : -1;
            PyBuffer_Release(&b);
            if (ok) return len == 3 ? 1 : 0;
        } else {
            PyErr_Clear();
        }
    }
    PyObject *seq = PySequence_Fast(o, "expected a sequence of 3 numbers");
    if (seq == NULL) return -1;
    int out = 0;
    if (PySequence_Fast_GET_SIZE(seq) == 3) {
        out = 1;
        for (int i = 0; i < 3 && out == 1; i++) {
            v[i] = PyFloat_AsDouble(PySequence_Fast_GET_ITEM(seq, i));
            if (v[i] == -1.0 && PyErr_Occurred()) out = -1;
        }
    }
    Py_DECREF(seq);
    return out;
}

/* An optional 3-vector: 1 present and valid, 0 absent/invalid, -1 error. */
static int read_optional3(PyObject *o, double *v)
{
    if (o == Py_None) return 0;
    int r = read3(o, v);
    if (r <= 0) return r;
    return cf_valid3(v);
}

static int check_params(PyObject *obj)
{
    if (!PyObject_TypeCheck(obj, &ParamsType)) {
        PyErr_SetString(PyExc_TypeError, "params must be a cf_estimator.core._kernel.Params");
        return 0;
    }
    return 1;
}

static PyObject *q_tuple(const cf_state *s, int ned)
{
    double q[4];
    cf_output_q(s, ned, q);
    PyObject *t = PyTuple_New(4);
    if (t == NULL) return NULL;
    for (int i = 0; i < 4; i++) {
        PyObject *f = PyFloat_FromDouble(q[i]);
        if (f == NULL) {
            Py_DECREF(t);
            return NULL;
        }
        PyTuple_SET_ITEM(t, i, f);
    }
    return t;
}

/* One sample's Python arguments (gyro, accel|None, dt, mag|None or absent) read and checked as
 * ComplementaryFilter.update does (ValueError for the gyro and dt; an invalid accel/mag is
 * skipped: its pointer NULL). 0, or -1 with an error set. */
typedef struct {
    double g[3], a[3], m[3], dt;
    const double *acc, *mag;
} py_sample;

static int read_sample(PyObject *og, PyObject *oa, PyObject *odt, PyObject *om, py_sample *x)
{
    int hg = read3(og, x->g);
    if (hg < 0) return -1;
    if (hg == 0) {
        PyErr_Format(PyExc_ValueError, "gyro sample must have 3 components: %R", og);
        return -1;
    }
    int problem = cf_gyro_problem(x->g);
    if (problem) {
        PyObject *t = PySequence_Tuple(og);
        if (t != NULL) {
            PyErr_Format(PyExc_ValueError, "%s: %R", GYRO_PROBLEM[problem], t);
            Py_DECREF(t);
        }
        return -1;
    }
    x->dt = PyFloat_CheckExact(odt) ? PyFloat_AS_DOUBLE(odt) : PyFloat_AsDouble(odt);
    if (x->dt == -1.0 && PyErr_Occurred()) return -1;
    if (!(x->dt > 0.0 && isfinite(x->dt))) {
        PyErr_Format(PyExc_ValueError, "dt must be a positive finite number of seconds, got %R",
                     odt);
        return -1;
    }
    int ha = read_optional3(oa, x->a);
    int hm = om != NULL ? read_optional3(om, x->m) : 0;
    if (ha < 0 || hm < 0) return -1;
    x->acc = ha ? x->a : NULL;
    x->mag = hm ? x->m : NULL;
    return 0;
}

/* Both hypotheses (null: NULL for one) stepped on a checked sample; 1 when the null one is
 * published after it. */
static int step_sample(cf_state *s, const cf_params *p, cf_state *null, const cf_params *pn,
                       const py_sample *x)
{
    if (null == NULL) {
        cf_step(s, p, x->g, x->acc, x->mag, x->dt);
        return 0;
    }
    return cf_step_pair(s, p, null, pn, x->g, x->acc, x->mag, x->dt);
}

/* ---- Python: Pair ------------------------------------------------------------------------- */
/* ComplementaryFilter's compiled update once initialised, one call per sample:
 * Pair(learning, params, null|None, null_params|None)(gyro, accel, dt, mag=None) ->
 * (q, the published State) = State.update's checks and step of both hypotheses (of the
 * learning one alone when null is None), without the per-call argument checks of the states
 * and parameters (done once here). */
typedef struct {
    PyObject_HEAD
    vectorcallfunc vectorcall;
    StateObject *learning, *null;      /* null NULL: one hypothesis */
    ParamsObject *params, *null_params;
} PairObject;

static PyTypeObject PairType;

static PyObject *Pair_vectorcall(PyObject *callable, PyObject *const *args, size_t nargsf,
                                 PyObject *kwnames)
{
    PairObject *self = (PairObject *)callable;
    Py_ssize_t nargs = PyVectorcall_NARGS(nargsf);
    py_sample x;
    if (nargs < 3 || nargs > 4 || (kwnames != NULL && PyTuple_GET_SIZE(kwnames) > 0)) {
        PyErr_SetString(PyExc_TypeError, "Pair(gyro, accel, dt, mag=None): positional only");
        return NULL;
    }
    if (read_sample(args[0], args[1], args[2], nargs == 4 ? args[3] : NULL, &x) < 0)
        return NULL;
    const cf_params *p = &self->params->p;
    int use_null = step_sample(&self->learning->s, p, self->null ? &self->null->s : NULL,
                               self->null ? &self->null_params->p : NULL, &x);
    StateObject *published = use_null ? self->null : self->learning;
    PyObject *q = q_tuple(&published->s, p->ned);
    if (q == NULL) return NULL;
    PyObject *out = PyTuple_New(2);
    if (out == NULL) {
        Py_DECREF(q);
        return NULL;
    }
    PyTuple_SET_ITEM(out, 0, q);
    Py_INCREF(published);
    PyTuple_SET_ITEM(out, 1, (PyObject *)published);
    return out;
}

static PyObject *Pair_new(PyTypeObject *type, PyObject *args, PyObject *kwds)
{
    PyObject *learning, *params, *null = Py_None, *null_params = Py_None;
    static char *kwlist[] = {"learning", "params", "null", "null_params", NULL};
    if (!PyArg_ParseTupleAndKeywords(args, kwds, "O!O!|OO:Pair", kwlist, &StateType, &learning,
                                     &ParamsType, &params, &null, &null_params))
        return NULL;
    if ((null == Py_None) != (null_params == Py_None) ||
        (null != Py_None && (!PyObject_TypeCheck(null, &StateType) ||
                             !PyObject_TypeCheck(null_params, &ParamsType)))) {
        PyErr_SetString(PyExc_TypeError, "Pair: null (a State) and null_params (Params), or "
                                         "neither");
        return NULL;
    }
    if (null == learning) {
        PyErr_SetString(PyExc_ValueError, "Pair: null must be another State than learning");
        return NULL;
    }
    PairObject *self = (PairObject *)type->tp_alloc(type, 0);
    if (self == NULL) return NULL;
    self->vectorcall = Pair_vectorcall;
    Py_INCREF(learning);
    self->learning = (StateObject *)learning;
    Py_INCREF(params);
    self->params = (ParamsObject *)params;
    if (null != Py_None) {
        Py_INCREF(null);
        self->null = (StateObject *)null;
        Py_INCREF(null_params);
        self->null_params = (ParamsObject *)null_params;
    }
    return (PyObject *)self;
}

static void Pair_dealloc(PairObject *self)
{
    Py_XDECREF(self->learning);
    Py_XDECREF(self->null);
    Py_XDECREF(self->params);
    Py_XDECREF(self->null_params);
    Py_TYPE(self)->tp_free((PyObject *)self);
}

static PyTypeObject PairType = {
    PyVarObject_HEAD_INIT(NULL, 0).tp_name = "cf_estimator.core._kernel.Pair",
    .tp_basicsize = sizeof(PairObject),
    .tp_flags = Py_TPFLAGS_DEFAULT | Py_TPFLAGS_HAVE_VECTORCALL,
    .tp_doc = "Pair(learning, params, null=None, null_params=None): called with (gyro, accel, "
              "dt, mag=None) -> (q in the output frame, the published State): State.update of "
              "both bias hypotheses, one call per sample.",
    .tp_new = Pair_new,
    .tp_dealloc = (destructor)Pair_dealloc,
    .tp_vectorcall_offset = offsetof(PairObject, vectorcall),
    .tp_call = PyVectorcall_Call,
};

/* A C-contiguous float64 buffer of exactly `count` doubles (None allowed if `optional`). */
static int get_array(PyObject *o, Py_buffer *b, Py_ssize_t count, int writable, int optional,
                     const char *name)
{
    b->obj = NULL;
    if (o == Py_None) {
        if (optional) return 1;
        PyErr_Format(PyExc_TypeError, "%s is required", name);
        return 0;
    }
    int flags = PyBUF_C_CONTIGUOUS | PyBUF_FORMAT | (writable ? PyBUF_WRITABLE : 0);
    if (PyObject_GetBuffer(o, b, flags) < 0) return 0;
    if (b->itemsize != 8 || b->format == NULL || strcmp(b->format, "d") != 0 ||
        b->len != count * 8) {
        PyErr_Format(PyExc_ValueError, "%s must be a C-contiguous float64 array of %zd values",
                     name, count);
        PyBuffer_Release(b);
        b->obj = NULL;
        return 0;
    }
    return 1;
}

static PyObject *State_run(StateObject *self, PyObject *args)
{
    PyObject *params, *og, *oa, *om, *odt, *oq, *ox, *onull = NULL, *onull_params = NULL;
    Py_ssize_t start;
    if (!PyArg_ParseTuple(args, "OOOOOnOO|O!O:run", &params, &og, &oa, &om, &odt, &start, &oq,
                          &ox, &StateType, &onull, &onull_params))
        return NULL;
    if (!check_params(params)) return NULL;
    if (onull != NULL && (onull_params == NULL || !check_params(onull_params))) {
        if (!PyErr_Occurred()) PyErr_SetString(PyExc_TypeError, "null needs null_params");
        return NULL;
    }
    Py_buffer bdt;
    if (!get_array(odt, &bdt, PyObject_Length(odt), 0, 0, "dt")) return NULL;
    Py_ssize_t n = bdt.len / 8;
    Py_buffer bg = {0}, ba = {0}, bm = {0}, bq = {0}, bx = {0};
    PyObject *result = NULL;
    if (!get_array(og, &bg, 3 * n, 0, 0, "gyro") || !get_array(oa, &ba, 3 * n, 0, 0, "accel") ||
        !get_array(om, &bm, 3 * n, 0, 1, "mag") || !get_array(oq, &bq, 4 * n, 1, 0, "q_out") ||
        !get_array(ox, &bx, CF_EXTRA_COLUMNS * n, 1, 1, "extra_out"))
        goto done;
    if (start < 0 || start > n) {
        PyErr_SetString(PyExc_ValueError, "start out of range");
        goto done;
    }
    const cf_params *p = &((ParamsObject *)params)->p;
    const double *G = bg.buf, *A = ba.buf, *M = bm.obj ? bm.buf : NULL, *DT = bdt.buf;
    double *Q = bq.buf, *X = bx.obj ? bx.buf : NULL;
    Py_ssize_t bad;
    int problem = CF_OK, use_null = 0;
    cf_state *null_s = onull ? &((StateObject *)onull)->s : NULL;
    const cf_params *pn = onull ? &((ParamsObject *)onull_params)->p : NULL;
    Py_BEGIN_ALLOW_THREADS
    if (null_s)
        bad = cf_run_pair(&self->s, p, null_s, pn, G, A, M, DT, start, n, Q, X, &problem,
                          &use_null);
    else
        bad = cf_run(&self->s, p, G, A, M, DT, start, n, Q, X, &problem);
    Py_END_ALLOW_THREADS
    if (bad >= 0) {
        if (problem == CF_BAD_DT)
            PyErr_Format(PyExc_ValueError, "dt must be positive and finite (row %zd)", bad);
        else {
            PyObject *t = Py_BuildValue("(ddd)", G[3 * bad], G[3 * bad + 1], G[3 * bad + 2]);
            if (t != NULL) {
                PyErr_Format(PyExc_ValueError, "%s: %R (row %zd)", GYRO_PROBLEM[problem], t,
                             bad);
                Py_DECREF(t);
            }
        }
        goto done;
    }
    result = onull ? PyBool_FromLong(use_null) : Py_None;
    if (!onull) Py_INCREF(result);
done:
    PyBuffer_Release(&bdt);
    if (bg.obj) PyBuffer_Release(&bg);
    if (ba.obj) PyBuffer_Release(&ba);
    if (bm.obj) PyBuffer_Release(&bm);
    if (bq.obj) PyBuffer_Release(&bq);
    if (bx.obj) PyBuffer_Release(&bx);
    return result;
}

static PyObject *State_copy(StateObject *self, PyObject *Py_UNUSED(ignored))
{
    StateObject *new = (StateObject *)StateType.tp_alloc(&StateType, 0);
    if (new != NULL) new->s = self->s;
    return (PyObject *)new;
}

/* ---- beside the step: the bulk replay's per-row loops (pipeline/bulk.py) ---------------- */

/* A 1-D float64 buffer of `count` values with any stride (a column of a row-major array). */
typedef struct {
    Py_buffer b;
    const char *p;
    Py_ssize_t stride;
} column;

static int get_column(PyObject *o, column *c, Py_ssize_t count, int writable, const char *name)
{
    c->b.obj = NULL;
    int flags = PyBUF_STRIDES | PyBUF_FORMAT | (writable ? PyBUF_WRITABLE : 0);
    if (PyObject_GetBuffer(o, &c->b, flags) < 0) return 0;
    if (c->b.ndim != 1 || c->b.itemsize != 8 || c->b.format == NULL ||
        strcmp(c->b.format, "d") != 0 || c->b.shape[0] != count) {
        PyErr_Format(PyExc_ValueError, "%s must be a 1-D float64 array of %zd values", name,
                     count);
        PyBuffer_Release(&c->b);
        c->b.obj = NULL;
        return 0;
    }
    c->p = c->b.buf;
    c->stride = c->b.strides[0];
    return 1;
}

static cf_column core_column(const column *c)
{
    cf_column out;
    out.data = c->b.obj ? (const double *)c->p : NULL;
    out.stride = c->stride;
    return out;
}

/* OrientationCovariance.steps over rows (the core's cf_covariance_rows):
 * covariance_rows(consts, state, heading_initialized, dt, clipped, bias_sigma, phase,
 *                 error_norm, lx, ly, noise_a2, yaw_error, mag_used, mag_age|None, loop_k1,
 *                 mag_rejected, tilt_out, yaw_out) -> state
 * consts = (k1, bias_prior, inv_6g2, tilt0, yaw0, yaw_unref, tilt_cap, yaw_cap, yaw_memory),
 * state = (clip_s, ms, yaw_err, cx, cy, sx, sy, yaw_lp, yaw_gap) before and after the rows
 * (sx, sy: the disagreement's steady part); clipped, mag_used and mag_rejected: non-zero =
 * true; bias_sigma NaN: the prior; mag_age None: never (the Python's None). */
static PyObject *covariance_rows(PyObject *Py_UNUSED(module), PyObject *args)
{
    cf_cov_consts k;
    cf_cov_state st;
    int heading;
    PyObject *o[15];
    if (!PyArg_ParseTuple(args, "(ddddddddd)(ddddddddd)pOOOOOOOOOOOOOOO:covariance_rows", &k.k1,
                          &k.bias_prior, &k.inv_6g2, &k.tilt0, &k.yaw0, &k.yaw_unref, &k.tilt_cap,
                          &k.yaw_cap, &k.yaw_memory, &st.clip_s, &st.ms, &st.yaw_err, &st.cx,
                          &st.cy, &st.sx, &st.sy, &st.yaw_lp, &st.yaw_gap, &heading, &o[0], &o[1],
                          &o[2], &o[3], &o[4], &o[5], &o[6], &o[7], &o[8], &o[9], &o[10], &o[11],
                          &o[12], &o[13], &o[14]))
        return NULL;
    static const char *names[15] = {"dt", "clipped", "bias_sigma", "phase", "error_norm", "lx",
                                    "ly", "noise_a2", "yaw_error", "mag_used", "mag_age",
                                    "loop_k1", "mag_rejected", "tilt_out", "yaw_out"};
    column c[15];
    for (int j = 0; j < 15; j++) {
        c[j].b.obj = NULL;
        c[j].p = NULL;
        c[j].stride = 0;
    }
    PyObject *result = NULL;
    Py_ssize_t n = PyObject_Length(o[0]);
    if (n < 0) return NULL;
    for (int j = 0; j < 15; j++) {
        if (j == 10 && o[j] == Py_None) continue;
        if (!get_column(o[j], &c[j], n, j >= 13, names[j])) goto done;
    }
    cf_cov_rows in;
    in.dt = core_column(&c[0]);
    in.clipped = core_column(&c[1]);
    in.bias_sigma = core_column(&c[2]);
    in.phase = core_column(&c[3]);
    in.error_norm = core_column(&c[4]);
    in.lx = core_column(&c[5]);
    in.ly = core_column(&c[6]);
    in.noise_a2 = core_column(&c[7]);
    in.yaw_error = core_column(&c[8]);
    in.mag_used = core_column(&c[9]);
    in.mag_age = core_column(&c[10]);
    in.loop_k1 = core_column(&c[11]);
    in.mag_rejected = core_column(&c[12]);
    if (cf_covariance_rows(&k, &st, heading, &in, n, (double *)c[13].p, c[13].stride,
                           (double *)c[14].p, c[14].stride) >= 0)
        PyErr_SetString(PyExc_OverflowError, "(34, 'Numerical result out of range')");
    else
        result = Py_BuildValue("(ddddddddd)", st.clip_s, st.ms, st.yaw_err, st.cx, st.cy, st.sx,
                               st.sy, st.yaw_lp, st.yaw_gap);
done:
    for (int j = 0; j < 15; j++)
        if (c[j].b.obj) PyBuffer_Release(&c[j].b);
    return result;
}

/* math.atan2 (CPython's m_atan2: its special values first, then libm's atan2). */
static double py_atan2(double y, double x)
{
    if (isnan(x) || isnan(y)) return Py_NAN;
    if (isinf(y)) {
        if (isinf(x)) return copysign(copysign(1., x) == 1. ? 0.25 * Py_MATH_PI
                                                             : 0.75 * Py_MATH_PI, y);
        return copysign(0.5 * Py_MATH_PI, y);
    }
    if (isinf(x) || y == 0.) return copysign(copysign(1., x) == 1. ? 0. : Py_MATH_PI, y);
    return atan2(y, x);
}

/* bulk._rpy's roll, pitch, yaw of each (w, x, y, z) row, without the unwrap:
 * rpy_rows(q (n, 4), out (n, 3)), both C-contiguous float64. */
static PyObject *rpy_rows(PyObject *Py_UNUSED(module), PyObject *args)
{
    PyObject *oq, *oo;
    if (!PyArg_ParseTuple(args, "OO:rpy_rows", &oq, &oo)) return NULL;
    Py_buffer bq, bo;
    Py_ssize_t n = PyObject_Length(oq);
    if (n < 0 || !get_array(oq, &bq, 4 * n, 0, 0, "q")) return NULL;
    if (!get_array(oo, &bo, 3 * n, 1, 0, "out")) {
        PyBuffer_Release(&bq);
        return NULL;
    }
    const double *Q = bq.buf;
    double *R = bo.buf;
    for (Py_ssize_t i = 0; i < n; i++) {
        const double qw = Q[4 * i], qx = Q[4 * i + 1], qy = Q[4 * i + 2], qz = Q[4 * i + 3];
        R[3 * i] = py_atan2(2.0 * (qw * qx + qy * qz), 1.0 - 2.0 * (qx * qx + qy * qy));
        double sp = 2.0 * (qw * qy - qz * qx);
        sp = sp > 1.0 ? 1.0 : (sp < -1.0 ? -1.0 : sp);
        R[3 * i + 1] = asin(sp);
        R[3 * i + 2] = py_atan2(2.0 * (qw * qz + qx * qy), 1.0 - 2.0 * (qy * qy + qz * qz));
    }
    PyBuffer_Release(&bq);
    PyBuffer_Release(&bo);
    Py_RETURN_NONE;
}

static PyMethodDef module_methods[] = {
    {"covariance_rows", covariance_rows, METH_VARARGS,
     "OrientationCovariance.steps over float64 rows (core/covariance.py): -> the state after."},
    {"rpy_rows", rpy_rows, METH_VARARGS,
     "rpy_rows(q, out): roll, pitch, yaw of each (w, x, y, z) row as math.atan2/asin give."},
    {NULL, NULL, 0, NULL}};

static PyMethodDef State_methods[] = {
    {"run", (PyCFunction)State_run, METH_VARARGS,
     "run(params, gyro, accel, mag|None, dt, start, q_out, extra_out|None[, null, null_params]): "
     "rows start..N-1; with the null hypothesis: each row the published one's, -> published_null "
     "after the last."},
    {"copy", (PyCFunction)State_copy, METH_NOARGS, "A copy of the state."},
    {NULL, NULL, 0, NULL}};

#define SD(n) {#n, T_DOUBLE, offsetof(StateObject, s) + offsetof(cf_state, n), 0, NULL}
#define SB(n) {#n, T_BOOL, offsetof(StateObject, s) + offsetof(cf_state, n), 0, NULL}
#define SI(n) {#n, T_INT, offsetof(StateObject, s) + offsetof(cf_state, n), 0, NULL}
static PyMemberDef State_members[] = {
    SD(qw), SD(qx), SD(qy), SD(qz), SD(lx), SD(ly), SD(lz), SD(rxx),
    SD(rxy), SD(rxz), SD(ryx), SD(ryy), SD(ryz), SD(rzx), SD(rzy), SD(rzz), SD(time_s),
    SD(clip_timer_s), SB(recovering), SD(recovery_count), SD(accel_hold), SD(acx), SD(acy), SD(acz),
    SD(rate_lp), SI(phase), SB(aided), SD(quick_until_s), SD(rest_timer_s), SB(at_rest), SB(moved), SD(blk_n), SD(blk_t),
    SD(blk_gx), SD(blk_gy), SD(blk_gz), SD(blk_ax), SD(blk_ay), SD(blk_az), SD(blk_g2), SD(blk_a2),
    SD(blk_d), SD(blk_mx), SD(blk_my), SD(blk_mz), SD(blk_mn), SD(blk_m2), SD(blk_md),
    SD(prev_n), SD(pgx), SD(pgy),
    SD(pgz), SD(pax), SD(pay), SD(paz), SD(pmx), SD(pmy), SD(pmz), SD(pm_n), SD(last_n), SD(lgx),
    SD(lgy), SD(lgz), SD(lax), SD(lay), SD(laz), SD(lmx), SD(lmy), SD(lmz), SD(noise_g2), SD(noise_a2),
    SD(noise_m2), SD(g_ref), SD(bx),
    SD(by), SD(bz), SD(bias_var), SD(bias_err_var), SB(bias_unverified), SD(pvx), SD(pvy), SD(pv_var), SD(turn_rate_lp), SD(turn_hold), SD(z_m), SD(mag_ref_norm), SD(mag_ref_dip),
    SD(mag_ref_count), SB(mag_disturbed), SD(mag_last_time_s), SB(heading_initialized),
    SD(mag_clip_timer_s), SB(mag_recovering), SD(mvx), SD(mvy), SD(mvz), SD(mcx), SD(mcy),
    SD(mcz), SD(mmx), SD(mmy), SD(mmz), SD(mag_cand_norm), SD(mag_seen_time_s), SD(mag_ok_timer_s), SD(mag_cand_timer_s),
    SB(mag_on_body), SD(mag_ref_time_s), SD(ex), SD(ey), SD(ez),
    SD(error_norm), SD(fx), SD(fy), SD(fz), SB(clipped), SB(accel_used), SI(mag_status),
    SD(yaw_error_rad), SD(loop_k1),
    {NULL, 0, 0, 0, NULL}};

static PyTypeObject StateType = {
    PyVarObject_HEAD_INIT(NULL, 0).tp_name = "cf_estimator.core._kernel.State",
    .tp_basicsize = sizeof(StateObject),
    .tp_flags = Py_TPFLAGS_DEFAULT,
    .tp_doc = "Filter state of the compiled step (the fields of step.StepState).",
    .tp_new = State_new,
    .tp_methods = State_methods,
    .tp_members = State_members,
};

static struct PyModuleDef kernel_module = {
    PyModuleDef_HEAD_INIT, "_kernel", "Compiled twin of cf_estimator.core.step.", -1,
    module_methods};

PyMODINIT_FUNC PyInit__kernel(void)
{
    if (PyType_Ready(&ParamsType) < 0 || PyType_Ready(&StateType) < 0 ||
        PyType_Ready(&PairType) < 0)
        return NULL;
    PyObject *m = PyModule_Create(&kernel_module);
    if (m == NULL) return NULL;
    PyObject *fields = PyList_New(0);
    for (PyMemberDef *d = State_members; d->name != NULL; d++) {
        PyObject *name = PyUnicode_FromString(d->name);
        PyList_Append(fields, name);
        Py_DECREF(name);
    }
    if (PyDict_SetItemString(StateType.tp_dict, "FIELDS", fields) < 0) return NULL;
    Py_DECREF(fields);
    PyObject *consts = PyDict_New(); /* the core's named constants (step.py's names) */
    for (const cf_constant *c = cf_constants; consts != NULL && c->name != NULL; c++) {
        PyObject *v = c->is_count ? PyLong_FromLong((long)c->value) : PyFloat_FromDouble(c->value);
        if (v == NULL || PyDict_SetItemString(consts, c->name, v) < 0) Py_CLEAR(consts);
        Py_XDECREF(v);
    }
    Py_INCREF(&ParamsType);
    Py_INCREF(&StateType);
    Py_INCREF(&PairType);
    if (consts == NULL || PyModule_AddObject(m, "CONSTANTS", consts) < 0 ||
        PyModule_AddObject(m, "Params", (PyObject *)&ParamsType) < 0 ||
        PyModule_AddObject(m, "State", (PyObject *)&StateType) < 0 ||
        PyModule_AddObject(m, "Pair", (PyObject *)&PairType) < 0) {
        Py_DECREF(m);
        return NULL;
    }
    return m;
}
