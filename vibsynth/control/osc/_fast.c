/*
 * OSC UDP fast path: the receive loop of the OSC server, in C.
 *
 * A VR app or a controller sends the same few messages hundreds of times a second:
 * `/vibsynth/intensity f`, `/vibsynth/balance f`, `/vibsynth/texture ff` and their
 * `/vibsynth/ch/N/...` forms. This loop receives datagrams with the GIL released, checks
 * the sender against the allow list, and decodes those shapes against a precomputed table
 * of exact addresses (no pattern matching); a valid in-range value goes straight into the
 * engine's command ring through the core's C API. Anything else (patterns, bundles, other
 * methods, out-of-range or non-finite values, malformed packets) is handed, in arrival
 * order, to the Python handler, which validates, answers and counts it.
 *
 * Python never holds up the socket. run() is the receive thread: once started it never takes the
 * GIL, so a busy interpreter (a slow handler, a thread holding the GIL, a machine so loaded that
 * normally scheduled threads wait for seconds) cannot stop it reading, and the fast path keeps
 * feeding the engine meanwhile. What is for Python goes into a queue (QUEUE_MAX datagrams,
 * QUEUE_ARENA bytes: seconds of a 10,000 messages/s flood), which deliver() hands over on a
 * second thread: on_state first, then on_slow. A datagram that finds the queue full is dropped and
 * counted (counters()["queue_full"]), never silently lost in the kernel's buffer.
 *
 * Order: while a datagram waits in the queue or Python is handling the queue's last hand-over,
 * every new datagram joins the queue too, and before Python sees queued datagrams the knob values
 * set by the fast path are recorded in the controller (on_state). So a `get` after a fast
 * `intensity` answers the new value, and the engine receives every command in arrival order.
 *
 * Without an engine core (core=None) there is no fast path: this is then just the receive
 * loop (allow list, queue) in front of the Python handler.
 *
 * The controller (queries, notify subscribers) learns of fast-path moves through
 * on_state(updates, last_seq, seen) with the last value per (knob, channel): before each
 * hand-over of the queue and at most every STATE_PERIOD_S otherwise.
 *
 * Monitors: while the byte of the `watch` buffer (the input tap's flag) is non-zero, each
 * datagram the fast path takes is also copied, as received, with its sender and arrival time,
 * into a log of MAX_SEEN entries handed to on_state as `seen` [(datagram, (host, port), unix
 * time), ...] in arrival order. While the log is full, datagrams go the queue's way (Python then
 * describes them itself): nothing is dropped.
 *
 * Locks: qlock guards the queue, the fast-path state and the log, for a few hundred
 * nanoseconds at a time, never while calling Python or waiting; wake is a binary semaphore
 * (posted at most once per hand-over) on which deliver() waits with the GIL released.
 *
 * Hostile callers: `core` must be an initialised vibsynth.engine._core.Core (checked against the
 * type the core's capsule exports: TypeError otherwise) or None; a Receiver is initialised once
 * (a second __init__ raises RuntimeError: run() may be using it on another thread), and run(),
 * stop() and counters() refuse one whose __init__ has not succeeded.
 *
 * Receive errors: EINTR is retried, EAGAIN ends the batch; errors a working UDP socket can report
 * (an ICMP error for an earlier reply, a lack of buffers: recv_error_kind) are counted
 * (counters()["recv_errors"]) and retried after a growing nap, and run() raises OSError after
 * MAX_RECV_ERRORS of them in a row; any other error (not a socket, a closed descriptor) makes
 * run() raise OSError at once. So run() never spins on a persistent error, and stop() is always
 * honoured within POLL_MS.
 */
#define PY_SSIZE_T_CLEAN
#include <Python.h>
#include <math.h>
#include <stdlib.h> /* malloc/calloc/free: Python.h leaves it out of limited-API builds */
#include <stdint.h>
#include <string.h>

#include "../../engine/_core_api.h"

#ifdef _WIN32
#include <winsock2.h>
#include <ws2tcpip.h>
typedef SOCKET sock_t;
#define poll WSAPoll
typedef int socklen_t;
#else
#include <arpa/inet.h>
#include <errno.h>
#include <netinet/in.h>
#include <poll.h>
#include <sys/socket.h>
#include <time.h>
typedef int sock_t;
#endif
#include "../../engine/_rt.h" /* after winsock2.h, which must come before windows.h */

#define MAX_DATAGRAM 65536
#define MAX_BATCH 256 /* datagrams read per poll() (then stop() is checked) */
#define QUEUE_MAX 32768 /* datagrams waiting for Python: > 3 s of a 10,000/s flood */
#define QUEUE_ARENA (4 << 20) /* their bytes */
#define TABLE_SIZE 4096 /* open addressing; > 4 x the largest table (15 + 8 x 64 addresses) */
#define MAX_ADDR 128
#define MAX_NETS 64
#define MAXCH 64
#define STATE_PERIOD_S 0.02
#define POLL_MS 100
#define MAX_SEEN 256
#define SEEN_DATAGRAM 160 /* > the longest fast-path datagram: 128 (address) + 4 (",dd") + 16 */
#define MAX_RECV_ERRORS 64 /* run() raises after this many receive errors in a row (no datagram between) */

