"""The README stays short and docs/ stays reachable (issue 62): the README has at most 150
lines, docs/index.md links every page of docs/, every relative link of the README and of
the index resolves, the README's first bash block still holds the two set-up commands that
.ci/run reads, and every block of figures that validation/readme_figures.py writes has its
markers in the file the script writes it to."""

import importlib.util
import re
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
README = ROOT / "README.md"
DOCS = ROOT / "docs"
INDEX = DOCS / "index.md"
MAX_README_LINES = 150
#: [text](target): the target up to the closing parenthesis, without a title
LINK = re.compile(r"\[[^\]]*\]\(([^)\s]+)\)")


def relative_links(path: Path) -> list[str]:
    """The link targets of a Markdown file that point into the repository (no scheme, no
    bare anchor), without their #fragment."""
    out = []
    for target in LINK.findall(path.read_text(encoding="utf-8")):
        if re.match(r"[a-z][a-z0-9+.-]*:", target, re.I) or target.startswith("#"):
            continue
        out.append(target.split("#", 1)[0])
    return out


def readme_command(n: int) -> str:
    """The line after the line that starts with "# N." in the README, as .ci/run's awk reads it
    (the first such line in the file)."""
    lines = README.read_text(encoding="utf-8").splitlines()
    for i, line in enumerate(lines):
        if line.startswith(f"# {n}."):
            return lines[i + 1] if i + 1 < len(lines) else ""
    return ""


def test_readme_is_short():
    n = len(README.read_text(encoding="utf-8").splitlines())
    assert n <= MAX_README_LINES, f"README.md has {n} lines, at most {MAX_README_LINES}"


def test_index_links_every_page():
    linked = {(INDEX.parent / t).resolve() for t in relative_links(INDEX)}
    pages = {p.resolve() for p in DOCS.rglob("*.md") if p != INDEX}
    missing = sorted(str(p.relative_to(ROOT)) for p in pages - linked)
    assert not missing, f"docs/index.md does not link {missing}"


@pytest.mark.parametrize("doc", [README, INDEX], ids=lambda p: str(p.relative_to(ROOT)))
def test_relative_links_resolve(doc):
    targets = relative_links(doc)
    assert targets, f"{doc.name} links nothing"
    broken = [t for t in targets if not (doc.parent / t).exists()]
    assert not broken, f"{doc.relative_to(ROOT)} links missing files: {broken}"


def test_readme_links_docs_index():
    assert "docs/index.md" in relative_links(README)


def test_first_bash_block_holds_the_set_up_commands():
    text = README.read_text(encoding="utf-8")
    block = re.search(r"^```bash\n(.*?)^```$", text, re.S | re.M)
    assert block, "README.md has no bash block"
    lines = block.group(1).splitlines()
    for n in (1, 2):
        tags = [i for i, line in enumerate(lines) if line.startswith(f"# {n}.")]
        assert tags, f"the first bash block has no '# {n}.' line"
        command = lines[tags[0] + 1] if tags[0] + 1 < len(lines) else ""
        assert command and not command.startswith("#"), f"no command under '# {n}.'"
        # .ci/run takes the first '# N.' line of the whole file: it must be this one
        assert readme_command(n) == command
    assert readme_command(1).endswith("pip install . && itr reproduce")
    assert readme_command(2).endswith("&& python -m pytest -q")


def test_first_python_block_is_a_snippet():
    """.ci/run runs the README's first python block from outside the checkout."""
    text = README.read_text(encoding="utf-8")
    block = re.search(r"^```python\n(.*?)^```$", text, re.S | re.M)
    assert block, "README.md has no python block"
    compile(block.group(1), "README snippet", "exec")


def test_figure_blocks_are_where_the_script_writes_them():
    spec = importlib.util.spec_from_file_location(
        "readme_figures", ROOT / "validation" / "readme_figures.py")
    figures = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(figures)
    assert figures.BLOCKS[0][0] == README, "the README keeps the main job's figures"
    for path, begin, end, _ in figures.BLOCKS:
        text = path.read_text(encoding="utf-8")
        assert text.count(begin) == 1 and text.count(end) == 1, (path, begin)
        assert text.index(begin) < text.index(end)
        inside = text.split(begin, 1)[1].split(end, 1)[0]
        assert "Written by `validation/readme_figures.py`" in " ".join(inside.split())
