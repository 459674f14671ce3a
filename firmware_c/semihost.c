/* semihost.c -- see semihost.h. */
#include "semihost.h"

#include <stdint.h>

#define SYS_WRITE0 0x04u
#define SYS_GET_CMDLINE 0x15u
#define SYS_EXIT 0x18u
#define SYS_EXIT_EXTENDED 0x20u
#define ADP_STOPPED_APPLICATION_EXIT 0x20026u

/* BKPT 0xAB with the operation in r0 and the argument block in r1 (M-profile semihosting). */
static uint32_t semihost_call(uint32_t op, const void *arg)
{
    register uint32_t r0 __asm__("r0") = op;
    register const void *r1 __asm__("r1") = arg;
    __asm__ volatile("bkpt 0xab" : "+r"(r0) : "r"(r1) : "memory");
    return r0;
}

int semihost_args(char *buffer, size_t size, char **argv, int max_args)
{
    uint32_t block[2];
    int argc = 0;
    char *p = buffer;
    if (size == 0u || max_args < 1) {
        return 0;
    }
    block[0] = (uint32_t)(uintptr_t)buffer;
    block[1] = (uint32_t)(size - 1u);
    if (semihost_call(SYS_GET_CMDLINE, block) != 0u) {
        buffer[0] = '\0';
    } else {
        buffer[block[1]] = '\0';
    }
    while (*p != '\0' && argc < max_args) {
        while (*p == ' ') {
            *p++ = '\0';
        }
        if (*p == '\0') {
            break;
        }
        argv[argc++] = p;
        while (*p != '\0' && *p != ' ') {
            ++p;
        }
    }
    argv[argc] = NULL;
    return argc;
}

void semihost_puts(const char *text)
{
    (void)semihost_call(SYS_WRITE0, text);
}

void semihost_exit(int status)
{
    uint32_t block[2];
    block[0] = ADP_STOPPED_APPLICATION_EXIT;
    block[1] = (uint32_t)status;
    (void)semihost_call(SYS_EXIT_EXTENDED, block);
    /* Hosts without the extended call: the plain one can only say "stopped". */
    (void)semihost_call(SYS_EXIT, (const void *)(uintptr_t)ADP_STOPPED_APPLICATION_EXIT);
    for (;;) {
    }
}
