/*
 * pyconfig.h for cross-building vibsynth's extensions for Windows x64 (win_amd64) with
 * mingw-w64's gcc, against the limited API (Py_LIMITED_API, abi3). scripts/crossbuild.py puts
 * this folder first on the include path, before a CPython include folder of this machine: the
 * limited-API headers are the same on every system but for this file, which configure writes
 * per system. No package registry ships Windows CPython headers, so this one is kept here.
 *
 * It states only what the limited-API headers read (checked by compiling: a missing size is an
 * #error in pyport.h), for a 64-bit Windows process (LLP64: long is 32 bits, wchar_t 16) and a
 * CPython built as a DLL, whose API is imported with __declspec(dllimport) from python3.dll.
 */
#ifndef Py_CONFIG_H
#define Py_CONFIG_H

#if !defined(_WIN64) || !defined(__GNUC__)
#error "scripts/cross/win/pyconfig.h is for x86_64-w64-mingw32-gcc (64-bit Windows) only"
#endif
#ifndef Py_LIMITED_API
#error "scripts/cross/win/pyconfig.h serves limited-API (abi3) builds only"
#endif

#include <io.h>
#include <stdio.h>

/* the platform */
#define MS_WIN32
#define MS_WIN64
#define MS_WINDOWS
#define NT_THREADS
#define WITH_THREAD
#define PLATFORM "win32"
#define COMPILER "[gcc]"
#define WITH_DOC_STRINGS 1

/* the core is a DLL: PyAPI_FUNC/PyAPI_DATA are dllimport, PyMODINIT_FUNC is dllexport */
#define Py_ENABLE_SHARED 1
#define MS_COREDLL
#define HAVE_DECLSPEC_DLL

/* LLP64 */
#define SIZEOF_SHORT 2
#define SIZEOF_INT 4
#define SIZEOF_LONG 4
#define SIZEOF_LONG_LONG 8
#define SIZEOF_FLOAT 4
#define SIZEOF_DOUBLE 8
#define SIZEOF_VOID_P 8
#define SIZEOF_SIZE_T 8
#define SIZEOF_TIME_T 8
#define SIZEOF_OFF_T 4
#define SIZEOF_FPOS_T 8
#define SIZEOF_WCHAR_T 2
#define SIZEOF__BOOL 1
#define LONG_BIT 32
#define WORD_BIT 32
#define PY_LONG_LONG long long
#define PY_LLONG_MIN LLONG_MIN
#define PY_LLONG_MAX LLONG_MAX
#define PY_ULLONG_MAX ULLONG_MAX
#define HAVE_SSIZE_T 1 /* mingw-w64's <sys/types.h> has a 64-bit ssize_t */
#define HAVE_UINTPTR_T 1
#define HAVE_INTPTR_T 1

/* the C library (the Universal CRT or msvcrt) */
#define HAVE_STDDEF_H 1
#define HAVE_WCHAR_H 1
#define HAVE_SYS_STAT_H 1
#define HAVE_COPYSIGN 1
#define HAVE_ROUND 1
#define HAVE_HYPOT 1
#define HAVE_DECL_ISINF 1
#define HAVE_DECL_ISNAN 1
#define HAVE_DECL_ISFINITE 1

#endif /* Py_CONFIG_H */
