"""pytest options of subtrace's tests: ``--update-golden`` rewrites the golden images
(``golden_images/<scene>.exr``) from fresh renders instead of comparing against them."""

from __future__ import annotations

import pytest


def pytest_addoption(parser):
    parser.addoption(
        "--update-golden",
        action="store_true",
        default=False,
        help="render every scene of scenes/ and write it as its golden image "
        "(golden_images/<scene>.exr) instead of comparing",
    )


@pytest.fixture
def update_golden(request) -> bool:
    """True when pytest runs with --update-golden."""
    return bool(request.config.getoption("--update-golden"))
