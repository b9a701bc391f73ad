"""A CasADi function interpreted until its use pays for a gcc build, then compiled (cached on disk).

CasADi evaluates an SX function in its virtual machine at about ``1e-8`` s per instruction and
input column; the same function compiled by gcc at ``-O1`` runs 10-15x faster, and the build costs
about ``3e-4`` s per instruction. The break-even is therefore near ``3e-4 / 1e-8 = 3e4`` evaluated
columns, whatever the function's size. :class:`CompiledOnDemand` counts the columns it evaluates
and compiles after :data:`COMPILE_AFTER_COLUMNS` of them (the ski-rental rule: never more than
about twice the cost of the better choice made in hindsight). A library already in the cache
(:mod:`pipeline.core.codegen`, named by the SHA-256 of its code) is loaded at the first call.
The count is kept per code, not per instance: instances of the same function in one process
(the measurement models of two parameter subsets) add up, and each loads the library one of
them built. A caller that knows a lower bound of the columns it is about to evaluate adds it to
the count ahead (:meth:`CompiledOnDemand.expect`): the rule then decides on the use known so far,
which a lower bound never overstates.

The compiled code performs the virtual machine's operations in the same order, and is built with
``-ffp-contract=off`` (no fused multiply-add), so both evaluate to the same numbers. When gcc is
missing or fails, the function stays interpreted (one warning on stderr): slower, same numbers.

:func:`compiled_with_jacobian` compiles a function together with its Jacobian for use inside an
expression graph (an NLP's constraints): the Jacobian is built from the function's own forward
derivative, so the compiled derivatives equal the interpreter's forward mode bit for bit.
"""

from __future__ import annotations

import sys
from pathlib import Path

import casadi as ca

from pipeline.core import codegen
from pipeline.core.casadi_buffers import BufferedFunction
from pipeline.core.errors import SolverError

#: evaluated input columns after which a function is compiled (break-even of the gcc build, above)
COMPILE_AFTER_COLUMNS = 30_000
#: gcc flags: -O1 builds in a quarter of -O2's time at nearly its speed; no FMA contraction
FLAGS = ("-O1", "-ffp-contract=off")
_WARNED: list[str] = []
#: columns counted towards the build in this process, per library (cache subfolder, name, key of the code)
_COLUMNS: dict[str, int] = {}


class CompiledOnDemand:
    """``mapped(n)``: ``function`` mapped over ``n`` columns, as a :class:`BufferedFunction`."""

    def __init__(self, function: ca.Function, *, subdir: str = "on_demand",
                 after_columns: int = COMPILE_AFTER_COLUMNS) -> None:
        self.function = function
        self.subdir = subdir
        self.after_columns = after_columns
        self.columns_interpreted = 0
        self.compiled: ca.Function | None = None
        self._key: str | None = None
        self._maps: dict[int, BufferedFunction] = {}

    def mapped(self, n: int) -> BufferedFunction:
        if self.compiled is None:
            self._maybe_compile(n)
            if self.compiled is None:
                self.columns_interpreted += n
        if n not in self._maps:
            base = self.compiled if self.compiled is not None else self.function
            self._maps[n] = BufferedFunction(base.map(n))
        return self._maps[n]

    def expect(self, columns: int) -> None:
        """Count ``columns`` that the caller will evaluate (a lower bound of its coming use) now,
        so that the build starts as soon as the known use passes the break-even."""
        if self.compiled is None:
            self._maybe_compile(columns)

    def _maybe_compile(self, n: int) -> None:
        name = self.function.name()
        if self._key is None:       # the C code is generated once: its hash names the library
            self._key = codegen.library_key([self.function], name, FLAGS)
            cached = codegen.cached_library(name, self._key, subdir=self.subdir)
            if cached is not None:
                self._load(cached)
                return
        code = f"{self.subdir}/{name}_{self._key}"
        _COLUMNS[code] = _COLUMNS.get(code, 0) + n
        if _COLUMNS[code] >= self.after_columns:
            library = _build_or_warn(name, [self.function], self.subdir, self._key)
            if library is None:
                self.after_columns = sys.maxsize
                return
            self._load(library)

    def _load(self, library: Path) -> None:
        self.compiled = ca.external(self.function.name(), str(library))
        self._maps.clear()


