/*
 * vibsynth real-time input: a PortAudio input callback that writes interleaved float32 frames
 * into a single-producer / single-consumer ring, in C so the audio thread never needs the GIL.
 *
 * Threads
 * -------
 * - The producer is the PortAudio callback (or a test, or the file feeder through write(), one
 *   at a time: a ring has one producer). It allocates nothing, takes no lock, never logs, and
 *   does O(frames x device channels) work per block.
 * - The consumer is one Python thread calling read_into()/skip() with the GIL held (so Python
 *   readers serialise on the GIL; the producer never waits for them).
 *
 * Hand-off: `wpos` (frames written, producer-owned) is published with a release store after the
 * frames; `rpos` (frames read, consumer-owned) likewise after the copy. Capacity is a power of
 * two. When the reader is behind and the ring is full, the newest frames of the block are
 * dropped and counted (`dropped_frames`, and `overflows` once per block that dropped any):
 * what the ring holds is always a gap-free run of what the device delivered, up to the drop.
 *
 * Clocks: `frames_captured` counts every frame the device delivered (dropped ones too): the
 * absolute input frame counter. Each callback stamps the block (its first frame, PortAudio's
 * inputBufferAdcTime / currentTime / outputBufferDacTime and the monotonic clock) so a reader
 * can put input frames on the output's clock (the engine core stamps its output blocks the
 * same way), e.g. to measure a loop's latency.
 *
 * Hostile callers: a ring is initialised once (a second __init__ raises RuntimeError), every
 * method and getter checks that it was (RuntimeError "InputRing is not initialised": one made by
 * InputRing.__new__ has no buffer), and every argument is validated where it enters.
 */
#define PY_SSIZE_T_CLEAN
#include <Python.h>
#include <math.h>
#include <stdlib.h> /* malloc/calloc/free: Python.h leaves it out of limited-API builds */
#include <stdint.h>
#include <string.h>

#include "_rt.h"

#define IN_MAXCH 64
#define PA_INPUT_UNDERFLOW 0x00000001UL
#define PA_INPUT_OVERFLOW 0x00000002UL
#define MAX_DELAY_S 60.0               /* run_callback's longest delay */
#define MAX_CALLBACK_FRAMES (1 << 26)  /* run_callback's most frames of no input (= the largest capacity) */

typedef struct {
    PyObject_HEAD
    float *buf;
    int64_t cap; /* frames, a power of two */
    int channels;
    double fs;
    /* device layout: ring channel ch <- device column cols[ch] of dev_channels */
    int dev_channels;
    int cols[IN_MAXCH];
    /* hand-off */
    int64_t wpos; /* producer-owned, published */
    int64_t rpos; /* consumer-owned, published */
    /* counters (producer-owned, published) */
    int64_t captured, dropped, overflows, pa_overflows, pa_underflows, callbacks;
    float peak[IN_MAXCH]; /* |x| max per ring channel since take_peaks() (a racy max: meters only) */
    double load_last, load_peak, load_avg;
    vs_stamp_t stamp;
    int has_stamp;
} Ring;

/* ------------------------------------------------------------------ producer (audio thread) */
/* Put `frames` device frames (interleaved, dev_channels wide; NULL = silence) into the ring. */
static void ring_put(Ring *r, const float *in, int64_t frames) {
    int nch = r->channels, dev = r->dev_channels;
    int64_t w = r->wpos;
    int64_t space = r->cap - (w - LOAD_ACQ(&r->rpos));
    int64_t n = frames < space ? frames : space;
    int64_t mask = r->cap - 1;
    float *peak = r->peak;
    for (int64_t j = 0; j < frames; j++) {
        float *dst = j < n ? r->buf + ((w + j) & mask) * nch : NULL;
        for (int ch = 0; ch < nch; ch++) {
            float x = in ? in[j * dev + r->cols[ch]] : 0.0f;
            float a = fabsf(x);
            if (a > peak[ch]) peak[ch] = a;
            if (dst) dst[ch] = x;
        }
    }
    if (n < frames) {
        STORE_REL(&r->dropped, r->dropped + (frames - n));
        STORE_REL(&r->overflows, r->overflows + 1);
    }
    STORE_REL(&r->wpos, w + n);
}

