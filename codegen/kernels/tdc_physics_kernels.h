/*
 * tdc_physics_kernels.h -- the fixed-point kernels of mems-tdc's grey-box (physics) compensators.
 *
 * Hand-written C99, shipped with codegen and copied next to every generated physics module (NAME.c
 * includes it after tdc_kernels.h); the module renders only its constants and the glue. Same rules
 * as tdc_kernels.h: every function `static inline`, no malloc, libm, stdio or floating point, no
 * undefined or implementation-defined behaviour (a negative value is never shifted right: floors
 * are exact divisions of a multiple, or shifts of a value offset by 2^63), every signed operation
 * inside a bound proved at generation time (codegen/quantize.py, `_physics`) and stated below as
 * the caller's precondition. Tested directly (tests/test_codegen_physics_kernels.py: against
 * references in Python integers, ASan/UBSan, gcc and clang strict flags).
 *
 * Why these shapes: a Cortex-M4 multiplies 32 x 32 -> 64 bits in one instruction (SMULL, SMLAL),
 * and the high word of a 64-bit value is free. So temperatures are int32, each filter state is an
 * int64 whose high word is the temperature, every product is one SMULL/SMLAL, and the only
 * rounding shifts are of a high word: 64-bit rounding shifts (tens of instructions each) are gone.
 */
#ifndef TDC_PHYSICS_KERNELS_H_INCLUDED
#define TDC_PHYSICS_KERNELS_H_INCLUDED

#include <stdint.h>

/* Cortex-M4 (any core with __ARM_FEATURE_DSP): the Horner step is one SMMLAR. Define TDCK_PORTABLE
 * (as for tdc_kernels.h) to build the portable path there too; both give identical results. */
#if defined(__ARM_FEATURE_DSP) && defined(__GNUC__) && !defined(TDCK_PORTABLE)
#define TDCP_DSP 1
#else
#define TDCP_DSP 0
#endif

#define TDCP_VERSION 1

/* floor(x / 2^32): the high word (any int64 x; the result fits int32). */
static inline int32_t tdcp_hi(int64_t x)
{
    return (int32_t)((int64_t)(((uint64_t)x + ((uint64_t)1 << 63)) >> 32) - ((int64_t)1 << 31));
}

/* floor(x / 2^(32 + s)) for 0 <= s <= 30 (any int64 x): the high word shifted, on the offset value. */
static inline int32_t tdcp_hi_floor(int64_t x, unsigned s)
{
    return (int32_t)((int64_t)(((uint64_t)x + ((uint64_t)1 << 63)) >> (32u + s)) - ((int64_t)1 << (31u - s)));
}

/* floor(x / 2^(32 + s) + 1/2) for 0 <= s <= 30 and |x| < 2^62: the high word, rounded half up
 * (tdcp_hi_floor of x + 2^(31 + s): shifts only, so a shift s read from a table at run time, as in
 * the IMU module, costs no 64-bit division; an exact division by 2^(32 + s) did, through
 * __aeabi_ldivmod on Cortex-M). */
static inline int32_t tdcp_hi_round(int64_t x, unsigned s)
{
    return tdcp_hi_floor(x + ((int64_t)1 << (31u + s)), s);
}

/* acc + floor(a b / 2^32 + 1/2), one Horner step: SMMLAR on a DSP core (gcc and clang have no
 * pattern for it), else an exact division of a multiple of 2^32 (one SMLAL). Precondition: the sum
 * fits int32. */
static inline int32_t tdcp_mla_hi_round(int32_t acc, int32_t a, int32_t b)
{
#if TDCP_DSP
    int32_t r;
    __asm__("smmlar %0, %1, %2, %3" : "=r"(r) : "r"(a), "r"(b), "r"(acc));
    return r;
#else
    int64_t p = (int64_t)a * b + ((int64_t)1 << 31);
    p = (p - (int64_t)((uint64_t)p & 0xFFFFFFFFu)) / ((int64_t)1 << 32);
    return acc + (int32_t)p;
#endif
}

/* One step of the first-order-hold low-pass y' = a y + b0 x + b1 x_prev, written
 * y' = y + c (x_prev - y) + b0 (x - x_prev) with c = 1 - a: y int64 Q(F + 32) (its high word is the
 * Q(F) temperature), prev = x_prev in Q(F), step = (x - x_prev) in Q(F - s), c and b0 in Q(32 + s):
 *   y' = y + floor((prev 2^32 - y) / 2^(32 + s)) c + step b0        (two SMLAL)
 * The floor leaves the settled state at most 2^(s - F) below its input (the generator bounds it).
 * Preconditions (proved by the generator): |prev 2^32| + |y| < 2^63, |y| + |d c| + |step b0| < 2^63. */
static inline int64_t tdcp_lowpass(int64_t y, int32_t prev, int32_t step, int32_t c, int32_t b0, unsigned s)
{
    int32_t d = tdcp_hi_floor((int64_t)prev * ((int64_t)1 << 32) - y, s);
    return y + (int64_t)d * c + (int64_t)step * b0;
}

/* The play operator of half width h: p moved just enough to lie within [x - h, x + h].
 * Precondition: x - h and x + h fit int32. */
static inline int32_t tdcp_play(int32_t p, int32_t x, int32_t h)
{
    if (p < x - h) {
        return x - h;
    }
    if (p > x + h) {
        return x + h;
    }
    return p;
}

/* Common tail of a step: count the sample (saturating); output = accel - drift saturated to int32
 * (a clamp sets `bit` in *flags). Precondition: |drift| <= 2^30, so an accel in [-2^30, 2^30)
 * (every real sample: 2^30 LSB = 67 g) cannot saturate and takes the short path. */
static inline int32_t tdcp_output(uint32_t *samples, uint32_t *flags, uint32_t bit, int32_t accel, int32_t drift)
{
    uint32_t n = *samples + 1u;
    if (n != 0u) {
        *samples = n;
    }
    if ((uint32_t)accel + 0x40000000u < 0x80000000u) {
        return accel - drift;
    }
    if (drift >= 0 ? accel < INT32_MIN + drift : accel > INT32_MAX + drift) {
        *flags |= bit;
        return drift >= 0 ? INT32_MIN : INT32_MAX;
    }
    return accel - drift;
}

#endif /* TDC_PHYSICS_KERNELS_H_INCLUDED */
