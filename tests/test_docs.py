"""The documentation: no dated measurement outside the lab book, no link to a file or heading
that is not there, and the teaching courses' lengths as the code builds them.

The how-to, reference and design pages state the current state; dated measurements and history
live in the lab book, ``docs/lab/`` (STYLE 15). A lab-book entry is named by its date, so a link
*target* may hold a date (``[lab book](lab/2026-11-28-stopping.md)``); the text a reader sees may
not.
"""

from __future__ import annotations

import re
from pathlib import Path
from typing import TYPE_CHECKING
from urllib.parse import unquote

import pytest

if TYPE_CHECKING:
    from terrapref.terrain.classes import ClassTable

ROOT = Path(__file__).resolve().parents[1]
DOCS = ROOT / "docs"
LAB = DOCS / "lab"

DATE = re.compile(r"20\d\d-\d\d-\d\d")
LINK = re.compile(r"!?\[(?P<text>[^\]]*)\]\((?P<target>[^)\s]+)(?:\s+\"[^\"]*\")?\)")
TARGET = re.compile(r"\]\([^)\s]*(?:\s+\"[^\"]*\")?\)")
FENCE = re.compile(r"^\s*(```|~~~)")
HEADING = re.compile(r"^(#{1,6})\s+(?P<title>.+?)\s*#*\s*$")


def _pages() -> list[Path]:
    """README.md and every page under docs/, the lab book included."""
    return [ROOT / "README.md", *sorted(DOCS.rglob("*.md"))]


def _user_pages() -> list[Path]:
    """The pages outside the lab book."""
    return [p for p in _pages() if LAB not in p.parents]


def _name(page: Path) -> str:
    return str(page.relative_to(ROOT))


def _prose(page: Path) -> str:
    """The page with its fenced code blocks blanked (line numbers kept)."""
    lines, fenced = [], False
    for line in page.read_text(encoding="utf-8").splitlines():
        if FENCE.match(line):
            fenced = not fenced
            lines.append("")
            continue
        lines.append("" if fenced else line)
    return "\n".join(lines)


def _links(page: Path) -> list[tuple[int, str]]:
    """(line number, target) of every relative link or image in the page's prose (a link's text
    may run over several lines)."""
    text = _prose(page)
    found = []
    for match in LINK.finditer(text):
        target = match["target"]
        if re.match(r"[A-Za-z][A-Za-z0-9+.-]*:", target):  # http:, https:, mailto:
            continue
        found.append((text.count("\n", 0, match.start("target")) + 1, target))
    return found


def _slug(title: str) -> str:
    """A heading's anchor as GitHub makes it: lower case, punctuation dropped, spaces to hyphens."""
    text = re.sub(r"\[([^\]]*)\]\([^)]*\)", r"\1", title)  # a link in a heading anchors by its text
    text = re.sub(r"[^\w\- ]", "", text.lower())
    return text.replace(" ", "-")


def _anchors(page: Path) -> set[str]:
    """Every heading anchor of a page (a repeated heading gets -1, -2, ... as on GitHub)."""
    seen: dict[str, int] = {}
    anchors = set()
    for line in _prose(page).splitlines():
        match = HEADING.match(line)
        if not match:
            continue
        slug = _slug(match["title"])
        count = seen.get(slug, 0)
        seen[slug] = count + 1
        anchors.add(slug if count == 0 else f"{slug}-{count}")
    return anchors


@pytest.mark.parametrize("page", _user_pages(), ids=_name)
def test_no_date_outside_the_lab_book(page: Path) -> None:
    """A date in a how-to, reference or design page (or the README) is a dated measurement that
    belongs in the lab book; link targets are left out, since lab-book entries are named by date."""
    text = page.read_text(encoding="utf-8")
    seen = TARGET.sub(lambda m: "]" + " " * (len(m.group(0)) - 1), text)  # targets blanked, offsets kept
    dated = [f"{_name(page)}:{seen.count(chr(10), 0, m.start()) + 1}: {m.group(0)}" for m in DATE.finditer(seen)]
    assert not dated, "dated text outside docs/lab/ (move it to the lab book):\n" + "\n".join(dated)


@pytest.mark.parametrize("page", _pages(), ids=_name)
def test_relative_links_point_at_files_that_exist(page: Path) -> None:
    broken = []
    for number, target in _links(page):
        path = unquote(target.split("#", 1)[0])
        if path and not (page.parent / path).exists():
            broken.append(f"{_name(page)}:{number}: {target}")
    assert not broken, "links to files that do not exist:\n" + "\n".join(broken)


@pytest.mark.parametrize("page", _pages(), ids=_name)
def test_links_to_headings_point_at_headings_that_exist(page: Path) -> None:
    broken = []
    for number, target in _links(page):
        path, _, anchor = target.partition("#")
        if not anchor:
            continue
        linked = page if not path else (page.parent / unquote(path)).resolve()
        if linked.suffix != ".md" or not linked.exists():
            continue  # a missing file is the test above's to report
        if anchor not in _anchors(linked):
            broken.append(f"{_name(page)}:{number}: {target}")
    assert not broken, "links to headings that do not exist:\n" + "\n".join(broken)


