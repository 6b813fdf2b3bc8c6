/*
 * vibsynth real-time core: the per-block mix, the command hand-off, the scheduler and the
 * PortAudio callback, in C so that the audio thread never needs Python's GIL.
 *
 * Threads
 * -------
 * - Producers (Python control threads holding the GIL, and C threads that do not, such as
 *   the OSC fast path) call core_push(). They serialise among themselves on a producer lock
 *   that the audio thread never takes.
 * - The consumer (the PortAudio callback, or an offline render call with the GIL released)
 *   calls core_render(). It allocates nothing, takes no lock, never logs, and does bounded
 *   work per block: at most DRAIN_MAX commands leave the ring per block (the rest wait for
 *   the next block), each costs O(channels + log heap), and the block is split at most once
 *   per distinct due frame popped from the heap.
 *
 * Hand-off: a single-producer single-consumer ring of fixed-size commands (head and tail
 * are published with release stores and read with acquire loads).
 *
 * Scheduler: commands with a future frame go into a binary heap keyed (frame, seq),
 * preallocated to the schedule cap. Producers refuse a scheduled command when
 * (scheduled submitted - scheduled done) reaches the cap, so the heap can never overflow
 * and the refusal happens on the control side, where it can be answered.
 *
 * Layers: a channel's knobs are driven by one control layer at a time (0 direct knobs, 1 follow,
 * 2 spatial sources, 3 clips). CMD_LAYER, in stream order, says which; a knob command moves
 * only the channels its layer drives, so a knob message on a channel a clip plays, or a
 * clip move queued before the clip was stopped, never reaches the ramps. CMD_CANCEL drops a
 * layer's commands submitted before it (by sequence number), O(channels) per command.
 *
 * Voices: each channel can also play one float32 recording once (CMD_VOICE), added to the
 * texture with a ramped gain and 5 ms edge fades, before the limiter's final clip. The
 * producer keeps the samples alive until the channel's voice id no longer names them.
 *
 * Trims: each channel can carry a calibration trim (CMD_TRIM): a balance offset added to its
 * balance knob and a gain curve over the bank's levels, read at the channel's effective bank
 * position, both applied after every layer resolved the knobs (so direct knobs, follow, sources
 * and clips all get them) and before the limiter. A new trim glides in (a linear blend from the
 * previous curve, the offset ramped), so changing one never clicks; one that arrives while another
 * still glides in waits for it (the newest waiting one wins) and starts at the end of that block.
 * The producer keeps each curve alive for the engine's lifetime.
 *
 * Output tap: every rendered frame is also copied into a ring of TAP_FRAMES frames, which
 * control threads read (Core.read_tap) for meters and spectra; the audio thread never waits.
 *
 * Arithmetic: every operation, and its order, is that of the numpy engine this replaced
 * (double controls, float32 crossfade), so block-by-block output equals one-shot output
 * exactly and the knob semantics are unchanged. Build with -ffp-contract=off.
 *
 * Hostile callers: a Core is initialised once (a second __init__ raises RuntimeError, a failed
 * one changes nothing), every method checks that it was (RuntimeError "Core is not
 * initialised"), and every argument is validated where it enters (TypeError/ValueError naming
 * it): push() refuses non-finite values and out-of-range glides, __init__ non-finite or
 * out-of-range settings. The audio thread converts seconds to samples only through
 * samples_of(), which checks before casting, so a C producer cannot cause undefined behaviour
 * either. The one trusted input is push()'s `ptr`/`length`: the engine's own arrays.
 */
#define PY_SSIZE_T_CLEAN
#include <Python.h>
#include <pythread.h>
#include <math.h>
#include <stdlib.h> /* malloc/calloc/free: Python.h leaves it out of limited-API builds */
#include <stdint.h>
#include <string.h>

#include "_core_api.h"
#include "_rt.h" /* atomics, the monotonic clock, PortAudio's time layout, block stamps */

#define MAXCH 64
#define DRAIN_MAX 1024
#define KNOB_FADE_IN 0.01
#define PA_OUTPUT_UNDERFLOW 0x00000004UL
#define TAP_FRAMES 65536 /* a power of two */
#define VOICE_FADE_S 0.005
#define TRIM_GLIDE_S 0.05
#define MAX_GLIDE_S 3600.0 /* longest glide or mute fade push()/__init__ accept (limits.GLIDE_MAX_MS is 10 s) */
#define MAX_FS 1e7         /* highest sample rate __init__ accepts */
#define MAX_RAMP_SAMPLES ((int64_t)1 << 40) /* samples_of() clamps to this (> MAX_GLIDE_S x MAX_FS) */
#define MAX_RING (1 << 24)
#define MAX_SCHEDULE (1 << 24)

enum { R_INTENSITY = 0, R_BALANCE = 1, R_MUTE = 2, R_VOICE = 3, R_TRIM_BAL = 4, R_TRIM_MIX = 5, N_RAMPS = 6 };
typedef vs_cmd_t cmd_t;

typedef struct {
    double start[MAXCH], delta[MAXCH], pos[MAXCH], len[MAXCH];
    int64_t end_frame;
} ramps_t;

typedef struct vs_core {
    PyObject_HEAD
    /* bank */
    Py_buffer sig;
    Py_buffer peaks_buf;
    const float *flat;
    const double *peaks;
    double dpeaks[4096];
    int64_t n;
    int levels;
    /* mappings */
    int channels;
    double fs, gain_a, gain_b, pos_scale, pos_offset, pos_max, limiter, mute_fade_s, bal_lo, bal_hi;
    double idx_max;
    float ceil32, floor32;
    int64_t max_block;
    /* real-time state (audio thread) */
    ramps_t ramps[N_RAMPS];
    double glide_s[MAXCH];
    int32_t top[MAXCH];                  /* layer driving each channel's knobs */
    int64_t cancel_seq[MAXCH][VS_LAYERS]; /* a layer's commands below this seq are dropped */
    /* voices */
    const float *vbuf[MAXCH];
    int64_t vlen[MAXCH], vpos[MAXCH];
    int64_t vid[MAXCH]; /* published: seq of the CMD_VOICE playing, 0 = none */
    int32_t vstop[MAXCH];
    double vfade;
    /* trims: gain curves over the bank levels (NULL = 1), blended prev -> cur by R_TRIM_MIX */
    const float *tcur[MAXCH], *tprev[MAXCH];
    /* a trim that came while the previous one still glided in: started when that glide ends */
    const float *tpend[MAXCH];
    double tpend_off[MAXCH];
    int64_t tpend_len[MAXCH];
    int tpend_on[MAXCH];
    /* output tap */
    float *tap;
    int64_t tap_frame; /* published: frames written to the tap */
    int32_t muted[MAXCH];
    int64_t read_idx[MAXCH];
    int64_t frame;
    /* ring */
    cmd_t *ring;
    int64_t ring_cap;
    int64_t head;   /* consumer-owned, published */
    int64_t tail;   /* producer-owned, published */
    /* scheduler */
    cmd_t *heap;
    int64_t heap_len, sched_cap;
    int64_t sched_submitted;  /* producer side */
    int64_t sched_done;       /* consumer side: fired, applied late, or dropped by panic */
    /* counters */
    int64_t next_seq, applied_seq, blocks, underflows, late, ring_full, schedule_full, callbacks;
    double load_last, load_peak, load_avg;
    vs_stamp_t out_stamp; /* the last PortAudio block: first frame, its DAC time (input path alignment) */
    int has_out_stamp;
    /* device output mapping (PortAudio callback) */
    int dev_channels;
    int identity;
    int colmap[MAXCH];
    PyThread_type_lock plock;
    int ready; /* __init__ succeeded: set once, last, and never cleared */
} Core;

