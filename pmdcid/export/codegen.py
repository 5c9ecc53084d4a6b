"""The kernel's exported forms, generated from its one source.

The physics is written once, as the numba-subset Python of :mod:`pmdcid.simulate` (the terms of
:mod:`~pmdcid.simulate.terms`, one internal step and the discretisation of
:mod:`~pmdcid.simulate.kernel`, the substep rule of :mod:`~pmdcid.simulate.substeps`, the slots
of :mod:`~pmdcid.simulate.layout`). This module reads that source (``inspect`` and ``ast``) and
writes it as C99 (:func:`c_kernel`) and as MATLAB/Octave (:func:`matlab_kernel`); the
python-control module embeds the Python source itself (:func:`python_kernel`). The exporters'
templates hold only the shell: the public API, the input and output, the late input's line of
past inputs, the sensor effects, the FMI wrapper.

The subset translated: float, int and bool scalars; arrays of fixed shape indexed by ints and
layout constants (their shapes by argument name, :data:`ARRAYS`: one name, one thing), local
arrays from ``np.zeros((..))`` or ``np.empty_like(X)`` at a function's top level; ``if``/``elif``/
``else``, ``for ... in range(..)``, ``while``, ``continue``, ``break``; ``+ - * / **``,
comparisons, ``and``/``or``/``not``, ``x if c else y`` (in MATLAB only as a whole right-hand
side or return value); ``abs``, ``min``/``max`` of two, ``int``, ``float``, ``math.*``; module
constants (inlined); calls between kernel functions, tuple returns (C: out-parameters; MATLAB:
several outputs) and arrays written in place (MATLAB: returned and assigned back). Anything else
is a :class:`CodegenError` naming the function and line, so that a kernel edit outside the
subset fails the export tests instead of exporting something else.
"""

from __future__ import annotations

import ast
import inspect
import math
import re
import textwrap
from dataclasses import dataclass, field
from pathlib import Path

from pmdcid.identify import grid
from pmdcid.simulate import kernel, layout, substeps, terms
from pmdcid.simulate.cache import sources_hash

#: what the exported shells call; every kernel function these call is translated with them
ENTRIES = (kernel.sample_input, kernel.stick_substep, kernel.lugre_substep,
           kernel.discretize_into, terms.lugre_on, terms.friction_guarded,
           terms.steady_friction_level, substeps.max_step, substeps.substeps_for)
#: the functions of the compiled runtime kernel (:data:`RUNTIME_SOURCE`, loaded by
#: :mod:`pmdcid.simulate.compiled`): the sample loops, the discretisation, a batch set's cost
RUNTIME = (kernel._run_states, kernel.discretize_into, grid._set_cost)
#: the generated C of :data:`RUNTIME`, compiled by the package's build (setup.py)
RUNTIME_SOURCE = Path(kernel.__file__).with_name("_kernel.c")
#: array arguments by name: their shapes (``p``: the parameter vector, layout.NAMES; None: a
#: length known at run time, passed in C as ``n_NAME`` after the array)
ARRAYS = {"p": (len(layout.NAMES),), "Phi": (4, 3, 3), "Gam": (4, 3, 3), "M": (6, 6),
          "E": (6, 6), "X": (6, 6), "Y": (6, 6), "Z": (6, 6), "u": (None,), "x0": (None,),
          "out": (None, layout.NSTATE), "w_meas": (None,), "th_meas": (None,)}
#: scalar arguments that are not floats, by name
BOOLS = frozenset({"torque_driven", "guarded", "engaged", "eng"})
INTS = frozenset({"m", "k", "nsub", "mode0"})
#: math.* functions and what they are called in C and in MATLAB
MATH = {"exp": "exp", "expm1": "expm1", "sin": "sin", "cos": "cos", "sqrt": "sqrt",
        "ceil": "ceil", "floor": "floor", "log2": "log2", "log": "log", "isfinite": "isfinite"}
#: C helpers with Python's min/max semantics (the first argument unless the second is past it)
C_HELPERS = {
    "py_fmin": "static inline double py_fmin(double a, double b) { return b < a ? b : a; }",
    "py_fmax": "static inline double py_fmax(double a, double b) { return b > a ? b : a; }",
    "py_imin": "static inline int py_imin(int a, int b) { return b < a ? b : a; }",
    "py_imax": "static inline int py_imax(int a, int b) { return b > a ? b : a; }",
}


class CodegenError(ValueError):
    """A kernel function uses Python outside the translated subset (message says where)."""


@dataclass
class Fn:
    """One kernel function as translated: its tree, types, returns and arrays it writes."""

    name: str
    node: ast.FunctionDef
    env: dict  # the module globals its names resolve in
    source: str
    params: list[str]
    types: dict = field(default_factory=dict)  # name -> "float" | "int" | "bool" | shape tuple
    returns: list = field(default_factory=list)  # [] none, [t] one value, [t, ...] a tuple
    written: list[str] = field(default_factory=list)  # array parameters written in place
    lengths: set[str] = field(default_factory=set)  # array parameters whose length it needs
    calls: list[str] = field(default_factory=list)

    def fail(self, node, why: str):
        line = getattr(node, "lineno", 1) + self.node.lineno - 1
        raise CodegenError(f"{self.name} (line {line} of its source): {why}")


