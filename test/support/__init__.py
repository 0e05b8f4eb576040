"""Helpers shared by several test modules (importable as `support.<module>`: test/ is on sys.path
because test/conftest.py sits there)."""
