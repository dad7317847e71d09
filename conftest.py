"""Every test run leaves the clone as it found it.

A test writes its outputs under its own ``tmp_path``; a command run without ``--out`` writes to
``out/`` in the working folder, and the README's lab sequence to ``lab/``. This session fixture
lists those two folders before the run and fails the run if anything new is in them afterwards,
naming the files, so a test that forgets its ``--out`` is found at once (it had left
``out/validate`` in every clone).
"""

from __future__ import annotations

from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parent
WATCHED = ("out", "lab")  # where commands write by default


def _entries() -> set[str]:
    found: set[str] = set()
    for name in WATCHED:
        folder = REPO / name
        if folder.is_dir():
            found |= {str(p.relative_to(REPO)) for p in folder.rglob("*")}
        elif folder.exists():
            found.add(name)
    return found


@pytest.fixture(scope="session", autouse=True)
def the_run_leaves_the_clone_clean():
    """Fail the run when tests left files in ``out/`` or ``lab/`` of the clone."""
    before = _entries()
    yield
    left = sorted(_entries() - before)
    if left:
        pytest.fail(f"the tests left {len(left)} paths in the clone: {', '.join(left[:6])}"
                    f"{' ...' if len(left) > 6 else ''} (write to tmp_path, give --out)",
                    pytrace=False)
