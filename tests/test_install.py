"""A non-editable install holds: a wheel built from this tree, installed into a fresh virtual
environment outside the repository, runs a service and the gateway on its shipped configs.

Only ORICF comes from the wheel; the third-party packages it needs come from the test
environment's site-packages through a .pth line (no index is reachable here). Every command
runs from a temporary folder with no PYTHONPATH or ORICF_CONFIG_DIR, so nothing can be found
in the checkout by accident.
"""

from __future__ import annotations

import os
import shutil
import signal
import subprocess
import sys
import sysconfig
import zipfile
from dataclasses import dataclass
from pathlib import Path

import pytest

from oricf.config import REPO_ROOT
from oricf.launch.health import free_port, wait_serving

# What a wheel is built from: the folders pyproject.toml maps onto the `oricf` package (a
# folder missing here makes the build below fail, naming it).
SOURCES = ("pyproject.toml", "README.md", "oricf", "protos", "services", "gateway", "bench",
           "configs")
HIDDEN = {"PYTHONPATH", "PYTHONHOME", "VIRTUAL_ENV", "ORICF_CONFIG_DIR"}


@dataclass(frozen=True)
class Installed:
    wheel: Path
    venv: Path
    site_packages: Path  # the venv's own
    cwd: Path  # outside the repository

    @property
    def package(self) -> Path:
        return self.site_packages / "oricf"

    def env(self, **extra: str) -> dict[str, str]:
        return {**{k: v for k, v in os.environ.items() if k not in HIDDEN}, **extra}

    def run(self, *argv: str, **env: str) -> subprocess.CompletedProcess[str]:
        """venv/bin/ARGV[0] with the rest, from cwd, in env()."""
        return subprocess.run([str(self.venv / "bin" / argv[0]), *argv[1:]], cwd=self.cwd,
                              env=self.env(**env), capture_output=True, text=True, timeout=60)


def build_wheel(tmp: Path) -> Path:
    """A wheel of a copy of the tree (the checkout's build/ folder stays untouched), built
    offline with this environment's setuptools."""
    src, out = tmp / "src", tmp / "wheel"
    src.mkdir()
    for name in SOURCES:
        source = REPO_ROOT / name
        if source.is_dir():
            shutil.copytree(source, src / name,
                            ignore=shutil.ignore_patterns("__pycache__", "*.pyc"))
        else:
            shutil.copy2(source, src / name)
    subprocess.run([sys.executable, "-m", "pip", "wheel", "--quiet", "--no-deps", "--no-index",
                    "--no-build-isolation", "--wheel-dir", str(out), str(src)], check=True)
    return next(out.glob("oricf-*.whl"))


@pytest.fixture(scope="module")
def installed(tmp_path_factory: pytest.TempPathFactory) -> Installed:
    tmp = tmp_path_factory.mktemp("install")
    assert REPO_ROOT not in tmp.resolve().parents, f"{tmp} is inside the repository"
    wheel = build_wheel(tmp)
    venv = tmp / "venv"
    subprocess.run([sys.executable, "-m", "venv", "--without-pip", str(venv)], check=True)
    subprocess.run([sys.executable, "-m", "pip", "--python", str(venv / "bin" / "python"),
                    "install", "--quiet", "--no-deps", "--no-index", str(wheel)], check=True)
    site_packages = subprocess.run(
        [str(venv / "bin" / "python"), "-c",
         "import sysconfig; print(sysconfig.get_path('purelib'))"],
        check=True, capture_output=True, text=True).stdout.strip()
    # After the wheel's own folder on sys.path: numpy, grpcio, pydantic... from this venv
    # (a path line only: that folder's own .pth files, the editable install's among them,
    # are not run).
    ours = dict.fromkeys([sysconfig.get_path("purelib"), sysconfig.get_path("platlib")])
    (Path(site_packages) / "oricf-test-deps.pth").write_text("".join(f"{p}\n" for p in ours))
    return Installed(wheel, venv, Path(site_packages), tmp)


def test_the_wheel_ships_every_config_file(installed: Installed) -> None:
    shipped = set(zipfile.ZipFile(installed.wheel).namelist())
    configs = [p.relative_to(REPO_ROOT / "configs").as_posix()
               for p in (REPO_ROOT / "configs").rglob("*") if p.is_file()]
    missing = [name for name in configs if f"oricf/configs/{name}" not in shipped]
    assert configs and not missing, f"configs/ files not in the wheel: {missing}"


def test_the_image_build_copies_what_the_wheel_is_built_from() -> None:
    dockerfile = (REPO_ROOT / "compose" / "Dockerfile").read_text()
    build_stage = dockerfile.split("\nFROM ")[1]
    folders = [name for name in SOURCES if (REPO_ROOT / name).is_dir()]
    missing = [name for name in folders if f"COPY {name}/ {name}/\n" not in build_stage]
    assert not missing, f"compose/Dockerfile's build stage does not copy {missing}"