/* The PortAudio stream callback (PaStreamCallback) of an interleaved float32 input stream. */
static int input_callback(const void *input, void *output, unsigned long frames, const void *time_info,
                          unsigned long status, void *user) {
    Ring *r = (Ring *)user;
    (void)output;
    double t0 = vs_now_s();
    vs_stamp_write(&r->stamp, r->captured, (const vs_pa_time_t *)time_info, t0);
    r->has_stamp = 1;
    if (status & PA_INPUT_OVERFLOW) STORE_REL(&r->pa_overflows, r->pa_overflows + 1);
    if (status & PA_INPUT_UNDERFLOW) STORE_REL(&r->pa_underflows, r->pa_underflows + 1);
    ring_put(r, (const float *)input, (int64_t)frames);
    STORE_REL(&r->captured, r->captured + (int64_t)frames);
    STORE_REL(&r->callbacks, r->callbacks + 1);
    if (frames) {
        double load = (vs_now_s() - t0) * r->fs / (double)frames;
        r->load_last = load;
        if (load > r->load_peak) r->load_peak = load;
        r->load_avg += 0.01 * (load - r->load_avg);
    }
    return 0; /* paContinue */
}

/* ------------------------------------------------------------------ Python type */
/* 1 (with a RuntimeError) when __init__ has not succeeded (no buffer: cap, channels 0). */
static int not_ready(const Ring *self) {
    if (self->buf) return 0;
    PyErr_SetString(PyExc_RuntimeError, "InputRing is not initialised (its __init__ has not succeeded)");
    return 1;
}

static void Ring_dealloc(Ring *self) {
    PyTypeObject *type = Py_TYPE((PyObject *)self);
    free(self->buf);
    ((freefunc)PyType_GetSlot(type, Py_tp_free))(self);
    Py_DECREF(type); /* a heap type: each instance holds a reference to it */
}

static int Ring_init(Ring *self, PyObject *args, PyObject *kw) {
    static char *names[] = {"channels", "capacity", "fs", NULL};
    int channels;
    Py_ssize_t cap;
    double fs;
    if (self->buf) { /* the PortAudio callback or a reader may use it meanwhile */
        PyErr_SetString(PyExc_RuntimeError, "InputRing is already initialised");
        return -1;
    }
    if (!PyArg_ParseTupleAndKeywords(args, kw, "ind", names, &channels, &cap, &fs)) return -1;
    if (channels < 1 || channels > IN_MAXCH) {
        PyErr_Format(PyExc_ValueError, "channels must be in 1..%d", IN_MAXCH);
        return -1;
    }
    if (cap < 2 || (cap & (cap - 1)) || cap > ((Py_ssize_t)1 << 26)) {
        PyErr_SetString(PyExc_ValueError, "capacity must be a power of two in 2..2**26 frames");
        return -1;
    }
    if (!(fs > 0.0) || !isfinite(fs)) {
        PyErr_SetString(PyExc_ValueError, "fs must be finite and > 0");
        return -1;
    }
    self->channels = channels;
    self->dev_channels = channels;
    for (int ch = 0; ch < channels; ch++) self->cols[ch] = ch;
    self->cap = cap;
    self->fs = fs;
    self->buf = calloc((size_t)cap * (size_t)channels, sizeof(float));
    if (!self->buf) {
        PyErr_NoMemory();
        return -1;
    }
    vs_prefault(self->buf, (size_t)cap * (size_t)channels * sizeof(float)); /* no page faults in the input callback */
    return 0;
}

/* A writable C-contiguous float32 (frames, width) buffer, or an error naming `what`. */
static int get_frames(PyObject *obj, Py_buffer *view, int width, int writable, const char *what) {
    int flags = PyBUF_C_CONTIGUOUS | PyBUF_FORMAT | PyBUF_ND | (writable ? PyBUF_WRITABLE : 0);
    if (PyObject_GetBuffer(obj, view, flags) < 0) return -1;
    if (view->ndim != 2 || strcmp(view->format, "f") != 0 || view->shape[1] != width) {
        PyBuffer_Release(view);
        PyErr_Format(PyExc_ValueError, "%s must be a C-contiguous float32 array (frames, %d)", what, width);
        return -1;
    }
    return 0;
}

static PyObject *Ring_set_input_map(Ring *self, PyObject *args) {
    if (not_ready(self)) return NULL;
    int dev;
    PyObject *cols;
    if (!PyArg_ParseTuple(args, "iO", &dev, &cols)) return NULL;
    if (dev < 1 || dev > 4096 || PySequence_Length(cols) != self->channels) {
        PyErr_SetString(PyExc_ValueError, "need 1..4096 device channels and one device column per ring channel");
        return NULL;
    }
    int tmp[IN_MAXCH];
    for (int ch = 0; ch < self->channels; ch++) {
        PyObject *o = PySequence_GetItem(cols, ch);
        if (!o) return NULL;
        long v = PyLong_AsLong(o);
        Py_DECREF(o);
        if (v == -1 && PyErr_Occurred()) return NULL;
        if (v < 0 || v >= dev) {
            PyErr_SetString(PyExc_ValueError, "device column out of range");
            return NULL;
        }
        tmp[ch] = (int)v;
    }
    memcpy(self->cols, tmp, sizeof(int) * (size_t)self->channels);
    self->dev_channels = dev;
    Py_RETURN_NONE;
}

