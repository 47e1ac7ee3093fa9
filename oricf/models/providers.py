"""onnxruntime's execution providers, tried in the declared order.

A declaration lists providers by preference (TensorRT, then CUDA, then the CPU, say). The
ones this onnxruntime build lacks are passed over; a provider whose session cannot start
here (its libraries or its device missing) is passed over with onnxruntime's error; a
provider onnxruntime itself drops while the session starts is found from the session's own
list. What runs, and what was passed over and why, is the caller's one log line.
"""

from __future__ import annotations

import logging
from typing import Any

from oricf.errors import ConfigError
from oricf.models.declaration import OnnxRuntimeBackend

log = logging.getLogger(__name__)

# Providers that need NVIDIA's libraries: onnxruntime-gpu finds those installed from PyPI
# (the nvidia-* wheels, as PyTorch brings them) only once preload_dlls() has loaded them.
NVIDIA_PROVIDERS = {"CUDAExecutionProvider", "TensorrtExecutionProvider"}


def _with_options(name: str, settings: OnnxRuntimeBackend) -> Any:
    options = settings.provider_options.get(name)
    return (name, {k: str(v) for k, v in options.items()}) if options else name


def _first_line(exc: BaseException) -> str:
    return (str(exc).strip().splitlines() or [type(exc).__name__])[0][:200]


def open_in_order(ort: Any, model: str | bytes, options: Any,
                  settings: OnnxRuntimeBackend) -> tuple[Any, list[str]]:
    """The session on the first declared provider that starts, and the declared providers
    ahead of it, each with why it was passed over."""
    available = ort.get_available_providers()
    why = {p: "not in this onnxruntime build" for p in settings.providers if p not in available}
    wanted = [p for p in settings.providers if p in available]
    if not wanted:
        raise ConfigError(f"backend.providers: none of {', '.join(settings.providers)} is in "
                          f"this onnxruntime build (it has: {', '.join(available)})")
    if NVIDIA_PROVIDERS & set(wanted) and hasattr(ort, "preload_dlls"):
        try:
            ort.preload_dlls()
        except Exception as exc:  # a session that then fails says more
            log.debug("onnxruntime.preload_dlls: %s", exc)
    for start, name in enumerate(wanted):
        try:
            session = ort.InferenceSession(
                model, options, providers=[_with_options(p, settings) for p in wanted[start:]])
        except Exception as exc:  # onnxruntime raises Fail types of its own
            if start == len(wanted) - 1:
                raise ConfigError(f"backend.providers: no provider could open the model "
                                  f"({name}: {_first_line(exc)})") from None
            why[name] = _first_line(exc)
            continue
        first = session.get_providers()[0]
        if first != name and first in wanted and settings.provider_options.get(first):
            # onnxruntime dropped providers itself and retried on its own fallback list,
            # without their options (a CUDA provider without its declared cuDNN search):
            # the session is opened again from that provider, with them.
            session = ort.InferenceSession(
                model, options, providers=[_with_options(p, settings)
                                           for p in wanted[wanted.index(first):]])
        # Ones onnxruntime dropped itself while the session started (it logs why).
        ahead = wanted[start:wanted.index(first)] if first in wanted else wanted[start:]
        why.update({p: "did not start (onnxruntime's log says why)" for p in ahead})
        return session, [f"{p}: {why[p]}" for p in settings.providers if p in why]
    raise AssertionError("unreachable: the last provider either opens or raises")
