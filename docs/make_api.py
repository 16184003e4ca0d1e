"""Write docs/api.md, the reference of every public name, from the package itself.

    .venv/bin/python docs/make_api.py          # rewrite docs/api.md
    .venv/bin/python docs/make_api.py --check  # exit 1 if docs/api.md is out of date

The public names are those ``jmse_jax/__init__.py`` and ``jmse_jax/lens/__init__.py``
re-export (``from ._module import name as name``). For each: its signature and the first
paragraph of its docstring; for a class also its public methods and properties; for a
constant its value and the ``#:`` comment above its definition. tests/test_api_docs.py
checks that the file is current, so a change of signature or docstring shows up here.
"""

from __future__ import annotations

import ast
import enum
import importlib
import inspect
import pathlib
import re
import sys

ROOT = pathlib.Path(__file__).resolve().parent.parent
API = ROOT / "docs" / "api.md"
MODULES = ("jmse_jax", "jmse_jax.lens")
VALUE_WIDTH = 90


def public_names(module_name: str) -> list[tuple[str, str]]:
    """``(name, defining module)`` of each ``from .x import name as name`` in ``__init__``."""
    init = ROOT / pathlib.Path(*module_name.split(".")) / "__init__.py"
    names = []
    for node in ast.parse(init.read_text()).body:
        if isinstance(node, ast.ImportFrom) and node.level == 1 and node.module:
            for alias in node.names:
                if alias.asname == alias.name:
                    names.append((alias.name, f"{module_name}.{node.module}"))
    return names


def summary(doc: str | None) -> str:
    """The first paragraph of a docstring, on one line ("" when there is none)."""
    if not doc:
        return ""
    paragraph = inspect.cleandoc(doc).split("\n\n", 1)[0]
    return " ".join(paragraph.split())


def signature(obj) -> str:
    try:
        text = str(inspect.signature(obj))
    except (TypeError, ValueError):
        return "(...)"
    # Annotations are strings under ``from __future__ import annotations``: shown unquoted.
    text = re.sub(r"(: |-> )'([^']*)'", r"\1\2", text)
    text = re.sub(r"ForwardRef\('([^']*)'\)", r"\1", text)  # NamedTuple fields
    # Object addresses in default values would change on every run.
    return re.sub(r" at 0x[0-9a-f]+", "", text)


def constant_comment(module_name: str, name: str) -> str:
    """The ``#:`` comment block right above ``name = ...`` in its module's source."""
    path = ROOT / pathlib.Path(*module_name.split(".")).with_suffix(".py")
    lines = path.read_text().splitlines()
    pattern = re.compile(rf"{re.escape(name)}\s*(:[^=]*)?=")
    for i, line in enumerate(lines):
        if pattern.match(line):
            comment = []
            j = i - 1
            while j >= 0 and re.match(r"[A-Z][A-Z0-9_]* = ", lines[j]):
                j -= 1  # a group of constants under one comment
            while j >= 0 and lines[j].startswith("#:"):
                comment.insert(0, lines[j][2:].strip())
                j -= 1
            return first_sentence(" ".join(" ".join(comment).split()))
    return ""


def first_sentence(text: str) -> str:
    """Up to the first full stop that ends a sentence (not one inside "e.g." or "1e-4")."""
    match = re.match(r"(.{20,}?[a-z0-9)`'][.])(\s+[A-Z(`]|$)", text)
    return match.group(1) if match else text


def short_value(value) -> str:
    text = " ".join(repr(value).split())
    return text if len(text) <= VALUE_WIDTH else text[: VALUE_WIDTH - 5] + " ...)"


def member_doc(cls, name: str) -> str:
    """A method's or property's docstring summary, from the nearest class in ``cls``'s MRO
    that documents it (an override inherits its abstract method's)."""
    for base in cls.__mro__:
        attribute = vars(base).get(name)
        if attribute is not None:
            text = summary(getattr(attribute, "__func__", attribute).__doc__)
            if text:
                return text
    return ""