def python_function(obj):
    """The plain Python function behind a kernel function (numba placeholder or dispatcher)."""
    return getattr(obj, "py_func", obj)


def out_name(name: str) -> str:
    """A name as C and MATLAB spell it: leading underscores dropped (``_`` -> ``each``)."""
    return name.lstrip("_") or "each"


def collect(entries=ENTRIES) -> list[Fn]:
    """The entries and every kernel function they call, callees first, typed."""
    order: list[Fn] = []
    seen: dict[str, Fn] = {}

    def visit(obj):
        func = python_function(obj)
        if func.__name__ in seen:
            return
        source = textwrap.dedent(inspect.getsource(func))
        node = ast.parse(source).body[0]
        node.decorator_list = []
        fn = Fn(func.__name__, node, func.__globals__, source, [a.arg for a in node.args.args])
        seen[fn.name] = fn
        for call in ast.walk(node):
            if isinstance(call, ast.Call) and isinstance(call.func, ast.Name):
                target = func.__globals__.get(call.func.id)
                if target is not None and _is_kernel(target):
                    visit(target)
                    if call.func.id not in fn.calls:
                        fn.calls.append(call.func.id)
        _type(fn, seen)
        order.append(fn)

    for e in entries:
        visit(e)
    return order


#: the modules whose functions are the kernel's source
SOURCES = (terms.__name__, kernel.__name__, substeps.__name__, grid.__name__)


def _is_kernel(obj) -> bool:
    func = python_function(obj)
    return inspect.isfunction(func) and func.__module__ in SOURCES


def constant(fn: Fn, name: str):
    """The value of module constant ``name`` seen from ``fn`` (int or float), or None."""
    val = fn.env.get(name)
    if isinstance(val, bool) or not isinstance(val, (int, float)):
        return None
    return val


# ---------------------------------------------------------------- types


def _type(fn: Fn, known: dict[str, Fn]) -> None:
    for a in fn.params:
        fn.types[a] = ARRAYS.get(a) or ("bool" if a in BOOLS else "int" if a in INTS
                                       else "float")
    for node in ast.walk(fn.node):
        if isinstance(node, ast.For):
            fn.types.setdefault(node.target.id, "int")
    for stmt in _statements(fn.node.body):
        if isinstance(stmt, ast.Assign):
            _type_assign(fn, stmt, known)
        elif isinstance(stmt, ast.Return) and stmt.value is not None and not fn.returns:
            vals = stmt.value.elts if isinstance(stmt.value, ast.Tuple) else [stmt.value]
            fn.returns = [_expr_type(fn, v, known) for v in vals]
        elif isinstance(stmt, (ast.Expr, ast.AugAssign)) and isinstance(
                getattr(stmt, "value", None), ast.Call):
            _note_written(fn, stmt.value, known)
    for node in ast.walk(fn.node):
        if isinstance(node, (ast.Assign, ast.AugAssign)):
            targets = node.targets if isinstance(node, ast.Assign) else [node.target]
            for t in targets:
                if isinstance(t, ast.Subscript) and isinstance(t.value, ast.Name):
                    _mark_written(fn, t.value.id)
    fn.written.sort(key=fn.params.index)
    _find_lengths(fn, known)


def _find_lengths(fn: Fn, known) -> None:
    """The array parameters of a run-time length whose length ``fn`` reads or passes on."""
    for node in ast.walk(fn.node):
        if isinstance(node, ast.Subscript) and _is_shape(node):
            fn.lengths.add(node.value.value.id)
        callee = _callee(fn, node, known) if isinstance(node, ast.Call) else None
        for param, arg in zip(callee.params if callee else (), node.args if callee else (),
                              strict=False):
            if param in callee.lengths and isinstance(arg, ast.Name):
                fn.lengths.add(arg.id)


def _statements(body):
    for stmt in body:
        yield stmt
        for attr in ("body", "orelse"):
            yield from _statements(getattr(stmt, attr, []))


def _type_assign(fn: Fn, stmt: ast.Assign, known) -> None:
    if len(stmt.targets) != 1:
        fn.fail(stmt, "one target per assignment")
    target, value = stmt.targets[0], stmt.value
    if isinstance(value, ast.Call):
        _note_written(fn, value, known)
    if isinstance(target, ast.Name):
        fn.types.setdefault(target.id, _expr_type(fn, value, known))
    elif isinstance(target, ast.Tuple):
        callee = _callee(fn, value, known)
        if callee is None or len(callee.returns) != len(target.elts):
            fn.fail(stmt, "a tuple is assigned only from a kernel function returning one")
        for t, ty in zip(target.elts, callee.returns, strict=True):
            fn.types.setdefault(t.id, ty)
    elif not isinstance(target, ast.Subscript):
        fn.fail(stmt, "assignment to a name, a tuple of names or an array element only")