enum { M_INTENSITY = 1, M_BALANCE = 2, M_TEXTURE = 3 };

typedef struct {
    char address[MAX_ADDR];
    int len;      /* 0 = empty slot */
    int method;
    int channel;  /* -1 = every channel */
} entry_t;

/* A sender, compactly (a queue holds QUEUE_MAX of them). */
typedef struct {
    uint8_t family; /* AF_INET or AF_INET6 */
    uint8_t ip[16];
    uint16_t port;
} peer_t;

typedef struct {
    double when;  /* wall clock (Unix seconds) of arrival */
    int len;
    uint8_t data[SEEN_DATAGRAM];
    peer_t peer;
} seen_t;

typedef struct {
    uint32_t off, len; /* in the queue's arena */
    peer_t peer;
} qitem_t;

/* Datagrams for Python, in arrival order, and the monitors' log of fast-path datagrams. */
typedef struct {
    qitem_t *items;
    uint8_t *arena;
    size_t used;
    int n;
    seen_t *seen;
    int n_seen;
} queue_t;

typedef struct {
    int family;   /* 4 or 6 */
    uint8_t net[16];
    int prefix;
} net_t;

typedef struct {
    PyObject_HEAD
    sock_t fd;
    PyObject *core;         /* the engine's _core.Core (kept alive) */
    struct vs_core *core_ptr;
    const vs_core_api_t *api;
    int channels;
    double bal_min, bal_max;
    PyObject *on_slow;      /* on_slow([(bytes, (host, port)), ...]) */
    PyObject *on_state;     /* on_state([(knob, channel, value), ...], last_seq, seen) */
    Py_buffer watch_view;   /* the tap's flag (view.obj NULL: no monitor support) */
    const volatile uint8_t *watch;
    entry_t table[TABLE_SIZE];
    net_t nets[MAX_NETS];
    int n_nets;             /* -1 = allow everyone */
    volatile int stop;
    int running;
    int finished;           /* (qlock) run() has returned: deliver() hands over what is left, then says so */
    int delivering;         /* deliver() is running (on some thread) */
    /* under qlock: what waits for Python */
    PyThread_type_lock qlock, wake;
    int wake_posted;        /* wake is released and deliver() has not taken it yet */
    queue_t q[2];           /* q[fill] fills; deliver() hands over the other */
    int fill;
    int handing;            /* Python is handling queued datagrams: new ones queue behind them */
    double last_value[2][MAXCH]; /* fast-path state not yet recorded in the controller */
    uint8_t dirty[2][MAXCH];
    int any_dirty;
    int64_t last_seq;
    /* deliver()'s own */
    double snap_value[2][MAXCH];
    uint8_t snap_dirty[2][MAXCH];
    double last_flush;
    /* counters */
    long long packets, bytes, fast, slow, delivered, denied, ring_full, queue_full, handler_errors, recv_errors;
    uint8_t *scratch;
    int ready; /* __init__ succeeded: set once, last, and never cleared */
} Receiver;

static double wall_s(void) {
#ifdef _WIN32
    FILETIME ft;
    GetSystemTimePreciseAsFileTime(&ft);
    return (double)(((uint64_t)ft.dwHighDateTime << 32) | ft.dwLowDateTime) * 1e-7 - 11644473600.0;
#else
    struct timespec ts;
    clock_gettime(CLOCK_REALTIME, &ts);
    return (double)ts.tv_sec + 1e-9 * (double)ts.tv_nsec;
#endif
}

static uint32_t hash_bytes(const char *s, int n) {
    uint32_t h = 2166136261u;
    for (int i = 0; i < n; i++) h = (h ^ (uint8_t)s[i]) * 16777619u;
    return h;
}

static const entry_t *lookup(const Receiver *r, const char *s, int n) {
    if (n >= MAX_ADDR) return NULL;
    uint32_t i = hash_bytes(s, n) & (TABLE_SIZE - 1);
    for (int probes = 0; probes < TABLE_SIZE; probes++, i = (i + 1) & (TABLE_SIZE - 1)) {
        const entry_t *e = &r->table[i];
        if (!e->len) return NULL;
        if (e->len == n && memcmp(e->address, s, (size_t)n) == 0) return e;
    }
    return NULL;
}

static int allowed(const Receiver *r, const struct sockaddr_storage *addr) {
    if (r->n_nets < 0) return 1;
    const uint8_t *bytes;
    int family;
    uint8_t mapped[4];
    if (addr->ss_family == AF_INET) {
        bytes = (const uint8_t *)&((const struct sockaddr_in *)addr)->sin_addr;
        family = 4;
    } else if (addr->ss_family == AF_INET6) {
        bytes = (const uint8_t *)&((const struct sockaddr_in6 *)addr)->sin6_addr;
        family = 6;
        static const uint8_t v4prefix[12] = {0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0xff, 0xff};
        if (memcmp(bytes, v4prefix, 12) == 0) { /* IPv4-mapped: compare as IPv4 */
            memcpy(mapped, bytes + 12, 4);
            bytes = mapped;
            family = 4;
        }
    } else {
        return 0;
    }
    for (int k = 0; k < r->n_nets; k++) {
        const net_t *net = &r->nets[k];
        if (net->family != family) continue;
        int bits = net->prefix, i = 0;
        for (; bits >= 8; bits -= 8, i++)
            if (bytes[i] != net->net[i]) goto next;
        if (bits && ((bytes[i] ^ net->net[i]) & (uint8_t)(0xff << (8 - bits)))) goto next;
        return 1;
    next:;
    }
    return 0;
}

