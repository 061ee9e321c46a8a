"""The package's layering (docs/rig.md, ../shared/design/README.md), checked on the source.

- inference (rig, representation, model, diffusion, generate, postprocess, constraints) never imports
  training code (kinema.train, kinema.data);
- the lower layers never import the layers above them;
- no function-level imports of kinema modules in the layers this refactor owns (they used to hide
  import circles: motion/core <-> io, constraints/types <-> constraints/io).
"""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

import kinema

KINEMA = Path(kinema.__file__).parent
INFERENCE = ("rig", "representation", "model", "diffusion", "generate", "postprocess", "constraints")
#: package -> packages it must not import
FORBIDDEN = {
    "motion": ("kinema.io", "kinema.rig", "kinema.representation", "kinema.model", "kinema.generate"),
    "rig": ("kinema.io", "kinema.motion", "kinema.representation", "kinema.model", "kinema.generate",
            "kinema.postprocess"),
    "representation": ("kinema.model", "kinema.generate", "kinema.postprocess", "kinema.diffusion"),
    **{pkg: ("kinema.train", "kinema.data") for pkg in INFERENCE if pkg not in ("rig", "representation")},
}
NO_LOCAL_IMPORTS = ("motion", "rig", "representation", "constraints", "postprocess", "io")


def _imports(path: Path) -> list[tuple[str, bool]]:
    """(module, inside a function) for every ``import`` / ``from ... import`` of a kinema module."""
    tree = ast.parse(path.read_text())
    local = set()
    for fn in ast.walk(tree):
        if isinstance(fn, (ast.FunctionDef, ast.AsyncFunctionDef)):
            local.update(id(n) for n in ast.walk(fn) if isinstance(n, (ast.Import, ast.ImportFrom)))
    out = []
    for node in ast.walk(tree):
        if isinstance(node, ast.ImportFrom) and node.module and node.module.startswith("kinema"):
            out.append((node.module, id(node) in local))
        elif isinstance(node, ast.Import):
            out += [(a.name, id(node) in local) for a in node.names if a.name.startswith("kinema")]
    return out


def _files(pkg: str) -> list[Path]:
    return sorted((KINEMA / pkg).glob("*.py"))


@pytest.mark.parametrize("pkg", sorted(FORBIDDEN))
def test_layers_import_downwards_only(pkg) -> None:
    for path in _files(pkg):
        for module, _ in _imports(path):
            bad = [f for f in FORBIDDEN[pkg] + ("kinema.train",) if module == f or module.startswith(f + ".")]
            assert not bad, f"kinema/{pkg}/{path.name} imports {module}"


@pytest.mark.parametrize("pkg", NO_LOCAL_IMPORTS)
def test_no_function_level_imports(pkg) -> None:
    for path in _files(pkg):
        local = [m for m, inside in _imports(path) if inside]
        assert not local, f"kinema/{pkg}/{path.name} imports {local} inside a function"


#: faces (parse input, call a pipeline, write files) and the packages none of the layers below them may import
FACES = ("kinema.cli", "kinema.server", "kinema.batch", "kinema.app")
#: package -> packages it must not import, for the one-pipeline shape (docs/architecture.md)
PIPELINE_RULES = {
    "pipeline": ("kinema.generate", "kinema.human", "kinema.anyrig", *FACES),
    "human": ("kinema.anyrig", "kinema.generate", *FACES),
    "anyrig": ("kinema.human", "kinema.generate", *FACES),
    "generate": FACES,
    "stream": ("kinema.pipeline", "kinema.human", "kinema.anyrig", "kinema.generate", *FACES),
    "objectives": ("kinema.human", "kinema.anyrig", "kinema.generate", *FACES),
    "batch": ("kinema.server", "kinema.cli", "kinema.app"),
    "server": ("kinema.batch", "kinema.cli", "kinema.app"),
    **{pkg: ("kinema.human", "kinema.anyrig", "kinema.generate", "kinema.pipeline", *FACES)
       for pkg in ("constraints", "diffusion", "postprocess", "model", "representation", "rig", "motion", "io",
                   "retarget", "robot")},
    # the vocabulary sits below the representation that encodes it, the engine below the vocabulary
    **{pkg: ("kinema.representation", "kinema.model", "kinema.human", "kinema.anyrig", "kinema.generate",
             "kinema.pipeline", *FACES) for pkg in ("constraints", "objectives")},
    **{pkg: ("kinema.constraints", "kinema.objectives", "kinema.representation", "kinema.model", "kinema.human",
             "kinema.anyrig", "kinema.generate", "kinema.pipeline", *FACES) for pkg in ("diffusion", "postprocess")},
    # faces never import one another; only the command line starts them (kinema serve, batch, app, ...)
    **{pkg: tuple(f for f in (*FACES, "kinema.bench", "kinema.evaluate") if f != f"kinema.{pkg}")
       for pkg in ("app", "bench", "evaluate")},
}


