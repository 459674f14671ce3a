/*
 * semihost.h -- the few Arm semihosting calls the QEMU apps need beyond newlib's (rdimon) stdio:
 * the command line (QEMU's -semihosting-config ...,arg=...), a message that works before stdio is
 * set up (fault handlers), and exit with a status that QEMU turns into its own exit code.
 * Semihosting is a debug channel: none of this belongs in flight firmware.
 */
#ifndef SEMIHOST_H_INCLUDED
#define SEMIHOST_H_INCLUDED

#include <stddef.h>

/* Split the semihosting command line into at most max_args words (no quoting); returns argc.
 * buffer receives the line and holds the words; argv[argc] is NULL. */
int semihost_args(char *buffer, size_t size, char **argv, int max_args);

/* Write a NUL-terminated string to the host console (SYS_WRITE0). */
void semihost_puts(const char *text);

/* End the emulation; QEMU exits with status (SYS_EXIT_EXTENDED, semihosting v2). */
void semihost_exit(int status) __attribute__((noreturn));

#endif /* SEMIHOST_H_INCLUDED */
