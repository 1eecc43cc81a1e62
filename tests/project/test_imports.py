"""The import graph of the library: no module of dmpopt imports another that imports it back,
directly or through others, and none imports the studies (tests/project/test_cli.py checks the
latter at run time)."""

import ast
from pathlib import Path

import dmpopt

ROOT = Path(dmpopt.__file__).parent


def _modules() -> dict:
    """Module name -> file, for every module of dmpopt."""
    found = {}
    for path in ROOT.rglob("*.py"):
        parts = ("dmpopt", *path.relative_to(ROOT).with_suffix("").parts)
        found[".".join(parts[:-1] if parts[-1] == "__init__" else parts)] = path
    return found


def _imports(name: str, path: Path, modules: dict) -> set:
    """The modules ``name`` imports, anywhere in its file (inside functions too); ``from
    package import module`` counts as importing the module, not the package."""
    package = name if path.name == "__init__.py" else name.rpartition(".")[0]
    targets = set()
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.Import):
            targets |= {alias.name for alias in node.names}
        elif isinstance(node, ast.ImportFrom):
            base = node.module or ""
            if node.level:
                parts = package.split(".")[: len(package.split(".")) - node.level + 1]
                base = ".".join(parts + ([base] if base else []))
            submodules = {f"{base}.{alias.name}" for alias in node.names}
            targets |= submodules & set(modules) or {base}
    return {target for target in targets if target in modules and target != name}


def _cycles(graph: dict) -> list:
    """Strongly connected components of more than one module (Tarjan's algorithm)."""
    index, low, stack, on_stack, found = {}, {}, [], set(), []

    def visit(node):
        index[node] = low[node] = len(index)
        stack.append(node)
        on_stack.add(node)
        for other in graph[node]:
            if other not in index:
                visit(other)
                low[node] = min(low[node], low[other])
            elif other in on_stack:
                low[node] = min(low[node], index[other])
        if low[node] == index[node]:
            component = set()
            while not component or node not in component:
                component.add(stack.pop())
            on_stack.difference_update(component)
            if len(component) > 1:
                found.append(sorted(component))

    for node in graph:
        if node not in index:
            visit(node)
    return found


def test_the_library_has_no_import_cycle_and_never_imports_the_studies():
    modules = _modules()
    graph = {name: _imports(name, path, modules) for name, path in modules.items()}
    for name, path in modules.items():
        tree = ast.parse(path.read_text())
        named = [
            node
            for node in ast.walk(tree)
            if isinstance(node, ast.Import)
            and any(a.name.split(".")[0] == "dmpopt_studies" for a in node.names)
            or isinstance(node, ast.ImportFrom)
            and (node.module or "").split(".")[0] == "dmpopt_studies"
            and not node.level
        ]
        assert named == [], name
    assert _cycles(graph) == []
    assert graph["dmpopt.cli"] >= {"dmpopt.folders"}  # the graph sees the command's imports


def test_the_cycle_finder_finds_a_cycle():
    """Its answer key: a three-module loop and a self-standing pair, written out."""
    graph = {"a": {"b"}, "b": {"c"}, "c": {"a"}, "d": {"e"}, "e": set()}
    assert _cycles(graph) == [["a", "b", "c"]]


def test_every_package_folder_is_installed_under_its_name():
    """pyproject.toml lists the packages by hand (studies/ and robots/ install as
    dmpopt_studies and dmpopt_robots): a new package folder left out of the list would be
    missing from the wheel."""
    import tomllib

    repo = ROOT.parent
    setuptools = tomllib.loads((repo / "pyproject.toml").read_text())["tool"]["setuptools"]
    names = {folder: name for name, folder in setuptools["package-dir"].items()}
    found = set()
    for init in repo.glob("*/**/__init__.py"):
        top, *rest = init.parent.relative_to(repo).parts
        if top in ("dmpopt", *names):
            found.add(".".join([names.get(top, top), *rest]))
    assert found == set(setuptools["packages"])
