"""Where a render's arrays live: numpy on the CPU, CuPy on a CUDA GPU (issue 47).

The core is one numpy program. Operations on arrays dispatch to the arrays' own library
(NumPy's ``__array_ufunc__`` / ``__array_function__``), so the only places that must know
the library are those that *create* arrays: they take it from an input with
``array_module(x)`` (numpy for numpy arrays and Python scalars). A device's arrays are
never turned into numpy arrays inside a trace; they come back once, with ``to_host``,
where a result leaves the core (the image, the passes, a summary). A ``Device`` names the
library and the two transfers; ``device_of("cpu" | "cuda")`` makes one (CuPy is an
optional dependency: without it, "cuda" is refused naming the package to install).
"""

from __future__ import annotations

import functools
import importlib.util
import weakref
from dataclasses import dataclass
from types import ModuleType
from typing import Any

import numpy as np

CUPY_HINT = "pip install cupy-cuda12x (CUDA 12) or cupy-cuda13x (CUDA 13)"
"""How to get CuPy (the package for NVIDIA GPUs), named where the GPU is refused."""


@dataclass(frozen=True)
class Device:
    """An array library a render runs on: ``xp`` (numpy's API: ``zeros``, ``asarray``,
    ...), its arrays made from host data by ``xp.asarray`` and brought back by ``to_host``."""

    name: str
    xp: Any

    @property
    def on_host(self) -> bool:
        """Whether the arrays are numpy's own (no transfer at all)."""
        return self.xp is np

    def to_device(self, array: Any) -> Any:
        """``array`` (host data) as this device's array."""
        return array if self.on_host else self.xp.asarray(array)

    def to_host(self, array: Any) -> Any:
        """``array`` (this device's, or a host one) as a numpy array; None stays None."""
        return to_host(array)


CPU = Device("cpu", np)
"""numpy, the default."""


def device_of(device: str | Device) -> Device:
    """The Device a render's ``device`` option names: "cpu", "cuda" (CuPy), or a Device."""
    if isinstance(device, Device):
        return device
    if device == "cpu":
        return CPU
    if device == "cuda":
        return Device("cuda", _cupy())
    raise ValueError(f"device must be 'cpu' or 'cuda', got {device!r}")


@functools.lru_cache(maxsize=1)
def cuda_problem() -> str | None:
    """Why "cuda" cannot render here (CuPy missing, or no GPU it can use), or None (asked
    once per process: a panel asks at every redraw)."""
    try:
        cupy = _cupy()
        cupy.cuda.runtime.getDeviceCount()
    except Exception as error:  # noqa: BLE001 - any failure is a reason to show
        return str(error)
    return None


def _cupy() -> ModuleType:
    """CuPy, or a clear error naming the package to install."""
    try:
        import cupy
    except ImportError as error:
        if importlib.util.find_spec("cupy") is None:
            raise RuntimeError(
                f"device 'cuda' needs CuPy, which is not installed here ({CUPY_HINT})"
            ) from error
        first = next((line for line in str(error).splitlines() if line.strip()), "")
        raise RuntimeError(
            f"device 'cuda': CuPy is installed but did not import ({first})"
        ) from error
    return cupy


def array_module(*arrays: Any) -> Any:
    """The array library of the first array among ``arrays`` that is not numpy's (its
    ``__array_namespace__``, or CuPy for a CuPy array); numpy when all are numpy arrays,
    numpy scalars or Python numbers."""
    for array in arrays:
        if array is None or isinstance(array, (np.ndarray, np.generic, int, float, bool)):
            continue
        namespace = getattr(array, "__array_namespace__", None)
        if type(array).__module__.split(".")[0] == "cupy":
            return _cupy()
        if namespace is not None:
            return namespace()
    return np


def to_host(array: Any) -> Any:
    """A device array as a numpy array (CuPy's ``.get()``); numpy arrays, scalars and
    None as they are."""
    if array is None or isinstance(array, (np.ndarray, np.generic, int, float, bool)):
        return array
    return array.get()


_PLACED: dict[tuple[int, int], tuple[Any, Any]] = {}
"""Host constants' device copies, by (id(host array), id(library)), each beside a weak
reference to its host array: dropped when that array is (weakref.finalize)."""


def placed(constant: Any, like: Any) -> Any:
    """``constant`` (a numpy array a scene or model holds: a position, a rotation, a
    texture) where ``like`` lives: itself beside numpy arrays (no cost), else its copy on
    ``like``'s device, made at the first use and kept."""
    if isinstance(like, (np.ndarray, np.generic, int, float)) or not isinstance(
        constant, np.ndarray
    ):
        return constant
    xp = array_module(like)
    if xp is np:
        return constant
    key = (id(constant), id(xp))
    held = _PLACED.get(key)
    if held is None or held[0]() is not constant:
        held = _PLACED[key] = (weakref.ref(constant), xp.asarray(constant))
        weakref.finalize(constant, _PLACED.pop, key, None)
    return held[1]


def asarray(value: Any, dtype: Any = None) -> Any:
    """``value`` as an array of its own library (numpy's ``asarray`` for host data)."""
    return array_module(value).asarray(value, dtype=dtype)


def is_array(value: Any) -> bool:
    """Whether ``value`` is an array, numpy's or a device's (not a number, not a Dual)."""
    if isinstance(value, np.ndarray):
        return True
    if isinstance(value, (np.generic, int, float, complex)):
        return False
    return type(value).__module__.split(".")[0] == "cupy" or hasattr(value, "__array_namespace__")
