"""Every example the README and the manual show is run, and prints what they show
(test/doc_examples.py: marked blocks, measured spans). Fast blocks run in the default suite,
those marked ``slow`` under ``pytest -m slow``."""

import re

import pytest

import doc_examples as de
from cdh_planner.cli_reference import reference

EXAMPLES = de.find_examples()


def _param(ex):
    marks = [pytest.mark.slow] if ex.slow else []
    return pytest.param(ex, id=ex.name, marks=marks)


def test_the_docs_have_examples_in_both_speeds():
    assert any(not ex.slow for ex in EXAMPLES)
    assert any(ex.slow for ex in EXAMPLES)


@pytest.mark.parametrize("ex", [_param(ex) for ex in EXAMPLES])
def test_example_prints_what_the_docs_show(ex):
    diff = de.differences(ex, de.run(ex))
    assert not diff, diff + "\n(if the change is right: python test/doc_examples.py --update)"


def test_a_changed_output_fails(tmp_path):
    """The runner can fail: an example whose shown output differs from the command's."""
    page = tmp_path / "page.md"
    page.write_text("<!-- example -->\n```console\n$ echo 227 waypoints\n215 waypoints\n```\n"
                    "<!-- example measured -->\n```console\n$ echo took 0.31 s\ntook 0.29 s\n```\n")
    good, timed = de.find_examples([page])
    assert "215 waypoints" in de.differences(good, de.run(good))
    assert de.differences(timed, de.run(timed)) == ""     # a time may differ
    de.update(good, de.run(good))
    assert "227 waypoints" in page.read_text()
    again, _ = de.find_examples([page])
    assert de.differences(again, de.run(again)) == ""


def test_a_failing_command_shows_its_exit_code(tmp_path):
    page = tmp_path / "page.md"
    page.write_text("<!-- example -->\n```console\n$ cdh-planner plan no_such.yaml\n[exit 2]\n```\n")
    ex, = de.find_examples([page])
    assert de.differences(ex, de.run(ex)) == ""


def test_a_trimmed_output_matches_its_kept_lines():
    assert de.matches(["a", "...", "z"], ["a", "b", "c", "z"])
    assert de.matches(["...", "z"], ["z"])
    assert not de.matches(["a", "...", "z"], ["a", "b"])


def test_the_command_line_reference_is_current():
    assert (de.REPO / "docs" / "cli.md").read_text() == reference(), \
        "docs/cli.md is stale: python -m cdh_planner.cli_reference > docs/cli.md"


def test_every_manual_page_is_reachable_from_the_readme():
    """README -> docs pages -> their links: every docs/*.md is reached."""
    seen, todo = set(), [de.REPO / "README.md"]
    while todo:
        page = todo.pop()
        for target in re.findall(r"\]\(([^)#\s]+\.md)\)", page.read_text()):
            path = (page.parent / target).resolve()
            if path.exists() and path not in seen and de.REPO / "docs" in path.parents:
                seen.add(path)
                todo.append(path)
    assert {p.name for p in (de.REPO / "docs").glob("*.md")} <= {p.name for p in seen}


def test_the_readme_is_a_front_door():
    assert len((de.REPO / "README.md").read_text().splitlines()) <= 250
