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

# A route's `call:`: the `method` key picks the schema, so a key of another method is refused.
CallConfig = Annotated[
    detect.DetectCall | transcribe.TranscribeCall | generate.GenerateCall | infer.InferCall
    | synthesize.SynthesizeCall,
    Field(discriminator="method")]

__all__ = ["METHODS", "CallConfig", "Method", "Partial", "Skip"]