def test_the_index_lists_every_page() -> None:
    """docs/index.md names every page outside the lab book, so that none is left unfound."""
    index = DOCS / "index.md"
    listed = {(index.parent / unquote(t.split("#", 1)[0])).resolve() for _, t in _links(index) if t.split("#", 1)[0]}
    missing = [_name(p) for p in sorted(DOCS.glob("*.md")) if p != index and p.resolve() not in listed]
    assert not missing, "pages docs/index.md does not list: " + ", ".join(missing)


# docs/layout.md's tree of src/terrapref/: an entry is a line indented less than the description
# column, naming one or more packages (``name/``) or modules (``name.py``), comma-separated, and
# then, after a space, what they are; a line indented to the description column or beyond goes on
# describing the entry above it. Two spaces of indent per level: ``  rules/`` is a part of
# terrapref, ``    offset/`` a part of rules/.
PACKAGE = ROOT / "src" / "terrapref"
LAYOUT = DOCS / "layout.md"
DESCRIPTION_COLUMN = 14
ENTRY = re.compile(r"(?P<names>[A-Za-z_]\w*(?:/|\.py)(?:, [A-Za-z_]\w*(?:/|\.py))*)(?:\s|$)")


def _layout_tree() -> list[tuple[int, str, int]]:
    """(line number, path under src/terrapref/, depth) of every part docs/layout.md's tree names,
    from the fenced block that opens with ``src/terrapref/``."""
    lines = LAYOUT.read_text(encoding="utf-8").splitlines()
    start = next(i for i, line in enumerate(lines) if line.strip() == "src/terrapref/" and i and FENCE.match(lines[i - 1]))
    parents: list[str] = []
    found = []
    for number, line in enumerate(lines[start + 1 :], start + 2):
        if FENCE.match(line):
            break
        indent = len(line) - len(line.lstrip(" "))
        if not line.strip() or indent >= DESCRIPTION_COLUMN:
            continue
        assert indent % 2 == 0 and indent >= 2, f"docs/layout.md:{number}: an entry is indented by a multiple of two spaces"
        depth = indent // 2
        match = ENTRY.match(line, indent)
        assert match, f"docs/layout.md:{number}: expected names ending in / or .py: {line.strip()!r}"
        assert depth - 1 <= len(parents), f"docs/layout.md:{number}: indented below no package"
        del parents[depth - 1 :]
        names = match["names"].split(", ")
        for name in names:
            found.append((number, "".join(parents) + name, depth))
        if len(names) == 1 and names[0].endswith("/"):
            parents.append(names[0])
    return found


def _parts(folder: Path) -> set[str]:
    """The packages (``name/``: folders with an ``__init__.py``) and modules (``name.py``) directly in
    ``folder``, without ``__init__.py`` and ``__main__.py``."""
    packages = {f"{p.name}/" for p in folder.iterdir() if p.is_dir() and (p / "__init__.py").is_file()}
    modules = {p.name for p in folder.glob("*.py") if p.name not in ("__init__.py", "__main__.py")}
    return packages | modules


def test_the_layout_tree_names_every_top_level_package_and_module() -> None:
    named = {path for _, path, depth in _layout_tree() if depth == 1}
    missing = sorted(_parts(PACKAGE) - named)
    assert not missing, "parts of src/terrapref/ that docs/layout.md's tree does not name: " + ", ".join(missing)


def test_the_layout_tree_names_every_decision_rule_package() -> None:
    named = {path for _, path, _ in _layout_tree()}
    rules = {f"rules/{p.name}/" for p in (PACKAGE / "rules").iterdir() if p.is_dir() and (p / "__init__.py").is_file()}
    assert rules, "the scan sees the rule packages"
    missing = sorted(rules - named)
    assert not missing, "rule packages that docs/layout.md's tree does not name: " + ", ".join(missing)


def test_every_part_the_layout_tree_names_exists() -> None:
    tree = _layout_tree()
    assert len(tree) > 30, "the scan reads the tree"
    gone = [
        f"docs/layout.md:{number}: {path}"
        for number, path, _ in tree
        if not ((PACKAGE / path).is_dir() if path.endswith("/") else (PACKAGE / path).is_file())
    ]
    assert not gone, "docs/layout.md's tree names what src/terrapref/ does not hold:\n" + "\n".join(gone)


# --- teaching courses' lengths and times: the docs state what `terrapref course` computes ---------


def _course_text(length_m: float, unit: str = "min") -> str:
    """A course's length and expected drive as the docs write them: ``586 m, about 9.8 min``."""
    from terrapref.scenario.teaching import DRIVER_SPEED_MPS

    return f"{length_m:,.0f} m, about {length_m / DRIVER_SPEED_MPS / 60:.1f} {unit}"