/* ------------------------------------------------------------------ decoding */
static int padded(int n) { return (n + 4) & ~3; } /* string of n chars + NUL, to a multiple of 4 */

static int read_number(const uint8_t *p, char tag, double *out, int *size) {
    if (tag == 'f') {
        uint32_t u = (uint32_t)p[0] << 24 | (uint32_t)p[1] << 16 | (uint32_t)p[2] << 8 | p[3];
        float f;
        memcpy(&f, &u, 4);
        *out = f;
        *size = 4;
    } else if (tag == 'i') {
        uint32_t u = (uint32_t)p[0] << 24 | (uint32_t)p[1] << 16 | (uint32_t)p[2] << 8 | p[3];
        *out = (double)(int32_t)u;
        *size = 4;
    } else if (tag == 'd') {
        uint64_t u = 0;
        for (int i = 0; i < 8; i++) u = u << 8 | p[i];
        memcpy(out, &u, 8);
        *size = 8;
    } else {
        return 0;
    }
    return isfinite(*out);
}

static void mark(Receiver *r, int knob, int channel, double value) {
    if (channel < 0) {
        for (int c = 0; c < r->channels; c++) {
            r->last_value[knob][c] = value;
            r->dirty[knob][c] = 1;
        }
    } else {
        r->last_value[knob][channel] = value;
        r->dirty[knob][channel] = 1;
    }
    r->any_dirty = 1;
}

static int push_knob(Receiver *r, int knob, int channel, double value) {
    vs_cmd_t cmd = {CMD_KNOB, knob, value, NAN, channel < 0 ? ~(uint64_t)0 : (uint64_t)1 << channel, -1, 0};
    int64_t seq = 0;
    if (r->api->push(r->core_ptr, &cmd, &seq) != PUSH_OK) {
        r->ring_full++;
        return 0;
    }
    r->last_seq = seq;
    mark(r, knob, channel, value);
    return 1;
}

/* 1 = handled here; 0 = for Python (which validates and answers). */
static int fast_handle(Receiver *r, const uint8_t *d, int n) {
    if (!r->api || n < 8 || (n & 3) || d[0] != '/') return 0;
    const uint8_t *nul = memchr(d, 0, (size_t)n);
    if (!nul) return 0;
    int alen = (int)(nul - d);
    int off = padded(alen);
    if (off >= n || d[off] != ',') return 0;
    const entry_t *e = lookup(r, (const char *)d, alen);
    if (!e) return 0;
    const uint8_t *tnul = memchr(d + off, 0, (size_t)(n - off));
    if (!tnul) return 0;
    int tlen = (int)(tnul - (d + off));
    const char *types = (const char *)d + off + 1;
    int nargs = tlen - 1;
    int want = e->method == M_TEXTURE ? 2 : 1;
    if (nargs != want) return 0;
    int p = off + padded(tlen);
    double v[2];
    for (int k = 0; k < nargs; k++) {
        int size;
        if (p + 4 > n || (types[k] == 'd' && p + 8 > n)) return 0;
        if (!read_number(d + p, types[k], &v[k], &size)) return 0;
        p += size;
    }
    if (p != n) return 0;
    switch (e->method) {
    case M_INTENSITY:
        if (!(v[0] >= 0.0 && v[0] <= 1.0)) return 0;
        return push_knob(r, 0, e->channel, v[0]);
    case M_BALANCE:
        if (!(v[0] >= r->bal_min && v[0] <= r->bal_max)) return 0;
        return push_knob(r, 1, e->channel, v[0]);
    case M_TEXTURE:
        if (!(v[0] >= 0.0 && v[0] <= 1.0) || !(v[1] >= r->bal_min && v[1] <= r->bal_max)) return 0;
        /* as Controller.set_texture: balance first, then intensity */
        if (!push_knob(r, 1, e->channel, v[1])) return 0;
        push_knob(r, 0, e->channel, v[0]);
        return 1;
    default:
        return 0;
    }
}

/* ------------------------------------------------------------------ the queue (qlock held) */
static void peer_of(const struct sockaddr_storage *addr, peer_t *p) {
    memset(p, 0, sizeof *p);
    if (addr->ss_family == AF_INET6) {
        const struct sockaddr_in6 *a = (const struct sockaddr_in6 *)addr;
        p->family = AF_INET6;
        memcpy(p->ip, &a->sin6_addr, 16);
        p->port = ntohs(a->sin6_port);
    } else {
        const struct sockaddr_in *a = (const struct sockaddr_in *)addr;
        p->family = AF_INET;
        memcpy(p->ip, &a->sin_addr, 4);
        p->port = ntohs(a->sin_port);
    }
}

