"""The methods a route can call, one module each: its call schema, its request, its typed
result, and its entry in METHODS (oricf.gateway.methods.base.Method).

    Detect      image            -> Detections (detections)
    Transcribe  audio            -> Transcript (transcript, duration_s); no words ends the route
    Generate    prompt template  -> Answer (answer); data products as typed facts for context
    Infer       image            -> Detections, or Classes (classes, label, score)
    Synthesize  text template    -> Speech (speech: each sentence's audio as it is made; spoken)

Adding a method is one module with a METHOD, and its line below.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Annotated

from pydantic import Field

from oricf.gateway.methods import detect, generate, infer, synthesize, transcribe
from oricf.gateway.methods.base import Method, Partial, Skip

METHODS: dict[str, Method] = {m.name: m for m in (
    detect.METHOD,
    transcribe.METHOD,
    generate.METHOD,
    infer.METHOD,
    synthesize.METHOD,
)}



def methods_that(test: Callable[[Method], bool]) -> tuple[str, ...]:
    """The names of the methods whose entry passes `test` (e.g. `lambda m: m.speaks`)."""
    return tuple(name for name, method in METHODS.items() if test(method))


# The call methods of routes that take camera frames.
IMAGE_METHODS = methods_that(lambda method: method.image_transport)

# A route's `call:`: the `method` key picks the schema, so a key of another method is refused.
CallConfig = Annotated[
    detect.DetectCall | transcribe.TranscribeCall | generate.GenerateCall | infer.InferCall
    | synthesize.SynthesizeCall,
    Field(discriminator="method")]

__all__ = ["IMAGE_METHODS", "METHODS", "CallConfig", "Method", "Partial", "Skip",
           "methods_that"]