/* ------------------------------------------------------------------ time */
#define now_s vs_now_s

/* ------------------------------------------------------------------ ramps */
static inline double ramp_value(const ramps_t *r, int c) {
    double length = r->len[c];
    return r->start[c] + r->delta[c] * (fmin(r->pos[c], length) / length);
}

/* Value after `step` more samples (the numpy engine's fill: ((pos+step) min len)/len*delta+start). */
static inline double ramp_at(const ramps_t *r, int c, double step) {
    double x = r->pos[c] + step;
    x = fmin(x, r->len[c]);
    x = x / r->len[c];
    x = x * r->delta[c];
    return x + r->start[c];
}

/* A ramp length in samples: x (seconds x rate) rounded; NaN or <= 0 -> 0, huge -> MAX_RAMP_SAMPLES.
 * Checked before the cast (converting NaN, inf or an out-of-range double to int64_t is undefined). */
static inline int64_t samples_of(double x) {
    if (!(x > 0.0)) return 0;
    if (x >= (double)MAX_RAMP_SAMPLES) return MAX_RAMP_SAMPLES;
    return (int64_t)nearbyint(x);
}

static void ramp_move(ramps_t *r, int c, double target, int64_t samples, int64_t frame) {
    double current = ramp_value(r, c);
    r->start[c] = current;
    r->delta[c] = target - current;
    if (samples <= 0) {
        r->pos[c] = 1.0;
        r->len[c] = 1.0;
    } else {
        r->pos[c] = 0.0;
        r->len[c] = (double)samples;
        if (frame + samples > r->end_frame) r->end_frame = frame + samples;
    }
}

/* ------------------------------------------------------------------ heap keyed (at, seq) */
static inline int cmd_less(const cmd_t *a, const cmd_t *b) {
    return a->at < b->at || (a->at == b->at && a->seq < b->seq);
}

static void heap_push(Core *c, const cmd_t *cmd) {
    int64_t i = c->heap_len++;
    cmd_t *h = c->heap;
    while (i > 0) {
        int64_t p = (i - 1) / 2;
        if (!cmd_less(cmd, &h[p])) break;
        h[i] = h[p];
        i = p;
    }
    h[i] = *cmd;
}

static void heap_pop(Core *c, cmd_t *out) {
    cmd_t *h = c->heap;
    *out = h[0];
    int64_t n = --c->heap_len;
    if (n == 0) return;
    cmd_t last = h[n];
    int64_t i = 0;
    for (;;) {
        int64_t l = 2 * i + 1, r = l + 1, m = i;
        const cmd_t *best = &last;
        if (l < n && cmd_less(&h[l], best)) { m = l; best = &h[l]; }
        if (r < n && cmd_less(&h[r], best)) { m = r; }
        if (m == i) break;
        h[i] = h[m];
        i = m;
    }
    h[i] = last;
}

/* ------------------------------------------------------------------ commands (audio thread) */
/* Start gliding channel ch from its current trim curve to `curve` (NULL = no trim) and its balance offset to `offset`. */
static void trim_start(Core *c, int ch, const float *curve, double offset, int64_t samples, int64_t frame) {
    c->tprev[ch] = c->tcur[ch];
    c->tcur[ch] = curve;
    ramps_t *mix = &c->ramps[R_TRIM_MIX];
    mix->start[ch] = 0.0;
    mix->delta[ch] = 0.0;
    mix->pos[ch] = 1.0;
    mix->len[ch] = 1.0;
    ramp_move(mix, ch, 1.0, samples, frame);
    ramp_move(&c->ramps[R_TRIM_BAL], ch, offset, samples, frame);
}

static void apply(Core *c, const cmd_t *cmd, int64_t frame) {
    double fs = c->fs;
    switch (cmd->kind) {
    case CMD_KNOB: {
        ramps_t *r = &c->ramps[cmd->arg == 0 ? R_INTENSITY : R_BALANCE];
        double value = cmd->value;
        int layer = cmd->layer;
        if (layer < 0 || layer >= VS_LAYERS || !isfinite(value)) break;
        if (cmd->arg == 1) value = fmin(fmax(value, c->bal_lo), c->bal_hi);
        for (int ch = 0; ch < c->channels; ch++) {
            if (!(cmd->mask >> ch & 1)) continue;
            if (c->top[ch] != layer || cmd->seq < c->cancel_seq[ch][layer]) continue;
            double glide = isnan(cmd->glide) ? c->glide_s[ch] : cmd->glide;
            ramp_move(r, ch, value, samples_of(glide * fs), frame);
        }
        break;
    }
    case CMD_GLIDE:
        if (!(cmd->value >= 0.0 && cmd->value <= MAX_GLIDE_S)) break; /* NaN too */
        for (int ch = 0; ch < c->channels; ch++)
            if (cmd->mask >> ch & 1) c->glide_s[ch] = cmd->value;
        break;
    case CMD_MUTE: {
        ramps_t *r = &c->ramps[R_MUTE];
        double target = cmd->arg ? 0.0 : 1.0;
        for (int ch = 0; ch < c->channels; ch++) {
            if (!(cmd->mask >> ch & 1)) continue;
            c->muted[ch] = cmd->arg ? 1 : 0;
            double distance = fabs(target - ramp_value(r, ch));
            ramp_move(r, ch, target, samples_of(c->mute_fade_s * fs * distance), frame);
        }
        break;
    }
    case CMD_PANIC:
        STORE_REL(&c->sched_done, c->sched_done + c->heap_len);
        c->heap_len = 0;
        for (int ch = 0; ch < c->channels; ch++) {
            ramp_move(&c->ramps[R_INTENSITY], ch, 0.0, samples_of(c->mute_fade_s * fs), frame);
            c->top[ch] = 0;
            if (c->vbuf[ch]) {
                c->vstop[ch] = 1;
                ramp_move(&c->ramps[R_VOICE], ch, 0.0, samples_of(c->mute_fade_s * fs), frame);
            }
        }
        break;
    case CMD_LAYER:
        if (cmd->arg < 0 || cmd->arg >= VS_LAYERS) break;
        for (int ch = 0; ch < c->channels; ch++)
            if ((cmd->mask >> ch & 1) && cmd->seq >= c->cancel_seq[ch][cmd->arg]) c->top[ch] = cmd->arg;
        break;
    case CMD_CANCEL:
        if (cmd->arg < 0 || cmd->arg >= VS_LAYERS) break;
        for (int ch = 0; ch < c->channels; ch++)
            if (cmd->mask >> ch & 1) c->cancel_seq[ch][cmd->arg] = cmd->seq;
        break;
    case CMD_VOICE: {
        double glide = isnan(cmd->glide) ? 0.0 : cmd->glide;
        if (!isfinite(cmd->value)) break;
        for (int ch = 0; ch < c->channels; ch++) {
            if (!(cmd->mask >> ch & 1)) continue;
            if (cmd->ptr) {
                c->vbuf[ch] = cmd->ptr;
                c->vlen[ch] = cmd->ival;
                c->vpos[ch] = 0;
                c->vstop[ch] = 0;
                STORE_REL(&c->vid[ch], cmd->seq);
                ramp_move(&c->ramps[R_VOICE], ch, cmd->value, 0, frame);
            } else if (c->vbuf[ch] && !c->vstop[ch]) {
                ramp_move(&c->ramps[R_VOICE], ch, cmd->value, samples_of(glide * fs), frame);
            }
        }
        break;
    }
    case CMD_TRIM: {
        if ((cmd->ptr && cmd->ival != c->levels) || !isfinite(cmd->value)) break;
        double glide = isnan(cmd->glide) ? TRIM_GLIDE_S : cmd->glide;
        int64_t samples = samples_of(glide * fs);
        for (int ch = 0; ch < c->channels; ch++) {
            if (!(cmd->mask >> ch & 1)) continue;
            const ramps_t *mix = &c->ramps[R_TRIM_MIX];
            if (mix->pos[ch] < mix->len[ch]) {
                /* two curves blend at a time: a third waits (the newest wins) so the gain never steps */
                c->tpend[ch] = cmd->ptr;
                c->tpend_off[ch] = cmd->value;
                c->tpend_len[ch] = samples;
                c->tpend_on[ch] = 1;
                continue;
            }
            trim_start(c, ch, cmd->ptr, cmd->value, samples, frame);
        }
        break;
    }
    case CMD_VOICE_STOP:
        for (int ch = 0; ch < c->channels; ch++) {
            if (!(cmd->mask >> ch & 1) || !c->vbuf[ch]) continue;
            c->vstop[ch] = 1;
            ramp_move(&c->ramps[R_VOICE], ch, 0.0, samples_of(c->vfade), frame);
        }
        break;
    default:
        break;
    }
}

