"""Scraping a /metrics endpoint the way Prometheus does, read with the official text parser."""

from __future__ import annotations

import ssl
import urllib.request
from dataclasses import dataclass

from prometheus_client.parser import text_string_to_metric_families
from prometheus_client.samples import Sample


@dataclass
class Scrape:
    families: dict[str, str]  # family name -> its type
    samples: list[Sample]

    def value(self, name: str, **labels: str) -> float:
        """The one sample called `name` whose labels include `labels`."""
        found = self.find(name, **labels)
        assert len(found) == 1, f"{name}{labels}: {len(found)} samples: {found}"
        return found[0].value

    def find(self, name: str, **labels: str) -> list[Sample]:
        return [s for s in self.samples
                if s.name == name and labels.items() <= s.labels.items()]


def scrape(url: str, context: ssl.SSLContext | None = None) -> Scrape:
    with urllib.request.urlopen(url, timeout=10, context=context) as response:
        assert response.status == 200
        assert response.headers["Content-Type"].startswith("text/plain")
        text = response.read().decode()
    families = list(text_string_to_metric_families(text))
    return Scrape({f.name: f.type for f in families}, [s for f in families for s in f.samples])
