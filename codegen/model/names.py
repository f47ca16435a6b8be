"""The one rule for names that become C identifiers: an observer's name and its model's signals.

An observer's name prefixes every identifier of its C API, names its CasADi functions and its
extension module (``_NAME``); a signal's name is a field of the step's C structs (``x.v_y``) and of
the Python API. Such a name must therefore be an identifier in C, C++ and CasADi at once,
and must not be expanded by the preprocessor of the headers the generated C includes (a state
called ``NAN``, ``errno`` or ``M_PI`` is a macro there, one called ``int`` a keyword). The rule:

* ASCII letters, digits and single underscores, starting with a letter and not ending with an
  underscore (C reserves ``_X`` and ``__`` anywhere; CasADi refuses ``__`` and a leading ``_``, and
  ``NAME_next`` must not hold ``__``);
* not a keyword of C (C99, C11) or of C++ (the header is included from C++ too);
* not an object-like macro of the C standard headers, POSIX's ``<math.h>``/``<errno.h>`` or
  ``<stdbool.h>`` (:data:`MACROS`), nor one that GNU C or the C library defines with them in a user's
  build (``linux``, ``M_PIl``, ``MAXFLOAT``, ``typeof``: :data:`GNU_MACROS`), nor under a prefix those
  headers, Python's, numpy's or CasADi's reserve for their macros (:data:`RESERVED_PREFIXES`).

It is checked at the first verb that reads the name (``uiogen new``, and any verb that reads the
observer file or imports the model), as one typed line naming the name and the rule.
"""
from __future__ import annotations

import re

_SHAPE = re.compile(r"[A-Za-z](?:_?[A-Za-z0-9])*")

C_KEYWORDS = frozenset(
    "auto break case char const continue default do double else enum extern float for goto if inline int long "
    "register restrict return short signed sizeof static struct switch typedef union unsigned void volatile "
    "while _Alignas _Alignof _Atomic _Bool _Complex _Generic _Imaginary _Noreturn _Static_assert "
    "_Thread_local".split())
CXX_KEYWORDS = frozenset(
    "alignas alignof and and_eq asm bitand bitor bool catch char8_t char16_t char32_t class compl concept consteval "
    "constexpr constinit const_cast co_await co_return co_yield decltype delete dynamic_cast explicit export false "
    "friend mutable namespace new noexcept not not_eq nullptr operator or or_eq private protected public "
    "reinterpret_cast requires static_assert static_cast template this thread_local throw true try typeid typename "
    "using virtual wchar_t xor xor_eq".split())

# object-like macros of <errno.h>, <float.h>, <limits.h>, <math.h> (with POSIX's M_*), <stdbool.h>,
# <stddef.h>, <stdint.h>, <stdio.h>, <stdlib.h>, <string.h>, <time.h>, <assert.h>, <signal.h>, <locale.h>
MACROS = frozenset("""
NAN INFINITY HUGE_VAL HUGE_VALF HUGE_VALL MATH_ERRNO MATH_ERREXCEPT math_errhandling FP_NAN FP_INFINITE FP_ZERO
FP_SUBNORMAL FP_NORMAL FP_FAST_FMA FP_FAST_FMAF FP_FAST_FMAL FP_ILOGB0 FP_ILOGBNAN DECIMAL_DIG
M_E M_LOG2E M_LOG10E M_LN2 M_LN10 M_PI M_PI_2 M_PI_4 M_1_PI M_2_PI M_2_SQRTPI M_SQRT2 M_SQRT1_2
errno EDOM ERANGE EILSEQ EOF BUFSIZ FILENAME_MAX FOPEN_MAX L_tmpnam SEEK_CUR SEEK_END SEEK_SET TMP_MAX stdin
stdout stderr NULL EXIT_FAILURE EXIT_SUCCESS RAND_MAX MB_CUR_MAX MB_LEN_MAX CLOCKS_PER_SEC TIME_UTC bool true
false assert offsetof CHAR_BIT CHAR_MAX CHAR_MIN SCHAR_MAX SCHAR_MIN UCHAR_MAX SHRT_MAX SHRT_MIN USHRT_MAX
INT_MAX INT_MIN UINT_MAX LONG_MAX LONG_MIN ULONG_MAX LLONG_MAX LLONG_MIN ULLONG_MAX SIZE_MAX PTRDIFF_MAX
PTRDIFF_MIN SIG_ATOMIC_MAX SIG_ATOMIC_MIN WCHAR_MAX WCHAR_MIN WINT_MAX WINT_MIN INTPTR_MAX INTPTR_MIN
UINTPTR_MAX INTMAX_MAX INTMAX_MIN UINTMAX_MAX SIGABRT SIGFPE SIGILL SIGINT SIGSEGV SIGTERM SIG_DFL SIG_ERR
SIG_IGN LC_ALL LC_COLLATE LC_CTYPE LC_MONETARY LC_NUMERIC LC_TIME FLT_RADIX FLT_ROUNDS FLT_EVAL_METHOD
""".split())

