"""The policy service: `oricf serve policy`, oricf.v1.Policy for any declared policy."""

from __future__ import annotations

import grpc

from oricf.models.declaration import load_declaration
from oricf.models.policy import PolicyModel
from oricf.services import SERVICES
from oricf.services.policy.config import PolicyConfig
from oricf.services.policy.servicer import PolicyServicer
from oricf.services.runtime import ModelSlot, ServiceParts
from oricf.services.runtime.streams import MessageStreams
from oricf.store import ModelStore
from oricf.v1 import policy_pb2_grpc

SPEC = SERVICES["policy"]


def create_model(config: PolicyConfig, store: ModelStore) -> PolicyModel:
    return PolicyModel(load_declaration(config.model), store)  # refuses a non-policy task


def add_servicer(server: grpc.Server, slot: ModelSlot[PolicyModel],
                 config: PolicyConfig) -> None:
    policy_pb2_grpc.add_PolicyServicer_to_server(PolicyServicer(slot, config), server)


def message_streams(config: PolicyConfig) -> MessageStreams:
    """ActStream: a robot's stream holds a call slot only while an observation is answered."""
    return MessageStreams(frozenset({f"/{SPEC.grpc_service}/ActStream"}),
                          config.stream_idle_s, "stream_idle_s")


PARTS = ServiceParts(
    SPEC,
    config_schema=PolicyConfig,
    create_model=create_model,
    add_servicer=add_servicer,
    message_streams=message_streams,
)
