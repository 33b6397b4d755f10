/*
 * Board runtime of the helmet ANC: wires the generated FB and FF filters (names
 * "fb" and "ff", Q15 variant) into a double-buffered block audio callback.
 *
 * This block path serves logging and identification; the control loop itself runs per sample
 * in the codec interrupt (anc_control.h: latency 2 samples instead of 2 * ANC_BLOCK).
 *
 * Timing: the codec DMA runs over two halves of each buffer. While half h is
 * being captured (chin and ear microphones) and played (speaker), the CPU works
 * on the other half. anc_dma_block_done() (from the DMA interrupt) marks a captured
 * half ready; anc_service() (main loop) processes it with anc_process_block(),
 * which must finish within one block period. When half h completes, the DMA moves
 * on to half h ^ 1 (capturing and playing it), so the speaker half the CPU may
 * fill is speaker[h], the one just played: it is played again two block periods
 * later. Input-to-speaker latency is therefore two blocks (2 * ANC_BLOCK samples).
 *
 * Interrupt/main-loop sharing (single writer per variable, no read-modify-write
 * of shared data): for each half h the interrupt alone writes captured[h] (a
 * count of completed captures) and overruns; the main loop alone writes
 * serviced[h]. Half h is ready when captured[h] != serviced[h]. Each is an
 * aligned 32-bit word, read and written atomically by one load or store on a
 * Cortex-M; volatile keeps the compiler from caching them. The interrupt counts
 * an overrun when it completes half h again before the main loop serviced the
 * previous capture (the main loop then processes the newest data once).
 *
 * Per block of ANC_BLOCK samples:
 *   ear_model[n] = G_fb * played[n]   the FB model driven by what the speaker played
 *                                     while this block was captured (the block the
 *                                     runtime computed two periods earlier);
 *   d_hat[n]     = ear[n] - ear_model[n]   internal-model disturbance observer:
 *                                     the ear signal not caused by the speaker;
 *   ff_pred[n]   = G_ff * chin[n]     the ear noise predicted from the chin microphone;
 *   speaker      = controller(d_hat, ff_pred)   the application's control law.
 * All signals are Q15; differences saturate.
 *
 * Headroom of the disturbance estimate: ear_model saturates when the speaker's DC
 * exceeds FB_DC_HEADROOM_LSB (32767 / FB_DC_GAIN, from fb_filter.h; 44 LSB for an FB
 * model with a DC gain of 738, which identification gives when a pole sits near z = 1
 * although a real speaker passes no DC). d_hat is then wrong by the excess, and
 * model_saturations counts the saturated samples. Keep the control law's output DC
 * below FB_DC_HEADROOM_LSB (e.g. a DC blocker in the control law) or use an FB model
 * whose DC gain matches the helmet.
 */
#ifndef ANC_RUNTIME_H
#define ANC_RUNTIME_H

#include <stddef.h>
#include <stdint.h>
#include "fb_filter.h"
#include "ff_filter.h"

#ifndef ANC_BLOCK
#define ANC_BLOCK 32u
#endif

/* Control law: from the disturbance estimate and the FF prediction (n samples
 * each) compute the next n speaker samples. */
typedef void (*anc_controller_fn)(void *context, const int16_t *d_hat, const int16_t *ff_pred,
                                  int16_t *speaker, size_t n);

typedef struct {
    fb_q15_state fb;
    ff_q15_state ff;
    int16_t chin[2][ANC_BLOCK];     /* DMA capture, chin microphone */
    int16_t ear[2][ANC_BLOCK];      /* DMA capture, ear-canal microphone */
    int16_t speaker[2][ANC_BLOCK];  /* DMA playback, headphone drive */
    int16_t played[ANC_BLOCK];      /* speaker samples played during the block being processed */
    int16_t ear_model[ANC_BLOCK];
    int16_t d_hat[ANC_BLOCK];
    int16_t ff_pred[ANC_BLOCK];
    volatile uint32_t captured[2];  /* written by the interrupt only: captures of half h completed */
    volatile uint32_t serviced[2];  /* written by the main loop only: captures of half h processed */
    volatile uint32_t overruns;     /* written by the interrupt only: halves captured again unprocessed */
    uint32_t model_saturations;     /* main loop: ear_model samples at the Q15 rail (see Headroom) */
    anc_controller_fn controller;   /* NULL: the speaker stays silent (observer only) */
    void *controller_context;
} anc_runtime;

void anc_init(anc_runtime *rt, anc_controller_fn controller, void *controller_context);
void anc_dma_block_done(anc_runtime *rt, unsigned half);
int anc_service(anc_runtime *rt);
/* speaker: on entry the samples played while chin/ear were captured, on return
 * the samples to play next in this half. */
void anc_process_block(anc_runtime *rt, const int16_t *chin, const int16_t *ear, int16_t *speaker);

#endif /* ANC_RUNTIME_H */
