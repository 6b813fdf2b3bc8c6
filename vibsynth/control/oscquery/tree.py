"""The OSCQuery tree: every OSC method the server answers as a node, generated from the handler's tables.

A node is built from a :class:`NodeSpec` (TYPE, ACCESS, RANGE, UNIT, DESCRIPTION and how to
read its VALUE). The specs of the OSC methods are in :mod:`~vibsynth.control.oscquery.methods`;
the handler says which methods it answers (:meth:`OscHandler.method_names`), its address space
says where (global, ``ch/{n}``, ``source/{k}``). Further nodes come from a :class:`NodeTable`
registered with :meth:`Tree.register` (the VRChat bridge's ``/avatar``); the adapter then calls
:meth:`~vibsynth.control.oscquery.server.OscQueryServer.structure_changed` (clients get
``PATH_ADDED`` at once) and, whenever one of its values changes,
:meth:`~vibsynth.control.oscquery.server.OscQueryServer.value_changed` (listeners get it within
5 ms; without the call they get it within the 50 ms poll).

Rules every node keeps (Vidvox OSCQueryProposal; ``tests/control/oscquery/test_tree.py``):

* ``VALUE``, ``RANGE`` and ``UNIT`` are arrays with one item per type tag of ``TYPE``;
* a node with a ``VALUE`` has ``ACCESS`` 1 or 3; a node without (a trigger such as ``play``
  or ``sync``, a container) has ``ACCESS`` 0, so clients that expect a VALUE wherever
  ACCESS is non-zero (python-oscquery) read the whole tree;
* containers have ``CONTENTS`` and no ``TYPE``.
"""

from __future__ import annotations

import json
import threading
from collections.abc import Callable, Iterable, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any, Protocol

__all__ = ["NodeSpec", "NodeTable", "Node", "Tree", "Context", "ATTRIBUTES", "TYPE_TAGS"]

#: Attributes a query may name (``?VALUE``); others are answered 400.
ATTRIBUTES = ("FULL_PATH", "CONTENTS", "TYPE", "ACCESS", "VALUE", "RANGE", "DESCRIPTION", "UNIT", "HOST_INFO")
#: OSC type tags a node may declare (one VALUE/RANGE/UNIT item each).
TYPE_TAGS = frozenset("ifsdhTF")

Value = Callable[["Context"], "Sequence[Any] | None"]
Range = Callable[["Context"], "list[dict[str, Any] | None]"]


class Context:
    """What value readers share during one request or one push round (each read taken once, lazily).

    Parameters
    ----------
    reads : mapping of str to callable
        Name -> a function reading it (the controller's state, the sources' views...).
    """

    def __init__(self, reads: Mapping[str, Callable[[], Any]]) -> None:
        self._reads = reads
        self._cache: dict[str, Any] = {}

    def __getitem__(self, name: str) -> Any:
        if name not in self._cache:
            self._cache[name] = self._reads[name]()
        return self._cache[name]


@dataclass(frozen=True)
class NodeSpec:
    """What a method node says about itself.

    Attributes
    ----------
    types : str
        OSC type tags of the messages it takes ("" = none, or any: TYPE is left out).
    description : str
    value : callable, optional
        ``value(context) -> list`` (one item per type tag), or None when the method holds no
        value (ACCESS 0). A reader returning None leaves VALUE out for now.
    range : callable, optional
        ``range(context) -> [{"MIN":..,"MAX":..} or {"VALS": [...]} or None, ...]``.
    unit : tuple of str or None
        One unit (from the proposal's units.md) or None per type tag.
    writable : bool
        Messages set what VALUE reads (ACCESS 3); False with a value: read-only (ACCESS 1).
    """

    types: str
    description: str
    value: Value | None = None
    range: Range | None = None
    unit: tuple[str | None, ...] | None = None
    writable: bool = True

    @property
    def access(self) -> int:
        if self.value is None:
            return 0
        return 3 if self.writable else 1


class NodeTable(Protocol):
    """Extra nodes (an adapter's address space): ``nodes() -> {full path: NodeSpec}`` (called at each refresh)."""

    def nodes(self) -> Mapping[str, NodeSpec]: ...


