/*
 * tdc_kernels.h -- the fixed-point kernel library of mems-tdc's generated compensators.
 *
 * Hand-written C99, shipped with codegen and copied next to every generated module (NAME.c
 * includes it); the modules render only their data (weights, tables, scales, sizes) and thin glue.
 * Every function is `static inline`: each module gets its own copy, nothing is exported, and
 * modules of different NAMEs link together. No malloc, libm, stdio or floating point; no undefined
 * or implementation-defined behaviour: right shifts act only on unsigned values, a negative value
 * reaches unsigned arithmetic only through a conversion (modular, defined), and every signed
 * operation stays inside a bound proved at generation time (codegen/quantize.py) or stated below
 * as the caller's precondition. Tested directly (tests/test_codegen_kernels.py: cffi and hypothesis
 * against the numpy golden functions, ASan/UBSan, gcc and clang, Cortex-M4 under QEMU).
 *
 * Two rounding rules: tdck_rshift_round64 and tdck_rdiv_round64 round half away from zero (the
 * memoryless models, the input normalisation); the network rounds half up, floor(x / 2^s + 1/2),
 * computed on the value offset by 2^63 (or 2^31), which costs a Cortex-M4 a few instructions.
 *
 * Cortex-M4 (and any core with __ARM_FEATURE_DSP): tdck_dot4 uses SMLAD, two 16 x 16 products
 * and a 32-bit accumulate per instruction. Define TDCK_PORTABLE to build the portable path there
 * too; both give identical results (the sums never leave int32, proved at generation time).
 */
#ifndef TDC_KERNELS_H_INCLUDED
#define TDC_KERNELS_H_INCLUDED

#include <stddef.h>
#include <stdint.h>

#if defined(__ARM_FEATURE_DSP) && !defined(__ARM_BIG_ENDIAN) && !defined(TDCK_PORTABLE)
#include <arm_acle.h>
#define TDCK_DSP 1
#else
#define TDCK_DSP 0
#endif

#define TDCK_VERSION 1

/* The layer kernel is inlined into each call so that its shifts and sizes become immediates (gcc
 * would otherwise share one copy with variable shifts: 25 % slower on a Cortex-M4). */
#if defined(__GNUC__)
#define TDCK_INLINE static inline __attribute__((always_inline))
#else
#define TDCK_INLINE static inline
#endif

/* BEGIN Q FORMATS: written by `python -m codegen.qformats --write` from codegen/qformats.py */
#define TDCK_X_FRAC         12 /* network inputs x: int16 Q3.12 (normalised, clamped to +-8, flagged) ... */
#define TDCK_X_MIN_FRAC     10 /* ... or wider, down to Q5.10 (+-32), when layer 0 loses no accumulator bit */
#define TDCK_H_FRAC         15 /* hidden states h: int16 Q15, |h| <= 32767 */
#define TDCK_GATE_FRAC      16 /* sigmoid gates i, f, o: Q16 in 1 .. 65535 (a forget gate stays below 1) */
#define TDCK_TANH_FRAC      15 /* tanh of the g gate and of the cell: Q15 in -32767 .. 32767 */
#define TDCK_C_FRAC         24 /* cell states c: int32 Q7.24 (saturated at the int32 limits, flagged) */
#define TDCK_EST_FRAC       16 /* held estimate: Q16 of the output LSB (1/16 ug) */
#define TDCK_MIN_ACC_FRAC   17 /* gate accumulators: int32 Q(A) with A >= 17 (the table's step and position bits) */
#define TDCK_MAX_ACC_FRAC   30 /* largest A the quantiser tries */
#define TDCK_ACT_RANGE      8 /* the activation table covers tanh inputs -8 .. 8 (sigmoid: -16 .. 16) */
#define TDCK_ACT_STEP_BITS  5 /* table step 2^-5 of the tanh input: 512 segments */
#define TDCK_ACT_SEGMENTS   512 /* segments of the activation table (2 ACT_RANGE 2^ACT_STEP_BITS) */
#define TDCK_ACT_POS_BITS   12 /* position inside a segment: 12 bits */
#define TDCK_ACT_SLOPE_BITS 16 /* slopes carry 16 bits below the Q15 output: out = v + (s pos + 2^15) >> 16 */
#define TDCK_ACT_VALUE_FRAC 15 /* table values: tanh(x) + 1 in Q15 (= sigmoid(2x) in Q16), 1 .. 65535 */
/* END Q FORMATS */

/* ---- saturation and rounding (generic: any model may use them) ------------------------------ */

/* Clamp to int32. */
static inline int32_t tdck_sat32(int64_t x)
{
    if (x > (int64_t)INT32_MAX) {
        return INT32_MAX;
    }
    if (x < (int64_t)INT32_MIN) {
        return INT32_MIN;
    }
    return (int32_t)x;
}