def _mark_written(fn: Fn, name: str) -> None:
    if name in fn.params and name not in fn.written:
        fn.written.append(name)


def _note_written(fn: Fn, call: ast.Call, known) -> None:
    callee = _callee(fn, call, known)
    if callee is None:
        return
    for param, arg in zip(callee.params, call.args, strict=False):
        if param in callee.written and isinstance(arg, ast.Name):
            _mark_written(fn, arg.id)


def _callee(fn: Fn, node, known) -> Fn | None:
    if not (isinstance(node, ast.Call) and isinstance(node.func, ast.Name)):
        return None
    target = fn.env.get(node.func.id)
    if target is None or not _is_kernel(target):
        return None
    return known.get(python_function(target).__name__)


def _expr_type(fn: Fn, node, known):  # noqa: C901 - one case per node kind
    if isinstance(node, ast.Constant):
        return {bool: "bool", int: "int", float: "float"}.get(type(node.value)) or fn.fail(
            node, f"constant {node.value!r}")
    if isinstance(node, ast.Name):
        if node.id in fn.types:
            return fn.types[node.id]
        val = constant(fn, node.id)
        return fn.fail(node, f"unknown name {node.id}") if val is None else (
            "int" if isinstance(val, int) else "float")
    if isinstance(node, (ast.Compare, ast.BoolOp)) or (
            isinstance(node, ast.UnaryOp) and isinstance(node.op, ast.Not)):
        return "bool"
    if isinstance(node, ast.UnaryOp):
        return _expr_type(fn, node.operand, known)
    if isinstance(node, ast.BinOp):
        a, b = _expr_type(fn, node.left, known), _expr_type(fn, node.right, known)
        return "int" if a == b == "int" and not isinstance(node.op, (ast.Div, ast.Pow)) \
            else "float"
    if isinstance(node, ast.IfExp):
        a, b = _expr_type(fn, node.body, known), _expr_type(fn, node.orelse, known)
        return a if a == b else "float"
    if isinstance(node, ast.Subscript):
        if _is_shape(node):
            return "int"
        if isinstance(node.value, ast.Name) and isinstance(fn.types.get(node.value.id), tuple):
            return "float"
        return fn.fail(node, f"subscript of {ast.unparse(node.value)}, not a kernel array")
    if isinstance(node, ast.Attribute) and _dotted(node) == "math.inf":
        return "float"
    if isinstance(node, ast.Call):
        return _call_type(fn, node, known)
    return fn.fail(node, f"expression {ast.unparse(node)}")


def _call_type(fn: Fn, node: ast.Call, known):
    name = _dotted(node.func)
    if name in ("abs",):
        return _expr_type(fn, node.args[0], known)
    if name in ("min", "max"):
        types = {_expr_type(fn, a, known) for a in node.args}
        return "int" if types == {"int"} else "float"
    if name in ("int", "float"):
        return name
    if name == "math.isfinite":
        return "bool"
    if name.startswith("math."):
        return "float"
    if name in ("np.zeros", "np.empty"):
        return tuple(_int_value(fn, e) for e in node.args[0].elts)
    if name in ("np.empty_like", "np.zeros_like"):
        return fn.types[node.args[0].id]
    callee = _callee(fn, node, known)
    if callee is None:
        fn.fail(node, f"call of {name}")
    if len(callee.returns) != 1:
        fn.fail(node, f"{name} returns {len(callee.returns)} values: assign them to names")
    return callee.returns[0]


def _int_value(fn: Fn, node) -> int:
    value = _folded(fn, node)
    return fn.fail(node, "an integer constant expected") if value is None else value


def _folded(fn: Fn, node) -> int | None:
    """The value of an integer expression of constants (+, -, *), or None."""
    if isinstance(node, ast.Constant) and type(node.value) is int:
        return node.value
    if isinstance(node, ast.Name) and node.id not in fn.types:
        val = constant(fn, node.id)
        return val if isinstance(val, int) else None
    if isinstance(node, ast.BinOp) and isinstance(node.op, (ast.Add, ast.Sub, ast.Mult)):
        a, b = _folded(fn, node.left), _folded(fn, node.right)
        if a is None or b is None:
            return None
        return a + b if isinstance(node.op, ast.Add) else a - b if isinstance(
            node.op, ast.Sub) else a * b
    return None


def _dotted(node) -> str:
    if isinstance(node, ast.Name):
        return node.id
    if isinstance(node, ast.Attribute):
        return _dotted(node.value) + "." + node.attr
    return "?"


def _is_shape(node: ast.Subscript) -> bool:
    return isinstance(node.value, ast.Attribute) and node.value.attr == "shape"


def _indices(node: ast.Subscript) -> list:
    sl = node.slice
    return list(sl.elts) if isinstance(sl, ast.Tuple) else [sl]


