"""The docs stay true: the options they list are the programs' options, every figure in
docs/benchmarks.md names its command and date, the README is a front page whose figures link
to where they were measured, and every link between the docs leads somewhere."""

import os
import re
import subprocess
import sys

import pytest
from helpers import REPO

DOCS = os.path.join(REPO, 'docs')
PROGRAMS = ('kobuki_lane.py', 'calibration.py', 'simulate.py')
HELP_OPTION = re.compile(r'^  (?:-\w(?: [A-Z_]+)?, )?(--[a-z0-9][a-z0-9-]*)')


def read(*path):
    with open(os.path.join(REPO, *path), encoding='utf-8') as f:
        return f.read()


def helped(program):
    """The long options `program --help` lists."""
    text = subprocess.run([sys.executable, program, '--help'], cwd=REPO, capture_output=True,
                          text=True, timeout=60).stdout
    return {m.group(1) for m in map(HELP_OPTION.match, text.splitlines()) if m} - {'--help'}


def documented(text, program):
    """The options in the first column of `program`'s table under docs/usage.md's 'Every
    option'."""
    section = text.split('## Every option', 1)[1]
    start = section.index(f'### `{program}`')
    end = section.find('\n### ', start + 1)
    rows = section[start:end if end > 0 else None].splitlines()
    return {m.group(1) for m in (re.match(r'^\| `(--[a-z0-9-]+)` \|', row) for row in rows) if m}


@pytest.mark.parametrize('program', PROGRAMS)
def test_the_usage_doc_lists_every_option_the_program_has(program):
    have, listed = helped(program), documented(read('docs', 'usage.md'), program)
    assert have == listed, (f'only in --help: {sorted(have - listed)}; only in docs/usage.md: '
                            f'{sorted(listed - have)}')


def test_the_check_fails_when_an_option_is_renamed_in_one_place_only():
    text = read('docs', 'usage.md')
    renamed = text.replace('| `--wait-for-base` |', '| `--wait-for-the-base` |', 1)
    assert documented(renamed, 'kobuki_lane.py') != helped('kobuki_lane.py')


def sections(text, level='## '):
    """(heading, body) for each section of a markdown text, code blocks left whole."""
    parts = re.split(rf'^{level}(.+)$', text, flags=re.M)
    return list(zip(parts[1::2], parts[2::2]))


COMMAND = re.compile(r'(python|simulate\.py|kobuki_lane\.py|run\.sh|setup\.sh|tools\.)')
DATE = re.compile(r'20\d\d-\d\d-\d\d')
FIGURE = re.compile(r'\d+ of \d+|\d+ ?%|\b\d+/\d+\b|\d+(\.\d+)? ?(ms|cm|frames/s)\b')


def test_every_figure_in_the_benchmarks_doc_names_its_command_and_date():
    found = sections(read('docs', 'benchmarks.md'))
    assert len(found) >= 5
    for heading, body in found:
        if FIGURE.search(body) or re.search(r'^\|.*\d', body, flags=re.M):  # a table of figures
            assert COMMAND.search(body), f"'{heading}' has figures but no command"
            assert DATE.search(body), f"'{heading}' has figures but not the date measured"


def prose(text):
    """The text without its code blocks."""
    return re.sub(r'```.*?```', '', text, flags=re.S)


def test_the_readme_is_a_front_page_whose_figures_link_to_their_measurements():
    text = read('README.md')
    assert len(text.splitlines()) <= 200
    for paragraph in re.split(r'\n\s*\n|\n(?=- )', prose(text)):
        if FIGURE.search(paragraph):
            assert 'docs/benchmarks.md' in paragraph, paragraph
    first_screen = '\n'.join(text.splitlines()[:40])
    for must in ('docs/WALKTHROUGH.md', '#on-the-robot', 'setup.sh demo', 'setup.sh test',
                 'docs/robot.md#the-nodes-ros-interface'):
        assert must in first_screen, must


def slug(heading):
    """GitHub's anchor for a heading."""
    heading = re.sub(r'[`*]', '', heading.strip().lower())
    return re.sub(r'[^\w\- ]', '', heading).replace(' ', '-')


def test_every_link_between_the_docs_leads_to_a_file_and_heading():
    pages = ['README.md'] + [os.path.join('docs', n) for n in os.listdir(DOCS)
                             if n.endswith('.md')]
    for page in pages:
        text = read(page)
        for target in re.findall(r'\]\(([^)\s]+)\)', prose(text)):
            if '://' in target:
                continue
            path, _, anchor = target.partition('#')
            where = os.path.normpath(os.path.join(os.path.dirname(page), path)) if path else page
            assert os.path.exists(os.path.join(REPO, where)), f'{page}: {target}'
            if anchor and where.endswith('.md'):
                headings = re.findall(r'^#+ (.+)$', prose(read(where)), flags=re.M)
                assert anchor in {slug(h) for h in headings}, f'{page}: {target}'
