/*
 * What the real-time C modules share: atomics, a monotonic clock, PortAudio's callback time
 * layout, and a lock-free block time stamp (a seqlock: one writer, the audio thread, which
 * never waits; readers retry while it writes).
 */
#ifndef VIBSYNTH_RT_H
#define VIBSYNTH_RT_H
#include <stdint.h>
#include <string.h>

#ifdef _WIN32
#include <windows.h>
#else
#include <time.h>
#endif

#if defined(__GNUC__) || defined(__clang__)
#define LOAD_ACQ(p) __atomic_load_n((p), __ATOMIC_ACQUIRE)
#define STORE_REL(p, v) __atomic_store_n((p), (v), __ATOMIC_RELEASE)
#define LOAD_RLX(p) __atomic_load_n((p), __ATOMIC_RELAXED)
#define STORE_RLX(p, v) __atomic_store_n((p), (v), __ATOMIC_RELAXED)
#define FETCH_ADD(p, v) __atomic_fetch_add((p), (v), __ATOMIC_ACQ_REL)
#define FENCE_REL() __atomic_thread_fence(__ATOMIC_RELEASE)
#define FENCE_ACQ() __atomic_thread_fence(__ATOMIC_ACQUIRE)
#else /* MSVC on x86/x64: aligned 64-bit accesses are atomic; barriers stop compiler reordering */
#include <intrin.h>
#define LOAD_ACQ(p) (_ReadWriteBarrier(), *(volatile int64_t *)(p))
#define STORE_REL(p, v) do { _ReadWriteBarrier(); *(volatile int64_t *)(p) = (v); } while (0)
#define LOAD_RLX(p) (*(volatile int64_t *)(p))
#define STORE_RLX(p, v) (*(volatile int64_t *)(p) = (v))
#define FETCH_ADD(p, v) _InterlockedExchangeAdd64((volatile __int64 *)(p), (v))
#define FENCE_REL() _ReadWriteBarrier()
#define FENCE_ACQ() _ReadWriteBarrier()
#endif

/* Monotonic seconds (CLOCK_MONOTONIC / QueryPerformanceCounter): one clock for every stream. */
static inline double vs_now_s(void) {
#ifdef _WIN32
    LARGE_INTEGER f, t;
    QueryPerformanceFrequency(&f);
    QueryPerformanceCounter(&t);
    return (double)t.QuadPart / (double)f.QuadPart;
#else
    struct timespec ts;
    clock_gettime(CLOCK_MONOTONIC, &ts);
    return (double)ts.tv_sec + 1e-9 * (double)ts.tv_nsec;
#endif
}

/* Make every page of a fresh allocation resident now, so that a buffer's pages do not arrive one
 * by one later, on a real-time thread, each time it is filled deeper than ever before (a volatile
 * store per page: a plain memset of zeros may be folded into calloc, whose pages stay untouched). */
static inline void vs_prefault(void *p, size_t n) {
    volatile unsigned char *b = (volatile unsigned char *)p;
    for (size_t i = 0; i < n; i += 4096) b[i] = 0;
    if (n) b[n - 1] = 0;
}

/* PortAudio's PaStreamCallbackTimeInfo (portaudio.h), laid out here to need no PortAudio header. */
typedef struct {
    double input_adc;   /* inputBufferAdcTime: when the block's first input frame was captured */
    double current;     /* currentTime: when the callback was called (the stream's clock) */
    double output_dac;  /* outputBufferDacTime: when the block's first output frame will be heard */
} vs_pa_time_t;

/* Where a stream's block began: its first frame, PortAudio's times of it, and the monotonic clock. */
typedef struct {
    int64_t seq;    /* odd while the writer is in the middle of an update */
    int64_t frame;  /* the block's first frame (the stream's frame counter) */
    int64_t bits[4]; /* doubles: adc, current, dac (PortAudio stream time, s), monotonic (s) */
} vs_stamp_t;

static inline int64_t vs_bits(double x) {
    int64_t b;
    memcpy(&b, &x, sizeof b);
    return b;
}

static inline double vs_double(int64_t b) {
    double x;
    memcpy(&x, &b, sizeof x);
    return x;
}

/* Audio thread: never waits. ti may be NULL (a test calling the callback). */
static inline void vs_stamp_write(vs_stamp_t *s, int64_t frame, const vs_pa_time_t *ti, double mono) {
    int64_t seq = LOAD_RLX(&s->seq) + 1;
    STORE_RLX(&s->seq, seq);
    FENCE_REL();
    STORE_RLX(&s->frame, frame);
    STORE_RLX(&s->bits[0], vs_bits(ti ? ti->input_adc : 0.0));
    STORE_RLX(&s->bits[1], vs_bits(ti ? ti->current : 0.0));
    STORE_RLX(&s->bits[2], vs_bits(ti ? ti->output_dac : 0.0));
    STORE_RLX(&s->bits[3], vs_bits(mono));
    STORE_REL(&s->seq, seq + 1);
}

/* Any thread: a consistent copy (frame, adc, current, dac, monotonic); 0 if the writer kept it busy. */
static inline int vs_stamp_read(const vs_stamp_t *s, int64_t *frame, double out[4]) {
    for (int attempt = 0; attempt < 1000; attempt++) {
        int64_t s1 = LOAD_ACQ(&s->seq);
        if (s1 & 1) continue;
        int64_t f = LOAD_RLX(&s->frame), b[4];
        for (int k = 0; k < 4; k++) b[k] = LOAD_RLX(&s->bits[k]);
        FENCE_ACQ();
        if (LOAD_RLX(&s->seq) != s1) continue;
        *frame = f;
        for (int k = 0; k < 4; k++) out[k] = vs_double(b[k]);
        return 1;
    }
    return 0;
}
#endif
