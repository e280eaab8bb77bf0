"""The stubs, the fake delegate and the compiled module agree on one protocol."""

from __future__ import annotations

import ast
import inspect
from pathlib import Path

import pytest

import mipray

from fake_delegate import FakeRenderDelegate, fake_module

STUB = Path(mipray.__file__).with_name("_mipray.pyi")


def stub_signatures(source: Path = STUB) -> dict[str, list[tuple[str, str, bool]]]:
    """``name`` or ``Class.method`` → [(parameter, kind, has default)] from the .pyi."""
    tree = ast.parse(source.read_text())
    result: dict[str, list[tuple[str, str, bool]]] = {}

    def params(fn: ast.FunctionDef) -> list[tuple[str, str, bool]]:
        a = fn.args
        positional = a.posonlyargs + a.args
        defaults = [False] * (len(positional) - len(a.defaults)) + [True] * len(a.defaults)
        out = [(p.arg, "positional", d) for p, d in zip(positional, defaults, strict=True)]
        out += [
            (p.arg, "keyword", d is not None)
            for p, d in zip(a.kwonlyargs, a.kw_defaults, strict=True)
        ]
        return [p for p in out if p[0] != "self"]

    for node in tree.body:
        if isinstance(node, ast.FunctionDef):
            result[node.name] = params(node)
        elif isinstance(node, ast.ClassDef):
            for item in node.body:
                if isinstance(item, ast.FunctionDef) and item.name != "__init__":
                    result[f"{node.name}.{item.name}"] = params(item)
    return result


def runtime_params(obj: object) -> list[tuple[str, str, bool]]:
    sig = inspect.signature(obj)  # type: ignore[arg-type]
    kinds = {
        inspect.Parameter.POSITIONAL_ONLY: "positional",
        inspect.Parameter.POSITIONAL_OR_KEYWORD: "positional",
        inspect.Parameter.KEYWORD_ONLY: "keyword",
    }
    return [
        (p.name, kinds[p.kind], p.default is not inspect.Parameter.empty)
        for p in sig.parameters.values()
        if p.name != "self" and p.kind in kinds
    ]


def resolve(module: object, name: str) -> object:
    obj = module
    for part in name.split("."):
        obj = getattr(obj, part)
    return obj


def test_stub_declares_the_protocol() -> None:
    sigs = stub_signatures()
    assert set(sigs) == {
        "RenderDelegate.set_mesh",
        "RenderDelegate.set_transform",
        "RenderDelegate.set_motion",
        "RenderDelegate.set_deformation",
        "RenderDelegate.set_instancer",
        "RenderDelegate.set_instancer_motion",
        "RenderDelegate.set_camera",
        "RenderDelegate.set_distant_light",
        "RenderDelegate.set_light",
        "RenderDelegate.remove",
        "RenderDelegate.prim_paths",
        "RenderDelegate.mesh_sync_count",
        "RenderDelegate.instancer_update_count",
        "RenderDelegate.render",
        "write_image",
        "output_plan",
        "eight_bit_aovs",
        "srgb_encode",
        "read_image",
        "read_metadata",
        "version",
        "render_settings",
        "settings",
        "parse_setting",
        "aov_names",
        "aovs",
        "subdiv_compare",
        "check_trim_curves",
    }
    assert [p[0] for p in sigs["RenderDelegate.render"]] == [
        "camera",
        "width",
        "height",
        "aovs",
        "settings",
        "progress",
        "on_update",
        "pass_output",
    ]
    assert ("on_update", "keyword", True) in sigs["RenderDelegate.render"]
    assert ("pass_output", "keyword", True) in sigs["RenderDelegate.render"]


def test_fake_delegate_matches_the_stub() -> None:
    module = fake_module()
    module.RenderDelegate = FakeRenderDelegate  # type: ignore[attr-defined]
    for name, expected in stub_signatures().items():
        if name in (
            "subdiv_compare",
            "render_settings",
            "settings",
            "parse_setting",
            "aov_names",
            "aovs",
            "RenderDelegate.mesh_sync_count",
            "RenderDelegate.instancer_update_count",
        ):
            # A tool (mipray-subdiv-compare), the renderer's own tables and the compiled
            # delegate's sync counters (what tests of incremental sync read), not part of the
            # scene delegate's protocol.
            continue
        assert runtime_params(resolve(module, name)) == expected, name


def compatibility_problems(stub: list, runtime: list) -> list[str]:
    """Why a call written against ``stub`` could fail on ``runtime`` (empty if it cannot).

    The compiled module may take more than the stub says (extra parameters with
    defaults, defaults where the stub has none), never less.
    """
    problems = []
    by_name = {p[0]: p for p in runtime}
    stub_positional = [p[0] for p in stub if p[1] == "positional"]
    runtime_positional = [p[0] for p in runtime if p[1] == "positional"]
    if runtime_positional[: len(stub_positional)] != stub_positional:
        problems.append(f"positional parameters {runtime_positional} != {stub_positional}")
    for name, kind, has_default in stub:
        if name not in by_name:
            problems.append(f"no parameter {name!r}")
        elif by_name[name][1] != kind and not (
            kind == "keyword" and by_name[name][1] == "positional"
        ):
            problems.append(f"{name!r} is {by_name[name][1]}, stub says {kind}")
        elif has_default and not by_name[name][2]:
            problems.append(f"{name!r} has no default")
    stub_names = {p[0] for p in stub}
    problems += [
        f"extra parameter {n!r} has no default"
        for n, _, d in runtime
        if n not in stub_names and not d
    ]
    return problems


def test_compatibility_check_catches_drift() -> None:
    stub = [
        ("path", "positional", False),
        ("points", "keyword", False),
        ("scheme", "keyword", True),
    ]
    assert compatibility_problems(stub, stub) == []
    assert compatibility_problems(stub, [*stub, ("extra", "keyword", True)]) == []
    assert compatibility_problems(stub, stub[:2]) == ["no parameter 'scheme'"]
    assert compatibility_problems(stub, [*stub[:2], ("scheme", "keyword", False)]) == [
        "'scheme' has no default"
    ]
    assert compatibility_problems(stub, [*stub, ("must", "keyword", False)]) == [
        "extra parameter 'must' has no default"
    ]


def test_compiled_module_accepts_the_stub_protocol(native) -> None:
    mismatches = []
    for name, expected in stub_signatures().items():
        try:
            actual = runtime_params(resolve(native, name))
        except (ValueError, TypeError):
            pytest.skip(f"{name} has no introspectable signature")
        mismatches += [f"{name}: {p}" for p in compatibility_problems(expected, actual)]
    assert not mismatches, "\n".join(mismatches)
    assert isinstance(native.version(), str) and native.version()


def test_the_scene_delegates_protocol_is_the_stubs() -> None:
    # usd/protocol.py types the scene delegate without the compiled module; it had drifted
    # (21 of set_mesh's 30 keyword arguments).
    protocol = stub_signatures(Path(mipray.__file__).parent / "usd" / "protocol.py")
    stub = stub_signatures()
    methods = {
        k.split(".", 1)[1]: v for k, v in protocol.items() if k.startswith("RenderDelegateLike.")
    }
    assert methods, "no RenderDelegateLike methods found"
    for name, params in methods.items():
        assert params == stub[f"RenderDelegate.{name}"], name
