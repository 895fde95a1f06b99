"""The command line stays thin: it maps flags to library calls, every rule lives in the
library, so no command module grows past 250 lines and none reaches into the library's
private names (its methods with a leading underscore included)."""

from __future__ import annotations

import ast
from pathlib import Path

CLI = Path(__file__).resolve().parents[2] / "o3d_rpointhop" / "cli"


def test_no_command_module_is_over_250_lines():
    sizes = {p.name: len(p.read_text().splitlines()) for p in CLI.glob("*.py")}
    assert {name: n for name, n in sizes.items() if n > 250} == {}


def test_the_command_line_uses_no_private_library_name():
    found = []
    for path in CLI.glob("*.py"):
        tree = ast.parse(path.read_text())
        for node in ast.walk(tree):
            if isinstance(node, ast.ImportFrom) and node.level >= 2:  # the library's
                private = [
                    a.name for a in node.names if a.name.startswith("_") and a.name[1] != "_"
                ]
                if private:
                    found.append((path.name, node.module, private))
            if (
                isinstance(node, ast.Attribute)
                and node.attr.startswith("_")
                and not node.attr.startswith("__")
                and not (isinstance(node.value, ast.Name) and node.value.id in ("self", "args"))
            ):
                found.append((path.name, node.lineno, node.attr))
    assert found == []
