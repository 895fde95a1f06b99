"""The README's code and the examples run as written."""

from __future__ import annotations

import contextlib
import io
import os
import re
import runpy
import subprocess
import sys
from pathlib import Path

import pytest

pytestmark = pytest.mark.slow

ROOT = Path(__file__).resolve().parents[1]


DATA_MARK = "<!-- test: needs shared data -->"
DOCUMENTS = [ROOT / "README.md", *sorted((ROOT / "docs").glob("*.md"))]


def _python_blocks(markdown: Path) -> list[tuple[bool, str]]:
    """Every python block of ``markdown``, and whether it is marked as needing the data."""
    found = re.findall(r"(<!-- test: [^>]*-->\n)?```python\n(.*?)```", markdown.read_text(), re.S)
    return [(DATA_MARK in mark, block) for mark, block in found]


def _has_python(path: Path) -> bool:
    return bool(_python_blocks(path))


@pytest.mark.filterwarnings("ignore::o3d_rpointhop.RegistrationWarning")
@pytest.mark.parametrize("document", [d for d in DOCUMENTS if _has_python(d)], ids=lambda p: p.name)
def test_documented_python_runs(document, tmp_path, monkeypatch, request):
    """Every python block of the README and the docs runs as written, in order, in one
    namespace per document (blocks marked as needing the shared data run when it is
    there)."""
    monkeypatch.chdir(tmp_path)
    # Dask's LocalCluster leaves OMP_NUM_THREADS=1 in this process's environment (its
    # nannies' pre-spawn-environ), which would put every later test on one thread.
    environ = dict(os.environ)
    request.addfinalizer(lambda: (os.environ.clear(), os.environ.update(environ)))
    namespace: dict = {"__name__": "__docs__"}
    ran = 0
    for k, (needs_data, block) in enumerate(_python_blocks(document)):
        if needs_data:
            try:
                request.getfixturevalue("shared_data")
            except pytest.skip.Exception:
                continue
        where = f"{document.name}, python block {k + 1}"
        out = io.StringIO()
        with contextlib.redirect_stdout(out):
            exec(compile(block, where, "exec"), namespace)
        # "print(...)  # prints: text": the documented output is what the code prints.
        printed = out.getvalue().splitlines()
        for expected in re.findall(r"print\(.*\)\s+# prints: (.*)$", block, re.M):
            assert expected.strip() in [line.strip() for line in printed], (where, printed)
        ran += 1
    assert ran > 0


#: The guides whose examples are code (the others are prose, tables and command lines).
GUIDES_WITH_CODE = {
    "README.md",
    "consensus.md",
    "datasets.md",
    "descriptors.md",
    "low_overlap.md",
    "multiway.md",
    "performance.md",
    "registration.md",
}


def test_every_document_with_code_is_tested():
    """Every guide that shows library code keeps it in python blocks (which
    ``test_documented_python_runs`` runs), and no other document grew code that escapes
    the test: a ``python`` block is the only form of Python code in the docs."""
    with_code = {d.name for d in DOCUMENTS if _has_python(d)}
    assert with_code == GUIDES_WITH_CODE
    for document in DOCUMENTS:
        other = re.findall(r"```(?:py|python3|pycon)\n", document.read_text())
        assert not other, f"{document.name}: a code block the docs test would not run"
        runnable = [block for needs, block in _python_blocks(document) if not needs]
        if document.name in GUIDES_WITH_CODE:
            assert runnable, f"{document.name}: every python block needs the shared data"


#: What each example prints that says it worked: a pattern with one number, how many
#: times it must appear, and the bound each number must meet.
EXAMPLE_CLAIMS = {
    "describe_and_match.py": (r"register\(\): ([\d.]+) deg off", 2, lambda v: v < 5),
    "grid_search.py": (r"recall=([\d.]+)", 4, lambda v: 0 <= v <= 1),
    "register_pair.py": (r"rotation error\s+([\d.]+) deg", 3, lambda v: v < 5),
    "register_scene.py": (r"rotation error ([\d.]+) deg", 3, lambda v: v < 15),
    "sklearn_pipeline.py": (r"clusters agree after a rotation: ([\d.]+)%", 1, lambda v: v > 90),
}


