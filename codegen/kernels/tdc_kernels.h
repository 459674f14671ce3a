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

#define TDCK_VERSION 3 /* 2: knot table, excess-2^31 accumulators, biases in the weight stream;
                          3: tdck_dot4_bias, tdck_dot4_add, tdck_lstm_gates, tdck_lstm_cell_gates (the
                          spread schedule's tasks); tdck_rdiv_round64 takes divisors below 2^16 */

/* The layer kernel is inlined into each call so that its shifts become immediates (gcc would
 * otherwise share one copy with variable shifts: 25 % slower on a Cortex-M4); a generated module
 * wraps it in one non-inlined function per distinct shift, shared by the layers (flash). */
#if defined(__GNUC__)
#define TDCK_INLINE static inline __attribute__((always_inline))
#define TDCK_UNLIKELY(x) __builtin_expect(!!(x), 0)
#define TDCK_NOINLINE __attribute__((noinline))
#else
#define TDCK_NOINLINE
#define TDCK_INLINE static inline
#define TDCK_UNLIKELY(x) (x)
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
#define TDCK_ACT_KNOTS      513 /* knots v (uint16) at the segment ends: out = v[k] + ((v[k+1] - v[k]) pos + 2^11) >> 12 */
#define TDCK_ACT_VALUE_FRAC 15 /* knot values: tanh(x) + 1 in Q15 (= sigmoid(2x) in Q16), 1 .. 65535 */
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

/* num / den rounded half away from zero, 0 < den < 2^16 (a window's sample count; the quantiser
 * refuses longer windows). The magnitude is divided as one 32-bit digit and two 16-bit digits, each
 * remainder below den, so every division is 32-bit (one UDIV on a Cortex-M4): exact, and no 64-bit
 * division routine (__aeabi_uldivmod, a few hundred instructions) in the module. */
static inline int64_t tdck_rdiv_round64(int64_t num, uint32_t den)
{
    uint64_t mag = ((num < 0) ? (0u - (uint64_t)num) : (uint64_t)num) + (uint64_t)(den / 2u);
    uint32_t hi = (uint32_t)(mag >> 32);
    uint32_t lo = (uint32_t)mag;
    uint32_t q2 = hi / den;
    uint32_t cur = ((hi - q2 * den) << 16) | (lo >> 16); /* remainder < den < 2^16 */
    uint32_t q1 = cur / den;                              /* < 2^16 */
    uint32_t q0;
    cur = ((cur - q1 * den) << 16) | (lo & 0xFFFFu);
    q0 = cur / den;
    mag = ((uint64_t)q2 << 32) | ((uint64_t)q1 << 16) | (uint64_t)q0;
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
 * knot[k] (k = 0 .. ACT_SEGMENTS) is T at x = -ACT_RANGE + k 2^-ACT_STEP_BITS, moved offline by
 * half the chord's mean deviation (codegen/activations.py); inside segment k,
 * T = knot[k] + ((knot[k+1] - knot[k]) pos + 2^11) >> 12 with pos the ACT_POS_BITS bits below the
 * segment index: a continuous line through the knots, 2 bytes of flash per segment. The knots
 * rise monotonically (the difference is unsigned, at most 1024) and the first and last segments
 * are flat, so an input beyond the table needs no special case: its segment index is clamped and
 * its position does not matter. T is tanh(x) + 1 in Q15 in 1 .. 65535; the same number is
 * sigmoid(2x) in Q16, so sigmoid(z) reads the table at z / 2 (one more shift bit). The _x variants
 * take the accumulator in excess-2^31 form, u = acc + 2^31 (mod 2^32), which the network's dot
 * products produce directly (the excess is folded into the biases): monotone in acc, so one
 * unsigned shift gives the segment. */

#if (1 << 9) != TDCK_ACT_SEGMENTS || TDCK_ACT_KNOTS != TDCK_ACT_SEGMENTS + 1
#error "tdc_kernels.h: the clamp to the table (USAT #9) assumes 512 segments"
#endif

/* T from segment k (0 .. 511) and position pos (ACT_POS_BITS bits). */
static inline int32_t tdck_act_lerp(const uint16_t *knot, int32_t k, uint32_t pos)
{
#if TDCK_DSP
    uint32_t e; /* both knots with one (unaligned) load, little-endian: knot[k] in bits 0-15 */
    int32_t v0;
    __builtin_memcpy(&e, knot + k, sizeof e);
    v0 = (int32_t)(e & 0xFFFFu);
    /* difference (< 2^15) times pos (< 2^12) plus the rounding half: one SMLABB */
    return v0 + (int32_t)((uint32_t)__smlabb((int32_t)(e >> 16) - v0, (int32_t)pos, 1 << (TDCK_ACT_POS_BITS - 1)) >> TDCK_ACT_POS_BITS);
#else
    uint32_t v0 = knot[k];
    return (int32_t)(v0 + ((((uint32_t)knot[k + 1] - v0) * pos + (1u << (TDCK_ACT_POS_BITS - 1))) >> TDCK_ACT_POS_BITS));
#endif
}

/* T of (u - 2^31) / 2^(shift + ACT_STEP_BITS), ACT_POS_BITS <= shift <= 30. When the table covers
 * every u (shift >= 23: all gates of a layer with A >= 28, the sigmoid gates with A = 27), the
 * segment is u >> shift counted from a fixed knot (2^(31 - shift) <= 256 below the middle, no
 * clamp); else it is clamped. */
static inline int32_t tdck_act_x(const uint16_t *table, uint32_t u, unsigned shift)
{
    uint32_t pos = (u >> (shift - TDCK_ACT_POS_BITS)) & ((1u << TDCK_ACT_POS_BITS) - 1u);
    if (shift >= 23u) {
        return tdck_act_lerp(table + (TDCK_ACT_SEGMENTS / 2 - (int32_t)(0x80000000u >> shift)), (int32_t)(u >> shift), pos);
    } else {
        int32_t k = (int32_t)(u >> shift) - ((int32_t)(0x80000000u >> shift) - TDCK_ACT_SEGMENTS / 2);
        if (k < 0) {
            k = 0;
        } else if (k > TDCK_ACT_SEGMENTS - 1) {
            k = TDCK_ACT_SEGMENTS - 1;
        }
        return tdck_act_lerp(table, k, pos);
    }
}

/* tdck_act_x for inputs that do reach beyond the table (the cell state): the clamp is one USAT. */
static inline int32_t tdck_act_x_clamped(const uint16_t *table, uint32_t u, unsigned shift)
{
    int32_t k = (int32_t)(u >> shift) - ((int32_t)(0x80000000u >> shift) - TDCK_ACT_SEGMENTS / 2);
    uint32_t pos = (u >> (shift - TDCK_ACT_POS_BITS)) & ((1u << TDCK_ACT_POS_BITS) - 1u);
#if TDCK_DSP
    k = (int32_t)__usat(k, 9);
#else
    if (k < 0) {
        k = 0;
    } else if (k > TDCK_ACT_SEGMENTS - 1) {
        k = TDCK_ACT_SEGMENTS - 1;
    }
#endif
    return tdck_act_lerp(table, k, pos);
}

/* T of acc / 2^(shift + ACT_STEP_BITS), ACT_POS_BITS <= shift <= 30. */
static inline int32_t tdck_act(const uint16_t *table, int32_t acc, unsigned shift)
{
    return tdck_act_x_clamped(table, (uint32_t)acc + 0x80000000u, shift);
}

/* sigmoid in Q16 (1 .. 65535) of acc / 2^(shift + ACT_STEP_BITS). */
static inline int32_t tdck_sigmoid_q16(const uint16_t *table, int32_t acc, unsigned shift)
{
    return tdck_act(table, acc, shift + 1u);
}

/* tanh in Q15 (-32767 .. 32767) of acc / 2^(shift + ACT_STEP_BITS). */
static inline int32_t tdck_tanh_q15(const uint16_t *table, int32_t acc, unsigned shift)
{
    return tdck_act(table, acc, shift) - (1 << TDCK_ACT_VALUE_FRAC);
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

/* u + w . x (mod 2^32) for one packed weight pair and the vector pair x0 (first), x1 (second):
 * |w . x| <= 2 32767^2 < 2^31, so the int32 product sum is exact before the modular add. */
static inline uint32_t tdck_mac2(uint32_t u, int32_t word, int32_t x0, int32_t x1)
{
    return u + (uint32_t)(tdck_pair_lo(word) * x0 + tdck_pair_hi(word) * x1);
}

#if TDCK_DSP && defined(__GNUC__) && !defined(__clang__)
/* Four consecutive weight words in four registers with one LDM and the pointer post-incremented
 * (gcc forms at most LDRD from C): one instruction instead of two to four. */
#define TDCK_LOAD4(w, q0, q1, q2, q3)                                                                     \
    do {                                                                                                  \
        register int32_t tdck_r4_ __asm__("r4");                                                         \
        register int32_t tdck_r5_ __asm__("r5");                                                         \
        register int32_t tdck_r6_ __asm__("r6");                                                         \
        register int32_t tdck_r8_ __asm__("r8"); /* not r7: the Thumb frame pointer at -O0 */            \
        __asm__("ldmia %4!, {%0, %1, %2, %3}"                                                             \
                : "=r"(tdck_r4_), "=r"(tdck_r5_), "=r"(tdck_r6_), "=r"(tdck_r8_), "+r"(w)                  \
                : "m"(*(const int32_t(*)[4])(w)));                                                        \
        (q0) = tdck_r4_;                                                                                  \
        (q1) = tdck_r5_;                                                                                  \
        (q2) = tdck_r6_;                                                                                  \
        (q3) = tdck_r8_;                                                                                  \
    } while (0)
#elif TDCK_DSP
#define TDCK_LOAD4(w, q0, q1, q2, q3)                                                                     \
    do {                                                                                                  \
        (q0) = (w)[0];                                                                                    \
        (q1) = (w)[1];                                                                                    \
        (q2) = (w)[2];                                                                                    \
        (q3) = (w)[3];                                                                                    \
        (w) += 4;                                                                                         \
    } while (0)
#endif

#if TDCK_DSP
/* The int32 whose bits are u (SMLAD's operand; a cast would be implementation-defined above
 * INT32_MAX): one register move. */
static inline int32_t tdck_bits_i32(uint32_t u)
{
    int32_t i;
    __builtin_memcpy(&i, &u, sizeof i);
    return i;
}

/* acc[r] += w[r] . x for one pair (DSP path: four SMLADs on the words as they are) */
#define TDCK_SMLAD4(w, x, a0, a1, a2, a3)                                                                 \
    do {                                                                                                  \
        int32_t tdck_q0_, tdck_q1_, tdck_q2_, tdck_q3_;                                                   \
        TDCK_LOAD4(w, tdck_q0_, tdck_q1_, tdck_q2_, tdck_q3_);                                            \
        (a0) = __smlad(tdck_q0_, (x), (a0));                                                              \
        (a1) = __smlad(tdck_q1_, (x), (a1));                                                              \
        (a2) = __smlad(tdck_q2_, (x), (a2));                                                              \
        (a3) = __smlad(tdck_q3_, (x), (a3));                                                              \
    } while (0)
#endif

/* The sums of a unit's block start at its biases: acc[r] = bias_x[r] as uint32 (modular), *wp past
 * them. tdck_dot4 is this, then tdck_dot4_add over the pairs. */
TDCK_INLINE void tdck_dot4_bias(const int32_t **wp, uint32_t *acc)
{
    const int32_t *w = *wp;
    acc[0] = (uint32_t)w[0];
    acc[1] = (uint32_t)w[1];
    acc[2] = (uint32_t)w[2];
    acc[3] = (uint32_t)w[3];
    *wp = w + 4;
}

/* tdck_dot4 continued: the four sums in acc (excess-2^31 words, as tdck_dot4 leaves them) go on
 * over `pairs` more pairs, *wp at their words (no biases); on return *wp points past them. A dot
 * product split in two (the spread schedule's tasks) gives the sums of the whole one. Preconditions:
 * pairs >= 1; those of tdck_dot4 for the whole product. */
TDCK_INLINE void tdck_dot4_add(const int32_t **wp, const int16_t *v, uint32_t pairs, uint32_t *acc)
{
    const int32_t *w = *wp;
#if TDCK_DSP
    /* Duff's device: unrolled by 8 pairs, entered at pairs mod 8 (no per-pair loop test) */
    int32_t a0;
    int32_t a1;
    int32_t a2;
    int32_t a3;
    uint32_t blocks = (pairs + 7u) / 8u;
    int32_t x;
    a0 = tdck_bits_i32(acc[0]); /* the sums so far (SMLAD adds modulo 2^32) */
    a1 = tdck_bits_i32(acc[1]);
    a2 = tdck_bits_i32(acc[2]);
    a3 = tdck_bits_i32(acc[3]);
#define TDCK_PAIR_                                                                                         \
    __builtin_memcpy(&x, v, sizeof x);                                                                    \
    v += 2;                                                                                               \
    TDCK_SMLAD4(w, x, a0, a1, a2, a3)
    switch (pairs % 8u) {
    case 0u:
        do {
            TDCK_PAIR_;
            /* fall through */
        case 7u:
            TDCK_PAIR_;
            /* fall through */
        case 6u:
            TDCK_PAIR_;
            /* fall through */
        case 5u:
            TDCK_PAIR_;
            /* fall through */
        case 4u:
            TDCK_PAIR_;
            /* fall through */
        case 3u:
            TDCK_PAIR_;
            /* fall through */
        case 2u:
            TDCK_PAIR_;
            /* fall through */
        case 1u:
            TDCK_PAIR_;
        } while (--blocks > 0u);
    }
#undef TDCK_PAIR_
    acc[0] = (uint32_t)a0;
    acc[1] = (uint32_t)a1;
    acc[2] = (uint32_t)a2;
    acc[3] = (uint32_t)a3;
#else
    uint32_t a0 = acc[0];
    uint32_t a1 = acc[1];
    uint32_t a2 = acc[2];
    uint32_t a3 = acc[3];
    uint32_t p;
    for (p = 0u; p < pairs; ++p) {
        int32_t x0 = v[2u * p];
        int32_t x1 = v[2u * p + 1u];
        a0 = tdck_mac2(a0, w[0], x0, x1);
        a1 = tdck_mac2(a1, w[1], x0, x1);
        a2 = tdck_mac2(a2, w[2], x0, x1);
        a3 = tdck_mac2(a3, w[3], x0, x1);
        w += 4;
    }
    acc[0] = a0;
    acc[1] = a1;
    acc[2] = a2;
    acc[3] = a3;
#endif
    *wp = w;
}

/* Four gate rows against one int16 vector, in excess-2^31 form. *wp points at a unit's block:
 * bias_x[0..3], then 4 packed words per input pair, w[4p + r]; on return it points past the block.
 * acc[r] = bias[r] + 2^31 + sum_p lo(w[4p + r]) v[2p] + hi(w[4p + r]) v[2p + 1] (mod 2^32), where
 * bias_x[r] is the bias with its sign bit flipped (bias + 2^31 mod 2^32 read as int32, as the
 * generator writes it). Biases and the rows' packed weight pairs are interleaved in one stream:
 * tdck_dot4_bias, then tdck_dot4_add over the pairs (whose DSP path loads the four words of each
 * pair with one LDM, runs unrolled by 8 pairs, and SMLAD takes each word as it is). Preconditions: pairs >= 1; |bias| + sum |w| |v| < 2^31 (proved by the quantiser for
 * every row), so the true sum stays in int32 and both paths give the same numbers. */
TDCK_INLINE void tdck_dot4(const int32_t **wp, const int16_t *v, uint32_t pairs, uint32_t *acc)
{
    tdck_dot4_bias(wp, acc);
    tdck_dot4_add(wp, v, pairs, acc);
}

/* tdck_dot4 with a pair count PAIRS that is an integer constant expression (a literal: the layer
 * functions dispatch on their layers' counts). With gcc on a DSP core the whole product is one
 * assembly block unrolled PAIRS times with no loop test: one LDM of the four biases into the
 * accumulators (r0-r3: LDM wants its registers in ascending order, and fixing them lets gcc plan
 * the unit around them), then per two pairs one LDRD of the two vector words and two LDMs of four
 * weight words each (11 instructions per 8 SMLADs instead of 12, and no loop entry); the vector v
 * must be 4-byte aligned (LDRD faults otherwise; the state struct
 * puts the vector at a multiple of 4 bytes and every layer's input at an even slot). Elsewhere it
 * is tdck_dot4. The same numbers either way (the sums stay in int32). */
#if TDCK_DSP && defined(__GNUC__) && !defined(__clang__) && defined(__OPTIMIZE__)
/* (optimised builds only: the block takes 12 registers, 8 of them fixed, which gcc -O0 cannot find) */
/* The pairs of the product: per two pairs one LDRD and two LDMs, then one odd pair. */
#define TDCK_DOT4_PAIRS_ASM_                                                                              \
    ".rept %c[n]\n\t"                                                                                     \
    "ldrd %[x0], %[x1], [%[v]], #8\n\t"                                                                   \
    "ldmia %[w]!, {%[q0], %[q1], %[q2], %[q3]}\n\t"                                                       \
    "smlad %[a0], %[q0], %[x0], %[a0]\n\t"                                                                \
    "smlad %[a1], %[q1], %[x0], %[a1]\n\t"                                                                \
    "smlad %[a2], %[q2], %[x0], %[a2]\n\t"                                                                \
    "smlad %[a3], %[q3], %[x0], %[a3]\n\t"                                                                \
    "ldmia %[w]!, {%[q0], %[q1], %[q2], %[q3]}\n\t"                                                       \
    "smlad %[a0], %[q0], %[x1], %[a0]\n\t"                                                                \
    "smlad %[a1], %[q1], %[x1], %[a1]\n\t"                                                                \
    "smlad %[a2], %[q2], %[x1], %[a2]\n\t"                                                                \
    "smlad %[a3], %[q3], %[x1], %[a3]\n\t"                                                                \
    ".endr\n\t"                                                                                           \
    ".if %c[odd]\n\t"                                                                                     \
    "ldr %[x0], [%[v]], #4\n\t"                                                                           \
    "ldmia %[w]!, {%[q0], %[q1], %[q2], %[q3]}\n\t"                                                       \
    "smlad %[a0], %[q0], %[x0], %[a0]\n\t"                                                                \
    "smlad %[a1], %[q1], %[x0], %[a1]\n\t"                                                                \
    "smlad %[a2], %[q2], %[x0], %[a2]\n\t"                                                                \
    "smlad %[a3], %[q3], %[x0], %[a3]\n\t"                                                                \
    ".endif"
/* The registers both blocks use, declared once. */
#define TDCK_DOT4_REGS_(wpp, vec)                                                                         \
    const int32_t *tdck_w_ = *(wpp);                                                                      \
    const int16_t *tdck_v_ = (vec);                                                                       \
    register int32_t tdck_a0_ __asm__("r0");                                                             \
    register int32_t tdck_a1_ __asm__("r1");                                                             \
    register int32_t tdck_a2_ __asm__("r2");                                                             \
    register int32_t tdck_a3_ __asm__("r3");                                                             \
    int32_t tdck_x0_;                                                                                     \
    int32_t tdck_x1_;                                                                                     \
    register int32_t tdck_q0_ __asm__("r4");                                                             \
    register int32_t tdck_q1_ __asm__("r5");                                                             \
    register int32_t tdck_q2_ __asm__("r6");                                                             \
    register int32_t tdck_q3_ __asm__("r8") /* not r7: the Thumb frame pointer at -O0 */
#define TDCK_DOT4_OPERANDS_(A)                                                                            \
    : [a0] A(tdck_a0_), [a1] A(tdck_a1_), [a2] A(tdck_a2_), [a3] A(tdck_a3_), [w] "+r"(tdck_w_),           \
      [v] "+r"(tdck_v_), [x0] "=&r"(tdck_x0_), [x1] "=&r"(tdck_x1_), [q0] "=&r"(tdck_q0_),                 \
      [q1] "=&r"(tdck_q1_), [q2] "=&r"(tdck_q2_), [q3] "=&r"(tdck_q3_)
#define TDCK_DOT4_STORE_(wpp, accs)                                                                       \
    (void)tdck_v_;                                                                                        \
    (accs)[0] = (uint32_t)tdck_a0_;                                                                       \
    (accs)[1] = (uint32_t)tdck_a1_;                                                                       \
    (accs)[2] = (uint32_t)tdck_a2_;                                                                       \
    (accs)[3] = (uint32_t)tdck_a3_;                                                                       \
    *(wpp) = tdck_w_
#define TDCK_DOT4_N(wpp, vec, PAIRS, accs)                                                                \
    do {                                                                                                  \
        TDCK_DOT4_REGS_(wpp, vec);                                                                        \
        __asm__("ldmia %[w]!, {%[a0], %[a1], %[a2], %[a3]}\n\t" TDCK_DOT4_PAIRS_ASM_                      \
                TDCK_DOT4_OPERANDS_("=&r")                                                                \
                : [n] "i"((PAIRS) / 2u), [odd] "i"((PAIRS) % 2u)                                          \
                : "memory"); /* reads the weights and the vector */                                       \
        TDCK_DOT4_STORE_(wpp, accs);                                                                      \
    } while (0)
/* tdck_dot4_add with a literal PAIRS: the same block, its sums loaded from accs first. */
#define TDCK_DOT4_ADD_N(wpp, vec, PAIRS, accs)                                                            \
    do {                                                                                                  \
        TDCK_DOT4_REGS_(wpp, vec);                                                                        \
        tdck_a0_ = tdck_bits_i32((accs)[0]);                                                          \
        tdck_a1_ = tdck_bits_i32((accs)[1]);                                                          \
        tdck_a2_ = tdck_bits_i32((accs)[2]);                                                          \
        tdck_a3_ = tdck_bits_i32((accs)[3]);                                                          \
        __asm__(TDCK_DOT4_PAIRS_ASM_                                                                      \
                TDCK_DOT4_OPERANDS_("+r")                                                                 \
                : [n] "i"((PAIRS) / 2u), [odd] "i"((PAIRS) % 2u)                                          \
                : "memory");                                                                              \
        TDCK_DOT4_STORE_(wpp, accs);                                                                      \
    } while (0)
#else
#define TDCK_DOT4_N(wpp, vec, PAIRS, accs) tdck_dot4((wpp), (vec), (PAIRS), (accs))
#define TDCK_DOT4_ADD_N(wpp, vec, PAIRS, accs) tdck_dot4_add((wpp), (vec), (PAIRS), (accs))
#endif

/* One cell from its gates (i, f, o sigmoid Q16; g tanh Q15): c' = f c + i g, rounded half up to
 * Q24 from Q40 and saturated to int32 (sets `sat_bit`); returns h = o tanh(c') in Q15
 * (|h| <= 32767: o <= 65535, |tanh| <= 32767). Two int64 multiply-accumulates, f c + i (g 2^9)
 * (|g| 2^9 < 2^24), plus 2^15 (the rounding half) and 2^47: the sum s is in [0, 2^48) iff
 * c' = floor(s / 2^16) - 2^31 fits int32, and s / 2^16 is already tanh's excess-2^31 input. */
static inline int16_t tdck_lstm_cell(int32_t gi, int32_t gf, int32_t gg, int32_t go, int32_t *c,
    const uint16_t *table, uint32_t *flags, uint32_t sat_bit)
{
    int64_t wide;
#if TDCK_DSP && defined(__GNUC__) && !defined(__clang__)
    /* gcc knows the gates are non-negative and widens them unsigned (UMULL + MLA each): force the
     * two signed 32 x 32 -> 64 multiply-accumulates */
    __asm__("smull %Q0, %R0, %1, %2\n\tsmlal %Q0, %R0, %3, %4"
            : "=&r"(wide)
            : "r"(gf), "r"(*c), "r"(gi), "r"(gg * (1 << (TDCK_C_FRAC - TDCK_TANH_FRAC))));
#else
    wide = (int64_t)gf * (int64_t)*c + (int64_t)gi * (int64_t)(gg * (1 << (TDCK_C_FRAC - TDCK_TANH_FRAC)));
#endif
    uint64_t s = (uint64_t)wide + (((uint64_t)1 << 47) + ((uint64_t)1 << (TDCK_GATE_FRAC - 1)));
    uint32_t u;
    int32_t th;
    if (TDCK_UNLIKELY((s >> 48) != 0u)) {
        *flags |= sat_bit;
        u = (wide < 0) ? 0u : 0xFFFFFFFFu;
    } else {
        u = (uint32_t)(s >> TDCK_GATE_FRAC);
    }
    th = tdck_act_x_clamped(table, u, TDCK_C_FRAC - TDCK_ACT_STEP_BITS) - (1 << TDCK_ACT_VALUE_FRAC);
    *c = (int32_t)((int64_t)u - ((int64_t)1 << 31));
#if TDCK_DSP && defined(__GNUC__) && !defined(__clang__)
    {
        /* floor((o 2^15 th 2^1 + 2^31) / 2^32) = floor((o th + 2^15) / 2^16): one SMMULR */
        int32_t h;
        __asm__("smmulr %0, %1, %2" : "=r"(h) : "r"(go * (1 << 15)), "r"(th * 2));
        return (int16_t)h;
    }
#else
    return (int16_t)tdck_round_shift32(go * th, TDCK_GATE_FRAC);
#endif
}

/* A unit's four activations from its gate accumulators (excess-2^31 form, Q(shift + ACT_STEP_BITS)):
 * gate[0], gate[1], gate[3] = sigmoid of i, f, o in Q16; gate[2] = tanh(g) + 1 in Q15 (the table's
 * value; all four in 1 .. 65535, so unsigned words hold them). gate may be acc (each gate reads only
 * its own accumulator). `sig` is table + 256 - 2^(30 - shift) when the sigmoid gates' accumulators
 * cannot leave the table (shift >= 22: the caller passes it, so that the compiler keeps that base
 * address in a register), else NULL. */
TDCK_INLINE void tdck_lstm_gates(const uint32_t *acc, unsigned shift, const uint16_t *table, const uint16_t *sig,
    uint32_t *gate)
{
    if (sig != NULL && shift + 1u >= 23u) {
        unsigned s = shift + 1u;
        uint32_t mask = (1u << TDCK_ACT_POS_BITS) - 1u;
        gate[0] = (uint32_t)tdck_act_lerp(sig, (int32_t)(acc[0] >> s), (acc[0] >> (s - TDCK_ACT_POS_BITS)) & mask);
        gate[1] = (uint32_t)tdck_act_lerp(sig, (int32_t)(acc[1] >> s), (acc[1] >> (s - TDCK_ACT_POS_BITS)) & mask);
        gate[3] = (uint32_t)tdck_act_lerp(sig, (int32_t)(acc[3] >> s), (acc[3] >> (s - TDCK_ACT_POS_BITS)) & mask);
    } else {
        gate[0] = (uint32_t)tdck_act_x(table, acc[0], shift + 1u);
        gate[1] = (uint32_t)tdck_act_x(table, acc[1], shift + 1u);
        gate[3] = (uint32_t)tdck_act_x(table, acc[3], shift + 1u);
    }
    gate[2] = (uint32_t)tdck_act_x(table, acc[2], shift);
}

/* The cell from the four activations of tdck_lstm_gates: tdck_lstm_cell; returns h. */
TDCK_INLINE int16_t tdck_lstm_cell_gates(const uint32_t *gate, int32_t *c, const uint16_t *table, uint32_t *flags,
    uint32_t sat_bit)
{
    return tdck_lstm_cell((int32_t)gate[0], (int32_t)gate[1], (int32_t)gate[2] - (1 << TDCK_ACT_VALUE_FRAC),
        (int32_t)gate[3], c, table, flags, sat_bit);
}

/* A unit's cell from its four gate accumulators: tdck_lstm_gates, then tdck_lstm_cell; returns h. */
TDCK_INLINE int16_t tdck_lstm_unit(const uint32_t *acc, unsigned shift, int32_t *c, const uint16_t *table,
    const uint16_t *sig, uint32_t *flags, uint32_t sat_bit)
{
    uint32_t gate[4];
    tdck_lstm_gates(acc, shift, table, sig, gate);
    return tdck_lstm_cell_gates(gate, c, table, flags, sat_bit);
}

/* One LSTM layer of `hidden` units: unit j's four gate rows (i, f, g, o) are tdck_dot4 of block j of
 * w (4 biases, then 4 packed words per input pair) against v (2 pairs int16, the layer's input
 * then its own h). The gate accumulators are Q(shift + ACT_STEP_BITS). New h go to h_new (not v:
 * the later units still read the old h); cell states are updated in place. `sig`: as for
 * tdck_lstm_unit. */
TDCK_INLINE void tdck_lstm_layer(const int32_t *w, const int16_t *v, uint32_t pairs, uint32_t hidden,
    unsigned shift, int32_t *c, int16_t *h_new, const uint16_t *table, const uint16_t *sig, uint32_t *flags,
    uint32_t sat_bit)
{
    uint32_t j;
    for (j = 0u; j < hidden; ++j) {
        uint32_t acc[4];
        tdck_dot4(&w, v, pairs, acc);
        h_new[j] = tdck_lstm_unit(acc, shift, &c[j], table, sig, flags, sat_bit);
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

/* acc += sum_j w[j] h[j] for a literal count N (an integer constant expression), int32 x int16
 * into int64 as tdck_dot_wide. With gcc on a DSP core: one assembly block, an LDM per four weights,
 * LDRSH and SMLAL per product, no loop. */
#if TDCK_DSP && defined(__GNUC__) && !defined(__clang__) && defined(__OPTIMIZE__)
#define TDCK_DOT_WIDE_N(wts, hs, N, acc64)                                                                     \
    do {                                                                                                  \
        const int32_t *tdck_w_ = (wts);                                                                     \
        const int16_t *tdck_h_ = (hs);                                                                     \
        int32_t tdck_t_;                                                                                  \
        register int32_t tdck_q0_ __asm__("r4");                                                         \
        register int32_t tdck_q1_ __asm__("r5");                                                         \
        register int32_t tdck_q2_ __asm__("r6");                                                         \
        register int32_t tdck_q3_ __asm__("r8");                                                         \
        __asm__(".rept %c[n4]\n\t"                                                                        \
                "ldmia %[w]!, {%[q0], %[q1], %[q2], %[q3]}\n\t"                                           \
                "ldrsh %[t], [%[h]], #2\n\t"                                                              \
                "smlal %Q[a], %R[a], %[q0], %[t]\n\t"                                                     \
                "ldrsh %[t], [%[h]], #2\n\t"                                                              \
                "smlal %Q[a], %R[a], %[q1], %[t]\n\t"                                                     \
                "ldrsh %[t], [%[h]], #2\n\t"                                                              \
                "smlal %Q[a], %R[a], %[q2], %[t]\n\t"                                                     \
                "ldrsh %[t], [%[h]], #2\n\t"                                                              \
                "smlal %Q[a], %R[a], %[q3], %[t]\n\t"                                                     \
                ".endr\n\t"                                                                               \
                ".rept %c[n1]\n\t"                                                                        \
                "ldr %[q0], [%[w]], #4\n\t"                                                               \
                "ldrsh %[t], [%[h]], #2\n\t"                                                              \
                "smlal %Q[a], %R[a], %[q0], %[t]\n\t"                                                     \
                ".endr"                                                                                   \
                : [a] "+r"(acc64), [w] "+r"(tdck_w_), [h] "+r"(tdck_h_), [t] "=&r"(tdck_t_),                 \
                  [q0] "=&r"(tdck_q0_), [q1] "=&r"(tdck_q1_), [q2] "=&r"(tdck_q2_), [q3] "=&r"(tdck_q3_)   \
                : [n4] "i"((N) / 4u), [n1] "i"((N) % 4u)                                                   \
                : "memory"); /* reads the weights and h */                                                \
        (void)tdck_w_;                                                                                    \
        (void)tdck_h_;                                                                                    \
    } while (0)
#else
#define TDCK_DOT_WIDE_N(wts, hs, N, acc64) ((acc64) = tdck_dot_wide((wts), (hs), (N), (acc64)))
#endif

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