/* Keep a copy of a datagram the fast path took, for monitors. */
static void log_seen(queue_t *q, const uint8_t *d, int n, const struct sockaddr_storage *addr) {
    if (n > SEEN_DATAGRAM || q->n_seen >= MAX_SEEN) return; /* cannot happen: take() and fast_handle bound both */
    seen_t *s = &q->seen[q->n_seen++];
    s->when = wall_s();
    s->len = n;
    memcpy(s->data, d, (size_t)n);
    peer_of(addr, &s->peer);
}

/* Wake deliver() (qlock held): at most once per hand-over, so a flood does not wake it per datagram. */
static void post_locked(Receiver *r) {
    if (!r->wake_posted) {
        r->wake_posted = 1;
        PyThread_release_lock(r->wake);
    }
}

/* One received, allowed datagram: into the engine (fast path) or into the queue for Python. */
static void take(Receiver *r, const uint8_t *d, int n, const struct sockaddr_storage *addr) {
    PyThread_acquire_lock(r->qlock, WAIT_LOCK);
    queue_t *q = &r->q[r->fill];
    int watched = r->watch && *r->watch;
    int news; /* something deliver() did not know of: the first queued datagram, state or log entry */
    if (!q->n && !r->handing && (!watched || q->n_seen < MAX_SEEN)) {
        int was_dirty = r->any_dirty;
        if (fast_handle(r, d, n)) {
            r->fast++;
            if (watched) log_seen(q, d, n, addr);
            news = (!was_dirty && r->any_dirty) || (watched && q->n_seen == 1);
            goto done;
        }
    }
    if (q->n == QUEUE_MAX || q->used + (size_t)n > QUEUE_ARENA) {
        r->queue_full++;
        news = 0;
    } else {
        qitem_t *it = &q->items[q->n++];
        it->off = (uint32_t)q->used;
        it->len = (uint32_t)n;
        peer_of(addr, &it->peer);
        memcpy(q->arena + q->used, d, (size_t)n);
        q->used += (size_t)n;
        r->slow++;
        news = q->n == 1;
    }
done:
    if (news) post_locked(r);
    PyThread_release_lock(r->qlock);
}

static void post_wake(Receiver *r) {
    PyThread_acquire_lock(r->qlock, WAIT_LOCK);
    post_locked(r);
    PyThread_release_lock(r->qlock);
}

/* ------------------------------------------------------------------ calls into Python (GIL held) */
static PyObject *peer_tuple(const peer_t *p) {
    char host[INET6_ADDRSTRLEN];
    inet_ntop(p->family, p->ip, host, sizeof host);
    return Py_BuildValue("(si)", host, (int)p->port);
}

/* on_state(updates, last_seq, seen) with deliver()'s snapshot and q's log. */
static void hand_state(Receiver *r, const queue_t *q, int64_t seq) {
    PyObject *seen = PyList_New(q->n_seen);
    PyObject *list = PyList_New(0);
    if (!list || !seen) goto fail;
    for (int k = 0; k < q->n_seen; k++) {
        const seen_t *s = &q->seen[k];
        PyObject *t = Py_BuildValue("(y#Nd)", (const char *)s->data, (Py_ssize_t)s->len, peer_tuple(&s->peer), s->when);
        if (!t) goto fail;
        PyList_SetItem(seen, k, t);
    }
    for (int knob = 0; knob < 2; knob++) {
        for (int c = 0; c < r->channels; c++) {
            if (!r->snap_dirty[knob][c]) continue;
            PyObject *t = Py_BuildValue("(sid)", knob ? "balance" : "intensity", c, r->snap_value[knob][c]);
            if (!t || PyList_Append(list, t) < 0) {
                Py_XDECREF(t);
                goto fail;
            }
            Py_DECREF(t);
        }
    }
    PyObject *res = PyObject_CallFunction(r->on_state, "OLO", list, (long long)seq, seen);
    Py_DECREF(list);
    Py_DECREF(seen);
    if (!res) goto fail_noclean;
    Py_DECREF(res);
    return;
fail:
    Py_XDECREF(list);
    Py_XDECREF(seen);
fail_noclean:
    r->handler_errors++;
    PyErr_WriteUnraisable(r->on_state);
}

/* on_slow([(datagram, (host, port)), ...]) with q's datagrams, in arrival order. */
static void hand_slow(Receiver *r, const queue_t *q) {
    PyObject *list = PyList_New(q->n);
    if (!list) goto fail;
    for (int k = 0; k < q->n; k++) {
        const qitem_t *it = &q->items[k];
        PyObject *t = Py_BuildValue("(y#N)", (const char *)q->arena + it->off, (Py_ssize_t)it->len, peer_tuple(&it->peer));
        if (!t) {
            Py_DECREF(list);
            goto fail;
        }
        PyList_SetItem(list, k, t);
    }
    PyObject *res = PyObject_CallFunctionObjArgs(r->on_slow, list, NULL);
    Py_DECREF(list);
    if (res) {
        Py_DECREF(res);
        return;
    }
fail:
    r->handler_errors++;
    PyErr_WriteUnraisable(r->on_slow);
}

/* ------------------------------------------------------------------ the loop */
enum { RX_RETRY, RX_WAIT, RX_TRANSIENT, RX_FATAL };

static int sock_errno(void) {
#ifdef _WIN32
    return WSAGetLastError();
#else
    return errno;
#endif
}

