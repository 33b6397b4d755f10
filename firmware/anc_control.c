/* Control path of the helmet ANC in the codec interrupt; see anc_control.h for the signal
 * flow, the latency budget and the limiter. */
#include "anc_control.h"

#define ANC_B ANC_CONTROL_BLOCK

#ifdef ANC_CONTROL_F32
/* Full-scale float to a 16-bit word: floor(32768 v + 1/2) in float32, saturated; NaN gives 0.
 * No libm: the floor of the truncated value is corrected by one where truncation rounded up. */
static int16_t anc_to_word(float v)
{
    float t = v * 32768.0f;
    int32_t q;
    if (t != t) {
        return 0;
    }
    if (t >= 32767.0f) {
        return 32767;
    }
    if (t <= -32768.0f) {
        return -32768;
    }
    t = t + 0.5f;
    q = (int32_t)t;
    if ((float)q > t) {
        q -= 1;
    }
    return (int16_t)q;
}

static float anc_from_word(int16_t w)
{
    return (float)w * (1.0f / 32768.0f);
}
#define ANC_PROCESS(filter, state, in, out) filter##_f32_process(state, in, out, ANC_B)
#define ANC_RESET(filter, state) filter##_f32_reset(state)
#else
static int16_t anc_sat16(int32_t v)
{
    return (int16_t)((v > 32767) ? 32767 : ((v < -32768) ? -32768 : v));
}
/* One step call per frame: for blocks of at most 4 frames the filters' per-sample kernel costs
 * less than process(), whose section loops and chunk bookkeeping pay off on longer blocks. */
#define ANC_PROCESS(filter, state, in, out)                  \
    do {                                                     \
        size_t j_;                                           \
        for (j_ = 0; j_ < ANC_B; ++j_) {                     \
            (out)[j_] = filter##_q15_step(state, (in)[j_]);  \
        }                                                    \
    } while (0)
#define ANC_RESET(filter, state) filter##_q15_reset(state)
#endif

static void anc_clear_limiter(anc_control *ctl)
{
    ctl->rail_score = 0u;
    ctl->window_fill = 0u;
    ctl->window_sum = 0u;
    ctl->previous_sum = 0u;
    ctl->growth_run = 0u;
    ctl->muted = 0u;
}

static void anc_clear_controller(anc_control *ctl)
{
    size_t i;
#if CTL_HAS_Q
    ANC_RESET(ctl_q, &ctl->q);
#endif
#if CTL_HAS_W
    ANC_RESET(ctl_w, &ctl->w);
#endif
    for (i = 0; i < ANC_EXTRA_DELAY + 1u; ++i) {
        ctl->d_line[i] = 0;
        ctl->x_line[i] = 0;
    }
    ctl->line_pos = 0u;
}

void anc_control_init(anc_control *ctl)
{
    size_t i;
    unsigned h;
    ANC_RESET(ctl_s, &ctl->model);
    anc_clear_controller(ctl);
    for (h = 0; h < 2u; ++h) {
        for (i = 0; i < ANC_B; ++i) {
            ctl->chin[h][i] = 0;
            ctl->ear[h][i] = 0;
            ctl->drive[h][i] = 0;
        }
    }
    for (i = 0; i < ANC_B; ++i) {
        ctl->d_hat[i] = 0;
    }
    anc_clear_limiter(ctl);
    ctl->trips = 0u;
    ctl->muted_at = 0u;
    ctl->frames = 0u;
    ctl->model_saturations = 0u;
}

void anc_control_unmute(anc_control *ctl)
{
    anc_clear_controller(ctl);
    anc_clear_limiter(ctl);
}