def _shape_value(fn: Fn, node: ast.Subscript) -> str:
    """A length: the shape's constant, or ``n_NAME`` for a length known at run time."""
    arr = node.value.value.id
    n = fn.types[arr][_int_value(fn, node.slice)]
    return f"n_{out_name(arr)}" if n is None else str(n)


# ---------------------------------------------------------------- shared by C and MATLAB

#: binary operator precedence (higher binds tighter), as C and MATLAB group them
PREC = {ast.Or: 1, ast.And: 2, "cmp": 3, ast.Add: 4, ast.Sub: 4, ast.Mult: 5, ast.Div: 5,
        "unary": 6, ast.Pow: 7}
SYMBOL = {ast.Add: "+", ast.Sub: "-", ast.Mult: "*", ast.Div: "/", ast.Lt: "<",
          ast.LtE: "<=", ast.Gt: ">", ast.GtE: ">=", ast.Eq: "=="}


def _prec(node) -> int:
    if isinstance(node, ast.BinOp):
        return PREC[type(node.op)]
    if isinstance(node, ast.BoolOp):
        return PREC[type(node.op)]
    if isinstance(node, ast.Compare):
        return PREC["cmp"]
    if isinstance(node, ast.UnaryOp):
        return PREC["unary"]
    if isinstance(node, ast.IfExp):
        return 0
    return 9


class Writer:
    """Shared walk of a function's statements; the language's spelling in the subclasses."""

    indent_unit = "    "

    def __init__(self, fn: Fn, fns: dict[str, Fn]):
        self.fn = fn
        self.fns = fns
        self.lines: list[str] = []
        self.depth = 1
        self.helpers: set[str] = set()

    def emit(self, text: str) -> None:
        self.lines.append(self.indent_unit * self.depth + text)

    def callee(self, node) -> Fn | None:
        return _callee(self.fn, node, self.fns)

    def if_(self, s) -> None:
        """An if/elif/else chain in the target's own words (:attr:`IF_LINES`)."""
        first, elif_, else_, end = self.IF_LINES
        self.emit(first.format(self.expr(s.test)))
        self.block(s.body)
        orelse = s.orelse
        while len(orelse) == 1 and isinstance(orelse[0], ast.If):
            self.emit(elif_.format(self.expr(orelse[0].test)))
            self.block(orelse[0].body)
            orelse = orelse[0].orelse
        if orelse:
            self.emit(else_.format())
            self.block(orelse)
        self.emit(end.format())

    def block(self, stmts) -> None:
        self.depth += 1
        self.body(stmts)
        self.depth -= 1

    def body(self, stmts) -> None:
        for s in stmts:
            self.stmt(s)

    def stmt(self, s) -> None:  # noqa: C901 - one case per statement kind
        if isinstance(s, ast.Expr) and isinstance(s.value, ast.Constant):
            return  # the docstring
        if isinstance(s, ast.Assign):
            return self.assign(s.targets[0], s.value)
        if isinstance(s, ast.AugAssign):
            return self.assign(s.target, ast.BinOp(s.target, s.op, s.value))
        if isinstance(s, ast.If):
            return self.if_(s)
        if isinstance(s, ast.For):
            return self.for_(s)
        if isinstance(s, ast.While):
            return self.while_(s)
        if isinstance(s, ast.Return):
            return self.return_(s.value)
        if isinstance(s, ast.Expr) and isinstance(s.value, ast.Call) and self.callee(s.value):
            return self.call_stmt([], s.value)
        if isinstance(s, (ast.Continue, ast.Break)):
            return self.emit("continue;" if isinstance(s, ast.Continue) else "break;")
        if isinstance(s, ast.Pass):
            return None
        return self.fn.fail(s, f"statement {ast.unparse(s).splitlines()[0]}")

    def assign(self, target, value) -> None:
        if isinstance(value, ast.Call) and _dotted(value.func).startswith("np."):
            return None  # a local array: declared with the function's locals
        if isinstance(target, ast.Tuple) or self.callee(value) and self.callee(value).written:
            return self.call_stmt(target.elts if isinstance(target, ast.Tuple) else [target],
                                  value)
        return self.simple_assign(target, value)

    def range_of(self, s: ast.For):
        if not (isinstance(s.iter, ast.Call) and _dotted(s.iter.func) == "range"
                and isinstance(s.target, ast.Name) and not s.orelse):
            self.fn.fail(s, "for loops over range(...) only")
        args = s.iter.args
        start = args[0] if len(args) > 1 else ast.Constant(0)
        stop = args[1] if len(args) > 1 else args[0]
        step = args[2] if len(args) > 2 else ast.Constant(1)
        if not (isinstance(step, ast.Constant) and step.value > 0):
            self.fn.fail(s, "range steps are positive constants")
        return out_name(s.target.id), start, stop, step.value

    def expr(self, node, parent: int = 0) -> str:
        text = self.expr_text(node)
        return f"({text})" if _prec(node) < parent else text

    def binop(self, node) -> str:
        p = _prec(node)
        op = type(node.op)
        if op is ast.Pow:
            return self.power(node)
        return f"{self.expr(node.left, p)} {SYMBOL[op]} {self.expr(node.right, p + 1)}"

    def compare(self, node) -> str:
        if len(node.ops) != 1:
            self.fn.fail(node, "chained comparisons")
        op = type(node.ops[0])
        sym = self.not_equal if op is ast.NotEq else SYMBOL.get(op) or self.fn.fail(
            node, "comparison")
        p = PREC["cmp"]
        return f"{self.expr(node.left, p + 1)} {sym} {self.expr(node.comparators[0], p + 1)}"

    def name(self, node: ast.Name) -> str:
        if node.id in self.fn.types:
            return out_name(node.id)
        val = constant(self.fn, node.id)
        if val is None:
            self.fn.fail(node, f"unknown name {node.id}")
        return self.constant_name(node.id, val)

    def float_literal(self, x: float) -> str:
        if math.isinf(x):
            return self.infinity if x > 0 else "-" + self.infinity
        text = repr(float(x))
        return text

    def expr_text(self, node) -> str:  # noqa: C901 - one case per node kind
        if isinstance(node, ast.Constant):
            if isinstance(node.value, bool):
                return self.true if node.value else self.false
            if isinstance(node.value, int):
                return str(node.value)
            return self.float_literal(node.value)
        if isinstance(node, ast.Name):
            return self.name(node)
        if isinstance(node, ast.Attribute):
            if _dotted(node) == "math.inf":
                return self.infinity
            return self.fn.fail(node, f"attribute {_dotted(node)}")
        if isinstance(node, ast.BinOp):
            return self.binop(node)
        if isinstance(node, ast.UnaryOp):
            sym = {ast.USub: "-", ast.UAdd: "+", ast.Not: self.not_}[type(node.op)]
            return sym + self.expr(node.operand, PREC["unary"])
        if isinstance(node, ast.BoolOp):
            p = _prec(node)
            sym = self.and_ if isinstance(node.op, ast.And) else self.or_
            return f" {sym} ".join(self.expr(v, p + 1) for v in node.values)
        if isinstance(node, ast.Compare):
            return self.compare(node)
        if isinstance(node, ast.IfExp):
            return self.if_expr(node)
        if isinstance(node, ast.Subscript):
            if _is_shape(node):
                return self.length(node)
            return self.subscript(node)
        if isinstance(node, ast.Call):
            return self.call(node)
        return self.fn.fail(node, f"expression {ast.unparse(node)}")

    def args(self, call) -> list[str]:
        return [self.expr(a) for a in call.args]

    def length(self, node) -> str:
        return _shape_value(self.fn, node)

    def call(self, node: ast.Call) -> str:
        name = _dotted(node.func)
        args = node.args
        if name in ("min", "max", "abs", "int", "float") or name.startswith("math."):
            return self.builtin(node, name, args)
        callee = self.callee(node)
        if callee is None:
            self.fn.fail(node, f"call of {name}")
        if callee.written or len(callee.returns) != 1:
            self.fn.fail(node, f"{name} is called as a statement (it returns {len(callee.returns)} "
                         "values or writes an array)")
        return f"{out_name(callee.name)}({', '.join(self.args(node))})"


