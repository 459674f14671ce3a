/*
 * kernel_app.c -- runs the kernels of codegen/kernels/tdc_kernels.h on recorded inputs, on the host
 * (tests/test_codegen_kernels.py: strict warnings, ASan + UBSan) and on the Cortex-M4 under QEMU
 * (firmware_c/Makefile `kernel-app`, semihosting files). Not part of any flight module.
 *
 * Usage: kernel_app INPUTS OUTPUTS
 * INPUTS: little-endian int64 records of KERNEL_IN values: kernel id, then its arguments;
 * OUTPUTS: one record of KERNEL_OUT int64 values per input record (unused values 0). The knots of
 * tdck_act are set by the records with id 0 (arguments: index, knot).
 */
#include <stdio.h>
#include <string.h>

#include "tdc_kernels.h"


#define KERNEL_IN 11
#define KERNEL_OUT 5

enum kernel {
    K_TABLE = 0,
    K_ACT = 1,
    K_ROUND_SHIFT64 = 2,
    K_ROUND_SHIFT32 = 3,
    K_RSHIFT_ROUND64 = 4,
    K_RDIV_ROUND64 = 5,
    K_DOT4 = 6,
    K_CELL = 7,
    K_INPUT = 8,
    K_HOLD = 9,
    K_SAT = 10,
    K_CLAMP = 11,
    K_SHAPE = 12,
    K_WINDOW = 13,
    K_DOT_WIDE = 14,
    K_GATES = 15
};

static uint16_t act_knot[TDCK_ACT_KNOTS];

/* window stream state (K_WINDOW: in = chunks, chunk_start, phase, v, reset; out = current, sum, pos) */
static int64_t window_current;
static int64_t window_ring[8];
static uint32_t window_pos;

/* The dot product DOT (TDCK_DOT4_N or TDCK_DOT4_ADD_N) with the literal pair count `pairs` (1 .. 9). */
#define DOT4_LITERAL_SWITCH(DOT)                                                                          \
    switch (pairs) {                                                                                      \
    case 1u: DOT(wp, v, 1u, acc); break;                                                                  \
    case 2u: DOT(wp, v, 2u, acc); break;                                                                  \
    case 3u: DOT(wp, v, 3u, acc); break;                                                                  \
    case 4u: DOT(wp, v, 4u, acc); break;                                                                  \
    case 5u: DOT(wp, v, 5u, acc); break;                                                                  \
    case 6u: DOT(wp, v, 6u, acc); break;                                                                  \
    case 7u: DOT(wp, v, 7u, acc); break;                                                                  \
    case 8u: DOT(wp, v, 8u, acc); break;                                                                  \
    default: DOT(wp, v, 9u, acc); break;                                                                  \
    }

/* TDCK_DOT4_N with a literal pair count: the layers' unrolled path. Functions of their own, so that
 * the twelve-register assembly blocks do not compete with run's live values (and one function with
 * both macros' eighteen blocks puts Thumb branches out of range). */
#if defined(__GNUC__)
__attribute__((noinline))
#endif
static void dot4_literal(const int32_t **wp, const int16_t *v, uint32_t pairs, uint32_t *acc)
{
    DOT4_LITERAL_SWITCH(TDCK_DOT4_N)
}

/* TDCK_DOT4_ADD_N with a literal pair count: the spread schedule's dot-product tasks. */
#if defined(__GNUC__)
__attribute__((noinline))
#endif
static void dot4_add_literal(const int32_t **wp, const int16_t *v, uint32_t pairs, uint32_t *acc)
{
    DOT4_LITERAL_SWITCH(TDCK_DOT4_ADD_N)
}

/* TDCK_DOT_WIDE_N with the literal count n (1 .. 10): the head's unrolled path. */
#if defined(__GNUC__)
__attribute__((noinline))
#endif
static int64_t dot_wide_literal(const int32_t *w, const int16_t *h, uint32_t n, int64_t acc)
{
    switch (n) {
    case 1u: TDCK_DOT_WIDE_N(w, h, 1u, acc); break;
    case 2u: TDCK_DOT_WIDE_N(w, h, 2u, acc); break;
    case 3u: TDCK_DOT_WIDE_N(w, h, 3u, acc); break;
    case 4u: TDCK_DOT_WIDE_N(w, h, 4u, acc); break;
    case 5u: TDCK_DOT_WIDE_N(w, h, 5u, acc); break;
    case 6u: TDCK_DOT_WIDE_N(w, h, 6u, acc); break;
    case 7u: TDCK_DOT_WIDE_N(w, h, 7u, acc); break;
    case 8u: TDCK_DOT_WIDE_N(w, h, 8u, acc); break;
    case 9u: TDCK_DOT_WIDE_N(w, h, 9u, acc); break;
    default: TDCK_DOT_WIDE_N(w, h, 10u, acc); break;
    }
    return acc;
}