def test_oricf_and_its_configs_come_from_the_installed_package(installed: Installed) -> None:
    code = ("import oricf, oricf.config as c; print(oricf.__file__); print(c.config_dir())\n"
            "from oricf.launch.deployment import load_deployment\n"
            "from oricf.services import SERVICES, load_spec\n"
            "for path in sorted((c.config_dir() / 'deployments').glob('*.yaml')):\n"
            "    load_deployment(path)\n"
            "for name in SERVICES:\n"
            "    c.load_config(c.shipped_service_config(name), load_spec(name).config_schema)\n")
    done = installed.run("python", "-c", code)
    assert done.returncode == 0, done.stderr
    module, configs = done.stdout.split()
    assert Path(module) == installed.package / "__init__.py"
    assert Path(configs) == installed.package / "configs"


@pytest.mark.parametrize(("flags", "name"), [((), "fastdds.xml"),
                                             (("--tcp",), "fastdds-tcp.xml")])
def test_the_fast_dds_profiles_are_the_installed_ones(installed: Installed,
                                                       flags: tuple[str, ...], name: str) -> None:
    done = installed.run("python", "-m", "oricf.gateway.ros.dds", *flags)
    assert done.returncode == 0, done.stderr
    profile = Path(done.stdout.strip())
    assert profile == installed.package / "configs" / "pipelines" / "dds" / name
    assert profile.is_file()


def test_gateway_check_passes_on_every_shipped_pipeline(installed: Installed) -> None:
    pipelines = sorted((installed.package / "configs" / "pipelines").glob("*.yaml"))
    assert pipelines
    placement = installed.package / "configs" / "pipelines" / "placement"
    commands = [["--check"], ["--check", "--overlay", str(placement / "edge.yaml")],
                *(["--check", "--config", str(p)] for p in pipelines)]
    # Started together: each is mostly interpreter start-up.
    checks = [subprocess.Popen([str(installed.venv / "bin" / "oricf"), "gateway", *argv],
                               cwd=installed.cwd, env=installed.env(), text=True,
                               stdout=subprocess.PIPE, stderr=subprocess.STDOUT)
              for argv in commands]
    for argv, check in zip(commands, checks, strict=True):
        output = check.communicate(timeout=60)[0]
        assert check.returncode == 0, f"oricf gateway {' '.join(argv)}:\n{output}"
        assert f"{installed.package / 'configs' / 'pipelines'}/" in output, output


def test_models_list_reads_the_shipped_catalog(installed: Installed) -> None:
    done = installed.run("oricf", "models", "list")
    assert done.returncode == 0, done.stderr
    root = os.environ.get("ORICF_MODEL_DIR") or str(Path.home() / ".cache" / "oricf" / "models")
    assert f"model store: {root}" in done.stdout
    assert any(line.split()[:1] == ["yolox-nano"] and " yes " in line
               for line in done.stdout.splitlines()), done.stdout


def test_a_service_serves_on_its_installed_defaults(installed: Installed) -> None:
    address = f"127.0.0.1:{free_port()}"
    service = subprocess.Popen([str(installed.venv / "bin" / "oricf"), "serve", "detector",
                                "--listen", address], cwd=installed.cwd, env=installed.env(),
                               stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    try:
        wait_serving(address, timeout=45, process=service)
        probe = installed.run("python", "-m", "oricf.launch.health", address)
        assert probe.returncode == 0, probe.stdout + probe.stderr
        service.send_signal(signal.SIGTERM)
        output = service.communicate(timeout=30)[0]
    finally:
        if service.poll() is None:
            service.kill()
            service.communicate()
    assert service.returncode == 0, output
    assert "detector model loaded" in output and "detector stopped" in output, output


def test_missing_configs_fail_loudly(installed: Installed, tmp_path: Path) -> None:
    absent = tmp_path / "absent"
    done = installed.run("oricf", "gateway", "--check", ORICF_CONFIG_DIR=str(absent))
    assert done.returncode == 2
    assert f"ORICF_CONFIG_DIR={absent}: no such folder" in done.stderr

    empty = tmp_path / "empty"
    empty.mkdir()
    done = installed.run("python", "-m", "oricf.gateway.ros.dds", ORICF_CONFIG_DIR=str(empty))
    assert done.returncode == 2
    assert f"{empty}/pipelines/dds/fastdds.xml: the Fast DDS profile is missing" in done.stderr
    done = installed.run("oricf", "gateway", "--check", ORICF_CONFIG_DIR=str(empty))
    assert done.returncode == 2
    assert f"{empty}/pipelines/people_qa.yaml: file not found" in done.stderr