# what the same headers define beyond the standards in the modes a user's own build compiles them in (GCC's
# and Clang's default GNU C, glibc's _DEFAULT_SOURCE): the predefined system names (``linux``, ``unix``,
# ``i386``), GNU C's and C23's keywords ``typeof``/``typeof_unqual``, <math.h>'s typed constants
# (``M_PIl``, ``M_Ef128``), ``MAXFLOAT``, ``SNAN``, ``HUGE_VAL_F64``, C23's ``*_WIDTH``, and what <stdlib.h>
# and <stdio.h> pull in (<endian.h>, <sys/select.h>, the wait() options, renameat2's flags)
_MATH_CONSTANTS = "E LOG2E LOG10E LN2 LN10 PI PI_2 PI_4 1_PI 2_PI 2_SQRTPI SQRT2 SQRT1_2".split()
_FLOAT_SUFFIXES = ("f", "l", "f16", "f32", "f64", "f128", "f32x", "f64x", "f128x")
GNU_MACROS = frozenset("""
linux unix i386 typeof typeof_unqual MAXFLOAT HUGE SNAN SNANF SNANL BIG_ENDIAN LITTLE_ENDIAN PDP_ENDIAN
BYTE_ORDER FD_SETSIZE NFDBITS L_ctermid L_cuserid P_tmpdir RENAME_EXCHANGE RENAME_NOREPLACE RENAME_WHITEOUT
SEEK_DATA SEEK_HOLE WNOHANG WUNTRACED WSTOPPED WEXITED WCONTINUED WNOWAIT BOOL_WIDTH BOOL_MAX CHAR_WIDTH
SCHAR_WIDTH UCHAR_WIDTH SHRT_WIDTH USHRT_WIDTH INT_WIDTH UINT_WIDTH LONG_WIDTH ULONG_WIDTH LLONG_WIDTH
ULLONG_WIDTH INTMAX_WIDTH UINTMAX_WIDTH INTPTR_WIDTH UINTPTR_WIDTH PTRDIFF_WIDTH SIZE_WIDTH WCHAR_WIDTH WINT_WIDTH
""".split()) | {f"M_{c}{s}" for c in _MATH_CONSTANTS for s in _FLOAT_SUFFIXES} | {
    f"{base}{s.upper()}" for base in ("SNAN", "HUGE_VAL_") for s in _FLOAT_SUFFIXES if s[0] == "f" and s != "f"} | {
    f"SNAN{s.upper()}" for s in _FLOAT_SUFFIXES}

# prefixes of macro families: C's <errno.h> (E + digit or capital), <float.h>, <stdint.h>, <inttypes.h>,
# <signal.h>, <locale.h>; Python's, numpy's and CasADi's headers
RESERVED_PREFIXES = ("FLT_", "DBL_", "LDBL_", "INT8_", "INT16_", "INT32_", "INT64_", "UINT8_", "UINT16_",
                     "UINT32_", "UINT64_", "INT_LEAST", "UINT_LEAST", "INT_FAST", "UINT_FAST", "PRI", "SCN",
                     "SIG_", "LC_", "FP_", "Py", "PY", "NPY", "npy_", "casadi_", "CASADI")
_ERRNO = re.compile(r"E[0-9A-Z][0-9A-Z_]*")


def c_name_problem(name: str) -> str | None:
    """Why ``name`` cannot be a C identifier of the generated code (module docstring), or None."""
    if not isinstance(name, str) or not name.isascii() or not _SHAPE.fullmatch(name):
        return ("is not made of ASCII letters, digits and single underscores, starting with a letter and not "
                "ending with an underscore")
    if name in C_KEYWORDS:
        return "is a C keyword"
    if name in CXX_KEYWORDS:
        return "is a C++ keyword (the generated header is included from C++ too)"
    if name in MACROS:
        return "is a macro of the C standard headers the generated C includes"
    if name in GNU_MACROS:
        return ("is a macro or keyword of GNU C (the compilers' default mode) or of the C library's headers the "
                "generated C includes, in a user's build of them")
    if _ERRNO.fullmatch(name):
        return "is in the names <errno.h> reserves for its macros (E followed by a digit or capital)"
    prefix = next((p for p in RESERVED_PREFIXES if name.startswith(p)), None)
    if prefix is not None:
        return f"starts with {prefix!r}, reserved for the macros of a header the generated C includes"
    return None


RULE = ("ASCII letters, digits and single underscores, starting with a letter, not ending with '_', not a C or "
        "C++ keyword, not a macro of the C headers (NAN, errno, M_PI, EOF, ...)")


def suggest(name: str) -> str:
    """A name close to ``name`` that passes (for the messages)."""
    s = re.sub(r"_+", "_", re.sub(r"[^A-Za-z0-9]", "_", str(name))).strip("_") or "signal"
    if not s[0].isalpha():
        s = f"s_{s}"
    return s if c_name_problem(s) is None else f"{s.lower()}_sig" if c_name_problem(f"{s.lower()}_sig") is None \
        else "signal"
