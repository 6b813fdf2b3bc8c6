/*
 * pyconfig.h for cross-building vibsynth's extensions for macOS (arm64 and x86_64) with
 * `zig cc` (the ziglang package), against the limited API (Py_LIMITED_API, abi3).
 * scripts/crossbuild.py puts this folder first on the include path, before a CPython include
 * folder of this machine: the limited-API headers are the same on every system but for this
 * file, which configure writes per system.
 *
 * It states only what the limited-API headers read (checked by compiling), for macOS 10.9 and
 * later on either architecture (LP64, little-endian). Python.h's pymacconfig.h restates the
 * sizes per architecture, as it does for CPython's own universal2 builds.
 */
#ifndef Py_CONFIG_H
#define Py_CONFIG_H

#if !defined(__APPLE__) || !defined(__LP64__)
#error "scripts/cross/macos/pyconfig.h is for 64-bit macOS targets only"
#endif
#ifndef Py_LIMITED_API
#error "scripts/cross/macos/pyconfig.h serves limited-API (abi3) builds only"
#endif

/* what CPython's macOS configure asks of the system headers */
#define _DARWIN_C_SOURCE 1
#define WITH_DOC_STRINGS 1
#define WITH_THREAD 1

/* LP64 */
#define SIZEOF_SHORT 2
#define SIZEOF_INT 4
#define SIZEOF_LONG 8
#define SIZEOF_LONG_LONG 8
#define SIZEOF_FLOAT 4
#define SIZEOF_DOUBLE 8
#define SIZEOF_VOID_P 8
#define SIZEOF_SIZE_T 8
#define SIZEOF_TIME_T 8
#define SIZEOF_OFF_T 8
#define SIZEOF_FPOS_T 8
#define SIZEOF_PID_T 4
#define SIZEOF_WCHAR_T 4
#define SIZEOF_UINTPTR_T 8
#define SIZEOF__BOOL 1
#define HAVE_SSIZE_T 1
#define HAVE_UINTPTR_T 1
#define HAVE_INTPTR_T 1

/* the system headers Python.h may include */
#define HAVE_UNISTD_H 1
#define HAVE_STDINT_H 1
#define HAVE_INTTYPES_H 1
#define HAVE_STDDEF_H 1
#define HAVE_WCHAR_H 1
#define HAVE_SYS_TYPES_H 1
#define HAVE_SYS_STAT_H 1
#define HAVE_SYS_TIME_H 1
#define HAVE_SYS_SELECT_H 1
#define HAVE_FORK 1
#define HAVE_KQUEUE 1
#define HAVE_COPYSIGN 1
#define HAVE_ROUND 1
#define HAVE_HYPOT 1
#define HAVE_DECL_ISINF 1
#define HAVE_DECL_ISNAN 1
#define HAVE_DECL_ISFINITE 1

#endif /* Py_CONFIG_H */