@pytest.mark.parametrize("script", sorted((ROOT / "examples").glob("*.py")), ids=lambda p: p.name)
def test_examples_run(script, tmp_path, monkeypatch):
    """Every example runs and prints the results it claims: errors within bounds."""
    monkeypatch.chdir(tmp_path)
    out = io.StringIO()
    with contextlib.redirect_stdout(out):
        runpy.run_path(str(script), run_name="__main__")
    pattern, count, meets = EXAMPLE_CLAIMS[script.name]
    values = [float(v) for v in re.findall(pattern, out.getvalue())]
    assert len(values) == count, out.getvalue()
    assert all(meets(v) for v in values), out.getvalue()
    if script.name == "grid_search.py":
        assert max(values) > 0 and "best:" in out.getvalue()


def test_ci_runs_the_readme_test_command():
    readme = (ROOT / "README.md").read_text()
    ci = (ROOT / ".ci" / "run").read_text()
    commands = [line for line in readme.splitlines() if line.startswith("sh scripts/setup.sh")]
    assert len(commands) == 2, "the quick start has exactly two commands"
    assert "pytest" in commands[1] and "grep" in ci and "pytest" in ci
    # The main job sets up what the demo needs; only the tests' set-up adds Chromium.
    assert "--test" not in commands[0] and "--test" in commands[1]
    assert "scripts/check_wheel.sh" in ci and (ROOT / "scripts" / "check_wheel.sh").is_file()


def test_console_script_entry_point():
    """The installed ``o3d-rpointhop`` script (beside this Python) and ``python -m``."""
    script = Path(sys.executable).parent / "o3d-rpointhop"
    assert script.is_file(), "the console script is not installed beside this Python"
    for command in (
        [str(script), "--version"],
        [sys.executable, "-m", "o3d_rpointhop.cli", "--version"],
    ):
        out = subprocess.run(command, capture_output=True, text=True, check=True)
        assert out.stdout.startswith("o3d-rpointhop ")


def test_registration_docs_tables_match_the_code():
    """docs/registration.md's step signatures and settings table are the code's."""
    import dataclasses

    import o3d_rpointhop
    from o3d_rpointhop import RegistrationSettings

    text = (ROOT / "docs" / "registration.md").read_text()
    rows = re.findall(r"^\| `(\w+)\(([^`]*)\)` \|", text, re.M)
    assert {name for name, _ in rows} >= {
        "SVDGlobal",
        "RANSACGlobal",
        "FGRGlobal",
        "MultiScaleICP",
        "SymmetryCheck",
    }
    for name, args in rows:
        params = getattr(o3d_rpointhop, name)().get_params()
        for arg in filter(None, (a.strip() for a in re.split(r",\s*(?![^()]*\))", args))):
            key, _, default = arg.partition("=")
            assert key in params, (name, key)
            if default:
                assert repr(params[key]).replace("_", "") == default.replace("_", "") or (
                    eval(default) == params[key]  # noqa: S307 - literals from our own docs
                ), (name, key, default, params[key])
    settings = dict(re.findall(r"^\| `(\w+_factors?)` \| ([^|]+) \|", text, re.M))
    fields = {f.name: f.default for f in dataclasses.fields(RegistrationSettings)}
    fields.pop("voxel_size")
    assert set(settings) == set(fields)
    for key, default in settings.items():
        assert eval(default.strip()) == fields[key], key  # noqa: S307


def test_the_readme_is_a_five_minute_read():
    """What it is, the two commands, which model for which data, one short table: the
    details live in docs/ (docs/results.md holds the full results)."""
    readme = (ROOT / "README.md").read_text()
    assert len(readme) < 9000
    assert readme.count("```sh") == 2  # the quick start's two commands


def _anchor(heading: str) -> str:
    """GitHub's anchor of a Markdown heading."""
    return re.sub(r"[^\w\- ]", "", heading.strip().lower()).replace(" ", "-")


def test_links_between_documents_resolve():
    """Every relative link of the README and the docs names a document that exists and,
    with ``#anchor``, one of its headings (sections moved between guides keep their
    links)."""
    headings = {
        doc.name: {_anchor(h) for h in re.findall(r"^#+ (.*)$", doc.read_text(), re.M)}
        for doc in DOCUMENTS
    }
    broken = []
    for doc in DOCUMENTS:
        for path, anchor in re.findall(r"\]\(([\w./-]*?\.md)?(?:#([\w-]+))?\)", doc.read_text()):
            name = Path(path).name if path else doc.name
            if name not in headings or (anchor and anchor not in headings[name]):
                broken.append(f"{doc.name}: {path}#{anchor}")
    assert not broken, broken
