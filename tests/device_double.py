"""A CPU test double for device (GPU) arrays: what CuPy refuses, it refuses (issue 47).

``DeviceArray`` wraps a numpy array. Like a CuPy array it dispatches numpy's functions and
ufuncs (``__array_function__``, ``__array_ufunc__``) and refuses what would move data
between host and device implicitly: ``np.asarray(device_array)`` (``__array__`` raises),
a numpy array (of any shape) mixed into a device operation, a numpy array as an index or
as the value set into a device array. Python and numpy scalars mix freely, and a device
array's size-1 values read as Python numbers (``float(a)``, ``bool(a)``, ``int(a)``), as
CuPy's do (a sync: ``host_reads`` counts them). Functions that CuPy answers with a 0-d
array (``array_equal``, ``array_equiv``, ``allclose``) answer with one here too, so an
``if`` on them is the sync it is on a GPU. ``DEVICE`` is a ``core.backend.Device`` over
it: ``core.render(..., device=DEVICE)`` runs the core as it would run on CuPy, so a stray
host array or conversion fails in CI, not on a user's GPU.
"""

from __future__ import annotations

from collections.abc import Iterator
from contextlib import contextmanager
from typing import Any

import numpy as np

from core.backend import Device


class HostTransferError(TypeError):
    """An implicit transfer between host and device arrays (CuPy raises TypeError too)."""


def _unwrap(value: Any, what: str) -> Any:
    """``value`` with every DeviceArray replaced by its data (recursively through lists,
    tuples and dicts); a numpy array inside is refused."""
    if isinstance(value, DeviceArray):
        return value.data
    if isinstance(value, np.ndarray):
        raise HostTransferError(f"a numpy array {value.shape} {value.dtype} given to {what}")
    if isinstance(value, (list, tuple)):
        return type(value)(_unwrap(v, what) for v in value)
    if isinstance(value, dict):
        return {k: _unwrap(v, what) for k, v in value.items()}
    return value


def _wrap(value: Any) -> Any:
    """numpy results as DeviceArrays (scalars as 0-d arrays, as CuPy returns them)."""
    if isinstance(value, np.ndarray):
        return DeviceArray(value)
    if isinstance(value, np.generic) and not isinstance(value, np.str_):
        return DeviceArray(np.asarray(value))
    if isinstance(value, tuple):
        return tuple(_wrap(v) for v in value)
    if isinstance(value, list):
        return [_wrap(v) for v in value]
    return value


class DeviceArray(np.lib.mixins.NDArrayOperatorsMixin):
    """A numpy array that behaves, towards numpy, like a CuPy array (module docstring)."""

    __slots__ = ("data",)

    def __init__(self, data: np.ndarray) -> None:
        self.data = data

    # --- what numpy and Python ask of an array ----------------------------------------
    def __array__(self, dtype=None, copy=None):
        raise HostTransferError(
            "implicit conversion of a device array to a numpy array (use core.backend.to_host)"
        )

    def __array_ufunc__(self, ufunc, method, *inputs, **kwargs):
        where = f"np.{ufunc.__name__}.{method}" if method != "__call__" else f"np.{ufunc.__name__}"
        result = getattr(ufunc, method)(*_unwrap(inputs, where), **_unwrap(kwargs, where))
        if "out" in kwargs:  # the outputs given, filled in place
            out = kwargs["out"]
            return out[0] if isinstance(out, tuple) and len(out) == 1 else out
        return _wrap(result)

    def __array_function__(self, func, types, args, kwargs):
        where = f"np.{func.__name__}"
        result = func(*_unwrap(args, where), **_unwrap(kwargs, where))
        if func.__name__ in _ANSWERED_ON_DEVICE:
            return DeviceArray(np.asarray(result))
        return _wrap(result)

    def __array_namespace__(self, api_version=None):
        return XP

    def get(self) -> np.ndarray:
        """The data, on the host (CuPy's explicit transfer)."""
        return self.data.copy()

    def __repr__(self) -> str:
        return f"DeviceArray({self.data!r})"

    def __len__(self) -> int:
        return len(self.data)

    def __iter__(self):
        return (_wrap(row) for row in self.data)

    def __getitem__(self, key):
        return _wrap(self.data[_unwrap(key, "an index")])

    def __setitem__(self, key, value) -> None:
        self.data[_unwrap(key, "an index")] = _unwrap(value, "a value set")

    def _scalar(self):
        _HOST_READS[0] += 1
        if self.data.size != 1:
            raise TypeError(f"only size-1 arrays read as Python scalars, not {self.data.shape}")
        return self.data.reshape(()).item()

    def __bool__(self) -> bool:
        return bool(self._scalar())

    def __float__(self) -> float:
        return float(self._scalar())

    def __int__(self) -> int:
        return int(self._scalar())

    def __complex__(self) -> complex:
        return complex(self._scalar())

    def __index__(self) -> int:
        if not np.issubdtype(self.data.dtype, np.integer):
            raise TypeError("only integer arrays are indices")
        return int(self._scalar())

    # --- attributes and methods of ndarray ----------------------------------------------
    shape = property(lambda self: self.data.shape)
    ndim = property(lambda self: self.data.ndim)
    size = property(lambda self: self.data.size)
    dtype = property(lambda self: self.data.dtype)
    itemsize = property(lambda self: self.data.itemsize)
    nbytes = property(lambda self: self.data.nbytes)
    T = property(lambda self: DeviceArray(self.data.T))
    flags = property(lambda self: self.data.flags)
    strides = property(lambda self: self.data.strides)

    @property
    def real(self):
        return DeviceArray(self.data.real)

    @property
    def imag(self):
        return DeviceArray(self.data.imag)

    def __getattr__(self, name: str):
        if name in _METHODS:
            method = getattr(self.data, name)

            def call(*args, **kwargs):
                where = f"ndarray.{name}"
                return _wrap(method(*_unwrap(args, where), **_unwrap(kwargs, where)))

            return call
        raise AttributeError(f"DeviceArray has no attribute {name!r}")

    def tolist(self):
        _HOST_READS[0] += 1
        return self.data.tolist()

    def item(self, *args):
        _HOST_READS[0] += 1
        return self.data.item(*args)


