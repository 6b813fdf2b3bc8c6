/*
 * What other compiled modules (the OSC fast path) need of the real-time core: the command
 * layout and the producer entry point, reached through the capsule
 * "vibsynth.engine._core._C_API" (see vibsynth/engine/_core.c).
 */
#ifndef VIBSYNTH_CORE_API_H
#define VIBSYNTH_CORE_API_H
#include <stdint.h>

enum {
    CMD_KNOB = 1,   /* glide a knob of the channels whose top layer is cmd.layer */
    CMD_GLIDE = 2,
    CMD_MUTE = 3,
    CMD_PANIC = 4,
    CMD_LAYER = 5,  /* arg = the layer that now drives the channels' knobs */
    CMD_CANCEL = 6, /* arg = layer: drop that layer's commands submitted before this one (immediate only) */
    CMD_VOICE = 7,  /* ptr/ival = float32 samples/length: play once; ptr NULL = set the playing voice's gain */
    CMD_VOICE_STOP = 8,
    CMD_TRIM = 9    /* ptr/ival = float32 gain curve over the bank levels (NULL = 1), value = balance offset */
};
#define VS_LAYERS 4 /* 0 knobs, 1 follow, 2 sources, 3 clip (engine/commands.py LAYER_NAMES) */
enum { PUSH_OK = 0, PUSH_RING_FULL = 1, PUSH_SCHEDULE_FULL = 2, PUSH_NOT_READY = 3 /* Core not initialised */ };

typedef struct {
    int32_t kind;
    int32_t arg;      /* knob index for CMD_KNOB (0 intensity, 1 balance), muted flag for CMD_MUTE */
    double value;     /* knob value, or glide seconds for CMD_GLIDE */
    double glide;     /* per-move glide (s); NaN = the channel's glide */
    uint64_t mask;    /* channels, bit c = channel c */
    int64_t at;       /* stream frame, -1 = as soon as possible */
    int64_t seq;
    int32_t layer;    /* CMD_KNOB: the control layer that sent it (0 = direct knob control) */
    int32_t reserved;
    const float *ptr; /* CMD_VOICE: samples, kept alive by the producer until the voice is done; CMD_TRIM: curve */
    int64_t ival;     /* CMD_VOICE: number of samples; CMD_TRIM: the curve's length (= bank levels) */
} vs_cmd_t;

struct vs_core;

/*
 * A user of this API holds a Python object it was given as "the core": before casting it to a
 * struct vs_core *, it checks PyObject_TypeCheck(obj, (PyTypeObject *)api->core_type) and then
 * api->ready(core) (an object made by Core.__new__ whose __init__ never succeeded has no ring).
 */
typedef struct {
    /* Any thread, GIL not needed. Returns PUSH_*; *seq_out gets the sequence number. */
    int (*push)(struct vs_core *core, vs_cmd_t *cmd, int64_t *seq_out);
    /* Channels of the core. */
    int (*channels)(struct vs_core *core);
    /* The Core type, a PyTypeObject * (void * so that this header needs no Python.h). */
    void *core_type;
    /* 1 if the core's __init__ succeeded (then it stays so until the object is freed), else 0. */
    int (*ready)(struct vs_core *core);
} vs_core_api_t;

#define VS_CORE_CAPSULE "vibsynth.engine._core._C_API"
#endif