def _package_graph() -> dict[str, set[str]]:
    """Top-level package -> the kinema packages its modules import (module-level and in functions)."""
    graph: dict[str, set[str]] = {}
    for path in KINEMA.rglob("*.py"):
        rel = path.relative_to(KINEMA).parts
        src = rel[0].removesuffix(".py")
        for module, _ in _imports(path):
            parts = module.split(".")
            if len(parts) > 1 and parts[1] != src:
                graph.setdefault(src, set()).add(parts[1])
    return graph


@pytest.mark.parametrize("pkg", sorted(PIPELINE_RULES))
def test_pipelines_and_faces_import_in_one_direction(pkg) -> None:
    for path in (KINEMA / pkg).rglob("*.py"):
        for module, _ in _imports(path):
            bad = [f for f in PIPELINE_RULES[pkg] if module == f or module.startswith(f + ".")]
            assert not bad, f"{path.relative_to(KINEMA)} imports {module}"


def test_no_import_cycle_between_packages() -> None:
    graph = _package_graph()

    def reaches(a: str, b: str, seen: set[str]) -> bool:
        return a == b or any(n not in seen and (seen.add(n) or reaches(n, b, seen)) for n in graph.get(a, ()))

    cycles = sorted({tuple(sorted((a, b))) for a in graph for b in graph[a] if reaches(b, a, set())})
    assert not cycles, f"packages importing each other (directly or through others): {cycles}"


def test_no_module_is_named_anyrig_prefix() -> None:
    assert not [p for p in KINEMA.rglob("anyrig_*.py")], "cut packages by concept (kinema/anyrig/...), not by prefix"


@pytest.mark.parametrize("module", ["render.py", "render_bones.py"])
def test_drawing_reads_no_file_format(module) -> None:
    """Drawing works on motions, not files: a face reads the file and hands the motion over."""
    assert not [m for m, _ in _imports(KINEMA / module) if m == "kinema.io" or m.startswith("kinema.io.")]


#: packages where feature tensors flow: their channels are named by kinema.representation (issue 32)
FEATURE_USERS = ("human", "anyrig", "model", "pipeline", "generate", "stream", "objectives", "constraints",
                 "diffusion", "postprocess", "train", "evaluate")


def _channel_slices(path: Path) -> list[str]:
    """``x[..., a:b]`` subscripts whose bounds are written with integer literals (``:3``, ``3:9``,
    ``: 3 * NUM_KEYJOINTS``): index arithmetic on the last (channel) axis."""
    def literal(node) -> bool:
        return node is not None and any(isinstance(n, ast.Constant) and type(n.value) is int for n in ast.walk(node))

    out = []
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.Subscript) and isinstance(node.slice, ast.Tuple):
            *head, last = node.slice.elts
            ellipsis = any(isinstance(e, ast.Constant) and e.value is Ellipsis for e in head)
            if ellipsis and isinstance(last, ast.Slice) and (literal(last.lower) or literal(last.upper)):
                out.append(f"{path.relative_to(KINEMA)}:{node.lineno} {ast.unparse(node)}")
    return out


def test_no_feature_channel_slices_outside_representation() -> None:
    found = [s for pkg in FEATURE_USERS for path in sorted((KINEMA / pkg).rglob("*.py")) for s in _channel_slices(path)]
    assert not found, f"name the channels in kinema.representation instead: {found}"
