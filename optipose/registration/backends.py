"""Registration back-ends behind one interface, picked by name (``RegistrationConfig.backend``).

========  ===========================================  ======================================
name      module                                       methods
========  ===========================================  ======================================
fast      :mod:`optipose.registration.fast`            point_to_point, point_to_plane
plain     :mod:`optipose.registration.fast` (numpy)    point_to_point, point_to_plane
open3d    :mod:`optipose.registration.open3d_icp`      point_to_point, point_to_plane, generalized
========  ===========================================  ======================================

A method the named back-end does not run goes to Open3D (generalized ICP has no fast path). The
built-in back-ends are listed as ``"module:Class"`` and imported on first use, so importing this module
(and validating an objective's names against :data:`BACKENDS`) loads neither SciPy, numba nor Open3D.
Every back-end passes the contract tests in ``tests/test_registration_backends.py``; add one with
:func:`register_backend`.
"""

from __future__ import annotations

import importlib
from typing import TYPE_CHECKING, Protocol, runtime_checkable

import numpy as np

from optipose.errors import ConfigError
from optipose.registration.result import MIN_POINTS, Matches, Registration

if TYPE_CHECKING:
    from optipose.registration.config import RegistrationConfig

__all__ = ["RegistrationBackend", "BACKENDS", "get_backend", "register_backend", "backend_for", "register"]


@runtime_checkable
class RegistrationBackend(Protocol):
    """What a registration back-end provides.

    methods : the ``RegistrationConfig.method`` values it runs.
    takes_initial : it uses ``initial`` (the source's :class:`Matches` at identity) when given, so a
        caller registering many subsets of the same clouds may search them once.
    register : ICP of ``source`` (n, 3) m onto ``reference`` from identity, under ``cfg``. ``reference``
        is a :class:`optipose.registration.reference.SurfaceReference` or ``SampledReference``
        (``closest``, ``follow``, ``nearest``, ``sample``). It returns a failed :class:`Registration`
        (``ok`` False, ``failure`` saying why), never raises, for a problem in the data.
    """

    methods: tuple[str, ...]
    takes_initial: bool

    def register(self, source: np.ndarray, reference, cfg: RegistrationConfig, initial: Matches | None = None) -> Registration: ...


BACKENDS: dict[str, RegistrationBackend | str] = {
    "fast": "optipose.registration.fast:FastBackend",
    "plain": "optipose.registration.fast:PlainBackend",
    "open3d": "optipose.registration.open3d_icp:Open3DBackend",
}


def register_backend(name: str, backend: RegistrationBackend) -> None:
    """Make ``backend`` available as ``RegistrationConfig.backend = name`` (replacing any of that name)."""
    if not isinstance(backend, RegistrationBackend):
        raise TypeError(f"registration backend '{name}' needs methods, takes_initial and register(); got {backend!r}")
    BACKENDS[str(name)] = backend


def get_backend(name: str) -> RegistrationBackend:
    """The back-end registered as ``name``; :class:`ConfigError` if there is none."""
    entry = BACKENDS.get(name)
    if entry is None:
        raise ConfigError(f"unknown registration backend '{name}' (registered: {', '.join(BACKENDS)})")
    if isinstance(entry, str):  # a built-in, imported on first use
        module, cls = entry.split(":")
        entry = BACKENDS[name] = getattr(importlib.import_module(module), cls)()
    return entry


def backend_for(cfg: RegistrationConfig) -> RegistrationBackend:
    """The back-end that runs ``cfg``: the named one, or Open3D for a method the named one lacks."""
    backend = get_backend(cfg.backend)
    return backend if cfg.method in backend.methods else get_backend("open3d")


def register(source: np.ndarray, reference, cfg: RegistrationConfig, initial: Matches | None = None) -> Registration:
    """Register a scan ``source`` (n, 3) m onto ``reference`` from identity (ICP, see :func:`backend_for`).

    initial : the reference matches of ``source`` at identity, if already known (they are the same for
        every subset that contains a sensor, so the evaluator searches them once per sensor).
    Returns a :class:`Registration`; fewer than :data:`MIN_POINTS` points fail without a back-end call.
    """
    backend = backend_for(cfg)
    if len(source) < MIN_POINTS:
        return Registration.failed(len(source), f"only {len(source)} points")
    return backend.register(source, reference, cfg, initial)
