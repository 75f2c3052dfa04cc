/* The cheapest brain there is, for bench/rollout.py: it waits for a signal, and SIGTERM's
   default action ends it. SIGHUP is ignored, so that agents configured to reload (reload:
   {signal: SIGHUP}) can tell it to, and it goes on. On x86-64 it has no C library at all, so
   starting it costs only the exec: no dynamic loader, no start-up code probing the CPU (slow
   under a hypervisor). */
#if defined(__x86_64__)
/* The kernel's struct sigaction: handler, flags, restorer, mask. SIG_IGN is 1. */
static const unsigned long ignore[4] = {1, 0, 0, 0};

void _start(void) {
    register long mask_size __asm__("r10") = 8;
    __asm__ volatile("syscall" /* rt_sigaction(SIGHUP, &ignore, 0, 8) */
                     : : "a"(13), "D"(1), "S"(ignore), "d"(0), "r"(mask_size)
                     : "rcx", "r11", "memory");
    for (;;) {
        __asm__ volatile("syscall" : : "a"(34) : "rcx", "r11", "memory"); /* pause(2) */
    }
}
#else
#include <signal.h>
#include <unistd.h>
int main(void) {
    signal(SIGHUP, SIG_IGN);
    for (;;) {
        pause();
    }
}
#endif