/* Consumer: copy up to len(out) frames out (oldest first); returns the number copied. */
static PyObject *Ring_read_into(Ring *self, PyObject *arg) {
    if (not_ready(self)) return NULL;
    Py_buffer view;
    if (get_frames(arg, &view, self->channels, 1, "out") < 0) return NULL;
    int64_t r = self->rpos;
    int64_t avail = LOAD_ACQ(&self->wpos) - r;
    int64_t n = view.shape[0] < avail ? view.shape[0] : avail;
    int64_t at = r & (self->cap - 1);
    int64_t first = n < self->cap - at ? n : self->cap - at;
    size_t row = sizeof(float) * (size_t)self->channels;
    if (first > 0) memcpy(view.buf, self->buf + at * self->channels, row * (size_t)first);
    if (n > first) memcpy((float *)view.buf + first * self->channels, self->buf, row * (size_t)(n - first));
    STORE_REL(&self->rpos, r + n);
    PyBuffer_Release(&view);
    return PyLong_FromLongLong(n);
}

/* Consumer: drop up to `frames` frames unread (negative: all); returns the number dropped. */
static PyObject *Ring_skip(Ring *self, PyObject *arg) {
    if (not_ready(self)) return NULL;
    long long want = PyLong_AsLongLong(arg);
    if (want == -1 && PyErr_Occurred()) return NULL;
    int64_t r = self->rpos;
    int64_t avail = LOAD_ACQ(&self->wpos) - r;
    int64_t n = want < 0 || want > avail ? avail : want;
    STORE_REL(&self->rpos, r + n);
    return PyLong_FromLongLong(n);
}

/* The producer outside PortAudio (the file feeder, tests): device-layout frames. The GIL is held
 * throughout, so Python producers take turns; never while a PortAudio stream feeds the ring. */
static PyObject *Ring_write(Ring *self, PyObject *arg) {
    if (not_ready(self)) return NULL;
    Py_buffer view;
    if (get_frames(arg, &view, self->dev_channels, 0, "frames") < 0) return NULL;
    int64_t before = self->wpos;
    ring_put(self, (const float *)view.buf, view.shape[0]);
    STORE_REL(&self->captured, self->captured + view.shape[0]);
    int64_t n = self->wpos - before;
    PyBuffer_Release(&view);
    return PyLong_FromLongLong(n);
}

/* Sleep `seconds`, 0..MAX_DELAY_S (checked by the caller), with the GIL released. */
static void pause_s(double seconds) {
    if (!(seconds > 0.0 && seconds <= MAX_DELAY_S)) return; /* NaN too: converting it to an integer is undefined */
#ifdef _WIN32
    Sleep((DWORD)(seconds * 1000.0));
#else
    struct timespec ts = {(time_t)seconds, (long)((seconds - (double)(time_t)seconds) * 1e9)};
    nanosleep(&ts, NULL);
#endif
}

/* Run the PortAudio callback on a float32 (frames, device_channels) block, or on `frames` frames
 * of no input (an int: PortAudio's NULL input), after `delay` seconds without the GIL: tests. */
static PyObject *Ring_run_callback(Ring *self, PyObject *args) {
    if (not_ready(self)) return NULL;
    PyObject *block;
    unsigned long status = 0;
    double delay = 0.0;
    vs_pa_time_t ti = {0.0, 0.0, 0.0};
    if (!PyArg_ParseTuple(args, "O|kdddd", &block, &status, &ti.input_adc, &ti.current, &ti.output_dac, &delay))
        return NULL;
    if (!(delay >= 0.0 && delay <= MAX_DELAY_S)) {
        char msg[120];
        PyOS_snprintf(msg, sizeof msg, "delay must be in 0..%g s, got %g", MAX_DELAY_S, delay);
        PyErr_SetString(PyExc_ValueError, msg);
        return NULL;
    }
    int rc;
    if (PyLong_Check(block)) {
        long long frames = PyLong_AsLongLong(block);
        if (frames < 0 || frames > MAX_CALLBACK_FRAMES) {
            if (!PyErr_Occurred())
                PyErr_Format(PyExc_ValueError, "block: frames must be in 0..%d, got %lld", MAX_CALLBACK_FRAMES, frames);
            return NULL;
        }
        Py_BEGIN_ALLOW_THREADS
        pause_s(delay);
        rc = input_callback(NULL, NULL, (unsigned long)frames, &ti, status, self);
        Py_END_ALLOW_THREADS
        return PyLong_FromLong(rc);
    }
    Py_buffer view;
    if (get_frames(block, &view, self->dev_channels, 0, "block") < 0) return NULL;
    Py_BEGIN_ALLOW_THREADS
    pause_s(delay);
    rc = input_callback(view.buf, NULL, (unsigned long)view.shape[0], &ti, status, self);
    Py_END_ALLOW_THREADS
    PyBuffer_Release(&view);
    return PyLong_FromLong(rc);
}

