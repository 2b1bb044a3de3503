"""The xdist groups reach pytest-xdist's scheduler under `make test` (--dist loadgroup): a test's id carries its
group (tests/conftest.py, _GroupIds), so the tests of a group and of a module sharing a fixture run on one worker."""

from __future__ import annotations

import pytest

pytestmark = pytest.mark.xdist_group(name="xdist_group_check")


@pytest.fixture(scope="module")
def shared() -> int:
    return 1


def test_an_explicit_group_is_in_the_id(request: pytest.FixtureRequest) -> None:
    if not getattr(request.config.option, "loadgroup", False):
        pytest.skip("not run under --dist loadgroup")
    assert request.node.nodeid.endswith("::test_an_explicit_group_is_in_the_id@xdist_group_check")


def test_a_module_fixture_does_not_change_an_explicit_group(
    request: pytest.FixtureRequest, shared: int
) -> None:
    if not getattr(request.config.option, "loadgroup", False):
        pytest.skip("not run under --dist loadgroup")
    assert shared == 1 and request.node.nodeid.endswith("@xdist_group_check")