@dataclass
class Node:
    """A method (``spec`` set) or a container (``children``)."""

    path: str
    spec: NodeSpec | None = None
    children: dict[str, Node] = field(default_factory=dict)
    description: str = ""

    def json(self, ctx: Context, *, deep: bool = True) -> dict[str, Any]:
        """The node as the proposal's JSON object (with CONTENTS when ``deep``)."""
        out: dict[str, Any] = {"FULL_PATH": self.path}
        spec = self.spec
        if spec is None:
            out["ACCESS"] = 0
            out["DESCRIPTION"] = self.description
            if deep and self.children:
                out["CONTENTS"] = {name: child.json(ctx) for name, child in self.children.items()}
            return out
        out["DESCRIPTION"] = spec.description
        if spec.types:
            out["TYPE"] = spec.types
        value = spec.value(ctx) if spec.value is not None else None
        out["ACCESS"] = spec.access if value is not None else 0
        if value is not None:
            out["VALUE"] = list(value)
        if spec.range is not None and spec.types:
            out["RANGE"] = spec.range(ctx)
        if spec.unit is not None and spec.types:
            out["UNIT"] = list(spec.unit)
        return out

    def signature(self, ctx: Context) -> str:
        """What a client caches of the node (everything but VALUE): a change is PATH_CHANGED."""
        data = self.json(ctx, deep=False)
        data.pop("VALUE", None)
        return json.dumps(data, sort_keys=True)


def _container_description(path: str) -> str:
    last = path.rsplit("/", 1)[-1]
    if last.isdigit():
        return f"{path.rsplit('/', 2)[-2]} {last}"
    return {"ch": "channels (1-based)", "source": "touch sources (docs/vr.md)"}.get(last, last)


class Tree:
    """The address space as OSCQuery nodes, rebuilt by :meth:`refresh` (structure) and read live (values).

    Parameters
    ----------
    build : callable
        ``build() -> {full path: NodeSpec}``: the OSC methods (see
        :func:`~vibsynth.control.oscquery.methods.method_nodes`).
    reads : mapping of str to callable
        The :class:`Context` readers the specs use.
    root_description : str
    """

    def __init__(
        self,
        build: Callable[[], Mapping[str, NodeSpec]],
        reads: Mapping[str, Callable[[], Any]],
        *,
        root_description: str = "",
    ) -> None:
        self._build = build
        self._reads = reads
        self.root_description = root_description
        self._tables: list[NodeTable] = []
        self._lock = threading.Lock()
        self.nodes: dict[str, Node] = {}
        self.methods: dict[str, NodeSpec] = {}
        self._signatures: dict[str, str] = {}
        self.refresh()

    def register(self, table: NodeTable) -> None:
        """Add a table of extra nodes (taken at the next :meth:`refresh`)."""
        with self._lock:
            self._tables.append(table)

    def context(self) -> Context:
        """A fresh :class:`Context` (one snapshot of each reading)."""
        return Context(self._reads)

    def refresh(self) -> list[tuple[str, str]]:
        """Rebuild the structure; returns what changed as ``[(command, path)]``.

        Commands: ``PATH_ADDED`` and ``PATH_REMOVED`` (methods), ``PATH_CHANGED`` (a method
        whose TYPE, RANGE (e.g. the preset names), UNIT, ACCESS or DESCRIPTION changed).
        """
        methods = dict(self._build())
        with self._lock:
            tables = list(self._tables)
        for table in tables:
            for path, spec in table.nodes().items():
                methods.setdefault(path, spec)
        nodes: dict[str, Node] = {"/": Node("/", description=self.root_description)}
        for path in methods:
            parent = nodes["/"]
            parts = path.strip("/").split("/")
            for i, part in enumerate(parts):
                sub = "/" + "/".join(parts[: i + 1])
                node = nodes.get(sub)
                if node is None:
                    node = nodes[sub] = Node(sub, description=_container_description(sub))
                    parent.children[part] = node
                parent = node
            parent.spec = methods[path]
        ctx = self.context()
        signatures = {path: nodes[path].signature(ctx) for path in methods}
        with self._lock:
            old = self._signatures
            self.nodes, self.methods, self._signatures = nodes, methods, signatures
        events = [("PATH_REMOVED", p) for p in old if p not in signatures]
        events += [("PATH_ADDED", p) for p in signatures if p not in old]
        events += [("PATH_CHANGED", p) for p, s in signatures.items() if p in old and old[p] != s]
        return events

    def find(self, path: str) -> Node | None:
        """The node at ``path`` (a trailing ``/`` is ignored), or None."""
        if len(path) > 1:
            path = path.rstrip("/") or "/"
        return self.nodes.get(path)

    def value(self, path: str, ctx: Context) -> tuple[str, list[Any]] | None:
        """``(TYPE, VALUE)`` of a method that holds a value now, or None."""
        spec = self.methods.get(path)
        if spec is None or spec.value is None:
            return None
        value = spec.value(ctx)
        return None if value is None else (spec.types, list(value))


def paths_of(tree: Tree, prefix: str) -> Iterable[str]:
    """The method paths under ``prefix`` (for tests and docs)."""
    return (p for p in tree.methods if p.startswith(prefix))
