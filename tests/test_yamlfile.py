"""Hostile YAML: every file ORICF reads goes through oricf.yamlfile, whose limits turn what
would exhaust memory, recurse without end or raise a parser's own exception into a
ConfigError naming the file, at once."""

from __future__ import annotations

import os
import subprocess
import sys
import time
from pathlib import Path

import pytest
import yaml

from oricf.config import REPO_ROOT, apply_set, config_dir, read_with_overlays
from oricf.errors import ConfigError
from oricf.yamlfile import MAX_BYTES, MAX_DEPTH, MAX_NODES, LimitedLoader, parse_yaml, read_limited


def alias_bomb(levels: int = 9, width: int = 9) -> str:
    """A few hundred bytes: each level repeats the one before `width` times."""
    lines = [f"l0: &l0 [{', '.join(['x'] * width)}]"]
    lines += [f"l{i}: &l{i} [{', '.join([f'*l{i - 1}'] * width)}]" for i in range(1, levels)]
    return "\n".join(lines) + "\n"


HOSTILE: dict[str, tuple[bytes, str]] = {
    "alias bomb": (alias_bomb().encode(), f"more than {MAX_NODES:,} values (aliases counted "
                   "as what they repeat), reached at l5["),
    "deep nesting": (b"[" * 10_000 + b"]" * 10_000, f"more than {MAX_DEPTH} levels"),
    "deep mapping": ("".join("  " * i + f"k{i}:\n" for i in range(200)).encode(),
                     f"more than {MAX_DEPTH} levels"),
    "latin-1": ("label: caf\xe9\n".encode("latin-1"), "not UTF-8 text (byte 10)"),
    "utf-16": ("name: edge\n".encode("utf-16"), "not UTF-8 text"),
    "big integer": (b"timeout_ms: " + b"9" * 5000, "an integer of more than"),
    "self-containing": (b"a: {b: [0, &a [1, *a]]}\n", "an alias inside the value it names "
                        "(a structure that contains itself) at a.b[1][1]"),
    "impossible date": (b"when: 2001-02-30\n", "day is out of range"),
    "control character": (b"name: \x1f\n", "character #x001f is not allowed in YAML"),
    "a long list": (b"- x\n" * (MAX_BYTES // 4 + 1), f"larger than {MAX_BYTES:,} bytes"),
    "too many values": (("[" + "1," * (MAX_NODES + 1) + "]").encode(), "values"),
    "a key given twice": (b"executor: python\nexecutor: events\n",
                          "(line 2, column 1): the key executor is given twice"),
    "a nested key given twice": (b"routes: {people: [{topic: a, topic: b}]}\n",
                                 "the key routes.people[0].topic is given twice"),
    "one key written two ways": (b"1: a\n0x1: b\n", "the key 0x1 is given twice"),
}


@pytest.mark.parametrize("case", HOSTILE)
def test_a_hostile_overlay_is_refused_naming_it(case: str, tmp_path: Path) -> None:
    data, reason = HOSTILE[case]
    base = tmp_path / "base.yaml"
    base.write_text("name: base\n")
    overlay = tmp_path / "overlay.yaml"
    overlay.write_bytes(data)
    started = time.monotonic()
    with pytest.raises(ConfigError) as err:
        read_with_overlays(base, [overlay])
    assert time.monotonic() - started < 10
    assert str(err.value).startswith(f"{overlay}: ")
    assert reason in str(err.value)


def test_a_link_to_an_endless_device_is_not_read(tmp_path: Path) -> None:
    config = tmp_path / "zero.yaml"
    config.symlink_to("/dev/zero")
    with pytest.raises(ConfigError, match=f"{config}: a device, not a YAML file"):
        read_with_overlays(config)


def test_a_fifo_is_refused_without_waiting_for_a_writer(tmp_path: Path) -> None:
    fifo = tmp_path / "overlay.yaml"
    os.mkfifo(fifo)
    with pytest.raises(ConfigError, match=rf"{fifo}: a FIFO \(named pipe\), not a YAML file"):
        read_with_overlays(config_dir() / "pipelines" / "people_qa.yaml", [fifo])


def test_a_file_beyond_the_cap_is_not_read(tmp_path: Path) -> None:
    big = tmp_path / "big.yaml"
    with open(big, "wb") as file:
        file.truncate(64 << 20)  # sparse: its size says it all
    with pytest.raises(ConfigError, match=f"{big}: larger than {MAX_BYTES:,} bytes"):
        read_limited(big, "a YAML file")


def test_a_folder_is_refused_by_name(tmp_path: Path) -> None:
    with pytest.raises(ConfigError, match=f"{tmp_path}: a folder, not a YAML file"):
        read_with_overlays(tmp_path)


def test_set_values_have_the_same_limits() -> None:
    with pytest.raises(ConfigError, match=r"--set a.b: the value: .*an integer of more than"):
        apply_set({}, "a.b=" + "9" * 5000)
    with pytest.raises(ConfigError, match=r"--set a: the value: .*values"):
        apply_set({}, "a=" + alias_bomb())


def test_what_configs_use_still_reads() -> None:
    text = "base: &base {timeout_ms: 5, labels: [a, b]}\nroute: {<<: *base, topic: t}\n"
    assert parse_yaml(text, "x") == {"base": {"timeout_ms": 5, "labels": ["a", "b"]},
                                     "route": {"timeout_ms": 5, "labels": ["a", "b"],
                                               "topic": "t"}}
    assert parse_yaml("\ufeffn: " + "9" * 30, "x") == {"n": int("9" * 30)}
    # A merge brings keys the mapping may give again (compose/edge.yaml does): not twice.
    merged = "base: &base {a: 1, b: 2}\nr: {<<: *base, a: 3}\ns: {<<: [*base], b: 4}\n"
    assert parse_yaml(merged, "x") == {"base": {"a": 1, "b": 2}, "r": {"a": 3, "b": 2},
                                       "s": {"a": 1, "b": 4}}
    assert parse_yaml("'1': a\n1: b\n", "x") == {"1": "a", 1: "b"}  # a string, a number


SHIPPED = ["configs", "compose", "ros", "tests/data", "docs"]


def test_no_shipped_yaml_gives_a_key_twice() -> None:
    """Every YAML file in the repository, each document of it, by the project's loader."""
    files = [path for folder in SHIPPED for pattern in ("*.yaml", "*.yml")
             for path in (REPO_ROOT / folder).rglob(pattern)]
    assert len(files) > 40
    for path in files:
        loader = LimitedLoader(path.read_text())
        try:
            while loader.check_node():
                loader.get_node()
        except yaml.YAMLError as exc:
            pytest.fail(f"{path.relative_to(REPO_ROOT)}: {exc}")
        finally:
            loader.dispose()


def test_the_gateway_refuses_a_bomb_overlay_with_one_line(tmp_path: Path) -> None:
    overlay = tmp_path / "bomb.yaml"
    overlay.write_text(alias_bomb())
    pipeline = config_dir() / "pipelines" / "people_qa.yaml"
    done = subprocess.run([sys.executable, "-m", "oricf", "gateway", "--config", str(pipeline),
                           "--overlay", str(overlay), "--check"],
                          capture_output=True, text=True, timeout=60)
    assert done.returncode == 2
    assert "Traceback" not in done.stderr
    assert f"{overlay}: invalid YAML" in done.stderr