/* One frame of the limiter (anc_control.h); returns the trip reason or 0. */
static uint32_t anc_limit(anc_control *ctl, int16_t drive, int16_t d_hat)
{
    uint32_t magnitude = (d_hat < 0) ? (uint32_t)(-(int32_t)d_hat) : (uint32_t)d_hat;
    if (drive == 32767 || drive == -32768 || d_hat == 32767 || d_hat == -32768) {
        ctl->rail_score = ctl->rail_score + 8u;
    } else if (ctl->rail_score > 0u) {
        ctl->rail_score = ctl->rail_score - 1u;
    }
    if (ctl->rail_score >= 8u * ANC_LIMIT_RAIL_SAMPLES) {
        return ANC_MUTE_RAILS;
    }
    /* At most ANC_LIMIT_WINDOW * 32768 = 2^25 for the default window: no overflow. */
    ctl->window_sum = ctl->window_sum + magnitude;
    ctl->window_fill = ctl->window_fill + 1u;
    if (ctl->window_fill == ANC_LIMIT_WINDOW) {
        if (ctl->window_sum / 2u > ctl->previous_sum && ctl->window_sum > ANC_LIMIT_FLOOR * ANC_LIMIT_WINDOW) {
            ctl->growth_run = ctl->growth_run + 1u;
        } else {
            ctl->growth_run = 0u;
        }
        ctl->previous_sum = ctl->window_sum;
        ctl->window_sum = 0u;
        ctl->window_fill = 0u;
        if (ctl->growth_run >= ANC_LIMIT_GROWTH_WINDOWS) {
            return ANC_MUTE_GROWTH;
        }
    }
    return 0u;
}

void anc_control_dma_done(anc_control *ctl, unsigned half)
{
    unsigned h = half & 1u;
    int16_t *drive = ctl->drive[h];
    anc_value played[ANC_B], model_out[ANC_B], q_in[ANC_B], w_in[ANC_B], q_out[ANC_B], w_out[ANC_B];
    uint32_t tripped = 0u;
    size_t i;
    /* What the DAC played during this half, while chin and ear were captured. */
    for (i = 0; i < ANC_B; ++i) {
#ifdef ANC_CONTROL_F32
        played[i] = anc_from_word(drive[i]);
#else
        played[i] = drive[i];
#endif
    }
    ANC_PROCESS(ctl_s, &ctl->model, played, model_out);
    for (i = 0; i < ANC_B; ++i) {
#ifdef ANC_CONTROL_F32
        anc_value d = anc_from_word(ctl->ear[h][i]) - model_out[i];
        anc_value x = anc_from_word(ctl->chin[h][i]);
        if (model_out[i] >= 1.0f || model_out[i] <= -1.0f) {
            ++ctl->model_saturations;
        }
        ctl->d_hat[i] = anc_to_word(d);
#else
        anc_value d = anc_sat16((int32_t)ctl->ear[h][i] - (int32_t)model_out[i]);
        anc_value x = ctl->chin[h][i];
        if (model_out[i] == INT16_MAX || model_out[i] == INT16_MIN) {
            ++ctl->model_saturations;
        }
        ctl->d_hat[i] = d;
#endif
#if ANC_EXTRA_DELAY > 0
        /* Delay to the controller's latency: read the oldest, store the newest in its place. */
        q_in[i] = ctl->d_line[ctl->line_pos];
        w_in[i] = ctl->x_line[ctl->line_pos];
        ctl->d_line[ctl->line_pos] = d;
        ctl->x_line[ctl->line_pos] = x;
        ctl->line_pos = (ctl->line_pos + 1u == ANC_EXTRA_DELAY) ? 0u : ctl->line_pos + 1u;
#else
        q_in[i] = d;
        w_in[i] = x;
#endif
    }
#if CTL_HAS_Q
    ANC_PROCESS(ctl_q, &ctl->q, q_in, q_out);
#else
    for (i = 0; i < ANC_B; ++i) {
        q_out[i] = 0;
    }
#endif
#if CTL_HAS_W
    ANC_PROCESS(ctl_w, &ctl->w, w_in, w_out);
#else
    for (i = 0; i < ANC_B; ++i) {
        w_out[i] = 0;
    }
#endif
    for (i = 0; i < ANC_B; ++i) {
#ifdef ANC_CONTROL_F32
        int16_t total = anc_to_word(q_out[i] + w_out[i]);
#else
        int16_t total = anc_sat16((int32_t)q_out[i] + (int32_t)w_out[i]);
#endif
        if (ctl->muted == 0u) {
            uint32_t reason = anc_limit(ctl, total, ctl->d_hat[i]);
            if (reason != 0u) {
                ctl->muted = reason;
                ctl->trips = ctl->trips + 1u;
                ctl->muted_at = ctl->frames;
                tripped = 1u;
            }
        }
        drive[i] = (ctl->muted != 0u) ? (int16_t)0 : total;
        ctl->frames = ctl->frames + 1u;
    }
    if (tripped != 0u) {
        anc_clear_controller(ctl);
    }
}