#: Jacobian columns (one evaluation of a function's Jacobian at one point) after which
#: :func:`compiled_with_jacobian` compiles: the break-even of the gcc build, measured on the
#: excitation constraints of a 6-axis arm (18 inputs, 2600 instructions): 0.46 ms per column
#: interpreted, 0.075 ms compiled, 3.6 s of CPU for the code and the build, so about 9 000 columns
JACOBIAN_COMPILE_AFTER_COLUMNS = 10_000


def forward_mode_jacobian(function: ca.Function) -> ca.Function:
    """``jac_<name>(x, out) = dF/dx`` of a function of one input and one output (column vectors),
    column ``j`` being ``function.forward(1)`` seeded with the unit vector ``e_j``, on the structural
    sparsity of the Jacobian: the numbers CasADi's forward mode gives inside an expression graph
    (its symbolic Jacobian simplifies the seeded expressions and differs in the last bits). The
    signature is the one ``ca.external`` looks for beside ``<name>`` in a library (``jac_<name>``)."""
    name, n_x = function.name(), function.nnz_in(0)
    x = ca.MX.sym(function.name_in(0), function.sparsity_in(0))
    out = ca.MX.sym("out_" + function.name_out(0), ca.Sparsity(*function.size_out(0)))
    fwd = function.forward(1)
    nominal = ca.MX(ca.Sparsity(*function.size_out(0)))
    columns = [fwd(x, nominal, ca.DM(function.sparsity_in(0), [float(k == j) for k in range(n_x)]))
               for j in range(n_x)]
    jac = ca.project(ca.horzcat(*columns), function.sparsity_jac(0, 0))
    return ca.Function(f"jac_{name}", [x, out], [jac], [function.name_in(0), "out_" + function.name_out(0)],
                       [f"jac_{function.name_out(0)}_{function.name_in(0)}"])


def compiled_with_jacobian(function: ca.Function, columns: int, *, subdir: str = "on_demand",
                           after_columns: int | None = None) -> ca.Function:
    """``function`` (one input, one output) and its :func:`forward_mode_jacobian` compiled into one
    library and loaded with ``ca.external``, which differentiates it with the compiled Jacobian
    (forward derivatives ``J seed``: the same numbers as the interpreter's forward mode, since a
    forward-mode colouring seeds at most one structural non-zero per row; reverse derivatives
    ``J^T seed`` may differ from the interpreter's reverse mode in the last bits). Compiled when the
    library is cached or when the caller expects at least ``after_columns`` (default
    :data:`JACOBIAN_COMPILE_AFTER_COLUMNS`) Jacobian ``columns``; otherwise, or when gcc fails (one
    warning, no further attempt in this process), ``function`` itself (interpreted, same numbers)."""
    after_columns = JACOBIAN_COMPILE_AFTER_COLUMNS if after_columns is None else after_columns
    name = function.name()
    functions = [function, forward_mode_jacobian(function)]
    key = codegen.library_key(functions, name, FLAGS)
    library = codegen.cached_library(name, key, subdir=subdir)
    if library is None and columns >= after_columns and not _WARNED:
        library = _build_or_warn(name, functions, subdir, key)
    return function if library is None else ca.external(name, str(library))


def _build_or_warn(name: str, functions: list[ca.Function], subdir: str, key: str) -> Path | None:
    """The library of ``functions`` built by gcc, or None after one warning per process when that fails."""
    try:
        return codegen.build_library(name, functions, subdir=subdir, flags=FLAGS, key=key)
    except (SolverError, OSError) as exc:
        if not _WARNED:
            _WARNED.append(str(exc))
            print(f"warning: CasADi functions stay interpreted (compilation failed: {exc})", file=sys.stderr)
        return None
