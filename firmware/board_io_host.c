/* board_io over stdio, for the host build of the harness and the runtime. */
#include <stdio.h>
#include <stdlib.h>
#include "board_io.h"

long board_io_read(const char *name, void *buf, size_t max)
{
    FILE *file = fopen(name, "rb");
    size_t got;
    if (file == NULL) {
        return -1;
    }
    got = fread(buf, 1, max, file);
    fclose(file);
    return (long)got;
}

int board_io_write(const char *name, const void *buf, size_t n)
{
    FILE *file = fopen(name, "wb");
    size_t put;
    if (file == NULL) {
        return -1;
    }
    put = fwrite(buf, 1, n, file);
    return (fclose(file) == 0 && put == n) ? 0 : -1;
}

void board_io_print(const char *text)
{
    fputs(text, stdout);
}

void board_io_exit(int status)
{
    exit(status);
}
