from oricf.v1 import common_pb2 as _common_pb2
from oricf.v1 import speech_pb2 as _speech_pb2
from google.protobuf import descriptor as _descriptor
from google.protobuf import message as _message
from collections.abc import Mapping as _Mapping
from typing import ClassVar as _ClassVar, Optional as _Optional, Union as _Union

DESCRIPTOR: _descriptor.FileDescriptor

class SynthesizeRequest(_message.Message):
    __slots__ = ("text", "voice", "encoding", "speed")
    TEXT_FIELD_NUMBER: _ClassVar[int]
    VOICE_FIELD_NUMBER: _ClassVar[int]
    ENCODING_FIELD_NUMBER: _ClassVar[int]
    SPEED_FIELD_NUMBER: _ClassVar[int]
    text: str
    voice: str
    encoding: str
    speed: float
    def __init__(self, text: _Optional[str] = ..., voice: _Optional[str] = ..., encoding: _Optional[str] = ..., speed: _Optional[float] = ...) -> None: ...

class SynthesizedAudio(_message.Message):
    __slots__ = ("audio", "duration_s", "timings", "sentence", "text", "last", "voice")
    AUDIO_FIELD_NUMBER: _ClassVar[int]
    DURATION_S_FIELD_NUMBER: _ClassVar[int]
    TIMINGS_FIELD_NUMBER: _ClassVar[int]
    SENTENCE_FIELD_NUMBER: _ClassVar[int]
    TEXT_FIELD_NUMBER: _ClassVar[int]
    LAST_FIELD_NUMBER: _ClassVar[int]
    VOICE_FIELD_NUMBER: _ClassVar[int]
    audio: _speech_pb2.Audio
    duration_s: float
    timings: _common_pb2.Timings
    sentence: int
    text: str
    last: bool
    voice: str
    def __init__(self, audio: _Optional[_Union[_speech_pb2.Audio, _Mapping]] = ..., duration_s: _Optional[float] = ..., timings: _Optional[_Union[_common_pb2.Timings, _Mapping]] = ..., sentence: _Optional[int] = ..., text: _Optional[str] = ..., last: _Optional[bool] = ..., voice: _Optional[str] = ...) -> None: ...
