"""Numbers over tracks, frame by frame: the count that holds, unique tracks in a window,
zone entries, exits and dwell, line crossings by direction."""

from __future__ import annotations

from oricf.gateway.tracking.bytetrack import TrackView
from oricf.gateway.tracking.measures import Line, SeenInWindow, Tracks, Zone, count_now
from oricf.imaging import Box


def at(track_id: int, x: float, y: float, now: float, last_seen: float | None = None,
       label: str = "person") -> TrackView:
    """A track whose box's bottom centre is (x, y)."""
    return TrackView(track_id, label, Box(x - 10, y - 60, x + 10, y), (0.0, 0.0), 0.0,
                     now if last_seen is None else last_seen, 5, now)


def test_count_now_holds_a_track_missed_for_less_than_hold_s() -> None:
    tracks = Tracks(10.0, [at(1, 0, 0, 10.0), at(2, 0, 0, 10.0, last_seen=9.8),
                           at(3, 0, 0, 10.0, last_seen=9.0), at(4, 0, 0, 10.0, label="dog")])
    assert count_now(tracks, "person", hold_s=0.3) == 2
    assert count_now(tracks, None, hold_s=0.0) == 2


def test_seen_in_window_counts_each_track_once_until_it_falls_out() -> None:
    seen = SeenInWindow("person", window_s=60)
    assert seen.update(Tracks(0.0, [at(1, 0, 0, 0.0), at(2, 0, 0, 0.0)])) == 2
    assert seen.update(Tracks(30.0, [at(2, 0, 0, 30.0), at(3, 0, 0, 30.0)])) == 3
    assert seen.update(Tracks(61.0, [])) == 2     # track 1 last seen at 0 s
    assert seen.update(Tracks(91.0, [])) == 0


SQUARE = [(100.0, 100.0), (200.0, 100.0), (200.0, 200.0), (100.0, 200.0)]


def test_a_zone_counts_entries_exits_and_dwell() -> None:
    zone = Zone(SQUARE, "person", "bottom", window_s=None)
    steps = [
        (0.0, [at(1, 50, 150, 0.0), at(2, 150, 150, 0.0)]),  # 2 first seen inside: entered
        (1.0, [at(1, 150, 150, 1.0), at(2, 150, 150, 1.0)]),  # 1 walks in
        (2.5, [at(1, 150, 150, 2.5), at(2, 250, 150, 2.5)]),  # 2 walks out
        (3.0, [at(1, 150, 150, 3.0)]),                         # 2 dropped (outside)
        (4.0, []),                                             # 1 dropped while inside: left
    ]
    results = [zone.update(Tracks(t, tracks)) for t, tracks in steps]
    assert [r["inside"] for r in results] == [1, 2, 1, 1, 0]
    assert [r["entries"] for r in results] == [1, 2, 2, 2, 2]
    assert [r["exits"] for r in results] == [0, 0, 1, 1, 2]
    assert [r["dwell_s"] for r in results] == [0.0, 1.0, 1.5, 2.0, 0.0]


def test_a_zone_waits_for_an_unseen_track_to_be_seen_and_windows_its_events() -> None:
    zone = Zone(SQUARE, None, "bottom", window_s=10)
    zone.update(Tracks(0.0, [at(1, 150, 150, 0.0)]))
    # predicted outside but not seen: not an exit yet
    assert zone.update(Tracks(0.5, [at(1, 250, 150, 0.5, last_seen=0.0)]))["exits"] == 0
    assert zone.update(Tracks(20.0, [at(1, 150, 150, 20.0)]))["entries"] == 0  # 0 s is old


def test_a_line_counts_crossings_each_way_and_only_within_the_segment() -> None:
    line = Line((100.0, 0.0), (100.0, 200.0), "person", "bottom", window_s=None)
    # start (100, 0) -> end (100, 200) points down the image: its right is smaller x
    path = [(1, 150, 100), (1, 50, 100), (1, 150, 100), (2, 150, 300), (2, 50, 300)]
    results = []
    for i, (track_id, x, y) in enumerate(path):
        results.append(line.update(Tracks(float(i), [at(track_id, x, y, float(i))])))
    assert [(r["in"], r["out"]) for r in results] == [(0, 0), (1, 0), (1, 1), (1, 1), (1, 1)]
