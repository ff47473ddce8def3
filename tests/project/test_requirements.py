"""The suite's one rule for what pip does not install (tests/conftest.py): a missing system
library or tool skips the test with the reason on a developer's machine, and fails it under
CI (CI=true), which installs everything (.ci/run)."""
import pytest

from conftest import SYSTEM_LIBRARIES, require_system_library

ABSENT = "libfeedaxis-absent.so.99"


def test_a_missing_library_skips_with_its_name_off_ci(monkeypatch):
    monkeypatch.delenv("CI", raising=False)
    with pytest.raises(pytest.skip.Exception, match=f"system library {ABSENT} cannot be loaded"):
        require_system_library(ABSENT)


def test_a_missing_library_fails_under_ci(monkeypatch):
    monkeypatch.setenv("CI", "true")
    with pytest.raises(pytest.fail.Exception, match=f"{ABSENT}.*CI must provide it"):
        require_system_library(ABSENT)


def test_the_install_hint_is_named(monkeypatch):
    monkeypatch.delenv("CI", raising=False)
    monkeypatch.setitem(SYSTEM_LIBRARIES, ABSENT, "apt-get install libfeedaxis-absent99")
    with pytest.raises(pytest.skip.Exception, match="apt-get install libfeedaxis-absent99"):
        require_system_library(ABSENT)


def test_a_present_library_passes(monkeypatch):
    monkeypatch.setenv("CI", "true")
    require_system_library("libc.so.6")


def test_the_ecos_tests_skip_without_libtbb_and_fail_under_ci(monkeypatch):
    import test_fmi_hosts as hosts
    monkeypatch.setattr(hosts, "ECOS_LIBRARY", ABSENT)
    monkeypatch.delenv("CI", raising=False)
    with pytest.raises(pytest.skip.Exception, match=ABSENT):
        hosts.require_ecospy()
    monkeypatch.setenv("CI", "true")
    with pytest.raises(pytest.fail.Exception, match=ABSENT):
        hosts.require_ecospy()