/* What a receive error means: retry now, no datagram waiting, a passing error (count it, nap,
 * retry), or one that will not pass (not a socket, closed, invalid). */
static int recv_error_kind(int err) {
#ifdef _WIN32
    switch (err) {
    case WSAEINTR: return RX_RETRY;
    case WSAEWOULDBLOCK: return RX_WAIT;
    case WSAECONNRESET: /* an ICMP port unreachable for an earlier reply */
    case WSAENETRESET:
    case WSAEMSGSIZE:
    case WSAENOBUFS:
    case WSAETIMEDOUT: return RX_TRANSIENT;
    default: return RX_FATAL;
    }
#else
    if (err == EINTR) return RX_RETRY;
    if (err == EAGAIN || err == EWOULDBLOCK) return RX_WAIT;
    switch (err) {
    case ECONNREFUSED: /* an ICMP error for an earlier reply (connected sockets, IP_RECVERR) */
    case ECONNRESET:
    case EHOSTUNREACH:
    case ENETUNREACH:
    case ETIMEDOUT:
    case ENOMEM:
    case ENOBUFS: return RX_TRANSIENT;
    default: return RX_FATAL;
    }
#endif
}

/* Sleep `ms` milliseconds (GIL released). */
static void nap_ms(int ms) {
#ifdef _WIN32
    Sleep((DWORD)ms);
#else
    struct timespec ts = {ms / 1000, (long)(ms % 1000) * 1000000L};
    nanosleep(&ts, NULL);
#endif
}

static void set_os_error(int err) {
#ifdef _WIN32
    PyErr_SetExcFromWindowsErr(PyExc_OSError, err);
#else
    errno = err;
    PyErr_SetFromErrno(PyExc_OSError);
#endif
}

/* 1 (with a RuntimeError) when __init__ has not succeeded. */
static int not_ready(const Receiver *r) {
    if (r->ready) return 0;
    PyErr_SetString(PyExc_RuntimeError, "Receiver is not initialised (its __init__ has not succeeded)");
    return 1;
}

static PyObject *Receiver_run(Receiver *r, PyObject *unused) {
    if (not_ready(r)) return NULL;
    if (r->running) {
        PyErr_SetString(PyExc_RuntimeError, "already running");
        return NULL;
    }
    r->running = 1;
    PyThread_acquire_lock(r->qlock, WAIT_LOCK); /* held for nanoseconds: the GIL may stay held */
    r->finished = 0;
    PyThread_release_lock(r->qlock);
    int err = 0;         /* the error that ends run() (0: stop()) */
    int consecutive = 0; /* receive errors since the last datagram */
    PyThreadState *ts = PyEval_SaveThread(); /* and never taken again until run() returns */
    while (!r->stop) {
        if (consecutive) { /* a passing error: let it pass (1, 2, ... POLL_MS ms) before trying again */
            nap_ms(consecutive < POLL_MS ? consecutive : POLL_MS);
            if (r->stop) break;
        }
        struct pollfd pfd = {r->fd, POLLIN, 0};
        int ready = poll(&pfd, 1, POLL_MS);
        if (r->stop) break;
        if (ready < 0) {
            int e = sock_errno();
            if (recv_error_kind(e) == RX_RETRY) continue;
            r->recv_errors++;
            err = e;
            break;
        }
        if (ready > 0 && (pfd.revents & POLLNVAL)) { /* not an open descriptor */
            r->recv_errors++;
#ifdef _WIN32
            err = WSAENOTSOCK;
#else
            err = EBADF;
#endif
            break;
        }
        for (int batch = 0; ready > 0 && batch < MAX_BATCH;) {
            struct sockaddr_storage addr;
            socklen_t alen = sizeof addr;
#ifdef _WIN32
            int n = recvfrom(r->fd, (char *)r->scratch, MAX_DATAGRAM, 0, (struct sockaddr *)&addr, &alen);
#else
            ssize_t n = recvfrom(r->fd, r->scratch, MAX_DATAGRAM, MSG_DONTWAIT, (struct sockaddr *)&addr, &alen);
#endif
            if (n < 0) {
                int e = sock_errno();
                int kind = recv_error_kind(e);
                if (kind == RX_WAIT) {
                    consecutive = 0;
                    break;
                }
                if (kind == RX_RETRY && ++consecutive < MAX_RECV_ERRORS) continue;
                if (kind != RX_RETRY) r->recv_errors++;
                if (kind == RX_TRANSIENT && ++consecutive < MAX_RECV_ERRORS) break;
                err = e;
                break;
            }
            consecutive = 0;
            batch++;
            r->packets++;
            r->bytes += n;
            if (!allowed(r, &addr)) {
                r->denied++;
                continue;
            }
            take(r, r->scratch, (int)n, &addr);
        }
        if (err) break;
    }
    /* Under qlock, after the last take(): deliver() reading it under qlock has seen every datagram. */
    PyThread_acquire_lock(r->qlock, WAIT_LOCK);
    r->finished = 1;
    post_locked(r); /* deliver() hands over what is left, then returns False */
    PyThread_release_lock(r->qlock);
    PyEval_RestoreThread(ts);
    r->running = 0;
    if (err && !r->stop) { /* after stop() (e.g. a socket closed meanwhile), an error is the end asked for */
        set_os_error(err);
        return NULL;
    }
    Py_RETURN_NONE;
}

