"""The type stubs (python/trisplat.pyi) name exactly what the module has."""

import ast
import pathlib

import trisplat

STUBS = pathlib.Path(__file__).resolve().parents[1] / "trisplat.pyi"


def stub_tree():
    return ast.parse(STUBS.read_text())


def public(names):
    return {n for n in names if not n.startswith("_")}


def test_every_public_name_has_a_stub():
    tree = stub_tree()
    stubbed = {node.name for node in tree.body if isinstance(node, (ast.FunctionDef, ast.ClassDef))}
    runtime = public(dir(trisplat)) - {"trisplat"}  # maturin's extension submodule
    assert stubbed == runtime


def test_every_class_member_has_a_stub():
    for node in stub_tree().body:
        if isinstance(node, ast.ClassDef) and node.name != "TrisplatError":
            stubbed = public(n.name for n in node.body if isinstance(n, ast.FunctionDef))
            runtime = public(dir(getattr(trisplat, node.name)))
            assert stubbed == runtime, node.name


def test_docstrings():
    for name in public(dir(trisplat)) - {"trisplat"}:
        obj = getattr(trisplat, name)
        if callable(obj):
            assert obj.__doc__, name
