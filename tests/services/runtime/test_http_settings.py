"""server.http in a service's YAML: validated at start, loopback unless a host is named."""

import pytest
from pydantic import ValidationError

from oricf.errors import ConfigError
from oricf.services.local import local_service, service_config
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


def test_a_service_without_an_http_api_refuses_server_http() -> None:
    config = service_config("detector", {"server": {"http": {"listen": "127.0.0.1:0"}}})
    with pytest.raises(ConfigError, match="the detector service has no HTTP API"), \
            local_service("detector", config, load=False):
        pass
