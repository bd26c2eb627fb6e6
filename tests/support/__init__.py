"""Helpers shared by the test folders (imported as `support.*`: tests/conftest.py puts tests/ on
sys.path)."""
