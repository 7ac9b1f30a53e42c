"""README's test command (``-n auto --dist loadgroup``) runs the tests of a file that share a module-scoped
fixture on one worker, so the fixture (a study, a sweep, a Ray cluster, a float64 reference) is made once:
tests/conftest.py marks them with an ``xdist_group``, and xdist puts the group's name in their node ids.
Two things broke that without a failing test: the conftest's marking ran after xdist had read the markers
(it is ``tryfirst`` now), and pytest 9 reads a node id that xdist 3.8 no longer rewrites (pyproject.toml's
``test`` extra keeps pytest below 9); each time the module fixtures were built once per worker."""

import pytest


@pytest.fixture(scope="module")
def shared():
    return object()


def test_a_test_with_a_module_fixture_is_in_its_files_group(request, shared):
    if not getattr(request.config.option, "loadgroup", False):  # set on xdist's workers under --dist loadgroup
        pytest.skip("only README's xdist command (--dist loadgroup) groups tests")
    assert request.node.nodeid.endswith("@tests/test_xdist_groups.py"), request.node.nodeid
