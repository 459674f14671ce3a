/*
 * physics_kernel_app.c -- runs the kernels of codegen/kernels/tdc_physics_kernels.h on recorded
 * inputs, on the host (tests/test_codegen_physics_kernels.py: strict warnings, ASan + UBSan) and on
 * the Cortex-M4 under QEMU (firmware_c/Makefile `physics-kernel-app`, semihosting files), with the
 * SMMLAR path and with the portable one. Not part of any flight module.
 *
 * Usage: physics_kernel_app INPUTS OUTPUTS
 * INPUTS: little-endian int64 records of KERNEL_IN values: kernel id, then its arguments;
 * OUTPUTS: one record of KERNEL_OUT int64 values per input record (unused values 0).
 */
#include <stdio.h>
#include <string.h>

#include "tdc_physics_kernels.h"


#define KERNEL_IN 7
#define KERNEL_OUT 3

enum kernel { K_HI = 0, K_HI_FLOOR = 1, K_HI_ROUND = 2, K_MLA = 3, K_LOWPASS = 4, K_PLAY = 5, K_OUTPUT = 6 };

static void run(const int64_t *in, int64_t *out)
{
    memset(out, 0, KERNEL_OUT * sizeof out[0]);
    switch ((int)in[0]) {
    case K_HI:
        out[0] = tdcp_hi(in[1]);
        break;
    case K_HI_FLOOR:
        out[0] = tdcp_hi_floor(in[1], (unsigned)in[2]);
        break;
    case K_HI_ROUND:
        out[0] = tdcp_hi_round(in[1], (unsigned)in[2]);
        break;
    case K_MLA:
        out[0] = tdcp_mla_hi_round((int32_t)in[1], (int32_t)in[2], (int32_t)in[3]);
        break;
    case K_LOWPASS:
        out[0] = tdcp_lowpass(in[1], (int32_t)in[2], (int32_t)in[3], (int32_t)in[4], (int32_t)in[5], (unsigned)in[6]);
        break;
    case K_PLAY:
        out[0] = tdcp_play((int32_t)in[1], (int32_t)in[2], (int32_t)in[3]);
        break;
    case K_OUTPUT: {
        /* in = samples, accel, drift, flags before; out = output, samples, flags after */
        uint32_t samples = (uint32_t)in[1];
        uint32_t flags = (uint32_t)in[4];
        out[0] = tdcp_output(&samples, &flags, 4u, (int32_t)in[2], (int32_t)in[3]);
        out[1] = samples;
        out[2] = flags;
        break;
    }
    default:
        out[0] = -1;
        break;
    }
}

#define HARNESS_NAME "physics_kernel_app"
#define HARNESS_DSP TDCP_DSP
#include "record_main.h"
