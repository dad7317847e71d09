"""The batched kernel's generated functions compiled as C, for the machine's C compiler to schedule.

Why: the generated stage (``eelsim.batch.codegen``) is one long straight-line block per lane loop,
and how fast it runs is decided by instruction scheduling and register allocation, not by the
arithmetic. Measured on the same text, GCC's schedule of the stage is 11-19 % faster than
LLVM's (numba's) on the GA generation and the stage alone (docs/kernel_history.md, session 4).

The C text is not written by hand: :func:`translate` reads the generated Python function with
``ast`` and writes the same statements in C, expression by expression (the generated code uses a
small subset: assignments, ``for r in range(k)``, ``if``/``else``, arithmetic, comparisons,
conditional expressions, ``abs``, ``min``, ``max``, ``np.floor``, ``np.inf``, ``_vsqrt``). So
there is one generator and one physics; the numba function stays the fallback when no C compiler
is found and the cross-check in the tests. ``min``/``max`` keep Python's (and numba's) rule
``min(a, b) = b if b < a else a`` so that NaNs travel the same way.

The library is built once per (text, compiler, flags, CPU) into the kernel cache folder and bound
into the numba kernel by symbol name (``numba.types.ExternalFunction``), which keeps numba's disk
cache valid: the compiled driver refers to the symbol, not to an address.
"""

from __future__ import annotations

import ast
import functools
import hashlib
import logging
import os
import shutil
import subprocess
from pathlib import Path

logger = logging.getLogger(__name__)

# -O3 with the host's vector units; contraction to FMA as numba's fastmath={"contract"};
# floor inlines (and the lane loops vectorise) only without trapping-math and errno
C_FLAGS = ("-O3", "-march=native", "-ffp-contract=fast", "-fno-trapping-math", "-fno-math-errno",
           "-fPIC", "-shared")

# Added to C_FLAGS on a CPU with AVX-512 that the compiler has no model of: GCC 12 takes this
# VM's AMD Zen 4 for a Zen 3 (-march=native: the instructions of the CPU, the tuning of znver3).
# GCC's tuning for Intel's AVX-512 servers, with 512-bit vectors kept, measured 0.96-0.98 of the
# stage's time and 0.97 of a GA generation's, results bit-identical (docs/kernel_history.md,
# session 11); the other Intel AVX-512 tunings did about as well, 256-bit vectors 1.65 times
# worse. A CPU the compiler knows keeps its own tuning.
AVX512_TUNING = ("-mtune=icelake-server", "-mprefer-vector-width=512")

# the -march values GCC resolves -march=native to for the AVX-512 CPUs it knows
_KNOWN_AVX512 = ("skylake-avx512", "cannonlake", "icelake", "cascadelake", "tigerlake",
                 "cooperlake", "sapphirerapids", "rocketlake", "knl", "knm", "znver4", "znver5",
                 "graniterapids", "emeraldrapids", "diamondrapids")

# the generated functions' flag arguments (bool in Python, int64 in C); every other scalar
# argument is a float64, ``work`` the buffer
_FLAG_ARGS = ("first", "last", "rotate", "advance", "plain")

_PRELUDE = """#include <math.h>
#include <stdint.h>

/* Python's (and numba's) min and max of two floats: min(a, b) is b if b < a else a */
static inline double py_min(double a, double b) { return b < a ? b : a; }
static inline double py_max(double a, double b) { return b > a ? b : a; }
"""

_BINARY = {ast.Add: "+", ast.Sub: "-", ast.Mult: "*", ast.Div: "/"}
_COMPARE = {ast.Lt: "<", ast.LtE: "<=", ast.Gt: ">", ast.GtE: ">=", ast.Eq: "==", ast.NotEq: "!="}


class CStageError(RuntimeError):
    """The C stage could not be translated or compiled."""


