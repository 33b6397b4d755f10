/*
 * board_io over ARM semihosting (ARM DUI 0471, "Semihosting operations"):
 * the call is "bkpt 0xAB" with the operation in r0 and a parameter block in r1;
 * QEMU runs it on the host when started with -semihosting-config enable=on.
 */
#include <stdint.h>
#include "board_io.h"

enum {
    SYS_OPEN = 0x01,
    SYS_CLOSE = 0x02,
    SYS_WRITE0 = 0x04,
    SYS_WRITE = 0x05,
    SYS_READ = 0x06,
    SYS_FLEN = 0x0C,
    SYS_EXIT_EXTENDED = 0x20
};

/* Open modes of SYS_OPEN: 1 = "rb", 5 = "wb" (ISO C fopen modes by index). */
enum { MODE_READ_BINARY = 1, MODE_WRITE_BINARY = 5 };

/* ADP_Stopped_ApplicationExit: the reason code SYS_EXIT expects. */
#define ADP_STOPPED_APPLICATION_EXIT 0x20026u

static uintptr_t semihost_call(uintptr_t op, const void *arg)
{
    register uintptr_t r0 __asm__("r0") = op;
    register const void *r1 __asm__("r1") = arg;
    __asm__ volatile("bkpt 0xAB" : "+r"(r0) : "r"(r1) : "memory");
    return r0;
}

static size_t length_of(const char *text)
{
    size_t n = 0;
    while (text[n] != '\0') {
        ++n;
    }
    return n;
}

static long open_file(const char *name, uintptr_t mode)
{
    uintptr_t block[3];
    block[0] = (uintptr_t)name;
    block[1] = mode;
    block[2] = (uintptr_t)length_of(name);
    return (long)(intptr_t)semihost_call(SYS_OPEN, block);
}

static void close_file(long handle)
{
    uintptr_t block[1];
    block[0] = (uintptr_t)handle;
    (void)semihost_call(SYS_CLOSE, block);
}

long board_io_read(const char *name, void *buf, size_t max)
{
    uintptr_t block[3];
    long handle = open_file(name, MODE_READ_BINARY);
    long length;
    if (handle < 0) {
        return -1;
    }
    block[0] = (uintptr_t)handle;
    length = (long)(intptr_t)semihost_call(SYS_FLEN, block);
    if (length < 0) {
        close_file(handle);
        return -1;
    }
    if ((size_t)length > max) {
        length = (long)max;
    }
    block[0] = (uintptr_t)handle;
    block[1] = (uintptr_t)buf;
    block[2] = (uintptr_t)length;
    /* SYS_READ returns the number of bytes NOT read. */
    length -= (long)semihost_call(SYS_READ, block);
    close_file(handle);
    return length;
}

int board_io_write(const char *name, const void *buf, size_t n)
{
    uintptr_t block[3];
    long handle = open_file(name, MODE_WRITE_BINARY);
    uintptr_t left;
    if (handle < 0) {
        return -1;
    }
    block[0] = (uintptr_t)handle;
    block[1] = (uintptr_t)buf;
    block[2] = (uintptr_t)n;
    left = semihost_call(SYS_WRITE, block);
    close_file(handle);
    return (left == 0u) ? 0 : -1;
}

void board_io_print(const char *text)
{
    (void)semihost_call(SYS_WRITE0, text);
}

void board_io_exit(int status)
{
    /* SYS_EXIT_EXTENDED takes {reason, status}; plain SYS_EXIT cannot carry a status on AArch32. */
    uintptr_t block[2];
    block[0] = ADP_STOPPED_APPLICATION_EXIT;
    block[1] = (uintptr_t)(intptr_t)status;
    (void)semihost_call(SYS_EXIT_EXTENDED, block);
    for (;;) {
    }
}
