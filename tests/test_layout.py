"""The module graph of ``soaring_env`` and ``baselines``: no import cycles, and the layers hold.

Every ``import`` statement of every module counts -- at module level, inside functions and under
``TYPE_CHECKING`` -- read with :mod:`ast` (nothing is imported). An edge goes to the deepest module
the statement names (``from a.b import c`` -> ``a.b.c`` if that is a module, else ``a.b``). The
implicit import of a module's parent packages is not an edge: every submodule import runs its
parents' ``__init__`` first, and counting that would make every package that re-exports its
submodules a cycle.
"""

from __future__ import annotations

import ast
import graphlib
import importlib
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
PACKAGES = ("soaring_env", "baselines")

#: Lowest first; a module may import only from its own layer or below. A module belongs to the
#: longest entry that is it or one of its parent packages (``soaring_env`` alone is the package's
#: facade ``__init__``, and any new top-level module until it is placed here).
LAYERS: tuple[tuple[str, ...], ...] = (
    ("soaring_env._jit", "soaring_env._validation", "soaring_env._threads"),
    ("soaring_env.physics",),
    ("soaring_env.primitives", "soaring_env.scenario"),
    ("soaring_env.model",),
    ("soaring_env.env", "soaring_env"),
    ("baselines",),
    ("baselines.cli",),  # the command-line programs: nothing imports them
)


def find_modules(root: Path, packages: tuple[str, ...]) -> dict[str, Path]:
    """Dotted module name -> file, for every ``.py`` file of ``packages`` under ``root``."""
    mods: dict[str, Path] = {}
    for pkg in packages:
        for path in sorted((root / pkg).rglob("*.py")):
            parts = path.relative_to(root).with_suffix("").parts
            if parts[-1] == "__init__":
                parts = parts[:-1]
            mods[".".join(parts)] = path
    return mods


def imports_of(name: str, path: Path, modules: dict[str, Path]) -> set[str]:
    """The modules of ``modules`` that module ``name`` (file ``path``) imports anywhere."""
    tree = ast.parse(path.read_text(), filename=str(path))
    package = name.split(".") if path.name == "__init__.py" else name.split(".")[:-1]
    found: set[str] = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            targets = [alias.name for alias in node.names]
        elif isinstance(node, ast.ImportFrom):
            if node.level:  # relative: from .x import y
                base = package[: len(package) - (node.level - 1)]
                mod = ".".join([*base, *([node.module] if node.module else [])])
            else:
                mod = node.module or ""
            targets = [f"{mod}.{a.name}" if f"{mod}.{a.name}" in modules else mod for a in node.names]
        else:
            continue
        for target in targets:
            while target and target not in modules:  # `import a.b.c` of a package that has no a.b.c module
                target = target.rpartition(".")[0]
            if target and target != name:
                found.add(target)
    return found


def import_graph(root: Path = ROOT, packages: tuple[str, ...] = PACKAGES) -> dict[str, set[str]]:
    """Module -> the modules it imports (within ``packages``)."""
    modules = find_modules(root, packages)
    return {name: imports_of(name, path, modules) for name, path in modules.items()}


def cycle_of(graph: dict[str, set[str]]) -> list[str] | None:
    """One import cycle (``[a, b, ..., a]``), or None if the graph is acyclic."""
    try:
        graphlib.TopologicalSorter(graph).prepare()
    except graphlib.CycleError as exc:
        return list(exc.args[1])
    return None


def layer_of(module: str) -> int:
    best, level = "", len(LAYERS) - 1
    for i, entries in enumerate(LAYERS):
        for entry in entries:
            if (module == entry or module.startswith(entry + ".")) and len(entry) > len(best):
                best, level = entry, i
    return level


GRAPH = import_graph()


def test_the_graph_sees_every_kind_of_import() -> None:
    """Sanity: module-level, function-level, TYPE_CHECKING and submodule imports are all edges."""
    assert "soaring_env.physics.thermals" in GRAPH["soaring_env.scenario"]  # module level
    assert "soaring_env.env.rendering" in GRAPH["soaring_env.env.core"]  # in a function and TYPE_CHECKING
    assert "baselines.sst.soaring" in GRAPH["baselines.agents"]  # in a method
    assert "baselines.sst._kernels" in GRAPH["baselines.sst.core"]  # from baselines.sst import _kernels
    assert len(GRAPH) > 30


