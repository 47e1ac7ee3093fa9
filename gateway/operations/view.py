"""The control operations (api.Operations) on a pipeline running in this process.

Reads come from the pipeline itself: data products from its ProductStore, the newest frame
of a camera route from the route (`Route.latest`), counters from routes and endpoints. Calls
on what the caller passes (detect, infer, ask, transcribe) go through the same endpoints as
the routes (deadlines, retries, failover), with the route's call settings, but no post step
and no output: an agent's image never reaches a topic or a tracker.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import asdict
from typing import Any

import grpc

from oricf.audio.wav import parse_wav
from oricf.errors import InvalidInput, NotReady
from oricf.gateway.actuation.actuation import Actuation
from oricf.gateway.actuation.audit import AuditLog
from oricf.gateway.actuation.messages import nested
from oricf.gateway.actuation.policy import Refused
from oricf.gateway.components import METHODS, Method, Skip
from oricf.gateway.methods.generate import context_readings
from oricf.gateway.methods.infer import InferCall
from oricf.gateway.operations.api import (
    MAX_AUDIO_BYTES,
    MAX_IMAGE_BYTES,
    MAX_TEXT_CHARS,
    Json,
)
from oricf.gateway.operations.names import known_product
from oricf.gateway.operations.tensors import tensor_inputs, tensor_json
from oricf.gateway.pipeline import Pipeline
from oricf.gateway.route import Route
from oricf.gateway.values import AudioClip, Frame, Record
from oricf.imaging import Detection, draw_detections, encode_image, encoded_size, label_counts
from oricf.logs import quoted
from oricf.metrics import LatencyHistogram
from oricf.models.wire import infer_request, response_outputs


def takes_images(method: Method) -> bool:
    """Routes that take camera frames (look, detect, infer an image)."""
    return method.image_transport


class PipelineView:
    def __init__(self, pipeline: Pipeline, actuation: Actuation | None = None,
                 audit: AuditLog | None = None) -> None:
        self.pipeline = pipeline
        self.actuation = actuation
        self.audit = audit or (actuation.audit if actuation else AuditLog())
        self._writers = {o.product: name for name, r in pipeline.config.routes.items()
                         for o in r.outputs if o.product}

    # reads

    def products(self) -> list[Json]:
        out = []
        for name, route in sorted(self._writers.items()):
            reading = self.pipeline.products.read(name)
            entry = {"name": name, "route": route, "written": reading is not None,
                     "max_age_s": self._max_age(name)}
            if reading is not None:
                entry |= {"value": plain(reading.value), "age_s": round(reading.age_s, 3)}
            out.append(entry)
        return out

    def read_product(self, name: str) -> Json:
        known_product(name, self._writers)
        reading = self.pipeline.products.read(name)
        if reading is None:
            raise NotReady(f"data product {name} has no value yet")
        return {"name": name, "value": plain(reading.value), "age_s": round(reading.age_s, 3),
                "stale": reading.stale, "max_age_s": reading.max_age_s,
                "route": self._writers[name]}

    def look(self, route: str | None = None) -> tuple[Json, bytes]:
        chosen = self._route(route, takes_images, "a camera")
        latest = chosen.latest
        if latest is None:
            raise NotReady(f"route {chosen.name} has taken no frame yet")
        done, record = latest
        frame: Frame = record["image"]
        found: list[Detection] = list(record.get("detections", []))
        pixels = draw_detections(frame.pixels(), found) if found else frame.pixels()
        info = {"route": chosen.name, "age_s": round(time.monotonic() - done, 3),
                "width": pixels.shape[1], "height": pixels.shape[0],
                **findings(record)}
        return info, encode_image(pixels, "jpeg", 80)

    def status(self) -> Json:
        endpoints = {}
        for name, endpoint in self.pipeline.endpoints.items():
            endpoints[name] = {
                "active": endpoint.active.address, "primary": endpoint.primary.address,
                "fallback": endpoint.fallback.address if endpoint.fallback else None,
                "on_fallback": endpoint.active is not endpoint.primary,
                "failovers": endpoint.failovers, "recoveries": endpoint.recoveries,
                "retries": endpoint.retries, "deadline_ms": endpoint.config.deadline_ms,
                **placement_status(endpoint)}
        routes = {}
        for name, route in self.pipeline.routes.items():
            stats = route.stats
            routes[name] = {"method": route.config.call.method, "endpoint": route.endpoint.name,
                            "ok": stats.ok, "skipped": stats.skipped,
                            "errors": dict(stats.errors), "last_ms": round(stats.last_ms, 1),
                            "mean_ms": mean_ms(stats.latency),
                            "received": self.pipeline.workers[name].stats.received,
                            "dropped": self.pipeline.workers[name].stats.dropped}
        return {"endpoints": endpoints, "routes": routes, "control": self._control_status(),
                "agent_calls": self.audit.counts()}

    def _control_status(self) -> Json:
        """Each control loop's counts and the age of its actions' observations (steps)."""
        status = {}
        for name, loop in self.pipeline.loops.items():
            status[name] = {**asdict(loop.counts), "empty_ticks": loop.queue.counts.empty_ticks,
                            "ticks": loop.queue.counts.ticks,
                            "switches": loop.queue.counts.switches,
                            "late_actions": loop.queue.counts.late_actions,
                            "action_age_steps_p50": loop.ages.percentile(50),
                            "action_age_steps_p99": loop.ages.percentile(99)}
        return status

    def policy(self) -> Json:
        if self.actuation is None:
            return {"targets": {}}
        return {"targets": {name: t.summary()
                            for name, t in self.actuation.policy.targets.items()}}

    # calls on what the caller passes

    def detect(self, image: bytes, route: str | None = None) -> Json:
        chosen = self._route(route, takes_images, "a detection", kind="detections")
        return self._run(chosen, {"image": image_frame(image)})

    def infer(self, route: str, image: bytes | None = None,
              tensors: dict[str, Any] | None = None) -> Json:
        """An image through the route's call (its model's pre- and post-processing), or
        tensors straight to an Infer route's model (outputs as tensors)."""
        if (image is None) == (tensors is None):
            raise InvalidInput("give an image or tensors, not both")
        if image is not None:
            return self._run(self._route(route, takes_images, "an image"),
                             {"image": image_frame(image)})
        chosen = self._route(route, lambda m: m.takes_tensors, "an Infer")
        call: InferCall = chosen.config.call  # type: ignore[assignment]
        request = infer_request(call.server_model, tensor_inputs(tensors))
        try:
            outputs = response_outputs(chosen.endpoint.call("ModelInfer", request))
        except grpc.RpcError as exc:
            raise call_error(exc, chosen) from None
        return {"route": chosen.name, "model": call.server_model,
                "outputs": {name: tensor_json(array) for name, array in outputs.items()}}

    def ask(self, question: str) -> Json:
        question = text_arg(question, "question")
        chosen = self._route(None, lambda m: m.answers, "a language model")
        facts = context_readings(chosen.config.call, self.pipeline.products)  # type: ignore[arg-type]
        result = self._run(chosen, {"text": question, "value": question, "route": chosen.name})
        result["facts"] = {r.name: {"value": plain(r.value), "age_s": round(r.age_s, 3),
                                    "stale": r.stale} for r in facts}
        return result

    def transcribe(self, audio: bytes) -> Json:
        if len(audio) > MAX_AUDIO_BYTES:
            raise InvalidInput(f"audio of {len(audio):,} bytes; at most {MAX_AUDIO_BYTES:,}")
        pcm = parse_wav(audio)
        clip = AudioClip(pcm.samples.astype("<i2").tobytes(), pcm.sample_rate, pcm.channels)
        chosen = self._route(None, lambda m: m.hears, "a speech recognition")
        return self._run(chosen, {"audio": clip})

    def say(self, text: str) -> Json:
        """Handed to the pipeline's speech route, so it plays where the pipeline says (a
        speaker, a topic, a file), after what it is saying already."""
        text = text_arg(text, "text")
        chosen = self._route(None, lambda m: m.speaks, "a speech synthesis")
        self.pipeline.submit(chosen.name, lambda: {"value": text, "text": text})
        return {"route": chosen.name, "queued": text}

    # actuation

    def check(self, target: str, message: Json) -> Json:
        checked = self._actuation().check(target, message)
        return {"target": target, "sent": nested(checked.fields), "clamped": checked.clamped}

    def publish(self, target: str, message: Json, approved: bool = False) -> Json:
        return self._actuation().send(target, message, approved)

    def close(self) -> None:
        if self.actuation is not None:
            self.actuation.close()
        self.audit.close()

    # helpers

    def _actuation(self) -> Actuation:
        if self.actuation is None:
            raise Refused("this pipeline has no agent policy: no target may be written")
        return self.actuation

    def _max_age(self, product: str) -> float:
        route = self.pipeline.config.routes[self._writers[product]]
        return next(o.max_age_s for o in route.outputs if o.product == product)

    def _route(self, name: str | None, test: Callable[[Method], bool], what: str,
               kind: str | None = None) -> Route:
        """The named route (or the first) whose method passes `test` and, given a `kind`,
        whose call adds that field."""
        fits = [r for r in self.pipeline.routes.values()
                if test(method := METHODS[r.config.call.method])
                and (kind is None or kind in method.fields(r.config.call))]
        if name is None:
            if not fits:
                raise NotReady(f"this pipeline has no {what} route")
            return fits[0]
        for route in fits:
            if route.name == name:
                return route
        raise InvalidInput(f"no {what} route {quoted(name, 100)} (routes: "
                           f"{', '.join(r.name for r in fits) or 'none'})")

    def _run(self, route: Route, record: Record) -> Json:
        try:
            result = route.method.execute(record)  # without the route's post steps
        except Skip as exc:
            return {"route": route.name, "nothing": str(exc)}
        except KeyError as exc:
            raise InvalidInput(f"route {route.name} needs the field {exc} in its prompt, "
                               f"which a caller cannot give") from None
        except grpc.RpcError as exc:
            raise call_error(exc, route) from None
        fields = {f: getattr(result, f) for f in result.__dataclass_fields__}
        return {"route": route.name, **findings(fields)}


