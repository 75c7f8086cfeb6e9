"""The Manager client's errors without a Manager: bad URLs and a Manager nobody listens on (the real
Manager is exercised in tests/blender/farm)."""
import socket

import pytest

from articula.solver.farm.flamenco import FarmError, Manager


def _closed_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]            # closed again when the socket is: nobody listens there


def test_an_unreachable_manager_is_named_with_what_to_check():
    url = f"http://127.0.0.1:{_closed_port()}"
    with pytest.raises(FarmError, match="unreachable.*is it running"):
        Manager(url, timeout=2).version()


@pytest.mark.parametrize("url,message", [("", "no Flamenco Manager URL"), ("ftp://farm", "not a Manager URL")])
def test_bad_urls_are_refused_before_any_request(url, message):
    with pytest.raises(FarmError, match=message):
        Manager(url)


def test_a_bare_host_gets_http():
    assert Manager("farm:8080/").url == "http://farm:8080"
