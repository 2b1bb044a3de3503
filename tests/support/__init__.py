"""Helpers shared by the tests (not test modules themselves): import them as tests.support.<module>."""
