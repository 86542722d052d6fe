"""Griffe extension: numpydoc's Sphinx roles rendered as mkdocstrings cross-references.

wardjax's docstrings are numpydoc, whose cross-references are Sphinx roles
(``:class:`WardParams```, ``:func:`~wardjax.run_batch```). mkdocstrings renders
numpydoc sections but not roles, so each role is rewritten, before the
docstring is parsed, into an autorefs reference: the name is resolved in the
scope of the object that carries the docstring (its module's imports, relative
names such as ``._data.moments_chunk``), then among ``wardjax``'s public names,
then among unique member names of the package. The reference is *optional*:
a target that the API pages document becomes a link, any other (a private
helper) renders as code, never as a raw role. ``:math:`x``` becomes inline
maths for arithmatex.

Used by ``mkdocs.yml`` (``extensions:``) and by ``tests/test_docs.py``.
"""

from __future__ import annotations

import re
from html import escape

import griffe

ROLE = re.compile(r":(?:py:)?(?P<role>class|func|meth|attr|mod|data|obj|exc|const|math):`(?P<body>[^`]+)`")
"""A Sphinx role as written in a docstring."""

RAW_ROLE = re.compile(r":(?:py:)?(?:class|func|meth|attr|mod|data|obj|exc|const|math):(?:`|<code>)")
"""What a role left unconverted looks like in Markdown or in the built HTML."""

EXPLICIT_TITLE = re.compile(r"^(?P<title>.+?)\s*<(?P<target>[^>]+)>$")


def _objects(obj: griffe.Object):
    """``obj`` and every member defined under it (aliases skipped: each object is visited where it lives)."""
    yield obj
    for member in obj.members.values():
        if not member.is_alias:
            yield from _objects(member)  # type: ignore[arg-type]


def _module(obj: griffe.Object) -> griffe.Object:
    while not obj.is_module and obj.parent is not None:
        obj = obj.parent
    return obj


class Resolver:
    """Names as written in a docstring → dotted paths (or ``None``) within one package."""

    def __init__(self, package: griffe.Object) -> None:
        self.package = package
        self.by_name: dict[str, set[str]] = {}
        for obj in _objects(package):
            self.by_name.setdefault(obj.name, set()).add(obj.path)

    def _exists(self, path: str) -> bool:
        try:
            self.package.modules_collection[path]  # type: ignore[index]
        except Exception:  # KeyError, or an alias that cannot be resolved
            return False
        return True

    def resolve(self, name: str, scope: griffe.Object) -> str | None:
        """The dotted path ``name`` means in ``scope``, or ``None``."""
        name = name.strip().removesuffix("()")
        root = self.package.name
        if name.startswith("wj."):
            name = f"{root}.{name[3:]}"
        if name.startswith("."):  # relative to the module's package, as in a relative import
            module = _module(scope)
            base = module.path if module.is_package else module.path.rpartition(".")[0]
            dots = len(name) - len(name.lstrip("."))
            for _ in range(dots - 1):
                base = base.rpartition(".")[0]
            name = f"{base}.{name.lstrip('.')}"
        if name.startswith(f"{root}.") or name == root:
            return name if self._exists(name) else None
        head, _, rest = name.partition(".")
        for obj in (scope, _module(scope)):
            try:
                found = obj.resolve(head)
            except Exception:  # NameResolutionError, or an alias that cannot be resolved
                continue
            path = f"{found}.{rest}" if rest else found
            if self._exists(path):
                return path
        if self._exists(f"{root}.{name}"):
            return f"{root}.{name}"
        candidates = self.by_name.get(name.rpartition(".")[2], set())
        matching = {p for p in candidates if p.endswith(f".{name}")}
        return matching.pop() if len(matching) == 1 else None


def convert(text: str, scope: griffe.Object, resolver: Resolver) -> str:
    """``text`` with every Sphinx role replaced by an optional autorefs reference (or arithmatex maths)."""

    def replace(m: re.Match[str]) -> str:
        role, body = m["role"], m["body"]
        if role == "math":
            return f"${body}$"
        explicit = EXPLICIT_TITLE.match(body)
        if explicit:
            title, target = explicit["title"], explicit["target"]
        else:
            target = body
            short = target.startswith("~")
            target = target.lstrip("~")
            title = target.rpartition(".")[2] if short else target.lstrip(".")
            if role in ("func", "meth") and not title.endswith(")"):
                title += "()"
        path = resolver.resolve(target.lstrip("~"), scope)
        code = f"<code>{escape(title)}</code>"
        if path is None:
            return code
        return f'<autoref identifier="{escape(path)}" optional>{code}</autoref>'

    return ROLE.sub(replace, text)


def convert_package(package: griffe.Object) -> int:
    """Rewrite the roles in every docstring under ``package`` in place; return how many docstrings changed."""
    resolver = Resolver(package)
    changed = 0
    for obj in _objects(package):
        if obj.docstring is not None and ROLE.search(obj.docstring.value):
            obj.docstring.value = convert(obj.docstring.value, obj, resolver)
            changed += 1
    return changed


class SphinxRoles(griffe.Extension):
    """Rewrite the Sphinx roles of a package's docstrings once the package is loaded."""

    def on_package(self, *, pkg: griffe.Module, **kwargs) -> None:
        convert_package(pkg)