static void drain(Core *c, int64_t block_start) {
    int64_t head = c->head;
    int64_t tail = LOAD_ACQ(&c->tail);
    int64_t mask = c->ring_cap - 1;
    int taken = 0;
    int64_t done = 0;
    /* The heap's commands due at this very frame were submitted before anything still in the
     * ring (the ring is FIFO): apply them first. Otherwise a move due now that was drained late
     * overtakes the layer switch queued before it for the same frame, and is dropped as a move
     * of a layer that does not drive the channel yet (a clip started one block ahead, whose
     * first moves reached the ring a block after its switch, was silent). */
    while (c->heap_len && c->heap[0].at <= block_start) {
        cmd_t cmd;
        heap_pop(c, &cmd);
        apply(c, &cmd, block_start);
        done++;
    }
    while (head != tail && taken < DRAIN_MAX) {
        const cmd_t *cmd = &c->ring[head & mask];
        int64_t at = cmd->at;
        if (at < 0 || at <= block_start) {
            if (at >= 0) {
                if (at < block_start) c->late++;
                done++;
            }
            apply(c, cmd, block_start);
        } else if (c->heap_len < c->sched_cap) {
            heap_push(c, cmd);
        } else {
            done++;  /* unreachable while producers honour the cap */
        }
        if (cmd->seq > c->applied_seq) STORE_REL(&c->applied_seq, cmd->seq);
        head++;
        taken++;
    }
    if (done) STORE_REL(&c->sched_done, c->sched_done + done);
    STORE_REL(&c->head, head);
}

/* ------------------------------------------------------------------ rendering */
static inline double trim_curve(const float *curve, int64_t i, double f) {
    if (!curve) return 1.0;
    double lo = (double)curve[i];
    return lo + ((double)curve[i + 1] - lo) * f;
}

static inline void controls(const Core *c, int ch, double step, float *G, float *F, int64_t *I) {
    double k = ramp_at(&c->ramps[R_INTENSITY], ch, step);
    double b = ramp_at(&c->ramps[R_BALANCE], ch, step);
    b = b + ramp_at(&c->ramps[R_TRIM_BAL], ch, step);
    double m = ramp_at(&c->ramps[R_MUTE], ch, step);
    double g = k * c->gain_a;
    g = g + c->gain_b;
    g = exp(g);
    double t = k * (1.0 / KNOB_FADE_IN);
    t = fmin(t, 1.0);
    g = g * t;
    t = b * c->pos_scale;
    t = t + c->pos_offset;
    t = fmin(fmax(t, 0.0), c->pos_max);
    double f = floor(t);
    f = fmin(f, c->idx_max);
    int64_t i = (int64_t)f;
    f = t - f;
    if (c->tcur[ch] || c->tprev[ch]) {
        double trim = trim_curve(c->tcur[ch], i, f);
        double mix = ramp_at(&c->ramps[R_TRIM_MIX], ch, step);
        if (mix < 1.0) {
            double before = trim_curve(c->tprev[ch], i, f);
            trim = before + (trim - before) * mix;
        }
        g = g * trim;
    }
    double lim = c->dpeaks[i] * f;
    lim = lim + c->peaks[i];
    lim = c->limiter / lim;
    g = fmin(g, lim);
    g = g * m;
    *G = (float)g;
    *F = (float)f;
    *I = i;
}

/* Frames s0..s1 of `out` (row stride `stride` floats; engine channel ch -> column colmap[ch]). */
static void segment(Core *c, float *out, int64_t stride, const int *colmap, int64_t s0, int64_t s1, int64_t frame) {
    int64_t m = s1 - s0;
    int64_t end = c->ramps[0].end_frame;
    for (int k = 1; k < N_RAMPS; k++)
        if (c->ramps[k].end_frame > end) end = c->ramps[k].end_frame;
    int ramping = frame < end;
    const float *flat = c->flat;
    int64_t n = c->n;
    float hi_clip = c->ceil32, lo_clip = c->floor32;
    for (int ch = 0; ch < c->channels; ch++) {
        float G, F;
        int64_t I;
        controls(c, ch, 1.0, &G, &F, &I);
        int64_t r = c->read_idx[ch];
        float *dst = out + s0 * stride + colmap[ch];
        const float *vb = c->vbuf[ch];
        int64_t vp = c->vpos[ch], vl = c->vlen[ch];
        for (int64_t j = 0; j < m; j++) {
            if (ramping && j) controls(c, ch, (double)(j + 1), &G, &F, &I);
            const float *row = flat + I * n;
            float lo = row[r], hi = row[r + n];
            hi = hi - lo;
            hi = hi * F;
            hi = lo + hi;
            hi = hi * G;
            if (vb && vp < vl) {
                double edge = fmin(fmin((double)(vp + 1), (double)(vl - vp)) / c->vfade, 1.0);
                hi += (float)((double)vb[vp] * ramp_at(&c->ramps[R_VOICE], ch, (double)(j + 1)) * edge);
                vp++;
            }
            hi = hi < hi_clip ? hi : hi_clip;
            hi = hi > lo_clip ? hi : lo_clip;
            dst[j * stride] = hi;
            if (++r == n) r = 0;
        }
        c->read_idx[ch] = r;
        c->vpos[ch] = vp;
    }
    if (ramping) {
        for (int k = 0; k < N_RAMPS; k++) {
            ramps_t *rp = &c->ramps[k];
            for (int ch = 0; ch < c->channels; ch++) rp->pos[ch] = fmin(rp->pos[ch] + (double)m, rp->len[ch]);
        }
    }
    for (int ch = 0; ch < c->channels; ch++) {
        const ramps_t *tm = &c->ramps[R_TRIM_MIX];
        if (tm->pos[ch] >= tm->len[ch]) {
            c->tprev[ch] = NULL;
            if (c->tpend_on[ch]) {
                c->tpend_on[ch] = 0;
                trim_start(c, ch, c->tpend[ch], c->tpend_off[ch], c->tpend_len[ch], frame + m);
            }
        }
        if (!c->vbuf[ch]) continue;
        const ramps_t *vr = &c->ramps[R_VOICE];
        if (c->vpos[ch] >= c->vlen[ch] || (c->vstop[ch] && vr->pos[ch] >= vr->len[ch])) {
            c->vbuf[ch] = NULL;
            STORE_REL(&c->vid[ch], 0);
        }
    }
}

