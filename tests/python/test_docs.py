"""The documentation lives in the repository: every docs/ page a source file, script, scene or page cites
exists, and nothing cites a design file kept outside the repository (a clone has only what is tracked)."""

import re
import subprocess
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]

# Text that users and developers read: sources, scripts, scenes, tests, pages.
SUFFIXES = {".cpp", ".hpp", ".py", ".md", ".json", ".sh", ".txt", ".cmake"}
OUTSIDE = re.compile(r"DESIGN\.md|STYLE\.md|\.\./shared/")
CITED_PAGE = re.compile(r"docs/([A-Za-z0-9_\-]+\.md)")


def tracked_text_files():
    out = subprocess.run(["git", "ls-files"], cwd=ROOT, capture_output=True, text=True, check=True).stdout
    for name in out.splitlines():
        path = ROOT / name
        # Results are records of past runs (their commands and notes), not documentation.
        if name.startswith("notebooks/results/") or path.suffix not in SUFFIXES or not path.is_file():
            continue
        yield name, path.read_text(encoding="utf-8", errors="replace")


def test_no_file_cites_a_document_outside_the_repository():
    offenders = [
        f"{name}:{text[: m.start()].count(chr(10)) + 1}: {m.group(0)}"
        for name, text in tracked_text_files()
        if name != "tests/python/test_docs.py"
        for m in OUTSIDE.finditer(text)
    ]
    assert not offenders, "cite docs/ instead:\n" + "\n".join(offenders)


def test_every_cited_docs_page_exists():
    pages = {p.name for p in (ROOT / "docs").glob("*.md")}
    missing = sorted(
        {
            f"{name}: docs/{m.group(1)}"
            for name, text in tracked_text_files()
            for m in CITED_PAGE.finditer(text)
            if m.group(1) not in pages
        }
    )
    assert not missing, "cited pages that do not exist:\n" + "\n".join(missing)


def test_the_readme_layout_names_every_top_level_folder():
    readme = (ROOT / "README.md").read_text(encoding="utf-8")
    layout = readme[readme.index("## Layout") :]
    out = subprocess.run(["git", "ls-files"], cwd=ROOT, capture_output=True, text=True, check=True).stdout
    folders = {name.split("/")[0] for name in out.splitlines() if "/" in name}
    unnamed = sorted(f for f in folders if not re.search(rf"(^|\s|`){re.escape(f)}/", layout))
    assert not unnamed, f"README's layout does not name: {unnamed}"


def test_the_readme_is_a_five_minute_read():
    """The README gets a newcomer to a first simulation, its video and the docs: the two commands, what
    they write, the Python example, the integrators' table, and at most 250 lines (the rest is in docs/)."""
    readme = (ROOT / "README.md").read_text(encoding="utf-8")
    assert len(readme.splitlines()) <= 250
    for must in ("./scripts/run.sh", "./scripts/test.sh", "sand_column_2d.mp4", "pnet video", "## From Python",
                 "## The integrators, measured", "docs/simulating.md", "docs/training.md"):
        assert must in readme, must
    image = re.search(r"!\[[^\]]*\]\(([^)]+)\)", readme)
    assert image and (ROOT / image.group(1)).is_file(), "the README's picture is missing"


def test_every_solver_option_is_documented_and_listed_by_help():
    """The integrators' options are declared once in C++, each beside what reads it (solver/, mpm/, fem/,
    coupling/; joined in sim/integrator_settings.hpp); their keys are
    what plasticitynet_sim reports, docs/scenes.md names each, and `pnet simulate --help` lists each flag."""
    import plasticitynet_sim as pns

    keys = set(pns.Simulation(ROOT / "scenes" / "tiny" / "sand_column_2d.json").solver)
    scenes_md = (ROOT / "docs" / "scenes.md").read_text(encoding="utf-8")
    assert not sorted(k for k in keys if f"`{k}`" not in scenes_md), "docs/scenes.md does not name these keys"
    help_text = subprocess.run([str(ROOT / "build" / "cpp" / "pnet"), "simulate", "--help"], capture_output=True,
                               text=True, check=True).stdout
    listed = set(re.findall(r"scene key (\w+)", help_text))
    assert listed and listed <= keys
