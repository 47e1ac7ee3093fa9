"""server.http in a service's YAML: validated at start, loopback unless a host is named."""

import pytest
from pydantic import ValidationError

from oricf.services.runtime.config import HttpSettings, ServerSettings


def test_a_bare_port_means_loopback() -> None:
    assert HttpSettings(listen="8053").listen == "127.0.0.1:8053"
    assert HttpSettings.model_validate({"listen": 8053}).listen == "127.0.0.1:8053"
    assert HttpSettings(listen="0.0.0.0:8053").listen == "0.0.0.0:8053"


def test_off_unless_asked_for() -> None:
    assert ServerSettings().http is None


@pytest.mark.parametrize("bad", [{"listen": "localhost"}, {"listen": "1.2.3.4:99999"},
                                 {"listen": "127.0.0.1:1", "max_body_kb": 0},
                                 {"listen": "127.0.0.1:1", "timeout": 3}, {}])
def test_bad_settings_are_refused(bad: dict[str, object]) -> None:
    with pytest.raises(ValidationError):
        HttpSettings.model_validate(bad)
