"""The one way from sympy expressions to callables, by target.

- "python": straight-line scalar Python for the IDA hot path (`emit`). One `jax.jit` call from Python costs
  several times a plain scalar Python call (docs/benchmarks.md, "Costs behind the code"), so the residual,
  Jacobian and event functions IDA calls thousands of times are emitted with common subexpressions eliminated
  (sympy.cse) and `math` functions, then compiled once with `exec`; the generated source is kept on the function
  (`__source__`).
- "numba": the same source with each symbol unpacked by indexing (`source_of`), the form numba compiles
  (dynamics/backends/compiled_model.py).
- "numpy" and "jax": one function of array arguments returning the expressions (`lambdify`, sympy.lambdify with
  cse): numpy for the consistent initialisation, the KKT pieces and the read-outs (dynamics/model.py), jax.numpy
  for the diffrax backend and the sensitivity pass (dynamics/jax_model.py, dynamics/sensitivity.py).
"""
from __future__ import annotations

import math
from typing import Sequence

import sympy as sp
from sympy.printing.numpy import JaxPrinter
from sympy.printing.pycode import PythonCodePrinter


class _Printer(PythonCodePrinter):
    """Python printer emitting bare `math` names (bound as globals of the generated module)."""

    def _print_known_func(self, expr):
        known = self.known_functions[expr.__class__.__name__]
        return "{name}({args})".format(name=known.split(".")[-1],
                                       args=", ".join(map(lambda arg: self._print(arg), expr.args)))

    def _print_known_const(self, expr):
        return self.known_constants[expr.__class__.__name__].split(".")[-1]

    def _print_sign(self, expr):
        a = self._print(expr.args[0])
        return f"(({a} > 0) - ({a} < 0))"

    def _print_Abs(self, expr):
        return f"abs({self._print(expr.args[0])})"


_GLOBALS = {name: getattr(math, name) for name in dir(math) if not name.startswith("_")}
_GLOBALS["Infinity"] = math.inf


def emit(name: str, signature: Sequence[str], unpack: Sequence[tuple[str, Sequence[sp.Symbol]]],
         outputs: Sequence[tuple[str, sp.Expr]], prologue: Sequence[str] = (), result: str | None = None):
    """Compile `def name(*signature)` that unpacks symbols from array arguments and assigns each output.

    unpack: (argument name, symbols) pairs; the argument must hold exactly those values, in order.
    outputs: (target, expression), the target being e.g. "out[3]" or "JJ[1, 2]".
    prologue: extra source lines run first (e.g. "JJ.fill(0.0)"). result: the expression returned.
    """
    source = source_of(name, signature, unpack, outputs, prologue, result, target="python")
    namespace = dict(_GLOBALS)
    exec(compile(source, f"<mechsim-generated {name}>", "exec"), namespace)
    fn = namespace[name]
    fn.__source__ = source
    return fn


def source_of(name: str, signature: Sequence[str], unpack: Sequence[tuple[str, Sequence[sp.Symbol]]],
              outputs: Sequence[tuple[str, sp.Expr]], prologue: Sequence[str] = (), result: str | None = None,
              target: str = "numba") -> str:
    """The source `emit` compiles. "numba" unpacks each symbol by indexing (`a = y[0]`), the form numba
    compiles (dynamics/backends/compiled_model.py); "python" converts the array to a list once (fastest in CPython)."""
    if target not in ("python", "numba"):
        raise ValueError(f"source_of: target must be 'python' or 'numba', got {target!r}")
    indexed = target == "numba"
    printer = _Printer({"fully_qualified_modules": False, "inline": True, "allow_unknown_functions": False})
    exprs = [sp.sympify(e) for _, e in outputs]
    replacements, reduced = sp.cse(exprs, symbols=sp.numbered_symbols("_x"), optimizations="basic")
    lines = [f"def {name}({', '.join(signature)}):"]
    lines += [f"    {line}" for line in prologue]
    for array, symbols in unpack:
        if indexed:
            lines += [f"    {printer._print(s)} = {array}[{i}]" for i, s in enumerate(symbols)]
        elif symbols:
            names = ", ".join(printer._print(s) for s in symbols)
            trailing = "," if len(symbols) == 1 else ""
            lines.append(f"    {names}{trailing} = {array}.tolist() if hasattr({array}, 'tolist') else {array}")
    for sym, expr in replacements:
        lines.append(f"    {printer._print(sym)} = {printer.doprint(expr)}")
    for (target, _), expr in zip(outputs, reduced):
        lines.append(f"    {target} = {printer.doprint(expr)}")
    if result:
        lines.append(f"    return {result}")
    return "\n".join(lines) + "\n"


class _JaxPrinter(JaxPrinter):
    """sympy's jax printer, plus functions that carry their own code printer (opaque functions print their
    explicit expression through `_numpycode`/`_pythoncode`, thermal/coupling.py `opaque_function`)."""

    def _print_Function(self, expr):
        for method in ("_jaxcode", "_numpycode", "_pythoncode"):
            own = getattr(expr, method, None)
            if own is not None:
                return own(self)
        return super()._print_Function(expr)


_JAX_SETTINGS = {"fully_qualified_modules": False, "inline": True, "allow_unknown_functions": True,
                 "user_functions": {}}


def lambdify(args, exprs, target: str):
    """sympy -> one function of `args` (symbols or lists of symbols) returning `exprs` (an expression, a list of
    them, or a Matrix, as sympy.lambdify), common subexpressions eliminated across all of them.

    target "numpy": numpy arrays (a Matrix comes back as an array); "jax": jax.numpy, a list comes back as a flat
    list of scalars (traceable)."""
    if target == "numpy":
        return sp.lambdify(args, exprs, modules="numpy", cse=True)
    if target == "jax":
        return sp.lambdify(args, [sp.sympify(e) for e in exprs], modules="jax", cse=True,
                           printer=_JaxPrinter(_JAX_SETTINGS))
    raise ValueError(f"lambdify: target must be 'numpy' or 'jax', got {target!r}")
