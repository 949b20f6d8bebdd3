"""setup.py installs every sub-package of src/view_selection (a missing one imports in the devel
space, which points at the source tree, and fails only in an install space)."""
import ast
import os

ROOT = os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "..")


def test_setup_lists_every_package():
    tree = ast.parse(open(os.path.join(ROOT, "setup.py")).read())
    listed = next(ast.literal_eval(k.value) for node in ast.walk(tree) if isinstance(node, ast.Call)
                  for k in node.keywords if k.arg == "packages")
    found = []
    for folder, _, files in os.walk(os.path.join(ROOT, "src", "view_selection")):
        if "__init__.py" in files and "__pycache__" not in folder:
            found.append(os.path.relpath(folder, os.path.join(ROOT, "src")).replace(os.sep, "."))
    assert sorted(listed) == sorted(found)
