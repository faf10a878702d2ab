/*
 * User-mode Linux on a host with AMX: an LD_PRELOAD shim for linux.uml (tests/vcan/run.sh).
 *
 * Why: Debian's UML 6.1 saves and restores its processes' FP state with
 * PTRACE_GETREGSET/SETREGSET (NT_X86_XSTATE) in a buffer sized for AVX-512 (2696 bytes).
 * The host kernel reads such a buffer only whole (xstateregs_set: count must equal the
 * host's XSAVE size), which AMX's tile state makes about 11 KB: every restore fails with
 * EFAULT ("ptrace set fp regs failed, errno = 14") and UML's init dies at boot.
 *
 * What: a restore shorter than the host's size is sent whole, the part UML did not hold
 * (the AMX tile components: no process in UML can use them, it never grants their permission)
 * zeroed and marked in its initial state in the XSAVE header. Every other call goes to libc.
 */
#define _GNU_SOURCE
#include <cpuid.h>
#include <dlfcn.h>
#include <elf.h>
#include <stdarg.h>
#include <stdint.h>
#include <string.h>
#include <sys/ptrace.h>
#include <sys/types.h>
#include <sys/uio.h>

typedef long (*ptrace_fn)(enum __ptrace_request, ...);

static long real_ptrace(enum __ptrace_request req, pid_t pid, void *addr, void *data) {
  static ptrace_fn real;
  if (!real) real = (ptrace_fn)dlsym(RTLD_NEXT, "ptrace");
  return real(req, pid, addr, data);
}

/* The whole XSAVE area, aligned as XSAVE wants it: AMX makes it about 11 KB. */
static unsigned char whole[64 * 1024] __attribute__((aligned(64)));
static size_t host_size;

/* The size the host's ptrace wants: a GETREGSET with room for anything says. */
static size_t xstate_size(pid_t pid) {
  if (!host_size) {
    struct iovec iov = {whole, sizeof whole};
    if (real_ptrace(PTRACE_GETREGSET, pid, (void *)NT_X86_XSTATE, &iov) == 0) host_size = iov.iov_len;
  }
  return host_size;
}

long ptrace(enum __ptrace_request req, ...) {
  va_list ap;
  va_start(ap, req);
  pid_t pid = va_arg(ap, pid_t);
  void *addr = va_arg(ap, void *);
  void *data = va_arg(ap, void *);
  va_end(ap);
  if (req == PTRACE_SETREGSET && (uintptr_t)addr == NT_X86_XSTATE && data) {
    struct iovec *iov = data;
    size_t want = xstate_size(pid);
    if (want > iov->iov_len && want <= sizeof whole && iov->iov_len >= 576) {
      size_t have = iov->iov_len;
      memcpy(whole, iov->iov_base, have);
      memset(whole + have, 0, want - have);
      /* Components that lie beyond what UML held: in their initial state. */
      uint64_t bv;
      memcpy(&bv, whole + 512, sizeof bv);
      for (unsigned i = 2; i < 64; i++) {
        unsigned size, offset, ecx, edx;
        if (!(bv & (1ull << i))) continue;
        __cpuid_count(0xd, i, size, offset, ecx, edx);
        if ((size_t)offset + size > have) bv &= ~(1ull << i);
      }
      memcpy(whole + 512, &bv, sizeof bv);
      struct iovec full = {whole, want};
      return real_ptrace(req, pid, addr, &full);
    }
  }
  return real_ptrace(req, pid, addr, data);
}
