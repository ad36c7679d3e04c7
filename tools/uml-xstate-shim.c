/*
 * LD_PRELOAD shim for Debian bookworm's User-Mode Linux (6.1) on hosts whose CPU has AMX.
 *
 * Why: UML keeps each guest task's FP registers in a buffer of fixed size, set when the package
 * was built (2696 bytes here: the XSAVE area up to AVX-512), and moves them between its memory
 * and the host process running the task with ptrace(PTRACE_GETREGSET/PTRACE_SETREGSET,
 * NT_X86_XSTATE). The host kernel lets a GETREGSET be shorter than the CPU's XSAVE area (it
 * truncates) but refuses any SETREGSET that is not exactly the whole area
 * (arch/x86/kernel/fpu/regset.c, xstateregs_set: count != fpu_user_cfg.max_size -> EFAULT). With
 * AMX's tile data the area is 11008 bytes, so the first switch to the guest's init fails
 * ("userspace - ptrace set fp regs failed, errno = 14") and the guest panics at boot. Upstream
 * UML sizes the buffer from the host since (host_fp_size); bookworm's package does not.
 *
 * What: this shim wraps libc's ptrace() in the UML process. A NT_X86_XSTATE SETREGSET shorter
 * than the host's area is written as the whole area: UML's bytes, then the rest. The XSAVE
 * header in UML's bytes (XSTATE_BV) says which components hold state; the kernel reads only
 * those. When all of them lie within UML's bytes (always, in practice: the components past
 * AVX-512 are AMX's, which a process must ask the host kernel for and UML's guests cannot), the
 * rest is zeros and the write is exact. Otherwise the rest is the host process's current area,
 * which the task left there. Every other ptrace request goes to libc unchanged, and on a host
 * whose area fits UML's buffer nothing changes at all.
 *
 * Built and preloaded by tools/in-vcan.sh; never linked into canmotion.
 */
#define _GNU_SOURCE
#include <cpuid.h>
#include <dlfcn.h>
#include <elf.h>
#include <errno.h>
#include <stdarg.h>
#include <stdint.h>
#include <string.h>
#include <sys/mman.h>
#include <sys/ptrace.h>
#include <sys/types.h>
#include <sys/uio.h>

#ifndef NT_X86_XSTATE
#define NT_X86_XSTATE 0x202
#endif
#define XSAVE_HEADER 512 /* offset of XSTATE_BV in the standard-format area */
#define PROBE_BYTES (1 << 16)

typedef long (*ptrace_fn)(int, pid_t, void *, void *);

static ptrace_fn real_ptrace;
static size_t host_size;           /* bytes of the host's XSAVE area; 0 until read */
static uint32_t component_end[64]; /* end offset of each XSAVE component (CPUID 0xD) */
static unsigned char *area;        /* scratch of host_size bytes */
static volatile int lock;

__attribute__((constructor)) static void init(void) {
    real_ptrace = (ptrace_fn)dlsym(RTLD_NEXT, "ptrace");
    /* x87 and SSE live in the legacy area, which UML always has. */
    for (unsigned i = 2; i < 64; i++) {
        unsigned a, b, c, d;
        if (__get_cpuid_count(0xD, i, &a, &b, &c, &d) && a) component_end[i] = b + a;
    }
}

static long regset(int req, pid_t pid, void *buf, size_t len, size_t *got) {
    struct iovec iov = {buf, len};
    long r = real_ptrace(req, pid, (void *)(uintptr_t)NT_X86_XSTATE, &iov);
    if (got) *got = iov.iov_len;
    return r;
}

/* The host's area size, read once from a tracee (a longer GETREGSET is cut to the area). */
static size_t area_size(pid_t pid) {
    if (host_size) return host_size;
    unsigned char *probe =
        mmap(NULL, PROBE_BYTES, PROT_READ | PROT_WRITE, MAP_PRIVATE | MAP_ANONYMOUS, -1, 0);
    if (probe == MAP_FAILED) return 0;
    size_t got = 0;
    if (regset(PTRACE_GETREGSET, pid, probe, PROBE_BYTES, &got) == 0 && got > XSAVE_HEADER + 64 &&
        got < PROBE_BYTES) {
        area = probe; /* kept as the scratch buffer */
        host_size = got;
        return host_size;
    }
    munmap(probe, PROBE_BYTES);
    return 0;
}

static long set_short(pid_t pid, const struct iovec *iov) {
    size_t have = iov->iov_len;
    uint64_t in_use = 0;
    if (have >= XSAVE_HEADER + 8) memcpy(&in_use, (const char *)iov->iov_base + XSAVE_HEADER, 8);
    int fits = have >= XSAVE_HEADER + 64;
    for (unsigned i = 2; i < 64 && fits; i++)
        if ((in_use >> i & 1) && component_end[i] > have) fits = 0;
    while (__atomic_exchange_n(&lock, 1, __ATOMIC_ACQUIRE)) {
    }
    long r = 0;
    size_t got = host_size;
    if (fits)
        memset(area + have, 0, host_size - have);
    else
        r = regset(PTRACE_GETREGSET, pid, area, host_size, &got);
    if (r == 0 && got == host_size) {
        memcpy(area, iov->iov_base, have);
        r = regset(PTRACE_SETREGSET, pid, area, host_size, NULL);
    } else if (r == 0) {
        errno = EFAULT;
        r = -1;
    }
    __atomic_store_n(&lock, 0, __ATOMIC_RELEASE);
    return r;
}

long ptrace(enum __ptrace_request request, ...) {
    va_list ap;
    va_start(ap, request);
    pid_t pid = va_arg(ap, pid_t);
    void *addr = va_arg(ap, void *);
    void *data = va_arg(ap, void *);
    va_end(ap);
    if (request == PTRACE_SETREGSET && (uintptr_t)addr == NT_X86_XSTATE && data) {
        const struct iovec *iov = data;
        size_t size = area_size(pid);
        if (size && iov->iov_len < size) return set_short(pid, iov);
    }
    return real_ptrace(request, pid, addr, data);
}