static PyObject *Ring_addresses(Ring *self, PyObject *unused) {
    if (not_ready(self)) return NULL;
    return Py_BuildValue("(KK)", (unsigned long long)(uintptr_t)&input_callback, (unsigned long long)(uintptr_t)self);
}

/* (first frame, adc time, current time, dac time, monotonic s) of the last callback, or None. */
static PyObject *Ring_stamp(Ring *self, PyObject *unused) {
    if (not_ready(self)) return NULL;
    int64_t frame;
    double t[4];
    if (!self->has_stamp || !vs_stamp_read(&self->stamp, &frame, t)) Py_RETURN_NONE;
    return Py_BuildValue("(Ldddd)", (long long)frame, t[0], t[1], t[2], t[3]);
}

static PyObject *Ring_take_peaks(Ring *self, PyObject *unused) {
    if (not_ready(self)) return NULL;
    PyObject *list = PyList_New(self->channels);
    if (!list) return NULL;
    for (int ch = 0; ch < self->channels; ch++) {
        volatile float *p = &self->peak[ch];
        PyObject *v = PyFloat_FromDouble((double)*p);
        *p = 0.0f;
        if (!v) {
            Py_DECREF(list);
            return NULL;
        }
        PyList_SetItem(list, ch, v);
    }
    return list;
}

static PyObject *Ring_take_load_peak(Ring *self, PyObject *unused) {
    if (not_ready(self)) return NULL;
    double peak = self->load_peak;
    self->load_peak = 0.0;
    return PyFloat_FromDouble(peak);
}

#define RING_INT(name, expr)                                                                       \
    static PyObject *Ring_get_##name(Ring *self, void *closure) {                                  \
        if (not_ready(self)) return NULL;                                                          \
        return PyLong_FromLongLong(expr);                                                          \
    }
RING_INT(channels, self->channels)
RING_INT(device_channels, self->dev_channels)
RING_INT(capacity, self->cap)
RING_INT(available, LOAD_ACQ(&self->wpos) - LOAD_ACQ(&self->rpos))
RING_INT(frames_written, LOAD_ACQ(&self->wpos))
RING_INT(frames_read, LOAD_ACQ(&self->rpos))
RING_INT(frames_captured, LOAD_ACQ(&self->captured))
RING_INT(dropped_frames, LOAD_ACQ(&self->dropped))
RING_INT(overflows, LOAD_ACQ(&self->overflows))
RING_INT(input_overflows, LOAD_ACQ(&self->pa_overflows))
RING_INT(input_underflows, LOAD_ACQ(&self->pa_underflows))
RING_INT(callbacks, LOAD_ACQ(&self->callbacks))
#define RING_DOUBLE(name, field)                                                                    \
    static PyObject *Ring_get_##name(Ring *self, void *closure) {                                  \
        if (not_ready(self)) return NULL;                                                          \
        return PyFloat_FromDouble(self->field);                                                    \
    }
RING_DOUBLE(fs, fs)
RING_DOUBLE(load_last, load_last)
RING_DOUBLE(load_peak, load_peak)
RING_DOUBLE(load_avg, load_avg)

