"""The command lines' shared conventions: a mistake the user can fix is one line on stderr,
'PROG: error: what was wrong and what to do', and exit status 2, never a traceback."""

import sys

from lanelib.settings import output_problem


def fail(prog, message):
    """Say what was wrong and exit with status 2."""
    print(f'{prog}: error: {message}', file=sys.stderr)
    raise SystemExit(2)


def check_output(prog, path, what):
    """Refuse an output path whose folder is missing or read-only, before the run starts."""
    problem = output_problem(path)
    if problem:
        fail(prog, f"{what} '{path}': {problem}")
