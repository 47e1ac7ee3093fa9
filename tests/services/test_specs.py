"""oricf.services.SERVICES, the one list of model services: each entry agrees with the code it
names (its parts, its proto, its shipped YAML), and a name not in it is refused."""

from __future__ import annotations

import pytest
from google.protobuf import descriptor_pool

from oricf.cli import build_parser
from oricf.config import load_config
from oricf.services import SERVICES, ServiceSpec, load_spec


@pytest.mark.parametrize("spec", SERVICES.values(), ids=lambda s: s.name)
def test_each_spec_names_parts_that_are_served_under_it(spec: ServiceSpec) -> None:
    parts = load_spec(spec.name)
    assert parts.spec is spec
    assert (parts.name, parts.service_name) == (spec.name, spec.grpc_service)
    assert (parts.http_routes is not None) == spec.http


@pytest.mark.parametrize("spec", SERVICES.values(), ids=lambda s: s.name)
def test_each_grpc_service_is_one_its_protos_declare(spec: ServiceSpec) -> None:
    load_spec(spec.name)  # imports its stubs, which add its protos to the default pool
    service = descriptor_pool.Default().FindServiceByName(spec.grpc_service)
    assert service.full_name == spec.grpc_service


@pytest.mark.parametrize("spec", SERVICES.values(), ids=lambda s: s.name)
def test_each_shipped_config_listens_on_the_specs_port(spec: ServiceSpec) -> None:
    config = load_config(spec.config, load_spec(spec.name).config_schema)
    assert str(config.server.listen).rpartition(":")[2] == str(spec.port)


def test_an_unknown_service_is_refused_naming_the_known_ones() -> None:
    with pytest.raises(KeyError, match="unknown service 'nope' \\(known: detector, asr"):
        load_spec("nope")


def test_oricf_serve_offers_exactly_the_registered_services(
        capsys: pytest.CaptureFixture[str]) -> None:
    parser = build_parser()
    assert parser.parse_args(["serve", "tts"]).service == "tts"
    with pytest.raises(SystemExit):
        parser.parse_args(["serve", "nope"])
    assert f"choose from {', '.join(map(repr, SERVICES))}" in capsys.readouterr().err
