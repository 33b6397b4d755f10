/*
 * Closed-loop harness: the control path (anc_control.c with a generated controller) against
 * a simulated true plant, frame by frame, identically on the host and on the (emulated)
 * board. Reads, from the working directory:
 *   plant.f64  float64: order n, delay, A (n x n, row major), B (n), C (n), D  (true S)
 *   d.f64      float64: the ear noise without control, full-scale units
 *   chin.q15   int16: the chin microphone's 16-bit words (as many as d.f64)
 * and writes ear.q15 (the ear words the codec captured), drive.q15 (the drive words the DAC
 * played) and status.u32 (muted, trips, muted_at, frames, model_saturations).
 *
 * Frame k, in the codec's order: the DAC plays drive[h][i] (h = (k / B) mod 2, i = k mod B);
 * the ear hears e = d[k] + (S drive)[k] (S with its delay, float64) and the ADC returns
 * floor(32768 e + 1/2), saturated to 16 bits; chin[h][i] takes chin.q15[k]; after the last
 * frame of a half the codec interrupt calls anc_control_dma_done(ctl, h). The float64
 * operations run in a fixed order (codegen.control_loop.board_loop is the Python twin);
 * build with -ffp-contract=off so no multiply-add is fused.
 */
#include <stddef.h>
#include <stdint.h>
#include "anc_control.h"
#include "board_io.h"

#ifndef CLOSED_LOOP_MAX_SAMPLES
#define CLOSED_LOOP_MAX_SAMPLES 131072
#endif
#define PLANT_MAX_ORDER 64
#define PLANT_MAX_DELAY 256

static double d_in[CLOSED_LOOP_MAX_SAMPLES + 1];
static int16_t chin_in[CLOSED_LOOP_MAX_SAMPLES + 1];
static int16_t ear_out[CLOSED_LOOP_MAX_SAMPLES];
static int16_t drive_out[CLOSED_LOOP_MAX_SAMPLES];
static double plant[3 + PLANT_MAX_ORDER * PLANT_MAX_ORDER + 2 * PLANT_MAX_ORDER + 1];
static double state[PLANT_MAX_ORDER];
static double next_state[PLANT_MAX_ORDER];
static double line[PLANT_MAX_DELAY];
static anc_control ctl;

/* The ADC: floor(32768 e + 1/2) saturated to 16 bits (no libm). */
static int16_t adc(double e)
{
    double t = e * 32768.0 + 0.5;
    long q;
    if (t >= 32767.0) {
        return 32767;
    }
    if (t <= -32768.0) {
        return -32768;
    }
    q = (long)t;
    if ((double)q > t) {
        q -= 1;
    }
    return (int16_t)q;
}

static int run(void)
{
    long bytes = board_io_read("plant.f64", plant, sizeof plant);
    size_t n, delay, order, k, i, j, pos = 0;
    const double *A, *B, *C;
    double D;
    uint32_t status[5];
    if (bytes < (long)(3 * sizeof(double))) {
        board_io_print("cannot read plant.f64\n");
        return 1;
    }
    order = (size_t)plant[0];
    delay = (size_t)plant[1];
    if (order > PLANT_MAX_ORDER || delay > PLANT_MAX_DELAY
        || (size_t)bytes != (3 + order * order + 2 * order) * sizeof(double)) {
        board_io_print("plant.f64: order above 64, delay above 256 or wrong size\n");
        return 1;
    }
    A = plant + 2;
    B = A + order * order;
    C = B + order;
    D = C[order];
    bytes = board_io_read("d.f64", d_in, sizeof d_in);
    if (bytes < 0 || (size_t)bytes / sizeof(double) > CLOSED_LOOP_MAX_SAMPLES) {
        board_io_print("cannot read d.f64, or longer than CLOSED_LOOP_MAX_SAMPLES\n");
        return 1;
    }
    n = (size_t)bytes / sizeof(double);
    bytes = board_io_read("chin.q15", chin_in, sizeof chin_in);
    if (bytes < 0 || (size_t)bytes != n * sizeof(int16_t)) {
        board_io_print("chin.q15 must hold as many samples as d.f64\n");
        return 1;
    }
    anc_control_init(&ctl);
    for (k = 0; k < n; ++k) {
        size_t h = (k / ANC_CONTROL_BLOCK) & 1u, slot = k % ANC_CONTROL_BLOCK;
        int16_t played = ctl.drive[h][slot];
        double v = (double)played / 32768.0, e;
        if (delay > 0) {
            double oldest = line[pos];
            line[pos] = v;
            pos = (pos + 1 == delay) ? 0 : pos + 1;
            v = oldest;
        }
        e = 0.0;
        for (i = 0; i < order; ++i) {
            e = e + C[i] * state[i];
        }
        e = d_in[k] + (e + D * v);
        for (i = 0; i < order; ++i) {
            double t = B[i] * v;
            for (j = 0; j < order; ++j) {
                t = t + A[i * order + j] * state[j];
            }
            next_state[i] = t;
        }
        for (i = 0; i < order; ++i) {
            state[i] = next_state[i];
        }
        ctl.ear[h][slot] = adc(e);
        ctl.chin[h][slot] = chin_in[k];
        ear_out[k] = ctl.ear[h][slot];
        drive_out[k] = played;
        if (slot + 1 == ANC_CONTROL_BLOCK) {
            anc_control_dma_done(&ctl, (unsigned)h);
        }
    }
    status[0] = ctl.muted;
    status[1] = ctl.trips;
    status[2] = ctl.muted_at;
    status[3] = ctl.frames;
    status[4] = ctl.model_saturations;
    if (board_io_write("ear.q15", ear_out, n * sizeof ear_out[0]) != 0
        || board_io_write("drive.q15", drive_out, n * sizeof drive_out[0]) != 0
        || board_io_write("status.u32", status, sizeof status) != 0) {
        return 2;
    }
    return 0;
}

int main(void)
{
    int status = run();
    board_io_print(status == 0 ? "closed loop done\n" : "closed loop failed\n");
    return status;
}
