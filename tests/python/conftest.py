import pytest

from support import Server


@pytest.fixture
def server():
    s = Server()
    yield s
    s.stop()