def call_error(exc: grpc.RpcError, route: Route) -> InvalidInput | NotReady:
    """A failed model call as the caller is told it: bad input with the server's reason,
    anything else as the endpoint's failure."""
    if exc.code() == grpc.StatusCode.INVALID_ARGUMENT:
        return InvalidInput(quoted(exc.details() or "", 300))
    return NotReady(f"{route.endpoint.name} failed: {exc.code().name}")


def mean_ms(latency: LatencyHistogram) -> float | None:
    """The mean time a route took per input handled, since the start."""
    buckets, total = latency.snapshot()
    count = buckets[-1][1]
    return round(total / count * 1000, 1) if count else None


def findings(record: Record) -> Json:
    """A record's results as JSON: detections (with track ids), counts per label, classes,
    answers and transcripts; images and audio left out."""
    out: Json = {}
    for key, value in record.items():
        if key == "detections":
            out[key] = [detection_json(d) for d in value]
            out["counts"] = label_counts(value)
        elif isinstance(value, str | int | float | bool) and key not in ("route",):
            out[key] = value
        elif key == "classes":
            out[key] = [[label, float(score)] for label, score in value]
    return out


def detection_json(d: Detection) -> Json:
    item: Json = {"label": d.label, "score": round(float(d.score), 3),
                  "box": [round(float(v), 1) for v in (d.box.x_min, d.box.y_min, d.box.x_max,
                                                       d.box.y_max)]}
    if d.track_id is not None:
        item["track_id"] = d.track_id
    return item


