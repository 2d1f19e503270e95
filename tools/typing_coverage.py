"""How much of gesturekit's public API is annotated: parameters and return types.

The public API is every function of a public module (no part of its dotted name starts with an
underscore) whose name does not start with one, and every such method of the module's public
classes, ``__init__`` included (its parameters are the class's). ``self`` and ``cls`` are not
counted, nor the return of ``__init__``; ``*args`` and ``**kwargs`` are counted like any parameter.
Nested functions are not API. Prints the shares and the least annotated modules::

    python3 tools/typing_coverage.py [--min PERCENT] [--list]

``--min`` exits 1 when the share of parameters or of returns is below PERCENT (for CI once the
API is complete); ``--list`` prints every public function with something unannotated.
"""

from __future__ import annotations

import argparse
import ast
import sys
from dataclasses import dataclass
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


@dataclass
class Count:
    params: int = 0
    params_typed: int = 0
    returns: int = 0
    returns_typed: int = 0

    def add(self, other: Count) -> None:
        self.params += other.params
        self.params_typed += other.params_typed
        self.returns += other.returns
        self.returns_typed += other.returns_typed


def public(name: str) -> bool:
    return not name.startswith("_")


def module_name(path: Path) -> str:
    parts = list(path.relative_to(ROOT).with_suffix("").parts)
    if parts[-1] == "__init__":
        parts.pop()
    return ".".join(parts)


def count_function(node: ast.FunctionDef | ast.AsyncFunctionDef, *, method: bool) -> Count:
    args = node.args
    params = [*args.posonlyargs, *args.args, *args.kwonlyargs]
    if method and params and not any(isinstance(d, ast.Name) and d.id == "staticmethod" for d in node.decorator_list):
        params = params[1:]  # self or cls
    params += [a for a in (args.vararg, args.kwarg) if a is not None]
    c = Count(params=len(params), params_typed=sum(a.annotation is not None for a in params))
    if node.name != "__init__":
        c.returns, c.returns_typed = 1, int(node.returns is not None)
    return c


def functions(tree: ast.Module):
    """(qualified name, node, is a method) of a module's public functions and public classes' methods."""
    for node in tree.body:
        if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)) and public(node.name):
            yield node.name, node, False
        elif isinstance(node, ast.ClassDef) and public(node.name):
            for item in node.body:
                if isinstance(item, (ast.FunctionDef, ast.AsyncFunctionDef)) and (
                    public(item.name) or item.name == "__init__"
                ):
                    yield f"{node.name}.{item.name}", item, True


def measure(package: Path) -> dict[str, tuple[Count, list[str]]]:
    """Module -> (its count, the public functions with something unannotated)."""
    out = {}
    for path in sorted(package.rglob("*.py")):
        name = module_name(path)
        if not all(public(p) for p in name.split(".")):
            continue
        total, gaps = Count(), []
        for qualname, node, method in functions(ast.parse(path.read_text(encoding="utf-8"))):
            c = count_function(node, method=method)
            total.add(c)
            if c.params_typed < c.params or c.returns_typed < c.returns:
                gaps.append(qualname)
        out[name] = (total, gaps)
    return out


def measure_everything(package: Path) -> Count:
    """Every function and method, private and nested ones included (for comparison)."""
    total = Count()
    for path in sorted(package.rglob("*.py")):
        tree = ast.parse(path.read_text(encoding="utf-8"))
        methods = {id(item) for cls in ast.walk(tree) if isinstance(cls, ast.ClassDef) for item in cls.body}
        for node in ast.walk(tree):
            if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)):
                total.add(count_function(node, method=id(node) in methods))
    return total


def share(part: int, whole: int) -> float:
    return 100.0 * part / whole if whole else 100.0


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--min", type=float, metavar="PERCENT", help="fail below this share")
    ap.add_argument("--list", action="store_true", help="print every public function with a gap")
    args = ap.parse_args(argv)

    modules = measure(ROOT / "gesturekit")
    total = Count()
    for count, _ in modules.values():
        total.add(count)
    print(f"public API of gesturekit: {len(modules)} modules, {total.params} parameters, {total.returns} returns")
    print(
        f"parameters annotated: {total.params_typed} / {total.params} = {share(total.params_typed, total.params):.1f} %"
    )
    print(
        f"returns annotated:    {total.returns_typed} / {total.returns} = "
        f"{share(total.returns_typed, total.returns):.1f} %"
    )
    every = measure_everything(ROOT / "gesturekit")
    print(
        f"(every function, private and nested included: parameters "
        f"{share(every.params_typed, every.params):.1f} % of {every.params}, returns "
        f"{share(every.returns_typed, every.returns):.1f} % of {every.returns})"
    )
    worst = sorted(modules.items(), key=lambda kv: share(kv[1][0].params_typed, kv[1][0].params))
    print("least annotated modules (parameters, returns):")
    for name, (c, _) in worst[:8]:
        print(
            f"  {name:36s} {share(c.params_typed, c.params):5.1f} % of {c.params:3d}   "
            f"{share(c.returns_typed, c.returns):5.1f} % of {c.returns:3d}"
        )
    if args.list:
        for name, (_, gaps) in modules.items():
            for qualname in gaps:
                print(f"{name}.{qualname}")
    if args.min is not None:
        low = min(share(total.params_typed, total.params), share(total.returns_typed, total.returns))
        if low < args.min:
            print(f"below {args.min:g} %", file=sys.stderr)
            return 1
    return 0


if __name__ == "__main__":
    sys.exit(main())