/* Snapshot, under qlock: swap the queues, copy the fast-path state. Returns the queue to hand over. */
static queue_t *swap_queues(Receiver *r, int64_t *seq) {
    queue_t *q = &r->q[r->fill];
    r->fill = 1 - r->fill;
    r->handing = q->n > 0;
    memcpy(r->snap_value, r->last_value, sizeof r->snap_value);
    memcpy(r->snap_dirty, r->dirty, sizeof r->snap_dirty);
    memset(r->dirty, 0, sizeof r->dirty);
    r->any_dirty = 0;
    *seq = r->last_seq;
    return q;
}

static PyObject *Receiver_deliver(Receiver *r, PyObject *arg) {
    if (not_ready(r)) return NULL;
    double timeout = PyFloat_AsDouble(arg);
    if (timeout == -1.0 && PyErr_Occurred()) return NULL;
    if (!(timeout >= 0.0 && timeout <= 3600.0)) {
        PyErr_Format(PyExc_ValueError, "timeout must be 0..3600 s, got %R", arg);
        return NULL;
    }
    if (r->delivering) {
        PyErr_SetString(PyExc_RuntimeError, "deliver() is already running on another thread");
        return NULL;
    }
    r->delivering = 1;
    int more = 1, hand = 0;
    int64_t seq = 0;
    queue_t *q = NULL;
    PyThreadState *ts = PyEval_SaveThread();
    double end = vs_now_s() + timeout;
    for (;;) {
        PyThread_acquire_lock(r->qlock, WAIT_LOCK);
        const queue_t *f = &r->q[r->fill];
        int items = f->n > 0, state = r->any_dirty || f->n_seen > 0;
        int finished = r->finished, over = finished || r->stop;
        double now = vs_now_s(), wait = end - now;
        if (state && !items) { /* the fast path's state: at most every STATE_PERIOD_S (and at the end) */
            double due = r->last_flush + STATE_PERIOD_S - now;
            if (over || due <= 0.0) items = 1;
            else if (due < wait) wait = due;
        }
        if (items) {
            q = swap_queues(r, &seq);
            hand = 1;
        }
        PyThread_release_lock(r->qlock);
        if (hand) break;
        if (finished) { /* run() has returned (read under qlock: after its last datagram) and nothing is left */
            more = 0;
            break;
        }
        if (wait <= 0.0) break;
        if (PyThread_acquire_lock_timed(r->wake, (long long)(wait * 1e6) + 1, 0) == PY_LOCK_ACQUIRED) {
            PyThread_acquire_lock(r->qlock, WAIT_LOCK);
            r->wake_posted = 0;
            PyThread_release_lock(r->qlock);
        }
    }
    PyEval_RestoreThread(ts);
    if (hand) {
        r->last_flush = vs_now_s();
        int any_state = q->n_seen > 0;
        for (int k = 0; k < 2 * MAXCH && !any_state; k++) any_state = ((const uint8_t *)r->snap_dirty)[k];
        if (any_state) hand_state(r, q, seq);
        if (q->n) hand_slow(r, q);
        /* At once, GIL held (qlock is only ever held for a few hundred ns, never while waiting): the
         * fast path is held until now, and a client answered by on_slow may already be sending. */
        PyThread_acquire_lock(r->qlock, WAIT_LOCK);
        r->delivered += q->n;
        q->n = 0;
        q->used = 0;
        q->n_seen = 0;
        r->handing = 0;
        PyThread_release_lock(r->qlock);
    }
    r->delivering = 0;
    if (!more) Py_RETURN_FALSE;
    Py_RETURN_TRUE;
}

static PyObject *Receiver_stop(Receiver *r, PyObject *unused) {
    if (not_ready(r)) return NULL;
    r->stop = 1;
    post_wake(r); /* deliver() wakes up at once */
    Py_RETURN_NONE;
}

/* ------------------------------------------------------------------ construction */
/* *slot = a new reference to value, then the old one released (Py_XSETREF, not in the limited API). */
static void set_ref(PyObject **slot, PyObject *value) {
    PyObject *old = *slot;
    Py_INCREF(value);
    *slot = value;
    Py_XDECREF(old);
}

