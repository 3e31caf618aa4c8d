"""Fixtures for the live tests."""

from __future__ import annotations

import pytest

from .streams import synthetic_messages


@pytest.fixture
def synth():
    return synthetic_messages()