/* Clamp to int32; a clamp sets `bit` in *flags. */
static inline int32_t tdck_sat32_flag(int64_t x, uint32_t *flags, uint32_t bit)
{
    int32_t y = tdck_sat32(x);
    if ((int64_t)y != x) {
        *flags |= bit;
    }
    return y;
}

/* Clamp v to [lo, hi]; a clamp sets `bit` in *flags. */
static inline int32_t tdck_clamp32_flag(int32_t v, int32_t lo, int32_t hi, uint32_t *flags, uint32_t bit)
{
    if (v < lo) {
        *flags |= bit;
        return lo;
    }
    if (v > hi) {
        *flags |= bit;
        return hi;
    }
    return v;
}

/* x / 2^s rounded half away from zero (0 <= s <= 62), on the unsigned magnitude. */
static inline int64_t tdck_rshift_round64(int64_t x, unsigned s)
{
    uint64_t mag;
    if (s == 0u) {
        return x;
    }
    mag = (x < 0) ? (0u - (uint64_t)x) : (uint64_t)x;
    mag = (mag + ((uint64_t)1 << (s - 1u))) >> s;
    return (x < 0) ? -(int64_t)mag : (int64_t)mag;
}

/* num / den (den > 0) rounded half away from zero. */
static inline int64_t tdck_rdiv_round64(int64_t num, uint32_t den)
{
    uint64_t mag = (num < 0) ? (0u - (uint64_t)num) : (uint64_t)num;
    mag = (mag + (uint64_t)(den / 2u)) / (uint64_t)den;
    return (num < 0) ? -(int64_t)mag : (int64_t)mag;
}

/* floor(x / 2^s + 1/2) for |x| < 2^62, 1 <= s <= 62: the value offset by 2^63 is shifted unsigned. */
static inline int64_t tdck_round_shift64(int64_t x, unsigned s)
{
    uint64_t u = (uint64_t)x + ((uint64_t)1 << 63) + ((uint64_t)1 << (s - 1u));
    return (int64_t)(u >> s) - ((int64_t)1 << (63u - s));
}

/* floor(x / 2^s + 1/2) for x <= INT32_MAX - 2^(s-1), 1 <= s <= 31. */
static inline int32_t tdck_round_shift32(int32_t x, unsigned s)
{
    uint32_t u = (uint32_t)x + 0x80000000u + (1u << (s - 1u));
    return (int32_t)(u >> s) - (int32_t)(0x80000000u >> s);
}

/* ---- activations: one table of tanh(x) + 1, linear interpolation ----------------------------
 * value[k], slope[k]: segment k covers x in [-ACT_RANGE + k 2^-ACT_STEP_BITS, + 2^-ACT_STEP_BITS);
 * inside it T = value[k] + (slope[k] pos + 2^15) >> 16 with pos the ACT_POS_BITS bits below the
 * segment index, all computed offline (codegen/activations.py). The first and last segments are
 * flat (slope 0), so an input beyond the table needs no special case: its segment index is
 * clamped and its position does not matter. T is tanh(x) + 1 in Q15 in 1 .. 65535; the same number
 * is sigmoid(2x) in Q16, so sigmoid(z) reads the table at z / 2 (one more shift bit). */

/* T of acc / 2^(shift + ACT_STEP_BITS), ACT_POS_BITS <= shift <= 30. */
static inline int32_t tdck_act(const uint16_t *value, const uint16_t *slope, int32_t acc, unsigned shift)
{
    uint32_t u = (uint32_t)acc + 0x80000000u; /* excess 2^31: monotone in acc, no wrap */
    int32_t k = (int32_t)(u >> shift) - ((int32_t)(0x80000000u >> shift) - TDCK_ACT_SEGMENTS / 2);
    uint32_t pos = (u >> (shift - TDCK_ACT_POS_BITS)) & ((1u << TDCK_ACT_POS_BITS) - 1u);
    if (k < 0) {
        k = 0;
    } else if (k > TDCK_ACT_SEGMENTS - 1) {
        k = TDCK_ACT_SEGMENTS - 1;
    }
    return (int32_t)value[k]
        + (int32_t)(((uint32_t)slope[k] * pos + (1u << (TDCK_ACT_SLOPE_BITS - 1))) >> TDCK_ACT_SLOPE_BITS);
}

/* sigmoid in Q16 (1 .. 65535) of acc / 2^(shift + ACT_STEP_BITS). */
static inline int32_t tdck_sigmoid_q16(const uint16_t *value, const uint16_t *slope, int32_t acc, unsigned shift)
{
    return tdck_act(value, slope, acc, shift + 1u);
}

/* tanh in Q15 (-32767 .. 32767) of acc / 2^(shift + ACT_STEP_BITS). */
static inline int32_t tdck_tanh_q15(const uint16_t *value, const uint16_t *slope, int32_t acc, unsigned shift)
{
    return tdck_act(value, slope, acc, shift) - (1 << TDCK_ACT_VALUE_FRAC);
}

