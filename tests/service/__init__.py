"""Tests of the analysis service (a package so that its conftest does not shadow the shared tests/conftest.py)."""