static void render_block(Core *c, float *out, int64_t stride, const int *colmap, int64_t frames) {
    int64_t start = c->frame;
    drain(c, start);
    int64_t end = start + frames, s = 0, fired = 0;
    while (c->heap_len && c->heap[0].at < end) {
        int64_t at = c->heap[0].at;
        int64_t split = at - start;
        if (split > s) {
            segment(c, out, stride, colmap, s, split, start + s);
            s = split;
        }
        while (c->heap_len && c->heap[0].at == at) {
            cmd_t cmd;
            heap_pop(c, &cmd);
            apply(c, &cmd, at);
            fired++;
        }
    }
    if (fired) STORE_REL(&c->sched_done, c->sched_done + fired);
    if (s < frames) segment(c, out, stride, colmap, s, frames, start + s);
    int nch = c->channels;
    for (int64_t j = 0; j < frames; j++) {
        float *row = c->tap + ((start + j) & (TAP_FRAMES - 1)) * nch;
        const float *src = out + j * stride;
        for (int ch = 0; ch < nch; ch++) row[ch] = src[colmap[ch]];
    }
    STORE_REL(&c->tap_frame, end);
    STORE_REL(&c->frame, end);
}

static void core_render(Core *c, float *out, int64_t frames, int64_t stride, const int *colmap) {
    double t0 = now_s();
    int64_t done = 0;
    while (done < frames) {
        int64_t step = frames - done < c->max_block ? frames - done : c->max_block;
        render_block(c, out + done * stride, stride, colmap, step);
        done += step;
    }
    STORE_REL(&c->blocks, c->blocks + 1);
    if (frames) {
        double load = (now_s() - t0) * c->fs / (double)frames;
        c->load_last = load;
        if (load > c->load_peak) c->load_peak = load;
        c->load_avg += 0.01 * (load - c->load_avg);
    }
}

/* Stamp the block about to render (its first frame, PortAudio's times, the monotonic clock), so
 * the input path can put its frames on the output's clock (Core.output_stamp). */
static void stamp_output_block(Core *c, const void *time_info) {
    vs_stamp_write(&c->out_stamp, c->frame, (const vs_pa_time_t *)time_info, now_s());
    c->has_out_stamp = 1;
}

/* The PortAudio stream callback (PaStreamCallback), interleaved float32 output. */
static int pa_callback(const void *input, void *output, unsigned long frames, const void *time_info,
                       unsigned long status, void *user) {
    Core *c = (Core *)user;
    (void)input;
    stamp_output_block(c, time_info);
    if (status & PA_OUTPUT_UNDERFLOW) STORE_REL(&c->underflows, c->underflows + 1);
    float *out = (float *)output;
    if (!c->identity) memset(out, 0, sizeof(float) * (size_t)frames * (size_t)c->dev_channels);
    core_render(c, out, (int64_t)frames, c->dev_channels, c->colmap);
    STORE_REL(&c->callbacks, c->callbacks + 1);
    return 0; /* paContinue */
}

/* ------------------------------------------------------------------ producer side */
/* Any thread; the GIL is not needed. Returns PUSH_*; *seq_out gets the sequence number. */
static int core_push(Core *c, cmd_t *cmd, int64_t *seq_out) {
    int rc = PUSH_OK;
    if (!c->ready) return PUSH_NOT_READY;
    PyThread_acquire_lock(c->plock, WAIT_LOCK);
    int64_t tail = c->tail;
    if (tail - LOAD_ACQ(&c->head) >= c->ring_cap) {
        c->ring_full++;
        rc = PUSH_RING_FULL;
    } else if (cmd->at >= 0 && c->sched_submitted - LOAD_ACQ(&c->sched_done) >= c->sched_cap) {
        c->schedule_full++;
        rc = PUSH_SCHEDULE_FULL;
    } else {
        if (cmd->at >= 0) c->sched_submitted++;
        cmd->seq = ++c->next_seq;
        c->ring[tail & (c->ring_cap - 1)] = *cmd;
        STORE_REL(&c->tail, tail + 1);
        if (seq_out) *seq_out = cmd->seq;
    }
    PyThread_release_lock(c->plock);
    return rc;
}

/* ------------------------------------------------------------------ Python type */
/* 1 (with a RuntimeError) when __init__ has not succeeded: every method and getter checks it,
 * since such an object (Core.__new__(Core)) has no ring, heap, tap, lock or bank. */
static int not_ready(const Core *self) {
    if (self->ready) return 0;
    PyErr_SetString(PyExc_RuntimeError, "Core is not initialised (its __init__ has not succeeded)");
    return 1;
}

static void Core_dealloc(Core *self) {
    PyTypeObject *type = Py_TYPE((PyObject *)self);
    if (self->sig.obj) PyBuffer_Release(&self->sig);
    if (self->peaks_buf.obj) PyBuffer_Release(&self->peaks_buf);
    free(self->ring);
    free(self->heap);
    free(self->tap);
    if (self->plock) PyThread_free_lock(self->plock);
    ((freefunc)PyType_GetSlot(type, Py_tp_free))(self);
    Py_DECREF(type); /* a heap type: each instance holds a reference to it */
}

/* 0, or -1 with a ValueError naming `name` unless lo <= x <= hi (NaN fails). */
static int check_range(const char *name, double x, double lo, double hi) {
    if (x >= lo && x <= hi) return 0;
    char msg[200];
    PyOS_snprintf(msg, sizeof msg, "%.60s must be in %g..%g, got %g", name, lo, hi, x);
    PyErr_SetString(PyExc_ValueError, msg);
    return -1;
}

/* 0, or -1 with a ValueError naming `name` unless x is finite. */
static int check_finite(const char *name, double x) {
    if (isfinite(x)) return 0;
    char msg[120];
    PyOS_snprintf(msg, sizeof msg, "%.60s must be finite, got %g", name, x);
    PyErr_SetString(PyExc_ValueError, msg);
    return -1;
}

/* Once: everything is parsed and validated into locals first and only then stored, so a failed
 * call leaves the object as it was (uninitialised) and a second one is refused (the audio thread,
 * an OSC receive loop or a PortAudio stream may use the object meanwhile). */