/* ---- the LSTM ------------------------------------------------------------------------------- */

/* The int16 weight pair packed in one word: bits 0-15 the first weight, 16-31 the second
 * (word = second 2^16 + (first mod 2^16), as the generator writes it). Unpacked with well-defined
 * arithmetic only (the portable path); SMLAD reads the word as it is. */
static inline int32_t tdck_pair_lo(int32_t word)
{
    return (int32_t)(((uint32_t)word & 0xFFFFu) ^ 0x8000u) - 0x8000;
}

static inline int32_t tdck_pair_hi(int32_t word)
{
    return (word - (int32_t)((uint32_t)word & 0xFFFFu)) / 65536;
}

/* acc + w . x for one packed weight pair and the vector pair x0 (first), x1 (second). */
static inline int32_t tdck_mac2(int32_t acc, int32_t word, int32_t x0, int32_t x1)
{
    return acc + tdck_pair_lo(word) * x0 + tdck_pair_hi(word) * x1;
}

/* Four gate rows against one int16 vector, int32 accumulators started at bias[0..3]:
 * acc[r] = bias[r] + sum_p lo(w[4p + r]) v[2p] + hi(w[4p + r]) v[2p + 1]. The rows' packed weight
 * pairs are interleaved (4 words per pair of inputs), so the DSP path loads the four words of a
 * pair at once and SMLAD takes each as it is. Precondition (proved by the quantiser for every
 * row): |bias| + sum |w| |v| < 2^31, so no partial sum leaves int32 and both paths give the same
 * numbers. */
static inline void tdck_dot4(const int32_t *w, const int16_t *v, uint32_t pairs, const int32_t *bias, int32_t *acc)
{
    int32_t a0 = bias[0];
    int32_t a1 = bias[1];
    int32_t a2 = bias[2];
    int32_t a3 = bias[3];
    uint32_t p = 0u;
#if TDCK_DSP
    for (; p < pairs; ++p) {
        int32_t x;
        __builtin_memcpy(&x, v + 2u * p, sizeof x);
        a0 = __smlad(w[0], x, a0);
        a1 = __smlad(w[1], x, a1);
        a2 = __smlad(w[2], x, a2);
        a3 = __smlad(w[3], x, a3);
        w += 4;
    }
#else
    for (; p < pairs; ++p) {
        int32_t x0 = v[2u * p];
        int32_t x1 = v[2u * p + 1u];
        a0 = tdck_mac2(a0, w[0], x0, x1);
        a1 = tdck_mac2(a1, w[1], x0, x1);
        a2 = tdck_mac2(a2, w[2], x0, x1);
        a3 = tdck_mac2(a3, w[3], x0, x1);
        w += 4;
    }
#endif
    acc[0] = a0;
    acc[1] = a1;
    acc[2] = a2;
    acc[3] = a3;
}

/* One cell from its gates (i, f, o sigmoid Q16; g tanh Q15): c' = f c + i g, rounded half up to
 * Q24 from Q40 (below 2^48) and saturated to int32 (sets `sat_bit`); returns h = o tanh(c') in Q15
 * (|h| <= 32767: o <= 65535, |tanh| <= 32767). */
static inline int16_t tdck_lstm_cell(int32_t gi, int32_t gf, int32_t gg, int32_t go, int32_t *c,
    const uint16_t *value, const uint16_t *slope, uint32_t *flags, uint32_t sat_bit)
{
    int64_t wide = (int64_t)gf * (int64_t)*c
        + (int64_t)(gi * gg) * ((int64_t)1 << (TDCK_C_FRAC + TDCK_GATE_FRAC - TDCK_GATE_FRAC - TDCK_TANH_FRAC));
    int32_t cell = tdck_sat32_flag(tdck_round_shift64(wide, TDCK_GATE_FRAC), flags, sat_bit);
    int32_t th = tdck_tanh_q15(value, slope, cell, TDCK_C_FRAC - TDCK_ACT_STEP_BITS);
    *c = cell;
    return (int16_t)tdck_round_shift32(go * th, TDCK_GATE_FRAC);
}

/* One LSTM layer of `hidden` units: unit j's four gate rows (i, f, g, o) are tdck_dot4 of block j of
 * w (4 packed words per input pair) and bias[4j..4j+3] against v (2 pairs int16, the layer's input
 * then its own h). The gate accumulators are Q(shift + ACT_STEP_BITS). New h go to h_new (not v:
 * the later units still read the old h); cell states are updated in place. */
