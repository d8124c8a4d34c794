"""Shared paths of the Python tests: the repository's fixtures (fixtures/data/)."""

import pathlib

import pytest

DATA = pathlib.Path(__file__).resolve().parents[2] / "fixtures" / "data"
REFERENCE = DATA / "reference"


@pytest.fixture
def data():
    return DATA


@pytest.fixture
def reference():
    return REFERENCE
