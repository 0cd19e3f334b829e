"""The documentation's examples run, and its links lead somewhere.

Every ```python block of README.md and docs/ runs; every line of a ```sh block runs (a
`pathgrad …` command with the program under test, a `python3 …` one with this interpreter), from a
scratch folder in which `scenes/`, `tests/` and `examples/` are the repository's; set-up commands
belong in ```text blocks, which only show (`scripts/setup`, `scripts/test` and `pip install
./python` may stand in a sh block: scripts/test has run them; `cargo run --release -- ARGS` runs
as `pathgrad ARGS`). The ```rust blocks of docs/library.md run as doctests
(`src/lib.rs`, `LibraryDocs`). Every relative link of the pages names a file that exists, and an
anchor names one of its headings."""

import os
import pathlib
import re
import shlex
import subprocess
import sys

import pytest

REPO = pathlib.Path(__file__).resolve().parents[2]
PAGES = sorted(
    [REPO / "README.md", REPO / "python" / "README.md", *(REPO / "docs").glob("*.md")]
    + [p for p in [REPO / "capi" / "README.md"] if p.exists()]
)
FENCE = re.compile(r"^```([^\n]*)\n(.*?)^```$", re.M | re.S)


def blocks(language):
    for page in PAGES:
        text = page.read_text()
        for m in FENCE.finditer(text):
            if m.group(1).split(",")[0].strip() == language:
                line = text.count("\n", 0, m.start()) + 1
                yield pytest.param(page, m.group(2), id=f"{page.relative_to(REPO)}:{line}")


@pytest.fixture
def scratch(tmp_path, monkeypatch):
    for name in ("scenes", "tests", "examples"):
        (tmp_path / name).symlink_to(REPO / name)
    monkeypatch.chdir(tmp_path)
    return tmp_path


@pytest.mark.parametrize("page, code", list(blocks("python")))
def test_python_examples_run(page, code, scratch):
    exec(compile(code, str(page), "exec"), {"__name__": "__docs__"})


# What scripts/test itself has run before this test (CI runs scripts/setup, then scripts/test).
ALREADY_RUN = [["scripts/setup"], ["scripts/test"], ["pip", "install", "./python"]]


def commands(code):
    """The commands of a shell block: continuation lines joined, comments dropped, `a && b`
    split, `cargo run --release -- ARGS` as `pathgrad ARGS`, and the set-up commands that
    scripts/test has already run left out."""
    for line in code.replace("\\\n", " ").splitlines():
        words = shlex.split(line, comments=True)
        while words:
            command, words = (words[: words.index("&&")], words[words.index("&&") + 1 :]) if "&&" in words else (words, [])
            if command[:4] == ["cargo", "run", "--release", "--"]:
                command = ["pathgrad", *command[4:]]
            if command not in ALREADY_RUN:
                yield command


@pytest.mark.parametrize("page, code", list(blocks("sh")))
def test_shell_examples_run(page, code, scratch):
    program = os.environ.get("PATHGRAD_BIN", str(REPO / "target" / "debug" / "pathgrad"))
    for words in commands(code):
        if words[0] == "pathgrad":
            argv = [program, *words[1:]]
        elif words[0] == "python3":
            argv = [sys.executable, *words[1:]]
        else:
            pytest.fail(f"{page.name}: `{' '.join(words)}` in a sh block: only pathgrad and python3 commands run; show set-up in a text block")
        done = subprocess.run(argv, capture_output=True, text=True)
        assert done.returncode == 0, f"{page.name}: `{' '.join(words)}` failed:\n{done.stderr[-3000:]}"


def slug(heading):
    """GitHub's anchor of a heading: lower case, punctuation dropped, spaces as hyphens."""
    text = re.sub(r"[`*_]", "", heading.strip().lower())
    text = re.sub(r"[^\w\- ]", "", text)
    return text.replace(" ", "-")


def anchors(page):
    text = FENCE.sub("", page.read_text())
    return {slug(m.group(1)) for m in re.finditer(r"^#+ (.*)$", text, re.M)}


def broken_links(pages, root):
    """The relative links of `pages` that name no file, or an anchor no heading of theirs has."""
    link = re.compile(r"\]\(([^)\s]+)\)")
    broken = []
    for page in pages:
        text = FENCE.sub("", page.read_text())
        for target in link.findall(text):
            if re.match(r"[a-z]+:", target):
                continue  # http:, https:, mailto:
            path, _, anchor = target.partition("#")
            file = (page.parent / path).resolve() if path else page
            if not file.exists():
                broken.append(f"{page.relative_to(root)}: {target} (no such file)")
            elif anchor and file.suffix == ".md" and anchor not in anchors(file):
                broken.append(f"{page.relative_to(root)}: {target} (no heading #{anchor})")
    return broken


def test_no_link_is_broken():
    broken = broken_links(PAGES, REPO)
    assert not broken, "broken links:\n" + "\n".join(broken)
    assert len(PAGES) >= 12


def test_the_link_check_sees_broken_links(tmp_path):
    assert slug("As a dependency") == "as-a-dependency"
    assert slug("Scenes: Mitsuba XML, glTF and the built-ins") == "scenes-mitsuba-xml-gltf-and-the-built-ins"
    (tmp_path / "other.md").write_text("# Other page\n")
    page = tmp_path / "p.md"
    page.write_text(
        "# Title\n\n[a](missing.md) [b](#title) [c](#nope) [d](other.md#other-page) [e](other.md#gone)\n"
        "[f](https://example.com/x)\n```text\n[g](in-a-fence.md)\n```\n"
    )
    assert broken_links([page], tmp_path) == [
        "p.md: missing.md (no such file)",
        "p.md: #nope (no heading #nope)",
        "p.md: other.md#gone (no heading #gone)",
    ]