_ANSWERED_ON_DEVICE = frozenset({"array_equal", "array_equiv", "allclose"})
"""numpy functions whose answer (a Python bool) CuPy gives as a 0-d device array."""
_HOST_READS = [0]
"""Device values read as Python values (syncs) so far, counted by ``host_reads``."""


class HostReads:
    """The syncs of a ``host_reads`` block: ``count`` (so far, or in all once it ended)."""

    def __init__(self) -> None:
        self.start, self.end = _HOST_READS[0], None

    @property
    def count(self) -> int:
        """Device values read back as Python values inside the block."""
        return (_HOST_READS[0] if self.end is None else self.end) - self.start


@contextmanager
def host_reads() -> Iterator[HostReads]:
    """Count the device values read back as Python values (each a sync on a GPU: bool(a),
    float(a), int(a), a.item(), a.tolist()) inside the block (``HostReads.count``)."""
    reads = HostReads()
    try:
        yield reads
    finally:
        reads.end = _HOST_READS[0]


_METHODS = frozenset(
    "astype copy reshape ravel flatten sum prod min max any all mean std var argmin argmax "
    "argsort sort nonzero clip transpose swapaxes cumsum cumprod dot fill view squeeze "
    "repeat take conj round diagonal trace searchsorted".split()
)
"""The ndarray methods a DeviceArray has (CuPy's have them too)."""

_HOST_DATA = frozenset("asarray array ascontiguousarray".split())
"""Functions that take host data onto the device (CuPy's ``asarray``: explicit)."""
_CREATION = frozenset(
    "zeros empty ones full arange linspace eye identity zeros_like empty_like ones_like "
    "full_like frombuffer fromiter indices geomspace logspace tri meshgrid".split()
)
"""Functions that make arrays from shapes or numbers."""


class _Namespace:
    """The double's array module: numpy's names; creation and host data give DeviceArrays."""

    def __getattr__(self, name: str):
        value = getattr(np, name)
        if name in _HOST_DATA:
            return lambda data, *args, **kwargs: DeviceArray(np.array(_host(data), *args, **kwargs))
        if name in _CREATION:

            def make(*args, **kwargs):
                return _wrap(value(*_unwrap(args, f"xp.{name}"), **_unwrap(kwargs, f"xp.{name}")))

            return make
        return value


def _host(data: Any) -> Any:
    """Host data for ``asarray``: DeviceArrays' data, anything else as given."""
    if isinstance(data, DeviceArray):
        return data.data
    if isinstance(data, (list, tuple)):
        return type(data)(_host(v) for v in data)
    return data


XP = _Namespace()
"""The double's array module (numpy's API over DeviceArrays)."""
DEVICE = Device("double", XP)
"""A core.backend.Device on the double."""


def is_device(value: Any) -> bool:
    """Whether ``value`` is a DeviceArray."""
    return isinstance(value, DeviceArray)


__all__ = ["DEVICE", "XP", "DeviceArray", "HostTransferError", "host_reads", "is_device"]