def _feature_table(k: int) -> ClassTable:
    """A table of ``k`` feature classes and one lethal class (the docs' table of lengths)."""
    from terrapref.terrain.classes import ClassTable, TerrainClass

    names = ["grass", *(f"c{i}" for i in range(k)), "tree"]
    return ClassTable(tuple(TerrainClass(i, n, (i, i, i)) for i, n in enumerate(names)), "grass", ("tree",), tuple(names[1:]))


def test_the_table_of_teaching_course_lengths_is_what_the_code_builds() -> None:
    from terrapref.scenario import parse_scenario
    from terrapref.scenario.teaching import designed_course, fits

    text = (DOCS / "classes.md").read_text(encoding="utf-8")
    rows = re.findall(r"^\| (\d+) \| (\d+) \| ([^|]+) \| ([^|]+) \| (full|compact) \|$", text, flags=re.MULTILINE)
    assert len(rows) >= 8, "the scan finds the table of lengths in docs/classes.md"
    wrong = []
    for row in rows:
        k = int(row[0])
        table = _feature_table(k)
        built = [parse_scenario(designed_course(table, design)[0].data(), "course", table) for design in ("full", "compact")]
        cells = [_course_text(course.path_length_m()).replace("about ", "") for course in built]  # as `course` prints them
        expected = (str(k), str(k * (k - 1) // 2), *cells, "full" if fits(table) else "compact")
        if row != expected:
            wrong.append(f"docs/classes.md: | {' | '.join(row)} | should be | {' | '.join(expected)} |")
    assert not wrong, "\n".join(wrong)


def test_the_example_courses_lengths_in_the_docs_are_what_the_code_builds() -> None:
    from collections import Counter

    from terrapref.scenario import resolve_scenario
    from terrapref.scenario.teaching import course_length, designed_course
    from terrapref.terrain.classes import load_classes

    _, items = designed_course(load_classes(ROOT / "examples" / "classes" / "rellis3d.yaml"))
    rellis_m, kinds = course_length(items), Counter(item.kind for item in items)
    small_m = course_length(designed_course(load_classes(ROOT / "examples" / "classes" / "small.yaml"))[1])
    teach_m = resolve_scenario("teach_course").path_length_m()
    readme, classes, teaching = ((ROOT / "README.md").read_text(), (DOCS / "classes.md").read_text(), (DOCS / "teaching.md").read_text())
    results = (DOCS / "results.md").read_text()
    claims = {
        "README.md: the example table's course": (readme, f"# its teaching course: {_course_text(rellis_m)} at 1 m/s"),
        "docs/classes.md: the example table's course": (
            " ".join(classes.split()),
            f"gives a {rellis_m:,.0f} m course: "
            + ", ".join(
                f"{kinds[k]} {name}"
                for k, name in (("pair", "pairs"), ("strip", "strips"), ("lone", "lone patches"), ("lane", "lanes"))
                if kinds[k]
            )
            + f", about {rellis_m / 60:.1f} minutes at 1 m/s",
        ),
        "docs/results.md: small.yaml's course": (
            " ".join(results.split()),
            f"has a {small_m:.0f} m teaching course ({small_m / 60:.1f} minutes",
        ),
        "README.md: teach_course": (readme, f"`teach_course` is the demonstration course ({teach_m:.0f} m;"),
        "docs/teaching.md: teach_course": (teaching, f"`teach_course` is the demonstration course ({teach_m:.0f} m;"),
    }
    wrong = [f"{where}: expected {claim!r}" for where, (text, claim) in claims.items() if claim not in text]
    assert not wrong, "\n".join(wrong)


def _words(text: str) -> str:
    """``text`` lowercased, underscores and runs of spaces as one space: a term as code or prose spells it."""
    return re.sub(r"[_\s]+", " ", text.lower())


def glossary_terms_the_code_does_not_use(glossary: str, code: str) -> list[str]:
    """The glossary's terms (its bold words; ``a / b`` is two) that ``code`` never spells, in the
    singular or the plural."""
    code = _words(code)
    terms = [t.strip() for bold in re.findall(r"\*\*([^*]+)\*\*", glossary) for t in bold.split(" / ")]
    return [t for t in terms if not any(w in code for w in {_words(t), _words(t).removesuffix("s")})]


def test_every_glossary_term_is_a_word_the_code_uses():
    """A term the code no longer says (renamed, or gone) is a stale entry: rename it or remove it."""
    code = " ".join(p.read_text() for p in (ROOT / "src" / "terrapref").rglob("*.py"))
    assert not glossary_terms_the_code_does_not_use((DOCS / "glossary.md").read_text(), code)


def test_the_glossary_check_finds_a_term_the_code_does_not_use():
    glossary = "- **ground map**: ...\n- **val acc / val top3**: ...\n- **stage plan**: ..."
    assert glossary_terms_the_code_does_not_use(glossary, "self.ground_map = ...; print('val acc', val_top3)") == ["stage plan"]
