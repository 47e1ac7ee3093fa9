"""Post steps: what a route does to its record after the call, in order, one module each.

    map_labels: {person: human}        rename detection labels
    filter: {labels: [..], min_score}  keep matching detections
    count: {label: person, into: count}
    annotate: {into: annotated}        draw the detections on the input image
    template: {text: "I see {count} people.", into: text}
    track: {labels: [person], min_hits: 2, max_age_s: 1}   follow objects: track ids, tracks
    count_tracks: {label: person, hold_s: 0.3, into: people_now}
    seen_tracks: {label: person, window_s: 60, into: people_last_minute}
    zone: {polygon: [[x, y], ...], measure: entries, into: door_entries}
    line: {start: [x, y], end: [x, y], measure: in, into: came_in}

Every step says which record fields it reads and which it writes, so a pipeline whose steps
or outputs name a field its route does not have is refused when it loads. Adding a step is
one module here with its schema, its class (a Step built from the settings, with a
`run(record)`) and `COMPONENT = StepKind(key, schema, StepClass)`
(oricf.gateway.components), and its line in COMPONENTS below: the pipeline schema's `post:`
entries take its key from then on (oricf.gateway.config.PostStep). The modules not listed
(base, over_tracks) are what steps share.
"""

from __future__ import annotations

from oricf.gateway.components import PostSteps, Step, StepKind

__all__ = ["PostSteps", "Step", "StepKind"]

COMPONENTS = (
    "annotate",
    "count",
    "count_tracks",
    "filter",
    "line",
    "map_labels",
    "round",
    "seen_tracks",
    "template",
    "track",
    "zone",
)