def members(cls) -> list[str]:
    """Public methods and properties defined by ``cls`` (not inherited from equinox)."""
    lines = []
    for name, attribute in sorted(vars(cls).items()):
        if name.startswith("_"):
            continue
        function = getattr(attribute, "__func__", attribute)  # static and class methods
        if isinstance(attribute, property):
            lines.append(f"  - `.{name}` (property): {member_doc(cls, name)}")
        elif inspect.isfunction(function):
            lines.append(f"  - `.{name}{signature(function)}`: {member_doc(cls, name)}")
    return lines


def entry(module, name: str, defined_in: str) -> list[str]:
    obj = getattr(module, name)
    source = defined_in.replace(".", "/") + ".py"
    if inspect.isclass(obj):
        kind = "enumeration" if issubclass(obj, enum.Enum) else "class"
        abstract = kind != "class" or name.startswith("Abstract")
        constructor = signature(obj).removesuffix(" -> None")
        head = f"### `{name}`" if abstract else f"### `{name}{constructor}`"
        lines = [head, "", f"*{kind}, `{source}`.* {summary(obj.__doc__)}"]
        methods = members(obj)
        if methods:
            lines += ["", *methods]
    elif callable(obj):
        lines = [f"### `{name}{signature(obj)}`", "", f"*function, `{source}`.* "
                 f"{summary(obj.__doc__)}"]
    else:
        comment = constant_comment(defined_in, name)
        lines = [f"### `{name}`", "", f"*constant, `{source}`.* `{short_value(obj)}`"
                 + (f" {comment}" if comment else "")]
    return [line.rstrip() for line in lines] + [""]


def undocumented() -> list[str]:
    """Public functions, classes, methods and properties without a docstring, and public
    constants without a ``#:`` comment."""
    missing = []
    for module_name in MODULES:
        module = importlib.import_module(module_name)
        for name, defined_in in public_names(module_name):
            obj = getattr(module, name)
            if inspect.isclass(obj):
                if not summary(obj.__doc__):
                    missing.append(f"{module_name}.{name}")
                for attribute_name, attribute in vars(obj).items():
                    function = getattr(attribute, "__func__", attribute)
                    documented = isinstance(attribute, property) or inspect.isfunction(function)
                    if (documented and not attribute_name.startswith("_")
                            and not member_doc(obj, attribute_name)):
                        missing.append(f"{module_name}.{name}.{attribute_name}")
            elif callable(obj):
                if not summary(obj.__doc__):
                    missing.append(f"{module_name}.{name}")
            elif not constant_comment(defined_in, name):
                missing.append(f"{module_name}.{name}")
    return missing


def render() -> str:
    out = [
        "# API reference",
        "",
        "Every public name of `jmse_jax` and `jmse_jax.lens`: its signature and the first",
        "paragraph of its docstring (`help(name)` in Python gives the whole of it: parameters",
        "with units and shapes, the equation, the paper's reference and an example). Units and",
        "signs: [conventions.md](conventions.md). Written by `docs/make_api.py` from the",
        "package; `tests/test_api_docs.py` checks that it is current.",
        "",
    ]
    for module_name in MODULES:
        module = importlib.import_module(module_name)
        names = public_names(module_name)
        out += [f"## `{module_name}`", ""]
        out.append(summary(module.__doc__))
        out.append("")
        for name, defined_in in sorted(names, key=lambda item: item[0].lower()):
            out += entry(module, name, defined_in)
    return "\n".join(out).rstrip() + "\n"


def main(argv: list[str]) -> int:
    text = render()
    if "--check" in argv:
        if API.read_text() != text:
            print(f"{API} is out of date: run python docs/make_api.py", file=sys.stderr)
            return 1
        return 0
    API.write_text(text)
    print(f"wrote {API}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main(sys.argv[1:]))
