"""A headless Chromium for the browser tests of this folder, one per module."""

from __future__ import annotations

import pytest

from tests.support.cdp import Browser, chromium_binary


@pytest.fixture(scope="module")
def browser():
    binary = chromium_binary()
    if binary is None:
        pytest.skip("no Chromium here (apt-get install chromium; .ci/run does this)")
    b = Browser(binary)
    yield b
    b.close()
