"""The type stubs describe the module as built: every public class,
function and member the extension has is in `_native.pyi`, and nothing
else."""

import ast
import pathlib

import skinpatch
from skinpatch import _native

STUB = pathlib.Path(__file__).resolve().parents[1] / "skinpatch" / "_native.pyi"


def stub_names():
    tree = ast.parse(STUB.read_text())
    top, members = set(), {}
    for node in tree.body:
        if isinstance(node, ast.ClassDef):
            top.add(node.name)
            members[node.name] = {
                item.name
                for item in node.body
                if isinstance(item, ast.FunctionDef) and not item.name.startswith("_")
            } | {
                item.target.id
                for item in node.body
                if isinstance(item, ast.AnnAssign) and isinstance(item.target, ast.Name)
            }
        elif isinstance(node, ast.FunctionDef):
            top.add(node.name)
        elif isinstance(node, ast.AnnAssign) and isinstance(node.target, ast.Name):
            top.add(node.target.id)
    return top, members


def test_the_stubs_list_what_the_module_has():
    top, members = stub_names()
    public = {n for n in dir(_native) if not n.startswith("_")} | {"__version__"}
    assert top == public
    assert set(skinpatch.__all__) == public
    for name in ["Mesh", "Scenario", "Frame", "Run"]:
        cls = getattr(_native, name)
        runtime = {n for n in dir(cls) if not n.startswith("_")}
        assert members[name] == runtime, name
    assert members["ScenarioError"] == {"file", "line", "key"}


def test_every_public_member_has_a_docstring():
    for name in ["Mesh", "Scenario", "Frame", "Run"]:
        cls = getattr(_native, name)
        assert cls.__doc__, name
        for member in dir(cls):
            if member.startswith("_"):
                continue
            assert getattr(cls, member).__doc__, f"{name}.{member}"