class _Translator:
    """Statements and expressions of the generated subset, written as C."""

    def __init__(self, integers: set[str]) -> None:
        self.doubles: set[str] = set()  # locals assigned a value: declared double at the top
        self.integers = set(integers)  # loop counters and flag arguments
        self.lines: list[str] = []

    def expr(self, node: ast.expr) -> str:
        if isinstance(node, ast.BinOp) and type(node.op) in _BINARY:
            return f"({self.expr(node.left)} {_BINARY[type(node.op)]} {self.expr(node.right)})"
        if isinstance(node, ast.UnaryOp) and isinstance(node.op, ast.USub):
            return f"(-{self.expr(node.operand)})"
        if isinstance(node, ast.Constant) and isinstance(node.value, (int, float)):
            value = node.value
            if isinstance(value, bool):
                return "1" if value else "0"
            if isinstance(value, int):
                return str(value)
            text = repr(float(value))  # repr round-trips a double exactly
            if text in ("inf", "-inf", "nan"):
                raise CStageError(f"literal {text} in the generated code")
            return text if ("e" in text or "." in text) else text + ".0"
        if isinstance(node, ast.Name):
            return node.id
        if isinstance(node, ast.Attribute) and node.attr == "inf":
            return "INFINITY"
        if isinstance(node, ast.Subscript) and isinstance(node.value, ast.Name):
            return f"{node.value.id}[{self.expr(node.slice)}]"
        if isinstance(node, ast.Compare) and len(node.ops) == 1:
            op = _COMPARE[type(node.ops[0])]
            return f"({self.expr(node.left)} {op} {self.expr(node.comparators[0])})"
        if isinstance(node, ast.IfExp):
            test, body, other = self.expr(node.test), self.expr(node.body), self.expr(node.orelse)
            return f"({test} ? {body} : {other})"
        if isinstance(node, ast.Call) and not node.keywords:
            func = node.func
            name = func.id if isinstance(func, ast.Name) else getattr(func, "attr", "")
            args = [self.expr(a) for a in node.args]
            if name == "abs" and len(args) == 1:
                return f"fabs({args[0]})"
            if name == "_vsqrt" and len(args) == 1:  # the kernel's vectorising sqrt
                return f"sqrt({args[0]})"
            if name == "floor" and len(args) == 1:
                return f"floor({args[0]})"
            if name in ("min", "max") and len(args) >= 2:
                result = args[0]
                for arg in args[1:]:  # left to right, as Python folds them
                    result = f"py_{name}({result}, {arg})"
                return result
        raise CStageError(f"line {node.lineno}: no C for {ast.unparse(node)!r}")

    def statement(self, node: ast.stmt, depth: int) -> None:
        pad = "    " * depth
        if isinstance(node, ast.Assign) and len(node.targets) == 1:
            target = node.targets[0]
            if isinstance(target, ast.Name) and target.id not in self.integers:
                self.doubles.add(target.id)
            self.lines.append(f"{pad}{self.expr(target)} = {self.expr(node.value)};")
        elif (isinstance(node, ast.For) and isinstance(node.target, ast.Name)
              and isinstance(node.iter, ast.Call) and getattr(node.iter.func, "id", "") == "range"
              and len(node.iter.args) == 1 and not node.orelse):
            counter = node.target.id
            self.integers.add(counter)
            stop = self.expr(node.iter.args[0])
            self.lines.append(f"{pad}for (int64_t {counter} = 0; {counter} < {stop}; {counter}++) {{")
            self.block(node.body, depth + 1)
            self.lines.append(f"{pad}}}")
        elif isinstance(node, ast.If):
            self.lines.append(f"{pad}if ({self.expr(node.test)}) {{")
            self.block(node.body, depth + 1)
            if node.orelse:
                self.lines.append(f"{pad}}} else {{")
                self.block(node.orelse, depth + 1)
            self.lines.append(f"{pad}}}")
        elif isinstance(node, ast.Expr) and isinstance(node.value, ast.Constant):
            pass  # the docstring
        else:
            raise CStageError(f"line {node.lineno}: no C for {ast.unparse(node)!r}")

    def block(self, body: list[ast.stmt], depth: int) -> None:
        for node in body:
            self.statement(node, depth)


