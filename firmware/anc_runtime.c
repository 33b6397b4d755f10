/* Block audio runtime of the helmet ANC; see anc_runtime.h for the signal flow. */
#include "anc_runtime.h"

static int16_t anc_sat16(int32_t v)
{
    return (int16_t)((v > 32767) ? 32767 : ((v < -32768) ? -32768 : v));
}

void anc_init(anc_runtime *rt, anc_controller_fn controller, void *controller_context)
{
    size_t i;
    unsigned h;
    fb_q15_init(&rt->fb);
    ff_q15_init(&rt->ff);
    for (h = 0; h < 2u; ++h) {
        for (i = 0; i < ANC_BLOCK; ++i) {
            rt->chin[h][i] = 0;
            rt->ear[h][i] = 0;
            rt->speaker[h][i] = 0;
        }
    }
    for (i = 0; i < ANC_BLOCK; ++i) {
        rt->played[i] = 0;
    }
    for (h = 0; h < 2u; ++h) {
        rt->captured[h] = 0u;
        rt->serviced[h] = 0u;
    }
    rt->overruns = 0u;
    rt->model_saturations = 0u;
    rt->controller = controller;
    rt->controller_context = controller_context;
}

void anc_process_block(anc_runtime *rt, const int16_t *chin, const int16_t *ear, int16_t *speaker)
{
    size_t i;
    /* What the DMA just played from this half, while chin and ear were captured. */
    for (i = 0; i < ANC_BLOCK; ++i) {
        rt->played[i] = speaker[i];
    }
    /* Internal model: what the ear would hear from the speaker alone. */
    fb_q15_process(&rt->fb, rt->played, rt->ear_model, ANC_BLOCK);
    for (i = 0; i < ANC_BLOCK; ++i) {
        if (rt->ear_model[i] == INT16_MAX || rt->ear_model[i] == INT16_MIN) {
            ++rt->model_saturations;
        }
        rt->d_hat[i] = anc_sat16((int32_t)ear[i] - (int32_t)rt->ear_model[i]);
    }
    ff_q15_process(&rt->ff, chin, rt->ff_pred, ANC_BLOCK);
    if (rt->controller != NULL) {
        rt->controller(rt->controller_context, rt->d_hat, rt->ff_pred, speaker, ANC_BLOCK);
    } else {
        for (i = 0; i < ANC_BLOCK; ++i) {
            speaker[i] = 0;
        }
    }
}

/* Interrupt side: writes captured[h] and overruns only (see anc_runtime.h). */
void anc_dma_block_done(anc_runtime *rt, unsigned half)
{
    unsigned h = half & 1u;
    uint32_t count = rt->captured[h];
    if (count != rt->serviced[h]) {
        rt->overruns = rt->overruns + 1u;
    }
    rt->captured[h] = count + 1u;
}

/* Main-loop side: writes serviced[h] only. */
int anc_service(anc_runtime *rt)
{
    unsigned h;
    for (h = 0; h < 2u; ++h) {
        uint32_t count = rt->captured[h];
        if (count != rt->serviced[h]) {
            /* Fill the half that just finished playing: the DMA is now on half h ^ 1. */
            anc_process_block(rt, rt->chin[h], rt->ear[h], rt->speaker[h]);
            rt->serviced[h] = count;
            return 1;
        }
    }
    return 0;
}