static int Core_init(Core *self, PyObject *args, PyObject *kw) {
    static char *names[] = {"signals", "peaks", "balances_lo", "balances_hi", "offsets", "fs", "ceiling_db",
                            "range_db", "glide_s", "mute_fade_s", "limiter_ceiling", "initial_intensity",
                            "initial_balance", "max_block", "ring_capacity", "schedule_capacity", NULL};
    PyObject *sig_obj, *peaks_obj, *offsets;
    double lo, hi, fs, ceiling_db, range_db, glide_s, mute_fade_s, limiter, init_k, init_b;
    Py_ssize_t max_block, ring_cap, sched_cap;
    if (self->ready) {
        PyErr_SetString(PyExc_RuntimeError, "Core is already initialised (make a new one)");
        return -1;
    }
    if (!PyArg_ParseTupleAndKeywords(args, kw, "OOddOddddddddnnn", names, &sig_obj, &peaks_obj, &lo, &hi, &offsets,
                                     &fs, &ceiling_db, &range_db, &glide_s, &mute_fade_s, &limiter, &init_k, &init_b,
                                     &max_block, &ring_cap, &sched_cap))
        return -1;
    Py_buffer sig, pk;
    memset(&sig, 0, sizeof sig);
    memset(&pk, 0, sizeof pk);
    cmd_t *ring = NULL, *heap = NULL;
    float *tap = NULL;
    PyThread_type_lock lock = NULL;
    int64_t read_idx[MAXCH];
    int levels = 0;
    int64_t n = 0;
    Py_ssize_t nch = 0;
    if (PyObject_GetBuffer(sig_obj, &sig, PyBUF_C_CONTIGUOUS | PyBUF_FORMAT | PyBUF_ND) < 0) goto fail;
    if (sig.ndim != 2 || strcmp(sig.format, "f") != 0) {
        PyErr_SetString(PyExc_ValueError, "signals must be a C-contiguous float32 array (levels, n)");
        goto fail;
    }
    if (sig.shape[0] < 2 || sig.shape[0] > 4096) {
        PyErr_SetString(PyExc_ValueError, "signals: levels must be in 2..4096");
        goto fail;
    }
    levels = (int)sig.shape[0];
    n = sig.shape[1];
    if (PyObject_GetBuffer(peaks_obj, &pk, PyBUF_C_CONTIGUOUS | PyBUF_FORMAT) < 0) goto fail;
    if (strcmp(pk.format, "d") != 0 || pk.len != (Py_ssize_t)(sizeof(double) * (size_t)levels)) {
        PyErr_SetString(PyExc_ValueError, "peaks must be float64 of shape (levels,)");
        goto fail;
    }
    if (check_finite("balances_lo", lo) < 0 || check_finite("balances_hi", hi) < 0) goto fail;
    if (!(lo < hi)) {
        PyErr_SetString(PyExc_ValueError, "balances_lo must be < balances_hi");
        goto fail;
    }
    nch = PySequence_Length(offsets);
    if (nch < 0) goto fail;
    if (nch < 1 || nch > MAXCH) {
        PyErr_Format(PyExc_ValueError, "offsets: channels must be in 1..%d", MAXCH);
        goto fail;
    }
    if (check_range("fs", fs, 0.0, MAX_FS) < 0) goto fail;
    if (fs == 0.0) {
        PyErr_SetString(PyExc_ValueError, "fs must be > 0");
        goto fail;
    }
    if (check_finite("ceiling_db", ceiling_db) < 0 || check_finite("range_db", range_db) < 0 ||
        check_range("glide_s", glide_s, 0.0, MAX_GLIDE_S) < 0 ||
        check_range("mute_fade_s", mute_fade_s, 0.0, MAX_GLIDE_S) < 0 ||
        check_finite("limiter_ceiling", limiter) < 0 || check_range("limiter_ceiling", limiter, 0.0, HUGE_VAL) < 0 ||
        check_finite("initial_intensity", init_k) < 0 || check_finite("initial_balance", init_b) < 0)
        goto fail;
    if (max_block < 1 || max_block >= n) {
        PyErr_SetString(PyExc_ValueError, "max_block must be in 1..n-1 (n = samples of a level)");
        goto fail;
    }
    if (ring_cap < 2 || ring_cap > MAX_RING || (ring_cap & (ring_cap - 1))) {
        PyErr_Format(PyExc_ValueError, "ring_capacity must be a power of two in 2..%d", MAX_RING);
        goto fail;
    }
    if (sched_cap < 1 || sched_cap > MAX_SCHEDULE) {
        PyErr_Format(PyExc_ValueError, "schedule_capacity must be in 1..%d", MAX_SCHEDULE);
        goto fail;
    }
    for (Py_ssize_t ch = 0; ch < nch; ch++) {
        PyObject *o = PySequence_GetItem(offsets, ch);
        if (!o) goto fail;
        long long off = PyLong_AsLongLong(o);
        Py_DECREF(o);
        if (off == -1 && PyErr_Occurred()) goto fail;
        read_idx[ch] = ((off % n) + n) % n;
    }
    ring = calloc((size_t)ring_cap, sizeof(cmd_t));
    heap = calloc((size_t)sched_cap, sizeof(cmd_t));
    tap = calloc((size_t)TAP_FRAMES * (size_t)nch, sizeof(float));
    lock = PyThread_allocate_lock();
    if (!ring || !heap || !tap || !lock) {
        PyErr_NoMemory();
        goto fail;
    }
    /* Resident from the start: calloc's pages are mapped on first touch, so the schedule's pages
     * would otherwise arrive one new record depth at a time (RSS creeping up, faults in the callback). */
    vs_prefault(ring, (size_t)ring_cap * sizeof(cmd_t));
    vs_prefault(heap, (size_t)sched_cap * sizeof(cmd_t));
    vs_prefault(tap, (size_t)TAP_FRAMES * (size_t)nch * sizeof(float));
    /* Nothing below fails: store it all. */
    self->sig = sig;
    self->peaks_buf = pk;
    self->levels = levels;
    self->n = n;
    self->flat = (const float *)sig.buf;
    self->peaks = (const double *)pk.buf;
    for (int i = 0; i < levels - 1; i++) self->dpeaks[i] = self->peaks[i + 1] - self->peaks[i];
    self->dpeaks[levels - 1] = 0.0;
    self->channels = (int)nch;
    self->fs = fs;
    double ln10_20 = log(10.0) / 20.0;
    self->gain_a = range_db * ln10_20;
    self->gain_b = (ceiling_db - range_db) * ln10_20;
    self->pos_scale = (double)(levels - 1) / (hi - lo);
    self->pos_offset = -lo * self->pos_scale;
    self->pos_max = (double)(levels - 1);
    self->idx_max = (double)(levels - 2);
    self->bal_lo = lo;
    self->bal_hi = hi;
    self->limiter = limiter;
    self->ceil32 = (float)limiter;
    self->floor32 = -(float)limiter;
    self->mute_fade_s = mute_fade_s;
    self->max_block = max_block;
    double b0 = fmin(fmax(init_b, lo), hi);
    for (int ch = 0; ch < self->channels; ch++) {
        double init[N_RAMPS] = {init_k, b0, 1.0, 0.0, 0.0, 1.0};
        for (int k = 0; k < N_RAMPS; k++) {
            self->ramps[k].start[ch] = init[k];
            self->ramps[k].delta[ch] = 0.0;
            self->ramps[k].pos[ch] = 1.0;
            self->ramps[k].len[ch] = 1.0;
        }
        self->glide_s[ch] = glide_s;
        self->read_idx[ch] = read_idx[ch];
        self->colmap[ch] = ch;
    }
    self->dev_channels = self->channels;
    self->identity = 1;
    self->ring_cap = ring_cap;
    self->sched_cap = sched_cap;
    self->vfade = fmax(1.0, nearbyint(VOICE_FADE_S * fs));
    self->ring = ring;
    self->heap = heap;
    self->tap = tap;
    self->plock = lock;
    self->ready = 1;
    return 0;
fail:
    if (sig.obj) PyBuffer_Release(&sig);
    if (pk.obj) PyBuffer_Release(&pk);
    free(ring);
    free(heap);
    free(tap);
    if (lock) PyThread_free_lock(lock);
    return -1;
}

