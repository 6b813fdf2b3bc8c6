/*
 * libFuzzer harness of the OSC fast path's datagram parser (vibsynth/control/osc/_fast.c).
 *
 * _fast.c is included whole, so its static functions are reachable: each input is one UDP
 * datagram handed to fast_handle(), the function the receive loop calls on every datagram, with
 * a Receiver set up as `vibsynth serve` sets it up (the table of /vibsynth and 8 channels, plus
 * the longest address the table holds) and a fake engine core whose push() checks and records
 * the commands (and refuses every 7th one: a full ring).
 *
 * Besides ASan/UBSan findings, the harness checks what the fast path promises:
 *   - a datagram it takes is one well-formed message, as the Python decoder reads it: the
 *     harness decodes it with vibsynth.control.osc.codec.decode_packet (the embedded
 *     interpreter) and compares address, argument count and values with what was pushed;
 *   - pushed values are finite and inside the live ranges, channels inside the core's;
 *   - it fits a monitor's log entry (SEEN_DATAGRAM), as log_seen() assumes.
 * A broken promise aborts (a crash for libFuzzer, with its input written as the reproducer).
 *
 * Build and run: scripts/fuzz.sh (clang -fsanitize=fuzzer,address,undefined against the Python
 * headers; PYTHONPATH must reach the repository).
 */
#include "../vibsynth/control/osc/_fast.c"

#include <stdio.h>
#include <stdlib.h>

#define CHANNELS 8
#define BAL_MIN (-3.5)
#define BAL_MAX 3.5
#define MAX_PUSHED 4

static Receiver rx;
static PyObject *decode_packet;
static vs_cmd_t pushed[MAX_PUSHED];
static int n_pushed, push_calls;

static void fail(const char *what, const uint8_t *d, size_t n) {
    fprintf(stderr, "fuzz_datagram: %s (datagram of %zu bytes)\n", what, n);
    for (size_t i = 0; i < n && i < 256; i++) fprintf(stderr, "%02x%s", d[i], i % 32 == 31 ? "\n" : " ");
    fprintf(stderr, "\n");
    abort();
}

static int fake_push(struct vs_core *core, vs_cmd_t *cmd, int64_t *seq) {
    (void)core;
    if (++push_calls % 7 == 0) return PUSH_RING_FULL;
    if (n_pushed == MAX_PUSHED) abort(); /* one datagram moves at most two knobs */
    pushed[n_pushed++] = *cmd;
    *seq = push_calls;
    return PUSH_OK;
}

static int fake_channels(struct vs_core *core) {
    (void)core;
    return CHANNELS;
}

static const vs_core_api_t fake_api = {.push = fake_push, .channels = fake_channels};

static void add(const char *address, int method, int channel) {
    int len = (int)strlen(address);
    if (len < 1 || len >= MAX_ADDR) abort();
    uint32_t i = hash_bytes(address, len) & (TABLE_SIZE - 1);
    while (rx.table[i].len) i = (i + 1) & (TABLE_SIZE - 1);
    memcpy(rx.table[i].address, address, (size_t)len);
    rx.table[i].len = len;
    rx.table[i].method = method;
    rx.table[i].channel = channel;
}

int LLVMFuzzerInitialize(int *argc, char ***argv) {
    (void)argc;
    (void)argv;
    static const char *methods[] = {"intensity", "balance", "texture"};
    char address[MAX_ADDR + 16];
    rx.api = &fake_api;
    rx.channels = CHANNELS;
    rx.bal_min = BAL_MIN;
    rx.bal_max = BAL_MAX;
    for (int m = 0; m < 3; m++) { /* as fast.fast_table builds it for the prefix /vibsynth */
        snprintf(address, sizeof address, "/vibsynth/%s", methods[m]);
        add(address, m + 1, -1);
        for (int c = 0; c < CHANNELS; c++) {
            snprintf(address, sizeof address, "/vibsynth/ch/%d/%s", c + 1, methods[m]);
            add(address, m + 1, c);
        }
    }
    /* the longest address the table holds (limits.OSC_FAST_ADDRESS_MAX bytes) */
    memset(address, 'a', MAX_ADDR - 1);
    address[0] = '/';
    address[MAX_ADDR - 1] = 0;
    add(address, M_TEXTURE, CHANNELS - 1);

    Py_Initialize();
    PyObject *codec = PyImport_ImportModule("vibsynth.control.osc.codec");
    if (codec) decode_packet = PyObject_GetAttrString(codec, "decode_packet");
    if (!decode_packet) {
        PyErr_Print();
        fprintf(stderr, "fuzz_datagram: cannot import vibsynth.control.osc.codec (PYTHONPATH?)\n");
        exit(2);
    }
    Py_XDECREF(codec);
    return 0;
}