# ---------------------------------------------------------------- C99


C_TYPE = {"float": "double", "int": "int", "bool": "int"}
#: the layout's slot constants (``BC``, ``DZ_SLOPE``...): their index in layout.NAMES
SLOTS = {n.upper(): k for k, n in enumerate(layout.NAMES)}


class CWriter(Writer):
    true, false, infinity = "1", "0", "INFINITY"
    not_, and_, or_, not_equal = "!", "&&", "||", "!="

    def constant_name(self, name: str, val) -> str:
        if SLOTS.get(name) == val:
            return "P_" + name
        return f"{self.float_literal(val) if isinstance(val, float) else val} /* {name} */"

    def power(self, node) -> str:
        return f"pow({self.expr(node.left)}, {self.expr(node.right)})"

    def subscript(self, node) -> str:
        arr = node.value.id
        return out_name(arr) + "".join(f"[{self.expr(i)}]" for i in _indices(node))

    def if_expr(self, node) -> str:
        return (f"{self.expr(node.test, 1)} ? {self.expr(node.body, 1)} : "
                f"{self.expr(node.orelse, 0)}")

    def builtin(self, node, name, args) -> str:
        ty = _expr_type(self.fn, node, self.fns)
        if name in ("min", "max"):
            if len(args) != 2:
                self.fn.fail(node, f"{name} of two values only")
            helper = f"py_{'i' if ty == 'int' else 'f'}{name}"
            self.helpers.add(helper)
            return f"{helper}({self.expr(args[0])}, {self.expr(args[1])})"
        if name == "abs":
            return f"{'abs' if ty == 'int' else 'fabs'}({self.expr(args[0])})"
        if name in ("int", "float"):
            return f"({C_TYPE[name]}){self.expr(args[0], PREC['unary'])}"
        fname = MATH.get(name[5:]) or self.fn.fail(node, f"call of {name}")
        return f"{fname}({', '.join(self.expr(a) for a in args)})"

    def simple_assign(self, target, value) -> None:
        self.emit(f"{self.expr(target)} = {self.expr(value)};")

    def args(self, call) -> list[str]:
        """The arguments, an array whose length the callee needs followed by its length."""
        callee = self.callee(call)
        out = []
        for param, a in zip(callee.params, call.args, strict=True):
            out.append(self.expr(a))
            if param in callee.lengths:
                out.append(f"n_{out_name(a.id)}")
        return out

    def call_stmt(self, targets, call) -> None:
        args = self.args(call) + [f"&{out_name(t.id)}" for t in targets]
        self.emit(f"{out_name(self.callee(call).name)}({', '.join(args)});")

    #: an if chain's lines: (if, else if, else, end), formatted with the condition
    IF_LINES = ("if ({}) {{", "}} else if ({}) {{", "}} else {{", "}}")

    def for_(self, s) -> None:
        var, start, stop, step = self.range_of(s)
        inc = f"{var}++" if step == 1 else f"{var} += {step}"
        self.emit(f"for ({var} = {self.expr(start)}; {var} < {self.expr(stop, PREC['cmp'] + 1)}; "
                  f"{inc}) {{")
        self.block(s.body)
        self.emit("}")

    def while_(self, s) -> None:
        self.emit(f"while ({self.expr(s.test)}) {{")
        self.block(s.body)
        self.emit("}")

    def return_(self, value) -> None:
        if value is None:
            return self.emit("return;")
        if len(self.fn.returns) == 1:
            return self.emit(f"return {self.expr(value)};")
        vals = value.elts if isinstance(value, ast.Tuple) else None
        if vals is None or len(vals) != len(self.fn.returns):
            self.fn.fail(value, "every return gives the same number of values")
        for k, v in enumerate(vals):
            self.emit(f"*r_{k} = {self.expr(v)};")
        return self.emit("return;")