static PyObject *Core_push(Core *self, PyObject *args) {
    if (not_ready(self)) return NULL;
    cmd_t cmd;
    memset(&cmd, 0, sizeof cmd);
    unsigned long long mask, ptr = 0;
    long long at, ival = 0;
    int layer = 0;
    if (!PyArg_ParseTuple(args, "iiddKL|iKL", &cmd.kind, &cmd.arg, &cmd.value, &cmd.glide, &mask, &at, &layer, &ptr,
                          &ival))
        return NULL;
    if (cmd.kind < CMD_KNOB || cmd.kind > CMD_TRIM) {
        PyErr_Format(PyExc_ValueError, "kind must be one of the CMD_* constants, got %d", cmd.kind);
        return NULL;
    }
    if (layer < 0 || layer >= VS_LAYERS) {
        PyErr_Format(PyExc_ValueError, "layer must be in 0..%d, got %d", VS_LAYERS - 1, layer);
        return NULL;
    }
    if (cmd.kind == CMD_KNOB && cmd.arg != 0 && cmd.arg != 1) {
        PyErr_Format(PyExc_ValueError, "arg must be 0 (intensity) or 1 (balance) for CMD_KNOB, got %d", cmd.arg);
        return NULL;
    }
    if ((cmd.kind == CMD_LAYER || cmd.kind == CMD_CANCEL) && (cmd.arg < 0 || cmd.arg >= VS_LAYERS)) {
        PyErr_Format(PyExc_ValueError, "arg must be a layer in 0..%d, got %d", VS_LAYERS - 1, cmd.arg);
        return NULL;
    }
    if (check_finite("value", cmd.value) < 0) return NULL;
    if (cmd.kind == CMD_GLIDE && check_range("value (glide seconds)", cmd.value, 0.0, MAX_GLIDE_S) < 0) return NULL;
    /* NaN = the default glide; anything else becomes glide x fs samples on the audio thread */
    if (!isnan(cmd.glide) && check_range("glide", cmd.glide, 0.0, MAX_GLIDE_S) < 0) return NULL;
    if (at < -1) {
        PyErr_Format(PyExc_ValueError, "at must be -1 (as soon as possible) or a frame >= 0, got %lld", at);
        return NULL;
    }
    if (ival < 0) {
        PyErr_Format(PyExc_ValueError, "length must be >= 0, got %lld", ival);
        return NULL;
    }
    if (cmd.kind == CMD_TRIM && ptr && ival != self->levels) {
        PyErr_Format(PyExc_ValueError, "length must be the bank's levels (%d) for a trim curve, got %lld",
                     self->levels, ival);
        return NULL;
    }
    cmd.mask = mask;
    cmd.at = at;
    cmd.layer = layer;
    cmd.ptr = (const float *)(uintptr_t)ptr;
    cmd.ival = ival;
    int64_t seq = 0;
    int rc = core_push(self, &cmd, &seq);
    if (rc != PUSH_OK) return PyLong_FromLong(-rc);
    return PyLong_FromLongLong(seq);
}

static PyObject *Core_render_into(Core *self, PyObject *arg) {
    if (not_ready(self)) return NULL;
    Py_buffer view;
    if (PyObject_GetBuffer(arg, &view, PyBUF_C_CONTIGUOUS | PyBUF_FORMAT | PyBUF_WRITABLE | PyBUF_ND) < 0) return NULL;
    if (view.ndim != 2 || strcmp(view.format, "f") != 0 || view.shape[1] != self->channels) {
        PyBuffer_Release(&view);
        PyErr_SetString(PyExc_ValueError, "out must be a writable C-contiguous float32 array (frames, channels)");
        return NULL;
    }
    static const int identity[MAXCH] = {0,  1,  2,  3,  4,  5,  6,  7,  8,  9,  10, 11, 12, 13, 14, 15,
                                        16, 17, 18, 19, 20, 21, 22, 23, 24, 25, 26, 27, 28, 29, 30, 31,
                                        32, 33, 34, 35, 36, 37, 38, 39, 40, 41, 42, 43, 44, 45, 46, 47,
                                        48, 49, 50, 51, 52, 53, 54, 55, 56, 57, 58, 59, 60, 61, 62, 63};
    float *out = (float *)view.buf;
    int64_t frames = view.shape[0];
    Py_BEGIN_ALLOW_THREADS
    core_render(self, out, frames, self->channels, identity);
    Py_END_ALLOW_THREADS
    PyBuffer_Release(&view);
    Py_RETURN_NONE;
}

static PyObject *Core_set_output_map(Core *self, PyObject *args) {
    if (not_ready(self)) return NULL;
    int dev_channels;
    PyObject *cols;
    if (!PyArg_ParseTuple(args, "iO", &dev_channels, &cols)) return NULL;
    Py_ssize_t len = PySequence_Length(cols);
    if (len < 0) return NULL; /* not a sequence: its TypeError */
    if (len != self->channels || dev_channels < 1) {
        PyErr_SetString(PyExc_ValueError, "need one device column per engine channel");
        return NULL;
    }
    int identity = dev_channels == self->channels;
    int tmp[MAXCH];
    for (int ch = 0; ch < self->channels; ch++) {
        PyObject *o = PySequence_GetItem(cols, ch);
        if (!o) return NULL;
        long v = PyLong_AsLong(o);
        Py_DECREF(o);
        if (v == -1 && PyErr_Occurred()) return NULL;
        if (v < 0 || v >= dev_channels) {
            PyErr_SetString(PyExc_ValueError, "device column out of range");
            return NULL;
        }
        tmp[ch] = (int)v;
        if (v != ch) identity = 0;
    }
    memcpy(self->colmap, tmp, sizeof(tmp));
    self->dev_channels = dev_channels;
    self->identity = identity;
    Py_RETURN_NONE;
}

static PyObject *Core_knob_values(Core *self, PyObject *unused) {
    if (not_ready(self)) return NULL;
    PyObject *list = PyList_New(self->channels);
    if (!list) return NULL;
    for (int ch = 0; ch < self->channels; ch++) {
        PyObject *t = Py_BuildValue("(ddO)", ramp_value(&self->ramps[R_INTENSITY], ch),
                                    ramp_value(&self->ramps[R_BALANCE], ch), self->muted[ch] ? Py_True : Py_False);
        if (!t) {
            Py_DECREF(list);
            return NULL;
        }
        PyList_SetItem(list, ch, t);
    }
    return list;
}

/* Copy the newest `frames` output frames into out (float32 (frames, channels)); returns the stream
 * frame just after the last one copied. Retries when the audio thread overwrote the span mid-copy. */
