"""A small, safe expression grammar for column mappings (no ``eval``).

Used when a mapping holds quotes or parentheses, e.g. ``omega="speed [rad/s]"*1`` or
``v=pwm*sign(dir)*12/255``::

    expr   := term (('+' | '-') term)*
    term   := factor (('*' | '/') factor)*
    factor := ('+' | '-') factor | NUMBER | UNIT | COLUMN | FUNC '(' expr ')' | '(' expr ')'
    COLUMN := "any text" | 'any text' | NAME      FUNC := sign | abs

A bare NAME is a unit (``rpm``, ``ms``, ``pi``, ... see :data:`pmdcid.io.mapping.UNITS`) when it
is one, otherwise a column (a misspelt unit is then a column the log lacks: an error naming it).
In the plain syntax (no quotes, no parentheses) a name after ``*`` or ``/`` must be a unit.

A parsed expression is a tree of tuples: ``("num", x)``, ``("col", name)``, ``("neg", a)``,
``("bin", op, a, b)``, ``("call", fn, a)``.
"""

from __future__ import annotations

import re

import numpy as np

from pmdcid.errors import LogError

FUNCS = {"sign": np.sign, "abs": np.abs}
#: longest expression [characters] and deepest nesting (parentheses and signs in a row) a
#: mapping may have: checked before parsing, so no input reaches Python's recursion limit
MAX_EXPR_CHARS = 400
MAX_EXPR_DEPTH = 32

_TOKEN = re.compile(r"""\s*(?:(?P<num>(?:\d+\.?\d*|\.\d+)(?:[eE][+-]?\d+)?)
                          |(?P<name>[A-Za-z_][A-Za-z0-9_.]*)
                          |"(?P<dq>[^"]*)"|'(?P<sq>[^']*)'
                          |(?P<op>[-+*/()]))""", re.X)


def _tokens(src: str, text: str) -> list[tuple[str, str]]:
    out, pos = [], 0
    while pos < len(src):
        if src[pos:].strip() == "":
            break
        m = _TOKEN.match(src, pos)
        if not m or m.end() == pos:
            raise LogError(f"column mapping '{text}': cannot read {src[pos:pos + 20]!r} "
                           "(quote column names holding spaces or symbols: \"speed [rad/s]\")")
        kind = m.lastgroup
        val = m.group(kind)
        out.append(("col" if kind in ("dq", "sq") else kind, val))
        pos = m.end()
    return out


class _Parser:
    def __init__(self, tokens, text: str, units: dict[str, float]):
        self.toks, self.k, self.text, self.units = tokens, 0, text, units

    def fail(self, why: str):
        raise LogError(f"column mapping '{self.text}': {why}")

    def peek(self):
        return self.toks[self.k] if self.k < len(self.toks) else (None, None)

    def take(self):
        tok = self.peek()
        self.k += 1
        return tok

    def expr(self):
        node = self.term()
        while self.peek() in (("op", "+"), ("op", "-")):
            op = self.take()[1]
            node = ("bin", op, node, self.term())
        return node

    def term(self):
        node = self.factor()
        while self.peek() in (("op", "*"), ("op", "/")):
            op = self.take()[1]
            rhs = self.factor()
            if op == "/" and rhs == ("num", 0.0):
                self.fail("divides by zero")
            node = ("bin", op, node, rhs)
        return node

    def factor(self):
        kind, val = self.take()
        if kind == "op" and val in "+-":
            inner = self.factor()
            return ("neg", inner) if val == "-" else inner
        if kind == "num":
            return ("num", float(val))
        if kind == "col":
            return ("col", val.strip())
        if kind == "name":
            if self.peek() == ("op", "("):
                if val not in FUNCS:
                    self.fail(f"unknown function '{val}' (known: {', '.join(FUNCS)})")
                self.take()
                inner = self.expr()
                self.close()
                return ("call", val, inner)
            if val in self.units:
                return ("num", self.units[val])
            return ("col", val)
        if (kind, val) == ("op", "("):
            inner = self.expr()
            self.close()
            return inner
        self.fail("expression ends too early" if kind is None else f"unexpected '{val}'")

    def close(self):
        if self.take() != ("op", ")"):
            self.fail("a '(' is not closed")


def _nesting(tokens) -> int:
    """Deepest nesting of ``tokens``: open parentheses plus signs in a row."""
    deepest = depth = signs = 0
    prev = None
    for kind, val in tokens:
        if kind == "op" and val == "(":
            depth += 1
        elif kind == "op" and val == ")":
            depth -= 1
        signs = signs + 1 if kind == "op" and val in "+-" and prev in (None, "(", "+", "-", "*",
                                                                        "/") else 0
        deepest = max(deepest, depth + signs)
        prev = val if kind == "op" else "x"
    return deepest


def parse_expr(src: str, text: str, units: dict[str, float]):
    """Parse ``src`` (the right-hand side of mapping ``text``) into a tree (see module doc).
    An expression longer than :data:`MAX_EXPR_CHARS` or nested deeper than
    :data:`MAX_EXPR_DEPTH` is refused before parsing (one line)."""
    short = text if len(text) <= 60 else text[:40] + "..."
    if len(src) > MAX_EXPR_CHARS:
        raise LogError(f"column mapping '{short}': the expression is {len(src)} characters long "
                       f"(at most {MAX_EXPR_CHARS}): map a simpler expression")
    toks = _tokens(src, text)
    if _nesting(toks) > MAX_EXPR_DEPTH:
        raise LogError(f"column mapping '{short}': nested deeper than {MAX_EXPR_DEPTH} levels "
                       "(parentheses or signs): simplify it")
    p = _Parser(toks, text, units)
    node = p.expr()
    if p.k != len(p.toks):
        p.fail(f"unexpected '{p.toks[p.k][1]}'")
    if not refs(node):
        p.fail("names no source column")
    return node


def refs(node) -> list[str]:
    """Column names an expression reads, in order of first appearance."""
    out: list[str] = []

    def walk(n):
        if n[0] == "col" and n[1] not in out:
            out.append(n[1])
        for sub in n[1:]:
            if isinstance(sub, tuple):
                walk(sub)
    walk(node)
    return out


def evaluate(node, get):
    """Value of the tree, ``get(name)`` giving a column as a float array."""
    kind = node[0]
    if kind == "num":
        return node[1]
    if kind == "col":
        return get(node[1])
    if kind == "neg":
        return -evaluate(node[1], get)
    if kind == "call":
        return FUNCS[node[1]](evaluate(node[2], get))
    a, b = evaluate(node[2], get), evaluate(node[3], get)
    with np.errstate(all="ignore"):
        return {"+": np.add, "-": np.subtract, "*": np.multiply, "/": np.divide}[node[1]](a, b)