def image_frame(data: bytes) -> Frame:
    """JPEG or PNG bytes from a caller, its size read from the header before any decoding."""
    if not isinstance(data, bytes | bytearray) or not data:
        raise InvalidInput("image: no bytes")
    if len(data) > MAX_IMAGE_BYTES:
        raise InvalidInput(f"image of {len(data):,} bytes; at most {MAX_IMAGE_BYTES:,}")
    encoding, width, height = encoded_size(bytes(data))
    return Frame(bytes(data), encoding, width, height)


def text_arg(text: Any, name: str) -> str:
    if not isinstance(text, str) or not text.strip():
        raise InvalidInput(f"{name}: give some text")
    if len(text) > MAX_TEXT_CHARS:
        raise InvalidInput(f"{name}: at most {MAX_TEXT_CHARS} characters")
    return text


def plain(value: Any) -> Any:
    """A product's value as JSON: numbers and text as they are, detections as objects."""
    if isinstance(value, str | int | float | bool) or value is None:
        return value
    if isinstance(value, Detection):
        return detection_json(value)
    if isinstance(value, list | tuple):
        return [plain(v) for v in value[:100]]
    if isinstance(value, Frame):
        return {"image": f"{value.width}x{value.height} {value.encoding}"}
    return str(value)[:1000]


def placement_status(endpoint: Any) -> Json:
    """Where a placement sends the endpoint's calls, its budget, and its moves by reason."""
    placement = endpoint.placement
    if placement is None:
        return {}
    return {"placement": {"place": placement.place, "budget_ms": round(placement.budget_ms, 2),
                          "moves": {k: v for k, v in placement.decisions.items() if v}}}