static const entry_t *entry_of(const char *address, Py_ssize_t len) {
    return len < MAX_ADDR ? lookup(&rx, address, (int)len) : NULL;
}

/* The Python decoder's reading of a datagram the fast path took must be what was pushed. */
static void check_taken(const uint8_t *d, size_t n) {
    if (n > SEEN_DATAGRAM) fail("taken datagram longer than a monitor log entry", d, n);
    PyObject *msg = PyObject_CallFunction(decode_packet, "y#", (const char *)d, (Py_ssize_t)n);
    if (!msg) {
        PyErr_Print();
        fail("the fast path took a datagram the Python decoder refuses", d, n);
    }
    PyObject *address = PyObject_GetAttrString(msg, "address");
    PyObject *args = PyObject_GetAttrString(msg, "args");
    if (!address || !args || !PyUnicode_Check(address) || !PyTuple_Check(args)) {
        PyErr_Clear();
        fail("the fast path took a bundle or something not a message", d, n);
    }
    Py_ssize_t alen;
    const char *a = PyUnicode_AsUTF8AndSize(address, &alen);
    const entry_t *e = a ? entry_of(a, alen) : NULL;
    if (!e) fail("the Python decoder reads another address than a table entry", d, n);
    Py_ssize_t nargs = PyTuple_GET_SIZE(args);
    if (nargs != (e->method == M_TEXTURE ? 2 : 1)) fail("argument count differs from the method's", d, n);
    double v[2];
    for (Py_ssize_t k = 0; k < nargs; k++) {
        v[k] = PyFloat_AsDouble(PyTuple_GET_ITEM(args, k));
        if (PyErr_Occurred()) fail("an argument the Python decoder reads as no number", d, n);
    }
    /* texture pushes balance then intensity; the harness's ring may refuse one push */
    for (int k = 0; k < n_pushed; k++) {
        const vs_cmd_t *c = &pushed[k];
        double want = e->method == M_TEXTURE ? (c->arg == 1 ? v[1] : v[0]) : v[0];
        if (c->kind != CMD_KNOB || c->arg != (e->method == M_BALANCE || (e->method == M_TEXTURE && k == 0)))
            fail("pushed the wrong knob", d, n);
        if (c->value != want) fail("pushed another value than the datagram holds", d, n);
        if (!isfinite(c->value)) fail("pushed a value that is not finite", d, n);
        if (c->arg == 0 && !(c->value >= 0.0 && c->value <= 1.0)) fail("pushed intensity outside [0, 1]", d, n);
        if (c->arg == 1 && !(c->value >= BAL_MIN && c->value <= BAL_MAX)) fail("pushed balance outside the live range", d, n);
        uint64_t mask = e->channel < 0 ? ~(uint64_t)0 : (uint64_t)1 << e->channel;
        if (c->mask != mask) fail("pushed to other channels than the address names", d, n);
    }
    Py_DECREF(address);
    Py_DECREF(args);
    Py_DECREF(msg);
}

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size) {
    if (size > MAX_DATAGRAM) return 0; /* recvfrom never hands more */
    n_pushed = 0;
    /* a private copy of exactly `size` bytes: ASan sees any read past the datagram */
    uint8_t *d = malloc(size ? size : 1);
    memcpy(d, data, size);
    int taken = fast_handle(&rx, d, (int)size);
    if (taken) check_taken(d, size);
    else if (n_pushed)
        fail("left a datagram to Python after moving a knob (Python would move it again)", d, size);
    free(d);
    return 0;
}
