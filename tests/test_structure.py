"""How service/ holds together: its import graph has no cycle, the front ends (CLI, HTTP, batch)
reach the maths only through the service's shared paths, a pipeline is validated once and
travels to worker processes as it is, and the typed enhance path writes what the CLI writes."""

from __future__ import annotations

import ast
import pickle
import re
from pathlib import Path

import pytest

from gbuffer.camera import Camera
from service import pipeline
from service.cli import main as cli
from service.enhance import ReadRequest, WriteRequest, enhance
from service.errors import PipelineError

ROOT = Path(__file__).resolve().parent.parent
SERVICE = ROOT / "service"
CORPUS = ROOT / "tests" / "fixtures" / "corpus"
#: A command's module named by the CLI's parser (imported when the command runs).
COMMAND = re.compile(r'"(service(?:\.\w+)+):\w+"')
#: The front ends: what they run goes through service/ modules, never straight to ops/.
FRONT_ENDS = ("service.cli", "service.http", "service.batch")


def module_name(path: Path) -> str:
    parts = path.relative_to(ROOT).with_suffix("").parts
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


def imports(path: Path, modules: set[str]) -> set[str]:
    """The modules ``path`` imports (at module level, in functions, or as a command's
    ``"module:function"``), as module names; ``from package import module`` is the module."""
    text = path.read_text()
    found: set[str] = set(COMMAND.findall(text))
    for node in ast.walk(ast.parse(text)):
        if isinstance(node, ast.Import):
            found.update(alias.name for alias in node.names)
        elif isinstance(node, ast.ImportFrom) and node.module and not node.level:
            subs = {f"{node.module}.{a.name}" for a in node.names} & modules
            found.update(subs if len(subs) == len(node.names) else {node.module, *subs})
    return found


def graph() -> dict[str, set[str]]:
    paths = {module_name(p): p for p in SERVICE.rglob("*.py")}
    names = set(paths)
    return {name: imports(path, names) for name, path in paths.items()}


def test_service_has_no_import_cycle() -> None:
    edges = {m: {t for t in targets if t.startswith("service")} for m, targets in graph().items()}
    state: dict[str, int] = {}  # 1: on the current path, 2: done

    def visit(module: str, path: list[str]) -> None:
        state[module] = 1
        for target in sorted(edges.get(module, ())):
            if state.get(target) == 1:
                cycle = [*path[path.index(target) :], target] if target in path else [target]
                pytest.fail(f"import cycle: {' -> '.join(cycle)}")
            if target not in state:
                visit(target, [*path, target])
        state[module] = 2

    for module in sorted(edges):
        if module not in state:
            visit(module, [module])


def test_the_front_ends_do_not_import_ops() -> None:
    offenders = {
        module: sorted(t for t in targets if t == "ops" or t.startswith("ops."))
        for module, targets in graph().items()
        if module.startswith(FRONT_ENDS)
    }
    bad = {m: t for m, t in offenders.items() if t}
    assert not bad, bad


def test_a_compiled_pipeline_is_validated_once_and_pickles_as_it_is() -> None:
    compiled = pipeline.compile([{"op": "radiance_scaling", "params": {"gamma": 2}}])
    step = compiled.steps[0]
    assert (step.op.name, step.params.gamma) == ("radiance_scaling", 2)
    assert pipeline.compile(compiled) is compiled  # compiling again is free
    back = pickle.loads(pickle.dumps(compiled))
    assert back.spec == compiled.spec and back.steps[0].op is step.op  # the registry's operator
    assert back.steps[0].params == step.params
    with pytest.raises(PipelineError, match="gamma"):
        pipeline.compile([{"op": "radiance_scaling", "params": {"gamma": -1}}])


def test_enhance_times_each_step_and_writes_what_the_cli_writes(tmp_path: Path) -> None:
    frame = CORPUS / "rock_240p_16spp.exr"
    camera = CORPUS / "rock_240p_16spp.camera.json"
    steps = [{"op": "curvature"}, {"op": "radiance_scaling"}]
    read = ReadRequest(camera=Camera.from_json_file(camera))
    mine = tmp_path / "typed.exr"
    result = enhance(frame, mine, pipeline.compile(steps), read, WriteRequest())
    assert [op for op, _ in result["op_s"]] == ["curvature", "radiance_scaling"]
    assert all(seconds >= 0 for _, seconds in result["op_s"])
    theirs = tmp_path / "cli.exr"
    args = ["enhance", str(frame), "--camera", str(camera), "-o", str(theirs)]
    assert cli([*args, "--op", "curvature", "--op", "radiance_scaling"]) == 0
    assert mine.read_bytes() == theirs.read_bytes()