def _c_param(fn: Fn, name: str) -> str:
    ty = fn.types[name]
    if name == "p":
        return "const double *p"
    if isinstance(ty, tuple) and ty[0] is None:
        const = "" if name in fn.written else "const "
        rows = "".join(f"[{n}]" for n in ty[1:])
        decl = f"double (*{out_name(name)}){rows}" if rows else f"{const}double *{out_name(name)}"
        return f"{decl}, int n_{out_name(name)}" if name in fn.lengths else decl
    if isinstance(ty, tuple):
        return "double " + out_name(name) + "".join(f"[{n}]" for n in ty)
    return f"{C_TYPE[ty]} {out_name(name)}"


def _c_function(fn: Fn, fns: dict[str, Fn], public: bool = False) -> tuple[str, set[str]]:
    w = CWriter(fn, fns)
    w.body(fn.node.body)
    params = [_c_param(fn, a) for a in fn.params]
    if len(fn.returns) > 1:
        params += [f"{C_TYPE[t]} *r_{k}" for k, t in enumerate(fn.returns)]
    ret = C_TYPE[fn.returns[0]] if len(fn.returns) == 1 else "void"
    decls = []
    for name, ty in fn.types.items():
        if name in fn.params:
            continue
        if isinstance(ty, tuple):  # zeroed, as np.zeros; np.empty_like's are written first
            zero = "{" * len(ty) + "0.0" + "}" * len(ty)
            decls.append(f"    double {out_name(name)}{''.join(f'[{n}]' for n in ty)} = {zero};")
        else:
            decls.append(f"    {C_TYPE[ty]} {out_name(name)};")
    doc = _comment(fn, " * ")
    head = f"/*{doc[2:]}\n */\n" if doc else ""
    storage = "" if public else ("PMDCID_INLINE " if _always_inline(fn) else "static inline ")
    text = (f"{head}{storage}{ret} {out_name(fn.name)}({', '.join(params)})\n{{\n"
            + "\n".join(decls + w.lines) + "\n}\n")
    return text, w.helpers


#: the C of numba's ``inline="always"``: GCC and Clang weigh ``static inline`` against a size
#: limit, and past it (the stick-slip step once L = 0 was added, session 34) stopped inlining
#: the step into the loop, a fifth slower per internal step (bench: 30 -> 37 ms for 40 s at
#: 1 kHz and 64 substeps); forced, 29 ms
C_INLINE = ("#if defined(__GNUC__)\n"
            "#define PMDCID_INLINE static inline __attribute__((always_inline))\n"
            "#else\n#define PMDCID_INLINE static inline\n#endif\n")


def _always_inline(fn: Fn) -> bool:
    """Whether the kernel function is decorated ``@njit(..., inline="always")`` (read from its
    source: :func:`collect` drops the tree's decorators)."""
    tree = ast.parse(textwrap.dedent(fn.source)).body[0]
    return any(kw.arg == "inline" and isinstance(kw.value, ast.Constant)
               and kw.value.value == "always"
               for dec in tree.decorator_list for kw in getattr(dec, "keywords", ()))


