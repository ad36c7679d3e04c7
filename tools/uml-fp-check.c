/*
 * In-guest check for tools/in-vcan-selftest.sh: vector registers survive the UML guest's
 * context switches. Six threads of one process (one host process under UML, so every switch
 * between them saves and restores registers through ptrace and tools/uml-xstate-shim.c) each load
 * their own values into ymm9 and, where the CPU has AVX-512, zmm17, yield many times, and read
 * them back. Exit 0 and print what was checked, or exit 1 on any lost value.
 */
#include <pthread.h>
#include <sys/syscall.h>
#include <stdint.h>
#include <stdio.h>

#define THREADS 6
#define ROUNDS 300

static int have_avx512;
static int lost;
static pthread_mutex_t lost_lock = PTHREAD_MUTEX_INITIALIZER;

/* Load a register, give the CPU away YIELDS times (sched_yield, as raw system calls inside the
 * same asm block: a call from C would let the compiler put a vzeroupper in between), read the
 * register back. */
#define YIELDS 8
#define HOLD(load, store, reg, in, out)                                                       \
    __asm__ volatile(load "\n\t"                                                                \
                     "mov %[n], %%r12d\n\t"                                                    \
                     "1: mov %[nr], %%eax\n\t"                                                 \
                     "syscall\n\t"                                                             \
                     "dec %%r12d\n\t"                                                          \
                     "jnz 1b\n\t" store                                                        \
                     : [o] "=m"(out)                                                           \
                     : [i] "m"(in), [n] "i"(YIELDS), [nr] "i"(SYS_sched_yield)                 \
                     : reg, "rax", "rcx", "r11", "r12", "memory")

__attribute__((target("avx"))) static int round_avx(uint64_t seed) {
    uint64_t in[4], out[4];
    for (int k = 0; k < 4; k++) in[k] = ~(seed * 7919u + (uint64_t)k);
    HOLD("vmovdqu %[i], %%ymm9", "vmovdqu %%ymm9, %[o]", "xmm9", in, out);
    int bad = 0;
    for (int k = 0; k < 4; k++) bad += in[k] != out[k];
    return bad;
}

__attribute__((target("avx512f"))) static int round_avx512(uint64_t seed) {
    uint64_t in[8], out[8];
    for (int k = 0; k < 8; k++) in[k] = seed * 1000003u + (uint64_t)k;
    HOLD("vmovdqu64 %[i], %%zmm17", "vmovdqu64 %%zmm17, %[o]", "xmm17", in, out);
    int bad = 0;
    for (int k = 0; k < 8; k++) bad += in[k] != out[k];
    return bad;
}

static void *run(void *arg) {
    uint64_t id = (uintptr_t)arg;
    int bad = 0;
    for (uint64_t r = 0; r < ROUNDS; r++) {
        bad += round_avx(id * 65537u + r);
        if (have_avx512) bad += round_avx512(id * 65537u + r);
    }
    pthread_mutex_lock(&lost_lock);
    lost += bad;
    pthread_mutex_unlock(&lost_lock);
    return NULL;
}

int main(void) {
    __builtin_cpu_init();
    if (!__builtin_cpu_supports("avx")) {
        printf("uml-fp-check: no AVX on this CPU: nothing to check\n");
        return 0;
    }
    have_avx512 = __builtin_cpu_supports("avx512f");
    pthread_t t[THREADS];
    for (uintptr_t i = 0; i < THREADS; i++) pthread_create(&t[i], NULL, run, (void *)(i + 1));
    for (int i = 0; i < THREADS; i++) pthread_join(t[i], NULL);
    printf("uml-fp-check: %d threads x %d rounds, ymm9%s: %d values lost\n", THREADS, ROUNDS,
           have_avx512 ? " and zmm17" : "", lost);
    return lost != 0;
}
