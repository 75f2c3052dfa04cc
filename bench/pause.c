/* The cheapest brain there is, for bench/rollout.py: it waits for a signal, and SIGTERM's
   default action ends it. On x86-64 it has no C library at all, so starting it costs only the
   exec: no dynamic loader, no start-up code probing the CPU (slow under a hypervisor). */
#if defined(__x86_64__)
void _start(void) {
    for (;;) {
        __asm__ volatile("syscall" : : "a"(34) : "rcx", "r11", "memory"); /* pause(2) */
    }
}
#else
#include <unistd.h>
int main(void) {
    for (;;) {
        pause();
    }
}
#endif