static PyObject *Core_read_tap(Core *self, PyObject *arg) {
    if (not_ready(self)) return NULL;
    Py_buffer view;
    if (PyObject_GetBuffer(arg, &view, PyBUF_C_CONTIGUOUS | PyBUF_FORMAT | PyBUF_WRITABLE | PyBUF_ND) < 0) return NULL;
    int64_t frames = view.ndim == 2 ? view.shape[0] : -1;
    if (view.ndim != 2 || strcmp(view.format, "f") != 0 || view.shape[1] != self->channels || frames > TAP_FRAMES / 2) {
        PyBuffer_Release(&view);
        PyErr_Format(PyExc_ValueError, "out must be float32 (frames <= %d, channels)", TAP_FRAMES / 2);
        return NULL;
    }
    float *out = (float *)view.buf;
    int nch = self->channels;
    int64_t end = 0;
    Py_BEGIN_ALLOW_THREADS
    for (int attempt = 0; attempt < 8; attempt++) {
        end = LOAD_ACQ(&self->tap_frame);
        int64_t first = end - frames;
        for (int64_t j = 0; j < frames; j++) {
            int64_t f = first + j;
            if (f < 0) {
                memset(out + j * nch, 0, sizeof(float) * (size_t)nch);
            } else {
                memcpy(out + j * nch, self->tap + (f & (TAP_FRAMES - 1)) * nch, sizeof(float) * (size_t)nch);
            }
        }
        /* Frames first.. are intact if the writer has not wrapped onto them meanwhile. */
        if (LOAD_ACQ(&self->tap_frame) - first <= TAP_FRAMES) break;
    }
    Py_END_ALLOW_THREADS
    PyBuffer_Release(&view);
    return PyLong_FromLongLong(end);
}

/* (balance offset, trim gain at the bank position of balance 0 + offset) per channel, as the audio thread has them. */
static PyObject *Core_trim_values(Core *self, PyObject *unused) {
    if (not_ready(self)) return NULL;
    PyObject *list = PyList_New(self->channels);
    if (!list) return NULL;
    for (int ch = 0; ch < self->channels; ch++) {
        double off = ramp_value(&self->ramps[R_TRIM_BAL], ch);
        double t = fmin(fmax(off * self->pos_scale + self->pos_offset, 0.0), self->pos_max);
        double f = fmin(floor(t), self->idx_max);
        const float *curve = *(const float *volatile *)&self->tcur[ch];
        PyObject *v = Py_BuildValue("(dd)", off, trim_curve(curve, (int64_t)f, t - f));
        if (!v) {
            Py_DECREF(list);
            return NULL;
        }
        PyList_SetItem(list, ch, v);
    }
    return list;
}

/* Sequence number of the voice each channel plays (0 = none). */
static PyObject *Core_voice_ids(Core *self, PyObject *unused) {
    if (not_ready(self)) return NULL;
    PyObject *list = PyList_New(self->channels);
    if (!list) return NULL;
    for (int ch = 0; ch < self->channels; ch++) {
        PyObject *v = PyLong_FromLongLong(LOAD_ACQ(&self->vid[ch]));
        if (!v) {
            Py_DECREF(list);
            return NULL;
        }
        PyList_SetItem(list, ch, v);
    }
    return list;
}

/* The layer driving each channel's knobs, as the audio thread last applied it. */
static PyObject *Core_layers(Core *self, PyObject *unused) {
    if (not_ready(self)) return NULL;
    PyObject *list = PyList_New(self->channels);
    if (!list) return NULL;
    for (int ch = 0; ch < self->channels; ch++) {
        PyObject *v = PyLong_FromLong(*(volatile int32_t *)&self->top[ch]);
        if (!v) {
            Py_DECREF(list);
            return NULL;
        }
        PyList_SetItem(list, ch, v);
    }
    return list;
}

static PyObject *Core_take_peak(Core *self, PyObject *unused) {
    if (not_ready(self)) return NULL;
    double peak = self->load_peak;
    self->load_peak = 0.0;
    return PyFloat_FromDouble(peak);
}

static PyObject *Core_add_underflows(Core *self, PyObject *arg) {
    if (not_ready(self)) return NULL;
    long long n = PyLong_AsLongLong(arg);
    if (n == -1 && PyErr_Occurred()) return NULL;
    FETCH_ADD(&self->underflows, (int64_t)n);
    Py_RETURN_NONE;
}

/* Run the PortAudio callback on a Python buffer (float32 (frames, device_channels)): tests. */
static PyObject *Core_run_callback(Core *self, PyObject *args) {
    if (not_ready(self)) return NULL;
    PyObject *arg;
    unsigned long status;
    if (!PyArg_ParseTuple(args, "Ok", &arg, &status)) return NULL;
    Py_buffer view;
    if (PyObject_GetBuffer(arg, &view, PyBUF_C_CONTIGUOUS | PyBUF_FORMAT | PyBUF_WRITABLE | PyBUF_ND) < 0) return NULL;
    if (view.ndim != 2 || strcmp(view.format, "f") != 0 || view.shape[1] != self->dev_channels) {
        PyBuffer_Release(&view);
        PyErr_SetString(PyExc_ValueError, "out must be float32 (frames, device_channels)");
        return NULL;
    }
    int rc;
    Py_BEGIN_ALLOW_THREADS
    rc = pa_callback(NULL, view.buf, (unsigned long)view.shape[0], NULL, status, self);
    Py_END_ALLOW_THREADS
    PyBuffer_Release(&view);
    return PyLong_FromLong(rc);
}

/* (first frame, adc, current, dac, monotonic s) of the last PortAudio output block, or None. */
static PyObject *Core_output_stamp(Core *self, PyObject *unused) {
    if (not_ready(self)) return NULL;
    int64_t frame;
    double t[4];
    if (!self->has_out_stamp || !vs_stamp_read(&self->out_stamp, &frame, t)) Py_RETURN_NONE;
    return Py_BuildValue("(Ldddd)", (long long)frame, t[0], t[1], t[2], t[3]);
}

static PyObject *Core_addresses(Core *self, PyObject *unused) {
    if (not_ready(self)) return NULL;
    return Py_BuildValue("(KK)", (unsigned long long)(uintptr_t)&pa_callback, (unsigned long long)(uintptr_t)self);
}

#define INT_GETTER(name, field)                                                                     \
    static PyObject *Core_get_##name(Core *self, void *closure) {                                  \
        if (not_ready(self)) return NULL;                                                          \
        return PyLong_FromLongLong(LOAD_ACQ(&self->field));                                        \
    }
INT_GETTER(frame, frame)
INT_GETTER(applied_seq, applied_seq)
INT_GETTER(blocks, blocks)
INT_GETTER(underflows, underflows)
INT_GETTER(late_commands, late)
INT_GETTER(ring_full, ring_full)
INT_GETTER(schedule_full, schedule_full)
INT_GETTER(callbacks, callbacks)

