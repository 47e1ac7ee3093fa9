"""Post-processors: small steps a route applies to its record after the call.

    map_labels: {person: human}        rename detection labels
    filter: {labels: [..], min_score}  keep matching detections
    count: {label: person, into: count}
    annotate: {into: annotated}        draw the detections on the input image
    template: {text: "I see {count} people.", into: text}

A step that changes the detections recounts `counts` (the call's per-label counts) from
them, so later steps and outputs never see counts of detections renamed or dropped.
"""

from __future__ import annotations

from collections.abc import Callable, Iterable
from dataclasses import replace

from oricf.errors import InvalidInput
from oricf.gateway.config import AnnotateStep, CountStep, FilterStep, PostStep, TemplateStep
from oricf.gateway.values import Frame, Record
from oricf.imaging import draw_detections, label_counts

Step = Callable[[Record], None]


def _recount(record: Record, labels: Iterable[str]) -> None:
    """`counts` from the record's detections; each of `labels` kept, at 0 if none is left."""
    record["counts"] = label_counts(record["detections"], labels)


def map_labels(mapping: dict[str, str]) -> Step:
    def run(record: Record) -> None:
        record["detections"] = [replace(d, label=mapping.get(d.label, d.label))
                                for d in record["detections"]]
        _recount(record, [mapping.get(label, label) for label in record.get("counts", {})])

    return run


def filter_detections(step: FilterStep) -> Step:
    labels = set(step.labels)

    def run(record: Record) -> None:
        record["detections"] = [d for d in record["detections"]
                                if (not labels or d.label in labels) and d.score >= step.min_score]
        _recount(record, record.get("counts", {}))

    return run


def count(step: CountStep) -> Step:
    def run(record: Record) -> None:
        detections = record["detections"]
        record[step.into] = (len(detections) if step.label is None
                             else label_counts(detections, [step.label])[step.label])

    return run


def annotate(step: AnnotateStep) -> Step:
    def run(record: Record) -> None:
        frame: Frame = record["image"]
        record[step.into] = Frame.from_pixels(draw_detections(frame.pixels(),
                                                              record["detections"]))

    return run


def template(step: TemplateStep) -> Step:
    def run(record: Record) -> None:
        try:
            record[step.into] = step.text.format_map(record)
        except (KeyError, IndexError, ValueError) as exc:
            raise InvalidInput(f"template {step.text!r}: cannot fill {exc}") from None

    return run


def build(step: PostStep) -> Step:
    if step.map_labels is not None:
        return map_labels(step.map_labels)
    if step.filter is not None:
        return filter_detections(step.filter)
    if step.count is not None:
        return count(step.count)
    if step.annotate is not None:
        return annotate(step.annotate)
    assert step.template is not None  # the schema guarantees exactly one key
    return template(step.template)


def chain(steps: list[PostStep]) -> Step:
    """All steps in order, as one."""
    built = [build(step) for step in steps]

    def run(record: Record) -> None:
        for step in built:
            step(record)

    return run