TDCK_INLINE void tdck_lstm_layer(const int32_t *w, const int32_t *bias, const int16_t *v, uint32_t pairs,
    uint32_t hidden, unsigned shift, int32_t *c, int16_t *h_new, const uint16_t *value, const uint16_t *slope,
    uint32_t *flags, uint32_t sat_bit)
{
    uint32_t j;
    for (j = 0u; j < hidden; ++j) {
        int32_t acc[4];
        tdck_dot4(w + 4u * pairs * j, v, pairs, bias + 4u * j, acc);
        h_new[j] = tdck_lstm_cell(tdck_sigmoid_q16(value, slope, acc[0], shift),
            tdck_sigmoid_q16(value, slope, acc[1], shift), tdck_tanh_q15(value, slope, acc[2], shift),
            tdck_sigmoid_q16(value, slope, acc[3], shift), &c[j], value, slope, flags, sat_bit);
    }
}

/* acc + sum_j w[j] h[j], int32 x int16 into int64 (the head: few MACs, full precision). */
static inline int64_t tdck_dot_wide(const int32_t *w, const int16_t *h, uint32_t n, int64_t acc)
{
    uint32_t j;
    for (j = 0u; j < n; ++j) {
        acc += (int64_t)w[j] * (int64_t)h[j];
    }
    return acc;
}

/* A network input as int16 (Q12 or Q10, the scale is in inv): clamp(rshift_round(clamp(
 * rshift_round(centred, pre), +-d_max) inv, shift), +-32767); the outer clamp sets `sat_bit`. |d| >= d_max saturates anyway; clamping it first
 * keeps the product in int64 (d_max inv < 2^62, proved by the quantiser). */
static inline int16_t tdck_input_x(int64_t centred, unsigned pre, int64_t d_max, int64_t inv, unsigned shift,
    uint32_t *flags, uint32_t sat_bit)
{
    int64_t d = tdck_rshift_round64(centred, pre);
    int64_t x;
    d = d > d_max ? d_max : (d < -d_max ? -d_max : d);
    x = tdck_rshift_round64(d * inv, shift);
    if (x > 32767) {
        *flags |= sat_bit;
        return 32767;
    }
    if (x < -32767) {
        *flags |= sat_bit;
        return -32767;
    }
    return (int16_t)x;
}

/* ---- front end: window sums without a ring of samples --------------------------------------
 * The window of W samples that ends at a network step starts at a fixed phase of the decimation
 * period, chunk_start = (1 - W) mod D. A running sum restarts there; with W > D the completed
 * chunk sums (D samples each, W div D of them, the first after a reset possibly shorter) are kept
 * in a ring. At the step the window sum is the running sum plus the ring: exact, W / D sums of
 * state instead of W samples. */
static inline void tdck_window_add(int64_t *current, int64_t *ring, uint32_t chunks, uint32_t *ring_pos,
    uint32_t phase, uint32_t chunk_start, int32_t v)
{
    if (phase == chunk_start) {
        if (chunks != 0u) {
            ring[*ring_pos] = *current;
            *ring_pos = (*ring_pos + 1u == chunks) ? 0u : *ring_pos + 1u;
        }
        *current = v;
    } else {
        *current += v;
    }
}

static inline int64_t tdck_window_sum(int64_t current, const int64_t *ring, uint32_t chunks)
{
    uint32_t k;
    for (k = 0u; k < chunks; ++k) {
        current += ring[k];
    }
    return current;
}

/* ---- output: held estimate with first-order error feedback ---------------------------------- */

/* Split a Q16 estimate into floor (whole) and fraction: estimate = whole + frac / 2^16.
 * |estimate| < 2^47 (the quantiser saturates it at +-(2^31 - 1) LSB). */
static inline void tdck_hold(int64_t estimate_q16, int32_t *whole, uint32_t *frac)
{
    int64_t w = (estimate_q16 < 0) ? -(int64_t)((((uint64_t)0 - (uint64_t)estimate_q16) + 0xFFFFu) >> 16)
                                   : (int64_t)((uint64_t)estimate_q16 >> 16);
    *whole = (int32_t)w;
    *frac = (uint32_t)(estimate_q16 - w * 65536);
}

/* The held fraction accumulates in *shaper; returns the carry (0 or 1) it produces. */
static inline uint32_t tdck_shape(uint32_t *shaper, uint32_t frac)
{
    uint32_t carry;
    *shaper += frac;
    carry = *shaper >> 16;
    *shaper &= 0xFFFFu;
    return carry;
}

/* Common tail of a step: count the sample (saturating), output = raw - drift saturated to int32. */
static inline int32_t tdck_output(uint32_t *samples, uint32_t *flags, uint32_t sat_bit, int32_t accel, int64_t drift)
{
    if (*samples != UINT32_MAX) {
        *samples += 1u;
    }
    return tdck_sat32_flag((int64_t)accel - drift, flags, sat_bit);
}

#endif /* TDC_KERNELS_H_INCLUDED */
