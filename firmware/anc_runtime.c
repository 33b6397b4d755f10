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
    rt->ready = 0u;
    rt->overruns = 0u;
    rt->controller = controller;
    rt->controller_context = controller_context;
}

void anc_process_block(anc_runtime *rt, const int16_t *chin, const int16_t *ear, int16_t *speaker)
{
    size_t i;
    /* Internal model: what the ear would hear from the speaker alone. */
    fb_q15_process(&rt->fb, rt->played, rt->ear_model, ANC_BLOCK);
    for (i = 0; i < ANC_BLOCK; ++i) {
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
    /* This block is played while the next one is captured. */
    for (i = 0; i < ANC_BLOCK; ++i) {
        rt->played[i] = speaker[i];
    }
}

void anc_dma_block_done(anc_runtime *rt, unsigned half)
{
    uint32_t bit = 1u << (half & 1u);
    if ((rt->ready & bit) != 0u) {
        ++rt->overruns;
    }
    rt->ready |= bit;
}

int anc_service(anc_runtime *rt)
{
    unsigned h;
    for (h = 0; h < 2u; ++h) {
        uint32_t bit = 1u << h;
        if ((rt->ready & bit) != 0u) {
            /* The speaker half to fill is the one the DMA plays next: the other half. */
            anc_process_block(rt, rt->chin[h], rt->ear[h], rt->speaker[h ^ 1u]);
            rt->ready &= ~bit;
            return 1;
        }
    }
    return 0;
}
