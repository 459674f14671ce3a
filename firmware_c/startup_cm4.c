/*
 * startup_cm4.c -- minimal start-up for a Cortex-M4F on QEMU's mps2-an386 board.
 *
 * The vector table sits at address 0 (mps2_an386.ld); the core loads the initial stack pointer and
 * the reset vector from it. Reset_Handler copies .data from flash, zeroes .bss, enables the FPU
 * (the code is built with -mfloat-abi=hard, so any FP instruction before this would fault), opens
 * newlib's semihosting stdio and calls main; main's return value becomes QEMU's exit status.
 * Faults and unexpected interrupts print a line through semihosting and stop with status 70.
 */
#include <stdint.h>
#include <stdlib.h>

#include "semihost.h"

#define N_IRQ 32u /* external interrupts of the AN386 image as QEMU models it */
#define SCB_CPACR (*(volatile uint32_t *)0xE000ED88u)
#define FAULT_STATUS 70

typedef void (*vector_t)(void);

struct vector_table {
    uint32_t *initial_sp;
    vector_t handlers[15u + N_IRQ];
};

extern uint32_t _estack;
extern uint32_t _sidata;
extern uint32_t _sdata;
extern uint32_t _edata;
extern uint32_t _sbss;
extern uint32_t _ebss;

int main(void);
extern void initialise_monitor_handles(void); /* newlib rdimon: stdin/stdout/stderr via semihosting */

/* crti/crtn are not linked (-nostartfiles): newlib's init/fini arrays call these; nothing to do. */
void _init(void);
void _fini(void);

void Reset_Handler(void);
void Default_Handler(void);
void HardFault_Handler(void);
void NMI_Handler(void) __attribute__((weak, alias("Default_Handler")));
void MemManage_Handler(void) __attribute__((weak, alias("HardFault_Handler")));
void BusFault_Handler(void) __attribute__((weak, alias("HardFault_Handler")));
void UsageFault_Handler(void) __attribute__((weak, alias("HardFault_Handler")));
void SVC_Handler(void) __attribute__((weak, alias("Default_Handler")));
void DebugMon_Handler(void) __attribute__((weak, alias("Default_Handler")));
void PendSV_Handler(void) __attribute__((weak, alias("Default_Handler")));
void SysTick_Handler(void) __attribute__((weak, alias("Default_Handler")));

__attribute__((section(".isr_vector"), used)) const struct vector_table vectors = {
    &_estack,
    {
        Reset_Handler,
        NMI_Handler,
        HardFault_Handler,
        MemManage_Handler,
        BusFault_Handler,
        UsageFault_Handler,
        0, 0, 0, 0, /* reserved */
        SVC_Handler,
        DebugMon_Handler,
        0, /* reserved */
        PendSV_Handler,
        SysTick_Handler,
        /* IRQ 0 .. 31: none used; an unexpected one ends up in Default_Handler */
        Default_Handler, Default_Handler, Default_Handler, Default_Handler, Default_Handler, Default_Handler,
        Default_Handler, Default_Handler, Default_Handler, Default_Handler, Default_Handler, Default_Handler,
        Default_Handler, Default_Handler, Default_Handler, Default_Handler, Default_Handler, Default_Handler,
        Default_Handler, Default_Handler, Default_Handler, Default_Handler, Default_Handler, Default_Handler,
        Default_Handler, Default_Handler, Default_Handler, Default_Handler, Default_Handler, Default_Handler,
        Default_Handler, Default_Handler,
    },
};

void Reset_Handler(void)
{
    const uint32_t *src = &_sidata;
    uint32_t *dst;
    for (dst = &_sdata; dst < &_edata; ++dst) {
        *dst = *src++;
    }
    for (dst = &_sbss; dst < &_ebss; ++dst) {
        *dst = 0u;
    }
    SCB_CPACR |= 0xFu << 20; /* CP10 and CP11 full access: the FPU */
    __asm__ volatile("dsb\n\tisb" ::: "memory");
    initialise_monitor_handles();
    exit(main());
}

void _init(void)
{
}

void _fini(void)
{
}

void HardFault_Handler(void)
{
    semihost_puts("startup_cm4: fault exception (hard, memory, bus or usage fault)\n");
    semihost_exit(FAULT_STATUS);
}

void Default_Handler(void)
{
    semihost_puts("startup_cm4: unexpected exception or interrupt\n");
    semihost_exit(FAULT_STATUS);
}
