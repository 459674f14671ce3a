/* The record-stream main shared by the kernel harnesses (kernel_app.c, physics_kernel_app.c).
 *
 * Include it last, after defining KERNEL_IN, KERNEL_OUT, HARNESS_NAME (the program's name),
 * HARNESS_DSP (1 when the DSP path is compiled in) and `static void run(const int64_t *in,
 * int64_t *out)`. It reads INPUTS (records of KERNEL_IN little-endian int64), writes OUTPUTS (one
 * record of KERNEL_OUT int64 each) and prints "records N dsp D"; under TDC_SEMIHOSTING the two
 * file names come from the QEMU command line. */
#ifndef RECORD_MAIN_H
#define RECORD_MAIN_H

#include <stdio.h>

#if defined(TDC_SEMIHOSTING)
#include "semihost.h"
#endif

static int run_files(int argc, char **argv)
{
    static int64_t in[KERNEL_IN];
    static int64_t out[KERNEL_OUT];
    FILE *fin;
    FILE *fout;
    unsigned long n = 0u;
    if (argc < 3) {
        printf("usage: %s INPUTS OUTPUTS\n", HARNESS_NAME);
        return 2;
    }
    fin = fopen(argv[1], "rb");
    fout = fopen(argv[2], "wb");
    if (fin == NULL || fout == NULL) {
        printf("error: cannot open the files\n");
        return 3;
    }
    while (fread(in, sizeof in[0], KERNEL_IN, fin) == KERNEL_IN) {
        run(in, out);
        if (fwrite(out, sizeof out[0], KERNEL_OUT, fout) != KERNEL_OUT) {
            return 4;
        }
        ++n;
    }
    fclose(fin);
    printf("records %lu dsp %d\n", n, HARNESS_DSP);
    return fclose(fout) == 0 ? 0 : 5;
}

#if defined(TDC_SEMIHOSTING)
int main(void)
{
    static char cmdline[512];
    char *argv[4];
    int argc = semihost_args(cmdline, sizeof cmdline, argv, 3);
    return run_files(argc, argv);
}
#else
int main(int argc, char **argv)
{
    return run_files(argc, argv);
}
#endif

#endif /* RECORD_MAIN_H */
