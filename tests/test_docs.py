"""The docs a newcomer reads stay a reference (issue 61): docs/benchmarks.md one section per script
with the command that reproduces it, short enough to read; README.md under 250 lines; every
citation of a benchmarks.md section ("docs/benchmarks.md \"Title\"") names a heading that exists."""

import re
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
BENCHMARKS = ROOT / "docs" / "benchmarks.md"
MAX_BENCHMARK_LINES = 1300      # about half of what it was as a diary (2,496 lines)
MAX_README_LINES = 250
# sections of benchmarks.md that describe no measurement of their own
NOT_MEASURED = {"Machines", "Contents", "Changelog"}
# an indented command line of a Markdown code block: a script, the CLI or a test run
COMMAND = re.compile(r"^    (?:\S+ )*?(?:\S*python\S* |iblbake |pytest |git |pip |\.venv/bin/pip )")
SCRIPT = re.compile(r"benchmarks/(\w+\.py)")
# where the docs and the code cite benchmarks.md's sections by title
CITING = ("README.md", "docs/*.md", "tests/*.py", "benchmarks/*.py", "iblbake/**/*.py",
          "kernels/**/*.h", "kernels/**/*.cl", "examples/corpus/*.yaml")


def sections(text, level):
    """(title, body) of each heading of exactly `level` #s, the body running to the next such heading."""
    marker = "#" * level + " "
    found, title, body = [], None, []
    for line in text.splitlines():
        if line.startswith(marker):
            if title is not None:
                found.append((title, body))
            title, body = line[len(marker):].strip(), []
        elif title is not None:
            body.append(line)
    if title is not None:
        found.append((title, body))
    return found


def test_benchmarks_md_is_short_enough_to_read():
    lines = BENCHMARKS.read_text().count("\n")
    assert lines <= MAX_BENCHMARK_LINES, f"docs/benchmarks.md has {lines} lines (at most {MAX_BENCHMARK_LINES}: history lives in git)"


def test_readme_stays_under_250_lines():
    lines = (ROOT / "README.md").read_text().count("\n")
    assert lines <= MAX_README_LINES, f"README.md has {lines} lines (at most {MAX_README_LINES})"


def test_every_benchmarks_section_says_how_to_reproduce_it():
    missing = []
    for title, body in sections(BENCHMARKS.read_text(), 2):
        if title in NOT_MEASURED:
            continue
        commands = [line for line in body if COMMAND.match(line)]
        named = SCRIPT.findall(title)
        if not commands or any(not any(script in c for c in commands) for script in named):
            missing.append(title)
    assert not missing, f"sections of docs/benchmarks.md without the command that reproduces them: {missing}"


def test_every_benchmark_script_has_its_section():
    titles = " ".join(title for title, _ in sections(BENCHMARKS.read_text(), 2))
    scripts = sorted(p.name for p in (ROOT / "benchmarks").glob("*.py"))
    assert scripts
    missing = [name for name in scripts if f"benchmarks/{name}" not in titles]
    assert not missing, f"benchmark scripts without a section of their own in docs/benchmarks.md: {missing}"


def test_citations_of_benchmarks_md_name_a_section_that_exists():
    text = BENCHMARKS.read_text()
    headings = [line.lstrip("#").strip() for line in text.splitlines() if line.startswith("#")]
    dangling = []
    for pattern in CITING:
        for path in ROOT.glob(pattern):
            if path == BENCHMARKS or not path.is_file():
                continue
            # a citation may break across lines of a comment or docstring
            flat = re.sub(r"\s*\n\s*(?:#|\*|//)?\s*", " ", path.read_text(errors="replace"))
            for match in re.finditer(r'benchmarks\.md,? "([^"]+)"', flat):
                title = match.group(1).strip()
                if title and not any(h.startswith(title) for h in headings):
                    dangling.append(f"{path.relative_to(ROOT)}: {title!r}")
    assert not dangling, f"citations of docs/benchmarks.md sections that do not exist: {dangling}"