def translate(source: str, function: str, symbol: str) -> str:
    """C text of the generated function ``function`` in ``source``, named ``symbol``.

    Parameters
    ----------
    source : str
        Python text holding ``def function(work, ...)`` in the generated subset.
    function : str
        Name of the function to translate.
    symbol : str
        Name of the C function.

    Returns
    -------
    str
        A C function definition (``void symbol(double *restrict work, ...)``).

    Raises
    ------
    CStageError
        If the function is missing or uses a construct outside the subset (the message names
        the line and the expression).
    """
    node = _functions(source).get(function)
    if node is None:
        raise CStageError(f"no function {function!r} in the generated source")
    names = [a.arg for a in node.args.args]
    if not names or names[0] != "work":
        raise CStageError(f"{function}: the first argument must be the buffer 'work'")
    params = ["double *restrict work"]
    params += [f"int64_t {a}" if a in _FLAG_ARGS else f"double {a}" for a in names[1:]]
    tr = _Translator(set(_FLAG_ARGS))
    tr.block(node.body, 1)
    decl = [f"    double {', '.join(sorted(tr.doubles))};"] if tr.doubles else []
    head = f"void {symbol}({', '.join(params)})"
    return "\n".join([f"{head} {{", *decl, *tr.lines, "}", ""])


def c_source(source: str, functions: tuple[str, ...], prefix: str) -> str:
    """The C file for ``functions`` of the generated ``source``: prelude and translations.

    Parameters
    ----------
    source : str
        The generated Python text.
    functions : tuple of str
        Names of the generated functions to translate.
    prefix : str
        Each C function is named ``prefix + name``.

    Returns
    -------
    str
    """
    return _PRELUDE + "\n".join(translate(source, f, prefix + f) for f in functions)


def _functions(source: str) -> dict[str, ast.FunctionDef]:
    """The module-level functions of a generated text, by name."""
    return {n.name: n for n in ast.parse(source).body if isinstance(n, ast.FunctionDef)}


def find_compiler() -> str | None:
    """The C compiler to use: $CC if set, else the first of cc, gcc, clang on the PATH.

    Returns
    -------
    str or None
        Path or name of the compiler; None when there is none.
    """
    chosen = os.environ.get("CC")
    if chosen:
        return chosen
    for name in ("cc", "gcc", "clang"):
        path = shutil.which(name)
        if path:
            return path
    return None


@functools.cache
def compile_flags(compiler: str) -> tuple[str, ...]:
    """The flags the C stage is compiled with: C_FLAGS, tuned for an AVX-512 CPU GCC does not know.

    Parameters
    ----------
    compiler : str
        The C compiler.

    Returns
    -------
    tuple of str
        C_FLAGS, with AVX512_TUNING after ``-march=native`` when the host CPU has AVX-512 and
        the compiler (GCC) resolves ``-march=native`` to a CPU without it.
    """
    if "+avx512f" not in _host_cpu():
        return C_FLAGS
    try:
        done = subprocess.run([compiler, "-march=native", "-Q", "--help=target"],
                              capture_output=True, text=True, check=False, timeout=60)
    except (OSError, subprocess.SubprocessError):
        return C_FLAGS
    march = next((line.split()[1] for line in done.stdout.splitlines()
                  if line.split()[:1] == ["-march="] and len(line.split()) > 1), None)
    if done.returncode != 0 or march is None or march.startswith(_KNOWN_AVX512):
        return C_FLAGS  # not GCC (clang has no -Q --help=target), or a CPU it knows
    at = C_FLAGS.index("-march=native") + 1
    return C_FLAGS[:at] + AVX512_TUNING + C_FLAGS[at:]


def _host_cpu() -> str:
    # part of the library's key: -march=native code must not run on another CPU from a shared
    # cache folder
    import llvmlite.binding as llvm

    return f"{llvm.get_host_cpu_name()} {llvm.get_host_cpu_features().flatten()}"