static void run(const int64_t *in, int64_t *out)
{
    uint32_t flags = 0u;
    memset(out, 0, KERNEL_OUT * sizeof out[0]);
    switch ((int)in[0]) {
    case K_TABLE:
        act_knot[in[1]] = (uint16_t)in[2];
        break;
    case K_ACT:
        out[0] = tdck_act(act_knot, (int32_t)in[1], (unsigned)in[2]);
        out[1] = tdck_sigmoid_q16(act_knot, (int32_t)in[1], (unsigned)in[2]);
        out[2] = tdck_tanh_q15(act_knot, (int32_t)in[1], (unsigned)in[2]);
        /* the excess-2^31 form the network uses, with the unclamped gate path where it applies */
        out[3] = tdck_act_x(act_knot, (uint32_t)in[1] + 0x80000000u, (unsigned)in[2]);
        break;
    case K_ROUND_SHIFT64:
        out[0] = tdck_round_shift64(in[1], (unsigned)in[2]);
        break;
    case K_ROUND_SHIFT32:
        out[0] = tdck_round_shift32((int32_t)in[1], (unsigned)in[2]);
        break;
    case K_RSHIFT_ROUND64:
        out[0] = tdck_rshift_round64(in[1], (unsigned)in[2]);
        break;
    case K_RDIV_ROUND64:
        out[0] = tdck_rdiv_round64(in[1], (uint32_t)in[2]);
        break;
    case K_DOT4: {
        /* in = w0..w3 (the packed words of pair 0), v0, v1, b0, b1, pairs (1 .. 9); the block is the
         * biases b0, b1, -b0, -b1 (sign bit flipped), then pair p's words: pair 0's, then the reverse
         * order for odd p, as they are for even p; the vector pairs alternate (v0, v1), (v1, v0) */
        int32_t w[4 + 4 * 9];
        union {
            int32_t align; /* TDCK_DOT4_N's LDRD needs the vector 4-byte aligned */
            int16_t v[2 * 9];
        } vec;
        int16_t *v = vec.v;
        const int32_t *wp = w;
        const int32_t *wn = w;
        uint32_t acc[4];
        uint32_t acc_n[4];
        uint32_t pairs = (uint32_t)in[9];
        uint32_t split = (uint32_t)in[10]; /* 0: whole only; else 1 .. pairs - 1 */
        uint32_t p;
        int k;
        int64_t bias[4];
        bias[0] = in[7];
        bias[1] = in[8];
        bias[2] = -in[7];
        bias[3] = -in[8];
        for (k = 0; k < 4; ++k) {
            /* bias + 2^31 mod 2^32, as int32 (the values are in int32 range, so this is exact) */
            w[k] = (int32_t)(bias[k] >= 0 ? bias[k] - 2147483647 - 1 : bias[k] + 2147483647 + 1);
        }
        for (p = 0u; p < pairs; ++p) {
            for (k = 0; k < 4; ++k) {
                w[4 + 4 * (int)p + k] = (int32_t)in[1 + ((p % 2u) != 0u ? 3 - k : k)];
            }
            v[2u * p] = (int16_t)in[(p % 2u) != 0u ? 6 : 5];
            v[2u * p + 1u] = (int16_t)in[(p % 2u) != 0u ? 5 : 6];
        }
        tdck_dot4(&wp, v, pairs, acc);
        /* the same product with a literal pair count (the layers' unrolled path) */
        dot4_literal(&wn, v, pairs, acc_n);
        for (k = 0; k < 4; ++k) {
            out[k] = (int64_t)acc[k] - 2147483648;
        }
        out[4] = wp - w; /* words consumed */
        if (wn != wp || acc_n[0] != acc[0] || acc_n[1] != acc[1] || acc_n[2] != acc[2] || acc_n[3] != acc[3]) {
            out[4] = -1; /* the two paths disagree: never the expected count */
        }
        if (split > 0u) {
            /* the product split after `split` pairs (the spread schedule's two tasks), both ways */
            const int32_t *ws = w;
            const int32_t *wl = w;
            uint32_t acc_s[4];
            uint32_t acc_l[4];
            tdck_dot4(&ws, v, split, acc_s);
            tdck_dot4_add(&ws, v + 2u * split, pairs - split, acc_s);
            tdck_dot4_bias(&wl, acc_l); /* as the spread schedule's first task: biases, then the pairs */
            dot4_add_literal(&wl, v, split, acc_l);
            dot4_add_literal(&wl, v + 2u * split, pairs - split, acc_l);
            for (k = 0; k < 4; ++k) {
                if (acc_s[k] != acc[k] || acc_l[k] != acc[k]) {
                    out[4] = -1;
                }
            }
            if (ws != wp || wl != wp) {
                out[4] = -1;
            }
        }
        break;
    }
    case K_CELL: {
        int32_t c = (int32_t)in[5];
        out[0] = tdck_lstm_cell((int32_t)in[1], (int32_t)in[2], (int32_t)in[3], (int32_t)in[4], &c, act_knot, &flags,
            4u);
        out[1] = c;
        out[2] = flags;
        break;
    }
    case K_INPUT:
        out[0] = tdck_input_x(in[1], (unsigned)in[2], in[3], in[4], (unsigned)in[5], &flags, 4u);
        out[1] = flags;
        break;
    case K_HOLD: {
        int32_t whole;
        uint32_t frac;
        tdck_hold(in[1], &whole, &frac);
        out[0] = whole;
        out[1] = frac;
        break;
    }
    case K_SAT:
        out[0] = tdck_sat32_flag(in[1], &flags, 4u);
        out[1] = flags;
        break;
    case K_CLAMP:
        out[0] = tdck_clamp32_flag((int32_t)in[1], (int32_t)in[2], (int32_t)in[3], &flags, 2u);
        out[1] = flags;
        break;
    case K_SHAPE: {
        uint32_t shaper = (uint32_t)in[1];
        out[0] = tdck_shape(&shaper, (uint32_t)in[2]);
        out[1] = shaper;
        break;
    }
    case K_WINDOW:
        if (in[5] != 0) {
            memset(window_ring, 0, sizeof window_ring);
            window_current = 0;
            window_pos = 0u;
        }
        tdck_window_add(&window_current, window_ring, (uint32_t)in[1], &window_pos, (uint32_t)in[3],
            (uint32_t)in[2], (int32_t)in[4]);
        out[0] = window_current;
        out[1] = tdck_window_sum(window_current, window_ring, (uint32_t)in[1]);
        out[2] = window_pos;
        break;
    case K_DOT_WIDE: {
        /* in = w0..w3 (int32, repeated), h0, h1 (alternating), acc, n (1 .. 10) */
        int32_t w[10];
        int16_t h[10];
        uint32_t n = (uint32_t)in[8];
        uint32_t j;
        for (j = 0u; j < n; ++j) {
            w[j] = (int32_t)in[1u + j % 4u];
            h[j] = (int16_t)in[5u + j % 2u];
        }
        out[0] = tdck_dot_wide(w, h, n, in[7]);
        out[1] = dot_wide_literal(w, h, n, in[7]) != out[0]; /* 1: the two paths disagree */
        break;
    }
    case K_GATES: {
        /* in = the four sums (int32), shift, 1: with the sigmoid base `sig` (shift >= 22) */
        unsigned shift = (unsigned)in[5];
        const uint16_t *sig = in[6] != 0 ? &act_knot[256 - (1 << (30u - shift))] : NULL;
        uint32_t acc[4];
        uint32_t gate[4];
        int k;
        for (k = 0; k < 4; ++k) {
            acc[k] = (uint32_t)in[1 + k] + 0x80000000u; /* excess-2^31 form */
        }
        tdck_lstm_gates(acc, shift, act_knot, sig, gate);
        tdck_lstm_gates(acc, shift, act_knot, sig, acc); /* in place, as the spread schedule calls it */
        for (k = 0; k < 4; ++k) {
            out[k] = gate[k];
            if (acc[k] != gate[k]) {
                out[4] = -1;
            }
        }
        break;
    }
    default:
        out[0] = -1;
        break;
    }
}

#define HARNESS_NAME "kernel_app"
#define HARNESS_DSP TDCK_DSP
#include "record_main.h"
