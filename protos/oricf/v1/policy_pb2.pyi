from oricf.v1 import common_pb2 as _common_pb2
from google.protobuf.internal import containers as _containers
from google.protobuf import descriptor as _descriptor
from google.protobuf import message as _message
from collections.abc import Iterable as _Iterable, Mapping as _Mapping
from typing import ClassVar as _ClassVar, Optional as _Optional, Union as _Union

DESCRIPTOR: _descriptor.FileDescriptor

class Observation(_message.Message):
    __slots__ = ("step", "capture_time_ns", "state", "images", "committed")
    class ImagesEntry(_message.Message):
        __slots__ = ("key", "value")
        KEY_FIELD_NUMBER: _ClassVar[int]
        VALUE_FIELD_NUMBER: _ClassVar[int]
        key: str
        value: _common_pb2.Image
        def __init__(self, key: _Optional[str] = ..., value: _Optional[_Union[_common_pb2.Image, _Mapping]] = ...) -> None: ...
    STEP_FIELD_NUMBER: _ClassVar[int]
    CAPTURE_TIME_NS_FIELD_NUMBER: _ClassVar[int]
    STATE_FIELD_NUMBER: _ClassVar[int]
    IMAGES_FIELD_NUMBER: _ClassVar[int]
    COMMITTED_FIELD_NUMBER: _ClassVar[int]
    step: int
    capture_time_ns: int
    state: _containers.RepeatedScalarFieldContainer[float]
    images: _containers.MessageMap[str, _common_pb2.Image]
    committed: CommittedActions
    def __init__(self, step: _Optional[int] = ..., capture_time_ns: _Optional[int] = ..., state: _Optional[_Iterable[float]] = ..., images: _Optional[_Mapping[str, _common_pb2.Image]] = ..., committed: _Optional[_Union[CommittedActions, _Mapping]] = ...) -> None: ...

class CommittedActions(_message.Message):
    __slots__ = ("start_step", "actions")
    START_STEP_FIELD_NUMBER: _ClassVar[int]
    ACTIONS_FIELD_NUMBER: _ClassVar[int]
    start_step: int
    actions: _containers.RepeatedScalarFieldContainer[float]
    def __init__(self, start_step: _Optional[int] = ..., actions: _Optional[_Iterable[float]] = ...) -> None: ...

class ActionChunk(_message.Message):
    __slots__ = ("start_step", "observation_step", "capture_time_ns", "action_dim", "actions", "model", "timings", "error")
    START_STEP_FIELD_NUMBER: _ClassVar[int]
    OBSERVATION_STEP_FIELD_NUMBER: _ClassVar[int]
    CAPTURE_TIME_NS_FIELD_NUMBER: _ClassVar[int]
    ACTION_DIM_FIELD_NUMBER: _ClassVar[int]
    ACTIONS_FIELD_NUMBER: _ClassVar[int]
    MODEL_FIELD_NUMBER: _ClassVar[int]
    TIMINGS_FIELD_NUMBER: _ClassVar[int]
    ERROR_FIELD_NUMBER: _ClassVar[int]
    start_step: int
    observation_step: int
    capture_time_ns: int
    action_dim: int
    actions: _containers.RepeatedScalarFieldContainer[float]
    model: str
    timings: _common_pb2.Timings
    error: _common_pb2.Error
    def __init__(self, start_step: _Optional[int] = ..., observation_step: _Optional[int] = ..., capture_time_ns: _Optional[int] = ..., action_dim: _Optional[int] = ..., actions: _Optional[_Iterable[float]] = ..., model: _Optional[str] = ..., timings: _Optional[_Union[_common_pb2.Timings, _Mapping]] = ..., error: _Optional[_Union[_common_pb2.Error, _Mapping]] = ...) -> None: ...
