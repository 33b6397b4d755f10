/*
 * Whole-file input/output for the filter harness, implemented twice: with ARM
 * semihosting (board_io_semihost.c, for QEMU's mps2-an386 and debug probes) and
 * with stdio (board_io_host.c, for the host build). File names are relative to
 * the working directory of QEMU or of the host process.
 */
#ifndef BOARD_IO_H
#define BOARD_IO_H

#include <stddef.h>

/* Read at most max bytes of file name into buf; returns bytes read or -1. */
long board_io_read(const char *name, void *buf, size_t max);
/* Write n bytes of buf to file name (created or truncated); returns 0 or -1. */
int board_io_write(const char *name, const void *buf, size_t n);
/* Report a line of text on the console. */
void board_io_print(const char *text);
/* End the program with the given status (QEMU exits with it). */
void board_io_exit(int status);

#endif /* BOARD_IO_H */