static PyGetSetDef Ring_getset[] = {
    {"channels", (getter)Ring_get_channels, NULL, "channels of a ring frame", NULL},
    {"device_channels", (getter)Ring_get_device_channels, NULL, "channels of a device frame", NULL},
    {"capacity", (getter)Ring_get_capacity, NULL, "frames the ring holds", NULL},
    {"fs", (getter)Ring_get_fs, NULL, "sample rate (Hz)", NULL},
    {"available", (getter)Ring_get_available, NULL, "frames waiting to be read", NULL},
    {"frames_written", (getter)Ring_get_frames_written, NULL, "frames put in the ring since start", NULL},
    {"frames_read", (getter)Ring_get_frames_read, NULL, "frames read or skipped since start", NULL},
    {"frames_captured", (getter)Ring_get_frames_captured, NULL, "frames the device delivered (dropped too)", NULL},
    {"dropped_frames", (getter)Ring_get_dropped_frames, NULL, "frames dropped: the ring was full", NULL},
    {"overflows", (getter)Ring_get_overflows, NULL, "blocks that dropped frames (reader behind)", NULL},
    {"input_overflows", (getter)Ring_get_input_overflows, NULL, "blocks PortAudio flagged paInputOverflow", NULL},
    {"input_underflows", (getter)Ring_get_input_underflows, NULL, "blocks PortAudio flagged paInputUnderflow", NULL},
    {"callbacks", (getter)Ring_get_callbacks, NULL, "callbacks run", NULL},
    {"load_last", (getter)Ring_get_load_last, NULL, "last callback's time / block period", NULL},
    {"load_peak", (getter)Ring_get_load_peak, NULL, "peak load since take_load_peak()", NULL},
    {"load_avg", (getter)Ring_get_load_avg, NULL, "exponential average load", NULL},
    {NULL}};

static PyMethodDef Ring_methods[] = {
    {"set_input_map", (PyCFunction)Ring_set_input_map, METH_VARARGS,
     "set_input_map(device_channels, columns): the device column of each ring channel (no stream running)"},
    {"read_into", (PyCFunction)Ring_read_into, METH_O,
     "read_into(out float32 (frames, channels)) -> frames copied, oldest first"},
    {"skip", (PyCFunction)Ring_skip, METH_O, "skip(frames) -> frames dropped unread (negative: all waiting)"},
    {"write", (PyCFunction)Ring_write, METH_O,
     "write(frames float32 (n, device_channels)) -> frames stored; the producer's side outside PortAudio"},
    {"run_callback", (PyCFunction)Ring_run_callback, METH_VARARGS,
     "run_callback(block float32 (frames, device_channels) | frames, status=0, adc=0, current=0, dac=0, "
     "delay=0) -> paContinue, called after delay s without the GIL; for tests"},
    {"addresses", (PyCFunction)Ring_addresses, METH_NOARGS, "(PaStreamCallback address, userdata address)"},
    {"stamp", (PyCFunction)Ring_stamp, METH_NOARGS,
     "(first frame, adc, current, dac, monotonic) of the last callback's block, or None"},
    {"take_peaks", (PyCFunction)Ring_take_peaks, METH_NOARGS, "[|x| max per channel since the last call] (resets)"},
    {"take_load_peak", (PyCFunction)Ring_take_load_peak, METH_NOARGS, "peak load since the last call (resets)"},
    {NULL}};

/* A heap type (the limited API has no static PyTypeObject), immutable like a static one. */
static PyType_Slot Ring_slots[] = {
    {Py_tp_doc, (void *)"InputRing(channels, capacity, fs): lock-free input ring and its PortAudio callback."},
    {Py_tp_new, (void *)PyType_GenericNew},
    {Py_tp_init, (void *)Ring_init},
    {Py_tp_dealloc, (void *)Ring_dealloc},
    {Py_tp_methods, Ring_methods},
    {Py_tp_getset, Ring_getset},
    {0, NULL}};
static PyType_Spec Ring_spec = {"vibsynth.engine._input.InputRing", sizeof(Ring), 0,
                                Py_TPFLAGS_DEFAULT | Py_TPFLAGS_IMMUTABLETYPE, Ring_slots};

static struct PyModuleDef module = {PyModuleDef_HEAD_INIT, "_input", "vibsynth real-time input ring", -1, NULL};

PyMODINIT_FUNC PyInit__input(void) {
    PyObject *m = PyModule_Create(&module);
    if (!m) return NULL;
    PyObject *type = PyType_FromSpec(&Ring_spec);
    if (!type || PyModule_AddObject(m, "InputRing", type) < 0) { /* (AddObject steals on success only) */
        Py_XDECREF(type);
        Py_DECREF(m);
        return NULL;
    }
    PyModule_AddIntConstant(m, "MAX_CHANNELS", IN_MAXCH);
    PyModule_AddIntConstant(m, "PA_INPUT_UNDERFLOW", (long)PA_INPUT_UNDERFLOW);
    PyModule_AddIntConstant(m, "PA_INPUT_OVERFLOW", (long)PA_INPUT_OVERFLOW);
    return m;
}