def _comment(fn: Fn, lead: str) -> str:
    doc = ast.get_docstring(fn.node) or ""
    doc = doc.replace("*/", "* /").replace(":func:", "").replace(":data:", "").replace("``", "")
    return "\n".join((lead + line).rstrip() for line in doc.splitlines())


def c_kernel(entries=ENTRIES, public: bool = False) -> str:
    """The kernel as C99: ``enum`` of the parameter slots ``P_NAME`` (layout.NAMES), then every
    translated function, ``static inline`` (a shell calling none of some draws no warning), the
    entries themselves external when ``public``. Arrays are C arrays of their fixed shapes
    (``n_NAME`` after one whose length is known at run time); ``p`` is ``const double *``;
    tuple returns are out-parameters ``r_0, r_1, ...`` after the arguments."""
    fns = collect(entries)
    by_name = {f.name: f for f in fns}
    outside = {python_function(e).__name__ for e in entries} if public else set()
    texts, helpers = [], set()
    for fn in fns:
        text, used = _c_function(fn, by_name, fn.name in outside)
        texts.append(text)
        helpers |= used
    slots = ",\n".join(f"    P_{n.upper()} = {k}" for k, n in enumerate(layout.NAMES))
    head = [C_INLINE, "/* the kernel's parameter slots (pmdcid.simulate.layout.NAMES) */\n"
            f"enum {{\n{slots},\n    P_COUNT = {len(layout.NAMES)}\n}};\n"]
    head += [C_HELPERS[h] for h in sorted(helpers)]
    return "\n".join(head) + "\n\n" + "\n".join(texts)


# ---------------------------------------------------------------- MATLAB / GNU Octave


class MWriter(Writer):
    indent_unit = "  "
    true, false, infinity = "true", "false", "Inf"
    not_, and_, or_, not_equal = "~", "&&", "||", "~="

    def constant_name(self, name: str, val) -> str:
        return self.float_literal(val) if isinstance(val, float) else str(val)

    def power(self, node) -> str:
        p = PREC[ast.Pow]
        return f"{self.expr(node.left, p + 1)}^{self.expr(node.right, p + 1)}"

    def index(self, node) -> str:
        """A 0-based index expression as MATLAB's 1-based one (constants folded)."""
        if self._is_const(node):
            return str(self._int(node) + 1)
        if isinstance(node, ast.BinOp) and isinstance(node.op, ast.Add):
            for const, other, first in ((node.left, node.right, True),
                                        (node.right, node.left, False)):
                if self._is_const(const):
                    k = str(self._int(const) + 1)
                    o = self.expr(other, PREC[ast.Add])
                    return f"{k} + {o}" if first else f"{o} + {k}"
        return f"{self.expr(node, PREC[ast.Add])} + 1"

    def _is_const(self, node) -> bool:
        return _folded(self.fn, node) is not None

    def _int(self, node) -> int:
        return _int_value(self.fn, node)

    def subscript(self, node) -> str:
        return f"{out_name(node.value.id)}({', '.join(self.index(i) for i in _indices(node))})"

    def length(self, node) -> str:
        arr = node.value.value.id
        return f"size({out_name(arr)}, {_int_value(self.fn, node.slice) + 1})"

    def if_expr(self, node) -> str:
        return self.fn.fail(node, "x if c else y in MATLAB only as a whole value assigned or "
                            "returned")

    def builtin(self, node, name, args) -> str:
        if name == "int":
            return f"fix({self.expr(args[0])})"
        if name == "float":
            return self.expr(args[0], PREC["unary"])
        if name in ("min", "max", "abs"):
            return f"{name}({', '.join(self.expr(a) for a in args)})"
        fname = MATH.get(name[5:]) or self.fn.fail(node, f"call of {name}")
        return f"{fname}({', '.join(self.expr(a) for a in args)})"

    def simple_assign(self, target, value) -> None:
        if isinstance(value, ast.IfExp):
            return self.if_(ast.If(value.test, [ast.Assign([target], value.body)],
                                   [ast.Assign([target], value.orelse)]))
        return self.emit(f"{self.expr(target)} = {self.expr(value)};")

    def call_stmt(self, targets, call) -> None:
        callee = self.callee(call)
        outs = [out_name(t.id) for t in targets]
        for param, arg in zip(callee.params, call.args, strict=True):
            if param in callee.written:
                if not isinstance(arg, ast.Name):
                    self.fn.fail(call, "an array written in place is passed by name")
                outs.append(out_name(arg.id))
        args = ", ".join(self.expr(a) for a in call.args)
        lhs = "" if not outs else (outs[0] + " = " if len(outs) == 1 else
                                   f"[{', '.join(outs)}] = ")
        self.emit(f"{lhs}{out_name(callee.name)}({args});")

    IF_LINES = ("if {}", "elseif {}", "else", "end")

    def for_(self, s) -> None:
        var, start, stop, step = self.range_of(s)
        if self._is_const(stop):
            last = str(self._int(stop) - 1)
        else:
            last = f"{self.expr(stop, PREC[ast.Sub] + 1)} - 1"
        mid = "" if step == 1 else f"{step}:"
        self.emit(f"for {var} = {self.expr(start)}:{mid}{last}")
        self.block(s.body)
        self.emit("end")

    def while_(self, s) -> None:
        self.emit(f"while {self.expr(s.test)}")
        self.block(s.body)
        self.emit("end")

    def return_(self, value) -> None:
        if value is not None:
            vals = value.elts if isinstance(value, ast.Tuple) else [value]
            if len(vals) != len(self.fn.returns):
                self.fn.fail(value, "every return gives the same number of values")
            for k, v in enumerate(vals):
                self.simple_assign(ast.Name(f"r_{k}"), v)
        self.emit("return;")

    def name(self, node: ast.Name) -> str:
        if node.id.startswith("r_") and node.id not in self.fn.types:
            return node.id
        return super().name(node)