def build(source: str, functions: tuple[str, ...], folder: Path,
          compiler: str | None = None) -> tuple[Path, dict[str, str]]:
    """Translate ``functions`` of the generated ``source`` to C and compile them to a library.

    The library (and its C text, for reading) is written to ``folder`` under a name made from a
    hash of the C text, the compiler, its flags and the host CPU; an existing one is reused. A
    small index file beside it names the library for a hash of the Python text (and of this
    module's translator), so that a later process finds it without translating again.

    Parameters
    ----------
    source : str
        The generated Python text (``codegen.generate_stage_source``).
    functions : tuple of str
        Names of the generated functions to compile.
    folder : Path
        Where the library goes (the kernel cache folder).
    compiler : str, optional
        C compiler (default :func:`find_compiler`).

    Returns
    -------
    (Path, dict)
        The shared library and, per Python function name, its C symbol.

    Raises
    ------
    CStageError
        No compiler, or the compiler failed (its message is included).
    """
    compiler = compiler or find_compiler()
    if compiler is None:
        raise CStageError("no C compiler found (set CC, or install gcc)")
    # a library built before is found from the Python text without translating it again: the
    # translation of a variant's three functions took most of a cached load (docs/durations.md,
    # session 23), and every process that runs the kernel loads its variants
    index = folder / f"eelsim_src_{_source_key(source, functions, compiler)}.stem"
    known = _known_library(index, functions)
    if known is not None:
        return known
    marker = "STAGE_SYMBOL_"
    text = c_source(source, functions, marker)
    # compile_flags follows from the compiler and the CPU, both in the key, and asks the
    # compiler (a process start) only when it compiles: the rule itself is in the key instead
    key = hashlib.sha256("\n".join([text, compiler, *C_FLAGS, *AVX512_TUNING, _host_cpu()])
                         .encode())
    stem = f"eelsim_c_{key.hexdigest()[:16]}"
    symbols = {f: f"{stem}{f}" for f in functions}
    text = text.replace(marker, stem)
    library = folder / f"{stem}.so"
    if library.exists():
        _write_index(index, stem)
        return library, symbols
    folder.mkdir(parents=True, exist_ok=True)
    logger.info("compiling the kernel's C stage with %s into %s", compiler, library)
    # each process writes and compiles its own files, then renames them into place (atomic):
    # concurrent processes never compile half a C file or load half a library
    c_path = folder / f"{stem}.c"
    own_c = folder / f"{stem}.tmp{os.getpid()}.c"
    own_c.write_text(text)
    partial = folder / f"{stem}.so.tmp{os.getpid()}"
    try:
        done = subprocess.run([compiler, *compile_flags(compiler), "-o", str(partial),
                               str(own_c)],
                              capture_output=True, text=True, check=False)
    except OSError as exc:
        own_c.unlink(missing_ok=True)
        raise CStageError(f"C compiler {compiler!r} could not be run: {exc}") from exc
    os.replace(own_c, c_path)  # kept beside the library, for reading (and the error below)
    if done.returncode != 0:
        partial.unlink(missing_ok=True)
        errors = done.stderr.strip().replace(str(own_c), str(c_path))
        raise CStageError(f"C compiler {compiler!r} failed on {c_path}:\n{errors}")
    os.replace(partial, library)
    _write_index(index, stem)
    return library, symbols


def _source_key(source: str, functions: tuple[str, ...], compiler: str) -> str:
    """A hash of everything the C library follows from, short of translating to C.

    The C text is a function of the generated Python text, the functions chosen and this module's
    translator, so the translator's own source is in the key: a change to it builds anew. The
    compiler, its flag rules and the host CPU are in it as in the C text's key (:func:`build`).
    """
    digest = _translator_digest().copy()
    for part in (source, *functions, compiler, *C_FLAGS, *AVX512_TUNING, _host_cpu()):
        digest.update(b"\0" + part.encode())
    return digest.hexdigest()[:16]


@functools.cache
def _translator_digest() -> hashlib._Hash:
    """The hash of this module's source, read once per process (every kernel load asks)."""
    return hashlib.sha256(Path(__file__).read_bytes())