static PyObject *Core_get_pending(Core *self, void *closure) {
    if (not_ready(self)) return NULL;
    PyThread_acquire_lock(self->plock, WAIT_LOCK);
    int64_t pending = self->sched_submitted - LOAD_ACQ(&self->sched_done);
    PyThread_release_lock(self->plock);
    return PyLong_FromLongLong(pending);
}
#define CORE_DOUBLE(name, field)                                                                    \
    static PyObject *Core_get_##name(Core *self, void *closure) {                                  \
        if (not_ready(self)) return NULL;                                                          \
        return PyFloat_FromDouble(self->field);                                                    \
    }
CORE_DOUBLE(load_last, load_last)
CORE_DOUBLE(load_peak, load_peak)
CORE_DOUBLE(load_avg, load_avg)
static PyObject *Core_get_schedule_capacity(Core *self, void *c) {
    if (not_ready(self)) return NULL;
    return PyLong_FromLongLong(self->sched_cap);
}

static PyGetSetDef Core_getset[] = {
    {"frame", (getter)Core_get_frame, NULL, "frames rendered since start", NULL},
    {"applied_seq", (getter)Core_get_applied_seq, NULL, "highest sequence number taken by the audio thread", NULL},
    {"blocks", (getter)Core_get_blocks, NULL, "render calls", NULL},
    {"underflows", (getter)Core_get_underflows, NULL, "output underflows reported by the driver", NULL},
    {"late_commands", (getter)Core_get_late_commands, NULL, "scheduled commands that arrived late", NULL},
    {"ring_full", (getter)Core_get_ring_full, NULL, "commands refused: hand-off ring full", NULL},
    {"schedule_full", (getter)Core_get_schedule_full, NULL, "commands refused: schedule cap reached", NULL},
    {"callbacks", (getter)Core_get_callbacks, NULL, "PortAudio callbacks run", NULL},
    {"pending", (getter)Core_get_pending, NULL, "scheduled commands not yet applied", NULL},
    {"schedule_capacity", (getter)Core_get_schedule_capacity, NULL, "schedule cap", NULL},
    {"load_last", (getter)Core_get_load_last, NULL, "last render time / block period", NULL},
    {"load_peak", (getter)Core_get_load_peak, NULL, "peak load since take_peak()", NULL},
    {"load_avg", (getter)Core_get_load_avg, NULL, "exponential average load", NULL},
    {NULL}};

static PyMethodDef Core_methods[] = {
    {"push", (PyCFunction)Core_push, METH_VARARGS,
     "push(kind, arg, value, glide, mask, at[, layer, ptr, length]) -> seq > 0, or -1 (ring full) / -2 (schedule "
     "full)"},
    {"render_into", (PyCFunction)Core_render_into, METH_O, "render_into(out float32 (frames, channels)); GIL released"},
    {"set_output_map", (PyCFunction)Core_set_output_map, METH_VARARGS,
     "set_output_map(device_channels, columns): where each engine channel goes in the callback's buffer"},
    {"knob_values", (PyCFunction)Core_knob_values, METH_NOARGS, "[(intensity, balance, muted)] per channel"},
    {"read_tap", (PyCFunction)Core_read_tap, METH_O,
     "read_tap(out float32 (frames, channels)) -> end frame: the newest output frames"},
    {"voice_ids", (PyCFunction)Core_voice_ids, METH_NOARGS, "[seq of the playing voice or 0] per channel"},
    {"trim_values", (PyCFunction)Core_trim_values, METH_NOARGS,
     "[(balance offset, trim gain at balance 0)] per channel (approximate while gliding)"},
    {"layers", (PyCFunction)Core_layers, METH_NOARGS, "[layer driving the knobs] per channel"},
    {"take_peak", (PyCFunction)Core_take_peak, METH_NOARGS, "peak load since the last call (and reset it)"},
    {"add_underflows", (PyCFunction)Core_add_underflows, METH_O, "count underflows seen by another output"},
    {"run_callback", (PyCFunction)Core_run_callback, METH_VARARGS,
     "run_callback(out float32 (frames, device_channels), status_flags) -> paContinue; for tests"},
    {"addresses", (PyCFunction)Core_addresses, METH_NOARGS, "(PaStreamCallback address, userdata address)"},
    {"output_stamp", (PyCFunction)Core_output_stamp, METH_NOARGS,
     "(first frame, adc, current, dac, monotonic) of the last PortAudio output block, or None"},
    {NULL}};

/* A heap type (the limited API has no static PyTypeObject), made once by PyInit__core and kept for
 * the process's life (the module is single-phase: it is never made twice). Immutable, like a static
 * type: its methods and attributes cannot be replaced from Python. */
static PyType_Slot Core_slots[] = {
    {Py_tp_doc, (void *)"Real-time engine state, command ring, scheduler and PortAudio callback."},
    {Py_tp_new, (void *)PyType_GenericNew},
    {Py_tp_init, (void *)Core_init},
    {Py_tp_dealloc, (void *)Core_dealloc},
    {Py_tp_methods, Core_methods},
    {Py_tp_getset, Core_getset},
    {0, NULL}};
static PyType_Spec Core_spec = {"vibsynth.engine._core.Core", sizeof(Core), 0,
                                Py_TPFLAGS_DEFAULT | Py_TPFLAGS_IMMUTABLETYPE, Core_slots};
static PyTypeObject *CoreType;

/* C producers (the OSC fast path) reach core_push through this capsule. */
static int core_channels(Core *c) { return c->channels; }
static int core_ready(Core *c) { return c->ready; }
static vs_core_api_t core_api = {core_push, core_channels, NULL, core_ready};

static struct PyModuleDef module = {PyModuleDef_HEAD_INIT, "_core", "vibsynth real-time core", -1, NULL};

PyMODINIT_FUNC PyInit__core(void) {
    if (!CoreType) CoreType = (PyTypeObject *)PyType_FromSpec(&Core_spec);
    if (!CoreType) return NULL;
    core_api.core_type = CoreType; /* what the fast path's Receiver checks its core against */
    PyObject *m = PyModule_Create(&module);
    if (!m) return NULL;
    if (PyModule_AddObjectRef(m, "Core", (PyObject *)CoreType) < 0) {
        Py_DECREF(m);
        return NULL;
    }
    PyModule_AddIntConstant(m, "CMD_KNOB", CMD_KNOB);
    PyModule_AddIntConstant(m, "CMD_GLIDE", CMD_GLIDE);
    PyModule_AddIntConstant(m, "CMD_MUTE", CMD_MUTE);
    PyModule_AddIntConstant(m, "CMD_PANIC", CMD_PANIC);
    PyModule_AddIntConstant(m, "CMD_LAYER", CMD_LAYER);
    PyModule_AddIntConstant(m, "CMD_CANCEL", CMD_CANCEL);
    PyModule_AddIntConstant(m, "CMD_VOICE", CMD_VOICE);
    PyModule_AddIntConstant(m, "CMD_VOICE_STOP", CMD_VOICE_STOP);
    PyModule_AddIntConstant(m, "CMD_TRIM", CMD_TRIM);
    PyModule_AddIntConstant(m, "LAYERS", VS_LAYERS);
    PyModule_AddIntConstant(m, "TAP_FRAMES", TAP_FRAMES);
    PyModule_AddIntConstant(m, "MAX_CHANNELS", MAXCH);
    PyModule_AddIntConstant(m, "DRAIN_MAX", DRAIN_MAX);
    PyModule_AddObject(m, "_C_API", PyCapsule_New(&core_api, VS_CORE_CAPSULE, NULL));
    return m;
}