def _m_function(fn: Fn, fns: dict[str, Fn]) -> str:
    w = MWriter(fn, fns)
    for name, ty in fn.types.items():
        if isinstance(ty, tuple) and name not in fn.params:
            w.emit(f"{out_name(name)} = zeros({', '.join(map(str, ty))});")
    w.body(fn.node.body)
    outs = [f"r_{k}" for k in range(len(fn.returns))] + [out_name(a) for a in fn.written]
    lhs = "" if not outs else (outs[0] + " = " if len(outs) == 1 else f"[{', '.join(outs)}] = ")
    head = f"function {lhs}{out_name(fn.name)}({', '.join(out_name(a) for a in fn.params)})"
    doc = _comment(fn, "% ")
    return "\n".join([head, doc, *w.lines, "end"] if doc else [head, *w.lines, "end"]) + "\n"


def matlab_kernel() -> str:
    """The kernel as MATLAB/Octave local functions (for the end of a function file). Indices
    stay 0-based in the loops and become 1-based where an array is indexed; ``p`` is the
    parameter row vector in layout.NAMES order; arrays written in place are returned."""
    fns = collect()
    by_name = {f.name: f for f in fns}
    return "\n".join(_m_function(fn, by_name) for fn in fns)


# ---------------------------------------------------------------- Python (python-control)


def python_kernel() -> str:
    """The kernel's own Python source (numba's decorators dropped, plain Python with numpy),
    preceded by the module constants it reads (the layout's slots among them)."""
    fns = collect()
    used: dict[str, object] = {}
    for fn in fns:
        for node in ast.walk(fn.node):
            if isinstance(node, ast.Name) and node.id not in fn.types:
                val = constant(fn, node.id)
                if val is not None:
                    used[node.id] = val
    slots = [n.upper() for n in layout.NAMES]
    consts = [f"{n} = {v!r}" for n, v in sorted(used.items()) if n not in slots]
    layout_line = textwrap.fill(", ".join(slots), 96, subsequent_indent=" ")
    head = [f"({layout_line}) = range({len(layout.NAMES)})", *consts]
    bodies = []
    for fn in fns:
        lines = fn.source.splitlines()
        start = next(k for k, ln in enumerate(lines) if ln.startswith("def "))
        text = "\n".join(lines[start:])
        bodies.append(re.sub(r"\s*# pragma: no cover[^\n]*", "", text))
    return "\n".join(head) + "\n\n\n" + "\n\n\n".join(bodies) + "\n"


def runtime_source() -> str:
    """The text of :data:`RUNTIME_SOURCE`: the :data:`RUNTIME` functions in C (external, for
    ctypes) and ``kernel_digest()``, the hash of the Python sources they were generated from
    (:func:`pmdcid.simulate.cache.sources_hash`: the loader uses a build only while it matches)."""
    head = (f"/* {RUNTIME_SOURCE.name}: generated by pmdcid/export/codegen.py from the kernel's\n"
            " * one source (pmdcid/simulate: terms.py, kernel.py, layout.py; identify/grid.py).\n"
            " * Do not edit: `python -m pmdcid.export.codegen` writes it (checked by\n"
            " * tests/system/test_codegen.py); setup.py compiles it, simulate/compiled.py\n"
            " * loads it.\n"
            " */\n#include <math.h>\n\n")
    return (head + f'const char *kernel_digest(void) {{ return "{sources_hash()}"; }}\n\n'
            + c_kernel(RUNTIME, public=True))


def main() -> int:
    """Write :data:`RUNTIME_SOURCE` (after an edit of the kernel's source)."""
    RUNTIME_SOURCE.write_text(runtime_source())
    print(f"pmdcid: wrote {RUNTIME_SOURCE}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

__all__ = ["ARRAYS", "ENTRIES", "RUNTIME", "CodegenError", "c_kernel", "collect",
           "matlab_kernel", "python_kernel", "runtime_source"]