static int Receiver_init(Receiver *r, PyObject *args, PyObject *kw) {
    static char *names[] = {"fd",      "core",     "table", "balance_min", "balance_max",
                            "on_slow", "on_state", "allow", "watch",       NULL};
    long long fd;
    PyObject *core, *table, *on_slow, *on_state, *allow, *watch = Py_None;
    if (r->ready) { /* run() may be using it on the receive thread */
        PyErr_SetString(PyExc_RuntimeError, "Receiver is already initialised (make a new one)");
        return -1;
    }
    if (!PyArg_ParseTupleAndKeywords(args, kw, "LOOddOOO|O", names, &fd, &core, &table, &r->bal_min, &r->bal_max,
                                     &on_slow, &on_state, &allow, &watch))
        return -1;
#ifdef _WIN32
    if (fd < 0) {
#else
    if (fd < 0 || fd > INT32_MAX) {
#endif
        PyErr_Format(PyExc_ValueError, "fd must be a socket descriptor (>= 0), got %lld", fd);
        return -1;
    }
    if (!PyCallable_Check(on_slow) || !PyCallable_Check(on_state)) {
        PyErr_SetString(PyExc_TypeError, "on_slow and on_state must be callable");
        return -1;
    }
    if (r->watch_view.obj) PyBuffer_Release(&r->watch_view);
    r->watch = NULL;
    if (watch != Py_None) { /* watch: a buffer whose first byte says whether to log for monitors */
        if (PyObject_GetBuffer(watch, &r->watch_view, PyBUF_SIMPLE) < 0) return -1;
        if (r->watch_view.len < 1) {
            PyBuffer_Release(&r->watch_view);
            PyErr_SetString(PyExc_ValueError, "watch: an empty buffer");
            return -1;
        }
        r->watch = (const volatile uint8_t *)r->watch_view.buf;
    }
    r->fd = (sock_t)fd;
    r->api = NULL;
    r->core_ptr = NULL;
    r->channels = 0;
    if (core != Py_None) { /* None: no fast path, every datagram goes to Python */
        const vs_core_api_t *api = (const vs_core_api_t *)PyCapsule_Import(VS_CORE_CAPSULE, 0);
        if (!api) return -1;
        if (!api->core_type || !PyObject_TypeCheck(core, (PyTypeObject *)api->core_type)) {
            PyErr_Format(PyExc_TypeError, "core must be a vibsynth.engine._core.Core or None, not %R",
                         (PyObject *)Py_TYPE(core)); /* %R of the type, not tp_name: the limited API has no tp_name */
            return -1;
        }
        if (!api->ready((struct vs_core *)core)) {
            PyErr_SetString(PyExc_RuntimeError, "core: the Core is not initialised (its __init__ has not succeeded)");
            return -1;
        }
        r->api = api;
        r->core_ptr = (struct vs_core *)core;
        r->channels = api->channels(r->core_ptr);
    }
    set_ref(&r->core, core);
    set_ref(&r->on_slow, on_slow);
    set_ref(&r->on_state, on_state);
    /* table: iterable of (address: bytes, method: int, channel: int) */
    memset(r->table, 0, sizeof r->table);
    PyObject *it = PyObject_GetIter(table);
    if (!it) return -1;
    PyObject *item;
    int count = 0;
    while ((item = PyIter_Next(it))) {
        const char *addr;
        Py_ssize_t alen;
        int method, channel;
        if (!PyArg_ParseTuple(item, "y#ii", &addr, &alen, &method, &channel)) {
            Py_DECREF(item);
            Py_DECREF(it);
            return -1;
        }
        Py_DECREF(item);
        if (!r->api || alen < 1 || alen >= MAX_ADDR || channel < -1 || channel >= r->channels ||
            ++count > TABLE_SIZE / 4) {
            Py_DECREF(it);
            PyErr_SetString(PyExc_ValueError, "fast-path table: bad address, channel or too many entries");
            return -1;
        }
        uint32_t i = hash_bytes(addr, (int)alen) & (TABLE_SIZE - 1);
        while (r->table[i].len) i = (i + 1) & (TABLE_SIZE - 1);
        memcpy(r->table[i].address, addr, (size_t)alen);
        r->table[i].len = (int)alen;
        r->table[i].method = method;
        r->table[i].channel = channel;
    }
    Py_DECREF(it);
    if (PyErr_Occurred()) return -1;
    /* allow: None, or iterable of (version 4|6, packed network bytes, prefix length) */
    r->n_nets = -1;
    if (allow != Py_None) {
        r->n_nets = 0;
        it = PyObject_GetIter(allow);
        if (!it) return -1;
        while ((item = PyIter_Next(it))) {
            int version, prefix;
            const char *net;
            Py_ssize_t nlen;
            if (!PyArg_ParseTuple(item, "iy#i", &version, &net, &nlen, &prefix) || r->n_nets == MAX_NETS ||
                nlen != (version == 4 ? 4 : 16) || prefix < 0 || prefix > 8 * nlen) {
                Py_DECREF(item);
                Py_DECREF(it);
                if (!PyErr_Occurred()) PyErr_SetString(PyExc_ValueError, "allow: bad network or too many");
                return -1;
            }
            Py_DECREF(item);
            net_t *dst = &r->nets[r->n_nets++];
            dst->family = version;
            memset(dst->net, 0, sizeof dst->net);
            memcpy(dst->net, net, (size_t)nlen);
            dst->prefix = prefix;
        }
        Py_DECREF(it);
        if (PyErr_Occurred()) return -1;
    }
    if (!r->scratch) r->scratch = malloc(MAX_DATAGRAM);
    /* The queues' pages are touched here, once: left untouched, each one would become resident the
     * first time Python fell that far behind, so the RSS would creep up with every new record depth
     * and the receive thread would take the page faults. */
    for (int k = 0; k < 2; k++) {
        queue_t *q = &r->q[k];
        if (!q->items && (q->items = malloc(QUEUE_MAX * sizeof(qitem_t))) != NULL)
            vs_prefault(q->items, QUEUE_MAX * sizeof(qitem_t));
        if (!q->arena && (q->arena = malloc(QUEUE_ARENA)) != NULL) vs_prefault(q->arena, QUEUE_ARENA);
        if (!q->seen && (q->seen = malloc(MAX_SEEN * sizeof(seen_t))) != NULL)
            vs_prefault(q->seen, MAX_SEEN * sizeof(seen_t));
        if (!q->items || !q->arena || !q->seen) break;
    }
    if (!r->qlock) r->qlock = PyThread_allocate_lock();
    if (!r->wake) { /* a binary semaphore: taken (nothing to hand over) until run() posts it */
        r->wake = PyThread_allocate_lock();
        if (r->wake) PyThread_acquire_lock(r->wake, WAIT_LOCK);
    }
    if (!r->scratch || !r->qlock || !r->wake) {
        PyErr_NoMemory();
        return -1;
    }
    for (int k = 0; k < 2; k++) {
        if (!r->q[k].items || !r->q[k].arena || !r->q[k].seen) {
            PyErr_NoMemory();
            return -1;
        }
    }
    r->ready = 1;
    return 0;
}

static void Receiver_dealloc(Receiver *r) {
    PyTypeObject *type = Py_TYPE((PyObject *)r);
    Py_XDECREF(r->core);
    Py_XDECREF(r->on_slow);
    Py_XDECREF(r->on_state);
    if (r->watch_view.obj) PyBuffer_Release(&r->watch_view);
    free(r->scratch);
    for (int k = 0; k < 2; k++) {
        free(r->q[k].items);
        free(r->q[k].arena);
        free(r->q[k].seen);
    }
    if (r->qlock) PyThread_free_lock(r->qlock);
    if (r->wake) {
        if (!r->wake_posted) PyThread_release_lock(r->wake); /* freeing a held lock is not allowed everywhere */
        PyThread_free_lock(r->wake);
    }
    ((freefunc)PyType_GetSlot(type, Py_tp_free))(r);
    Py_DECREF(type); /* a heap type: each instance holds a reference to it */
}

static PyObject *Receiver_counters(Receiver *r, PyObject *unused) {
    if (not_ready(r)) return NULL;
    return Py_BuildValue("{sLsLsLsLsLsLsLsLsLsL}", "packets", r->packets, "bytes", r->bytes, "fast", r->fast, "slow",
                         r->slow, "delivered", r->delivered, "denied", r->denied, "ring_full", r->ring_full, "queue_full", r->queue_full,
                         "handler_errors", r->handler_errors, "recv_errors", r->recv_errors);
}

static PyMethodDef Receiver_methods[] = {
    {"run", (PyCFunction)Receiver_run, METH_NOARGS,
     "receive until stop() (returns None), or until the socket fails (raises OSError); call from the receive "
     "thread (it never takes the GIL meanwhile)"},
    {"deliver", (PyCFunction)Receiver_deliver, METH_O,
     "deliver(timeout_s): wait up to timeout_s (0..3600) for what run() queued for Python and hand it over "
     "(on_state, then on_slow); False once run() has returned and nothing is left, else True; call in a loop "
     "from a second thread"},
    {"stop", (PyCFunction)Receiver_stop, METH_NOARGS, "ask run() to return (within 100 ms)"},
    {"counters", (PyCFunction)Receiver_counters, METH_NOARGS,
     "packets, bytes, fast, slow (queued for Python), delivered (handed to Python, which has returned), denied, ring_full, queue_full (dropped: Python was "
     "QUEUE_MAX datagrams behind), handler_errors, recv_errors"},
    {NULL}};

/* A heap type (the limited API has no static PyTypeObject), immutable like a static one. */
static PyType_Slot Receiver_slots[] = {
    {Py_tp_doc, (void *)"OSC UDP receive loop with a compiled fast path for knob messages."},
    {Py_tp_new, (void *)PyType_GenericNew},
    {Py_tp_init, (void *)Receiver_init},
    {Py_tp_dealloc, (void *)Receiver_dealloc},
    {Py_tp_methods, Receiver_methods},
    {0, NULL}};
static PyType_Spec Receiver_spec = {"vibsynth.control.osc._fast.Receiver", sizeof(Receiver), 0,
                                    Py_TPFLAGS_DEFAULT | Py_TPFLAGS_IMMUTABLETYPE, Receiver_slots};

static struct PyModuleDef module = {PyModuleDef_HEAD_INIT, "_fast", "OSC UDP fast path", -1, NULL};

PyMODINIT_FUNC PyInit__fast(void) {
    PyObject *m = PyModule_Create(&module);
    if (!m) return NULL;
    PyObject *type = PyType_FromSpec(&Receiver_spec);
    if (!type || PyModule_AddObject(m, "Receiver", type) < 0) { /* (AddObject steals on success only) */
        Py_XDECREF(type);
        Py_DECREF(m);
        return NULL;
    }
    PyModule_AddIntConstant(m, "M_INTENSITY", M_INTENSITY);
    PyModule_AddIntConstant(m, "M_BALANCE", M_BALANCE);
    PyModule_AddIntConstant(m, "M_TEXTURE", M_TEXTURE);
    PyModule_AddIntConstant(m, "MAX_BATCH", MAX_BATCH);
    PyModule_AddIntConstant(m, "QUEUE_MAX", QUEUE_MAX);
    return m;
}