def _known_library(index: Path, functions: tuple[str, ...]) -> tuple[Path, dict[str, str]] | None:
    """The library an index file names, with its symbols, when both exist; else None."""
    try:
        stem = index.read_text().strip()
    except OSError:
        return None
    library = index.parent / f"{stem}.so"
    if not stem.startswith("eelsim_c_") or not library.exists():
        return None
    return library, {f: f"{stem}{f}" for f in functions}


def _write_index(index: Path, stem: str) -> None:
    """Name the library ``stem`` for the Python text of ``index`` (atomic: write, then rename)."""
    partial = index.with_name(f"{index.name}.tmp{os.getpid()}")
    try:
        partial.write_text(stem + "\n")
        os.replace(partial, index)
    except OSError:  # a read-only cache folder: the library is still found from its C text
        partial.unlink(missing_ok=True)


def binding_source(library: Path, symbols: dict[str, str], source: str) -> str:
    """Python text that loads ``library`` and redefines the generated functions to call it.

    Appended after the generated part of the kernel module, so the driver's calls to, e.g.,
    ``_stage(work, ...)`` reach the C function (numba resolves the symbol at link time).

    Parameters
    ----------
    library : Path
        The shared library from :func:`build`.
    symbols : dict
        Python function name -> C symbol, from :func:`build`.
    source : str
        The generated Python text (for the functions' argument lists).

    Returns
    -------
    str
    """
    args = {name: [a.arg for a in node.args.args] for name, node in _functions(source).items()}
    lines = ["", "", "# ---- the generated functions compiled as C (eelsim.batch.c_stage)",
             "import llvmlite.binding as _llvm_binding", "",
             f"_llvm_binding.load_library_permanently({str(library)!r})"]
    for name, symbol in symbols.items():
        names = args[name]
        types = ["numba.types.intp"] + [
            "numba.types.int64" if a in _FLAG_ARGS else "numba.types.float64" for a in names[1:]]
        call = ", ".join(["_data_address(work)", *names[1:]])  # (kernel_template's)
        lines += [
            f"_C{name.upper()} = numba.types.ExternalFunction(",
            f"    {symbol!r}, numba.types.void({', '.join(types)}))",
            "",
            "",
            "@numba.njit(cache=True)",
            f"def {name}({', '.join(names)}):",
            f'    """{name} of the generated part, run by the C library."""',
            f"    _C{name.upper()}({call})",
            "",
            "",
        ]
    return "\n".join(lines)


def pointer_call_source(source: str, functions: tuple[str, ...]) -> str:
    """Python text defining ``_call<name>(fn, work, ...)``: the C function at address ``fn``.

    One per generated function, for the driver module (``eelsim.batch.loading.driver_module``),
    which redefines the template's direct calls with these: the address is an argument, so one
    compiled driver serves every variant's library (and numba's disk cache of it stays valid). The arguments are
    converted as :func:`translate` declares them: flags to int64, other scalars to float64. The
    intrinsic's code is ``kernel_template._pointer_call``.

    Parameters
    ----------
    source : str
        A generated Python text (for the functions' argument lists, the same for every law).
    functions : tuple of str
        Names of the generated functions.

    Returns
    -------
    str
    """
    args = {name: [a.arg for a in node.args.args] for name, node in _functions(source).items()}
    lines = ["", "", "# ---- the generated functions' C code, called by address "
             "(eelsim.batch.c_stage)"]
    for name in functions:
        names = args[name]
        c_types = ["types.int64" if a in _FLAG_ARGS else "types.float64" for a in names[1:]]
        listed = "".join(f"{t}, " for t in c_types)
        params = ", ".join(["fn", *names])
        lines += [
            "",
            "",
            "@intrinsic",
            f"def _call{name}(typingctx, {params}):",
            f'    """{name} of the generated part: the C function at address ``fn``."""',
            f"    return _pointer_call(({listed}), {params})",
        ]
    return "\n".join(lines) + "\n"