def test_cycle_detection_finds_a_planted_cycle(tmp_path: Path) -> None:
    pkg = tmp_path / "pkg"
    (pkg / "sub").mkdir(parents=True)
    (pkg / "__init__.py").write_text("")
    (pkg / "sub" / "__init__.py").write_text("from pkg.sub.b import B\n")
    (pkg / "a.py").write_text("import numpy\nfrom pkg.sub import b\n")
    (pkg / "sub" / "b.py").write_text("from typing import TYPE_CHECKING\nif TYPE_CHECKING:\n    from ..a import A\n")
    graph = import_graph(tmp_path, ("pkg",))
    assert graph["pkg.a"] == {"pkg.sub.b"} and graph["pkg.sub.b"] == {"pkg.a"}
    cycle = cycle_of(graph)
    assert cycle is not None and set(cycle) == {"pkg.a", "pkg.sub.b"}
    (pkg / "sub" / "b.py").write_text("def f():\n    import pkg\n")  # b -> pkg: no way back
    assert cycle_of(import_graph(tmp_path, ("pkg",))) is None


def test_no_import_cycles() -> None:
    cycle = cycle_of(GRAPH)
    assert cycle is None, "import cycle: " + " -> ".join(cycle or [])


def test_layers_hold() -> None:
    upward = [
        f"{a} (layer {layer_of(a)}) imports {b} (layer {layer_of(b)})"
        for a, targets in sorted(GRAPH.items())
        for b in sorted(targets)
        if layer_of(b) > layer_of(a)
    ]
    assert not upward, "imports against the layer order:\n" + "\n".join(upward)


@pytest.mark.parametrize(
    ("lower", "forbidden"),
    [
        ("soaring_env.physics", ("soaring_env.", "baselines")),  # physics: only physics, _jit, _validation
        ("soaring_env", ("baselines",)),  # the env package never needs the baselines
    ],
)
def test_lower_packages_import_nothing_above(lower: str, forbidden: tuple[str, ...]) -> None:
    allowed = (lower, "soaring_env._jit", "soaring_env._validation")
    bad = [
        f"{a} -> {b}"
        for a, targets in sorted(GRAPH.items())
        if a == lower or a.startswith(lower + ".")
        for b in sorted(targets)
        if b.startswith(forbidden) and not any(b == p or b.startswith(p + ".") for p in allowed)
    ]
    assert not bad, "\n".join(bad)


def test_wheel_ships_py_typed_for_both_packages(tmp_path: Path) -> None:
    """PEP 561: a type checker outside the checkout sees our hints only through ``py.typed``.

    (An editable install's default setuptools finder hook is invisible to type checkers; the
    ``editable_mode=compat`` install is a plain path entry they follow.)
    """
    import importlib.metadata
    import subprocess
    import sys
    import zipfile

    try:
        if int(importlib.metadata.version("setuptools").split(".")[0]) < 68:
            pytest.skip("needs setuptools >= 68 (pyproject's build requirement) to build without isolation")
    except importlib.metadata.PackageNotFoundError:
        pytest.skip("needs setuptools to build the wheel without network access")
    src = tmp_path / "src"
    src.mkdir()
    for name in ("pyproject.toml", "README.md", "LICENSE"):
        (src / name).write_bytes((ROOT / name).read_bytes())
    for pkg in PACKAGES:
        for path in (ROOT / pkg).rglob("*"):
            if path.is_file() and "__pycache__" not in path.parts:
                dst = src / path.relative_to(ROOT)
                dst.parent.mkdir(parents=True, exist_ok=True)
                dst.write_bytes(path.read_bytes())
    out = tmp_path / "wheel"
    subprocess.run(
        [sys.executable, "-m", "pip", "wheel", "-q", "--no-deps", "--no-build-isolation", "-w", str(out), str(src)],
        check=True,
        capture_output=True,
        timeout=300,
    )
    (wheel,) = out.glob("*.whl")
    names = zipfile.ZipFile(wheel).namelist()
    assert {f"{pkg}/py.typed" for pkg in PACKAGES} <= set(names)
    assert {n.split("/")[0] for n in names} == {*PACKAGES, f"soaring_env-{wheel.name.split('-')[1]}.dist-info"}


def test_console_commands_and_script_shims_run_the_cli_modules() -> None:
    """Every ``[project.scripts]`` command names a ``main`` of :mod:`baselines.cli`, and every
    ``scripts/<name>.py`` is a shim for the module of the same name."""
    tomllib = pytest.importorskip("tomllib")  # Python >= 3.11
    root = Path(__file__).resolve().parents[1]
    commands = tomllib.loads((root / "pyproject.toml").read_text())["project"]["scripts"]
    shims = sorted(p.stem for p in (root / "scripts").glob("*.py"))
    assert sorted(v.split(":")[0].rsplit(".", 1)[1] for v in commands.values()) == shims
    for name, target in commands.items():
        module, func = target.split(":")
        assert name == "soaring-" + module.rsplit(".", 1)[1].replace("_", "-")
        assert callable(getattr(importlib.import_module(module), func))
    for stem in shims:
        assert f"from baselines.cli.{stem} import main" in (root / "scripts" / f"{stem}.py").read_text()
