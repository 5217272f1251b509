"""No import cycles between modules: a grimp check and an import-linter contract.

import-linter's own ``acyclic_siblings`` contract compares packages as
aggregates (``workbench.methods`` against ``workbench.core``); this one
compares *modules*, which is what "no import cycle" means at run time. Every
import grimp sees is an edge, function-local ones included; imports under
``if TYPE_CHECKING:`` are left out when the graph is built with
``exclude_type_checking_imports`` (``[tool.importlinter]`` sets it).

Each strongly connected component of the module graph is a knot of cycles;
it is reported as a few short cycles that together use every import inside
it, each import with its line number, e.g.::

    workbench.io -> workbench.fileformat (l.18) -> workbench (l.190) -> workbench.io (l.13)

reads "workbench/io/__init__.py line 18 imports workbench.fileformat, whose line 190
imports workbench, whose line 13 imports workbench.io".

Used by ``lint-imports`` (``contract_types`` in pyproject.toml) and by
``tests/test_import_graph.py``.
"""

from __future__ import annotations

from collections import deque
from collections.abc import Iterable
from dataclasses import dataclass

import grimp
from importlinter.application import output
from importlinter.domain import fields
from importlinter.domain.contract import Contract, ContractCheck

__all__ = ["AcyclicModulesContract", "Cycle", "find_cycles", "format_cycles"]


@dataclass(frozen=True)
class Cycle:
    """``modules[0] -> modules[1] -> ... -> modules[0]``; ``lines[i]`` are the
    line numbers in ``modules[i]`` of its imports of the next module."""

    modules: tuple[str, ...]
    lines: tuple[tuple[int, ...], ...]

    def __str__(self) -> str:
        parts = [self.modules[0]]
        n = len(self.modules)
        for i in range(n):
            nxt = self.modules[(i + 1) % n]
            where = ",".join(str(x) for x in self.lines[i])
            parts.append(f"{nxt} (l.{where})" if where else nxt)
        return " -> ".join(parts)


def _within(module: str, packages: Iterable[str]) -> bool:
    return any(module == p or module.startswith(p + ".") for p in packages)


def _components(adj: dict[str, list[str]]) -> list[list[str]]:
    """Strongly connected components with a cycle (Tarjan, iterative)."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on_stack: set[str] = set()
    found: list[list[str]] = []
    counter = 0
    for root in sorted(adj):
        if root in index:
            continue
        work: list[tuple[str, int]] = [(root, 0)]
        while work:
            v, i = work.pop()
            if i == 0:
                index[v] = low[v] = counter
                counter += 1
                stack.append(v)
                on_stack.add(v)
            if i < len(adj[v]):
                work.append((v, i + 1))
                w = adj[v][i]
                if w not in index:
                    work.append((w, 0))
                elif w in on_stack:
                    low[v] = min(low[v], index[w])
                continue
            if work:  # v is done: pass its low link up to its caller
                parent = work[-1][0]
                low[parent] = min(low[parent], low[v])
            if low[v] == index[v]:
                comp: list[str] = []
                while True:
                    w = stack.pop()
                    on_stack.discard(w)
                    comp.append(w)
                    if w == v:
                        break
                if len(comp) > 1 or v in adj[v]:
                    found.append(sorted(comp))
    return sorted(found)


def _shortest_path(adj: dict[str, list[str]], members: set[str], start: str, goal: str) -> list[str]:
    """Shortest path start -> ... -> goal inside ``members`` (BFS; exists in an SCC)."""
    prev: dict[str, str | None] = {start: None}
    queue = deque([start])
    while queue:
        v = queue.popleft()
        if v == goal:
            break
        for w in adj[v]:
            if w in members and w not in prev:
                prev[w] = v
                queue.append(w)
    path = [goal]
    while prev[path[-1]] is not None:
        path.append(prev[path[-1]])  # type: ignore[arg-type]
    return path[::-1]


def find_cycles(graph: grimp.ImportGraph, packages: Iterable[str]) -> list[list[Cycle]]:
    """The import cycles among the modules of ``packages``, one list per knot.

    Each knot (strongly connected component) is given as short cycles that
    together cover every import between its modules: for each such import
    ``a -> b`` not yet shown, the cycle ``a -> b -> (shortest way back) -> a``.
    Returns ``[]`` when the modules are acyclic.
    """
    pkgs = list(packages)
    mods = sorted(m for m in graph.modules if _within(m, pkgs))
    inside = set(mods)
    adj = {
        m: sorted(x for x in graph.find_modules_directly_imported_by(m) if x in inside)
        for m in mods
    }
    knots: list[list[Cycle]] = []
    for comp in _components(adj):
        members = set(comp)
        covered: set[tuple[str, str]] = set()
        cycles: list[Cycle] = []
        for a in comp:
            for b in adj[a]:
                if b not in members or (a, b) in covered:
                    continue
                path = [a] if a == b else [a, *_shortest_path(adj, members, b, a)[:-1]]
                edges = [(path[i], path[(i + 1) % len(path)]) for i in range(len(path))]
                covered.update(edges)
                lines = tuple(
                    tuple(
                        sorted(
                            {
                                int(d["line_number"])
                                for d in graph.get_import_details(importer=u, imported=v)
                            }
                        )
                    )
                    for u, v in edges
                )
                cycles.append(Cycle(tuple(path), lines))
        knots.append(cycles)
    return knots


def format_cycles(knots: list[list[Cycle]]) -> str:
    """Readable report of :func:`find_cycles`' result ('' when there are none)."""
    out: list[str] = []
    for cycles in knots:
        members = sorted({m for c in cycles for m in c.modules})
        out.append(f"Import cycle among {len(members)} modules: {', '.join(members)}")
        out.extend(f"  {c}" for c in cycles)
    return "\n".join(out)


class AcyclicModulesContract(Contract):
    """import-linter contract: no import cycle among the modules of ``packages``.

    Configuration (pyproject.toml)::

        [tool.importlinter]
        exclude_type_checking_imports = true
        contract_types = ["acyclic_modules: tests.contracts.acyclic.AcyclicModulesContract"]

        [[tool.importlinter.contracts]]
        name = "No import cycles in workbench"
        type = "acyclic_modules"
        packages = ["workbench"]
    """

    type_name = "acyclic_modules"

    packages = fields.ListField(subfield=fields.StringField())

    def check(self, graph: grimp.ImportGraph, verbose: bool) -> ContractCheck:
        packages = list(self.packages)  # type: ignore[call-overload]
        missing = [p for p in packages if p not in graph.modules]
        if missing:
            raise ValueError(f"acyclic_modules: no such package(s) in the graph: {missing}")
        knots = find_cycles(graph, packages)
        return ContractCheck(kept=not knots, metadata={"knots": knots})

    def render_broken_contract(self, check: ContractCheck) -> None:
        knots: list[list[Cycle]] = check.metadata["knots"]
        n = sum(len(c) for c in knots)
        output.print_error(
            f"{n} import cycle(s) in {len(knots)} knot(s); each line is one cycle, "
            "(l.N) = line of the import in the module before the arrow:",
            bold=True,
        )
        output.new_line()
        for line in format_cycles(knots).splitlines():
            output.print_error(line, bold=not line.startswith(" "))
        output.new_line()
