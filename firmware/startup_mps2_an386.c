/*
 * Minimal start-up code for QEMU's mps2-an386 (Cortex-M4F): vector table,
 * reset handler that enables the FPU, zeroes .bss and calls main(), then ends
 * the emulation through semihosting with main's return value.
 *
 * QEMU loads every ELF segment at its address, so .data needs no copy from flash.
 */
#include <stdint.h>
#include "board_io.h"

extern uint32_t __bss_start__;
extern uint32_t __bss_end__;
extern uint32_t __stack_top__;

int main(void);
void Reset_Handler(void);
void Fault_Handler(void);

/* Coprocessor access control register: CP10/CP11 full access enables the FPU. */
#define SCB_CPACR (*(volatile uint32_t *)0xE000ED88u)

void Reset_Handler(void)
{
    uint32_t *word;
    SCB_CPACR |= (0xFu << 20);
    __asm__ volatile("dsb\n\tisb" ::: "memory");
    for (word = &__bss_start__; word < &__bss_end__; ++word) {
        *word = 0u;
    }
    board_io_exit(main());
}

void Fault_Handler(void)
{
    board_io_print("fault\n");
    board_io_exit(3);
}

/* One vector-table word: the initial stack pointer (an object address) or a handler.
 * A union keeps both as ISO C (-Wpedantic forbids converting between object and
 * function pointers). */
typedef union {
    uint32_t *stack;
    void (*handler)(void);
} vector_entry;

/* Initial stack pointer, reset, NMI, hard fault, MPU/bus/usage faults. */
__attribute__((section(".isr_vector"), used)) const vector_entry vector_table[7] = {
    {.stack = &__stack_top__}, {.handler = Reset_Handler}, {.handler = Fault_Handler}, {.handler = Fault_Handler},
    {.handler = Fault_Handler}, {.handler = Fault_Handler}, {.handler = Fault_Handler},
};
